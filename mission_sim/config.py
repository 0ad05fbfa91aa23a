"""Mission configuration: TOML in, a validated frozen dataclass tree out.

Sections (see ``default_mission.toml``, the embedded default, for every key and its unit):
``seed``, ``[link]``, ``[coupling]``, ``[[pads]]``, ``[drone]``, ``[battery]``, ``[charger]``,
``[wind]``, ``[mission]``, ``[[waypoints]]`` (a route instead of the built-in pattern; also read from a
mission file, ``[mission] file``, by :mod:`mission_sim.plans`), ``[sim]``. Unknown keys, wrong types and out-of-range values raise
``ValueError`` naming the dotted key (``battery.capacity_ah``), the value and the valid range: every
numeric key has a physically plausible range (:data:`PLAUSIBLE`), checked before its section is built.
"""

from __future__ import annotations

import copy
import functools
import math
import numbers
import tomllib
from dataclasses import asdict, dataclass, field, fields
from importlib import resources
from pathlib import Path

import numpy as np

from wpt_receiver import LinkParams
from wpt_receiver.coupling import NOMINAL_GAP_M

from .world.battery import BatteryParams, CcCvParams
from .world.power import DRONE_RANGES, DroneParams
from .validation import (ALT_RANGE, CRUISE_ALTITUDE_RANGE, HOLD_RANGE, HOVER_GAP_RANGE, PAD_RADIUS_RANGE,
                         SPEED_RANGE, Range, check_number_fields, check_positive, check_range, check_table,
                         read_toml_file, shown)
from .world.wind import WindParams

__all__ = ["DEFAULT_MISSION_TOML", "LinkConfig", "CouplingConfig", "PadConfig", "MissionPlan", "SimConfig",
           "MissionConfig", "WaypointConfig", "load_config", "config_from_dict", "config_to_dict", "apply_overrides",
           "load_config_dict", "check_file_route_keys", "check_cross_fields", "check_replay_keys", "section_from_dict",
           "check_seed", "PLAUSIBLE", "plausible_range", "differing_keys"]

DEFAULT_MISSION_TOML: str = resources.files("mission_sim").joinpath("default_mission.toml").read_text("utf-8")


@dataclass(frozen=True)
class LinkConfig:
    """Link parameters besides the inductances (Table I), the transmitter's soft start and the
    semiconductor preset ``devices`` (``wpt_receiver/parts.toml``; "ideal" = the paper's circuit);
    ``device_tj_c`` the devices' junction temperature [C] for their conduction values (0 = the
    table's: 125 C Schottky, 25 C MOSFET data; e.g. from :func:`wpt_receiver.thermal.steady_junctions`)."""

    r1_ohm: float = 0.108
    r2_ohm: float = 0.0325
    vdc_v: float = 30.0
    f_hz: float = 85e3
    rated_i2_a: float = 15.0
    tx_ramp_s: float = 0.005
    devices: str = "schottky"
    device_tj_c: float = 0.0

    def __post_init__(self):
        check_number_fields(self)
        check_positive(self, "r1_ohm", "r2_ohm", "vdc_v", "f_hz", "rated_i2_a")
        if not (self.device_tj_c == 0.0 or 25.0 <= self.device_tj_c <= 175.0):
            raise ValueError(f"device_tj_c={self.device_tj_c!r} is invalid; valid range: 0 (table values) or "
                             "[25, 175] C")
        check_positive(self, "tx_ramp_s", allow_zero=True)
        from wpt_receiver.devices import preset_names
        if self.devices not in preset_names():
            raise ValueError(f"devices={self.devices!r} is invalid; valid values: {', '.join(preset_names())}")

    def device_set(self):
        """The :class:`wpt_receiver.devices.DeviceSet` of the ``devices`` preset (``parts.toml``), the inverter
        switch's Coss charge-equivalent at ``vdc_v`` (the SBAR's capacitance is taken at each step's battery voltage
        where it acts, the edge energies: ``MissionLoop.add_edges``)."""
        from wpt_receiver.devices import preset
        return preset(self.devices, tj_c=self.device_tj_c or None, v_block_inv_v=self.vdc_v)

    def link_params(self, l1_h: float, l2_h: float, lm_h: float, vl_v: float = 30.0) -> LinkParams:
        return LinkParams(l1_h=l1_h, l2_h=l2_h, lm_h=lm_h, r1_ohm=self.r1_ohm, r2_ohm=self.r2_ohm,
                          vdc_v=self.vdc_v, vl_v=vl_v, f_hz=self.f_hz)


@dataclass(frozen=True)
class CouplingConfig:
    """Coil geometry ("default": the calibrated pair of wpt_receiver.coupling) and pad gating."""

    geometry: str = "default"
    tx_min_k: float = 0.075
    tx_k_hysteresis: float = 0.003

    def __post_init__(self):
        check_number_fields(self)
        if self.geometry != "default":
            raise ValueError(f"geometry={self.geometry!r} is invalid; valid values: 'default'")
        if not 0 < self.tx_min_k < 1:
            raise ValueError(f"tx_min_k={self.tx_min_k!r} is invalid; valid range: (0, 1)")
        if not 0 <= self.tx_k_hysteresis < 1 - self.tx_min_k:
            raise ValueError(f"tx_k_hysteresis={self.tx_k_hysteresis!r} is invalid; valid range: "
                             f"[0, {1 - self.tx_min_k:.4g})")

    def model(self):
        from wpt_receiver.coupling import default_coupling
        return default_coupling()


