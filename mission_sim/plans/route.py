"""Mission items -> the config's ``[[waypoints]]`` route in the pad frame; pads files -> ``[[pads]]``.

The pad frame of a mission file is local ENU metres about the mission's home (its ground is z = 0),
by :func:`mission_sim.mavlink.geodesy.geodetic_to_enu` (WGS84 radii of curvature at home; the
flat-plane error is ~8 cm of height at 1 km). Altitude frames: 0 / 5 (global, m AMSL: z = alt -
home altitude) and 3 / 6 (relative to home: z = alt); terrain frames (10, 11) are refused (no
terrain model). As ArduCopter does (``ModeAuto::loc_from_cmd``), latitude = longitude = 0 means
"here" and altitude 0 "at the current height".

Commands: NAV_WAYPOINT (16; param1 > 0 = hold seconds: a loiter), NAV_LOITER_TIME (19, param1
seconds), NAV_RETURN_TO_LAUNCH (20: climb to at least :data:`RTL_ALT_M`, fly home, land),
NAV_LAND (21), NAV_TAKEOFF (22, vertical), NAV_DELAY (93, param1 > 0 seconds: a hover where the vehicle is, in the
air only; param1 = 0 with params 2-4 zero: no delay; else a time of day, refused), DO_CHANGE_SPEED (178, param2 m/s: the speed of the
following legs), DO_JUMP (177, param1 the target, param2 the number of jumps: the loop unrolled, :func:`_unrolled`).
Commands that do not move the vehicle (camera, gimbal, servo, relay, ROI, yaw:
:data:`IGNORED_COMMANDS`) are skipped; any other command is an error naming it and its item.
Payload releases (:func:`release_of`): DO_GRIPPER (211) with param2 = 0 (GRIPPER_ACTION_RELEASE) counts one release
on the waypoint before it (``release`` of its ``[[waypoints]]`` dict: as ArduPilot and PX4 run a DO item once the nav
item before it is done). Each release drops ``drone.release_kg`` of ``drone.payload_kg``
(:func:`mission_sim.world.power.payload_after_releases`). A gripper grab (param2 = 1) or hold (2) adds or drops
nothing (the mass picked up is not known: carry it from take-off in ``payload_kg`` instead). DO_WINCH (42600) is
not a release, not even WINCH_DELIVER (param2 = 4), which the MAVLink spec describes as "lower, release, reel up":
the autopilots do not drop a payload on it in a mission (ArduCopter's ``ModeAuto::do_winch`` handles relaxed, length
and rate control only; PX4 supports grippers, not winches, for package delivery), and the simulator follows the
autopilots: a route holding a winch deliver warns once that it drops nothing (count it with a DO_GRIPPER release
after it, or ``release = 1`` on the ``[[waypoints]]`` entry). A release before the first navigation item is refused
(it would drop the payload on the ground before take-off).
A loiter within ``mission.pad_radius_m`` of a pad (horizontally) and at least
:data:`CHARGE_CLEARANCE_M` above it becomes a charging hover over that pad (waypoint action
"charge": descend to the pad, charge, climb back).
"""

from __future__ import annotations

import math
from pathlib import Path

from ..mavlink.geodesy import GeoPoint, geodetic_to_enu
from ..validation import (ALT_RANGE, HOLD_RANGE, PAD_RADIUS_RANGE, SPEED_RANGE,
                          Range, check_number)
from .items import LOG_SUFFIXES, NAV_LAND, NAV_LOITER_TIME, NAV_RTL, NAV_TAKEOFF, NAV_WAYPOINT, RawMission, read_mission
from .pads import read_pads

__all__ = ["apply_mission_files", "check_file_keys", "mission_home", "route_from_items", "pads_to_local", "command_name",
           "release_of", "winch_deliver_of", "RTL_ALT_M", "IGNORED_COMMANDS"]

