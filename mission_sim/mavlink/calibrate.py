"""Calibrate the drone power model (world/power.py) to a flight log's battery power.

Data (:func:`calibration_samples`): the log's battery samples (BAT / CURR / SYS_STATUS /
BATTERY_STATUS / PX4 battery_status: V I [W]) on the log's one time base (clock.py), in the boot
segment a replay would fly (:func:`~mission_sim.mavlink.replay.replay_span`). At each battery
sample the flown track gives the horizontal speed and the climb rate: GPS positions on a uniform
grid of :data:`GRID_DT_S`, differentiated by a Savitzky-Golay filter (:data:`SMOOTH_S` window,
quadratic: GPS noise of ~0.1 m at 5 Hz would otherwise give metres per second). The speed is the
logged airspeed where the vehicle has an airspeed sensor (``FlightLog.airspeed``), else the GPS
ground speed taken as airspeed (the shipped logs with a battery have no sensor; wind unknown).
Samples are *airborne* (armed and more than ``ground.GROUND_M`` above the pad) or *disarmed* (the
motors off: the logged power is the avionics alone). Armed is the replay's rule
(:func:`~mission_sim.mavlink.takeoff.flown_periods`): a log whose armed state is unknown (no armed-state record and no
motor output) counts its whole track as armed, with a warning, and has no disarmed samples; one whose track never
rises 1 m is refused as ``replay`` refuses it (:func:`~mission_sim.mavlink.replay.unknown_armed_check`).

Split: the airborne samples in time order, the first :data:`TRAIN_FRACTION` of the airborne time
trains, the rest is held out (and the disarmed samples before the split train the avionics).

Fit (:func:`fit_drone`): ``scipy.optimize.least_squares`` with a robust loss (``soft_l1``, scale
:data:`LOSS_SCALE` x the median logged power: spikes of current, radio-corrupted samples and
flips do not pull the fit) on

    r_i = (P_model(theta; v_i, vz_i) - P_log_i) / s          airborne training samples
    r_j = (avionics_w - P_log_j) / s * sqrt(w_d)              disarmed samples (the avionics)
    r_p = (theta_p - prior_p) / sigma_p * sqrt(n)              priors (identifiability, below)

over theta = (mass_kg, figure_of_merit, drive_efficiency, flat_plate_area_m2, avionics_w) inside
physical bounds (:data:`BOUNDS`). **Identifiability**: in hover the electrical power is
``(m g)^1.5 / sqrt(2 rho A) / (FM eta) + avionics`` (power.py), so mass, FM and drive efficiency
enter only through ``m^1.5 / (FM eta)``, and forward flight separates them only weakly. So:

* ``mass_kg`` given (``--mass``, the vehicle weighed): mass is fixed and FM is fitted;
* mass not given: FM is held near :data:`FM_PRIOR` by a Gaussian prior and the mass is fitted,
  as the *equivalent* mass of the model (a heavier drone or a less efficient one look alike);
* drive efficiency always has a Gaussian prior at the config's value (:data:`ETA_SIGMA`);
* avionics: from the disarmed samples when the log has them, else a prior at the config's value.

The rotor count and radius, payload and air density are the config's (not fitted).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
import pandas as pd

from ..world.power import DroneParams, above_max_takeoff, propulsion_power_w, takeoff_excess
from . import ground
from .logs import FlightLog
from .replay import _in_periods, check_decoded, replay_span, track_from_log, unknown_armed_check
from .takeoff import flown_periods

__all__ = ["check_mass", "NoBatteryError", "CalibrationSamples", "Calibration", "calibration_samples", "fit_drone",
           "calibrate_log", "heldout_energy", "drone_toml", "read_drone_toml", "BOUNDS", "TRAIN_FRACTION"]

GRID_DT_S = 0.2
SMOOTH_S = 2.0            # Savitzky-Golay window for the GPS velocities
TRAIN_FRACTION = 0.7      # first 70 % of the airborne time trains, the last 30 % is held out
LOSS_SCALE = 0.1          # soft_l1 scale: 10 % of the median airborne power
FM_PRIOR, FM_SIGMA = 0.6, 0.05     # small-propeller figure of merit 0.5-0.65 (power.py)
ETA_SIGMA = 0.05
AVIONICS_SIGMA_W = 5.0
DISARMED_WEIGHT = 0.2     # the disarmed rows together count as 20 % of the airborne ones
_MAX_GAP_S = 10.0
#: physical bounds of the fitted parameters
BOUNDS = {"mass_kg": (0.1, 25.0), "figure_of_merit": (0.3, 0.85), "drive_efficiency": (0.5, 0.95),
          "flat_plate_area_m2": (1e-4, 0.5), "avionics_w": (0.0, 100.0)}
PARAMS = tuple(BOUNDS)


class NoBatteryError(ValueError):
    """The log has no battery voltage and current (or none while airborne): nothing to calibrate to."""


@dataclass
class CalibrationSamples:
    """Battery samples with the flight state: table columns t_s, power_w, speed_m_s, climb_m_s,
    height_m, airborne, disarmed, train; ``split_t_s`` the log time where the held-out part starts."""

    table: pd.DataFrame
    split_t_s: float
    window: tuple | None
    span_info: dict


@dataclass
class Calibration:
    """A fitted drone, the default drone it started from, and the fit's facts (JSON-ready ``report``)."""

    drone: DroneParams
    default: DroneParams
    samples: CalibrationSamples
    report: dict


