"""A demanding newcomer's bad inputs (2026-11-27 midday; docs/robustness.md, "Newcomer's bad inputs
(2026-11-27 midday)"): each test failed on the tree before its fix (``main``)."""

from __future__ import annotations

import pytest

from _cli_helpers import one_error_line as _one_error_line
from mission_sim.cli import main


# ------------------------------------------------------------------ paper / netlist / export-controller --link
@pytest.mark.parametrize("argv, text", [
    # a KeyError traceback (the "given twice" check compared nan with itself), exit 1
    (["paper", "--no-plot", "--link", "lm_h=nan"], "--link lm_h=nan is invalid; valid range: (0, 1] H"),
    (["netlist", "--link", "f_hz=nan"], "--link f_hz=nan is invalid; valid range: [10000, 3e+07] Hz"),
    (["export-controller", "--link", "vl_v=nan"], "--link vl_v=nan is invalid; valid range: (0, 1000] V"),
    # a ZeroDivisionError traceback
    (["paper", "--no-plot", "--link", "f_hz=1e-300"], "--link f_hz=1e-300 is invalid; valid range: [10000, 3e+07] Hz"),
    # RuntimeWarnings (overflow), then "i2_a[0]=nan at t_s=0.0 is not finite" naming no input
    (["paper", "--no-plot", "--link", "vdc_v=1e308"], "--link vdc_v=1e+308 is invalid; valid range: (0, 1000] V"),
    (["paper", "--no-plot", "--link", "r1_ohm=1e308"], "--link r1_ohm=1e+308 is invalid; valid range: [1e-06, 100] ohm"),
    # "c1_f=0.0 is invalid" (a derived value, not the one given)
    (["paper", "--no-plot", "--link", "l1_h=1e308"], "--link l1_h=1e+308 is invalid; valid range: [1e-09, 1] H"),
])
def test_link_values_are_checked_where_read(capsys, argv, text):
    line = _one_error_line(capsys, argv)
    assert text in line, line


def test_link_ranges_are_the_mission_configs_where_it_has_the_key():
    """One source: ``--link vdc_v`` / ``r1_ohm`` / ``r2_ohm`` / ``f_hz`` take the mission's ``[link]`` ranges."""
    from mission_sim.config import LINK_PARAM_RANGES, PLAUSIBLE
    from wpt_receiver import TABLE_I
    for key in ("vdc_v", "r1_ohm", "r2_ohm", "f_hz"):
        assert LINK_PARAM_RANGES[key] is PLAUSIBLE[f"link.{key}"]
    for key, rng in LINK_PARAM_RANGES.items():   # Table I inside every range
        assert rng.contains(getattr(TABLE_I, key)), key


# ------------------------------------------------------------------ a route's speeds and holds
_HOME = ("QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\t-35.363262\t149.165237\t584.09\t1\n"
         "1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t20\t1\n")
_LEG = "\t0\t3\t16\t0\t0\t0\t0\t-35.362656\t149.165072\t20\t1\n"
_LEG2 = "\t0\t3\t16\t0\t0\t0\t0\t-35.360174\t149.167908\t14\t1\n"


def _wpl(tmp_path, *rows) -> str:
    path = tmp_path / "m.waypoints"
    path.write_text(_HOME + "".join(f"{i + 2}{row}" for i, row in enumerate(rows)))
    return str(path)


def _speed_row(v: str) -> str:
    return f"\t0\t0\t178\t1\t{v}\t0\t0\t0\t0\t0\t1\n"


