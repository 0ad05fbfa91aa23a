"""Robustness for a newcomer (issue #16): the bad-input table of docs/robustness.md, run row by row
in-process, plus atomic outputs, the run-size estimate against real runs, and NaN actions in the envs."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mission_sim.cli import main

DOC = Path(__file__).resolve().parents[1] / "docs" / "robustness.md"
_ROW = re.compile(r"^\|\s*`(?P<cmd>[^`]+)`\s*\|\s*(?P<rc>\d+)\s*\|\s*`(?P<text>[^`]+)`\s*\|\s*$")


def _table_rows():
    """(command, exit status, expected text) of every row of the "Bad inputs tried" table."""
    text = DOC.read_text("utf-8")
    section = text.split("## Bad inputs tried", 1)[1]
    rows = [m.groups() for line in section.splitlines() if (m := _ROW.match(line))]
    return [(cmd, int(rc), expect) for cmd, rc, expect in rows]


ROWS = _table_rows()


def _run(argv) -> int:
    try:
        return int(main(argv))
    except SystemExit as exc:  # argparse usage errors and --version
        return int(exc.code or 0)


@pytest.fixture
def bad_inputs_dir(tmp_path, monkeypatch):
    """The folder the table's commands run in (see docs/robustness.md)."""
    (tmp_path / "binary.toml").write_bytes(bytes(range(256))[::-1] + b"\x00\xd0\xff" * 15)
    (tmp_path / "bad.toml").write_text("x = = 1\n")
    (tmp_path / "a_file").write_text("")
    (tmp_path / "a_folder").mkdir()
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_table_has_the_rows():
    assert len(ROWS) >= 50
    assert all(rc in (0, 2, 3) for _, rc, _ in ROWS)


@pytest.mark.parametrize("cmd,rc,expect", ROWS, ids=[r[0] for r in ROWS])
def test_bad_input_row(cmd, rc, expect, bad_inputs_dir, capsys):
    before = set(bad_inputs_dir.rglob("*"))
    got = _run(shlex.split(cmd))
    out, err = capsys.readouterr()
    assert got == rc, (out, err)
    if rc == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        assert expect in lines[0]
        assert lines[0].startswith("dronewpt")
        assert "Traceback" not in err
        # refused before anything was written; an output folder made before the refusal is removed again
        assert set(bad_inputs_dir.rglob("*")) - before == set()
    else:
        assert expect in out + err


# ----------------------------------------------------------------------------- atomic outputs
def _small_result():
    from mission_sim.world.results import MissionResult
    ts = pd.DataFrame({"t_s": np.arange(5.0), "soc": np.linspace(0.9, 0.8, 5), "phase": pd.Categorical(["charge"] * 5)})
    return MissionResult(timeseries=ts, summary={"final_soc": 0.8})


def test_interrupted_write_leaves_no_partial_file_and_no_stale_summary(tmp_path, monkeypatch):
    (tmp_path / "summary.json").write_text('{"stale": true}')
    (tmp_path / "timeseries.csv").write_text("old,complete\n1,2\n")

    def interrupted(self, path, *a, **k):
        if hasattr(path, "write"):  # the CSV is written in row chunks to an open file
            path.write("t_s,so")
        else:
            Path(path).write_text("t_s,so")  # half a line, then Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(pd.DataFrame, "to_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _small_result().write(tmp_path, csv=True)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["timeseries.csv", "timeseries.parquet"]  # no summary.json, no temporary file
    assert (tmp_path / "timeseries.csv").read_text() == "old,complete\n1,2\n"  # the old file, untouched
    assert len(pd.read_parquet(tmp_path / "timeseries.parquet")) == 5  # complete


def test_summary_is_written_last(tmp_path):
    seen = []

    def figures(result, out):
        seen.append((out / "summary.json").exists())
        return []

    paths = _small_result().write(tmp_path, figures=figures)
    assert seen == [False]
    assert paths[-1].name == "summary.json"
    assert json.loads(paths[-1].read_text()) == {"final_soc": 0.8}
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


# ----------------------------------------------------------------------------- run size
def _config(overrides: dict):
    """The default mission with dotted-key overrides."""
    from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config
    return config_from_dict(apply_overrides(config_to_dict(load_config()), overrides))


def _mission(overrides: dict, charge: bool = True):
    """(config, result) of the default mission with ``overrides``, model-based policy."""
    import policies
    from mission_sim.config import policy_context
    from mission_sim.world.runner import run_mission
    cfg = _config(overrides)
    return cfg, run_mission(cfg, policies.make("model_based", policy_context(cfg)), charge=charge)


