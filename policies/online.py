"""The model-based controller with an online estimate of Lm (the paper's stated future work).

The paper's controller assumes Lm; a hovering drone's Lm moves with its pose. In quasi-steady
state the envelope model (eq. 4) gives, with ``X = w Lm``,

    I2 (R1 R2 + X^2) = X V1 - R1 V2    ->    X = (V1 + sqrt(V1^2 - 4 I2 (I2 R1 R2 + R1 V2))) / (2 I2)

(the larger root: X ~ V1 / I2 for a series-series link). The estimator low-passes the measured I2
envelope and the applied V2 (from the last duty and the measured battery voltage, eq. 9), solves
for Lm only while V2 is quasi-steady (|V2 - its low-passed value| < ``steady_v2_v``), and smooths
the result. When a receiver's estimate has moved by more than ``rediscretise_rel`` (1 %) from the
Lm its inverse controller was built for, that controller is rebuilt for the new Lm (one scipy
discretisation; never per step). The swap is bumpless: the new controller starts in the steady
state whose output is the V2* the old one was giving, and then follows the reference through Q
as before (restarting it at the reference itself would turn a running transition into a step).
Each controller's reference is computed with that controller's own Lm: H = Q G22^-1 has a DC gain
of 1/G22(0) ~ -100 V/A, so a 1 % model/reference mismatch would be volts of V2*.

Why the gate on dV2/dt: G22 has a zero at R1/(2 L1) ~ 229 rad/s, so while V2 moves, I2 carries a
term ``-(alpha2/omega_n^2) dV2/dt`` (4.2e-5 A per V/s with Table I) besides the static one. With
|V2 - its 1 ms low-pass| < 0.3 V (|dV2/dt| <~ 300 V/s) that term is < 0.02 A, < 0.2 % of Lm.
"""

from __future__ import annotations

import math

import numpy as np

from mission_sim.contract import OBS_FIELDS, OBS_INDEX, PolicyContext, denormalise_obs
from wpt_receiver import InverseModelController, LowPassFilter, duty_from_v2_clipped, steady_state
from wpt_receiver.envelope import steady_state_unchecked

from .classical import target_v2

__all__ = ["lm_from_steady_state", "OnlineLmModelBasedPolicy"]

#: the observation fields the controller reads (its estimator, its reference, its V2 and duty)
READS = ("i2_amp_a", "battery_v", "charge_cmd_a", "last_d_short")
_READ_COLS = [OBS_INDEX[name] for name in READS]


def _refuse_non_finite(obs) -> None:
    """``ValueError`` naming the first non-finite value of a field in :data:`READS` of ``obs`` (normalised, one row
    per receiver), its receiver and what is checked: finite (a value outside the normalised [-1, 1] is taken, as the
    controller takes it: only what would poison its state is refused)."""
    for name, j in zip(READS, _READ_COLS):
        bad = np.flatnonzero(~np.isfinite(obs[:, j]))
        if len(bad):
            f = OBS_FIELDS[j]
            raise ValueError(f"observation {name}={float(obs[bad[0], j])!r} (receiver {int(bad[0])}) is invalid; "
                             f"valid range: finite (normalised: -1..1 is {f.lo:g}..{f.hi:g}"
                             + ("" if f.unit == "-" else f" {f.unit}") + ")")


def lm_from_steady_state(link, i2_a, v2_v, v1_v=None):
    """Lm [H] that makes ``i2_a`` the steady secondary current for ``v2_v`` (inverse of
    :func:`wpt_receiver.steady_state`); NaN where no real solution exists."""
    i2 = np.asarray(i2_a, dtype=float)
    v2 = np.asarray(v2_v, dtype=float)
    v1 = link.v1_amp_v if v1_v is None else v1_v
    disc = v1 * v1 - 4.0 * i2 * (i2 * link.r1_ohm * link.r2_ohm + link.r1_ohm * v2)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = (v1 + np.sqrt(disc)) / (2.0 * i2)
    return np.where((disc >= 0) & (i2 > 0), x / link.omega_rad_s, np.nan)