@pytest.mark.parametrize("rows, text", [
    # DO_CHANGE_SPEED 1e308 m/s: flown (the check was > 0), where mission.cruise_speed_m_s stops at 100 m/s
    ((_LEG, _speed_row("1e308"), _LEG2),
     "m.waypoints: row 3: DO_CHANGE_SPEED speed param2=1e+308 is invalid; valid range: (0, 100] m/s"),
    # a hold the run-size check blamed on "waypoints.hold_s" (no row); pads' hover times stop at 1e6 s
    (("\t0\t3\t19\t1e308\t0\t0\t0\t-35.362656\t149.165072\t20\t1\n",),
     "m.waypoints: row 2: hold time param1=1e+308 is invalid; valid range: [0, 1e+06] s"),
    # a slow speed: "mission.cruise_speed_m_s=8.0 makes the run too large" (a key nobody changed)
    ((_LEG, _speed_row("1e-9"), _LEG2), "waypoints.2.speed_m_s=1e-09 makes the run too large"),
    # an altitude of 1e308: the message printed it in 309 digits
    (("\t0\t3\t16\t0\t0\t0\t0\t-35.362656\t149.165072\t1e308\t1\n",),
     "m.waypoints: row 2: altitude 1e+308 m (above home) is 1e+308 m above home; valid range: [0, 5000] m above home"),
])
def test_mission_file_speeds_holds_and_heights(capsys, tmp_path, rows, text):
    line = _one_error_line(capsys, ["mission", "--plan", _wpl(tmp_path, *rows), "--no-charge", "--dry-run"])
    assert text in line, line
    assert len(line) < 400


def test_do_change_speed_in_range_and_no_change_still_fly(capsys, tmp_path):
    """-1 / 0 (MAVLink's "no change", as ArduCopter) and 100 m/s, the top of the range, are taken as before."""
    for v in ("-1", "0", "100"):
        assert main(["mission", "--plan", _wpl(tmp_path, _LEG, _speed_row(v), _LEG2), "--no-charge", "--dry-run"]) == 0
    capsys.readouterr()


@pytest.mark.parametrize("extra, text", [
    ('speed_m_s = 1e308', "waypoints.1.speed_m_s=1e+308 is invalid; valid range: (0, 100] m/s"),
    ('speed_m_s = 150.0', "waypoints.1.speed_m_s=150.0 is invalid; valid range: (0, 100] m/s"),
    ('hold_s = 1e7', "waypoints.1.hold_s=10000000.0 is invalid; valid range: [0, 1e+06] s"),
    ('speed_m_s = 1e-9', "waypoints.1.speed_m_s=1e-09 makes the run too large"),
])
def test_toml_waypoint_speed_and_hold(capsys, tmp_path, extra, text):
    cfg = tmp_path / "route.toml"
    cfg.write_text('[[waypoints]]\naction = "takeoff"\nz_m = 20.0\n'
                   f'[[waypoints]]\naction = "loiter"\nx_m = 50.0\ny_m = 0.0\nz_m = 20.0\n{extra}\n')
    line = _one_error_line(capsys, ["mission", str(cfg), "--dry-run"])
    assert text in line, line


def test_waypoint_ranges_from_python():
    """``dataclasses.replace`` with a route is checked as a file is (the route's sections were only type-checked)."""
    import dataclasses

    from mission_sim.config import WaypointConfig, load_config
    cfg = load_config()
    with pytest.raises(ValueError, match=r"^speed_m_s=1e\+308 is invalid; valid range: \(0, 100\] m/s$"):
        WaypointConfig(action="waypoint", x_m=50.0, z_m=20.0, speed_m_s=1e308)   # (the section's own check)
    fast = WaypointConfig(action="waypoint", x_m=50.0, z_m=20.0, speed_m_s=100.0)
    object.__setattr__(fast, "speed_m_s", 1e308)   # (past its own check: the tree's is the other line of defence)
    with pytest.raises(ValueError, match=r"waypoints\.1\.speed_m_s=1e\+308 is invalid; valid range: \(0, 100\] m/s"):
        dataclasses.replace(cfg, waypoints=(WaypointConfig(action="takeoff", z_m=20.0), fast))
    ok = dataclasses.replace(fast, speed_m_s=12.0)
    assert dataclasses.replace(cfg, waypoints=(ok,)).waypoints == (ok,)