@dataclass(frozen=True)
class PadConfig:
    """A charging pad: coil centre (pad frame) and how long the drone hovers over it (None = mission default)."""

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    hover_time_s: float | None = None

    def __post_init__(self):
        check_number_fields(self)
        for name in ("x_m", "y_m", "z_m"):
            v = getattr(self, name)
            if not math.isfinite(v) or abs(v) > 1e5:
                raise ValueError(f"{name}={v!r} is invalid; valid range: [-1e5, 1e5] m")
        if self.hover_time_s is not None:
            check_range("hover_time_s", self.hover_time_s, HOLD_RANGE)   # (PLAUSIBLE's: [0, inf) here let 2e6 build)


@dataclass(frozen=True)
class MissionPlan:
    """Waypoint mission: start, pads in order, landing spot; speed and acceleration limits."""

    start_x_m: float = -15.0
    start_y_m: float = 0.0
    land_x_m: float = 50.0
    land_y_m: float = 0.0
    cruise_altitude_m: float = 5.0
    cruise_speed_m_s: float = 8.0
    max_accel_m_s2: float = 2.5
    climb_rate_m_s: float = 2.0
    descent_rate_m_s: float = 1.0
    hover_gap_m: float = NOMINAL_GAP_M
    hover_time_s: float = 60.0
    file: str = ""                 # mission file (.plan, .waypoints, a flight log) -> [[waypoints]]
    pads_file: str = ""            # pads file (CSV lat,lon[,alt] or GeoJSON Points) -> [[pads]]
    pad_radius_m: float = 5.0      # a loiter item this close to a pad (horizontally) charges there
    from_log: str = "auto"         # a log as mission file: "uploaded" items, "flown" track, "auto"

    def __post_init__(self):
        check_number_fields(self)
        check_positive(self, "pad_radius_m")
        if self.from_log not in ("auto", "uploaded", "flown"):
            raise ValueError(f"from_log={self.from_log!r} is invalid; valid values: auto, uploaded, flown")
        for name in ("start_x_m", "start_y_m", "land_x_m", "land_y_m"):
            v = getattr(self, name)
            if not math.isfinite(v) or abs(v) > 1e5:
                raise ValueError(f"{name}={v!r} is invalid; valid range: [-1e5, 1e5] m")
        check_positive(self, "cruise_speed_m_s", "max_accel_m_s2", "climb_rate_m_s", "descent_rate_m_s")
        check_positive(self, "hover_time_s", allow_zero=True)
        if not 0.03 <= self.hover_gap_m <= 1.0:
            raise ValueError(f"hover_gap_m={self.hover_gap_m!r} is invalid; valid range: [0.03, 1.0] m")
        if not self.hover_gap_m < self.cruise_altitude_m <= 500:
            raise ValueError(f"cruise_altitude_m={self.cruise_altitude_m!r} is invalid; valid range: "
                             f"(hover_gap_m={self.hover_gap_m!r}, 500] m")


WAYPOINT_ACTIONS = ("takeoff", "waypoint", "loiter", "charge", "land")
#: ``[[waypoints]] release``: payload releases when the waypoint is done (a count: two grippers opened there, 2)
RELEASE_RANGE = Range(0, 1000, integer=True)


@dataclass(frozen=True)
class WaypointConfig:
    """One route point in the pad frame (local ENU metres about the mission's home, z up).

    ``action``: "takeoff" climbs vertically to ``z_m``; "waypoint" flies straight to (x, y, z);
    "loiter" flies there and hovers ``hold_s``; "charge" flies above pad ``pad`` (its x, y) at
    ``z_m``, descends to the pad, charges ``hold_s`` (the pad's ``hover_time_s`` if set) and climbs
    back; "land" flies to (x, y) at the current height and descends to the ground (z = 0).
    ``speed_m_s``: the horizontal speed limit from here on (None: ``mission.cruise_speed_m_s``).
    ``release``: how many payload releases happen when this waypoint is done (after its hold, charge or landing;
    a mission file's DO_GRIPPER release items after it): each drops ``drone.release_kg`` (0:
    all the payload left), so the drone flies on lighter (:func:`mission_sim.world.power.payload_after_releases`).
    """

    action: str = "waypoint"
    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    hold_s: float = 0.0
    speed_m_s: float | None = None
    pad: int = -1
    release: int = 0

    def __post_init__(self):
        check_number_fields(self)
        if self.action not in WAYPOINT_ACTIONS:
            raise ValueError(f"action={self.action!r} is invalid; valid values: {', '.join(WAYPOINT_ACTIONS)}")
        for name in ("x_m", "y_m"):
            v = getattr(self, name)
            if not math.isfinite(v) or abs(v) > 1e5:
                raise ValueError(f"{name}={v!r} is invalid; valid range: [-1e5, 1e5] m")
        check_range("z_m", self.z_m, ALT_RANGE)   # the shared ranges (a Python-built hold_s=-1 said [0, inf))
        check_range("hold_s", self.hold_s, HOLD_RANGE)
        if self.speed_m_s is not None:
            check_range("speed_m_s", self.speed_m_s, SPEED_RANGE)
        check_range("release", self.release, RELEASE_RANGE)
        if (self.pad >= 0) != (self.action == "charge"):
            raise ValueError(f"pad={self.pad!r} is invalid; valid: a pad index >= 0 for action 'charge' only")