def test_size_estimate_brackets_a_real_run():
    """The estimate is within a factor 2 of the rows a real run produces, for a short and a long hover."""
    from mission_sim.world.budget import check_run_size, estimate_run

    for hover_s in (60.0, 1000.0):
        cfg, res = _mission({"pads.1.hover_time_s": hover_s})
        est = estimate_run(cfg)
        rows = len(res.timeseries)
        assert 0.5 * rows < est.rows < 2.0 * rows, (hover_s, est.rows, rows)
        assert est.key == ("sim.control_period_s" if hover_s < 100 else "pads.1.hover_time_s")
        assert check_run_size(cfg) == est
    big = _config({"pads.1.hover_time_s": 1e6})  # the longest plausible hover (config.PLAUSIBLE)
    assert check_run_size(big, force=True).rows > 1e6 / big.sim.traj_dt_s
    # streamed (the mission command, sweeps) neither its rows nor its trajectory are held: bounded memory
    from mission_sim.world.budget import FIXED_BYTES, HELD_SAMPLES, SAMPLE_BYTES
    assert check_run_size(big).memory_bytes == FIXED_BYTES + SAMPLE_BYTES * HELD_SAMPLES
    with pytest.raises(ValueError, match=r"pads\.1\.hover_time_s=1000000\.0 makes the run too large"):
        check_run_size(big, frame=True)   # held as a DataFrame (telemetry): every row counts


# ----------------------------------------------------------------------------- SoC in [0, 1], depletion
SOC_CASES = {
    "default mission": {},
    "docs/mission.md example": {"wind.gust_sigma_m_s": 3.0, "pads.0.hover_time_s": 30.0},
    "examples/study_small.toml, longest and farthest, strongest wind": {
        "pads.0.hover_time_s": 30.0, "pads.1.y_m": 0.0, "pads.1.hover_time_s": 240.0, "pads.1.x_m": 80.0,
        "wind.speed_m_s": 6.0},
    "full battery, 10 min hover over an energised pad": {"battery.initial_soc": 1.0, "pads.1.hover_time_s": 600.0},
    "nearly empty battery, charged at the first pad": {"battery.initial_soc": 0.02},
}


@pytest.mark.parametrize("overrides", SOC_CASES.values(), ids=SOC_CASES.keys())
def test_soc_stays_in_0_1_and_these_missions_complete(overrides):
    cfg, res = _mission(overrides)
    soc, s = res.timeseries["soc"].to_numpy(), res.summary
    assert 0.0 <= soc.min() and soc.max() <= 1.0
    for key in ("final_soc", "min_soc", "final_soc_without_charging"):
        assert 0.0 <= s[key] <= 1.0, key
    assert not s["battery_depleted"]
    assert s["sim_time_s"] == pytest.approx(res.trajectory.t_s[-1] - res.trajectory.t_s[0])
    assert s["energy_balance_error_rel"] < 1e-9


def _check_depleted_run(cfg, res):
    """The run ended at SoC 0: last row, summary keys, the chemistry's energy and the pad distance."""
    ts, s = res.timeseries, res.summary
    soc = ts["soc"].to_numpy()
    assert soc.min() >= 0.0 and soc.max() <= 1.0
    assert s["battery_depleted"] and s["final_soc"] == soc[-1] and abs(soc[-1]) <= 1e-9
    assert s["depleted_at_s"] == pytest.approx(ts["t_s"].iloc[-1], abs=1e-9) == pytest.approx(s["sim_time_s"])
    assert s["depleted_at_s"] < res.trajectory.t_s[-1]  # the planned mission was longer
    # the chemistry gave exactly what the OCV curve holds between the initial SoC and 0 (OCV held per step)
    usable = cfg.battery.usable_energy_j
    assert s["battery_chem_delta_j"] == pytest.approx(usable(0.0) - usable(cfg.battery.initial_soc), rel=1e-3)
    assert s["energy_balance_error_rel"] < 1e-9
    last = ts[["x_m", "y_m", "z_m"]].iloc[-1].to_numpy()
    pads = np.array([[p.x_m, p.y_m, p.z_m] for p in cfg.pads])
    assert s["depleted_pad_distance_m"] == pytest.approx(np.linalg.norm(pads - last, axis=1).min())


def test_a_far_pad_ends_the_mission_at_depletion():
    """Pad 1 at 10 km: the battery runs out on the way; charging at pad 0 only postpones it."""
    cfg, res = _mission({"pads.1.x_m": 10_000.0})
    _check_depleted_run(cfg, res)
    s = res.summary
    assert 500.0 < s["depleted_pad_distance_m"] < 9_500.0  # in the open, between the pads
    assert s["battery_depleted_without_charging"]
    assert s["depleted_at_s_without_charging"] < s["depleted_at_s"]
    assert s["flight_time_gain_s"] == pytest.approx(s["depleted_at_s"] - s["depleted_at_s_without_charging"])


def test_a_long_hover_without_charging_ends_over_the_pad():
    cfg, res = _mission({"pads.1.hover_time_s": 3000.0}, charge=False)
    _check_depleted_run(cfg, res)
    assert res.summary["depleted_pad_distance_m"] < 1.0
    assert res.timeseries["phase"].iloc[-1] == "charge"