@pytest.mark.parametrize("cls, kw, text", [
    # said [0, inf) (a -1 hold: the range a route's hold does not have), 2e6 built and failed later as another key
    ("WaypointConfig", {"hold_s": -1.0}, "hold_s=-1.0 is invalid; valid range: [0, 1e+06] s"),
    ("WaypointConfig", {"hold_s": 2e6}, "hold_s=2000000.0 is invalid; valid range: [0, 1e+06] s"),
    ("WaypointConfig", {"speed_m_s": 101.0}, "speed_m_s=101.0 is invalid; valid range: (0, 100] m/s"),
    ("WaypointConfig", {"z_m": 5001.0}, "z_m=5001.0 is invalid; valid range: [0, 5000] m above home"),
    ("PadConfig", {"hover_time_s": -1.0}, "hover_time_s=-1.0 is invalid; valid range: [0, 1e+06] s"),
    ("PadConfig", {"hover_time_s": 2e6}, "hover_time_s=2000000.0 is invalid; valid range: [0, 1e+06] s"),
])
def test_a_waypoint_and_a_pad_built_in_python_have_the_shared_ranges(cls, kw, text):
    """One range each (``mission_sim.validation``: HOLD_RANGE, SPEED_RANGE, ALT_RANGE), as the files are read."""
    import mission_sim.config as mc
    from mission_sim.validation import ALT_RANGE, HOLD_RANGE, SPEED_RANGE
    with pytest.raises(ValueError) as exc:
        getattr(mc, cls)(**kw)
    assert str(exc.value) == text
    assert mc.PLAUSIBLE["waypoints.hold_s"] is HOLD_RANGE and mc.PLAUSIBLE["waypoints.speed_m_s"] is SPEED_RANGE
    assert ALT_RANGE.text() == "[0, 5000] m above home"
    assert mc.WaypointConfig(hold_s=1e6, speed_m_s=100.0, z_m=5000.0).hold_s == 1e6   # the ends are in


# ------------------------------------------------------------------ pads files: hover times
_SQUARE = str(__import__("pathlib").Path(__file__).resolve().parent / "data" / "missions" / "qgc_simple_square.plan")


def _feature(props: str) -> str:
    return ('{"type":"FeatureCollection","features":[{"type":"Feature","geometry":{"type":"Point",'
            f'"coordinates":[8.5456,47.3977]}},"properties":{props}}}]}}')


@pytest.mark.parametrize("name, text, expected", [
    # the reader said [0, inf) s; 1e308 then failed in the config as "pads.0.hover_time_s=1e+308 ..." (no file, line)
    ("p.csv", "lat,lon,hover_time_s\n47.3977,8.5456,1e308\n",
     "p.csv: line 2: hover_time_s='1e308' is invalid; valid range: [0, 1e+06] s"),
    ("p.csv", "lat,lon,hover_time_s\n47.3977,8.5456,-5\n", "p.csv: line 2: hover_time_s='-5' is invalid; valid range: [0, 1e+06] s"),
    ("p.geojson", _feature('{"hover_time_s":1e308}'),
     "p.geojson: feature 0: hover_time_s=1e+308 is invalid; valid range: [0, 1e+06] s"),
    # JSON's true was float(True): a 1 s hover
    ("p.geojson", _feature('{"hover_time_s":true}'),
     "p.geojson: feature 0: hover_time_s=true is invalid; valid range: [0, 1e+06] s, a JSON number"),
])
def test_pad_hover_times_take_the_configs_range_where_read(capsys, tmp_path, name, text, expected):
    (tmp_path / name).write_text(text)
    line = _one_error_line(capsys, ["mission", "--plan", _SQUARE, "--pads", str(tmp_path / name), "--dry-run"])
    assert expected in line, line


def test_pad_hover_time_at_the_top_of_the_range_is_read(tmp_path):
    from mission_sim.plans.pads import read_pads
    (tmp_path / "p.csv").write_text("lat,lon,hover_time_s\n47.3977,8.5456,1e6\n47.3978,8.5456,0\n")
    assert [p.hover_time_s for p in read_pads(tmp_path / "p.csv")] == [1e6, 0.0]


def test_pad_radius_read_with_a_mission_file_has_the_configs_range(capsys, tmp_path):
    """The file reader's own check said (0, inf) m, the config (0, 1000] m: one range now."""
    cfg = tmp_path / "m.toml"
    cfg.write_text(f'[mission]\nfile = "{_SQUARE}"\npad_radius_m = 0\n')
    assert "mission.pad_radius_m=0 is invalid; valid range: (0, 1000] m" in _one_error_line(capsys, ["mission", str(cfg), "--dry-run"])


