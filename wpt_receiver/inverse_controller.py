"""The paper's model-based controller (Fig. 5), in discrete time as on a DSP.

``I2ref -> Q(s) -> G22^-1(s) -> V2* -> f^-1 -> d_short*``

``G22^-1`` is improper (eq. 8 has relative degree 1), so a low-pass filter
``Q(s) = 1/(tau s + 1)^order`` (order >= 1) precedes it. The cascade ``H = Q G22^-1`` is
discretised once (ZOH at the control period) and run as a state-space recursion; nothing is
discretised per step.

Because the envelope model is linear, ``I2 = G21 V1 + G22 V2``. With V1 constant the controller
works on the deviation from the short-mode current ``I2_sm = gamma V1 / omega_n^2`` (the current
for V2 = 0), so ``V2* = H (I2ref - I2_sm)``; at DC ``H(0) = 1/G22(0)`` and the controller returns
the exact steady-state V2 for any I2ref. Then ``I2 = Q I2ref``: the current follows the filtered
reference and cannot overshoot when Q does not (Q is a real-pole filter: no overshoot).

The slow zero of G22 at ``-beta2/alpha2 = -R1/(2 L1)`` (about -229 rad/s with Table I) becomes a
pole of H: V2* decays with the time constant ``2 L1 / R1`` (about 4.4 ms), so V2* settles in
about 14 ms (5 %) while I2 settles in a few tau.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .envelope import coefficients, steady_state
from .lti import tf2ss, zoh_ss
from .params import LinkParams, check_control_period, check_v1
from .sbar import duty_from_v2_clipped

__all__ = ["LowPassFilter", "InverseModelController", "inverse_tf", "TAU_RANGE_S", "DC_GAIN_RTOL"]

TAU_RANGE_S = (1e-6, 0.1)
"""Valid ``LowPassFilter.tau_s`` [s], as ``dronewpt export-controller --lpf-tau`` (1e300 or 1e-300 gave a NaN duty)."""

DC_GAIN_RTOL = 1e-3
"""Largest relative error of the discretised controller's DC gain against ``1/G22(0)``: beyond it float64 has
lost the controller (a fast, high-order Q makes the canonical form's coefficients span ~1e40)."""


@dataclass(frozen=True)
class LowPassFilter:
    """Q(s) = 1 / (tau_s s + 1)^order. Defaults: tau 0.2 ms, second order (smooth V2*)."""

    tau_s: float = 2e-4
    order: int = 2

    def __post_init__(self):
        lo, hi = TAU_RANGE_S
        try:
            tau = float(self.tau_s)
        except (TypeError, ValueError):
            raise ValueError(f"tau_s={self.tau_s!r} is not a number; valid range: [{lo:g}, {hi:g}] s") from None
        if isinstance(self.tau_s, bool) or not lo <= tau <= hi:    # NaN fails too
            raise ValueError(f"tau_s={self.tau_s!r} is invalid; valid range: [{lo:g}, {hi:g}] s")
        if (isinstance(self.order, bool) or not isinstance(self.order, (int, float, np.integer, np.floating))
                or int(self.order) != self.order or not 1 <= self.order <= 8):
            raise ValueError(f"order={self.order!r} is invalid; valid range: integer 1..8 (G22^-1 needs >= 1)")


def inverse_tf(params: LinkParams, lpf: LowPassFilter = LowPassFilter()):
    """``(num, den)`` of ``H(s) = Q(s) G22^-1(s) = -(s^2 + 2 zeta wn s + wn^2) / ((alpha2 s + beta2)(tau s + 1)^n)``."""
    c = coefficients(params)
    num = -np.array([1.0, 2 * c.zeta * c.omega_n, c.omega_n**2])
    den = np.array([c.alpha2, c.beta2])
    for _ in range(int(lpf.order)):
        den = np.polymul(den, [lpf.tau_s, 1.0])
    return num, den


class InverseModelController:
    """Inverse-model feed-forward of the paper for a batch of ``n`` receivers sharing one model.

    Parameters
    ----------
    params : LinkParams
        The controller's *assumed* link model (may differ from the true plant).
    control_period_s : float, optional
        Update period; default is the rectifier period T = 1/(2f) (one duty per half cycle).
    lpf : LowPassFilter
        The filter Q before G22^-1.
    n : int
        Batch size.
    """

    def __init__(self, params: LinkParams, control_period_s: float | None = None,
                 lpf: LowPassFilter = LowPassFilter(), n: int = 1):
        self.params = params
        self.lpf = lpf
        if int(n) != n or n < 1:
            raise ValueError(f"n={n!r} is invalid; valid range: integer >= 1")
        self.n = int(n)
        self.control_period_s = params.rectifier_period_s if control_period_s is None else float(control_period_s)
        check_control_period(self.control_period_s, control_period_s)
        num, den = inverse_tf(params, lpf)
        a, b, cd, dd = tf2ss(num, den)   # scipy.signal's algorithms without its 1.2 s import
        with np.errstate(all="ignore"):     # a lost controller (below) is refused by name, not by numpy's warnings
            ad, bd = zoh_ss(a, b, self.control_period_s)
        self._ad, self._bd = ad, bd[:, 0]
        self._cd, self._dd = cd[0], float(dd[0, 0])
        # steady-state map x_ss = (I - Ad)^-1 Bd u
        self._xss = self._check_dc_gain(num, den)
        self.v1_v = params.v1_amp_v
        self._i2_sm = float(steady_state(params, 0.0)[1])
        self.x = np.zeros((self.n, len(ad)))
        self.v2_cmd_v = np.zeros(self.n)

    def _check_dc_gain(self, num, den) -> np.ndarray:
        """``x_ss = (I - Ad)^-1 Bd``, after checking ``Cd x_ss + Dd = H(0)`` (the exact steady V2 the controller
        promises): a fast, high-order filter gave a controller off by 14 % (tau 3 us, order 6, 0.1 ms) or NaN
        without a word (1 us, order 8, 1 ms)."""
        h0 = num[-1] / den[-1]
        with np.errstate(all="ignore"):
            try:
                xss = np.linalg.solve(np.eye(len(self._ad)) - self._ad, self._bd)
                err = abs(float(self._cd @ xss) + self._dd - h0) / abs(h0)
            except np.linalg.LinAlgError:
                err = np.inf
        if not err <= DC_GAIN_RTOL:
            raise ValueError(
                f"LowPassFilter(tau_s={self.lpf.tau_s!r}, order={self.lpf.order!r}) at control_period_s="
                f"{self.control_period_s!r} is invalid: float64 loses the discretised controller (DC gain off by "
                f"{f'{err:.3g}' if np.isfinite(err) else 'a non-finite amount'}, limit {DC_GAIN_RTOL:g}); valid: a "
                f"larger tau_s or a lower order (order <= 4 with any tau_s in [{TAU_RANGE_S[0]:g}, "
                f"{TAU_RANGE_S[1]:g}] s on Table I)")
        return xss

    # ------------------------------------------------------------------
    @property
    def discrete_ss(self):
        """``(Ad, Bd, Cd, Dd)`` of H at the control period: ``x+ = Ad x + Bd u``, ``V2* = Cd.x + Dd u``
        with ``u = I2ref - I2_sm`` (shapes (k, k), (k,), (k,), scalar)."""
        return self._ad, self._bd, self._cd, self._dd

    @property
    def i2_sm_a(self) -> float:
        """Short-mode current of the assumed model at the current V1 [A]."""
        return self._i2_sm

    def i2_for_v2(self, v2_v):
        """Steady I2 [A] of the assumed model for a constant V2."""
        return steady_state(self.params, v2_v, v1_v=self.v1_v)[1]

    def reset(self, i2_ref_a, v1_v: float | None = None):
        """Start at steady state for the reference ``i2_ref_a`` (scalar or (n,)); returns d_short."""
        if v1_v is not None:
            self.v1_v = check_v1(v1_v)
            self._i2_sm = float(steady_state(self.params, 0.0, v1_v=self.v1_v)[1])
        u = np.broadcast_to(np.asarray(i2_ref_a, dtype=float), (self.n,)) - self.i2_sm_a
        self.x = u[:, None] * self._xss[None, :]
        self.v2_cmd_v = self.x @ self._cd + self._dd * u
        return duty_from_v2_clipped(self.v2_cmd_v, self.params.vl_v)

    def update(self, i2_ref_a) -> np.ndarray:
        """One control period: new reference in, ``V2*`` [V] out (shape (n,), before saturation).

        Also stored in ``self.v2_cmd_v``. Use this when the duty is computed with a measured VL.
        """
        u = np.asarray(i2_ref_a, dtype=float) - self._i2_sm
        if u.shape != (self.n,):
            if u.ndim > 1 or u.size not in (1, self.n):
                raise ValueError(f"i2_ref_a has shape {u.shape}; valid: a scalar or shape ({self.n},), one per receiver")
            u = np.broadcast_to(u, (self.n,))
        self.v2_cmd_v = self.x @ self._cd + self._dd * u
        self.x = self.x @ self._ad.T + u[:, None] * self._bd
        return self.v2_cmd_v

    def update1(self, i2_ref_a: float) -> float:
        """:meth:`update` for ``n = 1`` with a float in and out (same arithmetic, less overhead)."""
        u = float(i2_ref_a) - self._i2_sm
        self.v2_cmd_v = self.x @ self._cd + self._dd * u
        self.x = self.x @ self._ad.T + u * self._bd
        return float(self.v2_cmd_v[0])

    def step(self, i2_ref_a):
        """One control period: new reference in, short duty ``d_short*`` out (shape (n,)).

        ``self.v2_cmd_v`` holds V2* before saturation into [0, (4/pi) VL].
        """
        return duty_from_v2_clipped(self.update(i2_ref_a), self.params.vl_v)

    def run(self, i2_ref_a: np.ndarray):
        """Run a whole reference sequence (one link); returns ``(v2_cmd_v, d_short)`` arrays.

        The controller is reset at ``i2_ref_a[0]``.
        """
        ref = np.asarray(i2_ref_a, dtype=float)
        u = ref - self.i2_sm_a
        x0 = u[0] * self._xss
        from scipy import signal

        ss = signal.dlti(self._ad, self._bd[:, None], self._cd[None, :], [[self._dd]], dt=self.control_period_s)
        _, y, _ = signal.dlsim(ss, u, x0=x0)
        v2 = y[:, 0]
        return v2, duty_from_v2_clipped(v2, self.params.vl_v)
