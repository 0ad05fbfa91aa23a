"""Mission items from files: QGC ``.plan``, ``.waypoints`` (QGC WPL 110) and MAVLink logs.

Every reader returns a :class:`RawMission`: the home position (a
:class:`~mission_sim.mavlink.geodesy.GeoPoint` with its altitude in m AMSL, or None when the file
has none) and the items in file order as :class:`MissionItem` (MAVLink ``MISSION_ITEM`` fields:
command, frame, param1..4, latitude, longitude, altitude). Bad content raises ``ValueError`` with
one line naming the file and, where it applies, the item (its index as the ground station shows
it: the position in ``mission.items`` of a .plan, the sequence number of a .waypoints row).

Formats (checked against QGroundControl's and ArduPilot's own files in tests/data/missions):

* ``.plan``: JSON, ``fileType`` "Plan", ``mission.items`` of ``SimpleItem`` (``command``,
  ``frame``, ``params`` = [p1, p2, p3, p4, lat, lon, alt], or QGC's older items: ``params`` = [p1..p4] and
  ``coordinate`` = [lat, lon, alt]) and ``ComplexItem`` (survey / corridor scan: their generated
  ``TransectStyleComplexItem.Items`` when present, else the ``VisualTransectPoints`` at the camera's
  ``DistanceToSurface``; a structure scan, which keeps only its inputs: the waypoints QGC generates,
  :func:`_structure_scan`), ``mission.plannedHomePosition`` = [lat, lon, alt AMSL]. Each item keeps its ``doJumpId``
  (a .waypoints row and a log item their sequence number) for DO_JUMP.
* ``.waypoints`` / ``.txt``: first line ``QGC WPL 110``, then one row per item: index, current,
  frame, command, p1, p2, p3, p4, lat, lon, alt, autocontinue (tabs); row 0 is home (AMSL).
* a ``.tlog``: the last MISSION_ITEM_INT / MISSION_ITEM of each sequence number (a mission is
  read back many times); ArduPilot's item 0 is home, else HOME_POSITION. A DataFlash ``.bin``:
  CMD records (CNum 0 = home). :func:`flown_mission` takes the GPS track instead.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..mavlink import ground
from ..mavlink.geodesy import GeoPoint
from ..validation import ALT_RANGE, Range, check_number

__all__ = ["MissionItem", "RawMission", "read_mission", "read_plan", "read_wpl", "uploaded_mission",
           "flown_mission", "LOG_SUFFIXES"]

LOG_SUFFIXES = (".tlog", ".bin", ".log", ".ulg")
NAV_WAYPOINT, NAV_LOITER_TIME, NAV_RTL, NAV_LAND, NAV_TAKEOFF = 16, 19, 20, 21, 22
FLOWN_TOLERANCE_M = 3.0        # decimation: the flown route stays within this of the GPS track
FLOWN_HOLD_S = 5.0             # slower than HOVER_M_S for this long: a loiter item in the flown route
HOVER_M_S = 0.5
#: QGC's complex items that save their generated waypoints (TransectStyleComplexItem); a StructureScan saves its inputs
_TRANSECT_TYPES = ("survey", "CorridorScan")


@dataclass(frozen=True)
class MissionItem:
    """One mission item (MAVLink MISSION_ITEM fields; lat/lon in degrees, alt in m in ``frame``).

    ``where`` names it in errors ("item 3", "item 5 (survey), generated item 12", "row 7").
    """

    where: str
    command: int
    frame: int
    params: tuple            # (p1, p2, p3, p4), nan where unset
    lat_deg: float
    lon_deg: float
    alt_m: float
    jump_id: int | None = None   # what a DO_JUMP names it by: a .plan's doJumpId, a row's / log's sequence no.


@dataclass(frozen=True)
class RawMission:
    """Items of one mission file and its home (None: the file has none); a ``.plan``'s geofence zones
    (:class:`~mission_sim.plans.fence.GeoZone`) and rally points ((lat, lon, alt AMSL)), read since 2026-11-28
    (:mod:`mission_sim.plans.fence`: warnings only, the route is flown as planned)."""

    source: str
    home: GeoPoint | None
    items: tuple
    fence: tuple = ()
    rally: tuple = ()


def _num(v) -> float:
    """A JSON / text number (None -> nan); ``TypeError`` / ``ValueError`` for anything else."""
    if v is None:
        return float("nan")
    if isinstance(v, bool) or not isinstance(v, (int, float, str)):
        raise TypeError(f"{v!r} is not a number")
    return float(v)


def _home(lat, lon, alt, name: str, what: str) -> GeoPoint:
    try:
        return GeoPoint(float(lat), float(lon), float(alt))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: {what} is invalid: {exc}") from None


def read_mission(path, from_log: str = "auto") -> RawMission:
    """The mission of ``path`` by its kind: .plan (JSON), QGC WPL text, or a flight log
    (``from_log``: "uploaded" items, "flown" track, "auto" = uploaded if the log holds a mission)."""
    from ..validation import check_regular_file
    path = check_regular_file(path, "mission file (--plan / mission.file)", "a .plan, .waypoints or log file")
    if path.suffix.lower() in LOG_SUFFIXES:
        if from_log != "flown":
            up = uploaded_mission(path)
            if up.items or from_log == "uploaded":
                if not up.items:
                    raise ValueError(f"{path.name}: the log holds no uploaded mission (no MISSION_ITEM / CMD "
                                     "records); valid: from_log = \"flown\" for its GPS track")
                return up
        return flown_mission(path)
    head = path.read_bytes()[:64].removeprefix(b"\xef\xbb\xbf").lstrip()   # a UTF-8 BOM (Windows editors)
    if head.startswith(b"QGC WPL"):
        return read_wpl(path)
    if head.startswith(b"{") or path.suffix.lower() == ".plan":
        return read_plan(path)
    raise ValueError(f"{path.name}: not a mission file; valid: a QGC .plan (JSON), a .waypoints file starting "
                     f"'QGC WPL 110', or a flight log ({', '.join(LOG_SUFFIXES)})")


# ----------------------------------------------------------------------------------- .plan
def read_plan(path) -> RawMission:
    """A QGroundControl ``.plan`` file (JSON); see the module docstring for the fields used."""
    path = Path(path)
    name = path.name
    try:
        doc = json.loads(path.read_bytes().decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{name}: not a UTF-8 text (JSON) file: byte {exc.object[exc.start]:#04x} at offset "
                         f"{exc.start}") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{name}: malformed JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:   # '[' * 100000: the parser's recursion, a traceback until 2026-11-28
        from ..validation import json_too_deep
        raise ValueError(json_too_deep(name, "a QGroundControl plan", "a JSON object with \"fileType\": \"Plan\"")) \
            from None
    if not isinstance(doc, dict) or doc.get("fileType") != "Plan":
        raise ValueError(f"{name}: not a QGroundControl plan; valid: a JSON object with \"fileType\": \"Plan\"")
    mission = doc.get("mission")
    if not isinstance(mission, dict) or not isinstance(mission.get("items"), list):
        raise ValueError(f"{name}: no mission items; valid: \"mission\": {{\"items\": [...]}}")
    hp = mission.get("plannedHomePosition")
    home = None
    if hp is not None:
        if not (isinstance(hp, list) and len(hp) == 3 and all(isinstance(v, (int, float)) for v in hp)):
            raise ValueError(f"{name}: plannedHomePosition={hp!r} is invalid; valid: [lat, lon, alt AMSL]")
        home = _home(*hp, name, "plannedHomePosition")
    items = []
    for i, it in enumerate(mission["items"]):
        items += _plan_item(it, f"item {i}", name)
    from .fence import read_plan_fence
    fence, rally = read_plan_fence(doc, name)
    return RawMission(name, home, tuple(items), fence, rally)


def _simple(it, where: str, name: str) -> MissionItem:
    _json_object(it, f"{name}: {where}", absent_ok=False)
    params = it.get("params")
    coord = it.get("coordinate")
    if isinstance(params, list) and len(params) == 4 and coord is not None:
        # an item as QGroundControl saved it before its item version 3 (QGC 3.2-3.3 plans, its own SectionTest.plan):
        # p1..p4 in "params", [lat, lon, alt] in "coordinate"; QGC reads it (MissionItem::_convertJsonV2ToV3)
        if not isinstance(coord, list) or len(coord) != 3:
            raise ValueError(f"{name}: {where}: coordinate={coord!r} is invalid; valid: [lat, lon, alt]")
        params = params + coord
    if not isinstance(params, list) or len(params) != 7:
        raise ValueError(f"{name}: {where}: params={params!r} is invalid; valid: 7 numbers (p1..p4, lat, lon, alt), "
                         "or 4 (p1..p4) beside a \"coordinate\" [lat, lon, alt] (QGroundControl's older plans)")
    try:
        p = [_num(v) for v in params]
        cmd, frame = it["command"], it.get("frame", 0)
        if isinstance(cmd, bool) or not isinstance(cmd, int) or isinstance(frame, bool) or not isinstance(frame, int):
            raise TypeError("command and frame must be integers")
    except KeyError:
        raise ValueError(f"{name}: {where} has no \"command\"") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: {where}: {exc}") from None
    jid = it.get("doJumpId")
    jid = jid if isinstance(jid, int) and not isinstance(jid, bool) else None
    return MissionItem(where, cmd, frame, tuple(p[:4]), p[4], p[5], p[6], jid)


def _plan_item(it, where: str, name: str) -> list[MissionItem]:
    kind = it.get("type") if isinstance(it, dict) else None
    if kind == "SimpleItem":
        return [_simple(it, where, name)]
    if kind != "ComplexItem":
        raise ValueError(f"{name}: {where}: type={kind!r} is invalid; valid: SimpleItem, ComplexItem")
    ctype = it.get("complexItemType", "?")
    tsc = _json_object(it.get("TransectStyleComplexItem"), f"{name}: {where} ({ctype}): TransectStyleComplexItem")
    sub = tsc.get("Items") or it.get("Items") or it.get("items")
    if isinstance(sub, list) and sub:
        return [_simple(s, f"{where} ({ctype}), generated item {j}", name) for j, s in enumerate(sub)]
    if ctype == "StructureScan" and isinstance(it, dict):   # QGC saves its inputs only, never its waypoints
        return _structure_scan(it, f"{where} ({ctype})", name)
    pts = tsc.get("VisualTransectPoints")
    cam = _json_object(tsc.get("CameraCalc"), f"{name}: {where} ({ctype}): CameraCalc")
    alt = cam.get("DistanceToSurface", tsc.get("Altitude"))
    if isinstance(pts, list) and pts and isinstance(alt, (int, float)) and not isinstance(alt, bool):
        frame = 3 if cam.get("DistanceToSurfaceRelative", True) else 0
        try:
            return [MissionItem(f"{where} ({ctype}), transect point {j}", NAV_WAYPOINT, frame, (0.0,) * 4,
                                _num(p[0]), _num(p[1]), float(alt)) for j, p in enumerate(pts)]
        except (TypeError, ValueError, IndexError, KeyError) as exc:
            raise ValueError(f"{name}: {where} ({ctype}): VisualTransectPoints are invalid: {exc}") from None
    if ctype not in _TRANSECT_TYPES:   # (a landing pattern keeps its inputs only, as a structure scan: no save helps)
        raise ValueError(f"{name}: {where}: complex item {ctype!r} is not supported; supported complex items: "
                         f"{', '.join(_TRANSECT_TYPES)}, StructureScan")
    raise ValueError(f"{name}: {where}: complex item {ctype!r} has no generated waypoints (TransectStyleComplexItem "
                     "Items or VisualTransectPoints with a CameraCalc DistanceToSurface); valid: save the plan "
                     "from QGroundControl after the survey was generated")


#: a structure scan's numeric inputs: (key, "CameraCalc." when it is the camera's, range); heights above home as a
#: route waypoint's (:data:`~mission_sim.validation.ALT_RANGE`)
_SCAN_INPUTS = (("EntranceAltitude", "", ALT_RANGE), ("ScanBottomAlt", "", ALT_RANGE), ("StructureHeight", "", ALT_RANGE),
                ("Layers", "", Range(1, 1000, integer=True)),
                ("DistanceToSurface", "CameraCalc.", Range(0.0, math.inf, "m", hi_open=True)),
                ("AdjustedFootprintFrontal", "CameraCalc.", Range(0.0, math.inf, "m", lo_open=True, hi_open=True)))


def _json_object(value, what: str, absent_ok: bool = True) -> dict:
    """``value`` (absent, null: ``{}`` when ``absent_ok``) when it is a JSON object; else ``ValueError`` naming ``what``
    and the value as the file spells it (a ``true`` or a list there was an AttributeError traceback)."""
    if absent_ok and (value is None or value == {}):
        return {}
    if not isinstance(value, dict):
        raise ValueError(f"{what}={json.dumps(value)[:60]} is invalid; valid: a JSON object {{...}}")
    return value


def _structure_scan(it: dict, where: str, name: str) -> list[MissionItem]:
    """The waypoints QGroundControl generates for a structure scan (``StructureScanComplexItem::appendMissionItems``;
    a plan holds only the scan's inputs): the structure's polygon offset outwards by the camera's
    ``DistanceToSurface`` (``QGCMapPolygon::offset``: each edge moved out, new vertices where the moved edges meet, in
    a tangent plane at vertex 0; QGC moves each edge to its left, which is outwards for the clockwise polygons its
    editor saves: here outwards whatever the winding), flown around (every vertex and back to the first) once per
    layer, the layers
    ``AdjustedFootprintFrontal`` apart from half of it above ``ScanBottomAlt`` up (or half of it below
    ``StructureHeight`` down with ``StartFromTop``), entered and left at vertex 0 at ``EntranceAltitude``; heights
    above home (QGC writes them in frame 3). Its camera and ROI items do not move the vehicle and are left out."""
    from ..mavlink.geodesy import enu_to_geodetic, geodetic_to_enu
    cam = _json_object(it.get("CameraCalc"), f"{name}: {where}: CameraCalc")
    vals = {}
    for key, src, rng in _SCAN_INPUTS:
        value = (cam if src else it).get(key)
        try:
            vals[key] = check_number(f"{src}{key}", value, rng, " (QGroundControl saves it)" if value is None else "")
        except ValueError as exc:
            raise ValueError(f"{name}: {where}: {exc}") from None
    layers, step, gap = vals["Layers"], vals["AdjustedFootprintFrontal"], vals["DistanceToSurface"]
    top = it.get("StartFromTop", False)
    if not isinstance(top, bool):   # (bool("false") is True: the scan was flown from the top)
        raise ValueError(f"{name}: {where}: StartFromTop={json.dumps(top)[:60]} is invalid; valid: true or false (a "
                         "JSON boolean)")
    poly = it.get("polygon")
    try:
        ll = np.array([[_num(c[0]), _num(c[1])] for c in poly], dtype=float)
        if len(ll) < 3 or not np.all(np.isfinite(ll)):
            raise ValueError("fewer than 3 vertices")
        origin = GeoPoint(float(ll[0, 0]), float(ll[0, 1]), 0.0)
    except (TypeError, ValueError, IndexError, KeyError) as exc:
        raise ValueError(f"{name}: {where}: polygon is invalid ({exc}); valid: 3 or more [lat, lon] vertices") from None
    e, n, _ = geodetic_to_enu(ll[:, 0], ll[:, 1], 0.0, origin)
    xy = np.column_stack([e, n])
    sign = -1.0 if np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]) > 0 else 1.0
    d = np.roll(xy, -1, axis=0) - xy                       # edge i: vertex i -> i + 1
    length = np.linalg.norm(d, axis=1)
    if np.any(length < 1e-6):
        raise ValueError(f"{name}: {where}: polygon has two equal consecutive vertices; valid: a simple polygon")
    out = sign * np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]   # outward normal (left of a clockwise edge)
    p0 = xy + gap * out                                    # the offset edges: p0 + t d
    flight = []
    for i in range(len(xy)):                               # vertex i: offset edges i - 1 and i meet
        a, da, b, db = p0[i - 1], d[i - 1], p0[i], d[i]
        den = da[0] * db[1] - da[1] * db[0]
        if abs(den) < 1e-9 * length[i - 1] * length[i]:    # (parallel: the shared vertex moved out)
            flight.append(b)
            continue
        t = ((b[0] - a[0]) * db[1] - (b[1] - a[1]) * db[0]) / den
        flight.append(a + t * da)
    flight = np.array(flight)
    lat, lon, _ = enu_to_geodetic(flight[:, 0], flight[:, 1], 0.0, origin)
    alt0 = vals["StructureHeight"] - step / 2 if top else vals["ScanBottomAlt"] + step / 2
    items = [MissionItem(f"{where}, entrance", NAV_WAYPOINT, 3, (0.0,) * 4, float(lat[0]), float(lon[0]),
                         vals["EntranceAltitude"])]
    for k in range(int(layers)):
        alt = alt0 - k * step if top else alt0 + k * step
        items += [MissionItem(f"{where}, layer {k} vertex {j % len(lat)}", NAV_WAYPOINT, 3, (0.0,) * 4,
                              float(lat[j % len(lat)]), float(lon[j % len(lat)]), alt) for j in range(len(lat) + 1)]
    items.append(MissionItem(f"{where}, exit", NAV_WAYPOINT, 3, (0.0,) * 4, float(lat[0]), float(lon[0]),
                             vals["EntranceAltitude"]))
    return items


# -------------------------------------------------------------------------------- .waypoints
#: a QGC WPL row's integer fields: (column, name, range): MISSION_ITEM's seq and command (uint16), frame (uint8)
_WPL_INTS = ((0, "index", Range(0, 65535, integer=True)), (2, "frame", Range(0, 255, integer=True)),
             (3, "command", Range(0, 65535, integer=True)))


def read_wpl(path) -> RawMission:
    """A ``QGC WPL 110`` text file (ArduPilot, Mission Planner, QGC); row 0 is home."""
    path = Path(path)
    name = path.name
    try:
        lines = path.read_bytes().decode("utf-8-sig").splitlines()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{name}: not a text file: byte {exc.object[exc.start]:#04x} at offset {exc.start}") from None
    if not lines or not lines[0].strip().startswith("QGC WPL 110"):
        raise ValueError(f"{name}: line 1 is {lines[0][:40]!r}; valid: 'QGC WPL 110'" if lines else f"{name}: empty file")
    rows = []
    for ln, text in enumerate(lines[1:], start=2):
        if not text.strip():
            continue
        f = text.split()
        if len(f) != 12:
            raise ValueError(f"{name}: line {ln} has {len(f)} fields; valid: 12 (index, current, frame, command, "
                             "p1..p4, lat, lon, alt, autocontinue)")
        try:
            v = [float(x) for x in f]
        except ValueError:
            raise ValueError(f"{name}: line {ln}: a field is not a number: {text.strip()[:80]!r}") from None
        # (index, frame, command are MAVLink integers: nan gave "cannot convert float NaN to integer", naming no file,
        #  inf an OverflowError traceback, 16.5 was taken as 16)
        seq, frame, cmd = (check_number(f"{name}: line {ln}: {what}", v[i], rng) for i, what, rng in _WPL_INTS)
        rows.append((seq, cmd, frame, tuple(v[4:8]), v[8], v[9], v[10]))
    if not rows or rows[0][0] != 0:
        raise ValueError(f"{name}: missing home: row 0 (the home position, AMSL) is not the first row")
    seq0, _, _, _, lat, lon, alt = rows[0]
    home = _home(lat, lon, alt, name, "home (row 0)")
    items = tuple(MissionItem(f"row {r[0]}", r[1], r[2], r[3], r[4], r[5], r[6], r[0]) for r in rows[1:])
    return RawMission(name, home, items)


# ------------------------------------------------------------------------------------- logs
def uploaded_mission(path) -> RawMission:
    """The mission a log uploaded or read back: a .tlog's MISSION_ITEM_INT / MISSION_ITEM (the last
    of each sequence number), a DataFlash log's CMD records; home from ArduPilot's item 0 or
    HOME_POSITION. No items: a RawMission with none. Read with the flight-log readers of
    :func:`mission_sim.mavlink.logs.open_log` (never ``mavlink_connection``, which executes a path
    containing /bin/), pymavlink's reports on corrupt bytes kept off the terminal."""
    from ..mavlink.logs import close_log, mavutil, open_log
    path = Path(path)
    found: dict[int, tuple] = {}
    home, count = None, None
    types = ["MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_COUNT", "CMD", "HOME_POSITION", "HEARTBEAT"]
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        try:
            conn, kind = open_log(path, mavutil())
        except Exception as exc:  # noqa: BLE001 -- untrusted bytes
            raise ValueError(f"{path.name}: the log could not be parsed: {type(exc).__name__}: {exc}") from None
        ardupilot = kind == "dataflash"
        try:
            while True:
                try:
                    msg = conn.recv_match(type=types, blocking=False)
                except Exception as exc:  # noqa: BLE001 -- untrusted bytes: stop where the parser failed
                    raise ValueError(f"{path.name}: the log could not be parsed: {type(exc).__name__}: {exc}") from None
                if msg is None:
                    break
                t = msg.get_type()
                if t == "HEARTBEAT":
                    ardupilot |= msg.autopilot == 3   # MAV_AUTOPILOT_ARDUPILOTMEGA: item 0 is home
                elif t == "MISSION_COUNT" and getattr(msg, "mission_type", 0) == 0:
                    count = int(msg.count)   # the last upload / download: its items are seq 0 .. count - 1
                elif t == "HOME_POSITION":
                    home = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
                elif t == "CMD":
                    found[int(msg.CNum)] = (int(msg.CId), int(getattr(msg, "Frame", 0 if msg.CNum == 0 else 3)),
                                            (msg.Prm1, msg.Prm2, msg.Prm3, msg.Prm4), msg.Lat, msg.Lng, msg.Alt)
                elif getattr(msg, "mission_type", 0) == 0:
                    scale = 1e-7 if t == "MISSION_ITEM_INT" else 1.0
                    found[int(msg.seq)] = (int(msg.command), int(msg.frame), (msg.param1, msg.param2, msg.param3,
                                           msg.param4), msg.x * scale, msg.y * scale, float(msg.z))
        finally:
            close_log(conn)
    seqs = sorted(s for s in found if count is None or s < count)
    if ardupilot and 0 in found:
        _, _, _, lat, lon, alt = found.pop(0)
        home = (lat, lon, alt)
        seqs = seqs[1:]
    items = tuple(MissionItem(f"item {s}", *found[s][:3], *found[s][3:], s) for s in seqs)
    return RawMission(path.name, None if home is None else _home(*home, path.name, "home"), items)


