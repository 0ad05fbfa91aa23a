"""A QGroundControl ``.plan``'s geofence and rally points, and whether a route stays inside the fence.

A ``.plan``'s ``geoFence`` (version 2: ``polygons`` of ``{"inclusion": bool, "polygon": [[lat, lon], ...]}`` and
``circles`` of ``{"inclusion": bool, "circle": {"center": [lat, lon], "radius": m}}``; version 1: one inclusion
``"polygon"``) and ``rallyPoints`` (``points``: [lat, lon, alt AMSL]) are read by :func:`read_plan_fence` into
:class:`GeoZone` records (geodetic); :func:`local_zones` puts them in the pad frame (ENU about home). The route is
flown as planned whatever the fence says (no fence action is simulated); :func:`fence_warnings` names, per zone,
the first leg of the route (the horizontal polyline home -> waypoints) that leaves an inclusion zone or enters an
exclusion zone, and each rally point outside the fence. Each inclusion zone is checked on its own, as ArduPilot
does (the vehicle inside every inclusion zone); PX4 asks for one of them, so a plan with several inclusion zones may
warn where PX4 would not breach. The fence's altitude limits are parameters of the vehicle, not in the plan.

The geometry (:func:`route_breaches`) is pure: a leg is split wherever it meets a polygon's edges (crossings,
touching points at vertices, the ends of a stretch along an edge) and each piece's midpoint is tested by the
even-odd rule; the distance of a segment from a circle's centre. The boundary belongs to the zone (a point on an
edge counts as inside): a leg along an edge or through a vertex stays inside an inclusion zone and enters an
exclusion zone (as shapely's ``covers`` / ``intersects``). A circle's rim: inside an inclusion circle, outside an
exclusion one (a leg tangent to it does not enter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..mavlink.geodesy import GeoPoint, geodetic_to_enu

__all__ = ["GeoZone", "Zone", "read_plan_fence", "local_zones", "route_breaches", "fence_warnings"]


@dataclass(frozen=True)
class GeoZone:
    """A fence zone of a plan, geodetic: ``kind`` "polygon" (``points``: (lat, lon) vertices, degrees) or "circle"
    (``points``: its centre, ``radius_m``); ``inclusion``: stay inside (True) or outside (False); ``name``: how
    the warnings call it ("inclusion polygon 1": its index among the plan's polygons / circles)."""

    kind: str
    inclusion: bool
    points: tuple
    radius_m: float = 0.0
    name: str = ""


@dataclass(frozen=True)
class Zone:
    """A fence zone in the pad frame: ``xy_m`` (n, 2) polygon vertices or the circle's centre (1, 2) [m]."""

    kind: str
    inclusion: bool
    xy_m: np.ndarray
    radius_m: float
    name: str


def _latlon(v, name: str, what: str) -> tuple[float, float]:
    if not (isinstance(v, list) and len(v) >= 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                       and math.isfinite(x) for x in v[:2])):
        raise ValueError(f"{name}: {what}={v!r} is invalid; valid: [lat, lon] in degrees")
    try:
        GeoPoint(float(v[0]), float(v[1]))   # (latitude / longitude ranges: one line naming the value)
    except ValueError as exc:
        raise ValueError(f"{name}: {what}={v!r} is invalid: {exc}") from None
    return float(v[0]), float(v[1])


def _short(v) -> str:
    r = repr(v)
    return r if len(r) <= 60 else r[:57] + "..."


def _list_or_none(obj: dict, key: str, name: str, where: str):
    """``obj[key]`` when it is a list or absent / null (None); anything else: a one-line ``ValueError``."""
    v = obj.get(key)
    if v is None or isinstance(v, list):
        return v
    raise ValueError(f"{name}: {where}.{key}={_short(v)} is invalid; valid: a list or null")


