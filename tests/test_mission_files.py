"""Mission files in (issue 24): QGC .plan / .waypoints / log missions fly through `dronewpt mission`
exactly as the hand-written TOML route of the same waypoints; pads files and loiters at pads;
survey grids; one-line errors (exit 2, nothing simulated) for every bad form.

The expected local coordinates are computed here independently of the project's geodesy (which
uses a tangent plane with the WGS84 radii of curvature): by the exact geodetic -> ECEF -> ENU
rotation. Over a few hundred metres the two agree to ~1 mm at 130 m and ~9 mm at 400 m (the
tangent plane's documented error), so the summaries agree to ~1e-5 relative; they are compared at
1e-4 (a wrong altitude frame, a swapped axis or an ignored speed changes them by percent).
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from mission_sim.cli import main

DATA = Path(__file__).resolve().parent / "data" / "missions"
FLIGHTLOGS = Path(__file__).resolve().parent / "data" / "flightlogs"


# ----------------------------------------------------------------------------- independent geodesy
def _ecef(lat_deg, lon_deg, h_m):
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    p, l = math.radians(lat_deg), math.radians(lon_deg)
    n = a / math.sqrt(1 - e2 * math.sin(p) ** 2)
    return np.array([(n + h_m) * math.cos(p) * math.cos(l), (n + h_m) * math.cos(p) * math.sin(l),
                     (n * (1 - e2) + h_m) * math.sin(p)])


def enu_xy(lat_deg, lon_deg, home):
    """(east, north) [m] of a point at the home's altitude, by the exact ECEF -> ENU rotation."""
    lat0, lon0, h0 = home
    d = _ecef(lat_deg, lon_deg, h0) - _ecef(lat0, lon0, h0)
    p, l = math.radians(lat0), math.radians(lon0)
    east = -math.sin(l) * d[0] + math.cos(l) * d[1]
    north = -math.sin(p) * math.cos(l) * d[0] - math.sin(p) * math.sin(l) * d[1] + math.cos(p) * d[2]
    return east, north


def _toml(waypoints, pads=None, extra="") -> str:
    lines = ["[mission]", "start_x_m = 0.0", "start_y_m = 0.0", extra]
    for p in pads or []:
        lines += ["[[pads]]"] + [f"{k} = {json.dumps(float(v))}" for k, v in p.items()]
    for w in waypoints:
        lines += ["[[waypoints]]"] + [f"{k} = {json.dumps(v if isinstance(v, (str, int)) else float(v))}" for k, v in w.items()]
    return "\n".join(lines) + "\n"


def _run(capsys, tmp_path, name, *argv) -> dict:
    out = tmp_path / name
    assert main(["mission", *argv, "--format", "json", "--no-plot", "--no-progress", "--out", str(out)]) == 0
    return json.loads(capsys.readouterr().out)


_SKIP = {"wall_s", "realtime_factor", "files", "policy"}


def _same_summary(a: dict, b: dict, rtol=1e-4):
    assert a.keys() == b.keys()
    for k in a:
        if k in _SKIP or a[k] is None or isinstance(a[k], (str, bool)):
            assert k in _SKIP or a[k] == b[k], k
            continue
        assert np.isclose(a[k], b[k], rtol=rtol, atol=1e-9), (k, a[k], b[k])


# ------------------------------------------------------------------------- same summary as the TOML
def test_qgc_plan_flies_as_the_handwritten_toml(capsys, tmp_path):
    """QGC's simple_square.plan: take-off to 20 m, four corners 20 m above home, no landing item
    (the route lands where it ends). The TOML writes the same route with ECEF-ENU coordinates."""
    home = (47.397742, 8.545594, 488.0)
    corners = [(47.398742, 8.546594), (47.398742, 8.544594), (47.396742, 8.544594), (47.396742, 8.546594)]
    wps = [{"action": "takeoff", "z_m": 20.0}]
    for lat, lon in corners:
        e, n = enu_xy(lat, lon, home)
        wps.append({"action": "waypoint", "x_m": e, "y_m": n, "z_m": 20.0})
    toml = tmp_path / "square.toml"
    toml.write_text(_toml(wps))
    from_file = _run(capsys, tmp_path, "plan", "--plan", str(DATA / "qgc_simple_square.plan"))
    by_hand = _run(capsys, tmp_path, "toml", str(toml))
    _same_summary(from_file, by_hand)
    # the route is what was flown: a closed 151 m x 222 m rectangle plus the legs from home to it
    legs = 2 * math.hypot(75.5, 111.2) / 2 + 151.0 + 222.4 + 151.0
    assert from_file["sim_time_s"] > legs / 8.0 + 2 * 20.0 / 2.0


