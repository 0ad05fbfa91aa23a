"""Users' own files from other tools and vehicles (2026-11-27 night): public real mission plans and logs that the
tests before did not hold, run through the readers the commands use (tests/data/flightlogs/SOURCES.md and
tests/data/missions/SOURCES.md, "Added 2026-11-27 night", for each file's origin and licence)."""

import json
from pathlib import Path

import numpy as np
import pytest

from _flightlogs import log_path
from test_mission_files import enu_xy
from mission_sim.mavlink.logs import read_log
from wpt_receiver.notices import DronewptWarning

PX4_EVENTS = "pyulog_sample_px4_events.ulg"   # PX4 SITL (v1.15 dev), arms, hops to ~2 m; battery_status current -1


def test_px4_unknown_battery_current_is_not_a_charge():
    """PX4's battery_status.current_a = -1 means "unknown" (its simulated battery sends it on every sample): it was
    read as a 1 A charge, so `replay` printed "logged -16 W" airborne and `calibrate` fitted a 0.1 kg drone to it.
    As SYS_STATUS's -1: no battery data."""
    from pyulog import ULog
    u = ULog(str(log_path(PX4_EVENTS)))
    b = next(d.data for d in u.data_list if d.name == "battery_status")
    assert len(b["current_a"]) == 157 and np.all(b["current_a"] == -1.0) and np.all(b["voltage_v"] > 15)
    log = read_log(log_path(PX4_EVENTS))
    assert len(log.position) == 109 and log.duration_s == pytest.approx(31.1, abs=0.05)
    assert log.battery_source is None and len(log.battery) == 0


# ------------------------------------------------------------------------------------------- mission plans
MISSIONS = Path(__file__).resolve().parent / "data" / "missions"


def test_qgc_plan_with_older_items_reads_their_coordinate():
    """QGroundControl's own SectionTest.plan keeps its items in QGC's older form: p1..p4 in "params", [lat, lon, alt]
    in "coordinate" (QGC still reads it, MissionItem::_convertJsonV2ToV3). It was refused ("params=[0, 0, 0, None] is
    invalid; valid: 7 numbers"); now it flies its take-off to 20 m and its three waypoints (the mount-control item 3
    does not move the vehicle)."""
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import route_from_items
    doc = json.loads((MISSIONS / "qgc_section_test.plan").read_text())
    raw = read_mission(MISSIONS / "qgc_section_test.plan")
    route = route_from_items(raw)
    home = tuple(doc["mission"]["plannedHomePosition"])
    assert [w["action"] for w in route] == ["takeoff", "waypoint", "waypoint", "waypoint"]
    for w, i in zip(route[1:], (1, 2, 4)):
        lat, lon, alt = doc["mission"]["items"][i]["coordinate"]
        e, n = enu_xy(lat, lon, home)
        assert (w["x_m"], w["y_m"], w["z_m"]) == pytest.approx((e, n, alt), abs=0.02)
    assert route[3]["x_m"] == pytest.approx(312.0, abs=0.5) and route[3]["y_m"] == pytest.approx(-86.3, abs=0.5)


def test_qgc_structure_scan_flies_the_waypoints_qgc_generates():
    """A structure scan in a plan holds only its inputs (QGC generates the waypoints when it loads the plan): it was
    refused ("has no generated waypoints ... save the plan after the survey was generated", which no save does).
    Now: entrance at 50 m, 2 layers (StartFromTop: 100 - 25/2 = 87.5 m, then 62.5 m), each around the structure's
    polygon offset 50 m outwards and back to its first vertex, exit at 50 m."""
    from mission_sim.mavlink.geodesy import geodetic_to_enu
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import route_from_items
    doc = json.loads((MISSIONS / "mavsdk_structure_scan.plan").read_text())
    scan = doc["mission"]["items"][1]
    raw = read_mission(MISSIONS / "mavsdk_structure_scan.plan")
    route = route_from_items(raw)
    z = [w["z_m"] for w in route]
    assert z == [50.0] + [87.5] * 5 + [62.5] * 5 + [50.0]
    xy = np.array([(w["x_m"], w["y_m"]) for w in route])
    ring = xy[1:5]
    assert np.allclose(xy[5], xy[1]) and np.allclose(xy[6:11], xy[1:6]) and np.allclose(xy[0], xy[1])
    poly = np.array(scan["polygon"])
    s = np.column_stack(geodetic_to_enu(poly[:, 0], poly[:, 1], raw.home.alt_m, raw.home)[:2])
    for i in range(4):   # flight edge i runs DistanceToSurface = 50 m outside structure edge i, parallel to it
        a, b = ring[i], ring[(i + 1) % 4]
        u = (b - a) / np.linalg.norm(b - a)
        for p in (s[i], s[(i + 1) % 4]):
            assert -(u[0] * (p - a)[1] - u[1] * (p - a)[0]) == pytest.approx(50.0, abs=0.05)


