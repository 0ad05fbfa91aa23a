"""The observation / action contract and the ``Policy`` protocol, defined once.

The mission runner, the gymnasium environments and every policy share this module, so every
policy runs through the same closed loop and comparisons are fair.

Observation (normalised to [-1, 1], one row per receiver; physical ranges below)

=====  ====================  ===========  =====  ==================================================
index  name                  range        unit   meaning (what the receiver can measure)
=====  ====================  ===========  =====  ==================================================
0      i2_amp_a              0 .. 60      A      secondary coil current envelope (sensor, noisy)
1      battery_v             20 .. 36     V      battery terminal voltage (= VL of the SBAR)
2      battery_current_a     -60 .. 30    A      battery current, + = charging
3      rect_current_a        0 .. 20      A      SBAR DC output current I_L (into the battery node)
4      soc                   0 .. 1       -      state of charge (battery management estimate)
5      charge_cmd_a          0 .. 20      A      commanded I_L; 0 = stop charging (short mode)
6      last_d_short          0 .. 1       -      the duty applied in the previous control period
7      t_since_stop_s        0 .. 0.01    s      time since the charge command dropped to 0 (the
                                                 stop); 0 while charging; saturates at 10 ms
=====  ====================  ===========  =====  ==================================================

Why field 7: the RM -> SM transition is a timed manoeuvre (the coil current answers the *rate* of
change of V2, G22 ~ -alpha2 s / (s^2 + ...)), and fields 0-6 do not say how far into it the receiver
is (the command is 0 throughout). The mission runner fills it from the time its command last went
to 0; the environments from the episode's stop time. Models trained on the 7-field contract keep
working: :class:`policies.rl.RLPolicy` gives them the first ``obs_dim`` fields of their metadata.

Action: the short duty ``d_short`` in [0, 1] (0 = rectification mode, 1 = short mode), applied
for one control period. Environments expose it as ``a in [-1, 1]`` with ``d = (a + 1) / 2``
(:func:`action_to_duty`); discrete environments as {0: RM, 1: SM}.

History (frame stack, issue 21): a learned policy may see the last ``history = K`` observations
instead of one (``dronewpt train --history K``), oldest first, flattened to ``K * OBS_DIM`` values
(:func:`history_obs_dim`); a window starts with ``K`` copies of its first observation. Nothing else
in the contract changes: the envs keep returning one observation, the stack is a wrapper
(:mod:`envs.history`) and the policy keeps its own (:class:`policies.rl.RLPolicy`). It lets a policy
see the phase of the 4 kHz ringing and a sensing delay, which one frame does not show.

Optional fast path: a policy may also offer ``kernel()`` returning ``(fn, params, state)`` (or None):
``fn`` a numba-compiled function of the signature :data:`POLICY_KERNEL_SIGNATURE`, ``d = fn(obs,
params, state)``, doing what ``act`` does for one receiver (``obs`` one normalised row, shape
(OBS_DIM,); ``state`` float64, updated in place, as after ``reset(1)``). The mission loop (compiled
for every policy, :mod:`mission_sim.world.loop_kernel`) then calls it in place of ``act``; after such a
run the policy object itself stays as reset. Policies without it are called from Python whenever the
loop needs a duty (:mod:`mission_sim.world.fastpath`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from wpt_receiver import TABLE_I, LinkParams

from .validation import Range, check_number

__all__ = ["ObsField", "OBS_FIELDS", "OBS_DIM", "OBS_INDEX", "normalise_obs", "normalise_obs_row", "denormalise_obs",
           "denormalise_obs_field", "action_to_duty", "duty_to_action", "PolicyContext", "Policy",
           "POLICY_KERNEL_SIGNATURE", "MAX_HISTORY", "HISTORY_RANGE", "check_history", "history_obs_dim", "LINK_MODELS", "CONTROL_PERIOD_RANGE"]

#: the plant's link models a policy may run on (:attr:`PolicyContext.link_model`, ``envs.EnvConfig.link_model``,
#: ``--link``): eq. 4's envelope, the exact modes (the mission's link, the envs' default since 2026-11-26). The one list.
LINK_MODELS = ("envelope", "modal")

#: a control period [s]: ``envs.EnvConfig``'s ``dt_s`` (= the env step) and so the ``control_period_s`` a trained
#: model's metadata may say (:func:`policies.rl.load_meta`)
CONTROL_PERIOD_RANGE = Range(1e-7, 1e-2, "s")

#: numba signature of a policy's optional compiled step ``d = fn(obs, params, state)`` (module notes)
POLICY_KERNEL_SIGNATURE = "float64(float64[::1], float64[::1], float64[::1])"


@dataclass(frozen=True)
class ObsField:
    name: str
    lo: float
    hi: float
    unit: str
    doc: str


OBS_FIELDS: tuple[ObsField, ...] = (
    ObsField("i2_amp_a", 0.0, 60.0, "A", "secondary coil current envelope (sensor, noisy)"),
    ObsField("battery_v", 20.0, 36.0, "V", "battery terminal voltage (= VL of the SBAR)"),
    ObsField("battery_current_a", -60.0, 30.0, "A", "battery current, + = charging"),
    ObsField("rect_current_a", 0.0, 20.0, "A", "SBAR DC output current I_L"),
    ObsField("soc", 0.0, 1.0, "-", "state of charge"),
    ObsField("charge_cmd_a", 0.0, 20.0, "A", "commanded I_L; 0 = stop charging (short mode)"),
    ObsField("last_d_short", 0.0, 1.0, "-", "duty applied in the previous control period"),
    ObsField("t_since_stop_s", 0.0, 0.01, "s", "time since the charge command dropped to 0; 0 while charging"),
)
OBS_DIM = len(OBS_FIELDS)
OBS_INDEX = {f.name: i for i, f in enumerate(OBS_FIELDS)}
_LO = np.array([f.lo for f in OBS_FIELDS])
_HI = np.array([f.hi for f in OBS_FIELDS])
_INV_SPAN = 1.0 / (_HI - _LO)


#: the longest observation history (frame stack) a learned policy may ask for [control periods]
MAX_HISTORY = 32
HISTORY_RANGE = Range(1, MAX_HISTORY, integer=True)


def check_history(history) -> int:
    """``history`` (frames stacked) as an int; ValueError out of 1..MAX_HISTORY (True was one frame, 2.0 stored as a
    float)."""
    return check_number("history", history, HISTORY_RANGE)


def history_obs_dim(history: int) -> int:
    """Width of a stacked observation of ``history`` frames (``history * OBS_DIM``); ValueError out of 1..MAX_HISTORY."""
    return check_history(history) * OBS_DIM


_LO_INV = tuple(zip(_LO.tolist(), _INV_SPAN.tolist()))
_LO_HALF = tuple(zip(_LO.tolist(), (0.5 * (_HI - _LO)).tolist()))   # denormalise: lo + (o + 1) * half span


def normalise_obs(physical) -> np.ndarray:
    """Physical values, shape (..., OBS_DIM) in the order of :data:`OBS_FIELDS` -> [-1, 1] (clipped)."""
    x = np.asarray(physical, dtype=float)
    if x.shape == (1, OBS_DIM):
        return normalise_obs_row(x[0].tolist())
    return np.minimum(np.maximum(2.0 * (x - _LO) * _INV_SPAN - 1.0, -1.0), 1.0)


def normalise_obs_row(values) -> np.ndarray:
    """:func:`normalise_obs` of one receiver given as OBS_DIM floats -> shape (1, OBS_DIM).

    The same arithmetic on Python floats (bit-identical), for the n = 1 loops where numpy's
    per-call overhead would dominate.
    """
    return np.array([[min(max(2.0 * (v - lo) * inv - 1.0, -1.0), 1.0) for v, (lo, inv) in zip(values, _LO_INV)]])


def denormalise_obs_field(obs, index: int) -> float:
    """Physical value of field ``index`` of the first observation row (float; :func:`denormalise_obs`'s arithmetic)."""
    lo, half = _LO_HALF[index]
    return lo + (float(obs[0, index] if np.ndim(obs) == 2 else obs[index]) + 1.0) * half


def denormalise_obs(obs) -> np.ndarray:
    """Inverse of :func:`normalise_obs` (values that were clipped stay at the range ends)."""
    o = np.asarray(obs, dtype=float)
    return _LO + (o + 1.0) * (0.5 * (_HI - _LO))


def action_to_duty(action) -> np.ndarray:
    """Environment action in [-1, 1] -> d_short in [0, 1] (clipped)."""
    return np.minimum(np.maximum((np.asarray(action, dtype=float) + 1.0) * 0.5, 0.0), 1.0)  # np.clip: slow at n=1


def duty_to_action(d_short) -> np.ndarray:
    """d_short in [0, 1] -> environment action in [-1, 1]."""
    return 2.0 * np.clip(np.asarray(d_short, dtype=float), 0.0, 1.0) - 1.0


@dataclass(frozen=True)
class PolicyContext:
    """What a policy may know besides the observation.

    link : the receiver's *assumed* link model (the truth may differ: Lm mismatch scenarios)
    control_period_s : how often ``act`` is called [s]; default 100 us, the control period of the
        environments and of the default mission (a 10 kHz DSP loop)
    rated_i2_a : rated secondary coil current amplitude [A]
    link_model : the plant's link model the policy runs on, one of :data:`LINK_MODELS`: ``"envelope"`` (eq. 4,
        a standalone context's default) or ``"modal"`` (the exact-mode link, the envs' default
        ``envs.EnvConfig(link_model="modal")``; the mission's); a model-predictive policy predicts with it. An env
        gives its own (``env.policy_context``), so a policy run by an env always sees that env's link
    """

    link: LinkParams = TABLE_I
    control_period_s: float = 1e-4
    rated_i2_a: float = 15.0
    link_model: str = "envelope"

    def __post_init__(self):
        if not np.isfinite(self.control_period_s) or self.control_period_s <= 0:
            raise ValueError(f"control_period_s={self.control_period_s!r} is invalid; valid range: (0, inf)")
        if not np.isfinite(self.rated_i2_a) or self.rated_i2_a <= 0:
            raise ValueError(f"rated_i2_a={self.rated_i2_a!r} is invalid; valid range: (0, inf)")
        if self.link_model not in LINK_MODELS:
            raise ValueError(f"link_model={self.link_model!r} is invalid; valid values: {', '.join(LINK_MODELS)}")


@runtime_checkable
class Policy(Protocol):
    """A receiver policy: normalised observations in, short duties out, for ``n`` receivers at once."""

    name: str

    def reset(self, n: int = 1) -> None:
        """Forget all internal state; the next ``act`` sees ``n`` receivers."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` shape (n, OBS_DIM), normalised -> ``d_short`` shape (n,) in [0, 1]."""