def test_ardupilot_waypoints_with_speeds_and_rtl_fly_as_the_toml(capsys, tmp_path):
    """ArduPilot's DO_CHANGE_SPEED mission (QGC WPL 110): take-off at home (lat = lon = 0), legs at
    15 / 10 / 17 m/s set by DO_CHANGE_SPEED, relative altitudes 20 / 14 / 18 / 20 m, then RTL (home
    at max(height, 15 m), land)."""
    home = (-35.363262, 149.165237, 584.090027)
    rows = [(-35.362656, 149.165072, 20.0, None), (-35.360174, 149.167908, 14.0, 15.0),
            (-35.363296, 149.169244, 18.0, 10.0), (-35.364115, 149.165747, 20.0, 17.0)]
    wps = [{"action": "takeoff", "z_m": 20.0}]
    for lat, lon, z, v in rows:
        e, n = enu_xy(lat, lon, home)
        wps.append({"action": "waypoint", "x_m": e, "y_m": n, "z_m": z, **({"speed_m_s": v} if v else {})})
    wps += [{"action": "waypoint", "x_m": 0.0, "y_m": 0.0, "z_m": 20.0}, {"action": "land"}]
    toml = tmp_path / "speed.toml"
    toml.write_text(_toml(wps))
    from_file = _run(capsys, tmp_path, "wpl", "--plan", str(DATA / "ardupilot_do_change_speed.waypoints"))
    by_hand = _run(capsys, tmp_path, "toml", str(toml))
    _same_summary(from_file, by_hand)
    # the speeds matter: the same route at the config's 8 m/s takes longer (the 15/10/17 m/s legs)
    slow = [{k: v for k, v in w.items() if k != "speed_m_s"} for w in wps]
    toml.write_text(_toml(slow))
    at_cruise = _run(capsys, tmp_path, "slow", str(toml))
    assert at_cruise["sim_time_s"] > from_file["sim_time_s"] + 20


def test_config_file_key_reads_relative_to_the_toml(capsys, tmp_path):
    """``[mission] file = ...`` in a config is the same as ``--plan`` (path relative to the TOML)."""
    (tmp_path / "m.plan").write_bytes((DATA / "qgc_simple_square.plan").read_bytes())
    cfg = tmp_path / "c.toml"
    cfg.write_text('[mission]\nfile = "m.plan"\n')
    a = _run(capsys, tmp_path, "a", str(cfg))
    b = _run(capsys, tmp_path, "b", "--plan", str(DATA / "qgc_simple_square.plan"))
    _same_summary(a, b)


# ------------------------------------------------------------------------------------ pads
def _plan(items, home=(47.0, 8.0, 500.0)) -> dict:
    return {"fileType": "Plan", "version": 1, "mission": {"version": 2, "plannedHomePosition": list(home),
                                                          "items": items}}


def _item(cmd, lat=0.0, lon=0.0, alt=0.0, p1=0.0, frame=3):
    return {"type": "SimpleItem", "command": cmd, "frame": frame, "params": [p1, 0, 0, None, lat, lon, alt]}


def test_loiter_at_a_pad_charges_there(capsys, tmp_path):
    """A 60 s loiter 3 m from a pad of the pads file (within pad_radius_m = 5) becomes a charging
    hover over the pad: the same summary as the TOML route with a "charge" waypoint, energy from
    the pad, and a positive flight-time gain; the pad 40 m away (beyond the radius) gives nothing."""
    home = (47.0, 8.0, 500.0)
    pad_ll = (47.0 + 30 / 111_200.0, 8.0 + 20 / 75_840.0)   # ~ (20 m E, 30 m N)
    loiter_ll = (pad_ll[0] + 3 / 111_200.0, pad_ll[1])        # 3 m north of the pad
    plan = tmp_path / "p.plan"
    plan.write_text(json.dumps(_plan([_item(22, *home[:2], 12.0), _item(19, *loiter_ll, 12.0, p1=60.0),
                                      _item(20)], home)))
    pads = tmp_path / "pads.csv"
    pads.write_text(f"lat,lon\n{pad_ll[0]},{pad_ll[1]}\n")
    from_file = _run(capsys, tmp_path, "f", "--plan", str(plan), "--pads", str(pads))
    e, n = enu_xy(*pad_ll, home)
    wps = [{"action": "takeoff", "z_m": 12.0}, {"action": "charge", "pad": 0, "x_m": e, "y_m": n, "z_m": 12.0,
                                                 "hold_s": 60.0},
           {"action": "waypoint", "x_m": 0.0, "y_m": 0.0, "z_m": 15.0}, {"action": "land"}]
    toml = tmp_path / "t.toml"
    toml.write_text(_toml([wps[0], wps[1], {**wps[2], "x_m": e, "y_m": n}, {**wps[2]}, wps[3]],
                          pads=[{"x_m": e, "y_m": n, "z_m": 0.0}]))
    by_hand = _run(capsys, tmp_path, "t", str(toml))
    _same_summary(from_file, by_hand)
    assert from_file["charge_time_s"] > 50 and from_file["battery_charge_in_j"] > 0
    assert from_file["final_soc"] > from_file["final_soc_without_charging"]
    assert from_file["flight_time_gain_s"] > 0
    far = tmp_path / "far.csv"
    far.write_text(f"lat,lon\n{pad_ll[0] + 40 / 111_200.0},{pad_ll[1]}\n")
    away = _run(capsys, tmp_path, "far", "--plan", str(plan), "--pads", str(far))
    assert away["charge_time_s"] == 0 and abs(away["flight_time_gain_s"]) < 0.1
    assert away["final_soc"] < from_file["final_soc"]


