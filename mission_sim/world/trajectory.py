"""Trajectories: waypoint missions with speed/acceleration limits, wind-driven hover error, replays.

Positions are those of the receiver coil's origin in the pad frame (local ENU metres, z up,
origin = the first pad's coil). Every straight move starts and ends at rest and follows a
trapezoidal speed profile (limits: cruise speed horizontally, climb / descent rate vertically,
one acceleration limit). A planned mission is

``takeoff -> (transit -> approach -> charge -> depart) per pad -> transit -> land``

sampled on a uniform grid. On top of the nominal path the seeded wind model
(:mod:`mission_sim.world.wind`) adds the position-hold error and sets the tilt, so Lm(t) fluctuates
while the drone hovers over a pad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .power import payload_after_releases as _payload_left
from .power import propulsion_power_w
from .wind import drag_force_n, hover_error_m, tilt_from_force, wind_series

__all__ = ["Trajectory", "PlannedTrajectory", "MassSchedule", "plan_mission", "PHASES", "PLAN_BLOCK"]

PHASES = ("ground", "takeoff", "transit", "approach", "charge", "depart", "land", "hover", "flight")


@dataclass
class Trajectory:
    """Sampled trajectory.

    Attributes
    ----------
    t_s : (N,) sample times [s], strictly increasing
    pos_m : (N, 3) receiver coil position [m] (pad frame)
    tilt_rad : (N,) tilt of the receiver coil [rad]
    phase : (N,) str, one of :data:`PHASES` (the pad only energises in "charge" and "hover")
    tilt_axis_rad : (N,) azimuth of the tilt axis [rad] (pi/2 = about y, normal leaning to +x)
    wind_m_s : (N, 3) wind velocity [m/s] (zeros for replays)
    """

    t_s: np.ndarray
    pos_m: np.ndarray
    tilt_rad: np.ndarray
    phase: np.ndarray
    tilt_axis_rad: np.ndarray | None = None
    wind_m_s: np.ndarray | None = None

    def __post_init__(self):
        self.t_s = np.asarray(self.t_s, dtype=float)
        self.pos_m = np.asarray(self.pos_m, dtype=float)
        n = len(self.t_s)
        if self.t_s.ndim != 1 or n < 2:
            raise ValueError(f"t_s has shape {self.t_s.shape}; valid: 1-D with at least 2 samples")
        if not np.all(np.isfinite(self.t_s)) or np.any(np.diff(self.t_s) <= 0):
            raise ValueError("t_s is invalid; valid: finite and strictly increasing")
        if self.pos_m.shape != (n, 3) or not np.all(np.isfinite(self.pos_m)):
            raise ValueError(f"pos_m has shape {self.pos_m.shape}; valid: ({n}, 3), finite")
        self.tilt_rad = np.broadcast_to(np.asarray(self.tilt_rad, dtype=float), (n,)).copy()
        if np.any(np.abs(self.tilt_rad) >= math.pi / 2):
            raise ValueError("tilt_rad is invalid; valid range: (-pi/2, pi/2)")
        self.phase = np.broadcast_to(np.asarray(self.phase, dtype=object), (n,)).copy()
        bad = set(self.phase) - set(PHASES)
        if bad:
            raise ValueError(f"phase {sorted(bad)[0]!r} is invalid; valid values: {', '.join(PHASES)}")
        self.tilt_axis_rad = np.full(n, math.pi / 2) if self.tilt_axis_rad is None else \
            np.broadcast_to(np.asarray(self.tilt_axis_rad, dtype=float), (n,)).copy()
        self.wind_m_s = np.zeros((n, 3)) if self.wind_m_s is None else np.asarray(self.wind_m_s, dtype=float)

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def t_start_s(self) -> float:
        return float(self.t_s[0])

    @property
    def t_end_s(self) -> float:
        return float(self.t_s[-1])

    def chunk(self, a: int, b: int) -> "Trajectory":
        """Samples ``[a, b)`` (views; as :meth:`PlannedTrajectory.chunk`)."""
        return _view(*(x[max(int(a), 0):int(b)] for x in _parts(self)))

    @classmethod
    def from_samples(cls, t_s, pos_m, tilt_rad=None, phase=None, hover_speed_m_s: float = 0.3) -> "Trajectory":
        """A trajectory from logged samples (e.g. a real flight log converted to the pad frame).

        ``phase=None`` labels samples slower than ``hover_speed_m_s`` as "hover" (pads may
        energise) and the rest "flight".
        """
        t = np.asarray(t_s, dtype=float)
        pos = np.asarray(pos_m, dtype=float)
        tr = cls(t, pos, np.zeros(len(t)) if tilt_rad is None else tilt_rad, "flight")
        if phase is None:
            speed = np.linalg.norm(tr.velocity_m_s(), axis=1)
            tr.phase = np.where(speed < hover_speed_m_s, "hover", "flight").astype(object)
        else:
            tr.phase = np.broadcast_to(np.asarray(phase, dtype=object), (len(t),)).copy()
            cls.__post_init__(tr)
        return tr

    def velocity_m_s(self) -> np.ndarray:
        """Velocity (N, 3) [m/s] by second-order finite differences."""
        return np.gradient(self.pos_m, self.t_s, axis=0)

    #: phases whose motors are off: the avionics alone draw power there ("ground": a planned mission's
    #: hold after landing, a replayed log's disarmed samples, a re-flight's). Read by :meth:`propulsion_w`
    #: and, chunk by chunk, by ``world.samples.MissionSamples`` (chunks are plain views, so it is read off
    #: the whole; :class:`PlannedTrajectory` has the same).
    motors_off_phases: ClassVar[tuple[str, ...]] = ("ground",)

    def propulsion_w(self, drone) -> np.ndarray:
        """Electrical propulsion power (N,) [W] from momentum theory (airspeed = |v_xy - wind_xy|) at each sample's
        mass: a planned route's :class:`MassSchedule` (``mass``, set by :meth:`PlannedTrajectory.materialise`;
        ``drone`` must give its masses, :meth:`MassSchedule.check_drone`), else ``drone.total_mass_kg``: the
        power a run over this trajectory draws (``world.samples.MissionSamples``)."""
        sched = getattr(self, "mass", None)
        if sched is not None:
            sched.check_drone(drone)
        return propulsion_from(drone, self.velocity_m_s(), self.wind_m_s, self.phase, self.motors_off_phases,
                               sched.at(self.t_s) if sched is not None and sched.changes else None)


def propulsion_from(drone, vel_m_s, wind_m_s, phase=None, motors_off=(), mass_kg=None) -> np.ndarray:
    """Electrical propulsion power (N,) [W] at velocities (N, 3) [m/s] in winds (N, 3) [m/s]
    (momentum theory, :func:`.power.propulsion_power_w`; airspeed = |v_xy - wind_xy|); samples
    whose ``phase`` is one of ``motors_off`` draw ``drone.avionics_w`` only. ``mass_kg``: the total mass per
    sample (N,) [kg] (a payload dropped on the way), None for the take-off mass ``drone.total_mass_kg``."""
    air = np.hypot(vel_m_s[:, 0] - wind_m_s[:, 0], vel_m_s[:, 1] - wind_m_s[:, 1])
    p = propulsion_power_w(drone, air, vel_m_s[:, 2], mass_kg=mass_kg)
    if len(motors_off) and phase is not None:
        p = np.where(np.isin(np.asarray(phase, dtype=object), list(motors_off)), float(drone.avionics_w), p)
    return p


# --------------------------------------------------------------------------- planning
def _profile(dist: float, vmax: float, amax: float):
    """Trapezoidal (or triangular) rest-to-rest profile: duration and s(t), v(t), a(t) evaluators."""
    if dist <= 0:
        return 0.0, None
    if dist <= vmax * vmax / amax:
        ta = math.sqrt(dist / amax)
        vp, tc = amax * ta, 0.0
    else:
        ta, vp = vmax / amax, vmax
        tc = (dist - vmax * ta) / vmax
    dur = 2 * ta + tc

    def ev(t):
        t = np.clip(t, 0.0, dur)
        s = np.where(t < ta, 0.5 * amax * t * t,
                     np.where(t < ta + tc, 0.5 * vp * ta + vp * (t - ta),
                              dist - 0.5 * amax * (dur - t) ** 2))
        v = np.where(t < ta, amax * t, np.where(t < ta + tc, vp, amax * (dur - t)))
        a = np.where(t < ta, amax, np.where(t < ta + tc, 0.0, -amax))
        return s, v, a
    return dur, ev


def _move_limit(m, d, speed_m_s: float) -> float:
    """Speed limit [m/s] of a straight move ``d`` (3-vector): the horizontal ``speed_m_s`` and the
    climb / descent rate on the vertical component (a pure vertical move at the climb or descent rate)."""
    dist = float(np.linalg.norm(d))
    rate = m.climb_rate_m_s if d[2] > 0 else m.descent_rate_m_s
    if abs(d[2]) > 1e-9 and np.hypot(d[0], d[1]) < 1e-9:
        return rate
    return min(speed_m_s, rate * dist / abs(d[2])) if abs(d[2]) > 1e-9 else speed_m_s


class _Path:
    """Builds the segment list: ``move`` (straight, rest to rest, trapezoidal) and ``hold``; ``grounds``: each
    segment's ground height [m] (``ground`` when it was added: the home's 0, a pad's z on the way to, at and
    from that pad), the lowest the drone's z may go there (its position-hold error included)."""

    def __init__(self, m, start):
        self.m, self.pos, self.segs = m, np.asarray(start, dtype=float), []
        self.ground, self.grounds = 0.0, []
        self.keys = []   # per segment: the route's (key, value) that set a move's speed or a hold's time, else None
        self.releases = []   # payload releases: (segment index they precede, count), in route order

    def move(self, p1, phase, speed_m_s=None, speed_key=None):
        p1 = np.asarray(p1, dtype=float)
        d = p1 - self.pos
        dist = float(np.linalg.norm(d))
        if dist < 1e-12:
            return
        vmax = _move_limit(self.m, d, self.m.cruise_speed_m_s if speed_m_s is None else speed_m_s)
        dur, ev = _profile(dist, vmax, self.m.max_accel_m_s2)
        self.segs.append((phase, self.pos.copy(), d / dist, dur, ev))
        self.grounds.append(self.ground)
        self.keys.append(None if speed_m_s is None else speed_key)
        self.pos = p1

    def hold(self, dur, phase, key=None):
        if dur > 0:
            self.segs.append((phase, self.pos.copy(), None, float(dur), None))
            self.grounds.append(self.ground)
            self.keys.append(key)