DO_CHANGE_SPEED = 178
NAV_DELAY = 93
NAV_PAYLOAD_PLACE = 94
#: NAV_PAYLOAD_PLACE's param1, the largest descent [m] (0 or unset: no limit; ArduPilot's AP_Mission stores it in cm)
PLACE_DESCENT_RANGE = Range(0.0, 5000.0, "m")
DO_JUMP = 177
MAX_ROUTE_ITEMS = 100_000   # a route with DO_JUMP loops unrolled: at most this many items flown
JUMP_REPEATS = Range(0, math.inf, integer=True)   # a DO_JUMP's param2, the number of jumps (-1, forever: refused)
CHARGE_CLEARANCE_M = 1.0   # a loiter becomes a charging hover only this far above the pad (it descends to it)
RTL_ALT_M = 15.0   # ArduCopter's RTL_ALT default (1500 cm): RTL climbs to at least this height
MAX_FROM_HOME_M = 100e3   # items farther from home than this are refused (the config's positions: within 1e5 m)
#: commands that do not move the vehicle: CONDITION_YAW, DO_SET_RELAY, DO_REPEAT_RELAY, DO_SET_SERVO,
#: DO_REPEAT_SERVO, DO_SET_ROI_LOCATION, DO_SET_ROI_NONE, DO_CONTROL_VIDEO, DO_SET_ROI,
#: DO_DIGICAM_CONFIGURE, DO_DIGICAM_CONTROL, DO_MOUNT_CONFIGURE, DO_MOUNT_CONTROL,
#: DO_SET_CAM_TRIGG_DIST, DO_SET_CAM_TRIGG_INTERVAL, SET_CAMERA_MODE, DO_GIMBAL_MANAGER_PITCHYAW,
#: IMAGE_START_CAPTURE, IMAGE_STOP_CAPTURE, VIDEO_START_CAPTURE, VIDEO_STOP_CAPTURE; since 2026-11-27 night also
#: CONDITION_DELAY, CONDITION_DISTANCE (they hold back the next DO command, not the vehicle), DO_LAND_START and JUMP_TAG
#: (markers flown through), DO_FENCE_ENABLE, DO_GRIPPER (since 2026-11-28 a release drops the payload:
#: :func:`release_of`; grab and hold change nothing), DO_SET_RESUME_REPEAT_DIST, DO_SPRAYER, DO_MOUNT_CONTROL_QUAT,
#: SET_CAMERA_ZOOM, SET_CAMERA_FOCUS, DO_GIMBAL_MANAGER_CONFIGURE, DO_WINCH (no payload drop, not even its deliver
#: action: the autopilots do not drop one, :func:`winch_deliver_of` warns)
IGNORED_COMMANDS = frozenset({115, 181, 182, 183, 184, 195, 197, 200, 201, 202, 203, 204, 205, 206, 214, 530, 1000,
                              2000, 2001, 2500, 2501,
                              112, 114, 189, 600, 207, 211, 215, 216, 220, 531, 532, 1001, 42600})
_NAV = {NAV_WAYPOINT: "waypoint", NAV_LOITER_TIME: "loiter", NAV_RTL: "rtl", NAV_LAND: "land", NAV_TAKEOFF: "takeoff"}
_AMSL_FRAMES, _RELATIVE_FRAMES, _TERRAIN_FRAMES = (0, 5), (3, 6), (10, 11)
#: MAV_CMD_NAV_FENCE_* and MAV_CMD_NAV_RALLY_POINT: the items of a fence or rally list, not of a mission
_FENCE_RALLY = {5000: "geofence return point", 5001: "geofence polygon vertex", 5002: "geofence polygon vertex",
                5003: "geofence circle", 5004: "geofence circle", 5100: "rally point"}
_SUPPORTED = ("NAV_WAYPOINT (16), NAV_LOITER_TIME (19), NAV_RETURN_TO_LAUNCH (20), NAV_LAND (21), NAV_TAKEOFF (22), "
              "NAV_DELAY (93), NAV_PAYLOAD_PLACE (94), DO_JUMP (177), DO_CHANGE_SPEED (178) and commands that do not move the vehicle "
              "(camera, gimbal, servo, relay, ROI, yaw, gripper, winch, sprayer, fence enable, conditions, markers)")