def test_geojson_pads_equal_csv_pads(tmp_path):
    from mission_sim.plans.pads import read_pads
    csv = tmp_path / "p.csv"
    csv.write_text("latitude,longitude,alt,hover_time_s\n47.1,8.2,510,30\n47.2,8.3,,\n")
    gj = tmp_path / "p.geojson"
    gj.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [8.2, 47.1, 510]},
         "properties": {"hover_time_s": 30}},
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [8.3, 47.2]}, "properties": {}}]}))
    assert read_pads(csv) == read_pads(gj)
    assert read_pads(csv)[0].point.alt_m == 510 and read_pads(csv)[1].hover_time_s is None


# ------------------------------------------------------------------------ surveys and logs
def test_survey_complex_item_flies_its_generated_waypoints(tmp_path):
    """A survey ComplexItem: its generated Items when present, else its VisualTransectPoints at the
    camera's DistanceToSurface (relative to home)."""
    from mission_sim.plans.items import read_plan
    from mission_sim.plans.route import route_from_items
    home = (47.0, 8.0, 500.0)
    pts = [[47.0005, 8.0005], [47.0015, 8.0005], [47.0015, 8.0010], [47.0005, 8.0010]]
    survey = {"type": "ComplexItem", "complexItemType": "survey", "TransectStyleComplexItem": {
        "CameraCalc": {"DistanceToSurface": 35, "DistanceToSurfaceRelative": True}, "Items": [],
        "VisualTransectPoints": pts}}
    p = tmp_path / "s.plan"
    p.write_text(json.dumps(_plan([_item(22, *home[:2], 35.0), survey], home)))
    route = route_from_items(read_plan(p))
    assert [w["action"] for w in route] == ["takeoff"] + ["waypoint"] * 4
    for w, (lat, lon) in zip(route[1:], pts):
        e, n = enu_xy(lat, lon, home)
        assert abs(w["x_m"] - e) < 5e-3 and abs(w["y_m"] - n) < 5e-3 and w["z_m"] == 35.0
    survey["TransectStyleComplexItem"]["Items"] = [_item(16, 47.0005, 8.0005, 40.0), _item(206),
                                                   _item(16, 47.0015, 8.0005, 40.0)]
    p.write_text(json.dumps(_plan([_item(22, *home[:2], 35.0), survey], home)))
    assert [w["z_m"] for w in route_from_items(read_plan(p))] == [35.0, 40.0, 40.0]


def test_mission_uploaded_in_a_tlog(capsys, tmp_path):
    """The mission an ArduPlane SITL vehicle held (MISSION_ITEM_INT / MISSION_ITEM read back by the
    ground station): home = item 0, take-off to 20 m, a waypoint at altitude 0 (= current height),
    CONDITION_YAW (ignored), a 5 s loiter "here"; it flies through `mission`."""
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.route import route_from_items
    raw = read_mission(DATA / "uavlogviewer_vtol_sitl_mission.tlog")
    route = route_from_items(raw)
    assert [w["action"] for w in route] == ["takeoff", "waypoint", "loiter"]
    assert [w["z_m"] for w in route] == [20.0, 20.0, 20.0] and route[2]["hold_s"] == 5.0
    assert route[2]["x_m"] == route[1]["x_m"]
    s = _run(capsys, tmp_path, "tlog", "--plan", str(DATA / "uavlogviewer_vtol_sitl_mission.tlog"))
    dist = math.hypot(route[1]["x_m"], route[1]["y_m"])
    assert s["sim_time_s"] > dist / 8.0 + 5.0 + 20 / 2.0 + 20 / 1.0