@dataclass(frozen=True)
class SimConfig:
    """Multi-rate stepping (see mission_sim/runner.py).

    ``settle_i2_tol_a``: a fine window settles when I2 is this close to its steady state; with the pad off, when
    |I1| and |I2| are both below it (the coil currents have died out).
    ``rectify_after_pad_off``: when the pad's V1 has reached 0 after its ramp and the coil currents still ring
    (|I1| or |I2| >= ``settle_i2_tol_a``), the receiver's protection holds the SBAR at d = 0 (plain diode
    rectification) until they have died out; the rows record the applied duty. False: v2 = 0 from that step (a
    shorted secondary, the model before 2026-11-28: the short-mode / upper case of the switch-off's I2 peak,
    docs/mission.md "Pad switch-off")."""

    control_period_s: float = 1e-4
    traj_dt_s: float = 0.2
    flight_dt_s: float = 1.0
    i2_noise_a: float = 0.0
    min_fine_s: float = 0.002
    max_fine_s: float = 0.06
    settle_duty_tol: float = 1e-5
    duty_event_tol: float = 2e-3
    lm_rel_tol: float = 0.05
    coarse_policy_period_s: float = 1.0
    settle_i2_tol_a: float = 0.01
    cmd_deadband_a: float = 0.25
    bms_period_s: float = 4.0
    tx_off_delay_s: float = 0.025
    rectify_after_pad_off: bool = True

    def __post_init__(self):
        check_number_fields(self)
        if not isinstance(self.rectify_after_pad_off, (bool, np.bool_)):   # numpy's bool too (a sweep's grid)
            raise ValueError(f"rectify_after_pad_off={self.rectify_after_pad_off!r} is invalid; valid values: true, false")
        object.__setattr__(self, "rectify_after_pad_off", bool(self.rectify_after_pad_off))
        check_positive(self, "control_period_s", "traj_dt_s", "flight_dt_s", "min_fine_s", "max_fine_s",
                  "settle_duty_tol", "duty_event_tol", "lm_rel_tol", "coarse_policy_period_s", "settle_i2_tol_a", "bms_period_s")
        check_positive(self, "i2_noise_a", "cmd_deadband_a", "tx_off_delay_s", allow_zero=True)
        if not 1e-7 <= self.control_period_s <= 1e-3:
            raise ValueError(f"control_period_s={self.control_period_s!r} is invalid; valid range: [1e-7, 1e-3] s")
        if not self.control_period_s * 10 <= self.traj_dt_s <= 1.0:
            raise ValueError(f"traj_dt_s={self.traj_dt_s!r} is invalid; valid range: "
                             f"[10 control periods = {10 * self.control_period_s:.3g}, 1.0] s")
        if self.flight_dt_s < self.traj_dt_s:
            raise ValueError(f"flight_dt_s={self.flight_dt_s!r} is invalid; valid range: [traj_dt_s="
                             f"{self.traj_dt_s!r}, inf) s")
        if self.max_fine_s < self.min_fine_s:
            raise ValueError(f"max_fine_s={self.max_fine_s!r} is invalid; valid range: [min_fine_s="
                             f"{self.min_fine_s!r}, inf) s")


@dataclass(frozen=True)
class MissionConfig:
    """The whole mission (frozen dataclass tree)."""

    seed: int = 7
    link: LinkConfig = field(default_factory=LinkConfig)
    coupling: CouplingConfig = field(default_factory=CouplingConfig)
    pads: tuple = (PadConfig(),)
    drone: DroneParams = field(default_factory=DroneParams)
    battery: BatteryParams = field(default_factory=BatteryParams)
    charger: CcCvParams = field(default_factory=CcCvParams)
    wind: WindParams = field(default_factory=WindParams)
    mission: MissionPlan = field(default_factory=MissionPlan)
    sim: SimConfig = field(default_factory=SimConfig)
    waypoints: tuple = ()          # WaypointConfig route; () = the built-in pattern (start, pads, land)

    def __post_init__(self):
        # a tree built in Python (dataclasses.replace, a section made by hand) is checked as a file is: every
        # numeric key in its PLAUSIBLE range, 1..100 pads, the seed; lists of pads / waypoints become tuples
        object.__setattr__(self, "seed", check_seed(self.seed))
        for name in ("pads", "waypoints"):
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        check_section_values(self)
        check_cross_fields(self)


def check_section_values(cfg: MissionConfig) -> None:
    """Every section of ``cfg`` of its class and every numeric key inside its :data:`PLAUSIBLE` range, as
    :func:`config_from_dict` checks a file (a tree changed with ``dataclasses.replace`` skips that path:
    ``capacity_ah=1300``, mAh for A h, was accepted); ``ValueError`` naming the dotted key, its value and the
    valid range. Section objects already checked (the same object: they are frozen) are not checked again. A tree
    may hold more than a file's 100 pads (``dataclasses.replace(cfg, pads=cfg.pads * 835)``: a 50 h mission)."""
    if not isinstance(cfg.pads, tuple) or not cfg.pads:   # (more than a file's 100: long missions repeat the pads)
        raise ValueError(f"pads={cfg.pads!r:.80} is invalid; valid: a tuple of at least one PadConfig; a mission "
                         "without charging: run_mission(..., charge=False)")
    for name, cls in _SECTIONS.items():
        _check_section(name, cls, getattr(cfg, name))
    for i, pad in enumerate(cfg.pads):
        _check_section(f"pads.{i}", PadConfig, pad)
    for i, wp in enumerate(cfg.waypoints):
        _check_section(f"waypoints.{i}", WaypointConfig, wp)


def _check_section(section: str, cls, obj) -> None:
    if _CHECKED.get(id(obj)) is obj and type(obj) is cls:
        return
    if not isinstance(obj, cls):
        raise ValueError(f"{section}={obj!r} is invalid; valid type: {cls.__name__}")
    check_number_fields(obj, f"{section}.")   # (its __post_init__ did, unless a subclass's skipped it)
    for f in fields(cls):
        rng = plausible_range(section, f.name)
        v = getattr(obj, f.name)
        if rng is not None and v is not None:
            check_range(f"{section}.{f.name}", v, rng)
    _remember_checked(obj)


#: ``id -> object`` of the (frozen) section objects whose values passed :func:`check_section_values` or
#: ``_build``'s checks (the object is held, so its id is not reused while it is in here)
_CHECKED: dict = {}


