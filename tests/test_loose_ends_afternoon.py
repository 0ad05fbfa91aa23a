"""Loose ends left by earlier sessions (2026-11-27 afternoon; docs/robustness.md, "Loose ends (2026-11-27
afternoon)"): each test failed on the tree before its fix (``main``)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest

from mission_sim.cli import main

_LOG = str(Path(__file__).resolve().parent / "data" / "flightlogs" / "dronekit-python_flight.tlog")
_FAR = ("pads.0.z_m={z} is outside +-120 m of {origin} (the pad is {d} m below it: a drone charging there flies up "
        "or down to it); valid: a pad's height within +-120 m of it (a pads file's alt in metres above mean sea level, "
        "not above the ground, not feet; [[pads]] z_m and --set pads.<i>.z_m in metres above it)")


def _one_error_line(capsys, argv) -> str:
    """``main(argv)``: exit status 2, nothing on stdout, one line on stderr and no traceback (the line returned)."""
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    cap = capsys.readouterr()
    assert rc == 2, (rc, cap.err)
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in cap.err, cap.err
    assert cap.out == "", cap.out
    return lines[0]


def _ours(caught) -> list[str]:
    from wpt_receiver.notices import DronewptWarning
    return [str(w.message) for w in caught if issubclass(w.category, DronewptWarning)]


# ------------------------------------------------------------------ 1. the far pad among the setup warnings
def test_a_sweep_counts_the_far_pad_among_its_setup_warnings(tmp_path):
    """A study whose cases put the pad 200 m / 130 m below home: the cases run with ``warn=False`` (warned once per
    study), and the study's lines had no word of it (only the link and unreached-pad kinds were counted)."""
    import policies
    from mission_sim.studies.prepare import prepare_study
    from mission_sim.studies.study import load_study
    (tmp_path / "s.toml").write_text('[study]\nname = "low"\n[grid]\n"pads.0.z_m" = [-200.0, 0.0, -130.0]\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prepare_study(load_study(tmp_path / "s.toml"), policies.make, policies.available())
    assert _ours(caught) == ["2 of 3 cases of study 'low' have a pad more than 120 m above or below its frame's origin, "
                             "e.g.: " + _FAR.format(z=-200, origin="the mission's home", d=200)]


def test_a_refly_summary_lists_the_far_pad(capsys, tmp_path):
    """``replay --pads`` with the pad 150 m below the ``--pad`` origin: warned during the run, but the summary's
    ``warnings`` (``refly_summary.json``, ``--format json``; a ``[replay]`` study's ``n_warnings``) had no word."""
    (tmp_path / "low.csv").write_text("lat,lon,alt,hover_time_s\n-35.3620800,149.1658531,0,10\n")
    argv = ["replay", _LOG, "--pads", str(tmp_path / "low.csv"), "--pad=-35.36208,149.1658531,150", "--window",
            "440,620", "--no-plot", "--format", "json", "--no-progress", "--out", str(tmp_path / "o"),
            "--set", "battery.n_series=3"]
    assert main(argv) == 0
    cap = capsys.readouterr()
    line = _FAR.format(z=-150, origin="the replay's pad frame origin", d=150)
    assert json.loads(cap.out)["warnings"].count(line) == 1
    assert json.loads((tmp_path / "o" / "refly_summary.json").read_text())["warnings"].count(line) == 1
    assert cap.err.splitlines().count(f"dronewpt replay: warning: {line}") == 1   # still once on stderr


# ------------------------------------------------------------------ 2. file keys no file read uses
_PLAN = str(Path(__file__).resolve().parent / "data" / "missions" / "qgc_simple_square.plan")
_NO_FILE = "there is no mission file (--plan or mission.file)"


@pytest.mark.parametrize("argv, text", [
    (["mission", "--dry-run", "--set", 'mission.from_log="flown"'],
     f"--set mission.from_log='flown' is invalid: it chooses what a flight log read as the mission file gives (its "
     f"uploaded mission or its flown track), and {_NO_FILE}; valid: a flight log (.tlog, .bin, .log, .ulg) as --plan "
     "or mission.file, or leave the key out"),
    (["mission", "--dry-run", "--plan", _PLAN, "--set", 'mission.from_log="uploaded"'],
     "--set mission.from_log='uploaded' is invalid: it chooses what a flight log read as the mission file gives (its "
     "uploaded mission or its flown track), and the mission file 'qgc_simple_square.plan' is not a log; valid: "),
    (["mission", "--dry-run", "--set", "mission.pad_radius_m=50"],
     f"--set mission.pad_radius_m=50 is invalid: it chooses which loiters of a mission file charge at a pad, and "
     f"{_NO_FILE}; valid: a mission file, or leave the key out (a config's [[waypoints]] charge with action = "
     '"charge")'),
    (["telemetry", "--set", "mission.pad_radius_m=50", "--duration", "1"], "--set mission.pad_radius_m=50 is invalid"),
])
def test_a_file_key_no_file_read_uses_is_refused(capsys, argv, text):
    """Before: exit 0, the value changed nothing (a .plan is read whatever from_log says; pad_radius_m picks which
    loiters of a mission file charge, and there was none)."""
    line = _one_error_line(capsys, argv)
    assert line.startswith(f"dronewpt {argv[0]}: error: {text}"), line


def test_the_file_keys_with_a_log_as_mission_file_still_run(capsys):
    """The keys where they are read: a log as ``--plan`` (``from_log``, ``pad_radius_m``) and a .plan
    (``pad_radius_m``): exit 0."""
    log = _LOG
    assert main(["mission", "--dry-run", "--plan", log, "--set", 'mission.from_log="flown"',
                 "--set", "mission.pad_radius_m=20"]) == 0
    assert main(["mission", "--dry-run", "--plan", _PLAN, "--set", "mission.pad_radius_m=20"]) == 0
    capsys.readouterr()


# ------------------------------------------------------------------ 3. a route's pattern keys in a config file
_ROUTE = '[[waypoints]]\naction = "loiter"\nx_m = 10.0\nz_m = 20.0\nhold_s = 5.0\n'
_UNUSED = ("is invalid: the mission flies a route (--plan, mission.file or [[waypoints]]), which never reads it (the "
           "built-in pattern's, as are ")


@pytest.mark.parametrize("body, plan, key", [
    ("[mission]\ncruise_altitude_m = 60.0\n" + _ROUTE, False, "mission.cruise_altitude_m=60.0"),
    ("[mission]\nland_y_m = 3.0\n" + _ROUTE, False, "mission.land_y_m=3.0"),
    ("[mission]\nhover_time_s = 30.0\n", True, "mission.hover_time_s=30.0"),   # the route is --plan's
])
def test_a_config_files_pattern_key_under_a_route_is_refused_as_sets(capsys, tmp_path, body, plan, key):
    """Before: exit 0, the route flown, the file's value ignored (``--set`` of the same key was refused)."""
    (tmp_path / "r.toml").write_text(body)
    argv = ["mission", str(tmp_path / "r.toml"), "--dry-run"] + (["--plan", _PLAN] if plan else [])
    line = _one_error_line(capsys, argv)
    assert line.startswith(f"dronewpt mission: error: config file {str(tmp_path / 'r.toml')!r}: {key} {_UNUSED}"), line


def test_a_config_file_without_its_pattern_keys_still_flies_its_route(capsys, tmp_path):
    """Only the keys the user's file sets are refused (the default laid under it has every key): a route file with other
    [mission] keys, and a pattern key without a route, run."""
    (tmp_path / "r.toml").write_text("[mission]\ncruise_speed_m_s = 6.0\n" + _ROUTE)
    (tmp_path / "alt.toml").write_text("[mission]\ncruise_altitude_m = 60.0\n")
    assert main(["mission", str(tmp_path / "r.toml"), "--dry-run"]) == 0
    assert main(["mission", str(tmp_path / "alt.toml"), "--dry-run"]) == 0
    capsys.readouterr()


# ------------------------------------------------------------------ 4. a re-flight makes the logged track once
def test_a_refly_makes_the_logged_track_once(capsys, tmp_path, monkeypatch):
    """``replay LOG --pads`` cut the log to its window and made the logged track three times (the origin, the plan
    checked for its errors, the plan again in ``refly_log``): three window checks. Now once, the same outputs."""
    import mission_sim.mavlink.replay as rp
    calls = {"track_from_log": 0, "check_window": 0}
    for name in calls:
        def counted(*a, _f=getattr(rp, name), _n=name, **k):
            calls[_n] += 1
            return _f(*a, **k)
        monkeypatch.setattr(rp, name, counted)
    pads = Path(__file__).resolve().parent / "data" / "missions" / "dronekit_flight_pads.csv"
    argv = ["replay", _LOG, "--pads", str(pads), "--window", "440,620", "--out", str(tmp_path / "o"), "--format", "json",
            "--no-progress", "--no-plot", "--set", "battery.n_series=3", "--ground-gap", "0.3"]
    assert main(argv) == 0
    assert calls == {"track_from_log": 1, "check_window": 1}
    assert len(json.loads(capsys.readouterr().out)["detours"]) == 2


def test_plan_refly_on_a_given_track_is_the_plan_made_from_the_log():
    """``plan_refly(..., track=T)`` (T made at another ground gap) gives the plan it makes from the log, bit for bit."""
    import numpy as np

    from mission_sim.config import config_to_dict, config_from_dict, load_config
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import track_from_log
    from mission_sim.plans.pads import read_pads
    from mission_sim.plans.refly import plan_refly, refly_base
    log = read_log(_LOG)
    track = track_from_log(log, window=(440.0, 620.0))
    pads = read_pads(Path(__file__).resolve().parent / "data" / "missions" / "dronekit_flight_pads.csv")
    cfg = config_from_dict(refly_base(config_to_dict(load_config()), pads, track.pad))
    kw = dict(pad=track.pad, window=(440.0, 620.0), ground_gap_m=0.3)
    made, given = plan_refly(log, cfg, **kw), plan_refly(log, cfg, track=track, **kw)
    for a, b in zip((made[0].t_s, made[0].pos_m, made[0].tilt_rad, made[0].armed, made[1]),
                    (given[0].t_s, given[0].pos_m, given[0].tilt_rad, given[0].armed, given[1])):
        assert a.tobytes() == b.tobytes()
    assert made[0].ground_gap_m == given[0].ground_gap_m == 0.3 and made[2:] == given[2:]
    assert not np.array_equal(track.pos_m[:, 2], track_from_log(log, window=(440.0, 620.0), ground_gap_m=0.3).pos_m[:, 2])