def _action(it) -> float:
    """A DO item's param2 (unset: 0, as the autopilots read a missing param)."""
    return it.params[1] if len(it.params) > 1 and math.isfinite(it.params[1]) else 0.0


def release_of(it) -> bool:
    """Whether mission item ``it`` releases the payload: DO_GRIPPER with param2 = GRIPPER_ACTION_RELEASE (0; unset
    counts as 0, as the autopilots read a missing param). Not DO_WINCH (:func:`winch_deliver_of`)."""
    from ..mavlink.logs import mavutil
    mav = mavutil().mavlink
    return it.command == mav.MAV_CMD_DO_GRIPPER and _action(it) == mav.GRIPPER_ACTION_RELEASE


def winch_deliver_of(it) -> bool:
    """Whether ``it`` is DO_WINCH with param2 = WINCH_DELIVER (4): no payload drop here (the autopilots drop none in
    a mission), a warning (:func:`route_from_items`)."""
    from ..mavlink.logs import mavutil
    mav = mavutil().mavlink
    return it.command == mav.MAV_CMD_DO_WINCH and _action(it) == mav.WINCH_DELIVER


def command_name(cmd: int) -> str:
    """``MAV_CMD_NAV_LOITER_TURNS`` -> ``NAV_LOITER_TURNS`` (pymavlink's MAV_CMD enum), else ``MAV_CMD <n>``."""
    from ..mavlink.logs import mavutil
    entry = mavutil().mavlink.enums.get("MAV_CMD", {}).get(int(cmd))
    name = getattr(entry, "name", "") or ""
    return name.removeprefix("MAV_CMD_") if name and not name.endswith("ENUM_END") else f"MAV_CMD {cmd}"


