"""Sweep store and serial engine: atomic parts, exactly-once rows, resume, error capture (no Dask)."""

import pathlib

import pandas as pd
import pyarrow.parquet as pq
import pytest
from sweep_toy import toy_case

from mission_sim.studies.study import Case, case_id
from mission_sim.studies.sweep import CaseStore, run_case_safe, run_sweep


def cases_for(hovers, fail=()):
    out = []
    for h in hovers:
        p = {"policy": "step", "mission.hover_time_s": h, "fail": h in fail}
        out.append(Case(case_id(p), p))
    return out


def raw_ids(out_dir):
    """case_ids in every Parquet file on disk (no reader-side filtering or deduplication)."""
    files = sorted((pathlib.Path(out_dir) / "cases").glob("*.parquet"))
    return [cid for f in files for cid in pq.read_table(f, columns=["case_id"]).column("case_id").to_pylist()]


class Counting:
    def __init__(self):
        self.calls = []

    def __call__(self, params):
        self.calls.append(params["mission.hover_time_s"])
        return toy_case(params)


def test_serial_sweep_rows_are_the_runner_results_and_resume_skips(tmp_path):
    cases = cases_for([5.0, 10.0, 20.0])
    run = Counting()
    res = run_sweep(cases, run, tmp_path, progress=False)
    assert (res.n_cases, res.n_skipped, res.n_run, res.n_ok, res.n_error) == (3, 0, 3, 3, 0)
    df = res.results.set_index("case_id")
    for c in cases:  # each row carries its parameters and exactly the runner's metrics
        row = df.loc[c.case_id]
        assert row["mission.hover_time_s"] == c.params["mission.hover_time_s"] and row["policy"] == "step"
        assert row["flight_time_gain_s"] == toy_case(c.params)["flight_time_gain_s"]
    # resume with two more cases: only the new ones run; every case on disk exactly once
    more = cases + cases_for([40.0, 80.0])
    res2 = run_sweep(more, run, tmp_path, progress=False)
    assert (res2.n_skipped, res2.n_run) == (3, 2)
    assert run.calls == [5.0, 10.0, 20.0, 40.0, 80.0]
    ids = raw_ids(tmp_path)
    assert sorted(ids) == sorted(c.case_id for c in more)
    assert len(list((tmp_path / "cases").glob("*.parquet"))) == 1  # compacted
    # a third run does nothing
    res3 = run_sweep(more, run, tmp_path, progress=False)
    assert res3.n_run == 0 and len(run.calls) == 5


def test_failing_case_is_stored_with_its_error_and_the_others_complete(tmp_path):
    cases = cases_for([5.0, 10.0, 20.0], fail={10.0})
    res = run_sweep(cases, toy_case, tmp_path, progress=False)
    assert (res.n_ok, res.n_error) == (2, 1)
    bad = res.results[res.results["status"] == "error"].iloc[0]
    assert bad["mission.hover_time_s"] == 10.0
    assert bad["error"].startswith("ValueError: fail=True") and "Traceback" in bad["traceback"]
    assert pd.isna(bad["flight_time_gain_s"])
    ok = res.results[res.results["status"] == "ok"]
    assert ok["flight_time_gain_s"].notna().all() and ok["error"].isna().all()
    # the failed case counts as done: a rerun does not retry it
    assert run_sweep(cases, toy_case, tmp_path, progress=False).n_run == 0


def test_runner_returning_a_non_dict_is_an_error_row():
    r = run_case_safe(lambda p: [1, 2], "x", {})
    assert r["status"] == "error" and "TypeError" in r["error"] and "dict" in r["error"]