def test_flown_track_route_stays_within_tolerance():
    """The route a log flew (``from_log = "flown"``): every armed GPS sample lies within the
    decimation tolerance of the route's polyline."""
    from mission_sim.mavlink.geodesy import geodetic_to_enu
    from mission_sim.mavlink.logs import read_log
    from mission_sim.plans.items import FLOWN_TOLERANCE_M, _decimate, read_mission
    path = FLIGHTLOGS / "dronekit-python_flight.tlog"
    raw = read_mission(path, from_log="auto")          # this log holds no mission: its track
    assert "flown track" in raw.source and raw.items[-1].command == 21
    from mission_sim.plans.route import route_from_items
    route = route_from_items(raw)
    # it landed and took off again several times (7 armed periods): landings, never a leg along the ground
    assert sum(w["action"] == "land" for w in route) >= 3
    assert all(w["z_m"] >= 1.0 for w in route if w["action"] != "land")
    log = read_log(path)
    pos = log.position
    e, n, u = geodetic_to_enu(pos.lat_deg.to_numpy(), pos.lon_deg.to_numpy(), pos.alt_m.to_numpy(), raw.home)
    p = np.column_stack([e, n, u])
    keep = _decimate(p, FLOWN_TOLERANCE_M)
    assert 2 < len(keep) < len(p) / 5
    for a, b in zip(keep[:-1], keep[1:]):
        seg = p[b] - p[a]
        rel = p[a:b + 1] - p[a]
        L = np.linalg.norm(seg)
        d = np.linalg.norm(np.cross(rel, seg / L), axis=1) if L > 1e-9 else np.linalg.norm(rel, axis=1)
        assert d.max() <= FLOWN_TOLERANCE_M + 1e-9


