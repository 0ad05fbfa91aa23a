"""A study made ready to run, refused early if it is too large or any case's values are bad.

:func:`prepare_study` is everything that happens before a cluster starts: the size check (from the
axis lengths: a 10^8-case study is refused at once), the case runner (the mission runner or the
study's own ``[study] runner``), the lazy case space, the keys check and the check of every case's
values (:func:`check_cases`: all bad values reported in one error, with the case ids).
"""

from __future__ import annotations

import hashlib
import importlib
from pathlib import Path
from collections.abc import Callable, Iterable

from .study import DEFAULT_MAX_CASES, POLICY_KEY, CaseSpace, Study, case_id, case_space, check_size

__all__ = ["prepare_study", "check_cases", "warn_study", "import_factory", "policy_files", "MAX_LISTED_ERRORS"]

MAX_LISTED_ERRORS = 20  # distinct errors named in the message (the count of the others follows)
_IDS_PER_ERROR = 3


def import_factory(spec: str):
    """The object at ``"package.module:attr"``; ``ValueError`` naming the spec if it cannot be imported."""
    mod, _, attr = spec.partition(":")
    try:
        obj = importlib.import_module(mod)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"[study] runner = {spec!r} cannot be imported ({exc})") from None
    return obj


def _runner(study: Study, make_policy: Callable | None, policy_names):
    """(case runner, base fingerprint) of a study: its own ``[study] runner``, the replay runner of a
    ``[replay]`` study (:mod:`.replay_cases`), else the mission runner."""
    if study.runner:
        runner = import_factory(study.runner)(study)
        base_text = study.base_path.read_text() if study.base_path else ""
        return runner, hashlib.sha256(f"{study.runner}\n{base_text}".encode()).hexdigest()[:16]
    if make_policy is None:
        raise ValueError("the mission and replay runners need a policy factory (make_policy=policies.make)")
    if study.replay is not None:
        from .replay_cases import replay_runner
        return replay_runner(study, make_policy, policy_names)
    from ..config import check_file_route_keys, config_from_dict, config_to_dict, load_config_dict
    from .mission_cases import MissionCaseRunner

    d, file_keys = load_config_dict(study.base_path, file_keys=True)
    base = config_to_dict(config_from_dict(d))
    check_file_route_keys(study.base_path, base, file_keys)   # (the cases fly its route: its own pattern keys change
    # nothing)
    from .worst_cases import base_fingerprint
    runner = MissionCaseRunner(base, make_policy, policy_names)
    return runner, base_fingerprint(base)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def policy_files(study: Study) -> dict:
    """The model files the study's policies read (``rl:PATH``, ``residual:PATH``, ...: a spec whose part after ':'
    names a file, and that file's metadata ``.json`` beside it), as ``{"policy rl:PATH": {"path", "sha256"}, ...}``
    for the sweep's manifest: a case's id holds the spec, not the model, so a model retrained into the same path
    would otherwise resume on the old model's rows (:func:`~mission_sim.studies.status.check_same_study` names it)."""
    specs = []
    if POLICY_KEY in study.fixed:
        specs.append(study.fixed[POLICY_KEY])
    specs += list(study.grid.get(POLICY_KEY, ()))
    if POLICY_KEY in study.mc_params:
        specs += list(study.mc_params[POLICY_KEY][1])
    out = {}
    for spec in dict.fromkeys(s for s in specs if isinstance(s, str)):
        _, colon, arg = spec.partition(":")
        path = Path(arg) if colon and arg and not _is_number(arg) else None   # (mpc:0.05: a budget, not a file)
        if path is None or not path.is_file():
            continue
        for what, f in ((f"policy {spec}", path), (f"policy {spec} metadata", path.with_suffix(".json"))):
            if f.is_file():
                out[what] = {"path": str(f), "sha256": hashlib.sha256(f.read_bytes()).hexdigest()}
    return out


