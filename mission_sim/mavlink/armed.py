"""Armed periods of a flight log: from its armed-state records, else inferred from the motors.

Sources, in the order they are trusted (the first one the log has is used, and named in
``FlightLog.armed_source``):

1. armed-state *reports* (HEARTBEAT base_mode bit 7 in a .tlog, PX4 ``vehicle_status``): the
   state at each report;
2. armed-state *events* (DataFlash EV 10/11, ARM ArmState): changes only. ArduCopter 4.x logs
   written from arming on hold no arm record at the start; their first event is the disarm
   near the end. A first event that is a disarm therefore means "armed from the start of the log"
   (``starts_armed``);
3. motor outputs: PWM of the motor channels (DataFlash RCOU, .tlog SERVO_OUTPUT_RAW, PX4
   ``actuator_outputs``) above the disarmed level, or ESC RPM > 0. A motor channel is one whose
   lowest value in the log is a disarmed output (<= :data:`DISARMED_PWM_MAX_US`); servos rest
   near 1500 us and are left out. Armed = any motor channel more than :data:`MOTOR_ON_US` above
   its disarmed level. Motors idle at the disarmed PWM when the spin-when-armed output is 0, so
   seconds on the ground before take-off and after landing may count as disarmed (-1 % of the
   armed time on the dronekit flight, 7 periods);
4. throttle: VFR_HUD.throttle or CTUN ThO / ThrOut above 0 (the autopilot outputs 0 disarmed).

Inferred states are debounced: motor-off stretches shorter than :data:`MIN_OFF_S` inside an
armed stretch are bridged (a flip or a throttle cut in flight does not disarm).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["armed_periods", "infer_armed", "starts_armed", "transitions", "DISARMED_PWM_MAX_US", "MOTOR_ON_US", "MIN_OFF_S"]

DISARMED_PWM_MAX_US = 1050.0   # a channel that never goes below this is a servo, not a motor
MOTOR_ON_US = 20.0             # this far above the disarmed level counts as spinning
MIN_OFF_S = 2.0                # shorter motor-off stretches inside an armed stretch are bridged
_ESC_BIN_S = 0.1               # ESC instances report one after another: combine them per bin


def armed_periods(armed: pd.DataFrame, end_s: float, starts_armed: bool = False) -> list[tuple[float, float]]:
    """(start_s, end_s) of each armed period from the ``armed`` table (t_s, armed).

    An open period ends at ``end_s``. ``starts_armed``: the vehicle was armed when the log began;
    if the first record is then a disarm (a log of events), the first period starts at 0; a first
    armed report starts it at that report, as any other."""
    first_off = len(armed) > 0 and not bool(armed["armed"].iloc[0])
    periods, start = [], (0.0 if starts_armed and first_off else None)
    for t, a in zip(armed["t_s"].to_numpy(float), armed["armed"].to_numpy(bool)):
        if a and start is None:
            start = t
        elif not a and start is not None:
            periods.append((start, t))
            start = None
    if start is not None:
        periods.append((start, max(float(end_s), start)))
    return periods


def starts_armed(armed: pd.DataFrame) -> bool:
    """A log of armed-state *reports* (or inferred states) starts armed when its first report says
    armed: the vehicle was armed when the log began (:func:`armed_periods` starts the first period
    at that report)."""
    return bool(len(armed) and armed["armed"].iloc[0])


def transitions(t, on, min_off_s: float = MIN_OFF_S) -> pd.DataFrame:
    """Rows (t_s, armed) at the first sample and at each change of the boolean series ``on``
    (``t`` sorted), with off stretches shorter than ``min_off_s`` between two on samples bridged."""
    t = np.asarray(t, dtype=float)
    on = np.asarray(on, dtype=bool).copy()
    if len(t) == 0:
        return pd.DataFrame({"t_s": pd.Series(dtype=float), "armed": pd.Series(dtype=bool)})
    idx = np.flatnonzero(on)
    for a, b in zip(idx[:-1], idx[1:]):
        if b > a + 1 and t[b] - t[a] < min_off_s:
            on[a:b] = True
    change = np.concatenate([[True], on[1:] != on[:-1]])
    return pd.DataFrame({"t_s": t[change], "armed": on[change]})


def _from_pwm(df: pd.DataFrame) -> pd.DataFrame | None:
    """Armed from PWM columns ``ch*`` [us]: motor channels are those with a disarmed level."""
    chans = [c for c in df.columns if c.startswith("ch")]
    if not len(df) or not chans:
        return None
    pwm = df[chans].to_numpy(float, copy=True)
    pwm[pwm <= 0] = np.nan                    # 0 = output off / not used
    with np.errstate(invalid="ignore"):
        low = np.nanmin(np.where(np.isfinite(pwm), pwm, np.inf), axis=0)
    motors = low <= DISARMED_PWM_MAX_US
    if not motors.any():
        return None
    with np.errstate(invalid="ignore"):
        on = np.any(pwm[:, motors] > low[motors] + MOTOR_ON_US, axis=1)
    return transitions(df["t_s"].to_numpy(float), on)


def _from_esc(df: pd.DataFrame) -> pd.DataFrame | None:
    if not len(df):
        return None
    b = np.floor(df["t_s"].to_numpy(float) / _ESC_BIN_S)
    g = pd.DataFrame({"bin": b, "t_s": df["t_s"].to_numpy(float), "on": df["rpm"].to_numpy(float) > 0})
    agg = g.groupby("bin").agg(t_s=("t_s", "first"), on=("on", "any"))
    return transitions(agg["t_s"].to_numpy(), agg["on"].to_numpy())


def _from_throttle(df: pd.DataFrame) -> pd.DataFrame | None:
    if not len(df):
        return None
    return transitions(df["t_s"].to_numpy(float), df["throttle"].to_numpy(float) > 0)


def infer_armed(tables: dict[str, tuple[pd.DataFrame, str]]) -> tuple[pd.DataFrame, str | None]:
    """Armed state inferred from ``tables`` = {"pwm" | "esc" | "throttle": (table, message name)},
    tried in that order; returns (transitions table, "NAME motor outputs" / "NAME throttle") or
    (empty table, None) when none of them tells."""
    for key, fn, what in (("pwm", _from_pwm, "motor outputs"), ("esc", _from_esc, "motor RPM"),
                          ("throttle", _from_throttle, "throttle")):
        if key in tables:
            df, name = tables[key]
            out = fn(df)
            if out is not None and out["armed"].any():
                return out, f"{name} {what} (inferred)"
    return transitions([], []), None