class _Builder:
    """Walks the items keeping the current position (pad frame) and the speed set by DO_CHANGE_SPEED."""

    def __init__(self, raw: RawMission, pads_xyz=(), pad_radius_m: float = 5.0):
        self.raw, self.name = raw, raw.source
        self.pads, self.radius = list(pads_xyz), pad_radius_m
        self.x = self.y = self.z = 0.0
        self.speed = None
        self.out: list[dict] = []
        self.placed: list[str] = []      # NAV_PAYLOAD_PLACE items flown (warned: what is not modelled)
        self.unplaced: list[str] = []    # those whose max descent stops above the ground (no release)

    def fail(self, it, text: str):
        raise ValueError(f"{self.name}: {it.where}: {text}")

    def in_range(self, it, what: str, value: float, rng, key: str):
        """:meth:`fail` unless ``value`` is inside ``rng``, the range of the route's ``[[waypoints]]`` key it becomes
        (``key``; one range for a file's item and a hand-written waypoint, :mod:`mission_sim.validation`)."""
        if not rng.contains(value):
            self.fail(it, f"{what}={value:g} is invalid; valid range: {rng.text()} ({key})")

    def where_to(self, it, xy_only: bool = False):
        """(x, y, z) of a nav item in the pad frame; "here" for lat = lon = 0 and for alt 0 / unset. ``xy_only``: an
        item whose altitude is not used (NAV_PAYLOAD_PLACE): any global frame (terrain-relative too), the altitude
        neither read nor checked (z: the current height)."""
        home = self.raw.home
        if xy_only and it.frame in _AMSL_FRAMES + _RELATIVE_FRAMES + _TERRAIN_FRAMES:
            pass
        elif it.frame not in _AMSL_FRAMES + _RELATIVE_FRAMES:
            kind = "terrain-relative altitude" if it.frame in _TERRAIN_FRAMES else "not a global frame"
            self.fail(it, f"frame {it.frame} ({kind}) is not supported; valid frames: 0 / 5 (AMSL), 3 / 6 "
                          "(relative to home)")
        here = (it.lat_deg == 0 and it.lon_deg == 0) or math.isnan(it.lat_deg) or math.isnan(it.lon_deg)
        if here:
            x, y = self.x, self.y
        else:
            try:
                GeoPoint(it.lat_deg, it.lon_deg)   # first: a latitude 1e308 made numpy warn (two more lines)
                e, n, _ = geodetic_to_enu(it.lat_deg, it.lon_deg, home.alt_m, home)
            except ValueError as exc:
                self.fail(it, str(exc))
            x, y = float(e), float(n)
            if math.hypot(x, y) > MAX_FROM_HOME_M:   # the pad frame is a tangent plane about home
                self.fail(it, f"({it.lat_deg:g}, {it.lon_deg:g}) is {math.hypot(x, y) / 1e3:.0f} km from home; valid: "
                              f"within {MAX_FROM_HOME_M / 1e3:g} km of home (a longer route: one mission per part)")
        if xy_only or math.isnan(it.alt_m) or it.alt_m == 0:
            return x, y, self.z
        z = it.alt_m - home.alt_m if it.frame in _AMSL_FRAMES else it.alt_m
        if not ALT_RANGE.contains(z):   # ([[waypoints]] z_m's range)
            self.fail(it, f"altitude {it.alt_m:g} m ({'AMSL' if it.frame in _AMSL_FRAMES else 'above home'}) is "
                          f"{z:.6g} m above home; valid range: {ALT_RANGE.text()}")   # (.1f: 1e308 in 309 digits)
        return x, y, z

    def add(self, action, x, y, z, hold_s=0.0):
        wp = {"action": action, "x_m": x, "y_m": y, "z_m": z, "hold_s": float(hold_s)}
        if action == "loiter" and self.pads:   # a loiter at a pad: charge there (and leave from there)
            d = [math.hypot(x - p[0], y - p[1]) for p in self.pads]
            k = min(range(len(d)), key=d.__getitem__)
            if d[k] <= self.radius and z > self.pads[k][2] + CHARGE_CLEARANCE_M:
                x, y = float(self.pads[k][0]), float(self.pads[k][1])
                wp.update(action="charge", pad=k, x_m=x, y_m=y)
        if self.speed is not None:
            wp["speed_m_s"], self.speed = self.speed, None
        self.out.append(wp)
        self.x, self.y, self.z = x, y, (0.0 if action == "land" else z)

    def nav_delay(self, it):
        """NAV_DELAY (93): ArduCopter's ``do_nav_delay`` takes only param1 > 0 as a delay in seconds (a hover where the
        vehicle is, in the air only); any other param1 waits for the UTC time of day in params 2-4, refused, except
        param1 = 0 with params 2-4 zero or unset: no delay (skipped)."""
        delay = it.params[0]
        clock = [0.0 if math.isnan(v) else v for v in it.params[1:4]]   # hour, minute, second UTC (unset: 0)
        if math.isfinite(delay) and delay == 0 and not any(clock):
            return
        if not math.isfinite(delay) or delay <= 0:
            self.fail(it, f"NAV_DELAY param1={delay:g} with params 2-4 = ({', '.join(f'{v:g}' for v in clock)}) waits "
                          "for a time of day (UTC hour, minute, second: ArduPilot's do_nav_delay takes only param1 > 0 "
                          "as seconds), not supported; valid: param1 > 0 seconds (or 0 with params 2-4 zero: no delay)")
        if self.z <= 0:
            self.fail(it, "NAV_DELAY on the ground is not supported (the route keeps no time on the ground); "
                          "valid: a NAV_DELAY after the take-off")
        self.in_range(it, "NAV_DELAY param1", delay, HOLD_RANGE, "waypoints.hold_s")
        self.add("loiter", self.x, self.y, self.z, delay)

    def payload_place(self, it):
        """NAV_PAYLOAD_PLACE (94) as ArduCopter flies it (``ModeAuto::do_payload_place``): to the item's position at the
        current height (its altitude is not used; lat = lon = 0: where the vehicle is), a descent until the payload
        touches the ground, the release, a climb back to the height it started from. The ground is home's (z = 0: no
        terrain model) and the payload is taken to touch it when the drone reaches it (the hang below the drone is not
        known). param1 > 0 limits the descent [m]: a limit that stops above the ground releases nothing (ArduCopter
        completes the item without releasing). Refused on the ground (before the take-off, after a landing)."""
        if self.z <= 0:
            self.fail(it, "NAV_PAYLOAD_PLACE on the ground is not supported (the vehicle descends from the air until "
                          "the payload touches down); valid: a NAV_PAYLOAD_PLACE after the take-off")
        limit = it.params[0] if math.isfinite(it.params[0]) else 0.0
        self.in_range(it, "NAV_PAYLOAD_PLACE max descent param1", limit, PLACE_DESCENT_RANGE, "0: no limit")
        x, y, _ = self.where_to(it, xy_only=True)   # (its altitude unused: not checked, any global frame)
        start = self.z
        if (x, y) != (self.x, self.y):
            self.add("waypoint", x, y, start)
        bottom = max(start - limit, 0.0) if limit > 0 else 0.0
        self.add("waypoint", x, y, bottom)
        if bottom <= 0.0:
            self.out[-1]["release"] = self.out[-1].get("release", 0) + 1
        else:
            self.unplaced.append(f"{it.where} (param1 = {limit:g} m from {start:g} m)")
        self.add("waypoint", x, y, start)
        self.placed.append(it.where)

    def release(self, it):
        """A payload release (:func:`release_of`): one more on the waypoint flown before it."""
        if not self.out:
            self.fail(it, f"{command_name(it.command)} ({it.command}) releases the payload before the first "
                          "navigation item: it would be dropped on the ground before take-off; valid: a release "
                          "after a waypoint, loiter or land item (or no payload: leave the item out)")
        self.out[-1]["release"] = self.out[-1].get("release", 0) + 1

    def item(self, it):
        if release_of(it):
            self.release(it)
            return
        if it.command == DO_CHANGE_SPEED:
            v = it.params[1]
            if math.isfinite(v) and v > 0:   # (-1, 0, unset: no change, as ArduCopter)
                self.in_range(it, "DO_CHANGE_SPEED speed param2", v, SPEED_RANGE, "waypoints.speed_m_s")
                self.speed = float(v)
            return
        if it.command in IGNORED_COMMANDS:
            return
        if it.command == NAV_DELAY:   # ArduCopter / PX4: hold position (in the air) for param1 seconds
            self.nav_delay(it)
            return
        if it.command == NAV_PAYLOAD_PLACE:   # ArduCopter: descend until the payload touches down, release, climb
            self.payload_place(it)
            return
        kind = _NAV.get(it.command)
        if kind is None and it.command in _FENCE_RALLY:
            self.fail(it, f"command {command_name(it.command)} ({it.command}) is a {_FENCE_RALLY[it.command]}, not a "
                          "mission item: the file is a geofence or rally-point list (as Mission Planner saves them); "
                          "valid: the mission's own file (its waypoints)")
        if kind is None:
            self.fail(it, f"command {command_name(it.command)} ({it.command}) is not supported; supported: {_SUPPORTED}")
        if kind == "rtl":
            z = max(self.z, RTL_ALT_M)
            if z > self.z:
                self.add("waypoint", self.x, self.y, z)
            self.add("waypoint", 0.0, 0.0, z)
            self.add("land", 0.0, 0.0, 0.0)
            return
        x, y, z = self.where_to(it)
        if kind == "takeoff":
            if z <= 0:
                self.fail(it, "take-off altitude 0; valid: a height above home > 0 m")
            self.add("takeoff", self.x, self.y, z)
        elif kind == "land":
            self.add("land", x, y, 0.0)
        else:
            hold = it.params[0] if math.isfinite(it.params[0]) else 0.0   # (unset: no hold)
            self.in_range(it, "hold time param1", hold, HOLD_RANGE, "waypoints.hold_s")
            self.add("loiter" if kind == "loiter" or hold > 0 else "waypoint", x, y, z, hold)