def _velocities(track) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(grid t [s from the track start], horizontal speed, climb rate [m/s], height [m]) by Savitzky-Golay."""
    from scipy.signal import savgol_filter

    t = np.arange(0.0, float(track.t_s[-1]) + 1e-9, GRID_DT_S)
    pos = np.column_stack([np.interp(t, track.t_s, track.pos_m[:, i]) for i in range(3)])
    win = max(5, int(round(SMOOTH_S / GRID_DT_S)) | 1)
    if len(t) <= win:
        vel = np.gradient(pos, t, axis=0) if len(t) > 1 else np.zeros_like(pos)
    else:
        vel = savgol_filter(pos, win, 2, deriv=1, delta=GRID_DT_S, axis=0)
    return t, np.hypot(vel[:, 0], vel[:, 1]), vel[:, 2], np.interp(t, track.t_s, track.height_m)


def _no_battery(log: FlightLog, what: str) -> NoBatteryError:
    from .logs import BATTERY_SOURCES
    return NoBatteryError(f"{log.path.name}: {what}; calibrate needs the flight battery's voltage and current "
                          f"({BATTERY_SOURCES}) while airborne")


def calibration_samples(log: FlightLog, window=None, segment=None) -> CalibrationSamples:
    """The battery samples of ``log`` with speed, climb and the train / held-out split (module docstring)."""
    check_decoded(log)   # an empty or text file: said as such, not as "no battery data"
    if not len(log.battery):
        raise _no_battery(log, "the log has no battery data")
    window, info = replay_span(log, window, segment)
    track = track_from_log(log, window=window)
    unknown = unknown_armed_check(log, track)   # the armed state unknown and the track on the ground: ValueError
    if unknown is not None:
        from wpt_receiver.notices import warn
        warn(unknown)
    tg, speed, climb, height = _velocities(track)
    bat = log.battery
    t0, t1 = track.t_offset_s, track.t_offset_s + float(track.t_s[-1])
    bat = bat[(bat["t_s"] >= t0) & (bat["t_s"] <= t1)]
    t = bat["t_s"].to_numpy(float)
    armed = _in_periods(t, flown_periods(log))   # (replay's rule: the armed state unknown, the whole track)
    known = log.armed_source is not None          # (unknown: no sample is known to be disarmed)
    h = np.interp(t - t0, tg, height)
    speed_at, source = np.interp(t - t0, tg, speed), "GPS ground speed"
    arsp = log.airspeed
    if arsp is not None and len(arsp) >= 2:
        speed_at, source = np.interp(t, arsp["t_s"].to_numpy(float), arsp["airspeed_m_s"].to_numpy(float)), "airspeed sensor"
    info = {**info, "speed_source": source}
    tab = pd.DataFrame({"t_s": t, "power_w": bat["power_w"].to_numpy(float),
                        "speed_m_s": speed_at, "climb_m_s": np.interp(t - t0, tg, climb),
                        "height_m": h, "airborne": armed & (h > ground.GROUND_M), "disarmed": ~armed & known})
    air = tab[tab["airborne"]]
    if len(air) < 20:
        raise _no_battery(log, f"only {len(air)} battery samples while airborne (armed and > {ground.GROUND_M:g} m "
                          "above the take-off spot), need at least 20")
    med = float(np.median(air["power_w"]))
    if med == 0.0:   # (not a sign: a current sensor absent or reading 0)
        raise _no_battery(log, f"the battery power while airborne is 0 W (median over {len(air)} samples): the logged "
                               "current is 0 (no current sensor?); valid: a log with the battery current measured")
    if med < 0.0:   # was fitted: mass 0.1 kg, f 1e-4 m^2, avionics 0 W (every bound), a [drone] TOML written
        raise _no_battery(log, f"the battery power while airborne is not positive (median {med:.0f} W over {len(air)} "
                               "samples): the logged current's sign is inverted (a current sensor wired or configured "
                               "backwards), or the battery charges in flight; valid: a current > 0 while discharging")
    ta = air["t_s"].to_numpy()
    dt = np.diff(ta)
    cum = np.concatenate([[0.0], np.cumsum(np.where(dt < _MAX_GAP_S, dt, 0.0))])
    split = float(ta[np.searchsorted(cum, TRAIN_FRACTION * cum[-1])])
    tab["train"] = (tab["airborne"] | tab["disarmed"]) & (tab["t_s"] < split)
    return CalibrationSamples(tab, split, window, info)


def _params(x, base: DroneParams, names) -> DroneParams:
    return replace(base, **{n: float(v) for n, v in zip(names, x)})


def _residuals(x, names, base, air, dis, priors, scale):
    d = _params(x, base, names)
    r = [(propulsion_power_w(d, air["speed_m_s"].to_numpy(), air["climb_m_s"].to_numpy())
          - air["power_w"].to_numpy()) / scale]
    if len(dis):
        w = np.sqrt(DISARMED_WEIGHT * len(air) / len(dis))
        r.append(w * (d.avionics_w - dis["power_w"].to_numpy()) / scale)
    n = np.sqrt(len(air))
    r.append(np.array([n * (getattr(d, p) - mu) / sd for p, (mu, sd) in priors.items()]))
    return np.concatenate(r)


def check_mass(mass_kg, key: str = "mass_kg"):
    """A weighed mass (``--mass``) as a float inside the config's ``drone.mass_kg`` range (one source of the range:
    5000 kg was fitted and written as a [drone] TOML that ``mission --drone`` refused); ``ValueError`` naming
    ``key``, the value and the range."""
    from ..config import PLAUSIBLE
    from ..validation import check_number
    return check_number(key, mass_kg, PLAUSIBLE["drone.mass_kg"], " (the config's drone.mass_kg)")


def fit_drone(samples: CalibrationSamples, base: DroneParams, mass_kg: float | None = None):
    """Least-squares fit (robust loss) of the drone parameters to the training samples; returns
    (fitted :class:`DroneParams`, scipy result, priors used). ``mass_kg``: fix the mass (module docstring,
    :func:`check_mass`)."""
    from scipy.optimize import least_squares

    if mass_kg is not None:
        mass_kg = check_mass(mass_kg)
    mtom = base.max_takeoff_mass_kg   # trial masses with the take-off limit off (the bounds reach 50 kg); said after
    base = replace(base, max_takeoff_mass_kg=None)
    tab = samples.table[samples.table["train"]]
    air, dis = tab[tab["airborne"]], tab[tab["disarmed"]]
    if mass_kg is not None:
        base = replace(base, mass_kg=float(mass_kg))
    names = [p for p in PARAMS if not (p == "mass_kg" and mass_kg is not None)]
    priors = {"drive_efficiency": (base.drive_efficiency, ETA_SIGMA)}
    if mass_kg is None:
        priors["figure_of_merit"] = (FM_PRIOR, FM_SIGMA)
    if not len(dis):
        priors["avionics_w"] = (base.avionics_w, AVIONICS_SIGMA_W)
    lo = np.array([BOUNDS[n][0] for n in names])
    hi = np.array([BOUNDS[n][1] for n in names])
    x0 = np.clip([getattr(base, n) for n in names], lo + 1e-6 * (hi - lo), hi - 1e-6 * (hi - lo))
    if len(dis):
        x0[names.index("avionics_w")] = np.clip(np.median(dis["power_w"]), lo[-1] + 1e-3, hi[-1] - 1e-3)
    scale = LOSS_SCALE * max(float(np.median(np.abs(air["power_w"]))), 1.0)
    res = least_squares(_residuals, x0, bounds=(lo, hi), loss="soft_l1", f_scale=1.0, x_scale="jac",
                        args=(names, base, air, dis, priors, scale))
    fitted = _params(res.x, base, names)
    if not above_max_takeoff(fitted.mass_kg, fitted.payload_kg, mtom):
        fitted = replace(fitted, max_takeoff_mass_kg=mtom)   # (above it: left unset, see max_takeoff_warning)
    return fitted, res, priors


def max_takeoff_warning(fitted: DroneParams, base: DroneParams) -> str | None:
    """The one-line warning when the fitted mass plus the config's payload is above the config's
    ``drone.max_takeoff_mass_kg`` (the fitted drone then has none: the written TOML leaves the key out, which
    ``mission --drone`` would refuse); None otherwise."""
    head = takeoff_excess("the fitted mass_kg", fitted.mass_kg, fitted.payload_kg, base.max_takeoff_mass_kg)
    if head is None:
        return None
    return (f"{head}: max_takeoff_mass_kg left out of the written [drone] TOML (the fitted mass is the model's equivalent "
            "mass; --mass KG fixes the weighed one)")


def heldout_energy(table: pd.DataFrame, drone: DroneParams, mask) -> tuple[float, float]:
    """(logged, modelled) energy [J] over the samples in ``mask`` (trapezoids between consecutive
    samples both in it, gaps over 10 s not bridged)."""
    t = table["t_s"].to_numpy(float)
    m = np.asarray(mask, dtype=bool)
    model = propulsion_power_w(drone, table["speed_m_s"].to_numpy(), table["climb_m_s"].to_numpy())
    dt = np.diff(t)
    seg = m[1:] & m[:-1] & (dt < _MAX_GAP_S)
    logged = table["power_w"].to_numpy(float)
    return (float(np.sum((0.5 * (logged[1:] + logged[:-1]) * dt)[seg])),
            float(np.sum((0.5 * (model[1:] + model[:-1]) * dt)[seg])))


def _rel(model, logged):
    return (model - logged) / logged if logged > 0 else float("nan")


def calibrate_log(log: FlightLog, base: DroneParams, mass_kg: float | None = None, window=None,
                  segment=None) -> Calibration:
    """Samples, fit and report of one log (module docstring); ``base`` the config's drone."""
    if mass_kg is not None:
        check_mass(mass_kg)   # before the samples are built
    samples = calibration_samples(log, window, segment)
    drone, res, priors = fit_drone(samples, base, mass_kg)
    tab = samples.table
    held = tab["airborne"].to_numpy() & ~tab["train"].to_numpy()
    train = tab["airborne"].to_numpy() & tab["train"].to_numpy()
    out = {"log": log.path.name, "battery_source": log.battery_source, "clock": samples.span_info.get("clock"),
           "speed_source": samples.span_info.get("speed_source"),
           "replayed_segment": samples.span_info.get("replayed_segment"), "segments": samples.span_info.get("segments"),
           "split_t_s": samples.split_t_s, "n_train_airborne": int(train.sum()), "n_heldout": int(held.sum()),
           "n_disarmed": int((tab["disarmed"] & tab["train"]).sum()), "mass_fixed": mass_kg is not None,
           "priors": {k: {"mean": v[0], "sigma": v[1]} for k, v in priors.items()},
           "loss": "soft_l1", "optimizer_status": int(res.status), "optimizer_message": str(res.message),
           "fitted": {p: float(getattr(drone, p)) for p in PARAMS},
           "default": {p: float(getattr(base, p)) for p in PARAMS},
           "warnings": [w for w in (max_takeoff_warning(drone, base),) if w],
           "at_bound": [p for p in PARAMS if np.isclose(getattr(drone, p), BOUNDS[p][0]) or np.isclose(getattr(drone, p), BOUNDS[p][1])]}
    for name, d in (("calibrated", drone), ("default", base)):
        for part, mask in (("heldout", held), ("train", train)):
            e_log, e_mod = heldout_energy(tab, d, mask)
            out[f"{name}_{part}_energy_error_rel"] = _rel(e_mod, e_log)
            out[f"{part}_logged_energy_j"] = e_log
            out[f"{name}_{part}_model_energy_j"] = e_mod
        p = propulsion_power_w(d, tab["speed_m_s"].to_numpy(), tab["climb_m_s"].to_numpy())
        out[f"{name}_heldout_rms_w"] = float(np.sqrt(np.mean((p[held] - tab["power_w"].to_numpy()[held]) ** 2)))
    return Calibration(drone=drone, default=base, samples=samples, report=out)


