"""Sweeps on a real local Dask cluster (two worker processes): equal to serial, kill-and-resume,
failing cases, CLI errors. The engine tests use the cheap closed-form runner of ``sweep_toy``."""

import json
import os
import pathlib
import signal
import subprocess
import sys
import time
from collections import Counter

import pandas as pd
import pyarrow.parquet as pq
import pytest
from sweep_toy import ToyRunner, toy_case

import policies

from mission_sim.cli import main
from mission_sim.studies.study import case_space as case_space_of
from mission_sim.studies.study import expand_cases, load_study
from mission_sim.studies.sweep import CaseStore, dask_client, prepare_study, read_results, run_sweep

ROOT = pathlib.Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
VOLATILE = ["case_wall_s", "case_cpu_s", "worker", "traceback", "worker_pid", "wall_s"]


def env():
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(TESTS), e.get("PYTHONPATH", "")])
    return e


def write_study(path, text):
    path.write_text(text)
    return path


def stable(df):
    """Rows sorted by case, without the columns that legitimately differ between runs (timing, pids)."""
    return df.drop(columns=[c for c in VOLATILE if c in df.columns]).sort_values("case_id").reset_index(drop=True)


def raw_case_ids(out_dir):
    files = sorted((pathlib.Path(out_dir) / "cases").glob("*.parquet"))
    return [cid for f in files for cid in pq.read_table(f, columns=["case_id"]).column("case_id").to_pylist()]


@pytest.fixture(scope="module")
def client():
    with dask_client(workers=2) as c:
        yield c


def test_workers_are_two_processes_importing_this_checkout(client):
    files = client.run(lambda: __import__("mission_sim").__file__)
    pids = client.run(os.getpid)
    assert len(files) == 2 and len(set(pids.values())) == 2 and os.getpid() not in pids.values()
    assert all(pathlib.Path(f).resolve().is_relative_to(ROOT) for f in files.values()), files


TOY = """
[study]
name = "toy"
runner = "sweep_toy:factory"
[fixed]
delay_s = 0.01
[grid]
"mission.hover_time_s" = [5.0, 10.0, 20.0]
"pads.1.x_m" = [20.0, 60.0]
fail = [false, true]
policy = ["step", "model_based"]
[monte_carlo]
n = 2
seed = 11
[monte_carlo.params]
seed = {integers = [0, 1000]}
"""


def test_dask_equals_serial_and_failing_cases_are_reported(client, tmp_path):
    st = load_study(write_study(tmp_path / "toy.toml", TOY))
    cases = expand_cases(st)
    dask_res = run_sweep(cases, ToyRunner(), tmp_path / "dask", client=client, progress=False)
    serial_res = run_sweep(cases, ToyRunner(), tmp_path / "serial", client=None, progress=False)
    assert dask_res.n_cases == serial_res.n_cases == 48
    pd.testing.assert_frame_equal(stable(dask_res.results), stable(serial_res.results), check_exact=True)
    # both workers did work
    assert dask_res.results["worker"].nunique() == 2
    # the failing half is recorded with its error; the other half completed with the closed-form results
    df = dask_res.results
    failed, ok = df[df["fail"]], df[~df["fail"]]
    assert (failed["status"] == "error").all() and len(failed) == 24
    assert failed["error"].str.startswith("ValueError: fail=True: this case is meant to fail").all()
    assert (ok["status"] == "ok").all() and len(ok) == 24
    for _, row in ok.iterrows():
        params = {k: row[k] for k in ("mission.hover_time_s", "pads.1.x_m", "policy", "seed")}
        assert row["flight_time_gain_s"] == toy_case(params)["flight_time_gain_s"]
    assert Counter(raw_case_ids(tmp_path / "dask")) == Counter({c.case_id: 1 for c in cases})


KILL = """
[study]
name = "kill"
runner = "sweep_toy:factory"
[fixed]
delay_s = 0.1
[grid]
"mission.hover_time_s" = [5.0, 10.0, 20.0, 40.0, 80.0]
"pads.1.x_m" = [20.0, 40.0, 60.0, 80.0]
policy = ["step", "model_based"]
seed = [1, 2, 3]
"""


N_KILL = 120  # 6 s of work on two workers: parts come every 2 s, so both kills land mid-run