# ------------------------------------------------------------------ a route over a raised pad
def test_a_route_over_a_roof_pad_is_not_refused_for_the_cruise_altitude(capsys, tmp_path):
    """A pad on a 30 m roof (pads file alt = home + 30 m) under a route loitering at 40 m was refused: "mission.
    cruise_altitude_m=5.0 is invalid; valid range: > pads.0.z_m + mission.hover_gap_m = 30.17 m", a key only the
    built-in pattern reads. Now the route charges there; its charge items still have to be above their pads."""
    import json

    from mission_sim.config import config_from_dict, load_config_dict
    from mission_sim.world.trajectory import _segments
    plan = json.loads(open(_SQUARE).read())
    plan["mission"]["items"][1].update(command=19, params=[30, 0, 0, None, 47.397742, 8.545594, 40])
    (tmp_path / "roof.plan").write_text(json.dumps(plan))
    (tmp_path / "roof.csv").write_text("lat,lon,alt\n47.397742,8.545594,518\n")   # the plan's home: 488 m AMSL
    cfg = config_from_dict(load_config_dict(None, tmp_path / "roof.plan", tmp_path / "roof.csv"))
    assert cfg.pads[0].z_m == pytest.approx(30.0, abs=1e-6) and cfg.mission.cruise_altitude_m == 5.0
    charge = [s for s in _segments(cfg) if s[0] == "charge"]
    assert len(charge) == 1 and charge[0][3] == 30.0 and charge[0][1][2] == pytest.approx(30.0 + cfg.mission.hover_gap_m)
    assert main(["mission", "--plan", str(tmp_path / "roof.plan"), "--pads", str(tmp_path / "roof.csv"), "--dry-run"]) == 0
    capsys.readouterr()
    low = tmp_path / "low.toml"   # a charge item below its pad: still refused, naming the item
    low.write_text('[[pads]]\nz_m = 30.0\n[[waypoints]]\naction = "charge"\npad = 0\nz_m = 20.0\nhold_s = 10.0\n')
    assert "waypoints.0.z_m=20.0 is invalid; valid range: > pads.0.z_m + mission.hover_gap_m = 30.17 m" in \
        _one_error_line(capsys, ["mission", str(low), "--dry-run"])
    assert "mission.cruise_altitude_m=5.0 is invalid" in _one_error_line(   # the built-in pattern: as before
        capsys, ["mission", "--set", "pads.0.z_m=7", "--dry-run"])


# ------------------------------------------------------------------ keys a route never reads
@pytest.mark.parametrize("argv, key", [
    (["mission", "--plan", _SQUARE, "--set", "mission.cruise_altitude_m=60", "--dry-run"], "mission.cruise_altitude_m=60"),
    (["mission", "--plan", _SQUARE, "--set", "mission.hover_time_s=100", "--dry-run"], "mission.hover_time_s=100"),
    (["telemetry", "--plan", _SQUARE, "--set", "mission.land_x_m=5", "--connect", "none", "--tlog", "x.tlog"],
     "mission.land_x_m=5"),
])
def test_set_of_a_key_a_route_never_reads_is_refused(capsys, tmp_path, monkeypatch, argv, key):
    """``--plan survey.plan --set mission.cruise_altitude_m=60`` flew the plan's 20 m, exit 0: only the built-in
    pattern reads the cruise altitude, the landing spot and mission.hover_time_s."""
    monkeypatch.chdir(tmp_path)
    line = _one_error_line(capsys, argv)
    assert f"--set {key} is invalid: the mission flies a route" in line, line
    assert line.endswith("valid: pads.<i>.hover_time_s (a charge's hover), or the file's loiter times ([[waypoints]] "
                         "hold_s)" if "hover_time_s" in key else "or leave the key out"), line   # (--set keys)
    assert not (tmp_path / "x.tlog").exists()