def _unrolled(raw: RawMission):
    """The items of ``raw`` in the order they are flown, DO_JUMP (177) followed as ArduPilot's and PX4's missions follow
    it: param1 names the target (a .plan's doJumpId, a .waypoints row, a log's sequence number), param2 the number of
    jumps; each DO_JUMP counts its own jumps over the whole mission (an inner loop is not re-armed by an outer one).
    Refused (one line naming the item): a jump that repeats forever (-1), a target the mission does not hold, a loop
    of more than :data:`MAX_ROUTE_ITEMS` items."""
    items = raw.items
    index: dict[int, int] = {}
    for k, it in enumerate(items):
        if it.jump_id is not None:
            index.setdefault(it.jump_id, k)
    jumps: dict[int, int] = {}
    k = n = 0
    while k < len(items):
        it = items[k]
        n += 1
        if n > MAX_ROUTE_ITEMS:
            raise ValueError(f"{raw.source}: {it.where}: the DO_JUMP loops give more than {MAX_ROUTE_ITEMS:,} items to "
                             "fly; valid: fewer repeats (DO_JUMP param2)")
        if it.command != DO_JUMP:
            yield it
            k += 1
            continue
        target, repeat = it.params[0], it.params[1]
        if repeat == -1:
            raise ValueError(f"{raw.source}: {it.where}: DO_JUMP repeats forever (param2 = -1): the route would never "
                             f"end; valid range: {JUMP_REPEATS.text()}")
        try:
            check_number("param2", repeat, JUMP_REPEATS)
        except ValueError as exc:
            raise ValueError(f"{raw.source}: {it.where}: DO_JUMP repeat count {exc}") from None
        if not (math.isfinite(target) and target == int(target) and int(target) in index):
            raise ValueError(f"{raw.source}: {it.where}: DO_JUMP target param1={target:g} is not an item of the "
                             f"mission; valid: {_jump_ids(sorted(index))}")
        if jumps.get(k, 0) < repeat:
            jumps[k] = jumps.get(k, 0) + 1
            k = index[int(target)]
        else:
            k += 1