def _segments(cfg):
    """Segments (phase, p0, unit direction or None, duration, evaluator) of the mission: the route of
    ``cfg.waypoints`` if any (:func:`_route_segments`), else the built-in pattern start -> pads -> land."""
    return _path(cfg).segs


def _path(cfg) -> _Path:
    """The mission's :class:`_Path`: its segments (:func:`_segments`) and their grounds."""
    if cfg.waypoints:
        return _route_segments(cfg)
    m = cfg.mission
    alt = m.cruise_altitude_m
    path = _Path(m, [m.start_x_m, m.start_y_m, 0.0])
    path.move([m.start_x_m, m.start_y_m, alt], "takeoff")
    for pad in cfg.pads:
        path.move([pad.x_m, pad.y_m, alt], "transit")
        path.ground = pad.z_m
        path.move([pad.x_m, pad.y_m, pad.z_m + m.hover_gap_m], "approach")
        path.hold(m.hover_time_s if pad.hover_time_s is None else pad.hover_time_s, "charge")
        path.move([pad.x_m, pad.y_m, alt], "depart")
        path.ground = 0.0
    path.move([m.land_x_m, m.land_y_m, alt], "transit")
    path.move([m.land_x_m, m.land_y_m, 0.0], "land")
    path.hold(1.0, "ground")
    return path