def _run_until(cmd, out_dir, n_done, sig):
    """Start the sweep CLI, wait until ``n_done`` cases are stored, send ``sig``; return (rc, n stored)."""
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    store = CaseStore(out_dir)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            if len(store.done_ids()) >= n_done:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "sweep finished before it could be killed: " + proc.stderr.read().decode()
        proc.send_signal(sig)
        rc = proc.wait(timeout=30)
        # the worker processes end with the sweep process (they watch their parent), even after SIGKILL
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and _group_alive(proc.pid):
            time.sleep(0.1)
        assert not _group_alive(proc.pid), "worker processes outlived the killed sweep"
    finally:
        if proc.poll() is None:
            proc.kill()
        if _group_alive(proc.pid):  # only on failure: end what this test started
            os.killpg(proc.pid, signal.SIGKILL)
    return rc, len(store.done_ids()), proc.stderr.read().decode()


def _group_alive(pgid):
    try:
        os.killpg(pgid, 0)
        return True
    except ProcessLookupError:
        return False


def test_kill_and_resume_every_case_exactly_once_and_equal_to_serial(tmp_path):
    study_path = write_study(tmp_path / "kill.toml", KILL)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "mission_sim.cli", "sweep", str(study_path), "--out", str(out),
           "--workers", "2", "--no-plot", "--no-progress", "--format", "json"]
    cases = prepare_study(load_study(study_path))[1]  # the case ids the CLI uses
    assert len(cases) == N_KILL

    t0 = time.monotonic()
    rc, n1, err = _run_until(cmd, out, 6, signal.SIGTERM)  # polite: pending cancelled, cluster closed
    assert rc == 143 and err.strip() == "dronewpt sweep: interrupted (SIGTERM)" and 6 <= n1 < N_KILL
    print(f"SIGTERM run {time.monotonic() - t0:.1f} s")
    rc, n2, _ = _run_until(cmd, out, n1 + 6, signal.SIGKILL)  # brutal: no cleanup at all
    print(f"SIGKILL run {time.monotonic() - t0:.1f} s")
    assert rc == -signal.SIGKILL and n1 + 6 <= n2 < N_KILL
    done = subprocess.run(cmd, cwd=ROOT, env=env(), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == "", done.stderr  # no Dask tracebacks on a normal run
    print(f"final run {time.monotonic() - t0:.1f} s")
    summary = json.loads(done.stdout)
    assert summary["skipped"] == n2 and summary["run"] == N_KILL - n2 and summary["ok"] == N_KILL

    # every case exactly once, counting rows in the Parquet files themselves
    assert Counter(raw_case_ids(out)) == Counter({c.case_id: 1 for c in cases})
    serial = run_sweep(cases, lambda p: toy_case({**p, "delay_s": 0.0}), tmp_path / "serial", progress=False)
    pd.testing.assert_frame_equal(stable(read_results(out)), stable(serial.results), check_exact=True)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_during_cluster_start_is_one_line_and_the_workers_end(tmp_path, sig):
    """SIGINT to the whole process group (a terminal's Ctrl-C), or SIGTERM to the sweep process (``kill``),
    just after the manifest is written, that is while the local cluster starts: one line naming the
    signal, its exit status (130 / 143), no traceback (Dask's ``Status.init`` assertion, the forkserver's
    ``SemLock`` FileNotFoundError), nothing left running."""
    study_path = write_study(tmp_path / "kill.toml", KILL)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "mission_sim.cli", "sweep", str(study_path), "--out", str(out), "--workers", "2",
           "--no-plot", "--no-progress"]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while not (out / "sweep.json").exists() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.01)
        time.sleep(0.3)  # workers being spawned
        t0 = time.monotonic()
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        rc = proc.wait(timeout=60)
        print(f"exit {time.monotonic() - t0:.2f} s after {sig.name}")
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and _group_alive(proc.pid):
            time.sleep(0.1)
        assert not _group_alive(proc.pid)
    finally:
        if _group_alive(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
    err = proc.stderr.read().decode()
    assert rc == 128 + sig and err == f"dronewpt sweep: interrupted ({sig.name})\n", err
    assert not (out / ".sweep.lock").exists() and not [p for p in out.rglob(".*") if p.name.endswith(".tmp")]


def test_futures_are_released_once_stored(client, tmp_path):
    st = load_study(write_study(tmp_path / "toy.toml", TOY.replace("delay_s = 0.01", "delay_s = 0.0")))
    res = run_sweep(case_space_of(st), ToyRunner(), tmp_path / "o", client=client, progress=False, max_in_flight=2)
    assert res.n_ok + res.n_error == 48
    assert not client.futures  # nothing held by this client ...
    deadline = time.monotonic() + 10  # the scheduler handles the releases asynchronously
    while client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) == 0  # nor kept there