def _remember_checked(obj) -> None:
    if len(_CHECKED) > 4096:
        _CHECKED.clear()
    _CHECKED[id(obj)] = obj


def check_cross_fields(cfg: MissionConfig) -> None:
    """Limits between sections (each section checks its own keys): the built-in pattern must be able to fly above
    every pad at the cruise altitude, a route's charge items above their pads. Raises
    ``ValueError`` naming the dotted key, its value and the valid range."""
    m = cfg.mission
    # the cruise altitude is the built-in pattern's: a route flies its own heights (its charge items checked below;
    # a pad on a 30 m roof under a route loitering at 40 m was refused for cruise_altitude_m=5, a key it never reads)
    for i, pad in enumerate(() if cfg.waypoints else cfg.pads):
        top = pad.z_m + m.hover_gap_m
        if not top < m.cruise_altitude_m:
            raise ValueError(f"mission.cruise_altitude_m={m.cruise_altitude_m!r} is invalid; valid range: "
                             f"> pads.{i}.z_m + mission.hover_gap_m = {top:.4g} m (the drone would fly "
                             "through the pad)")
    for i, wp in enumerate(cfg.waypoints):
        if wp.action == "charge" and wp.pad >= len(cfg.pads):
            raise ValueError(f"waypoints.{i}.pad={wp.pad!r} is invalid; valid range: 0..{len(cfg.pads) - 1}")
        if wp.action == "charge" and not wp.z_m > cfg.pads[wp.pad].z_m + m.hover_gap_m:
            raise ValueError(f"waypoints.{i}.z_m={wp.z_m!r} is invalid; valid range: > pads.{wp.pad}.z_m + "
                             f"mission.hover_gap_m = {cfg.pads[wp.pad].z_m + m.hover_gap_m:.4g} m")
    if m.file and not cfg.waypoints:
        raise ValueError(f"mission.file={m.file!r} was not read into a route; valid: set it in the config "
                         "file or with --plan (mission files are read when the config is loaded)")


#: ``[mission]`` keys only the built-in pattern (start -> pads -> land) reads: a route (``[[waypoints]]``, or one read
#: from ``mission.file`` / ``--plan``) flies its own heights, holds and landing
PATTERN_KEYS = ("mission.cruise_altitude_m", "mission.land_x_m", "mission.land_y_m", "mission.hover_time_s")


def check_route_keys(cfg_or_dict, keys, what: str = "--set") -> None:
    """``ValueError`` naming the first of ``keys`` (given explicitly: ``--set``'s dict, a study's varied keys) that the
    route of ``cfg_or_dict`` (a :class:`MissionConfig` or its dict) never reads (:data:`PATTERN_KEYS`): its value would
    change nothing (``--plan survey.plan --set mission.cruise_altitude_m=60`` flew the plan's 20 m without a word)."""
    route = cfg_or_dict.get("waypoints") if isinstance(cfg_or_dict, dict) else cfg_or_dict.waypoints
    key = next((k for k in keys if k in PATTERN_KEYS), None) if route else None
    if key is not None:
        value = f"={keys[key]!r}" if isinstance(keys, dict) else ""
        valid = ("pads.<i>.hover_time_s (a charge's hover), or the file's loiter times ([[waypoints]] hold_s)"
                 if key == "mission.hover_time_s" else "the route's own heights, holds and landing (its mission "
                 'file\'s items, or [[waypoints]] z_m / hold_s / action = "land"), or leave the key out')
        raise ValueError(
            f"{what} {key}{value} is invalid: the mission flies a route (--plan, mission.file or [[waypoints]]), which "
            f"never reads it (the built-in pattern's, as are {', '.join(k for k in PATTERN_KEYS if k != key)}); valid: "
            f"{valid}")


def check_replay_keys(keys, with_pads: bool, what: str = "--set") -> None:
    """``ValueError`` naming the first of ``keys`` (``replay --set``'s, a ``[replay]`` study's varied keys) that a
    replay never reads: the built-in pattern's (:data:`PATTERN_KEYS`; the track, its heights and its landing are the
    log's), ``mission.hover_time_s`` but with pads (a re-flight's default hover). ``dronewpt replay`` and the replay
    studies of ``dronewpt sweep`` both check here (a study over ``mission.cruise_altitude_m`` ran identical cases)."""
    key = next((k for k in keys if k in PATTERN_KEYS and (k != "mission.hover_time_s" or not with_pads)), None)
    if key is not None:
        raise ValueError(f"{what} {key} is not used by replay: the track, its heights and its landing are the log's "
                         "(mission.hover_time_s: the default hover of a re-flight with pads); valid: drop it")


def _cv_range() -> Range:
    """``charger.cv_cell_v``: the cell's open-circuit voltage from SoC 0 to 1 (above it the CV phase never ends)."""
    from .world.battery import ocv_cell_v
    return Range(float(ocv_cell_v(0.0)), math.floor(float(ocv_cell_v(1.0)) * 1e4) / 1e4, "V")