def test_kill_during_compaction_or_write_never_duplicates(tmp_path, monkeypatch):
    store = CaseStore(tmp_path)
    rows = [{"case_id": f"c{i}", "status": "ok", "v": float(i)} for i in range(6)]
    store.write(rows[:2])
    store.write(rows[2:4])
    # a writer killed mid-write leaves only a temporary, which no reader counts
    (store.dir / ".part-x.parquet.1.tmp").write_bytes(b"PAR1 half a file")
    assert sorted(store.done_ids()) == ["c0", "c1", "c2", "c3"]
    real_unlink = pathlib.Path.unlink

    def killed(self, missing_ok=False):
        if self.suffix == ".parquet":
            raise KeyboardInterrupt("killed between writing the compact file and deleting the parts")
        real_unlink(self, missing_ok=missing_ok)

    monkeypatch.setattr(pathlib.Path, "unlink", killed)
    with pytest.raises(KeyboardInterrupt):
        store.compact()
    monkeypatch.undo()
    assert len(raw_ids(tmp_path)) == 8  # 2 parts + a compact file holding their 4 rows ...
    assert sorted(store.done_ids()) == ["c0", "c1", "c2", "c3"]  # ... but the parts are absorbed
    assert list(store.read()["case_id"]) == ["c0", "c1", "c2", "c3"]
    store.write(rows[4:])
    # second compaction killed too: it absorbs the first compact file and the still-present parts
    monkeypatch.setattr(pathlib.Path, "unlink", killed)
    with pytest.raises(KeyboardInterrupt):
        store.compact()
    monkeypatch.undo()
    assert sorted(store.done_ids()) == [f"c{i}" for i in range(6)]
    store.compact()
    assert sorted(raw_ids(tmp_path)) == [f"c{i}" for i in range(6)]
    assert [p.name for p in store.dir.iterdir()][0].startswith("compact-") and len(list(store.dir.iterdir())) == 1
    assert list(store.read().sort_values("case_id")["v"]) == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]


def test_one_writer_at_a_time(tmp_path):
    cases = cases_for([5.0])
    with CaseStore(tmp_path).lock():
        with pytest.raises(ValueError, match="another sweep is writing"):
            run_sweep(cases, toy_case, tmp_path, progress=False)
    assert run_sweep(cases, toy_case, tmp_path, progress=False).n_run == 1


def test_cli_serial_json_summary_plots_and_exit_status(tmp_path, capsys):
    import json

    from mission_sim.cli import main

    study = tmp_path / "s.toml"
    study.write_text('[study]\nname = "toy"\nrunner = "sweep_toy:factory"\n'
                     '[grid]\n"mission.hover_time_s" = [5.0, 10.0]\n"pads.1.x_m" = [0.0, 50.0]\n'
                     'policy = ["step", "model_based"]\nfail = [false, true]\n')
    rc = main(["sweep", str(study), "--out", str(tmp_path / "o"), "--workers", "0", "--format", "json"])
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert rc == 1 and "8 of 16 cases failed" in cap.err.strip().splitlines()[-1]
    assert (out["cases"], out["run"], out["ok"], out["errors"]) == (16, 16, 8, 8)
    assert len(out["failed"]) == 8 and all("meant to fail" in f["error"] for f in out["failed"])
    rows = {r["group"]: r for r in out["summary"]}
    assert set(rows) == {"all", "step", "model_based"}
    assert rows["step"]["cases"] == 8 and rows["step"]["errors"] == 4
    # closed forms of the toy runner: gain = hover * 8 / (1 + spacing / 50), peak by policy (+-0.01 noise)
    assert abs(rows["step"]["peak_i2_a mean"] - 50.5) < 0.05
    assert abs(rows["model_based"]["peak_i2_a mean"] - 11.44) < 0.05
    assert abs(rows["all"]["flight_time_gain_s max"] - 80.0) < 0.05
    names = sorted(pathlib.Path(f).name for f in out["figures"])
    assert names == ["peak_i2_by_policy.png", "tradeoff_flight_time_gain_s.png"]
    assert all(pathlib.Path(f).stat().st_size > 10_000 for f in out["figures"])
    # the same command again: nothing to run, same outcome
    rc = main(["sweep", str(study), "--out", str(tmp_path / "o"), "--workers", "0", "--format", "json", "--no-plot"])
    again = json.loads(capsys.readouterr().out)
    assert rc == 1 and (again["skipped"], again["run"]) == (16, 0)


