"""How far a sweep is: ``dronewpt sweep --status DIR`` (done, failed, pending), without a lock.

A sweep writes ``DIR/sweep.json`` (the manifest) before it runs anything: the study's name, its
number of cases, the base fingerprint and the study's TOML document. The status re-creates the
study's case ids from it (lazily, ~1 s per 10^5 cases) and counts them in the store, so rows of
an earlier, different study in the same folder are not counted as this study's.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from ..files import atomic_output
from .store import CaseStore
from .study import Study, case_space, parse_study

__all__ = ["SweepStatus", "write_manifest", "read_manifest", "sweep_status", "MANIFEST", "check_same_study", "physics_code_hash"]

MANIFEST = "sweep.json"


@dataclass(frozen=True)
class SweepStatus:
    """Counts of a sweep folder: this study's cases ``ok`` / ``failed`` (stored as errors) /
    ``pending`` (not stored yet), and rows of other studies (``other``)."""

    study: str
    n_cases: int
    ok: int
    failed: int
    pending: int
    other: int

    def line(self) -> str:
        done = self.ok + self.failed
        pct = 100.0 * done / self.n_cases if self.n_cases else 100.0
        other = f", {self.other:,} rows of other studies" if self.other else ""
        return (f"study {self.study}: {self.n_cases:,} cases, {done:,} done ({pct:.1f} %): {self.ok:,} ok, "
                f"{self.failed:,} failed, {self.pending:,} pending{other}")


def physics_code_hash(replay: bool = False) -> str:
    """sha256 (16 hex digits) of the sources that compute a mission's numbers: :mod:`wpt_receiver` and
    :mod:`mission_sim.world` (link, devices, battery, the compiled loop), the mission's configuration and the
    policies' context built from it (:mod:`mission_sim.config`, :mod:`mission_sim.contract`), the policies
    (the :mod:`policies` package's sources and its shipped pre-trained models, ``policies/pretrained/*.zip``,
    ``*.json``, ``*.npz``; found with :func:`importlib.util.find_spec`, not imported, since ``mission_sim`` never
    imports ``policies``) and the case runner that turns a case's values into the mission it runs
    (:mod:`mission_sim.studies.mission_cases`); with ``replay`` also those that turn a log into a replay or a
    re-flight (:mod:`mission_sim.mavlink`, :mod:`mission_sim.plans`) and the replay runner that decides what a
    case gives them (:mod:`mission_sim.studies.replay_cases`: origin, options). A sweep folder records it, so a
    resume by another version of that code is refused instead of mixing old and new results."""
    import importlib.util

    from wpt_receiver.kernel_cache import dependency_hash
    import wpt_receiver
    pkg = Path(__file__).resolve().parents[1]
    roots = [Path(wpt_receiver.__file__).parent, pkg / "world"] + ([pkg / "mavlink", pkg / "plans"] if replay else [])
    spec = importlib.util.find_spec("policies")
    policies = Path(spec.origin).parent if spec is not None and spec.origin else None
    if policies is not None:
        roots.append(policies)
    files = sorted((f for root in roots for f in root.rglob("*.py")), key=lambda f: (f.parent.name, f.name))
    if policies is not None:   # the shipped models (~3.7 MB, a few ms to hash)
        files += sorted(f for ext in ("zip", "json", "npz") for f in (policies / "pretrained").glob(f"*.{ext}"))
    files += [pkg / "config.py", pkg / "contract.py", pkg / "studies" / "mission_cases.py"]
    files += [pkg / "studies" / "replay_cases.py"] if replay else []
    return dependency_hash(files)[:16]


def _manifest(study: Study, fingerprint: str, n_cases: int, inputs: dict | None = None) -> dict:
    """The manifest's content (the base mission is named by its fingerprint only; ``inputs``: the files the
    cases read, ``{"[replay] log": {"path": ..., "sha256": ...}, ...}``, recorded so a changed one is named)."""
    doc = json.loads(json.dumps(study.source, default=str))
    doc.get("study", {}).pop("base", None)  # the fingerprint stands for it; the path may not resolve later
    out = {"study": study.name, "n_cases": n_cases, "fingerprint": fingerprint, "doc": doc,
           "physics_code": physics_code_hash(study.replay is not None)}
    if inputs:
        out["inputs"] = inputs
    return out


def _changed_input(old: dict, new: dict) -> str | None:
    """The first input file whose content differs between two manifests, in words; None if none does (or the
    old manifest recorded none)."""
    for what, now in (new.get("inputs") or {}).items():
        was = (old.get("inputs") or {}).get(what)
        if was and was.get("sha256") != now.get("sha256"):
            moved = "" if was.get("path") == now.get("path") else f", then {was.get('path')!r}"
            return (f"{what} {now.get('path')!r} changed since it ran (sha256 {str(was.get('sha256'))[:12]}...{moved}, "
                    f"now {str(now.get('sha256'))[:12]}...)")
    return None


def check_same_study(out_dir, study: Study, fingerprint: str, n_cases: int, inputs: dict | None = None) -> None:
    """``ValueError`` (one line naming ``--out``) when ``out_dir`` already holds the manifest of another
    study (other parameters, another base mission, or a changed input file, which it names); the same study
    (a resume) and a new folder pass."""
    if not (Path(out_dir) / MANIFEST).is_file():
        return
    old, new = read_manifest(out_dir, "--out"), _manifest(study, fingerprint, n_cases, inputs)
    changed = _changed_input(old, new) if old.get("doc") == new["doc"] else None
    if changed and old.get("fingerprint") == new["fingerprint"]:   # a policy's model file (not in the fingerprint)
        raise ValueError(f"--out {str(out_dir)!r} holds this study's results over another file: {changed}; its rows "
                         "are the old model's and a case's id holds the policy's name, not the model, so a resume "
                         "would run nothing; valid: a new --out folder, or the file as it was to resume")
    if old.get("doc") == new["doc"] and old.get("fingerprint") == new["fingerprint"]:
        if old.get("physics_code") == new["physics_code"]:
            return
        raise ValueError(f"--out {str(out_dir)!r} holds this study's results computed by another version of "
                         f"dronewpt's physics code ({old.get('physics_code') or 'unrecorded'}, now "
                         f"{new['physics_code']}); valid: a new --out folder, or --force to resume it anyway "
                         "(old and new results then mix)")
    what = "another base mission" if old.get("doc") == new["doc"] else "other parameters"
    if changed:
        raise ValueError(f"--out {str(out_dir)!r} holds this study's results over another file: {changed}; valid: a "
                         "new --out folder, the file as it was to resume, or --force to add this study's cases to it "
                         "(its sweep.json then describes this study)")
    raise ValueError(f"--out {str(out_dir)!r} holds another study ({old.get('study')!r}, {old.get('n_cases')} "
                     f"cases, {what}); valid: a new --out folder, the same study to resume it, or --force to add "
                     "this study's cases to it (its sweep.json then describes this study)")


def write_manifest(out_dir, study: Study, fingerprint: str, n_cases: int, inputs: dict | None = None) -> Path:
    """Write ``out_dir/sweep.json`` atomically (:func:`_manifest`)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_output(out / MANIFEST, tmp_name=f".{MANIFEST}.{os.getpid()}.tmp") as tmp:
        tmp.write_text(json.dumps(_manifest(study, fingerprint, n_cases, inputs), indent=1))
    return out / MANIFEST


