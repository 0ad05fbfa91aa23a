"""A .plan's geofence and rally points: read, put in the pad frame, and the route checked against them (warnings)."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from mission_sim.mavlink.geodesy import GeoPoint
from mission_sim.plans.fence import GeoZone, Zone, fence_warnings, read_plan_fence, route_breaches

MISSIONS = Path(__file__).parent / "data" / "missions"
GEOFENCE_PLAN = MISSIONS / "px4_geofence_avoid.plan"


def _poly(name, inclusion, *xy):
    return Zone("polygon", inclusion, np.array(xy, dtype=float), 0.0, name)


def _circle(name, inclusion, c, r):
    return Zone("circle", inclusion, np.array([c], dtype=float), float(r), name)


def test_px4_geofence_plan_rtl_leg_crosses_both_exclusion_zones():
    """PX4's geofence test plan: take-off, three waypoints, RTL, an exclusion circle (111 m), an exclusion polygon and
    an inclusion polygon. Its waypoints stay clear of the zones; its return-to-launch leg, flown straight, passes
    53 m from the circle's centre and through the polygon: one warning each, naming that leg; the inclusion polygon
    holds the whole route (no warning)."""
    from mission_sim.config import load_config_dict
    from wpt_receiver.notices import DronewptWarning
    doc = json.loads(GEOFENCE_PLAN.read_text())
    assert [c["inclusion"] for c in doc["geoFence"]["circles"]] == [False]
    assert [p["inclusion"] for p in doc["geoFence"]["polygons"]] == [False, True]
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        d = load_config_dict(None, GEOFENCE_PLAN)
    said = [str(w.message) for w in rec if issubclass(w.category, DronewptWarning)]
    assert len(said) == 2
    assert "enters the plan's geofence exclusion polygon 0 on the leg from route point 3" in said[0]
    assert "enters the plan's geofence exclusion circle 0 on the leg from route point 3" in said[1]
    assert all("to route point 4 (0, 0) m" in s for s in said)
    assert all("route points are [[waypoints]] indices, not the plan's item numbers" in s for s in said)
    assert [w["action"] for w in d["waypoints"]][4:] == ["waypoint", "land"]   # the RTL: over home, land
    # the leg's closest approach to the circle's centre: inside the 111 m radius
    from mission_sim.plans.fence import local_zones
    from mission_sim.plans.items import read_plan
    raw = read_plan(GEOFENCE_PLAN)
    circle = [z for z in local_zones(raw.fence, raw.home) if z.kind == "circle"][0]
    p = np.array([d["waypoints"][3]["x_m"], d["waypoints"][3]["y_m"]])
    c = circle.xy_m[0]
    t = np.clip(np.dot(c - p, -p) / np.dot(p, p), 0, 1)
    closest = np.hypot(*(p + t * (-p) - c))
    assert closest == pytest.approx(53.1, abs=0.1) and closest < circle.radius_m == pytest.approx(111.05, abs=0.01)


def test_plans_without_a_fence_say_nothing():
    from mission_sim.plans.items import read_plan
    for name in ("qgc_simple_square.plan", "px4_triangle_gripper_package_delivery.plan", "qgc_section_test.plan"):
        raw = read_plan(MISSIONS / name)
        assert raw.fence == () and raw.rally == ()


def test_concave_inclusion_polygon_caught_between_two_inside_points():
    """A U-shaped inclusion zone: a leg from one arm to the other has both ends inside and leaves the zone across
    the notch (only the edge crossings see it); a leg along one arm stays inside."""
    u = _poly("inclusion polygon 0", True, (0, 0), (30, 0), (30, 30), (20, 30), (20, 10), (10, 10), (10, 30), (0, 30))
    assert route_breaches([(5, 5), (5, 25)], [u]) == []
    (z, k), = route_breaches([(5, 5), (5, 25), (25, 25)], [u])
    assert z is u and k == 1
    assert route_breaches([(5, 5), (40, 5)], [u])[0][1] == 0   # an end outside


def test_legs_through_corners_and_along_edges():
    """The leg (-5, -5) -> (15, 15) across the square (0, 0)-(10, 10) through two of its corners crosses no edge
    properly and has both ends outside: it enters the exclusion square (missed before) and leaves the inclusion one.
    A leg touching one vertex from outside, through one vertex into the inside, along an edge, and along an edge
    beyond its end: the boundary belongs to the zone."""
    sq = [(0, 0), (10, 0), (10, 10), (0, 10)]
    inc, exc = _poly("in", True, *sq), _poly("ex", False, *sq)
    diagonal = [(-5, -5), (15, 15)]
    assert route_breaches(diagonal, [exc]) == [(exc, 0)]
    assert route_breaches(diagonal, [inc]) == [(inc, 0)]
    touch = [(-5, 5), (5, -5)]                     # touches the corner (0, 0) only, from outside
    assert route_breaches(touch, [exc]) == [(exc, 0)] and route_breaches(touch, [inc]) == [(inc, 0)]
    miss = [(-5, 4.9), (4.9, -5)]                  # 0.07 m short of that corner
    assert route_breaches(miss, [exc]) == []
    into = [(-5, -5), (5, 5)]                      # through the corner into the square
    assert route_breaches(into, [exc]) == [(exc, 0)] and route_breaches(into, [inc]) == [(inc, 0)]
    corner_to_corner = [(0, 0), (10, 10)]          # inside: the diagonal, vertex to vertex
    assert route_breaches(corner_to_corner, [inc]) == [] and route_breaches(corner_to_corner, [exc]) == [(exc, 0)]
    along = [(0, 0), (10, 0)]                      # along the bottom edge
    assert route_breaches(along, [inc]) == [] and route_breaches(along, [exc]) == [(exc, 0)]
    beyond = [(2, 0), (15, 0)]                     # along the edge, then past its end: outside
    assert route_breaches(beyond, [inc]) == [(inc, 0)]
    # a concave polygon: a leg from one reflex vertex to the other stays on the boundary / inside
    u = _poly("u", True, (0, 0), (30, 0), (30, 30), (20, 30), (20, 10), (10, 10), (10, 30), (0, 30))
    assert route_breaches([(5, 10), (25, 10)], [u]) == []        # along the notch's bottom edge (and inside)
    assert route_breaches([(5, 20), (25, 20)], [u]) == [(u, 0)]  # across the notch


def test_circles_inclusion_and_exclusion():
    inc = _circle("inclusion circle 0", True, (0, 0), 100)
    exc = _circle("exclusion circle 0", False, (50, 0), 10)
    # a leg passing 9.9 m from the exclusion centre, both ends far outside it: enters; 10.1 m: does not
    assert [z.name for z, _ in route_breaches([(0, -9.9), (90, -9.9)], [inc, exc])] == ["exclusion circle 0"]
    assert route_breaches([(0, -10.1), (90, -10.1)], [inc, exc]) == []
    assert [(z.name, k) for z, k in route_breaches([(0, 0), (0, 50), (0, 101)], [inc])] == [("inclusion circle 0", 1)]


def test_geometry_agrees_with_shapely():
    """Random legs against a concave polygon and a circle: inside / crossing as shapely (GEOS) decides."""
    shapely = pytest.importorskip("shapely")
    from shapely.geometry import LineString, Point, Polygon
    rng = np.random.default_rng(3)
    verts = [(0, 0), (60, 0), (60, 50), (35, 20), (20, 50), (0, 40)]
    inc, exc = _poly("in", True, *verts), _poly("ex", False, *verts)
    circ = _circle("c", False, (30, 25), 12.0)
    poly, disc = Polygon(verts), Point(30, 25).buffer(12.0, quad_segs=4096)
    fat = poly.buffer(1e-7, join_style="mitre")
    seen = {True: 0, False: 0}
    # random legs, and deliberate ones through the vertices (random legs never hit one): vertex to vertex, and
    # from a random point through a vertex to twice as far
    v = np.array(verts, dtype=float)
    legs = [(rng.uniform(-10, 70, 2), rng.uniform(-10, 70, 2)) for _ in range(400)]
    legs += [(v[i], v[j]) for i in range(len(v)) for j in range(len(v)) if i != j]
    legs += [(a, 2 * v[i] - a) for i in range(len(v)) for a in rng.uniform(-10, 70, (10, 2))]
    for a, b in legs:
        seg = LineString([a, b])
        # (the boundary belongs to the zone, within the reader's 1 um: a leg through a vertex v computed as 2 v - a
        # misses it by ~1e-14 m in floating point)
        leaves = not fat.covers(seg)
        assert bool(route_breaches([a, b], [inc])) == leaves
        assert bool(route_breaches([a, b], [exc])) == (poly.distance(seg) <= 1e-6)
        d = seg.distance(Point(30, 25))
        if abs(d - 12.0) > 1e-3:   # (the buffered disc is a polygon: not at its rim)
            assert bool(route_breaches([a, b], [circ])) == (d < 12.0)
        seen[leaves] += 1
    assert min(seen.values()) > 20   # (both kinds of leg drawn)


def test_fence_versions_rally_and_bad_entries():
    home = GeoPoint(47.0, 8.0, 400.0)
    # version 1: one inclusion polygon; a rally point outside it warns
    doc = {"geoFence": {"version": 1, "polygon": [[47.0, 7.999], [47.0, 8.001], [47.001, 8.001], [47.001, 7.999]]},
           "rallyPoints": {"points": [[47.0005, 8.0, 410.0], [47.01, 8.0, 410.0]], "version": 2}}
    zones, rally = read_plan_fence(doc, "v1.plan")
    assert [(z.kind, z.inclusion, len(z.points)) for z in zones] == [("polygon", True, 4)]
    route = [{"x_m": 0.0, "y_m": 50.0}]
    said = fence_warnings(zones, rally, home, route, "v1.plan")
    assert said == ["v1.plan: rally point 1 (47.010000, 8.000000) is outside the plan's geofence inclusion polygon 0"]
    route = [{"x_m": 0.0, "y_m": 50.0}, {"x_m": 0.0, "y_m": -20.0}]   # (home on the fence's south edge: inside)
    assert len(fence_warnings(zones, (), home, route, "v1.plan")) == 1
    with pytest.raises(ValueError, match=r"^x\.plan: geoFence\.circles\[0\] is invalid; valid: .*radius"):
        read_plan_fence({"geoFence": {"circles": [{"circle": {"center": [47, 8], "radius": -5}}]}}, "x.plan")
    with pytest.raises(ValueError, match=r"^x\.plan: geoFence\.polygons\[0\]\.polygon has 2 vertices; valid: 3 or more$"):
        read_plan_fence({"geoFence": {"polygons": [{"inclusion": True, "polygon": [[47, 8], [47, 8.1]]}]}}, "x.plan")
    with pytest.raises(ValueError, match=r"^x\.plan: geoFence\.polygons\[0\]\.polygon\[1\]=\[95, 8\] is invalid"):
        read_plan_fence({"geoFence": {"polygons": [{"polygon": [[47, 8], [95, 8], [47, 8.1]]}]}}, "x.plan")
    assert math.isnan(read_plan_fence({"rallyPoints": {"points": [[47, 8]]}}, "x.plan")[1][0][2])
    assert isinstance(zones[0], GeoZone)


@pytest.mark.parametrize("doc, said", [
    ({"geoFence": {"polygons": 5}}, r"geoFence\.polygons=5 is invalid; valid: a list or null"),
    ({"geoFence": {"circles": 3.5}}, r"geoFence\.circles=3\.5 is invalid; valid: a list or null"),
    ({"geoFence": {"polygons": [], "circles": {"a": 1}}}, r"geoFence\.circles=\{'a': 1\} is invalid"),
    ({"rallyPoints": {"points": 7}}, r"rallyPoints\.points=7 is invalid; valid: a list or null"),
    ({"rallyPoints": [1, 2]}, r"rallyPoints=\[1, 2\] is invalid; valid: an object"),
    ({"geoFence": []}, r"geoFence=\[\] is invalid; valid: an object"),
    ({"geoFence": 4}, r"geoFence=4 is invalid; valid: an object"),
    ({"geoFence": {"version": 1, "polygon": {"lat": 47}}}, r"geoFence\.polygon=\{'lat': 47\} is invalid; valid: a list"),
    # a version 1 fence's errors name its own key (geoFence.polygon), not a v2 key the file lacks
    ({"geoFence": {"version": 1, "polygon": [[47, 8], [95, 8], [47, 8.1]]}}, r"geoFence\.polygon\[1\]=\[95, 8\] is invalid"),
    ({"geoFence": {"version": 1, "polygon": [[47, 8], [47, 8.1]]}}, r"geoFence\.polygon has 2 vertices; valid: 3 or more$"),
])
def test_malformed_fence_containers_refused_in_one_line(doc, said):
    with pytest.raises(ValueError, match=r"^x\.plan: " + said) as exc:
        read_plan_fence(doc, "x.plan")
    assert "\n" not in str(exc.value)


def test_null_fence_containers_read_as_absent():
    assert read_plan_fence({"geoFence": None, "rallyPoints": None}, "x.plan") == ((), ())
    assert read_plan_fence({"geoFence": {"polygons": None, "circles": None, "polygon": []},
                            "rallyPoints": {"points": None}}, "x.plan") == ((), ())


def test_cli_refuses_a_number_as_polygons_in_one_line(tmp_path):
    """``dronewpt mission --plan X.plan --dry-run`` with ``geoFence.polygons`` a number: exit 2, one line, no traceback."""
    import subprocess
    import sys
    doc = json.loads((MISSIONS / "px4_geofence_avoid.plan").read_text())
    doc["geoFence"]["polygons"] = 3
    plan = tmp_path / "bad.plan"
    plan.write_text(json.dumps(doc))
    r = subprocess.run([sys.executable, "-m", "mission_sim.cli", "mission", "--plan", str(plan), "--dry-run"],
                       capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    assert "geoFence.polygons=3 is invalid; valid: a list or null" in r.stderr