def test_keys_a_route_reads_and_the_patterns_keys_without_a_route_still_work(capsys):
    assert main(["mission", "--plan", _SQUARE, "--set", "mission.start_x_m=5", "--set", "mission.cruise_speed_m_s=5",
                 "--dry-run"]) == 0
    assert main(["mission", "--set", "mission.cruise_altitude_m=60", "--set", "mission.hover_time_s=10", "--dry-run"]) == 0
    capsys.readouterr()


def test_a_study_varying_a_key_its_route_never_reads_is_refused(capsys, tmp_path):
    """Every case the same mission (the cruise altitude of a base mission that flies a route), before: 2 cases run."""
    (tmp_path / "route.toml").write_text('[[waypoints]]\naction = "loiter"\nx_m = 10.0\nz_m = 20.0\nhold_s = 5.0\n')
    (tmp_path / "s.toml").write_text('[study]\nname = "alt"\nbase = "route.toml"\n[grid]\n'
                                     '"mission.cruise_altitude_m" = [5.0, 50.0]\n')
    line = _one_error_line(capsys, ["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out"), "--workers", "0",
                                    "--no-plot"])
    assert "study key mission.cruise_altitude_m is invalid: the mission flies a route" in line, line
    assert not (tmp_path / "out" / "cases").exists()


# ------------------------------------------------------------------ a pads file's altitude in another frame
def test_a_pad_far_above_or_below_home_warns(tmp_path):
    """``alt = 0`` (meant as "on the ground") at the plan's home 488 m AMSL: the pad 488 m below home, and a route
    loitering over it flew down there to charge (941.6 s, 87.6 kJ of propulsion instead of ~165 s), no word."""
    from mission_sim.config import config_from_dict, load_config_dict
    from mission_sim.setup_warnings import far_pad_warnings, mission_warnings
    (tmp_path / "p.csv").write_text("lat,lon,alt\n47.397742,8.545594,0\n47.398742,8.546594,518\n")
    cfg = config_from_dict(load_config_dict(None, _SQUARE, tmp_path / "p.csv"))
    assert far_pad_warnings(cfg) == [
        "pads.0.z_m=-488 is outside +-120 m of the mission's home (the pad is 488 m below it: a drone charging there "
        "flies up or down to it); valid: a pad's height within +-120 m of it (a pads file's alt in metres above mean "
        "sea level, not above the ground, not feet; [[pads]] z_m and --set pads.<i>.z_m in metres above it)"]
    assert far_pad_warnings(config_from_dict(load_config_dict())) == []   # the default mission: no warning
    assert far_pad_warnings(cfg)[0] in mission_warnings(cfg)
    # whatever the route: a replayed trajectory's pads are about the replay's pad frame origin
    assert far_pad_warnings(cfg)[0] in mission_warnings(cfg, own_route=False)
    replayed = [w for w in mission_warnings(cfg, own_route=False, replay=True) if "+-120 m" in w]
    assert replayed == [far_pad_warnings(cfg)[0].replace("the mission's home", "the replay's pad frame origin")]


def test_a_far_pad_under_a_replay_refly_warns(capsys, tmp_path):
    """``replay --pads`` with a pads file's ``alt = 0`` (150 m below the ``--pad`` origin): the detour flew down there
    and back (+911 s here; +1918 s and an empty battery at the take-off spot's altitude), without a word."""
    (tmp_path / "low.csv").write_text("lat,lon,alt,hover_time_s\n-35.3620800,149.1658531,0,10\n")
    argv = ["replay", _LOG, "--pads", str(tmp_path / "low.csv"), "--pad=-35.36208,149.1658531,150", "--window",
            "440,620", "--no-plot", "--format", "json", "--no-progress", "--out", str(tmp_path / "o"),
            "--set", "battery.n_series=3"]
    assert main(argv) == 0
    far = [ln for ln in capsys.readouterr().err.splitlines() if "+-120 m" in ln]
    assert far == ["dronewpt replay: warning: pads.0.z_m=-150 is outside +-120 m of the replay's pad frame origin (the "
                   "pad is 150 m below it: a drone charging there flies up or down to it); valid: a pad's height within "
                   "+-120 m of it (a pads file's alt in metres above mean sea level, not above the ground, not feet; "
                   "[[pads]] z_m and --set pads.<i>.z_m in metres above it)"], far