#: DroneParams keys of the mission's load, not of the airframe: not written by :func:`drone_toml` (``--drone FILE``
#: laid over a config kept the file's ``payload_kg = 0`` over the config's payload until 2026-11-28)
MISSION_LOAD_KEYS = ("payload_kg", "release_kg")


def drone_toml(cal: Calibration) -> str:
    """The ``[drone]`` TOML of a calibration (every DroneParams key but the mission's load,
    :data:`MISSION_LOAD_KEYS`), the fit's facts as comments."""
    r = cal.report
    lines = [f"# drone power model calibrated by `dronewpt calibrate` from {r['log']} ({r['battery_source']})",
             f"# held-out energy error: calibrated {100 * r['calibrated_heldout_energy_error_rel']:+.1f} %, "
             f"default model {100 * r['default_heldout_energy_error_rel']:+.1f} %",
             "# mass " + ("fixed (--mass)" if r["mass_fixed"] else "fitted as the equivalent mass (figure of merit "
                                                                  f"held near {FM_PRIOR} by a prior)"),
             "# use: dronewpt mission --drone THIS.toml / replay --drone / telemetry --drone, or as a sweep's base",
             "# payload_kg / release_kg not written: the mission's payload is its config's",
             "[drone]"]
    for f in fields(DroneParams):
        if f.name in MISSION_LOAD_KEYS:
            continue
        v = getattr(cal.drone, f.name)
        if v is None:       # (max_takeoff_mass_kg unset: no limit, no line)
            continue
        lines.append(f"{f.name} = {v:d}" if isinstance(v, int) else f"{f.name} = {float(v):.6g}")
    return "\n".join(lines) + "\n"


def read_drone_toml(path) -> dict:
    """``drone.KEY`` overrides from a TOML file with a ``[drone]`` table (what :func:`drone_toml`
    writes); ``ValueError`` naming the file when it has none or other tables."""
    from ..validation import read_toml_file

    d = read_toml_file(path, "--drone file")
    if not isinstance(d.get("drone"), dict) or set(d) != {"drone"}:
        raise ValueError(f"--drone {str(path)!r} is invalid; valid: a TOML file with only a [drone] table "
                         "(as `dronewpt calibrate` writes)")
    return {f"drone.{k}": v for k, v in d["drone"].items()}