def test_a_resume_by_other_physics_code_is_refused(tmp_path):
    """A sweep folder records the hash of the physics sources; resuming the same study with another version of
    that code (or from a folder written before the hash was recorded) is refused with one line, since old and
    new rows would mix; the same code resumes."""
    import json as _json

    from mission_sim.studies.status import MANIFEST, check_same_study, physics_code_hash, write_manifest
    from mission_sim.studies.study import load_study
    st = load_study(pathlib.Path(__file__).resolve().parents[1] / "examples" / "study_small.toml")
    write_manifest(tmp_path, st, "f" * 16, 4)
    check_same_study(tmp_path, st, "f" * 16, 4)   # the same study and code: a resume
    man = _json.loads((tmp_path / MANIFEST).read_text())
    assert man["physics_code"] == physics_code_hash() and len(man["physics_code"]) == 16
    for old in ("0" * 16, None):
        if old is None:
            del man["physics_code"]
        else:
            man["physics_code"] = old
        (tmp_path / MANIFEST).write_text(_json.dumps(man))
        with pytest.raises(ValueError, match="another version of dronewpt's physics code") as e:
            check_same_study(tmp_path, st, "f" * 16, 4)
        assert "\n" not in str(e.value) and "--force" in str(e.value)


@pytest.mark.parametrize("replay", [False, True])
def test_an_edit_of_the_mission_case_runner_changes_the_physics_code_hash(monkeypatch, replay):
    """``studies/mission_cases.py`` turns a case's values into the mission it runs (and the replay case runner
    is one of its runners): an edit of it changes the physics-code hash of mission and replay studies alike, so a
    resume by another version of it is refused instead of mixing stale rows with new ones. The edit is seen
    through the real ``dependency_hash`` (the file's bytes as read, one comment line added)."""
    from mission_sim.studies import mission_cases
    _assert_an_edit_changes_the_hash(monkeypatch, pathlib.Path(mission_cases.__file__).resolve(), replay)


def _assert_an_edit_changes_the_hash(monkeypatch, target, replay):
    """The physics-code hash with ``target``'s bytes as read plus one comment line differs from the hash before, and
    is the same again once the edit is undone (the real ``dependency_hash`` reads the files)."""
    from mission_sim.studies.status import physics_code_hash
    before = physics_code_hash(replay)
    read_bytes = pathlib.Path.read_bytes

    def edited(self):
        data = read_bytes(self)
        return data + b"# edited\n" if pathlib.Path(self).resolve() == target else data

    monkeypatch.setattr(pathlib.Path, "read_bytes", edited)
    after = physics_code_hash(replay)
    assert len(after) == 16 and after != before
    monkeypatch.undo()
    assert physics_code_hash(replay) == before


@pytest.mark.parametrize("source", ["mission_sim/config.py", "mission_sim/contract.py", "policies/mpc_modal.py",
                                    "policies/pretrained/rl_s0.zip"])
@pytest.mark.parametrize("replay", [False, True])
def test_an_edit_of_the_config_or_a_policy_changes_the_physics_code_hash(monkeypatch, source, replay):
    """A mission's numbers also depend on its configuration and the policies' context built from it
    (``mission_sim/config.py``, ``contract.py``) and on the policy that flies it (the ``policies`` package and its
    shipped models): an edit of one changes the physics-code hash, so a sweep resumed after, e.g., a change of the
    MPC is refused instead of mixing old and new rows. The hash finds ``policies`` without importing it."""
    import sys

    from mission_sim.studies.status import physics_code_hash
    root = pathlib.Path(__file__).resolve().parents[1]
    target = (root / source).resolve()
    assert target.is_file()
    _assert_an_edit_changes_the_hash(monkeypatch, target, replay)
    if "policies" not in sys.modules:   # this test process may have imported it elsewhere; if not, still not
        physics_code_hash(replay)
        assert "policies" not in sys.modules