def _jump_ids(ids: list[int], shown: int = 8) -> str:
    """The jump targets a mission holds, named (a .plan's doJumpIds can have gaps: "1..9" suggested ids it lacks):
    all of them up to ``shown``, else the first ``shown`` and how many."""
    if not ids:
        return "none: the mission has no item a DO_JUMP can name"
    more = f", ... ({len(ids)} ids, the last {ids[-1]})" if len(ids) > shown else ""
    return f"one of {', '.join(map(str, ids[:shown]))}{more}"


def route_from_items(raw: RawMission, pads_xyz=(), pad_radius_m: float = 5.0) -> list[dict]:
    """The ``[[waypoints]]`` dicts of ``raw`` (pad frame about ``raw.home``); loiters within
    ``pad_radius_m`` of a pad in ``pads_xyz`` ((x, y, z) in the pad frame) become "charge"."""
    if raw.home is None:
        raise ValueError(f"{raw.source}: missing home position (a .plan's plannedHomePosition, row 0 of a "
                         ".waypoints file, a log's HOME_POSITION); the pad frame is about home")
    b = _Builder(raw, pads_xyz, pad_radius_m)
    for it in _unrolled(raw):
        b.item(it)
    if not b.out:
        raise ValueError(f"{raw.source}: no waypoints: {len(raw.items)} item(s), none that moves the vehicle "
                         f"(supported: {_SUPPORTED})")
    delivers = [it.where for it in raw.items if winch_deliver_of(it)]
    if delivers:
        from wpt_receiver.notices import warn
        warn(f"{raw.source}: {', '.join(delivers[:3])}{' ...' if len(delivers) > 3 else ''}: DO_WINCH (42600) "
             "WINCH_DELIVER drops no payload here: ArduCopter (ModeAuto::do_winch) and PX4 do not release one on it in "
             "a mission (the MAVLink spec's 'lower, release, reel up' is not what they fly), so the payload stays on "
             "board; valid: a DO_GRIPPER release after it, or release = 1 on the [[waypoints]] entry")
    if b.placed:
        from wpt_receiver.notices import warn
        warn(f"{raw.source}: {_some(b.placed)}: NAV_PAYLOAD_PLACE (94) flown as ArduCopter flies it (to its position at "
             "the current height, a descent until the payload touches down, the release, a climb back) with the "
             "ground at home's altitude (no terrain model) and the touchdown when the drone reaches it; not modelled: "
             "the payload's hang below the drone, the touchdown detection, the descent speed (PLDP_SPEED_DN, "
             "LAND_SPEED: the route flies mission.descent_rate_m_s) and the autopilot's delays around the release "
             "(PLDP_* parameters)")
    if b.unplaced:
        from wpt_receiver.notices import warn
        warn(f"{raw.source}: {_some(b.unplaced)}: NAV_PAYLOAD_PLACE's max descent stops above the ground, so the "
             "payload is not released there (ArduCopter completes the item without releasing); valid: param1 = 0 (no "
             "limit) or at least the height above home")
    return b.out