def test_replay_refuses_the_built_in_patterns_keys(capsys):
    """``replay LOG --set mission.cruise_altitude_m=60`` replayed the log's track, the value ignored, exit 0;
    ``mission.hover_time_s`` is refused without ``--pads`` only (a re-flight's default hover)."""
    from pathlib import Path
    log = str(Path(__file__).resolve().parent / "data" / "flightlogs" / "dronekit-python_flight.tlog")
    for key in ("mission.cruise_altitude_m=60", "mission.land_y_m=3", "mission.hover_time_s=30"):
        line = _one_error_line(capsys, ["replay", log, "--window", "440,460", "--set", key, "--no-plot"])
        assert f"--set {key.partition('=')[0]} is not used by replay: the track, its heights" in line, line


# ------------------------------------------------------------------ reviewer's findings (2026-11-27, 13:00)
_LOG = str(__import__("pathlib").Path(__file__).resolve().parent / "data" / "flightlogs" / "dronekit-python_flight.tlog")


def test_a_roof_pad_under_a_replay_refly_charges(capsys, tmp_path):
    """A pad 30 m above the replay's pad frame origin (``--pad ...,500``, the pads file's ``alt = 530``): refused with
    "mission.cruise_altitude_m=5.0 is invalid; valid range: > pads.0.z_m + mission.hover_gap_m = 30.17 m" once the
    re-flight had no route, and ``--set mission.cruise_altitude_m`` (main's way round) is refused by replay. The
    re-flight never flies the built-in pattern: its base carries a cruise altitude above its pads."""
    import json
    (tmp_path / "roof.csv").write_text("lat,lon,alt,hover_time_s\n-35.3620800,149.1658531,530,30\n")
    argv = ["replay", _LOG, "--pads", str(tmp_path / "roof.csv"), "--pad=-35.36208,149.1658531,500", "--window",
            "440,620", "--no-plot", "--format", "json", "--no-progress", "--out", str(tmp_path / "o")]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["pads"] == [{"x_m": 0.0, "y_m": 0.0, "z_m": pytest.approx(30.0, abs=1e-6)}]
    assert [d["pad"] for d in s["detours"]] == [0] and s["detours"][0]["hover_s"] == 30.0
    assert 29.0 < s["charge_time_s"] <= 31.0 and s["battery_charge_in_j"] > 0
    from mission_sim.plans.pads import read_pads
    from mission_sim.plans.refly import refly_base
    from mission_sim.config import config_from_dict, config_to_dict, load_config
    from mission_sim.mavlink.geodesy import parse_geo_point
    base = config_to_dict(load_config())
    d = refly_base(base, read_pads(tmp_path / "roof.csv"), parse_geo_point("-35.36208,149.1658531,500"))
    assert d["mission"]["cruise_altitude_m"] == pytest.approx(32.0)   # 30 m + the hover gap's top 1 m + 1 m
    d["mission"]["hover_gap_m"] = 1.0   # (--set mission.hover_gap_m: any value in its range passes)
    assert config_from_dict(d).pads[0].z_m == pytest.approx(30.0)
    ground = read_pads(_LOG.replace("flightlogs/dronekit-python_flight.tlog", "missions/dronekit_flight_pads.csv"))
    d = refly_base(base, ground, parse_geo_point("-35.36208,149.1658531,500"))   # pads on the ground (z = 0)
    assert d["mission"] == base["mission"] | {"file": ""}   # the base's mission as it was