_M = Range(-1e5, 1e5, "m")
_FRACTION = Range(0.0, 1.0, lo_open=True)
#: Every numeric config key and the values a real system can have (pads keys as ``pads.<key>``).
#: Checked by :func:`config_from_dict` / :func:`section_from_dict` before the section is built, so the
#: message names the dotted key; limits between keys (``charger.cutoff_current_a < cc_current_a``,
#: ``mission.cruise_altitude_m`` above the pads, ``sim.traj_dt_s`` >= 10 control periods, ...) are
#: checked after, by the sections and :func:`check_cross_fields`. The sim tolerances are numerical knobs:
#: their ranges only keep the arithmetic finite (``sim.max_fine_s = 1e9``: fine steps throughout).
PLAUSIBLE: dict[str, Range] = {
    "link.r1_ohm": Range(1e-6, 100.0, "ohm"), "link.r2_ohm": Range(1e-6, 100.0, "ohm"),
    "link.vdc_v": Range(0.0, 1000.0, "V", lo_open=True), "link.f_hz": Range(1e4, 3e7, "Hz"),
    "link.rated_i2_a": Range(0.0, 1000.0, "A", lo_open=True), "link.tx_ramp_s": Range(0.0, 10.0, "s"),
    "coupling.tx_min_k": Range(0.0, 1.0, lo_open=True, hi_open=True),
    "coupling.tx_k_hysteresis": Range(0.0, 1.0, hi_open=True),
    "pads.x_m": _M, "pads.y_m": _M, "pads.z_m": _M, "pads.hover_time_s": HOLD_RANGE,
    **{f"drone.{k}": r for k, r in DRONE_RANGES.items()},   # (the physical ranges and their sources: world/power.py)
    "battery.n_series": Range(1, 32, integer=True), "battery.capacity_ah": Range(0.01, 1000.0, "A h"),
    "battery.r0_ohm_cell": Range(1e-6, 1.0, "ohm"), "battery.r1_ohm_cell": Range(1e-6, 1.0, "ohm"),
    "battery.c1_f_cell": Range(1e-3, 1e6, "F"), "battery.initial_soc": Range(0.0, 1.0),
    "charger.cc_current_a": Range(0.0, 1000.0, "A", lo_open=True), "charger.cv_cell_v": _cv_range(),
    "charger.cutoff_current_a": Range(0.0, 1000.0, "A", lo_open=True),
    "wind.speed_m_s": Range(0.0, 30.0, "m/s"), "wind.direction_deg": Range(-360.0, 360.0, "deg"),
    "wind.gust_sigma_m_s": Range(0.0, 30.0, "m/s"), "wind.gust_tau_s": Range(0.01, 3600.0, "s"),
    "wind.hold_omega_rad_s": Range(0.01, 100.0, "rad/s"), "wind.hold_zeta": Range(0.01, 10.0),
    "wind.drag_area_m2": Range(0.0, 100.0, "m^2", lo_open=True), "wind.air_density_kg_m3": Range(0.05, 2.0, "kg/m^3"),
    "mission.start_x_m": _M, "mission.start_y_m": _M, "mission.land_x_m": _M, "mission.land_y_m": _M,
    "mission.cruise_altitude_m": CRUISE_ALTITUDE_RANGE,
    "mission.cruise_speed_m_s": SPEED_RANGE,
    "mission.max_accel_m_s2": Range(0.0, 100.0, "m/s^2", lo_open=True),
    "mission.climb_rate_m_s": Range(0.0, 50.0, "m/s", lo_open=True),
    "mission.descent_rate_m_s": Range(0.0, 50.0, "m/s", lo_open=True),
    "mission.hover_gap_m": HOVER_GAP_RANGE, "mission.hover_time_s": HOLD_RANGE,
    "sim.control_period_s": Range(1e-7, 1e-3, "s"), "sim.traj_dt_s": Range(0.0, 1.0, "s", lo_open=True),
    "sim.flight_dt_s": Range(0.0, 3600.0, "s", lo_open=True), "sim.i2_noise_a": Range(0.0, 1000.0, "A"),
    "sim.min_fine_s": Range(0.0, 10.0, "s", lo_open=True), "sim.max_fine_s": Range(0.0, 1e9, "s", lo_open=True),
    "sim.settle_duty_tol": _FRACTION, "sim.duty_event_tol": _FRACTION, "sim.lm_rel_tol": Range(0.0, 10.0, lo_open=True),
    "sim.coarse_policy_period_s": Range(0.0, 3600.0, "s", lo_open=True),
    "sim.settle_i2_tol_a": Range(0.0, 1000.0, "A", lo_open=True), "sim.cmd_deadband_a": Range(0.0, 1000.0, "A"),
    "sim.bms_period_s": Range(0.0, 3600.0, "s", lo_open=True), "sim.tx_off_delay_s": Range(0.0, 60.0, "s"),
    "link.device_tj_c": Range(0.0, 175.0, "C (0 = the parts table's values; else >= 25)"),
    "mission.pad_radius_m": PAD_RADIUS_RANGE,
    "charger.recharge_drop_cell_v": Range(0.005, 0.5, "V per cell"),
}
# a route's speed and holds as the mission's cruise speed and hover times (a waypoint's speed_m_s = 1e308, a
# mission file's DO_CHANGE_SPEED 1e308 m/s, were accepted: their check was only > 0)
PLAUSIBLE["waypoints.speed_m_s"] = SPEED_RANGE
PLAUSIBLE["waypoints.hold_s"] = HOLD_RANGE
PLAUSIBLE["waypoints.release"] = RELEASE_RANGE


#: ``--link KEY=VALUE`` of ``dronewpt paper`` / ``netlist`` / ``export-controller``: a range for every
#: :class:`~wpt_receiver.LinkParams` field (``vdc_v=1e308`` overflowed, ``f_hz=1e-300`` and ``lm_h=nan`` were
#: tracebacks); the four keys the mission's ``[link]`` has are its :data:`PLAUSIBLE` ranges (one source), the battery
#: voltage is the inverter's, the inductances 1 nH .. 1 H (``k < 1`` is LinkParams' own check)
LINK_PARAM_RANGES: dict[str, Range] = {
    "l1_h": Range(1e-9, 1.0, "H"), "l2_h": Range(1e-9, 1.0, "H"), "lm_h": Range(0.0, 1.0, "H", lo_open=True),
    "r1_ohm": PLAUSIBLE["link.r1_ohm"], "r2_ohm": PLAUSIBLE["link.r2_ohm"], "vdc_v": PLAUSIBLE["link.vdc_v"],
    "vl_v": PLAUSIBLE["link.vdc_v"], "f_hz": PLAUSIBLE["link.f_hz"],
}


