"""What-if re-flights (issue 24): `dronewpt replay LOG --pads FILE` flies the logged track with a
detour to each pad and reports the flight time the pads buy, with a figure."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mission_sim.cli import main

DATA = Path(__file__).resolve().parent / "data"
LOG = DATA / "flightlogs" / "dronekit-python_flight.tlog"
PADS = DATA / "missions" / "dronekit_flight_pads.csv"


def _track(n=301, dt=0.2):
    """A straight 60 m flight east at 10 m height (3 m/s), armed, about a pad frame origin."""
    from mission_sim.config import MissionPlan
    from mission_sim.mavlink.geodesy import GeoPoint
    from mission_sim.mavlink.replay import FlightTrack
    t = np.arange(n) * dt
    pos = np.column_stack([3.0 * t, np.zeros(n), np.full(n, 10.0)])
    tr = FlightTrack(t_s=t, pos_m=pos, tilt_rad=np.zeros(n), height_m=pos[:, 2].copy(), t_offset_s=100.0,
                     pad=GeoPoint(47.0, 8.0, 500.0), ground_gap_m=0.17, armed=np.ones(n, bool))
    return tr, MissionPlan()


def test_detour_leaves_at_the_closest_point_and_rejoins_the_log():
    from mission_sim.plans.refly import plan_detours, refly_track
    tr, m = _track()
    pads = np.array([[30.0, 8.0, 0.0], [30.0, 900.0, 0.0]])
    detours, skipped = plan_detours(tr, pads, [40.0, 40.0], reach_m=500.0)
    assert [d.pad for d in detours] == [0] and skipped[0][0] == 1 and skipped[0][1] == pytest.approx(900.0)
    assert tr.pos_m[detours[0].sample, 0] == pytest.approx(30.0, abs=0.6) and detours[0].distance_m == pytest.approx(8.0, abs=0.1)
    new, phase = refly_track(tr, pads, detours, m, 0.2)
    assert np.all(np.diff(new.t_s) > 0)
    chg = np.array([p == "charge" for p in phase])
    # charging: over the pad at the charging gap, for the pad's hover time
    assert np.allclose(new.pos_m[chg], [30.0, 8.0, m.hover_gap_m])
    assert chg.sum() * 0.2 == pytest.approx(40.0, abs=0.4)
    # the detour: 8 m out and back at the cruise limits, 9.8 m down and up at the descent / climb rates
    extra = new.t_s[-1] - tr.t_s[-1]
    assert extra > 40.0 + 2 * 8.0 / m.cruise_speed_m_s + (10 - m.hover_gap_m) * (1 / m.descent_rate_m_s + 1 / m.climb_rate_m_s)
    # the logged samples after the detour are the log's, shifted by the detour
    logged = np.array([p is None for p in phase])
    assert logged.sum() == len(tr.t_s)
    assert np.allclose(new.pos_m[logged], tr.pos_m)
    after = new.t_s[logged][detours[0].sample + 1:] - tr.t_s[detours[0].sample + 1:]
    assert np.allclose(after, extra)


def test_replay_with_pads_reports_the_flight_time_gain(capsys, tmp_path):
    out = tmp_path / "refly"
    argv = ["replay", str(LOG), "--pads", str(PADS), "--window", "440,620", "--out", str(out), "--format", "json",
            "--no-progress"]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert (out / "refly.png").stat().st_size > 10_000 and (out / "refly_summary.json").is_file()
    assert sorted(d["pad"] for d in s["detours"]) == [0, 1] and all(d["distance_m"] < 5 for d in s["detours"])
    hover = sum(d["hover_s"] for d in s["detours"])
    assert s["refly_time_s"] - s["logged_flight_time_s"] == pytest.approx(s["detour_time_s"], abs=0.5)
    assert s["detour_time_s"] > hover
    assert 0.9 * hover < s["charge_time_s"] <= hover + 1.0
    # charging pays: the re-flight ends fuller than with the pads off and than the logged flight
    assert s["final_soc_refly"] > s["final_soc_refly_without_charging"]
    assert s["final_soc_refly"] > s["final_soc_logged_flight"] and s["flight_time_gain_s"] > 0
    # the gain is the usable energy difference over the hover power (runner.flight_time_gain_s)
    from mission_sim.config import load_config
    from mission_sim.world.power import hover_power_w
    cfg = load_config()
    assert s["flight_time_gain_s"] == pytest.approx(s["net_battery_energy_gain_j"] / hover_power_w(cfg.drone), rel=1e-9)
    # energy: what reached the battery is less than what the pads sent
    assert 0 < s["battery_charge_in_j"] < s["rectifier_output_j"] < s["energy_from_pads_j"]


@pytest.mark.parametrize("pads", [True, False])
def test_replay_lists_every_file_it_wrote_its_summary_last(capsys, tmp_path, pads):
    """``replay`` (and ``replay --pads``) listed the time series, CSV and figures it wrote but not
    ``replay_summary.json`` / ``refly_summary.json``, the file docs/mavlink.md and docs/mission_files.md name as its
    output (``mission`` lists its ``summary.json``): now every written file is listed, the summary last."""
    out = tmp_path / "o"
    argv = ["replay", str(LOG), "--window", "440,620", "--out", str(out), "--no-plot", "--no-progress"]
    assert main(argv + (["--pads", str(PADS)] if pads else [])) == 0
    text = capsys.readouterr().out
    wrote = [ln.removeprefix("wrote ") for ln in text.splitlines() if ln.startswith("wrote ")]
    assert wrote[-1] == str(out / ("refly_summary.json" if pads else "replay_summary.json"))
    if pads:  # the re-flight's peak current against its rating, as `mission` words it (11.9 A, none of it above 15 A)
        s = json.loads((out / "refly_summary.json").read_text())
        assert s["peak_i2_a"] >= s["peak_i2_envelope_a"] > 0 and s["time_above_rated_s"] == 0
        assert (f"; peak I2 {s['peak_i2_a']:.2f} A instantaneous (envelope {s['peak_i2_envelope_a']:.2f} A; "
                f"rated {s['rated_i2_a']:g} A; above it 0.00 ms)") in text
    on_disk = {str(p) for p in out.rglob("*") if p.is_file() and not p.name.startswith(".")}
    assert sorted(wrote) == sorted(on_disk)


def _one_line(capsys, argv, *needles):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for n in needles:
        assert n in err[0], err[0]


def test_replay_pads_bad_forms(capsys, tmp_path):
    far = tmp_path / "far.csv"
    far.write_text("lat,lon\n-35.30,149.16\n")   # ~7 km north of the flight
    _one_line(capsys, ["replay", str(LOG), "--pads", str(far), "--out", str(tmp_path / "o")], "no pad within --reach")
    bad = tmp_path / "bad.geojson"
    bad.write_text('{"type": "Point", "coordinates": [149.16]}')
    _one_line(capsys, ["replay", str(LOG), "--pads", str(bad), "--out", str(tmp_path / "o")], "bad.geojson", "coordinates")
    _one_line(capsys, ["replay", str(LOG), "--pads", str(PADS), "--reach", "-1"], "--reach")
    assert not (tmp_path / "o").exists()