def _decimate(p: np.ndarray, tol: float) -> np.ndarray:
    """Indices of the Ramer-Douglas-Peucker simplification of the polyline ``p`` (N, 3): every
    dropped point lies within ``tol`` metres of the kept polyline."""
    keep = np.zeros(len(p), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(p) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg = p[b] - p[a]
        rel = p[a + 1:b] - p[a]
        L = float(np.linalg.norm(seg))
        if L < 1e-9:
            d = np.linalg.norm(rel, axis=1)
        else:
            d = np.linalg.norm(np.cross(rel, seg / L), axis=1)
        k = int(np.argmax(d))
        if d[k] > tol:
            keep[a + 1 + k] = True
            stack += [(a, a + 1 + k), (a + 1 + k, b)]
    return np.flatnonzero(keep)


def flown_mission(path, tolerance_m: float = FLOWN_TOLERANCE_M) -> RawMission:
    """The route a log flew: its GPS track (fix >= 3, implausible fixes rejected) over the armed time,
    decimated to waypoints within ``tolerance_m`` of the track (Ramer-Douglas-Peucker; every take-off and landing, the
    track crossing :data:`~mission_sim.mavlink.ground.GROUND_M`, kept), stops of at least :data:`FLOWN_HOLD_S` in the air as loiter items,
    points on the ground as landings (the route takes off
    again at the next airborne point; time spent on the ground is not kept), a landing at the end;
    home = the replay's take-off spot (:func:`mission_sim.mavlink.takeoff.default_pad`: the first armed position, or
    for a log that starts armed in the air where its first armed period ends). A log that never armed has none
    (``ValueError``); one whose armed state is unknown flies its whole track
    (:func:`~mission_sim.mavlink.takeoff.flown_periods`, :func:`~mission_sim.mavlink.takeoff.unknown_armed_state`)."""
    from ..mavlink.geodesy import geodetic_to_enu
    from ..mavlink.logs import read_log
    log = read_log(path)
    pos = log.position
    from ..mavlink.takeoff import VALID_FLIGHT, flown_periods, unknown_armed_state
    periods = flown_periods(log)   # the armed periods; the armed state unknown: the whole track (one rule with replay)
    name = Path(path).name
    if log.armed_source is not None and not periods:   # (its fixes were GPS drift on the ground: 1 s of "flight")
        raise ValueError(f"{name}: no flown track: the vehicle never armed in the log (armed state from "
                         f"{log.armed_source}); valid: {VALID_FLIGHT}, or a log holding an uploaded mission")
    if periods:
        t = pos["t_s"].to_numpy(float)
        pos = pos[(t >= periods[0][0]) & (t <= periods[-1][1])]
    if len(pos) < 2:
        raise ValueError(f"{name}: no flown track: {len(pos)} usable position(s) (GPS fix >= 3)"
                         + (" while armed" if log.armed_periods else ""))
    lat, lon, alt = (pos[c].to_numpy(float) for c in ("lat_deg", "lon_deg", "alt_m"))
    from ..mavlink.takeoff import default_pad, starts_airborne_warning
    home = default_pad(log)   # the first armed position; a log that starts in the air: where its first flight ended
    airborne = starts_airborne_warning(log)   # (then said, as replay says it)
    if airborne is not None:
        from wpt_receiver.notices import warn
        warn(airborne)
    e, n, u = geodetic_to_enu(lat, lon, alt, home)
    p = np.column_stack([e, n, np.maximum(u, 0.0)])
    if log.armed_source is None:   # no armed-state record and no motor output: the whole track (as before 2026-11-27)
        from wpt_receiver.notices import warn
        warn(unknown_armed_state(name, float(p[:, 2].max()), valid=f"{VALID_FLIGHT}, or a log holding an uploaded "
                                 "mission"))
    t = pos["t_s"].to_numpy(float)
    air = p[:, 2] >= ground.GROUND_M   # (below it: on the ground, a landing)
    cross = np.flatnonzero(air[1:] != air[:-1])   # each take-off and landing kept: a flight lower than the tolerance
    keep = np.union1d(_decimate(p, tolerance_m), np.concatenate([cross, cross + 1]))   # (a 2 m hop) was dropped whole
    items = []
    for a, b in zip(keep[:-1], keep[1:]):
        if p[b, 2] < ground.GROUND_M:   # on the ground: a landing (the next airborne point takes off again)
            if not items or items[-1].command != NAV_LAND:
                items.append(MissionItem(f"track point {b}", NAV_LAND, 0, (0.0,) * 4, lat[b], lon[b], home.alt_m))
            continue
        hold = _stop_time(p[a:b + 1], t[a:b + 1], air[a:b + 1])
        cmd, p1 = (NAV_LOITER_TIME, hold) if hold >= FLOWN_HOLD_S else (NAV_WAYPOINT, 0.0)
        items.append(MissionItem(f"track point {b}", cmd, 0, (p1, 0.0, 0.0, 0.0), lat[b], lon[b], home.alt_m + p[b, 2]))
    if not items or items[-1].command != NAV_LAND:
        items.append(MissionItem("track end", NAV_LAND, 0, (0.0,) * 4, lat[-1], lon[-1], home.alt_m))
    return RawMission(f"{Path(path).name} (flown track)", home, tuple(items))


def _stop_time(p: np.ndarray, t: np.ndarray, air: np.ndarray) -> float:
    """Seconds spent slower than :data:`HOVER_M_S` in the air (``air`` at both ends of a step) on one decimated leg (its
    hovering; time sitting on the ground is no hover)."""
    if len(t) < 2:
        return 0.0
    dt = np.diff(t)
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.maximum(dt, 1e-9)
    return float(np.sum(dt[(v < HOVER_M_S) & (dt < 10.0) & air[:-1] & air[1:]]))