def plausible_range(section: str, name: str) -> Range | None:
    """The :data:`PLAUSIBLE` range of key ``name`` of ``section`` (``"battery"``, ``"pads.1"``, ``"waypoints.3"``),
    None for strings."""
    return PLAUSIBLE.get(f"{section.partition('.')[0] if section.startswith(('pads.', 'waypoints.')) else section}.{name}")


_SECTIONS = {"link": LinkConfig, "coupling": CouplingConfig, "drone": DroneParams, "battery": BatteryParams,
             "charger": CcCvParams, "wind": WindParams, "mission": MissionPlan, "sim": SimConfig}


def _coerce(section: str, cls, name: str, value):
    ftype = {f.name: f.type for f in fields(cls)}[name]
    ftype = ftype if isinstance(ftype, str) else getattr(ftype, "__name__", str(ftype))
    key = f"{section}.{name}"
    if ftype == "str":
        if not isinstance(value, str):
            raise ValueError(f"{key}={shown(value)} is invalid; valid type: string")
        return value
    if ftype == "bool":   # numpy's bool too (a sweep's grid), as a Python bool
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{key}={shown(value)} is invalid; valid values: true, false")
        return bool(value)
    if ftype == "int":   # numbers.Real: numpy's integers and floats too (np.arange, np.linspace)
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or (
                not math.isfinite(value)) or int(value) != value:
            raise ValueError(f"{key}={shown(value)} is invalid; valid type: integer")
        return int(value)
    if value is None and "None" in ftype:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{key}={shown(value)} is invalid; valid type: number")
    return float(value)


def _build(section: str, cls, d):
    check_table(section, d)
    names = {f.name for f in fields(cls)}
    for k in d:
        if k not in names:
            raise ValueError(f"{section}.{k} is not a valid key; valid keys: {', '.join(sorted(names))}")
    kwargs = {k: _coerce(section, cls, k, v) for k, v in d.items()}
    for k, v in kwargs.items():
        rng = plausible_range(section, k)
        if rng is not None and v is not None:
            # integer keys: the value as given (1e308, not its 309-digit integer)
            check_range(f"{section}.{k}", d[k] if rng.integer else v, rng)
    try:
        obj = cls(**kwargs)
    except ValueError as exc:
        raise ValueError(f"{section}.{exc}") from None
    if section in _SECTIONS or section.startswith(("pads.", "waypoints.")):
        _remember_checked(obj)   # its ranges were checked above (MissionConfig does not check them again)
    return obj


def config_from_dict(d: dict) -> MissionConfig:
    """Validated :class:`MissionConfig` from a plain dict (as parsed from TOML)."""
    check_table("config", d)
    valid = {"seed", "pads", "waypoints", *_SECTIONS}
    for k in d:
        if k not in valid:
            raise ValueError(f"{k} is not a valid key; valid keys: {', '.join(sorted(valid))}")
    kw = {}
    if "seed" in d:
        kw["seed"] = check_seed(d["seed"])
    for name, cls in _SECTIONS.items():
        if name in d:
            kw[name] = _build(name, cls, d[name])
    if "waypoints" in d:
        wps = d["waypoints"]
        if not isinstance(wps, list) or len(wps) > 100_000:
            raise ValueError(f"waypoints={wps!r} is invalid; valid: a list of up to 100000 [[waypoints]] tables")
        kw["waypoints"] = tuple(_build(f"waypoints.{i}", WaypointConfig, w) for i, w in enumerate(wps))
    if "pads" in d:
        pads = d["pads"]
        if not isinstance(pads, list) or not 1 <= len(pads) <= 100:
            raise ValueError(f"pads={pads!r} is invalid; valid: a list of 1..100 [[pads]] tables")
        kw["pads"] = tuple(_build(f"pads.{i}", PadConfig, p) for i, p in enumerate(pads))
    return MissionConfig(**kw)


def check_seed(s) -> int:
    """The mission ``seed`` (an integer in [0, 2^63)); ``ValueError`` naming the value otherwise."""
    if type(s) is not int and (isinstance(s, bool) or not isinstance(s, numbers.Integral)) or not 0 <= s < 2**63:
        # (numpy's integers too)
        raise ValueError(f"seed={s!r} is invalid; valid range: integer in [0, 2^63)")
    return int(s)


def section_from_dict(section: str, d: dict):
    """One validated section (``"battery"``, ``"pads.1"``, ...) from its complete dict, as
    :func:`config_from_dict` builds it (sweeps check many cases' values without rebuilding the rest)."""
    if section.startswith("pads."):
        return _build(section, PadConfig, d)
    return _build(section, _SECTIONS[section], d)


#: Keys added after sweeps were stored (2026-11-28: the payload drop), left out of :func:`config_to_dict` at their
#: default 0: a base mission without a payload release keeps the dict, hence the sweep fingerprint
#: (:func:`mission_sim.studies.worst_cases.base_fingerprint`), it had before them, so an older sweep folder resumes.
#: ``drone.max_takeoff_mass_kg`` (2026-11-28 04:35 UTC) is left out when unset (None: TOML has no null).
OMITTED_AT_DEFAULT = {"drone": ("release_kg", "max_takeoff_mass_kg"), "waypoints": ("release",)}


def config_to_dict(cfg: MissionConfig) -> dict:
    """Plain dict (TOML-ready: no None values) of a :class:`MissionConfig`; the keys of :data:`OMITTED_AT_DEFAULT`
    only when not 0 / None (reading the dict back gives the same config)."""
    out = asdict(cfg)
    out["pads"] = [{k: v for k, v in p.items() if v is not None} for p in out["pads"]]
    out["waypoints"] = [{k: v for k, v in w.items() if v is not None and not (k in OMITTED_AT_DEFAULT["waypoints"]
                                                                             and v == 0)}
                        for w in out["waypoints"]]
    out["drone"] = {k: v for k, v in out["drone"].items() if not (k in OMITTED_AT_DEFAULT["drone"]
                                                                  and (v is None or v == 0))}
    return out