def test_px4_package_delivery_plan_flies_past_its_gripper_item():
    """PX4's package-delivery test plan: a waypoint at 5 m, a landing 40 m on, DO_GRIPPER (release), a waypoint at
    10 m. The gripper item was refused ("command DO_GRIPPER (211) is not supported"): it does not move the vehicle.
    Since 2026-11-28 its release is counted on the landing before it (``release``: the payload's mass is taken off
    the drone there, tests/test_payload.py). The route lands and takes off again."""
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import IGNORED_COMMANDS, route_from_items
    doc = json.loads((MISSIONS / "px4_triangle_gripper_package_delivery.plan").read_text())
    assert [it["command"] for it in doc["mission"]["items"]] == [16, 21, 211, 16]
    raw = read_mission(MISSIONS / "px4_triangle_gripper_package_delivery.plan")
    route = route_from_items(raw)
    assert 211 in IGNORED_COMMANDS
    assert [(w["action"], w["z_m"]) for w in route] == [("waypoint", 5.0), ("land", 0.0), ("waypoint", 10.0)]
    assert [w.get("release", 0) for w in route] == [0, 1, 0]
    home = tuple(doc["mission"]["plannedHomePosition"])
    for w, i in zip(route, (0, 1, 3)):
        e, n = enu_xy(*doc["mission"]["items"][i]["params"][4:6], home)
        assert (w["x_m"], w["y_m"]) == pytest.approx((e, n), abs=0.02)