def _route_segments(cfg):
    """The :class:`_Path` of the ``cfg.waypoints`` route, from the ground at (start_x_m, start_y_m). A waypoint
    reached from the ground first climbs vertically to its height; the route ends on the ground (a
    vertical landing where the last waypoint left the drone, if it did not land)."""
    m = cfg.mission
    path = _Path(m, [m.start_x_m, m.start_y_m, 0.0])
    speed = key = None
    pending = 0   # the releases of the waypoint before: when it is done, before the segments of the next
    for i, wp in enumerate(cfg.waypoints):
        if pending:
            path.releases.append((len(path.segs), pending))
        pending = int(wp.release)
        if wp.speed_m_s is not None:
            speed, key = wp.speed_m_s, (f"waypoints.{i}.speed_m_s", wp.speed_m_s)
        x, y, z = wp.x_m, wp.y_m, wp.z_m
        if wp.action == "charge":
            pad = cfg.pads[wp.pad]
            x, y = pad.x_m, pad.y_m
        if wp.action == "takeoff":
            path.move([path.pos[0], path.pos[1], z], "takeoff")
            continue
        if wp.action == "land":
            path.move([x, y, path.pos[2]], "transit", speed, key)
            path.move([x, y, 0.0], "land")
            continue
        if path.pos[2] <= 0.0 and z > 0.0:
            path.move([path.pos[0], path.pos[1], z], "takeoff")
        path.move([x, y, z], "transit", speed, key)
        if wp.action == "loiter":
            path.hold(wp.hold_s, "hover", (f"waypoints.{i}.hold_s", wp.hold_s))
        elif wp.action == "charge":
            pad = cfg.pads[wp.pad]
            path.ground = pad.z_m
            path.move([x, y, pad.z_m + m.hover_gap_m], "approach")
            key = ((f"waypoints.{i}.hold_s", wp.hold_s) if pad.hover_time_s is None else
                   (f"pads.{wp.pad}.hover_time_s", pad.hover_time_s))
            path.hold(key[1], "charge", key)
            path.move([x, y, z], "depart")
            path.ground = 0.0
    if pending:
        path.releases.append((len(path.segs), pending))
    if path.pos[2] > 0.0:
        path.move([path.pos[0], path.pos[1], 0.0], "land")
    path.hold(1.0, "ground")
    return path