def load_config(path=None) -> MissionConfig:
    """Read a mission TOML file (``None`` = the embedded default)."""
    return config_from_dict(load_config_dict(path))


def load_config_dict(path=None, mission_file=None, pads_file=None, mission_keys=None, file_keys: bool = False):
    """The mission dict of TOML file ``path`` laid over the embedded default (:func:`layer_on_default`;
    ``None`` = the default itself), not yet validated: apply ``--set`` overrides, then
    :func:`config_from_dict`. File errors name the file (see :func:`~mission_sim.validation.read_toml_file`).
    A ``[mission] file`` / ``pads_file`` (paths relative to the TOML file), or ``mission_file`` /
    ``pads_file`` given here (``--plan``, ``--pads``; they win), is read into ``[[waypoints]]`` /
    ``[[pads]]`` now (:func:`mission_sim.plans.route.apply_mission_files`); ``mission_keys`` (``--set
    mission.from_log=...`` and the like) are laid over ``[mission]`` before that, and refused when no file read
    uses them (:func:`~mission_sim.plans.route.check_file_keys`: ``from_log`` without a log as the mission file,
    ``pad_radius_m`` without a mission file). The file's own pattern keys beside a route are checked by the callers
    that fly it (:func:`check_file_route_keys`), not here: a replay reads the file too; ``file_keys=True`` returns
    ``(dict, keys)`` with ``keys`` the ``[mission]`` keys the file itself sets (``{"mission.KEY": value}``, for that
    check: the file is read once)."""
    from .plans.route import apply_mission_files, check_file_keys
    mine = {}
    if path is None:
        d = tomllib.loads(DEFAULT_MISSION_TOML)
    else:
        raw = read_toml_file(path, "config file")
        check_no_empty_table(raw, f"config file {str(path)!r}")
        if isinstance(raw.get("mission"), dict):
            mine = {f"mission.{k}": v for k, v in raw["mission"].items()}
        d = layer_on_default(raw)
    if mission_keys and isinstance(d.get("mission"), dict):
        d["mission"] = {**d["mission"], **mission_keys}
    out = apply_mission_files(d, None if path is None else Path(path).parent, mission_file, pads_file)
    if mission_keys and isinstance(out.get("mission"), dict):   # (a key no file read uses changed nothing)
        check_file_keys(mission_keys, out["mission"].get("file"))
    return (out, mine) if file_keys else out


def check_file_route_keys(path, cfg_or_dict, file_keys: dict, given=()) -> None:
    """``ValueError`` (:func:`check_route_keys`'s line) for a built-in pattern key (:data:`PATTERN_KEYS`) given
    explicitly (``given``: ``--set``'s dict) or set by the config file ``path`` itself (``file_keys``, from
    :func:`load_config_dict` with ``file_keys=True``; not the default it is laid over, which has every key) beside
    the route of ``cfg_or_dict`` (its ``[[waypoints]]``, ``mission.file`` or ``--plan``): the route never reads it.
    For the callers that fly the config's route (``mission``, ``sizing``, ``telemetry``, the mission studies); not
    ``replay``, whose track is the log's and whose ``--pads`` re-flight reads ``mission.hover_time_s`` (a pad's
    default hover: its ``--set`` keys follow :func:`check_replay_keys`)."""
    check_route_keys(cfg_or_dict, given)   # (changed nothing: a route flies its own heights)
    if path is not None:
        check_route_keys(cfg_or_dict, file_keys, f"config file {str(path)!r}:")


def check_no_empty_table(d: dict, what: str) -> None:
    """``ValueError`` naming the first table of ``d`` without a key (``[battery]`` or a ``[[pads]]``
    entry followed by nothing): a file cut at a table boundary would otherwise take the defaults."""
    tables = [(k, v) for k, v in d.items() if isinstance(v, dict)]
    tables += [(f"pads.{i}", p) for i, p in enumerate(d.get("pads", [])) if isinstance(p, dict)]
    for name, table in tables:
        if not table:
            header = f"[[pads]] entry {name}" if name.startswith("pads.") else f"[{name}]"
            raise ValueError(f"{what}: {header} is empty (a file cut short?); valid: a table with at least one "
                             "key, or no header (the default values)")