@pytest.mark.parametrize("edit, needles", [
    (lambda scan: scan.update(complexItemType="fwLandingPattern"),
     ["item 1: complex item 'fwLandingPattern' is not supported; supported complex items: survey, CorridorScan, "
      "StructureScan"]),
    (lambda scan: scan.pop("Layers"), ["item 1 (StructureScan): Layers=None is invalid; valid range: integer 1..1000 "
                                       "(QGroundControl saves it)"]),
    (lambda scan: scan["CameraCalc"].update(AdjustedFootprintFrontal=0),
     ["CameraCalc.AdjustedFootprintFrontal=0 is invalid; valid range: (0, inf) m"]),
    # (2026-11-27 night review: the scan's own checks, not validation's shared ones; "false" flew the scan from the top,
    # a CameraCalc that is no object was read as {}, a negative height passed the scan and failed as a waypoint's)
    (lambda scan: scan.update(StartFromTop="false"),
     ['item 1 (StructureScan): StartFromTop="false" is invalid; valid: true or false (a JSON boolean)']),
    (lambda scan: scan.update(CameraCalc="50 m"),
     ['item 1 (StructureScan): CameraCalc="50 m" is invalid; valid: a JSON object {...}']),
    (lambda scan: scan.update(EntranceAltitude=-5),
     ["item 1 (StructureScan): EntranceAltitude=-5 is invalid; valid range: [0, 5000] m above home"]),
    (lambda scan: scan.update(Layers="2"), ["item 1 (StructureScan): Layers='2' is invalid; valid range: integer "
                                            "1..1000"]),
    (lambda scan: scan.update(polygon=scan["polygon"][:2]), ["polygon is invalid (fewer than 3 vertices)"]),
])
def test_complex_items_that_cannot_be_flown_are_one_line_errors(capsys, tmp_path, edit, needles):
    """The structure-scan plan with one input broken, or its complex item another kind: one line naming the item and
    the bad value, exit 2, nothing simulated (a landing pattern was told to "save the plan after the survey was
    generated", which does not help: QGC saves its inputs only)."""
    from mission_sim.cli import main
    doc = json.loads((MISSIONS / "mavsdk_structure_scan.plan").read_text())
    edit(doc["mission"]["items"][1])
    plan = tmp_path / "scan.plan"
    plan.write_text(json.dumps(doc))
    assert main(["mission", "--plan", str(plan), "--no-plot", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    for n in needles:
        assert n in err, err
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------------------------ DO_JUMP
def _flown(path):
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import _unrolled
    raw = read_mission(path)
    return raw, [it.where for it in _unrolled(raw)]


def test_do_jump_loops_are_flown_as_ardupilot_flies_them():
    """DO_JUMP (param1 the target, param2 the number of jumps) was refused; ArduPilot's and PX4's missions loop
    with it. ArduPilot's CAN-GPS copter mission jumps from row 10 back to row 8 once; the ArduPlane mission that
    pymavlink's test.BIN logged (CMD records) jumps from item 6 to item 2 three times: items 2-5 flown 4 times, then
    its landing sequence."""
    raw, order = _flown(MISSIONS / "ardupilot_can_gps_copter_mission.waypoints")
    assert order == [f"row {r}" for r in (1, 2, 3, 4, 5, 6, 7, 8, 9, 8, 9, 11, 12)]
    raw, order = _flown(log_path("pymavlink_test.BIN"))
    assert raw.items[5].command == 177 and raw.items[5].params[:2] == (2.0, 3.0)
    assert order == [f"item {i}" for i in [1] + [2, 3, 4, 5] * 4 + [7, 8, 9, 10, 11]]
    from mission_sim.plans.route import route_from_items
    route = route_from_items(raw)
    assert [w["action"] for w in route] == ["takeoff"] + ["waypoint"] * 19 + ["land"]
    lap = np.array([(w["x_m"], w["y_m"]) for w in route[1:5]])
    assert np.allclose(np.array([(w["x_m"], w["y_m"]) for w in route[13:17]]), lap)   # the 4th lap = the 1st


# ------------------------------------------------------------------------------------ logs that never flew
@pytest.mark.parametrize("name", ["amc_backend_log_80k.bin", "pymavlink_test.BIN"])
def test_a_ground_log_has_no_flown_route(capsys, tmp_path, name):
    """ArduCopter 4.6.2 on a Pixhawk 4 (0.4 s, 2 fixes, BAT 16.4 V) and ArduPlane 3.8 (1.1 s, 5 fixes), both on the
    ground, with no armed-state record and no motor output (the armed state is unknown): `mission --plan LOG` (no
    uploaded mission, or `from_log = "flown"`) made a route of the GPS drift on the ground (a 1 s "flight", 25 J of
    propulsion); `replay` marks such a track NOT FLOWN. Now one line, exit 2: the track never rises 1 m above its
    first position."""
    from mission_sim.cli import main
    log = read_log(log_path(name))
    assert log.armed_periods == [] and log.armed_source is None and len(log.position) >= 2 and len(log.battery) >= 4
    assert 16.3 < log.battery["voltage_v"].median() < 16.6 if name.startswith("amc") else 12.3 < \
        log.battery["voltage_v"].median() < 12.5
    argv = ["mission", "--plan", str(log_path(name)), "--no-plot", "--out", str(tmp_path / "out")]
    if name == "pymavlink_test.BIN":   # (it holds an uploaded mission: the flown track on request)
        argv += ["--set", "mission.from_log=flown"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f"{name}: no flown track: the armed state is unknown" in err, err
    assert "never rises 1 m above its first position (max 0.0" in err, err
    assert not (tmp_path / "out").exists()


def test_a_log_that_never_armed_has_no_flown_route(monkeypatch):
    """A log whose armed-state records say disarmed throughout (the ArduCopter ground log given a HEARTBEAT-like
    disarmed record): "the vehicle never armed", naming where the armed state came from."""
    import dataclasses

    import pandas as pd

    import mission_sim.mavlink.logs as logs
    from mission_sim.plans.items import read_mission
    full = read_log(log_path("amc_backend_log_80k.bin"))
    log = dataclasses.replace(full, armed=pd.DataFrame({"t_s": [0.0], "armed": [False]}), armed_source="HEARTBEAT")
    monkeypatch.setattr(logs, "read_log", lambda path: log)
    with pytest.raises(ValueError, match=r"^amc_backend_log_80k.bin: no flown track: the vehicle never armed in the "
                                         r"log \(armed state from HEARTBEAT\)"):
        read_mission(log_path("amc_backend_log_80k.bin"), "flown")


def test_a_log_with_unknown_armed_state_flies_its_whole_track(monkeypatch):
    """A log with no armed-state record and no motor output (``armed_source`` None: the armed state is unknown, not
    "never armed") was refused by `mission --plan LOG` as "the vehicle never armed"; before the never-armed rule it
    flew its whole GPS track. It does again, with one warning saying the armed state is unknown. log171 with its
    armed-state records taken out: the whole track, from its first fix (the 27 s on the ground before arming
    included)."""
    import dataclasses

    import mission_sim.mavlink.logs as logs
    from mission_sim.plans.items import NAV_LAND, read_mission
    from wpt_receiver.notices import DronewptWarning
    full = read_log(log_path("dronekit-la-testdata_log171.bin"))
    log = dataclasses.replace(full, armed=full.armed.iloc[0:0], armed_source=None)
    assert log.armed_periods == [] and full.armed_periods[0][0] > full.position["t_s"].iloc[0] + 25
    monkeypatch.setattr(logs, "read_log", lambda path: log)
    with pytest.warns(DronewptWarning, match="the armed state is unknown .*whole GPS track") as rec:
        raw = read_mission(log_path("dronekit-la-testdata_log171.bin"), "flown")
    assert len(rec) == 1
    first = log.position.iloc[0]
    assert (raw.home.lat_deg, raw.home.lon_deg, raw.home.alt_m) == (first.lat_deg, first.lon_deg, first.alt_m)
    assert raw.items[-1].command == NAV_LAND and len(raw.items) > 5
    monkeypatch.setattr(logs, "read_log", lambda path: full)        # (with its armed state: the armed time only)
    assert read_mission(log_path("dronekit-la-testdata_log171.bin"), "flown").home != raw.home


@pytest.mark.parametrize("name", ["amc_backend_log_80k.bin", "pymavlink_test.BIN"])
def test_replay_refuses_a_ground_log_whose_armed_state_is_unknown_as_mission_plan_does(capsys, tmp_path, name):
    """`replay` of a ground log with no armed-state record and no motor output said "never armed" and marked the
    track NOT FLOWN (exit 0), while `mission --plan LOG` refuses it: the armed state is unknown, not "never armed". One
    rule now (:func:`mission_sim.mavlink.takeoff.flown_periods`): the same one-line refusal, exit 2, nothing written."""
    from mission_sim.cli import main
    assert main(["replay", str(log_path(name)), "--no-plot", "--no-progress", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f"{name}: no flown track: the armed state is unknown" in err, err
    assert "never rises 1 m above its first position (max 0.0" in err and "never armed" not in err, err
    assert not (tmp_path / "out").exists()
    pads = Path(__file__).parent / "data" / "missions" / "dronekit_flight_pads.csv"   # (`replay --pads`: the same)
    argv = ["replay", str(log_path(name)), "--pads", str(pads), "--no-progress", "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f"{name}: no flown track: the armed state is unknown" in err, err


def test_replay_of_a_log_with_unknown_armed_state_counts_its_whole_track_as_flown(capsys):
    """log171 with its armed-state records taken out (``armed_source`` None): `replay` marked it never armed (0 s
    armed, NOT FLOWN); now its whole track is armed (the rule `mission --plan LOG` flies, one source:
    :func:`~mission_sim.mavlink.takeoff.flown_periods`), with one warning saying the armed state is unknown, and the log
    facts say so."""
    import dataclasses

    from mission_sim.cli.mavlink import _print_log_facts
    from mission_sim.mavlink.replay import flight_stats, replay_warnings, track_from_log
    from mission_sim.mavlink.takeoff import flown_periods
    full = read_log(log_path("dronekit-la-testdata_log171.bin"))
    log = dataclasses.replace(full, armed=full.armed.iloc[0:0], armed_source=None)
    t = log.position["t_s"].to_numpy(float)
    assert flown_periods(log) == [(t.min(), t.max())] and flown_periods(full) == full.armed_periods
    track = track_from_log(log)
    assert track.armed.all()
    stats = flight_stats(log, track)
    assert stats["flown"] and stats["flown_time_s"] == pytest.approx(float(track.t_s[-1]), abs=0.5)
    assert stats["flown_time_s"] > full.armed_time_s + 25   # (the 27 s on the ground before arming included)
    # (2026-11-28: no armed time is claimed for it: "armed_time_s" gave the whole track, "log_armed_time_s" 0)
    assert stats["armed_time_s"] is None and stats["armed_periods_s"] is None and stats["log_armed_time_s"] is None
    known = flight_stats(full, track_from_log(full))
    assert known["armed_time_s"] == known["flown_time_s"] == pytest.approx(full.armed_time_s, abs=1.0)
    assert known["armed_periods_s"] == known["flown_periods_s"] and known["log_armed_time_s"] == full.armed_time_s
    warns = replay_warnings(log, track)
    assert not any("never armed" in w or "NOT FLOWN" in w for w in warns), warns
    assert sum("the armed state is unknown" in w and "whole GPS track" in w for w in warns) == 1, warns
    _print_log_facts(log.path.name, stats)
    out = capsys.readouterr().out
    assert "never armed" not in out and "NOT FLOWN" not in out and "the armed state is unknown" in out, out
    assert f"the whole replayed track, {stats['flown_time_s']:.1f} s, counted as flown" in out and "armed 0.0" not in out
    assert not any("armed state is unknown" in w for w in replay_warnings(full, track_from_log(full)))


# ------------------------------------------------------------------------- a log that starts in the air
PX4_ESC = "px4_ulog_rs_esc_status_log.ulg"   # PX4 v1.9 on a Pixhawk (FMU v3), 6S, 26-74 A: logging began in flight


def test_a_log_that_starts_in_the_air_is_about_the_ground_it_lands_on():
    """A real PX4 flight logged from 4 s after take-off (armed from its first record, 6-7 m up, climbs to ~10 m,
    lands at the end, 26-74 A): the pad, the first armed position, was in the air, every height below it (the whole
    descent) was clipped to 0, and `replay` said "max 3.1 m above the pad" and 22 s airborne of 38.8 s armed. Now the
    default pad is where that flight ends (its last position before the disarm, its landing, here also its lowest):
    the heights span the log's own altitude range, and one warning says so."""
    from pyulog import ULog

    from mission_sim.mavlink.ground import GROUND_M
    from mission_sim.mavlink.replay import default_pad, replay_warnings, track_from_log
    u = ULog(str(log_path(PX4_ESC)))
    gp = next(d.data for d in u.data_list if d.name == "vehicle_global_position")
    b = next(d.data for d in u.data_list if d.name == "battery_status")
    assert b["current_a"].min() > 25 and 21.5 < b["voltage_v"].min() < b["voltage_v"].max() < 22.7
    log = read_log(log_path(PX4_ESC))
    assert log.starts_armed and len(log.armed_periods) == 1
    pad = default_pad(log)
    assert pad.alt_m == pytest.approx(float(gp["alt"].min()), abs=0.01)          # 426.37 m: the landing
    track = track_from_log(log)
    span = float(gp["alt"].max() - gp["alt"].min())                               # 10.2 m
    assert track.height_m.max() == pytest.approx(span, abs=0.3) and span > 9.5
    airborne = track.armed & (track.height_m > GROUND_M)
    t_air = float(np.sum(np.diff(track.t_s)[airborne[:-1]]))
    assert 30 < t_air < 38.8                                                      # (it was 22 s)
    warn = replay_warnings(log, track)
    assert any("starts armed 7.1 m above where its first flight ends" in w for w in warn), warn
    # its flown route (`mission --plan LOG`): at ~10 m, 41.2 s (docs/changes.md; 33.4 s at ~3 m about the air)
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import route_from_items
    with pytest.warns(DronewptWarning, match="starts armed 7.1 m above"):   # (mission --plan says it too)
        route = route_from_items(read_mission(log_path(PX4_ESC), "flown"))
    assert 9.5 < max(w["z_m"] for w in route) < 10.5


def test_a_log_that_starts_in_the_air_flies_its_route_as_documented(tmp_path, capsys):
    """docs/changes.md's number for the px4-ulog-rs flight's flown route: 41.2 s (the reviewer found 41.8 s written);
    and `mission --plan LOG` says its home moved to the landing (426.37 m, not the first fix's 432.05 m), with replay's
    warning, one text (mavlink.takeoff.starts_airborne_warning): it said nothing (review of the night's merge)."""
    from mission_sim.cli import main
    from mission_sim.mavlink.takeoff import starts_airborne_warning
    assert main(["mission", "--plan", str(log_path(PX4_ESC)), "--no-plot", "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    text = starts_airborne_warning(read_log(log_path(PX4_ESC)))
    assert "starts armed 7.1 m above where its first flight ends" in text and "mission --plan" in text
    assert err.count(text) == 1, err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["sim_time_s"] == pytest.approx(41.2, abs=0.05)
    assert "flown route is 41.2 s at ~10 m" in (Path(__file__).resolve().parents[1] / "docs" / "changes.md").read_text()


PX4_BENCH = "pyulog_sample_log_small.ulg"   # PX4 on the bench, armed from its first record, disarmed at 5.5 s


def test_a_log_that_starts_armed_on_high_ground_keeps_its_take_off_spot():
    """2026-11-27 night review: "starts armed and its first flight goes > 5 m below its first position" also matched a
    take-off from high ground that flies down into a valley (PX4 logs start at arming: many start armed on the ground).
    pyulog's bench log (armed from its first record, disarmed at 5.5 s) with the middle fifth of its track 8 m lower:
    the pad moved from 66.8 m AMSL (the first armed position) to 55.8 m, the valley's floor, with a warning calling it
    "its landing". Now the first armed position is compared with the end of the first armed period (the disarm, on the
    ground: 62.9 m, 3.9 m lower, GPS drift): the pad stays; and a log that ends armed (its end may be in the air) never
    moves it."""
    import dataclasses

    from mission_sim.mavlink.replay import replay_warnings, track_from_log
    from mission_sim.mavlink.takeoff import _airborne_start, default_pad
    log = read_log(log_path(PX4_BENCH))
    assert log.starts_armed and len(log.armed_periods) == 1 and not log.armed["armed"].iloc[-1]
    pos = log.position.copy()
    n = len(pos)
    pos.loc[2 * n // 5:3 * n // 5 - 1, "alt_m"] -= 8.0                       # a valley in the middle of the flight
    valley = dataclasses.replace(log, position=pos)
    first = float(log.position["alt_m"].iloc[0])                              # 66.8 m, armed at the first record
    assert first - float(pos["alt_m"].min()) > 8 and _airborne_start(valley) is None
    assert default_pad(valley).alt_m == pytest.approx(first)                  # (was 58.8 m: the valley)
    assert not any("starts armed" in w for w in replay_warnings(valley, track_from_log(valley)))
    # the real flight that starts in the air, cut before its disarm: no landing to measure against, the pad stays
    esc = read_log(log_path(PX4_ESC))
    assert _airborne_start(esc) is not None
    cut = dataclasses.replace(esc, armed=esc.armed[esc.armed["armed"]])
    assert cut.armed_periods[0][1] == esc.duration_s and _airborne_start(cut) is None
    assert default_pad(cut).alt_m == pytest.approx(float(esc.position["alt_m"].iloc[2]))   # the first armed position


@pytest.mark.parametrize("name, needle", [
    ("pymavlink_fence-110.txt", "row 1: command NAV_FENCE_POLYGON_VERTEX_INCLUSION (5001) is a geofence polygon vertex, "
     "not a mission item: the file is a geofence or rally-point list"),
    ("pymavlink_rally-110.txt", "row 1: command NAV_RALLY_POINT (5100) is a rally point, not a mission item"),
])
def test_a_fence_or_rally_file_given_as_the_mission_says_what_it_is(capsys, tmp_path, name, needle):
    """pymavlink's QGC WPL 110 fence and rally lists (Mission Planner's format for them) as --plan: refused as before,
    but the line says the file is a fence / rally list (it said the command "is not supported" and listed the
    mission commands)."""
    from mission_sim.cli import main
    assert main(["mission", "--plan", str(MISSIONS / name), "--no-plot", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and needle in err, err


# ------------------------------------------------------------------------------------------ flown routes
def test_flown_route_hovers_only_where_the_log_hovered_in_the_air(monkeypatch):
    """The flown route counted every slow sample of a decimated leg as hovering, ground time included. log171 (one
    armed period from 61 s, take-off at ~78 s): the armed wait on the ground became a 9.6 s hover at 3 m, its loiters
    held 35.4 s (25.8 s now). On the dronekit tlog (7 armed periods) a leg from 853 s to 930 s (a landing, 66 s
    disarmed on the ground, the next take-off) became a 70 s hover at 5 m: 142.6 s of loiters (11.6 s now), a 556 s route (442 s now)
    for 429.5 s armed. Each loiter's hold is now at most the time the log spent slower than 0.5 m/s in the air (1 m or
    more above the take-off spot) on its leg."""
    import mission_sim.mavlink.logs as logs
    from mission_sim.mavlink.geodesy import geodetic_to_enu
    from mission_sim.plans.items import NAV_LOITER_TIME, read_mission
    log = read_log(log_path("dronekit-la-testdata_log171.bin"))
    monkeypatch.setattr(logs, "read_log", lambda path: log)          # (one read of the log)
    raw = read_mission(log_path("dronekit-la-testdata_log171.bin"), "flown")
    (a0, a1), = log.armed_periods
    pos = log.position[(log.position["t_s"] >= a0) & (log.position["t_s"] <= a1)]
    t = pos["t_s"].to_numpy(float)
    e, n, u = geodetic_to_enu(pos["lat_deg"].to_numpy(), pos["lon_deg"].to_numpy(), pos["alt_m"].to_numpy(), raw.home)
    u = np.maximum(u, 0.0)
    air = u >= 1.0
    dt = np.diff(t)
    slow = (np.hypot(np.hypot(np.diff(e), np.diff(n)), np.diff(u)) / np.maximum(dt, 1e-9) < 0.5) & (dt < 10)
    prev, loiters = 0, []
    for it in raw.items:
        k = int(it.where.split()[-1]) if it.where.startswith("track point") else len(t) - 1
        if it.command == NAV_LOITER_TIME:
            in_air = float(np.sum(dt[prev:k][slow[prev:k] & air[prev:k] & air[prev + 1:k + 1]]))
            loiters.append((it.params[0], in_air))
        prev = k
    assert loiters and all(hold <= in_air + 1e-9 for hold, in_air in loiters), loiters
    assert 20 < sum(h for h, _ in loiters) < 30     # (35.4 s before)


def test_flown_route_stop_time_counts_only_time_in_the_air():
    """``_stop_time``'s ``air`` mask alone (the route test above passes without it: every take-off and landing is kept,
    so a decimated leg spans ground and air only on a one-step take-off). A leg shaped as log171's start: 9.6 s armed
    and still on the ground, a 0.5 s step up to 3 m, 6 s hovering there, a 0.4 s dash away: 6 s of hover (with the
    ground wait counted, 15.6 s)."""
    from mission_sim.mavlink.ground import GROUND_M
    from mission_sim.plans.items import FLOWN_HOLD_S, _stop_time
    t = np.r_[np.arange(0.0, 9.61, 0.4), 10.1 + np.arange(0.0, 6.01, 0.4), 16.5]
    z = np.r_[np.zeros(25), np.full(16, 3.0), 3.0]
    x = np.r_[np.zeros(41), 10.0]
    p = np.column_stack([x, np.zeros_like(x), z])
    hold = _stop_time(p, t, p[:, 2] >= GROUND_M)
    assert hold == pytest.approx(6.0, abs=1e-9) and hold >= FLOWN_HOLD_S
    assert _stop_time(p[:25], t[:25], np.zeros(25, bool)) == 0.0   # all on the ground: no hover


def test_flown_route_keeps_a_hop_lower_than_the_decimation_tolerance():
    """PX4's SITL hop to 2.1 m (pyulog's sample_px4_events.ulg) lies within the 3 m decimation tolerance of the
    ground: the flown route was one landing where it stood (1.2 s of mission). Every take-off and landing (the track
    crossing 1 m) is kept now: the route takes off and lands."""
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import route_from_items
    route = route_from_items(read_mission(log_path(PX4_EVENTS), "flown"))
    assert [w["action"] for w in route][-1] == "land"
    assert any(w["action"] == "waypoint" and w["z_m"] >= 1.0 for w in route)


def test_nav_delay_in_the_air_is_a_hover_where_the_vehicle_is(tmp_path):
    """ArduPilot's NavDelay test mission: take-off to 20 m, a waypoint, NAV_DELAY 60 s, RTL. It was refused
    ("NAV_DELAY (93) is not supported"); ArduCopter holds its position for the delay: a 60 s loiter there (over a pad:
    a charging hover, as any loiter). A delay before the take-off or until a time of day (param1 < 0, or 0 with a time
    in params 2-4: ArduPilot's do_nav_delay takes only param1 > 0 as seconds): one line; param1 = 0 with params 2-4
    zero: no delay."""
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import route_from_items
    path = MISSIONS / "ardupilot_copter_nav_delay.waypoints"
    route = route_from_items(read_mission(path))
    assert [(w["action"], w["hold_s"]) for w in route] == [("takeoff", 0), ("waypoint", 0), ("loiter", 60.0),
                                                          ("waypoint", 0), ("land", 0)]
    assert (route[2]["x_m"], route[2]["y_m"], route[2]["z_m"]) == (route[1]["x_m"], route[1]["y_m"], 20.0)
    pads = [(route[1]["x_m"], route[1]["y_m"], 0.0)]
    charged = route_from_items(read_mission(path), pads)
    assert charged[2]["action"] == "charge" and charged[2]["pad"] == 0 and charged[2]["hold_s"] == 60.0
    lines = path.read_text().splitlines(keepends=True)
    assert "\t93\t60.000000\t" in lines[4]
    def delay(p1, hour=0, minute=0, second=0):   # row 3 with params 1-4 replaced
        f = lines[4].split("\t")
        return "\t".join(f[:4] + [f"{v:f}" for v in (p1, hour, minute, second)] + f[8:])

    p = tmp_path / "delay.waypoints"
    for bad, needle in ((delay(0, 12, 30), r"NAV_DELAY param1=0 with params 2-4 = \(12, 30, 0\) waits for a time of"),
                        (delay(-1), r"NAV_DELAY param1=-1 with params 2-4 = \(0, 0, 0\) waits for a time of day"),
                        (None, "NAV_DELAY on the ground is not supported")):
        # (the delay's value made 0 with 12:30 UTC, ArduPilot's do_nav_delay: a time of day, it was flown as
        # no delay; made -1; the delay moved before the take-off)
        p.write_text("".join(lines[:4] + [bad] + lines[5:]) if bad else "".join(lines[:2] + [lines[4]] + lines[2:4]
                                                                               + lines[5:]))
        with pytest.raises(ValueError, match=needle):
            route_from_items(read_mission(p))
    # param1 = 0 with params 2-4 zero: no delay, skipped, also before the take-off (it was refused there)
    for order in ((0, 1, 2, 3, 4, 5), (0, 1, 4, 2, 3, 5)):
        rows = lines[:4] + [delay(0)] + lines[5:]
        p.write_text("".join(rows[k] for k in order))
        assert [w["action"] for w in route_from_items(read_mission(p))] == ["takeoff", "waypoint", "waypoint", "land"]


def test_do_jump_to_a_missing_target_names_the_ids_the_mission_holds(tmp_path):
    """A .plan's doJumpIds can have gaps: the DO_JUMP error said "valid: 1..9", suggesting ids the mission lacks. PX4's
    package-delivery plan with its doJumpIds 1, 3, 7, 9 and a DO_JUMP (id 10) to 5: the ids are named."""
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import _jump_ids, route_from_items
    doc = json.loads((MISSIONS / "px4_triangle_gripper_package_delivery.plan").read_text())
    items = doc["mission"]["items"]
    for it, jid in zip(items, (1, 3, 7, 9)):
        it["doJumpId"] = jid
    items.append({"type": "SimpleItem", "command": 177, "frame": 2, "doJumpId": 10, "autoContinue": True,
                  "params": [5, 1, 0, 0, 0, 0, 0]})
    plan = tmp_path / "jump.plan"
    plan.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"DO_JUMP target param1=5 is not an item of the mission; valid: one of 1, 3, "
                                         r"7, 9, 10$"):
        route_from_items(read_mission(plan))
    assert _jump_ids(list(range(2, 26, 2))) == "one of 2, 4, 6, 8, 10, 12, 14, 16, ... (12 ids, the last 24)"


@pytest.mark.parametrize("repeat, said", [
    (2.5, "DO_JUMP repeat count param2=2.5 is invalid; valid range: integer >= 0"),
    (-2.0, "DO_JUMP repeat count param2=-2.0 is invalid; valid range: integer >= 0"),
    (float("nan"), "DO_JUMP repeat count param2=nan is invalid; valid range: integer >= 0"),
    (-1.0, "DO_JUMP repeats forever (param2 = -1): the route would never end; valid range: integer >= 0"),
    (1e6, "the DO_JUMP loops give more than 100,000 items to fly"),
])
def test_do_jump_repeat_count_is_checked_in_the_projects_words(repeat, said):
    """Review of the merge: the repeat count's check was written by hand ("valid: an integer >= 0", not
    ``validation.check_number``'s "valid range: integer >= 0") and the item limit printed "100000" where the docs say
    "100,000"."""
    from mission_sim.plans.items import MissionItem, RawMission
    from mission_sim.plans.route import _unrolled
    nan = float("nan")
    wp = [MissionItem(f"item {k}", 16, 3, (nan,) * 4, 0.0, 0.0, 10.0, jump_id=k) for k in (1, 2)]
    jump = MissionItem("item 3", 177, 3, (1.0, repeat, nan, nan), nan, nan, nan, jump_id=3)
    with pytest.raises(ValueError) as exc:
        list(_unrolled(RawMission("m.plan", None, (*wp, jump))))
    assert str(exc.value).startswith("m.plan: item ") and said in str(exc.value), str(exc.value)
    assert "\n" not in str(exc.value)


def test_a_ulog_gives_its_flown_track_never_an_uploaded_mission():
    """Review of the merge: README said `mission --plan` flies "the mission in a .tlog / .bin / .ulg"; a .ulg's mission
    is not read (uploaded_mission opens it with pymavlink's .tlog reader, which finds no MAVLink mission items): "auto"
    flies its track, "uploaded" is refused. README and docs/mission_files.md say so."""
    from mission_sim.plans.items import read_mission, uploaded_mission
    assert uploaded_mission(log_path(PX4_ESC)).items == ()
    with pytest.warns(DronewptWarning, match="starts armed"):
        assert all(it.where.startswith("track") for it in read_mission(log_path(PX4_ESC)).items)
    with pytest.raises(ValueError, match="holds no uploaded mission"):
        read_mission(log_path(PX4_ESC), "uploaded")
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    assert "/ `.ulg`, with pads" not in readme and "any `.ulg`, whose mission is not\nread" in readme