def plan_mission(cfg, rng: np.random.Generator | None = None) -> Trajectory:
    """Plan the waypoint mission of ``cfg`` (a MissionConfig) on a grid of ``cfg.sim.traj_dt_s``.

    The wind is drawn from ``rng`` (default: ``np.random.default_rng(cfg.seed)``), so the same
    config gives the same trajectory. All samples at once: :class:`PlannedTrajectory`
    materialised (its chunks are the same numbers; it leaves ``rng`` where this did).
    """
    return PlannedTrajectory(cfg, rng).materialise()


@dataclass(frozen=True)
class MassSchedule:
    """The total mass flown along a planned route: ``takeoff_mass_kg`` (``drone.mass_kg + payload_kg``) until the
    first release, ``mass_after_kg[i]`` from ``release_t_s[i]`` [s] on (:func:`.power.payload_after_releases`);
    ``empty_releases``: how many releases found no payload left; ``dt_s``: the plan's sample period (sample k
    is at ``k dt_s``). A sample at or after a release flies without what it dropped (the power and the hold are
    held over the sample, so the drop lands on the sample grid)."""

    takeoff_mass_kg: float
    release_t_s: np.ndarray
    mass_after_kg: np.ndarray
    empty_releases: int
    dt_s: float

    @classmethod
    def of(cls, drone, release_t_s, dt_s: float) -> "MassSchedule":
        left, empty = _payload_left(drone, len(release_t_s))
        return cls(float(drone.total_mass_kg), np.array(release_t_s, dtype=float),
                   np.array([drone.mass_kg + x for x in left], dtype=float), empty, float(dt_s))

    @property
    def final_mass_kg(self) -> float:
        """The mass the route ends with (the landing mass)."""
        return float(self.mass_after_kg[-1]) if len(self.mass_after_kg) else self.takeoff_mass_kg

    @property
    def changes(self) -> bool:
        """Whether the mass changes along the route (a release that drops payload); else every sample flies
        the take-off mass (and the power model is called as without a schedule: the same numbers)."""
        return self.final_mass_kg != self.takeoff_mass_kg

    def check_drone(self, drone) -> None:
        """One-line ``ValueError`` when ``drone`` (a run's ``cfg.drone``) gives other masses at these releases than
        the ones planned (the schedule and the positions' hold were planned for them: re-plan with the run's
        config, ``plan_mission(cfg)``). A route whose mass changes under neither drone flies the run's
        ``drone.total_mass_kg`` throughout, as without a schedule."""
        mine = MassSchedule.of(drone, self.release_t_s, self.dt_s)
        if not (self.changes or mine.changes):
            return
        if mine.takeoff_mass_kg == self.takeoff_mass_kg and np.array_equal(mine.mass_after_kg, self.mass_after_kg):
            return
        raise ValueError(f"the trajectory was planned for {self.describe()}, the run's drone flies {mine.describe()} "
                         f"(drone.mass_kg={drone.mass_kg:g}, payload_kg={drone.payload_kg:g}, "
                         f"release_kg={drone.release_kg:g}); valid: a trajectory planned from the run's config "
                         "(plan_mission(cfg))")

    def describe(self) -> str:
        """``1.5 kg, 1 kg from t = 28.5 s``: the masses flown, for messages."""
        out, last = f"{self.takeoff_mass_kg:g} kg", self.takeoff_mass_kg
        for t, m in zip(self.release_t_s, self.mass_after_kg):
            if m != last:
                out, last = out + f", {m:g} kg from t = {t:g} s", m
        return out if last != self.takeoff_mass_kg else out + " throughout"

    def at(self, t_s) -> np.ndarray:
        """The total mass [kg] at the sample times ``t_s``."""
        table = np.concatenate([[self.takeoff_mass_kg], self.mass_after_kg])
        return table[np.searchsorted(self.release_t_s, np.asarray(t_s, dtype=float), side="right")]

    def at_samples(self, k) -> np.ndarray:
        """The total mass [kg] of the samples ``k`` (indices on the plan's grid)."""
        return self.at(np.asarray(k, dtype=np.int64) * self.dt_s)


