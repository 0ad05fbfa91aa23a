"""Sweeps at scale without Dask: studies refused before any work (size, bad values, empty grid),
--retry-errors, --status, the part writer's merges (files stay few, kills never duplicate)."""

import itertools
import json
import pathlib
import re
import time
from collections import Counter

import pyarrow.parquet as pq
import pytest
from sweep_toy import toy_case

from mission_sim.cli import main
from mission_sim.studies import store as store_mod
from mission_sim.studies.store import CaseStore, PartWriter
from mission_sim.studies.study import case_space, load_study
from mission_sim.studies.sweep import prepare_study, read_results, run_sweep, write_manifest


def raw_ids(out_dir):
    files = sorted((pathlib.Path(out_dir) / "cases").glob("*.parquet"))
    return [cid for f in files for cid in pq.read_table(f, columns=["case_id"]).column("case_id").to_pylist()]


def sweep(args, capsys):
    rc = main(["sweep", *map(str, args)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err.strip().splitlines()


@pytest.mark.parametrize("grid, size", [
    ('a = {linspace = [0.0, 1.0, 10000]}\nb = {linspace = [0.0, 1.0, 10000]}\n', "100,000,000"),
    ('"mission.hover_time_s" = {linspace = [0.0, 100.0, 100000000]}\n', "100,000,000"),
])
def test_a_10_8_case_study_is_refused_at_once_with_its_size(tmp_path, capsys, grid, size):
    study = tmp_path / "huge.toml"
    study.write_text("[grid]\n" + grid)  # the mission runner: the refusal comes before policies are imported
    t0 = time.perf_counter()
    rc, _, err = sweep([study, "--out", tmp_path / "o"], capsys)
    elapsed = time.perf_counter() - t0
    assert rc == 2 and len(err) == 1, err
    assert f"{size} cases" in err[0] and "--max-cases" in err[0] and "1,000,000" in err[0]
    assert elapsed < 5.0, elapsed  # the bound; a materialised 10^8 grid takes minutes or dies
    assert not (tmp_path / "o").exists()
    rc, _, err = sweep([study, "--out", tmp_path / "o", "--max-cases", "1000"], capsys)
    assert rc == 2 and "more than the limit of 1,000" in err[0]


def test_bad_values_are_all_reported_before_any_work_with_case_ids(tmp_path, capsys):
    import policies

    study = tmp_path / "bad.toml"
    study.write_text('[grid]\n"battery.capacity_ah" = [-1.0, "ten", 2.0]\npolicy = ["step", "bang_bang"]\n'
                     '"pads.1.hover_time_s" = [5.0, 10.0]\n')
    rc, _, err = sweep([study, "--out", tmp_path / "o"], capsys)
    assert rc == 2 and len(err) == 1, err
    msg = err[0]
    assert "10 of 12 cases" in msg and "nothing was run" in msg
    # every distinct error, with its number of cases: 2 capacities x 2 hovers x step, and 6 bang_bang cases
    assert "battery.capacity_ah=-1.0 is invalid" in msg and "battery.capacity_ah='ten' is invalid" in msg
    assert "policy='bang_bang' is invalid" in msg and "[6 cases: " in msg
    assert msg.count("[2 cases: ") == 2
    # the ids named are the ids of those cases
    st = load_study(study)
    _, space, _ = prepare_study(st, policies.make, policies.available(), check_values=False)
    by_id = {c.case_id: c.params for c in space}
    named = re.findall(r"\b[0-9a-f]{16}\b", msg)
    assert len(named) == 3 + 2 + 2 and set(named) <= set(by_id)
    assert all(by_id[i]["battery.capacity_ah"] != 2.0 or by_id[i]["policy"] == "bang_bang" for i in named)
    assert not (tmp_path / "o").exists()


def test_a_cross_field_limit_and_the_run_size_are_checked_per_case(tmp_path):
    import policies

    from mission_sim.studies.study import parse_study

    st = parse_study({"grid": {"pads.1.z_m": [0.0, 6.0], "sim.max_fine_s": [10.0, 1e9]}})
    with pytest.raises(ValueError) as err:
        prepare_study(st, policies.make, policies.available())
    msg = str(err.value)
    assert msg.startswith("3 of 4 cases")
    assert "mission.cruise_altitude_m=5.0 is invalid" in msg and "fly through the pad" in msg and "[2 cases" in msg
    assert "makes the run too large" in msg


def test_an_empty_grid_is_an_error_unless_allow_single(tmp_path, capsys):
    study = tmp_path / "one.toml"
    study.write_text('[study]\nrunner = "sweep_toy:factory"\n[grid]\n')
    rc, _, err = sweep([study, "--out", tmp_path / "o", "--workers", "0"], capsys)
    assert rc == 2 and "varies nothing" in err[0] and "allow_single" in err[0]
    study.write_text('[study]\nrunner = "sweep_toy:factory"\nallow_single = true\n[grid]\n')
    rc, out, err = sweep([study, "--out", tmp_path / "o", "--workers", "0", "--no-plot", "--format", "json"], capsys)
    assert rc == 0 and json.loads(out)["run"] == 1


RETRY = """
[study]
name = "retry"
runner = "sweep_toy:factory"
[grid]
"mission.hover_time_s" = [5.0, 10.0, 20.0, 40.0, 80.0]
"pads.1.x_m" = [20.0, 60.0]
fail = [false, true]
"""


def test_retry_errors_reruns_exactly_the_error_rows(tmp_path, capsys, monkeypatch):
    study = tmp_path / "retry.toml"
    study.write_text(RETRY)
    out = tmp_path / "o"
    args = [study, "--out", out, "--workers", "0", "--no-plot", "--format", "json"]
    monkeypatch.setenv("SWEEP_TOY_FAIL_ABOVE", "15")  # a flaky setup: hover > 15 s fails this time
    rc, text, _ = sweep(args, capsys)
    first = read_results(out).set_index("case_id")
    assert rc == 1 and json.loads(text)["errors"] == 10 + 3 * 2  # fail = true, and hover 20, 40, 80 s
    errors1 = set(first.index[first["status"] == "error"])
    assert errors1 == set(first.index[first["fail"] | (first["mission.hover_time_s"] > 15)])
    rc, text, _ = sweep(args, capsys)  # a plain re-run leaves the error rows alone
    assert json.loads(text)["run"] == 0
    monkeypatch.delenv("SWEEP_TOY_FAIL_ABOVE")
    rc, text, _ = sweep([*args, "--retry-errors"], capsys)
    summary = json.loads(text)
    assert summary["run"] == len(errors1) and summary["skipped"] == 20 - len(errors1)
    after = read_results(out).set_index("case_id")
    rerun = set(after.index[after["attempt"] == 2])
    assert rerun == errors1 and set(after.index[after["attempt"] == 1]) == set(first.index) - errors1
    # the ok rows were not touched (same run time to the bit); the flaky ones are ok now, fail=true ones still fail
    ok1 = first.index[first["status"] == "ok"]
    assert (after.loc[ok1, "case_wall_s"] == first.loc[ok1, "case_wall_s"]).all()
    assert set(after.index[after["status"] == "error"]) == set(after.index[after["fail"]])
    assert Counter(raw_ids(out)) == Counter({i: 1 for i in first.index})  # superseded rows merged away


def test_status_counts_done_failed_pending(tmp_path, capsys):
    study = tmp_path / "retry.toml"
    study.write_text(RETRY)
    st = load_study(study)
    runner, space, fp = prepare_study(st)
    out = tmp_path / "o"
    write_manifest(out, st, fp, len(space))
    run_sweep(list(itertools.islice(space, 8)), runner, out, progress=False)  # 8 of 20, 4 with fail = true
    rc, text, _ = sweep(["--status", out, "--format", "json"], capsys)
    assert rc == 0 and json.loads(text) == {"study": "retry", "n_cases": 20, "ok": 4, "failed": 4, "pending": 12,
                                            "other": 0}
    rc, text, _ = sweep(["--status", out], capsys)
    assert text.strip() == "study retry: 20 cases, 8 done (40.0 %): 4 ok, 4 failed, 12 pending"
    rc, _, err = sweep(["--status", tmp_path], capsys)
    assert rc == 2 and len(err) == 1 and "not a sweep folder" in err[0]


def rows(lo, hi):
    return [{"case_id": f"c{i:06d}", "status": "ok", "v": float(i)} for i in range(lo, hi)]


def test_part_writer_merges_keep_files_few_and_every_row_once(tmp_path):
    store = CaseStore(tmp_path)
    w = PartWriter(store, max_rows=10, max_age_s=1e9)
    for i in range(0, 1000, 5):
        w.add(rows(i, i + 5))
    w.flush()
    assert w.n_parts == 100
    # 100 parts of 10 rows: merged 8 at a time, a level up every 8 merges: far fewer files than parts
    assert len(store.files()) <= 2 * (store_mod.FANOUT - 1) + 1
    assert sorted(raw_ids(tmp_path)) == [f"c{i:06d}" for i in range(1000)]
    store.compact()
    assert len(store.files()) == 1 and len(raw_ids(tmp_path)) == 1000


def test_a_killed_merge_never_brings_absorbed_rows_back(tmp_path, monkeypatch):
    store = CaseStore(tmp_path)
    for i in range(0, 40, 5):
        store.write(rows(i, i + 5))
    real_unlink = pathlib.Path.unlink

    def killed(self, missing_ok=False):
        raise KeyboardInterrupt("killed after the merged file was written")

    monkeypatch.setattr(pathlib.Path, "unlink", killed)
    with pytest.raises(KeyboardInterrupt):
        store.merge_levels()  # the L1 file is written, its 8 parts are still there
    monkeypatch.setattr(pathlib.Path, "unlink", real_unlink)
    assert len(raw_ids(tmp_path)) == 80 and len(store.read()) == 40
    store.write(rows(40, 45))
    store.compact()  # the L1 file and the new part merged: the parts absorbed by L1 must stay absorbed
    assert sorted(store.read()["case_id"]) == [f"c{i:06d}" for i in range(45)]
    assert Counter(raw_ids(tmp_path)) == Counter({f"c{i:06d}": 1 for i in range(45)})


def test_serial_rows_equal_the_runner_and_ids_follow_the_case_space(tmp_path):
    study = tmp_path / "retry.toml"
    study.write_text(RETRY)
    runner, space, _ = prepare_study(load_study(study))
    res = run_sweep(space, runner, tmp_path / "o", progress=False, part_rows=3)
    assert (res.n_cases, res.n_ok, res.n_error) == (20, 10, 10)
    df = res.results.set_index("case_id")
    for c in case_space(load_study(study), space.fingerprint):
        if not c.params["fail"]:
            assert df.loc[c.case_id, "flight_time_gain_s"] == toy_case(c.params)["flight_time_gain_s"]