class OnlineLmModelBasedPolicy:
    """Paper's inverse-model controller, one per receiver, each with its own online Lm estimate."""

    name = "model_based_online"

    def __init__(self, ctx: PolicyContext = PolicyContext(), lpf: LowPassFilter = LowPassFilter(),
                 tau_meas_s: float = 1e-3, tau_est_s: float = 1e-3, steady_v2_v: float = 0.3,
                 rediscretise_rel: float = 0.01):
        for name, v in (("tau_meas_s", tau_meas_s), ("tau_est_s", tau_est_s), ("steady_v2_v", steady_v2_v),
                        ("rediscretise_rel", rediscretise_rel)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} is invalid; valid range: (0, inf)")
        self.ctx, self.lpf = ctx, lpf
        dt = ctx.control_period_s
        self.a_meas = dt / (tau_meas_s + dt)
        self.a_est = dt / (tau_est_s + dt)
        self.steady_v2_v = float(steady_v2_v)
        self.rediscretise_rel = float(rediscretise_rel)
        self.rebuilds = 0
        self.reset(1)

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self._x = None

    @property
    def lm_estimate_h(self) -> np.ndarray:
        """Current Lm estimate per receiver [H]."""
        return self._lm.copy()

    def _build(self, idx, v2_now):
        """(Re)build the controllers of receivers ``idx`` for their current Lm estimate, each starting
        in the steady state whose output is ``v2_now[i]`` (bumpless). One scipy discretisation per
        rebuilt receiver; the stepping itself is batched over all receivers."""
        for i, v2 in zip(idx, v2_now):
            link = self.ctx.link.with_(lm_h=float(self._lm[i]))
            ctl = InverseModelController(link, self.ctx.control_period_s, self.lpf, n=1)
            ctl.reset(steady_state(link, v2)[1])
            ad, bd, cd, dd = ctl.discrete_ss
            if self._x is None:  # first build: allocate the stacked state space (k from the filter order)
                k, n = len(bd), self.n
                self._a, self._b, self._c = np.zeros((n, k, k)), np.zeros((n, k)), np.zeros((n, k))
                self._d, self._i2sm, self._x = np.zeros(n), np.zeros(n), np.zeros((n, k))
            self._a[i], self._b[i], self._c[i], self._d[i] = ad, bd, cd, dd
            self._x[i], self._i2sm[i] = ctl.x[0], ctl.i2_sm_a
            self._lm_ctl[i] = self._lm[i]
            self.rebuilds += 1

    def act(self, obs):
        """The duties for observations ``obs`` (normalised, one row per receiver). A non-finite value of a field the
        controller reads (:data:`READS`) is refused (``ValueError`` naming the field, the receiver and the valid
        range) before any state moves: a NaN would poison the estimator and the controllers until :meth:`reset`."""
        phys = denormalise_obs(np.atleast_2d(obs))
        i2 = phys[:, OBS_INDEX["i2_amp_a"]]
        vl = phys[:, OBS_INDEX["battery_v"]]
        cmd = phys[:, OBS_INDEX["charge_cmd_a"]]
        d_last = phys[:, OBS_INDEX["last_d_short"]]
        n = len(i2)
        if not (math.isfinite(i2[0]) and math.isfinite(vl[0]) and math.isfinite(cmd[0]) and math.isfinite(d_last[0])
                if n == 1 else np.isfinite(phys[:, _READ_COLS]).all()):
            _refuse_non_finite(np.atleast_2d(obs))
        v2 = 4.0 / np.pi * vl * (1.0 - np.sin(0.5 * np.pi * d_last))
        link = self.ctx.link
        fresh = self._x is None or len(self._x) != n
        if fresh:
            self.n = n
            self._x = None
            self._lm = np.full(n, link.lm_h)
            self._lm_ctl = np.full(n, np.nan)
            self._i2f, self._v2f = i2.copy(), v2.copy()
        # estimator (quasi-steady inversion of the envelope model, gated)
        self._i2f += self.a_meas * (i2 - self._i2f)
        self._v2f += self.a_meas * (v2 - self._v2f)
        steady = np.abs(v2 - self._v2f) < self.steady_v2_v
        lm_inst = lm_from_steady_state(link, self._i2f, self._v2f)
        # frozen once the command is the stop: the controller built before decays V2 to short mode, and a
        # rebuild mid-transition (bumpless: it restarts from the V2 it was giving) would hold V2 up
        charging = cmd > 0.0
        ok = charging & steady & np.isfinite(lm_inst) & (lm_inst > 0.2 * link.lm_h) & (lm_inst < 5.0 * link.lm_h)
        self._lm = np.where(ok, self._lm + self.a_est * (lm_inst - self._lm), self._lm)
        # controllers: build on the first call, rebuild where the estimate moved by > rediscretise_rel
        if fresh:
            self._out = np.asarray(target_v2(self.ctx, cmd, vl, lm_h=self._lm), dtype=float)
            self._build(range(n), self._out)
            moved = ()
        else:
            moved = np.flatnonzero(charging & (np.abs(self._lm / self._lm_ctl - 1.0) > self.rediscretise_rel))
        if len(moved):
            self._build(moved, self._out[moved])  # start where they were: at the V2* they last gave
        v2_target = target_v2(self.ctx, cmd, vl, lm_h=self._lm_ctl)
        # (unchecked: the Lm is a controller's, checked by LinkParams when it was built; V2* is target_v2's of the
        # observations checked finite above, and finite inputs give a finite V2*)
        ref = steady_state_unchecked(link, v2_target, self._lm_ctl, link.v1_amp_v)[1]
        u = ref - self._i2sm
        self._out = np.einsum("nk,nk->n", self._c, self._x) + self._d * u
        self._x = np.einsum("nij,nj->ni", self._a, self._x) + self._b * u[:, None]
        return duty_from_v2_clipped(self._out, vl)