def test_cli_runs_on_an_existing_cluster_given_its_scheduler_address(client, tmp_path, capsys):
    study_path = write_study(tmp_path / "s.toml", '[study]\nrunner = "sweep_toy:factory"\n'
                                                  '[grid]\n"mission.hover_time_s" = [1.0, 2.0, 3.0, 4.0]\n')
    rc = main(["sweep", str(study_path), "--out", str(tmp_path / "o"), "--scheduler", client.scheduler.address,
               "--no-plot", "--no-progress", "--format", "json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and (out["run"], out["ok"]) == (4, 4)
    pids = set(client.run(os.getpid).values())
    assert set(read_results(tmp_path / "o")["worker_pid"]) <= pids  # ran on that cluster's workers


def test_cli_bad_scheduler_is_one_line_error(tmp_path, capsys):
    study_path = write_study(tmp_path / "s.toml", '[study]\nrunner = "sweep_toy:factory"\n[grid]\nseed = [1, 2]\n')
    for addr in ("tcp://127.0.0.1:9", "not an address"):
        rc = main(["sweep", str(study_path), "--out", str(tmp_path / "o"), "--scheduler", addr,
                   "--connect-timeout", "1"])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and addr in err[0] and "scheduler" in err[0], err
    assert not (tmp_path / "o").exists()


def test_cli_unknown_parameter_key_is_one_line_error_naming_valid_keys(tmp_path, capsys):
    study_path = write_study(tmp_path / "s.toml", '[study]\nrunner = "sweep_toy:factory"\n'
                                                  '[grid]\n"mission.hover_tme_s" = [1, 2]\n')
    rc = main(["sweep", str(study_path), "--out", str(tmp_path / "o"), "--workers", "0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "mission.hover_tme_s" in err[0] and "mission.hover_time_s" in err[0]
    assert not (tmp_path / "o").exists()


TINY = """
[study]
name = "tiny"
[fixed]
"pads.0.hover_time_s" = 2.0
"pads.1.y_m" = 0.0
"pads.1.x_m" = 20.0
"mission.land_x_m" = 25.0
[grid]
policy = ["step", "model_based"]
"pads.1.hover_time_s" = [2.0, 8.0, -1.0]
"""


def test_real_missions_on_two_workers_equal_serial_with_physics_orderings(client, tmp_path):
    (tmp_path / "tiny.toml").write_text(TINY)
    st = load_study(tmp_path / "tiny.toml")
    with pytest.raises(ValueError, match=r"^2 of 6 cases .*pads\.1\.hover_time_s=-1\.0 .*\[2 cases: \w{16}, \w{16}\]$"):
        prepare_study(st, policies.make, policies.available())  # refused before anything runs ...
    # ... and, unchecked, the same values fail on the workers (recorded as error rows)
    runner, cases, _ = prepare_study(st, policies.make, policies.available(), check_values=False)
    assert len(cases) == 6
    res = run_sweep(cases, runner, tmp_path / "dask", client=client, progress=False)
    serial = run_sweep(cases, runner, tmp_path / "serial", progress=False)

    def stable_mission(df):
        drop = [c for c in df.columns if "wall" in c or c in ("case_cpu_s", "worker", "traceback", "realtime_factor")]
        return df.drop(columns=drop).sort_values("case_id").reset_index(drop=True)

    pd.testing.assert_frame_equal(stable_mission(res.results), stable_mission(serial.results), check_exact=True)
    df = res.results
    # the two cases with a negative hover time fail in config validation, naming the value
    bad = df[df["pads.1.hover_time_s"] < 0]
    assert (bad["status"] == "error").all() and len(bad) == 2
    assert bad["error"].str.contains("hover_time_s=-1.0").all()
    ok = df[df["status"] == "ok"]
    assert len(ok) == 4 and res.n_error == 2
    # every mission closes its energy balance; longer hover-charging gains more flight time;
    # the step policy overshoots the secondary current, the model-based one stays below rated
    assert (ok["energy_balance_error_rel"].abs() < 1e-9).all()
    for pol, d in ok.groupby("policy"):
        g = d.set_index("pads.1.hover_time_s")["flight_time_gain_s"]
        assert g[8.0] > g[2.0] > 0, pol
    peak = ok.groupby("policy")["peak_i2_a"].max()
    assert peak["step"] > 1.5 * peak["model_based"]
    assert peak["model_based"] < ok["rated_i2_a"].min()