def _error_message(space: CaseSpace, errors: dict, n_bad: int) -> str:
    parts = []
    for msg, (count, ids) in list(errors.items())[:MAX_LISTED_ERRORS]:
        more = ", ..." if count > len(ids) else ""
        parts.append(f"{msg} [{count:,} case{'s' if count > 1 else ''}: {', '.join(ids)}{more}]")
    rest = len(errors) - MAX_LISTED_ERRORS
    tail = f"; and {rest:,} more distinct errors" if rest > 0 else ""
    return (f"{n_bad:,} of {len(space):,} cases of study {space.study.name!r} have invalid values, nothing was "
            f"run: " + "; ".join(parts) + tail)


def check_cases(space: CaseSpace, runner, progress: bool = False) -> int:
    """Check every case's values with ``runner.check_params(params) -> None | message`` (if the runner
    has it) before anything runs; one ``ValueError`` listing every distinct error with its number of
    cases and their first case ids. Returns the number of cases checked."""
    from tqdm.auto import tqdm

    check = getattr(runner, "check_params", None)
    if check is None:
        return 0
    errors: dict[str, list] = {}
    n = n_bad = 0
    for params in tqdm(space.params(), total=len(space), desc="check", unit="case", disable=not progress,
                       leave=False, mininterval=0.5, dynamic_ncols=True):
        n += 1
        msg = check(params)
        if msg is None:
            continue
        n_bad += 1
        entry = errors.setdefault(msg, [0, []])
        entry[0] += 1
        if len(entry[1]) < _IDS_PER_ERROR:
            entry[1].append(case_id(params, space.fingerprint))
    if errors:
        raise ValueError(_error_message(space, errors, n_bad))
    return n


def prepare_study(study: Study, make_policy: Callable | None = None, policy_names: Iterable[str] | None = None,
                  *, max_cases: int = DEFAULT_MAX_CASES, check_values: bool = True, progress: bool = False,
                  warn: bool = True):
    """``(runner, cases, fingerprint)`` of a study, checked before anything runs.

    The size is checked first (``max_cases``, from the axis lengths alone). The mission runner needs
    ``make_policy`` (and ``policy_names`` to check the policies), so does the replay runner of a study
    with a ``[replay]`` section (:mod:`.replay_cases`); a study with ``[study] runner =
    "mod:factory"`` uses ``factory(study)`` (any picklable ``run_case``, optionally with
    ``validate_keys`` and ``check_params`` hooks). ``cases`` is the lazy
    :class:`~mission_sim.studies.study.CaseSpace`. Unknown keys, unknown policies and bad values
    raise ``ValueError`` naming them (bad values: all at once, see :func:`check_cases`). The checked cases' setup
    warnings are warned once for the study (:func:`warn_study`) unless ``warn=False`` (``dronewpt sweep`` warns them
    after its own checks of ``--out`` and of a resume, which may refuse the run).
    """
    check_size(study, max_cases)
    runner, fingerprint = _runner(study, make_policy, policy_names)
    models = policy_files(study) if not study.runner else {}
    if models:   # recorded in sweep.json with a replay study's log and pads (dronewpt sweep reads input_files)
        runner.input_files = {**(getattr(runner, "input_files", None) or {}), **models}
    cases = case_space(study, fingerprint)
    validate = getattr(runner, "validate_keys", None)
    if validate is not None and len(cases):
        validate(study.override_keys, next(iter(cases.params())))
    if policy_names is not None and getattr(runner, "check_params", None) is None:
        valid = set(policy_names)
        bad = sorted({str(p.get(POLICY_KEY)) for p in cases.params()} - valid)
        if bad:
            raise ValueError(f"policy={bad[0]!r} is invalid; valid values: {', '.join(sorted(valid))}")
    if check_values:
        check_cases(cases, runner, progress=progress)
        if warn:
            warn_study(study, runner)
    return runner, cases, fingerprint


def warn_study(study: Study, runner) -> None:
    """The runner's setup warnings of the checked cases (``study_warnings(name)``, if it has it), once per study
    as :class:`~wpt_receiver.notices.DronewptWarning` (the cases themselves run without warnings)."""
    notes = getattr(runner, "study_warnings", None)
    if notes is None:
        return
    from wpt_receiver.notices import warn
    for text in notes(study.name):
        warn(text)