def test_link_at_an_ism_frequency_above_10_mhz_still_runs(capsys):
    """``netlist --link f_hz=13.56e6`` (the 13.56 MHz ISM band) ran on main; the mission ``link.f_hz`` range (10 MHz
    top) that ``--link`` takes was too narrow: it is [1e4, 3e7] Hz (6.78, 13.56, 27.12 MHz), one range for both."""
    from mission_sim.config import LINK_PARAM_RANGES, apply_overrides, config_from_dict, load_config_dict
    assert main(["netlist", "--link", "f_hz=13.56e6"]) == 0
    out = capsys.readouterr().out
    vinv = next(line for line in out.splitlines() if line.startswith("VINV "))   # PULSE(..., period)
    assert float(vinv.rstrip(")").split()[-1]) == pytest.approx(1 / 13.56e6, rel=1e-12), vinv
    for f in (6.78e6, 13.56e6, 27.12e6):
        assert LINK_PARAM_RANGES["f_hz"].contains(f)
        assert config_from_dict(apply_overrides(load_config_dict(), {"link.f_hz": f})).link.f_hz == f


@pytest.mark.parametrize("replay, grid, key", [
    # with pads: every case the same re-flight (the cruise altitude is the built-in pattern's), 2 cases ran
    ('pads = "{pads}"\n', '"mission.cruise_altitude_m" = [10.0, 50.0]', "mission.cruise_altitude_m"),
    # without pads: no hover to set (the track is the log's)
    ("", '"mission.hover_time_s" = [10.0, 20.0]', "mission.hover_time_s"),
])
def test_a_replay_study_refuses_the_keys_replay_set_refuses(capsys, tmp_path, replay, grid, key):
    """``[replay]`` studies refuse what ``replay --set`` refuses (``config.check_replay_keys``, one rule)."""
    from pathlib import Path
    pads = Path(_LOG).parents[1] / "missions" / "dronekit_flight_pads.csv"
    (tmp_path / "s.toml").write_text(f'[replay]\nlog = "{_LOG}"\n{replay.format(pads=pads)}window = [440.0, 460.0]\n'
                                     f"[grid]\n{grid}\n")
    line = _one_error_line(capsys, ["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers", "0",
                                    "--no-plot", "--no-progress"])
    assert f"study key {key} is not used by replay: the track, its heights and its landing are the log's" in line, line
    assert not (tmp_path / "o").exists()
    cli = _one_error_line(capsys, ["replay", _LOG, "--window", "440,460", "--no-plot", "--set", f"{key}=10"]
                          + (["--pads", str(pads)] if replay else []))
    assert cli.split(" is not used by replay", 1)[1] == line.split(" is not used by replay", 1)[1], (cli, line)


@pytest.mark.parametrize("d, key", [
    ({"waypoints": [{"action": "takeoff", "z_m": 20.0}, {"action": "loiter", "x_m": 50.0, "z_m": 20.0, "hold_s": 10.0},
                    {"action": "loiter", "x_m": 60.0, "z_m": 20.0, "hold_s": 1e6}]}, "waypoints.2.hold_s"),
    ({"pads": [{}], "waypoints": [{"action": "charge", "pad": 0, "z_m": 20.0, "hold_s": 1e6}]}, "waypoints.0.hold_s"),
    # the pad's hover time replaces the charge item's hold: it is the key
    ({"pads": [{"hover_time_s": 1e6}], "waypoints": [{"action": "charge", "pad": 0, "z_m": 20.0, "hold_s": 5.0}]},
     "pads.0.hover_time_s"),
])
def test_the_run_size_names_the_hold_that_makes_it(capsys, tmp_path, d, key):
    """A route's long hold was blamed on a bare ``waypoints.hold_s`` (no index; a pad's hover time too): the planned
    path records each hold's key (``_Path.keys``), as it does a waypoint's speed."""
    from mission_sim.config import config_from_dict
    from mission_sim.world.budget import estimate_run
    est = estimate_run(config_from_dict(d))
    assert (est.key, est.value) == (key, 1e6)
    if key == "pads.0.hover_time_s":   # the command's line names it too
        (tmp_path / "r.toml").write_text('[[pads]]\nhover_time_s = 1e6\n[[waypoints]]\naction = "charge"\npad = 0\n'
                                         'z_m = 20.0\nhold_s = 5.0\n')
        assert main(["mission", str(tmp_path / "r.toml"), "--dry-run"]) == 0
        assert "(largest contribution: pads.0.hover_time_s)" in capsys.readouterr().out