def layer_on_default(d: dict) -> dict:
    """A user's mission dict laid over the embedded default mission: tables merge key by key, anything
    else (values, the ``[[pads]]`` list) replaces the default. An empty file is the default mission."""
    def merge(base, top):
        out = dict(base)
        for k, v in top.items():
            out[k] = merge(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
        return out
    return merge(tomllib.loads(DEFAULT_MISSION_TOML), d)


def apply_overrides(d: dict, overrides: dict) -> dict:
    """Copy of config dict ``d`` with dotted-key overrides (``"battery.capacity_ah"``, ``"pads.0.x_m"``).

    Unknown keys raise ``ValueError`` naming them; values are validated later by :func:`config_from_dict`.
    """
    out = copy.deepcopy(d)
    for key, value in overrides.items():
        parts = str(key).split(".")
        if parts[0] == "seed" and len(parts) == 1:
            out["seed"] = value
            continue
        if parts[0] == "pads":
            if len(parts) != 3 or not parts[1].isdigit():
                raise ValueError(f"override key {key!r} is invalid; valid form: pads.<index>.<key>")
            i = int(parts[1])
            pads = out.setdefault("pads", [asdict(PadConfig())])
            if not isinstance(pads, list) or not all(isinstance(p, dict) for p in pads):
                raise ValueError(f"pads={pads!r} is invalid; valid: a list of 1..100 [[pads]] tables")
            if not 0 <= i < len(pads):
                raise ValueError(f"override key {key!r} is invalid; valid pad indices: 0..{len(pads) - 1}")
            if parts[2] not in {f.name for f in fields(PadConfig)}:
                raise ValueError(f"override key {key!r} is invalid; valid pad keys: "
                                 f"{', '.join(f.name for f in fields(PadConfig))}")
            pads[i][parts[2]] = value
            continue
        if len(parts) != 2 or parts[0] not in _SECTIONS:
            raise ValueError(f"override key {key!r} is invalid; valid form: <section>.<key> with section in "
                             f"{', '.join(sorted(_SECTIONS))}, pads.<index>.<key> or seed")
        names = {f.name for f in fields(_SECTIONS[parts[0]])}
        if parts[1] not in names:
            raise ValueError(f"override key {key!r} is invalid; valid keys of [{parts[0]}]: {', '.join(sorted(names))}")
        section = out.setdefault(parts[0], {})
        check_table(parts[0], section)   # the config file gave a value where the table belongs
        section[parts[1]] = value
    return out


@functools.lru_cache(maxsize=64)
def hover_inductances(coupling: CouplingConfig, hover_gap_m: float) -> tuple[float, float, float]:
    """``(L1, L2, Lm)`` [H] of ``coupling``'s coils at the nominal hover pose ``(0, 0, hover_gap_m)`` (remembered:
    the policy context and the setup warnings of a mission ask for the same pose; a lookup costs ~0.5-4 ms)."""
    model = coupling.model()
    return model.l1_h, model.l2_h, float(model.lm_h(0.0, 0.0, hover_gap_m))


def mission_link_params(cfg: MissionConfig):
    """The mission's link as :class:`wpt_receiver.LinkParams` at the hover pose (Lm at ``(0, 0,
    mission.hover_gap_m)``) and at the pack's highest voltage, the charger's CV voltage
    ``battery.n_series * charger.cv_cell_v`` (the setup warnings' link: the lowest Vdc/VL and emf margin of the run;
    the policies' link, :func:`policy_context`)."""
    l1_h, l2_h, lm_h = hover_inductances(cfg.coupling, cfg.mission.hover_gap_m)
    return cfg.link.link_params(l1_h, l2_h, lm_h, vl_v=cfg.battery.n_series * cfg.charger.cv_cell_v)


def policy_context(cfg: MissionConfig):
    """The :class:`~mission_sim.contract.PolicyContext` that ``run_mission`` expects for ``cfg``.

    The receiver's assumed link is the mission's link at the nominal hover pose (coil inductances of the coupling
    model, Lm at ``(0, 0, mission.hover_gap_m)``) and the pack's charging voltage, the charger's CV voltage
    ``battery.n_series * charger.cv_cell_v`` (:func:`mission_link_params`, the setup warnings' link too);
    ``control_period_s = sim.control_period_s`` and ``rated_i2_a = link.rated_i2_a``; ``link_model="modal"``:
    every mission runs the exact-mode link (:mod:`mission_sim.world.loop_kernel` steps
    :mod:`wpt_receiver.modal_kernel`; there is no eq. 4 link in a mission), so a model-predictive
    policy (``mpc``) predicts with the modes.

    The link's VL is what the modal MPC builds its clamp table at (:func:`policies.mpc_modal.v2_frame_table`: the
    SBAR's V2 at ``Vc0 = VL + Vf``, scaled by ``Vc / Vc0`` to the observed pack voltage) and the budgeted policies
    their plant (:func:`policies.budget_modal._plant`); the others take the pack voltage from the observation (the
    default mission's ``step``, ``model_based`` and ``model_based_budget:0.02`` are bit-identical at 30 and 32.8 V).
    Until 2026-11-28 it
    was Table I's 30 V, below the default 8S pack's 32.28-32.90 V in flight: the table's V2 was off by up to
    0.47 V there (0 at its own VL), and ``mpc:0.02`` peaked at 32.5 A in the default mission (13.31 A with VL at
    32.3, 32.6, 32.8 or 33.5 V).
    """
    from .contract import PolicyContext

    return PolicyContext(link=mission_link_params(cfg),
                         control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a,
                         link_model="modal")


def _flat(d: dict) -> dict:
    """``{"battery.capacity_ah": 1.3, "pads.0.x_m": 0.0, "seed": 7, ...}`` of a config dict."""
    out = {}
    for k, v in d.items():
        if k == "pads":
            out.update({f"pads.{i}.{n}": x for i, p in enumerate(v) for n, x in p.items()})
        elif isinstance(v, dict):
            out.update({f"{k}.{n}": x for n, x in v.items()})
        else:
            out[k] = v
    return out


def differing_keys(cfg: MissionConfig, limit: int = 5) -> list[str]:
    """``key=value`` of at most ``limit`` keys of ``cfg`` that differ from the default mission, the farthest
    first (by decades from the default value; a key the default lacks or a string counts as farthest):
    the inputs that may have produced a NaN or an infinity in a run."""
    default, mine = _flat(config_to_dict(load_config())), _flat(config_to_dict(cfg))

    def distance(k, v):
        d = default.get(k)
        if d is None or isinstance(v, str) or isinstance(d, str):
            return math.inf
        if v and d:
            return abs(math.log10(abs(v) / abs(d))) + (0.0 if (v > 0) == (d > 0) else 1.0)
        return 1.0 + abs(v - d)

    diff = sorted(((distance(k, v), k, v) for k, v in mine.items() if default.get(k, object()) != v),
                  key=lambda t: -t[0])
    return [f"{k}={v!r}" for _, k, v in diff[:limit]]