def read_manifest(out_dir, flag: str = "--status") -> dict:
    """The manifest of sweep folder ``out_dir``; errors name ``flag`` (the option that gave the folder)."""
    path = Path(out_dir) / MANIFEST
    if Path(out_dir).exists() and not Path(out_dir).is_dir():
        raise ValueError(f"{flag} {str(out_dir)!r} is a file; valid: the --out folder of a sweep")
    if not Path(out_dir).is_dir():
        raise FileNotFoundError(f"{flag} {str(out_dir)!r}: no such folder")
    if not path.is_file():
        raise FileNotFoundError(f"{flag} {str(out_dir)!r} is not a sweep folder (no {MANIFEST}); "
                                "valid: the --out folder of a sweep")
    try:
        man = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{str(path)!r} is not a valid sweep manifest ({exc})") from None
    # (valid JSON of another shape, {} or [] or a manifest cut to some keys, was a KeyError / TypeError traceback)
    what = "not a JSON object" if not isinstance(man, dict) else next(
        (_manifest_key_problem(man, key, types, kind) for key, types, kind in _MANIFEST_KEYS
         if not isinstance(man.get(key), types)), None)
    if what:
        raise ValueError(f"{str(path)!r} is not a valid sweep manifest ({what}); valid: the sweep.json a dronewpt "
                         "sweep wrote")
    return man


#: the keys every reader of a manifest takes, their types and how a message names them
_MANIFEST_KEYS = (("study", str, "a string, the study's name"), ("fingerprint", str, "a string, the base mission's "
                                                                                         "fingerprint"),
                  ("doc", dict, "a JSON object, the study"))


def _manifest_key_problem(man: dict, key: str, types, kind: str) -> str:
    """What is wrong with manifest key ``key``: missing, or its value (as JSON spells it) and what is valid."""
    if key not in man:
        return f"no {key!r} ({kind})"
    text = json.dumps(man[key])   # (cut as a .plan's JSON values are: a 20,000-item list was a 129 kB line)
    return f"{key!r} = {text if len(text) <= 80 else text[:60] + '...'} is invalid; valid: {kind}"


def sweep_status(out_dir) -> SweepStatus:
    """Counts of the study recorded in ``out_dir/sweep.json`` against the rows stored in ``out_dir``."""
    man = read_manifest(out_dir)
    try:
        study = parse_study(man["doc"], name=man["study"])
    except ValueError as exc:   # (a damaged manifest's study: "varies nothing ... add parameters" named no folder)
        raise ValueError(f"{str(Path(out_dir) / MANIFEST)!r} is not a valid sweep manifest (its study: {exc}); valid: "
                         "the sweep.json a dronewpt sweep wrote") from None
    state = CaseStore(out_dir).state()
    ok = failed = n = 0
    for case in case_space(study, man["fingerprint"]):
        n += 1
        if case.case_id in state.errors:
            failed += 1
        elif case.case_id in state.done:
            ok += 1
    return SweepStatus(study=man["study"], n_cases=n, ok=ok, failed=failed, pending=n - ok - failed,
                       other=state.n_done - ok - failed)