def test_depletion_exit_status_and_message(tmp_path, capsys):
    assert _run(["mission", "--set", "pads.1.x_m=10000", "--no-plot", "--no-progress", "--out", str(tmp_path)]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert re.fullmatch(r"dronewpt mission: battery depleted at t = \d+\.\d s, \d+ m from the nearest pad; "
                        r"the mission ended there", err[0])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["battery_depleted"] and summary["final_soc"] <= 1e-9


# ----------------------------------------------------------------------------- learning, envs
def test_compare_without_sb3_skips_the_rl_row(monkeypatch, capsys, tmp_path):
    from mission_sim.cli import learning
    monkeypatch.setattr(learning, "sb3_installed", lambda: False)
    assert _run(["compare", "--policies", "step,rl", "--no-plot"]) == 2
    assert "stable-baselines3" in capsys.readouterr().err
    monkeypatch.setattr("policies.compare.DEFAULT_POLICIES", ("step", "rl"))
    assert _run(["compare", "--episodes", "1", "--scenarios", "nominal", "--no-plot", "--format", "json"]) == 0
    out, err = capsys.readouterr()
    assert "skipping the rl row" in err
    assert [r["policy"] for r in json.loads(out)["rows"]] == ["step"]


def test_nan_action_is_refused_by_name():
    from envs import SbarChargingVectorEnv
    from envs.charging import SbarChargingEnv
    env = SbarChargingEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action=nan is invalid; valid range: \[-1, 1\]"):
        env.step(np.array([np.nan], dtype=np.float32))
    venv = SbarChargingVectorEnv(num_envs=3)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions\[1\]=inf is invalid"):
        venv.step(np.array([[0.0], [np.inf], [0.0]]))


# ----------------------------------------------------------------------------- replay warnings
def _write_tlog(path: Path, seconds: float, armed_at_end: bool) -> None:
    """A synthetic .tlog: 5 Hz GPS fix 3 moving east, armed from t = 2 s (to the end, or until 3 s before)."""
    import os
    import struct
    os.environ["MAVLINK20"] = "1"
    from pymavlink.dialects.v20 import ardupilotmega as mav
    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    out = bytearray()
    for k in range(int(seconds * 5)):
        t = k / 5
        armed = t >= 2 and (armed_at_end or t < seconds - 3)
        lon = int(149.16523e7 + t * 100)
        msgs = [m.gps_raw_int_encode(int(t * 1e6), 3, int(-35.363261e7), lon, 584000, 100, 100, 0, 0, 10),
                m.global_position_int_encode(int(t * 1e3), int(-35.363261e7), lon, 584000, 0, 0, 0, 0, 0)]
        if k % 5 == 0:
            msgs.append(m.heartbeat_encode(2, 3, 128 * armed | 1, 4, 4))
        for msg in msgs:
            out += struct.pack(">Q", int((1.7e9 + t) * 1e6)) + msg.pack(m)
    path.write_bytes(bytes(out))


def test_replay_warns_on_a_log_ending_armed_and_a_far_pad(tmp_path):
    from mission_sim.mavlink.geodesy import GeoPoint
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import replay_warnings, track_from_log
    _write_tlog(tmp_path / "cut.tlog", 20.0, armed_at_end=True)
    _write_tlog(tmp_path / "whole.tlog", 20.0, armed_at_end=False)
    cut, whole = read_log(tmp_path / "cut.tlog"), read_log(tmp_path / "whole.tlog")
    assert len(whole.position) == 100
    assert replay_warnings(whole, track_from_log(whole)) == []
    (w,) = replay_warnings(cut, track_from_log(cut))
    assert "ends while the vehicle is armed" in w
    far = GeoPoint(35.363261, -149.16523, None)  # signs swapped: the other side of the Earth
    (w,) = replay_warnings(whole, track_from_log(whole, pad=far))
    assert re.search(r"is \d{4,5} km from the nearest point of the track", w)


def test_replay_warns_when_the_battery_runs_out(tmp_path, capsys):
    _write_tlog(tmp_path / "whole.tlog", 20.0, armed_at_end=False)
    out = tmp_path / "r"
    argv = ["replay", str(tmp_path / "whole.tlog"), "--out", str(out), "--no-plot", "--no-progress"]
    assert _run([*argv, "--set", "battery.initial_soc=0.0005"]) == 0
    err = capsys.readouterr().err
    assert re.search(r"warning: battery depleted at t = \d+\.\d s, \d+ m from the nearest pad", err)
    s = json.loads((out / "replay_summary.json").read_text())
    mission = json.loads((out / "mission" / "summary.json").read_text())
    assert mission["battery_depleted"] and mission["final_soc"] <= 1e-9
    assert any("battery depleted" in w for w in s["warnings"])
    assert _run(argv) == 0 and "depleted" not in capsys.readouterr().err