def read_plan_fence(doc: dict, name: str) -> tuple[tuple[GeoZone, ...], tuple[tuple[float, float, float], ...]]:
    """The geofence zones and the rally points (lat, lon, alt AMSL) of a ``.plan``'s JSON ``doc`` (none when absent);
    a malformed entry is a ``ValueError`` naming the file ``name`` and the entry."""
    zones: list[GeoZone] = []
    fence = doc.get("geoFence")
    if fence is not None and not isinstance(fence, dict):
        raise ValueError(f"{name}: geoFence={_short(fence)} is invalid; valid: an object "
                         "{\"polygons\": [...], \"circles\": [...]} or absent")
    fence = fence or {}
    polys = _list_or_none(fence, "polygons", name, "geoFence")
    if polys is None and fence.get("polygon") is not None:   # version 1: one inclusion polygon
        v1 = _list_or_none(fence, "polygon", name, "geoFence")
        polys = [("geoFence", {"inclusion": True, "polygon": v1})] if v1 else []
    else:
        polys = [(f"geoFence.polygons[{i}]", p) for i, p in enumerate(polys or [])]
    for i, (where, p) in enumerate(polys):
        if not isinstance(p, dict) or not isinstance(p.get("polygon"), list):
            raise ValueError(f"{name}: {where} is invalid; valid: {{\"inclusion\": true|false, \"polygon\": "
                             "[[lat, lon], ...]}")
        pts = tuple(_latlon(v, name, f"{where}.polygon[{j}]") for j, v in enumerate(p["polygon"]))
        if len(pts) < 3:
            raise ValueError(f"{name}: {where}.polygon has {len(pts)} vertices; valid: 3 or more")
        inc = p.get("inclusion", True)
        if not isinstance(inc, bool):
            raise ValueError(f"{name}: {where}.inclusion={inc!r} is invalid; valid: true, false")
        zones.append(GeoZone("polygon", inc, pts, 0.0, f"{'inclusion' if inc else 'exclusion'} polygon {i}"))
    for i, c in enumerate(_list_or_none(fence, "circles", name, "geoFence") or []):
        where = f"geoFence.circles[{i}]"
        circle = c.get("circle") if isinstance(c, dict) else None
        r = circle.get("radius") if isinstance(circle, dict) else None
        if not (isinstance(r, (int, float)) and not isinstance(r, bool) and math.isfinite(r) and r > 0):
            raise ValueError(f"{name}: {where} is invalid; valid: {{\"inclusion\": true|false, \"circle\": "
                             "{\"center\": [lat, lon], \"radius\": metres > 0}}")
        inc = c.get("inclusion", True)
        if not isinstance(inc, bool):
            raise ValueError(f"{name}: {where}.inclusion={inc!r} is invalid; valid: true, false")
        centre = _latlon(circle.get("center"), name, f"{where}.circle.center")
        zones.append(GeoZone("circle", inc, (centre,), float(r), f"{'inclusion' if inc else 'exclusion'} circle {i}"))
    rally = []
    rp = doc.get("rallyPoints")
    if rp is not None and not isinstance(rp, dict):
        raise ValueError(f"{name}: rallyPoints={_short(rp)} is invalid; valid: an object {{\"points\": "
                         "[[lat, lon, alt], ...]} or absent")
    for i, v in enumerate(_list_or_none(rp or {}, "points", name, "rallyPoints") or []):
        lat, lon = _latlon(v, name, f"rallyPoints.points[{i}]")
        alt = v[2] if len(v) > 2 and isinstance(v[2], (int, float)) and not isinstance(v[2], bool) else math.nan
        rally.append((lat, lon, float(alt)))
    return tuple(zones), tuple(rally)


def local_zones(zones, home: GeoPoint) -> list[Zone]:
    """:class:`GeoZone` records in the pad frame about ``home`` (ENU metres, horizontal)."""
    out = []
    for z in zones:
        xy = np.array([geodetic_to_enu(lat, lon, home.alt_m, home)[:2] for lat, lon in z.points], dtype=float)
        out.append(Zone(z.kind, z.inclusion, xy, z.radius_m, z.name))
    return out