#: samples per block a :class:`PlannedTrajectory` generates (and keeps the last few of)
PLAN_BLOCK = 1 << 15
_PHASE_NAMES = np.array(PHASES, dtype=object)


def _clone(rng: np.random.Generator) -> np.random.Generator:
    """A generator in ``rng``'s state (drawing from it leaves ``rng`` where it is)."""
    bg = type(rng.bit_generator)()
    bg.state = rng.bit_generator.state
    return np.random.Generator(bg)


def _skip_normals(rng: np.random.Generator, n: int) -> None:
    """Advance ``rng`` past ``n`` standard normals (drawn in blocks; the same stream as one draw)."""
    for a in range(0, n, PLAN_BLOCK):
        rng.standard_normal(min(PLAN_BLOCK, n - a))


class PlannedTrajectory:
    """The planned mission of ``cfg`` generated in blocks of :data:`PLAN_BLOCK` samples on demand, so
    a long mission never holds all its samples (:meth:`chunk`: samples ``[a, b)`` as a
    :class:`Trajectory`, the same numbers as :func:`plan_mission`'s; blocks are generated forward,
    the wind's gust and position-hold filters and the three gust streams of the generator carried
    from block to block; a request behind the kept blocks starts again from sample 0).

    ``len()`` and :attr:`t_start_s` / :attr:`t_end_s` cost nothing; the array attributes of a
    :class:`Trajectory` (``t_s``, ``pos_m``, ...) materialise the whole trajectory on first use
    (cached): for short missions and error messages, not for long runs.
    """

    motors_off_phases: ClassVar[tuple[str, ...]] = Trajectory.motors_off_phases

    def __init__(self, cfg, rng: np.random.Generator | None = None):
        rng = np.random.default_rng(cfg.seed) if rng is None else rng
        self.cfg, self.dt = cfg, cfg.sim.traj_dt_s
        path = _path(cfg)
        self.segs, self._grounds = path.segs, np.array(path.grounds)
        total = sum(s[3] for s in self.segs)
        self.n = int(math.floor(total / self.dt)) + 1
        starts, t0 = [], 0.0
        for seg in self.segs:
            starts.append(t0)
            t0 += seg[3]
        self._starts = np.array(starts)  # accumulated as plan_mission always did (the masks' bounds)
        self._mass_schedule(path.releases, t0)
        self._gens0 = []
        for _ in range(3):   # the x, y and z gust streams, drawn one after the other from rng
            self._gens0.append(_clone(rng))
            _skip_normals(rng, self.n)
        wp = self.cfg.wind
        d = math.radians(wp.direction_deg)
        self._mean_wind = np.array([wp.speed_m_s * math.cos(d), wp.speed_m_s * math.sin(d), 0.0])
        self.uniform_spacing = _uniform_grid(self.n, self.dt)
        self._full = None
        self._restart()

    def _mass_schedule(self, releases, t_end: float) -> None:
        """:attr:`mass`: the :class:`MassSchedule` of the route's payload releases (each at the start of the segment
        after its waypoint; the end of the route after the last)."""
        times = [float(self._starts[j]) if j < len(self._starts) else t_end for j, n in releases for _ in range(n)]
        self.mass = MassSchedule.of(self.cfg.drone, times, self.dt)

    @property
    def mass_changes(self) -> bool:
        return self.mass.changes

    def mass_at(self, t_s) -> np.ndarray:
        return self.mass.at(t_s)

    def _restart(self):
        self._gens = [_clone(g) for g in self._gens0]
        self._gust_z = [[[0.0]] for _ in range(3)]
        self._hold_z = [[0.0, 0.0] for _ in range(3)]
        self._next, self._blocks = 0, {}

    def __len__(self) -> int:
        return self.n

    @property
    def t_start_s(self) -> float:
        return 0.0

    @property
    def t_end_s(self) -> float:
        return float(np.arange(self.n - 1, self.n)[0] * self.dt)

    def __getattr__(self, name):
        if name in ("t_s", "pos_m", "tilt_rad", "phase", "tilt_axis_rad", "wind_m_s", "velocity_m_s",
                    "propulsion_w"):
            if self._full is None:
                self._full = self.materialise()
            return getattr(self._full, name)
        raise AttributeError(name)

    def materialise(self) -> Trajectory:
        """All samples as one :class:`Trajectory` (with the route's :class:`MassSchedule` as its ``mass``)."""
        full = Trajectory(*_parts(self.chunk(0, self.n)))
        full.mass = self.mass
        self._restart()   # the blocks are in ``full`` now
        return full

    def chunk(self, a: int, b: int) -> Trajectory:
        """Samples ``[a, b)`` (clipped to the mission) as a :class:`Trajectory` (not validated again)."""
        a, b = max(int(a), 0), min(int(b), self.n)
        if b <= a:
            raise ValueError(f"samples [{a}, {b}) are invalid; valid: 0 <= a < b <= {self.n}")
        first, last = a // PLAN_BLOCK, (b - 1) // PLAN_BLOCK
        if first < min(self._blocks, default=self._next):
            self._restart()
        for j in [j for j in self._blocks if j < first]:
            del self._blocks[j]
        while self._next <= last:
            self._blocks[self._next] = self._block(self._next)
            self._next += 1
        cols = [np.concatenate([self._blocks[j][c] for j in range(first, last + 1)]) for c in range(6)]
        lo = a - first * PLAN_BLOCK
        return _view(*(c[lo:lo + b - a] for c in cols))

    def _block(self, j: int):
        """Block ``j``: (t, pos, tilt, phase, tilt axis, wind) of samples ``[j B, (j + 1) B)``."""
        k0, k1 = j * PLAN_BLOCK, min((j + 1) * PLAN_BLOCK, self.n)
        t = np.arange(k0, k1) * self.dt
        pos, vel, acc, code, ground = self._nominal(t)
        wind = self._wind(k0, k1)
        phase = _PHASE_NAMES[code]
        wp, cfg = self.cfg.wind, self.cfg
        force = drag_force_n(wp, wind, vel)
        force_mean = drag_force_n(wp, self._mean_wind[None, :], vel)
        mass = self.mass.at(t) if self.mass.changes else cfg.drone.total_mass_kg
        err = hover_error_m(wp, force - force_mean, mass, self.dt, state=self._hold_z)
        on_ground = code == PHASES.index("ground")
        err[on_ground] = 0.0
        pos = pos + err
        # the ground of each sample's segment (no terrain model): the home's z = 0, the target pad's z on the way
        # to, at and from a pad (a pad below home, a pads file's AMSL altitude, is flown down to; one ground for
        # all pads, the lowest's, let the coil 0.118 m into a pad at 0 m behind one at -3 m)
        pos[:, 2] = np.maximum(pos[:, 2], ground)
        # never let the coil touch a pad while charging
        chg = code == PHASES.index("charge")
        floor = min(0.03, cfg.mission.hover_gap_m)
        pos[chg, 2] = np.maximum(pos[chg, 2], floor + ground[chg])
        tilt, axis = tilt_from_force(mass, acc, force)
        tilt[on_ground] = 0.0
        return t, pos, tilt, phase, axis, wind

    def _nominal(self, t):
        """Nominal position, velocity, acceleration (n, 3), phase codes and ground heights [m] (n,) at the times
        ``t`` (sorted)."""
        pos = np.empty((len(t), 3))
        vel = np.zeros((len(t), 3))
        acc = np.zeros((len(t), 3))
        code = np.zeros(len(t), dtype=np.int8)
        ground = np.zeros(len(t))
        n_seg = len(self.segs)
        j0 = max(int(np.searchsorted(self._starts, t[0], "right")) - 1, 0)
        j1 = int(np.searchsorted(self._starts, t[-1], "right"))
        for j in range(j0, j1):
            ph, p0, u, dur, ev = self.segs[j]
            # the samples starts[j] <= t < starts[j + 1] (to the end for the last) as an index range
            hi = len(t) if j == n_seg - 1 else int(np.searchsorted(t, self._starts[j + 1], "left"))
            mask = slice(int(np.searchsorted(t, self._starts[j], "left")), hi)
            tau = t[mask] - self._starts[j]
            if ev is None:
                pos[mask] = p0
            else:
                s, v, a = ev(tau)
                pos[mask] = p0 + s[:, None] * u
                vel[mask] = v[:, None] * u
                acc[mask] = a[:, None] * u
            code[mask] = PHASES.index(ph)
            ground[mask] = self._grounds[j]
        return pos, vel, acc, code, ground

    def _wind(self, k0: int, k1: int) -> np.ndarray:
        """Wind (k1 - k0, 3) [m/s] of samples ``[k0, k1)``: :func:`.wind.wind_series` continued."""
        return wind_series(self.cfg.wind, k1 - k0, self.dt, self._gens, self._gust_z, first=k0 == 0)


def _uniform_grid(n: int, dt: float) -> bool:
    """True if the steps of ``arange(n) * dt`` are all bitwise equal (``numpy.gradient``'s test)."""
    d0 = None
    for a in range(0, n - 1, PLAN_BLOCK):
        d = np.diff(np.arange(a, min(a + PLAN_BLOCK + 1, n)) * dt)
        d0 = d[0] if d0 is None else d0
        if not (d == d0).all():
            return False
    return True


def _parts(tr: Trajectory) -> tuple:
    return tr.t_s, tr.pos_m, tr.tilt_rad, tr.phase, tr.tilt_axis_rad, tr.wind_m_s


def _view(t_s, pos_m, tilt_rad, phase, tilt_axis_rad, wind_m_s) -> Trajectory:
    """A :class:`Trajectory` of these arrays as they are (no validation, no copies)."""
    tr = object.__new__(Trajectory)
    tr.t_s, tr.pos_m, tr.tilt_rad, tr.phase, tr.tilt_axis_rad, tr.wind_m_s = \
        t_s, pos_m, tilt_rad, phase, tilt_axis_rad, wind_m_s
    return tr