def _some(where: list[str]) -> str:
    """The first three of ``where`` (items, each once: a DO_JUMP loop flies an item again), and ``...`` when there are
    more."""
    where = list(dict.fromkeys(where))
    return ", ".join(where[:3]) + (" ..." if len(where) > 3 else "")


def pads_to_local(pads, ref: GeoPoint, name: str = "pads", what: str = "the mission's home") -> list[dict]:
    """``[[pads]]`` dicts of :class:`~mission_sim.plans.pads.GeoPad` records about ``ref`` (a pad
    without altitude sits on the ground of ``ref``: z = 0). A pad more than :data:`MAX_FROM_HOME_M` from
    ``ref`` is a ``ValueError`` naming the file ``name`` and ``what`` ``ref`` is."""
    out = []
    for i, p in enumerate(pads):
        e, n, u = geodetic_to_enu(p.point.lat_deg, p.point.lon_deg,
                                  ref.alt_m if p.point.alt_m is None else p.point.alt_m, ref)
        if math.hypot(e, n) > MAX_FROM_HOME_M:
            raise ValueError(f"{name}: pad {i} is {math.hypot(e, n) / 1e3:.0f} km from {what} ({ref.lat_deg:.6f}, "
                             f"{ref.lon_deg:.6f}); valid: within {MAX_FROM_HOME_M / 1e3:g} km (lat, lon swapped?)")
        d = {"x_m": float(e), "y_m": float(n), "z_m": float(u)}
        if p.hover_time_s is not None:
            d["hover_time_s"] = p.hover_time_s
        out.append(d)
    return out


def _path(value, base_dir, key: str):
    if value in (None, ""):
        return None
    if not isinstance(value, str):
        raise ValueError(f"mission.{key}={value!r} is invalid; valid type: string (a file path)")
    p = Path(value).expanduser()
    return p if p.is_absolute() or base_dir is None else Path(base_dir) / p


def _first_pad_ref(geo) -> GeoPoint:
    first = geo[0].point
    return GeoPoint(first.lat_deg, first.lon_deg, 0.0 if first.alt_m is None else first.alt_m)


def mission_home(mission) -> GeoPoint | None:
    """The geodetic origin of the pad frame of a config's ``[mission]`` (a :class:`mission_sim.config.MissionConfig`
    after :func:`apply_mission_files`): the mission file's home, else the first pad of its pads file;
    None for a hand-written route (its frame has no place on Earth)."""
    if mission.file:
        return read_mission(Path(mission.file), mission.from_log).home
    if mission.pads_file:
        return _first_pad_ref(read_pads(Path(mission.pads_file)))
    return None