# ------------------------------------------------------------------------------ bad forms
def _bad(capsys, tmp_path, argv, *needles):
    out = tmp_path / "out"
    assert main(["mission", *argv, "--no-progress", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for s in needles:
        assert s in err[0], err[0]
    assert not out.exists()   # nothing simulated, nothing written
    return err[0]


def test_deeply_nested_plan_is_one_line(capsys, tmp_path):
    """A .plan of JSON nested deeper than the parser's recursion (``'[' * 100000``) was a RecursionError traceback."""
    p = tmp_path / "deep.plan"
    p.write_text("[" * 100000)
    _bad(capsys, tmp_path, ["--plan", str(p)], "deep.plan: JSON nested deeper than the reader takes",
         "not a QGroundControl plan")


def test_malformed_json(capsys, tmp_path):
    p = tmp_path / "bad.plan"
    p.write_text('{"fileType": "Plan", "mission": {"items": [}')
    _bad(capsys, tmp_path, ["--plan", str(p)], "bad.plan", "malformed JSON", "line 1")


@pytest.mark.parametrize("name,needles", [
    ("ardupilot_cmac_copter_circuit.waypoints", ("row 6", "DO_JUMP repeats forever (param2 = -1)", "never end")),
    ("qgc_ardupilot_sitl_copter.plan", ("item 7", "frame 10", "terrain")),
])
def test_unsupported_items_in_real_files(capsys, tmp_path, name, needles):
    _bad(capsys, tmp_path, ["--plan", str(DATA / name)], name, *needles)


def test_unknown_command_named_with_its_index(capsys, tmp_path):
    p = tmp_path / "spline.plan"
    p.write_text(json.dumps(_plan([_item(22, 47.0, 8.0, 10.0), _item(16, 47.001, 8.0, 10.0),
                                   _item(82, 47.002, 8.0, 10.0)])))
    _bad(capsys, tmp_path, ["--plan", str(p)], "item 2", "NAV_SPLINE_WAYPOINT (82)", "not supported")


def test_missing_home(capsys, tmp_path):
    p = tmp_path / "nohome.plan"
    doc = _plan([_item(22, 47.0, 8.0, 10.0)])
    del doc["mission"]["plannedHomePosition"]
    p.write_text(json.dumps(doc))
    _bad(capsys, tmp_path, ["--plan", str(p)], "nohome.plan", "missing home")
    w = tmp_path / "nohome.waypoints"
    w.write_text("QGC WPL 110\n1\t0\t3\t16\t0\t0\t0\t0\t47.0\t8.0\t10\t1\n")
    _bad(capsys, tmp_path, ["--plan", str(w)], "nohome.waypoints", "missing home")


@pytest.mark.parametrize("text,needles", [
    ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47\t8\t500\t1\n1\t0\t3\t16\t0\t0\t0\n", ("line 3", "12")),
    ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47\t8\t500\t1\n1\t0\t3\t16\t0\t0\t0\t0\t47\tx\t10\t1\n", ("line 3", "not a number")),
    ("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47\t8\t500\t1\n1\t0\t0\t16\t0\t0\t0\t0\t47.001\t8\t450\t1\n", ("row 1", "above home")),
    ("hello\n", ("not a mission file",)),
])
def test_bad_waypoints_text(capsys, tmp_path, text, needles):
    p = tmp_path / "m.waypoints"
    p.write_text(text)
    _bad(capsys, tmp_path, ["--plan", str(p)], *needles)


@pytest.mark.parametrize("name,text,needles", [
    ("p.csv", "x,y\n1,2\n", ("no lat / lon column",)),
    ("p.csv", "lat,lon\n95,8\n", ("line 2", "latitude")),
    # a value past the header's columns (an altitude without an alt column) was dropped without a word
    # a misspelt column (hover_time for hover_time_s) was ignored: the default hover instead of the file's
    ("p.csv", "lat,lon,hover_time\n47,8,30\n", ("column 'hover_time' is unknown (did you mean 'hover_time_s'?)",
                                                "hover_time_s (hover_s)")),
    ("p.csv", "lat,lon\n47,8\n47.0001,8,5\n", ("line 3 has 3 values, the header 2 (lat,lon); valid: one value per "
                                                "header column",)),
    ("p.geojson", '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": '
                  '{"type": "LineString", "coordinates": [[8, 47], [8.1, 47]]}}]}', ("feature 0", "LineString")),
    ("p.geojson", '{"type": "FeatureCollection", "features": [', ("malformed JSON",)),
    # a misspelt GeoJSON property was ignored (the default hover instead of the file's), as CSV columns were
    ("p.geojson", '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Point", '
                  '"coordinates": [8, 47]}, "properties": {"name": "a", "hover_time": 30}}]}',
     ("feature 0: property 'hover_time' is unknown (did you mean 'hover_time_s'?); valid properties: hover_time_s",
      "other properties are ignored")),
    ("p.geojson", '{"type": "Point", "coordinates": [8, 47], "properties": {"hover_s": 30}}',
     ("feature 0: property 'hover_s' is unknown (did you mean 'hover_time_s'?)",)),
    ("p.geojson", '{"type": "Point", "coordinates": [8, 47], "properties": {"Hover_Time_S": 30}}',
     ("feature 0: property 'Hover_Time_S' is unknown (did you mean 'hover_time_s'?)",)),
    # an altitude property beside 2-D coordinates would leave the pad on the ground without a word
    ("p.geojson", '{"type": "Point", "coordinates": [8, 47], "properties": {"altitude": 512}}',
     ("property 'altitude' is ignored (did you mean the coordinates' alt? the feature's coordinates are 2-D",
      "[lon, lat, alt] in m AMSL")),
    ("p.geojson", '{"type": "MultiPoint", "coordinates": [[8, 47, 512], [8.1, 47]], "properties": {"ALT": 3}}',
     ("property 'ALT' is ignored (did you mean the coordinates' alt?",)),
    # 2026-11-27: properties not an object (null: none) were an AttributeError traceback (a list, a string, a number) or
    # nothing ([], 0); coordinates not JSON numbers were taken (true as 1.0 deg, "8.5" as 8.5); MultiPoint coordinates
    # not a list a TypeError; a feature without geometry "geometry type 'Feature' is not supported"
    *[("p.geojson", '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Point", '
                    '"coordinates": [8, 47, 512]}, "properties": %s}]}' % props,
       (f"p.geojson: feature 0: properties {shown} ({kind}) are not an object; valid: a JSON object {{...}} or null",))
      for props, shown, kind in (("[1, 2]", "[1, 2]", "array"), ("[]", "[]", "array"), ('"pad"', '"pad"', "string"),
                                 ("5", "5", "number"), ("0", "0", "number"))],
    ("p.geojson", '{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}}]}',
     ("p.geojson: feature 0: geometry null is not a geometry object (a feature without one has no location); valid: "
      "Point, MultiPoint",)),
    *[("p.geojson", '{"type": "Point", "coordinates": %s}' % c,
       (f"p.geojson: feature 0: coordinates {shown} are invalid; valid: [lon, lat] or [lon, lat, alt], JSON numbers",))
      for c, shown in (("[true, false, 512]", "[true, false, 512]"), ('["8.5", "47"]', '["8.5", "47"]'))],
    ("p.geojson", '{"type": "MultiPoint", "coordinates": 5}',
     ("p.geojson: feature 0: MultiPoint coordinates 5 are invalid; valid: a list of [lon, lat] or [lon, lat, alt]",)),
    # (values as the file spells them, json.dumps: they were Python's, None, True, ['8.5', '47'])
    ("p.geojson", '{"type": "Point", "coordinates": [8, 47, 512], "properties": {"hover_time_s": true}}',
     ("p.geojson: feature 0: hover_time_s=true is invalid; valid range: [0, 1e+06] s, a JSON number",)),
    # a hover time given as a string is refused (JSON numbers only; "5" was taken as 5 s); a MultiPoint without
    # coordinates (no pad at all: skipped without a word before the review's previous pass)
    ("p.geojson", '{"type": "Point", "coordinates": [8, 47, 512], "properties": {"hover_time_s": "5"}}',
     ('p.geojson: feature 0: hover_time_s="5" is invalid; valid range: [0, 1e+06] s, a JSON number',)),
    ("p.geojson", '{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "MultiPoint"}}]}',
     ("p.geojson: feature 0: MultiPoint coordinates null are invalid; valid: a list of [lon, lat] or [lon, lat, alt]",)),
    # CSV errors name the file's line (blank lines counted; they were the row's number after blank rows were dropped)
    ("p.csv", "lat,lon\n\n47,8\n\n95,8\n", ("p.csv: line 5: latitude 95.0 is invalid",)),
    ("p.csv", "\nlat,lon\n47,8\n47.0001,8,5\n", ("line 4 has 3 values, the header 2 (lat,lon)",)),
    # 2026-11-28: JSON nested deeper than the parser's recursion was a RecursionError traceback (an array: the
    # JSON-array check's json.loads; an object: the GeoJSON reader's), a CSV field over csv's 128 KiB limit a
    # _csv.Error traceback
    pytest.param("p.json", "[" * 100000, ("p.json: JSON nested deeper than the reader takes", "not a pads file"),
                 id="deep-array"),
    pytest.param("p.json", '{"a":' * 100000, ("p.json: JSON nested deeper than the reader takes", "not a pads file"),
                 id="deep-object"),
    pytest.param("p.geojson", '{"type": "FeatureCollection", "features": ' + "[" * 100000,
                 ("p.geojson: JSON nested deeper than the reader takes",), id="deep-features"),
    pytest.param("p.csv", "lat,lon\n" + "4" * (128 * 1024 + 1) + ",8\n",
                 ("p.csv: not a readable CSV: field larger than field limit (131072) at line 2",), id="csv-field-128k"),
])
def test_bad_pads_files(capsys, tmp_path, name, text, needles):
    p = tmp_path / name
    p.write_text(text)
    _bad(capsys, tmp_path, ["--plan", str(DATA / "qgc_simple_square.plan"), "--pads", str(p)], name, *needles)


def test_missing_files_and_conflicting_route(capsys, tmp_path):
    _bad(capsys, tmp_path, ["--plan", str(tmp_path / "nope.plan")], "nope.plan", "does not exist")
    cfg = tmp_path / "c.toml"
    cfg.write_text('[mission]\nfile = "x.plan"\n[[waypoints]]\naction = "takeoff"\nz_m = 5.0\n')
    (tmp_path / "x.plan").write_bytes((DATA / "qgc_simple_square.plan").read_bytes())
    _bad(capsys, tmp_path, [str(cfg)], "mission.file", "[[waypoints]]")
    cfg.write_text('[[waypoints]]\naction = "charge"\npad = 7\nz_m = 5.0\n')
    _bad(capsys, tmp_path, [str(cfg)], "waypoints.0.pad=7", "valid range")


def test_altitude_frames_and_here():
    """Frame 0 (AMSL) and 3 (relative) give the same height; lat = lon = 0 is "here", alt 0 the
    current height (ArduCopter's rules); a waypoint param1 > 0 is a hold (a loiter)."""
    from mission_sim.plans.items import RawMission, read_plan
    from mission_sim.plans.route import route_from_items
    home = (47.0, 8.0, 500.0)
    doc = _plan([_item(22, 0.0, 0.0, 10.0), _item(16, 47.001, 8.0, 530.0, frame=0),
                 _item(16, 47.001, 8.001, 30.0, frame=3, p1=4.0), _item(16, 0.0, 0.0, 0.0), _item(21)], home)
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "f.plan"
        p.write_text(json.dumps(doc))
        raw = read_plan(p)
    assert isinstance(raw, RawMission)
    r = route_from_items(raw)
    assert [w["action"] for w in r] == ["takeoff", "waypoint", "loiter", "waypoint", "land"]
    assert [w["z_m"] for w in r] == [10.0, 30.0, 30.0, 30.0, 0.0]
    assert r[2]["hold_s"] == 4.0 and (r[3]["x_m"], r[3]["y_m"]) == (r[2]["x_m"], r[2]["y_m"])
    assert (r[4]["x_m"], r[4]["y_m"]) == (r[2]["x_m"], r[2]["y_m"])
    e, n = enu_xy(47.001, 8.001, home)
    assert abs(r[2]["x_m"] - e) < 5e-3 and abs(r[2]["y_m"] - n) < 5e-3


def test_mission_planner_file_without_takeoff(capsys, tmp_path):
    """QGC's MissionPlanner.waypoints: no take-off item and no landing: the route climbs at home to
    the first waypoint's 100 m, flies the five legs and lands where it ends: at least the climb at
    climb_rate, the descent at descent_rate and the legs at cruise speed."""
    from mission_sim.config import MissionPlan
    home = (47.660459, -122.103167, 5.21)
    pts = [(47.661298, -122.103274), (47.661030, -122.101858), (47.659961, -122.101525),
           (47.659195, -122.103370), (47.660459, -122.105538)]
    xy = [(0.0, 0.0)] + [enu_xy(lat, lon, home) for lat, lon in pts]
    length = sum(math.dist(a, b) for a, b in zip(xy[:-1], xy[1:]))
    s = _run(capsys, tmp_path, "mp", "--plan", str(DATA / "qgc_missionplanner.waypoints"))
    m = MissionPlan()
    assert s["sim_time_s"] > 100 / m.climb_rate_m_s + 100 / m.descent_rate_m_s + length / m.cruise_speed_m_s
    assert s["sim_time_s"] < 100 / m.climb_rate_m_s + 100 / m.descent_rate_m_s + length / m.cruise_speed_m_s + 60


def test_px4_style_tlog_mission(tmp_path):
    """A non-ArduPilot vehicle (PX4: item 0 is a real item) with HOME_POSITION; an older, longer
    upload leaves a stale item 3 that the last MISSION_COUNT (3) excludes."""
    import struct

    from mission_sim.mavlink.logs import mavutil
    from mission_sim.plans.items import uploaded_mission
    from mission_sim.plans.route import route_from_items
    mav = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    home = (47.0, 8.0, 500.0)

    def item(seq, cmd, lat, lon, alt):
        return mav.mission_item_int_encode(255, 0, seq, 3, cmd, 0, 1, 0, 0, 0, 0, int(lat * 1e7), int(lon * 1e7), alt)
    msgs = [mav.heartbeat_encode(2, 12, 0, 0, 0),   # quadrotor, MAV_AUTOPILOT_PX4
            mav.mission_count_encode(255, 0, 4), item(3, 16, 47.01, 8.0, 50.0),
            mav.home_position_encode(int(home[0] * 1e7), int(home[1] * 1e7), int(home[2] * 1e3), 0, 0, 0,
                                     [1, 0, 0, 0], 0, 0, 0),
            mav.mission_count_encode(255, 0, 3), item(0, 22, 47.0, 8.0, 25.0), item(1, 16, 47.001, 8.0, 25.0),
            item(2, 21, 47.001, 8.0, 0.0)]
    p = tmp_path / "px4.tlog"
    p.write_bytes(b"".join(struct.pack(">Q", 1_700_000_000_000_000 + i * 100_000) + m.pack(mav)
                           for i, m in enumerate(msgs)))
    raw = uploaded_mission(p)
    assert raw.home.alt_m == pytest.approx(500.0) and [it.command for it in raw.items] == [22, 16, 21]
    r = route_from_items(raw)
    e, n = enu_xy(47.001, 8.0, home)
    assert [w["action"] for w in r] == ["takeoff", "waypoint", "land"]
    assert abs(r[1]["y_m"] - n) < 0.02 and abs(r[1]["x_m"]) < 0.02 and r[1]["z_m"] == 25.0


def test_telemetry_streams_about_the_mission_files_home(capsys, tmp_path):
    """`telemetry --config` with a mission file: positions are about the file's home (no --home needed)."""
    from mission_sim.mavlink.logs import mavutil
    (tmp_path / "m.plan").write_bytes((DATA / "qgc_simple_square.plan").read_bytes())
    cfg = tmp_path / "c.toml"
    cfg.write_text('[mission]\nfile = "m.plan"\n')
    tlog = tmp_path / "t.tlog"
    assert main(["telemetry", "--config", str(cfg), "--connect", "none", "--tlog", str(tlog), "--speed", "inf",
                 "--duration", "3", "--rate", "2"]) == 0
    home = json.loads((DATA / "qgc_simple_square.plan").read_text())["mission"]["plannedHomePosition"]
    with contextlib.closing(mavutil().mavlink_connection(str(tlog))) as conn:
        first = conn.recv_match(type="GLOBAL_POSITION_INT")
    assert first.lat * 1e-7 == pytest.approx(home[0], abs=1e-6) and first.lon * 1e-7 == pytest.approx(home[1], abs=1e-6)
    assert first.alt * 1e-3 == pytest.approx(home[2], abs=2.0)   # near the ground at home (not SITL's 584 m)


def test_pads_csv_trailing_empty_fields_are_accepted(tmp_path):
    """A spreadsheet's trailing commas (empty values past the header's columns) are not a value dropped."""
    from mission_sim.plans.pads import read_pads
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text("lat,lon\n47,8\n")
    b.write_text("lat,lon\n47,8,,\n")
    assert read_pads(a) == read_pads(b)
    b.write_text("id,lat,lon,name\n1,47,8,north pad\n")   # other columns (not near a known name) are ignored
    assert read_pads(a) == read_pads(b)


def test_pads_csv_alt_amsl_is_the_altitude_column():
    """The altitude column is m AMSL (docs/mission_files.md), so `alt_amsl` names it (2026-11-27: refused as a
    misspelt column); a relative one (alt_agl) is still refused, the message saying the column is AMSL."""
    from mission_sim.plans.pads import _csv
    ref = _csv("lat,lon,alt\n47,8,512.5\n", "a.csv")
    assert _csv("lat,lon,alt_amsl\n47,8,512.5\n", "b.csv") == ref and ref[0].point.alt_m == 512.5
    with pytest.raises(ValueError, match=r"column 'alt_agl' is unknown .*\(alt in m AMSL\)"):
        _csv("lat,lon,alt_agl\n47,8,12\n", "c.csv")


def test_geojson_pads_take_other_properties_and_the_same_names_as_before(tmp_path):
    """Properties not near a pad value's name (a pad's name, an id) are still ignored; hover_time_s is read."""
    from mission_sim.plans.pads import read_pads
    p = tmp_path / "p.geojson"
    p.write_text('{"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Point", '
                 '"coordinates": [8, 47, 512]}, "properties": {"name": "north pad", "id": 3, "hover_time_s": 30}}]}')
    (pad,) = read_pads(p)
    assert (pad.point.lat_deg, pad.point.lon_deg, pad.point.alt_m, pad.hover_time_s) == (47.0, 8.0, 512.0, 30.0)


@pytest.mark.parametrize("props", [
    {"name": "a", "lat": 47, "lon": 8},                  # the position again, beside the geometry
    {"latitude": 47.0, "longitude": 8.0},                # as CSV-to-GeoJSON exporters keep them
    {"altitude": 512}, {"ALT": 3}, {"alt_amsl": 512},    # an altitude beside 3-D coordinates
    {"lang": "de", "last": "2026-11-27"},                # near lon / lat, not pad values
])
def test_geojson_pads_with_ordinary_extra_properties_load(tmp_path, props):
    """Properties other than a hover time are ignored where the coordinates carry the value (they were refused as
    misspellings: 'property 'lat' is unknown'); the pads are those of the file without them."""
    import json
    from mission_sim.mavlink.geodesy import GeoPoint
    from mission_sim.plans.pads import GeoPad, read_pads

    def pads(properties):
        p = tmp_path / "p.geojson"
        p.write_text(json.dumps({"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "Point", "coordinates": [8, 47, 512]}, "properties": properties},
            {"type": "Feature", "geometry": {"type": "MultiPoint", "coordinates": [[8.001, 47, 515], [8, 47.001, 520]]},
             "properties": dict(properties or {}, hover_time_s=30)}]}))
        return read_pads(p)
    ref = pads({})
    assert pads(None) == ref   # null properties: none (legal GeoJSON)
    assert pads(props) == ref and [p.hover_time_s for p in ref] == [None, 30.0, 30.0]
    assert [p.point.alt_m for p in ref] == [512.0, 515.0, 520.0]
    if not any(k.lower().startswith("alt") for k in props):   # with 2-D coordinates too (lat / lon never refused)
        flat = tmp_path / "flat.geojson"
        flat.write_text(json.dumps({"type": "Point", "coordinates": [8, 47], "properties": props}))
        assert read_pads(flat) == (GeoPad(GeoPoint(47.0, 8.0, None)),)