def _inside_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule: which of the points (n, 2) are inside the polygon (m, 2) (a point on an edge: inside)."""
    x, y = pts[:, 0:1], pts[:, 1:2]
    a, b = poly, np.roll(poly, -1, axis=0)
    ax, ay, bx, by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    straddle = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = ax + (y - ay) * (bx - ax) / (by - ay)
    inside = (np.sum(straddle & (x < xc), axis=1) % 2) == 1
    return inside | _on_boundary(pts, poly)


def _on_boundary(pts: np.ndarray, poly: np.ndarray, tol_m: float = 1e-6) -> np.ndarray:
    a, b = poly, np.roll(poly, -1, axis=0)
    return np.array([np.min(_seg_distance(p, a, b)) <= tol_m for p in pts], dtype=bool)


def _seg_distance(p, a, b) -> np.ndarray:
    """Distance of point ``p`` (2,) from segments ``a``-``b`` ((k, 2) each)."""
    d = b - a
    den = np.einsum("ij,ij->i", d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(den > 0, np.einsum("ij,ij->i", p - a, d) / den, 0.0)
    q = a + np.clip(t, 0.0, 1.0)[:, None] * d
    return np.hypot(*(p - q).T)


def _split_params(p, q, poly: np.ndarray, tol_m: float = 1e-6) -> np.ndarray:
    """The parameters t in [0, 1] (sorted, with 0 and 1) where segment ``p`` + t (``q`` - ``p``) meets an edge of the
    polygon: proper crossings, touching points (a vertex on the leg, the leg's end on an edge) and the ends of an
    overlap with an edge the leg runs along. Between two of them the leg is wholly inside, outside or on an edge."""
    d = q - p
    length = math.hypot(*d)
    ts = [0.0, 1.0]
    if length == 0.0:
        return np.array([0.0])
    a, e = poly, np.roll(poly, -1, axis=0) - poly
    den = d[0] * e[:, 1] - d[1] * e[:, 0]                       # cross(d, e)
    ap = a - p
    t_num = ap[:, 0] * e[:, 1] - ap[:, 1] * e[:, 0]               # cross(a - p, e)
    s_num = ap[:, 0] * d[1] - ap[:, 1] * d[0]                     # cross(a - p, d)
    e_len = np.hypot(e[:, 0], e[:, 1])
    eps_t, parallel = tol_m / length, np.abs(den) <= 1e-12 * length * np.maximum(e_len, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        t, s = t_num / den, s_num / den
    eps_s = tol_m / np.maximum(e_len, 1e-300)
    hit = ~parallel & (t >= -eps_t) & (t <= 1 + eps_t) & (s >= -eps_s) & (s <= 1 + eps_s)
    ts.extend(np.clip(t[hit], 0.0, 1.0).tolist())
    # an edge along the leg (collinear: a within tol of the leg's line): its ends projected on the leg
    on_line = parallel & (np.abs(s_num) <= tol_m * length)
    for k in np.flatnonzero(on_line):
        for v in (a[k], a[k] + e[k]):
            tv = float(np.dot(v - p, d) / (length * length))
            if -eps_t <= tv <= 1 + eps_t:
                ts.append(min(max(tv, 0.0), 1.0))
    return np.unique(np.array(ts))


def _leg_breaches_polygon(p, q, poly: np.ndarray, inclusion: bool) -> bool:
    """Whether leg ``p``-``q`` leaves the inclusion polygon / enters the exclusion polygon ``poly``: the leg split
    at every meeting with the polygon's edges (:func:`_split_params`), each split point and each piece's midpoint
    tested (the boundary belongs to the zone: a leg running along an edge, or touching a vertex, stays inside an
    inclusion zone and enters an exclusion zone)."""
    t = _split_params(p, q, poly)
    mids = (t[:-1] + t[1:]) / 2.0
    probe = np.concatenate([t, mids])
    pts = p[None, :] + probe[:, None] * (q - p)[None, :]
    inside = _inside_polygon(pts, poly)   # (an edge's points count as inside)
    return bool(not inside.all()) if inclusion else bool(inside.any())


def route_breaches(route_xy, zones) -> list[tuple[Zone, int]]:
    """Per zone the first leg ``k`` (route point k -> k + 1; a one-point route: its point, k = 0) of the horizontal
    polyline ``route_xy`` (n, 2) [m] that leaves an inclusion zone or enters an exclusion zone: ``(zone, k)``, in
    the order of ``zones``; zones the route respects are left out."""
    pts = np.asarray(route_xy, dtype=float).reshape(-1, 2)
    legs = [(pts[k], pts[k + 1]) for k in range(len(pts) - 1)] or [(pts[0], pts[0])]
    out = []
    for z in zones:
        for k, (p, q) in enumerate(legs):
            if z.kind == "circle":
                c = z.xy_m[0]
                if z.inclusion:
                    bad = max(math.hypot(*(p - c)), math.hypot(*(q - c))) > z.radius_m   # (a disc is convex)
                else:
                    bad = float(_seg_distance(c, p[None], q[None])[0]) < z.radius_m
            else:
                bad = _leg_breaches_polygon(p, q, z.xy_m, z.inclusion)
            if bad:
                out.append((z, k))
                break
    return out


def fence_warnings(zones, rally, home: GeoPoint, route: list[dict], name: str) -> list[str]:
    """One line per fence zone the route of ``[[waypoints]]`` dicts ``route`` (from home, (0, 0)) leaves (inclusion)
    or enters (exclusion), naming the leg by its route points (indices of ``route``, the ``[[waypoints]]`` the plan
    became: not the plan's item numbers, as the message says); one per rally point outside the fence (``rally``: (lat, lon, alt))."""
    if not zones:
        return []
    local = local_zones(zones, home)
    xy = [(0.0, 0.0)] + [(float(w["x_m"]), float(w["y_m"])) for w in route]
    out = []
    for z, k in route_breaches(xy, local):
        a, b = xy[k], xy[min(k + 1, len(xy) - 1)]
        leg = "from home" if k == 0 else f"from route point {k - 1}"
        verb = "leaves" if z.inclusion else "enters"
        out.append(f"{name}: the route {verb} the plan's geofence {z.name} on the leg {leg} ({a[0]:.0f}, {a[1]:.0f}) m "
                   f"to route point {k} ({b[0]:.0f}, {b[1]:.0f}) m (pad frame, ENU about home; route points are "
                   "[[waypoints]] indices, not the plan's item numbers); the route is flown as planned (no fence "
                   "action is simulated): valid: a route inside the fence")
    for i, (lat, lon, _) in enumerate(rally):
        p = local_zones([GeoZone("circle", True, ((lat, lon),), 1.0)], home)[0].xy_m
        for z, _k in route_breaches(p, local):
            out.append(f"{name}: rally point {i} ({lat:.6f}, {lon:.6f}) is {'outside' if z.inclusion else 'inside'} "
                       f"the plan's geofence {z.name}")
    return out