def apply_mission_files(d: dict, base_dir=None, mission_file=None, pads_file=None) -> dict:
    """Config dict ``d`` with its ``[mission] file`` read into ``[[waypoints]]`` (start at home) and
    its ``[mission] pads_file`` into ``[[pads]]``; ``mission_file`` / ``pads_file`` (command line)
    replace the config's. Relative paths of the config are relative to ``base_dir``. Returns ``d``
    itself when there is nothing to read."""
    m = d.get("mission")
    if not isinstance(m, dict):
        return d
    mf = Path(mission_file) if mission_file is not None else _path(m.get("file"), base_dir, "file")
    pf = Path(pads_file) if pads_file is not None else _path(m.get("pads_file"), base_dir, "pads_file")
    if mf is None and pf is None:
        return d
    if mf is not None and mission_file is None and d.get("waypoints"):
        raise ValueError(f"mission.file={m.get('file')!r} and [[waypoints]] are both given; valid: one route")
    radius = check_number("mission.pad_radius_m", m.get("pad_radius_m", 5.0), PAD_RADIUS_RANGE)   # (the config's range)
    out = {**d, "mission": dict(m)}
    raw = read_mission(mf, m.get("from_log", "auto")) if mf is not None else None
    ref = raw.home if raw is not None else None
    if raw is not None and ref is None:
        route_from_items(raw)  # raises: missing home
    if pf is not None:
        geo = read_pads(pf)
        if ref is None:
            ref = _first_pad_ref(geo)
        out["pads"] = pads_to_local(geo, ref, pf.name)
        out["mission"]["pads_file"] = str(pf)
    if raw is not None:
        pads = [(p.get("x_m", 0.0), p.get("y_m", 0.0), p.get("z_m", 0.0)) for p in out.get("pads") or []
                if isinstance(p, dict)]
        out["waypoints"] = route_from_items(raw, pads, float(radius))
        if raw.fence:   # a .plan's geofence: warnings only (the route is flown as planned)
            from wpt_receiver.notices import warn

            from .fence import fence_warnings
            for text in fence_warnings(raw.fence, raw.rally, raw.home, out["waypoints"], raw.source):
                warn(text)
        out["mission"].update(file=str(mf), start_x_m=0.0, start_y_m=0.0)
        last = out["waypoints"][-1]
        out["mission"].update(land_x_m=last["x_m"], land_y_m=last["y_m"])
    return out


def check_file_keys(keys: dict, mission_file, what: str = "--set") -> None:
    """``ValueError`` (one line) for a ``[mission]`` key of ``keys`` (given explicitly with the files: ``--set``'s,
    :func:`mission_sim.config.load_config_dict`'s ``mission_keys``) that the files read never use, so its value would
    change nothing: ``pad_radius_m`` without a mission file ``mission_file`` (it picks which of the file's loiters
    charge at a pad), ``from_log`` without a flight log as mission file (it picks a log's uploaded mission or its
    flown track; a .plan or .waypoints file is read whatever it says)."""
    name = Path(mission_file).name if mission_file else ""
    none = "there is no mission file (--plan or mission.file)"
    if "from_log" in keys and Path(name).suffix.lower() not in LOG_SUFFIXES:
        raise ValueError(f"{what} mission.from_log={keys['from_log']!r} is invalid: it chooses what a flight log read "
                         "as the mission file gives (its uploaded mission or its flown track), and "
                         f"{f'the mission file {name!r} is not a log' if name else none}; valid: a flight log "
                         f"({', '.join(LOG_SUFFIXES)}) as --plan or mission.file, or leave the key out")
    if "pad_radius_m" in keys and not name:
        raise ValueError(f"{what} mission.pad_radius_m={keys['pad_radius_m']!r} is invalid: it chooses which loiters "
                         f"of a mission file charge at a pad, and {none}; valid: a mission file, or leave the key out "
                         '(a config\'s [[waypoints]] charge with action = "charge")')
