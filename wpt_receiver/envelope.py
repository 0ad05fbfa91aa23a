"""Envelope (slowly varying amplitude) model of the series-series link, paper eq. 3-8.

States are the fundamental amplitudes ``I1(t)``, ``I2(t)`` of ``i1 = I1 sin(wt)`` and
``i2 = I2 cos(wt)``; inputs are ``V1 = (4/pi) Vdc`` and ``V2`` (the rectifier's fundamental,
eq. 9). With the sign of V2 consistent with eq. 4b-5 (eq. 3b as printed has a sign slip, and so has
eq. 4a with +V1: eq. 5a needs -V1 there)::

    2 L1 dI1/dt + R1 I1 + w Lm I2 - V1 = 0          (eq. 3a)
    2 L2 dI2/dt + R2 I2 - w Lm I1 + V2 = 0          (eq. 3b with the sign of eq. 4b and 5b)

i.e. ``dx/dt = A x + B u`` with ``x = [I1, I2]``, ``u = [V1, V2]``.

Stepping is by exact zero-order-hold discretisation (closed-form matrix exponential of the 2x2
state matrix), vectorised over a batch of independent links: see :class:`EnvelopeLink`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import LinkParams, check_v1, lm_limit_h

__all__ = [
    "EnvelopeCoefficients",
    "coefficients",
    "state_matrices",
    "g22",
    "steady_state",
    "steady_state_unchecked",
    "short_mode_rated_k",
    "check_v2",
    "check_lm",
    "zoh_discretise",
    "EnvelopeLink",
    "simulate",
]


@dataclass(frozen=True)
class EnvelopeCoefficients:
    """Coefficients of eq. 6 (units: zeta [-], omega_n [rad/s], alpha [1/H],
    beta [ohm/H^2], gamma [ohm/H^2])."""

    zeta: float
    omega_n: float
    alpha1: float
    beta1: float
    alpha2: float
    beta2: float
    gamma: float


def coefficients(p: LinkParams) -> EnvelopeCoefficients:
    """zeta, omega_n, alpha1/2, beta1/2, gamma exactly as in the paper (eq. 6)."""
    wlm = p.omega_rad_s * p.lm_h
    det = p.r1_ohm * p.r2_ohm + wlm**2
    l1l2 = p.l1_h * p.l2_h
    return EnvelopeCoefficients(
        zeta=(p.l1_h * p.r2_ohm + p.l2_h * p.r1_ohm) / np.sqrt(4 * l1l2) / np.sqrt(det),
        omega_n=0.5 * np.sqrt(det / l1l2),
        alpha1=1.0 / (2 * p.l1_h),
        beta1=p.r2_ohm / (4 * l1l2),
        alpha2=1.0 / (2 * p.l2_h),
        beta2=p.r1_ohm / (4 * l1l2),
        gamma=wlm / (4 * l1l2),
    )


def state_matrices(p: LinkParams, lm_h=None):
    """Continuous-time ``(A, B)`` of eq. 4 for ``x=[I1, I2]``, ``u=[V1, V2]``.

    ``lm_h`` (scalar or array of shape (N,)) overrides ``p.lm_h``; with an array the result is
    batched: A has shape (N, 2, 2), B shape (2, 2) (B does not depend on Lm).
    """
    lm = p.lm_h if lm_h is None else np.asarray(lm_h, dtype=float)
    wlm = p.omega_rad_s * np.asarray(lm, dtype=float)
    a = np.empty(np.shape(wlm) + (2, 2))
    a[..., 0, 0] = -p.r1_ohm / (2 * p.l1_h)
    a[..., 0, 1] = -wlm / (2 * p.l1_h)
    a[..., 1, 0] = wlm / (2 * p.l2_h)
    a[..., 1, 1] = -p.r2_ohm / (2 * p.l2_h)
    b = np.array([[1.0 / (2 * p.l1_h), 0.0], [0.0, -1.0 / (2 * p.l2_h)]])
    return a, b


def g22(p: LinkParams):
    """Transfer function G22 = I2/V2 = -(alpha2 s + beta2)/(s^2 + 2 zeta omega_n s + omega_n^2) (eq. 8)."""
    c = coefficients(p)
    from scipy import signal   # 1.2 s import: only here

    return signal.TransferFunction([-c.alpha2, -c.beta2], [1.0, 2 * c.zeta * c.omega_n, c.omega_n**2])


#: arrays up to this size are checked on a Python list (``tolist``, ``min``, ``max``, ``sum``: ~0.5 us at 8 values),
#: larger ones by numpy reductions (~1 us each, whatever the size up to thousands): ``policies.online`` calls
#: :func:`steady_state` once per step with one value per link (benchmarks/bench_steady_state_checks.py)
_SMALL = 32


def check_v2(v2_v, sequence: bool = False) -> None:
    """``v2_v`` [V] all finite (``sequence``: also a non-empty 1-D sequence, :func:`simulate`'s input), else a
    ``ValueError`` naming the first bad value: the one rule of :func:`simulate` and :func:`steady_state` (a NaN V2
    gave NaN currents)."""
    if type(v2_v) is float and not sequence and math.isfinite(v2_v):   # (the common scalar call: no numpy)
        return
    v2 = np.asarray(v2_v, dtype=float)
    shape_ok = not sequence or (v2.ndim == 1 and len(v2) > 0)
    flat = v2 if v2.ndim == 1 else v2.reshape(-1)
    if shape_ok and (math.isfinite(sum(flat.tolist())) if flat.size <= _SMALL else
                     np.logical_and.reduce(np.isfinite(flat))):   # (see _SMALL; a finite sum overflowing: exact look)
        return
    bad = flat[~np.isfinite(flat)]
    if shape_ok and not bad.size:
        return
    what = f"v2_v={float(bad[0])!r}" if bad.size else f"v2_v of shape {v2.shape}"
    raise ValueError(f"{what} is invalid; valid: {'a non-empty 1-D sequence of ' if sequence else ''}finite V2 "
                     "amplitudes [V]")


def check_lm(p: LinkParams, lm_h, zero_ok: bool = False) -> None:
    """``lm_h`` [H] (a number or an array) inside ``(0, sqrt(L1 L2))``, 0 < k < 1 (``zero_ok``: from 0 on, where the
    steady state is regular), else a ``ValueError`` naming the first bad value: the one rule of :func:`simulate`,
    :func:`steady_state` (a negative Lm ran) and :class:`EnvelopeLink`."""
    lm_max = lm_limit_h(p)   # (LinkParams' limit)
    if type(lm_h) is float:   # (a Python float: no numpy)
        lo = hi = lm_h
    else:
        lm = np.asarray(lm_h, dtype=float)
        if lm.size <= _SMALL:   # (Python's min and max skip a NaN: the sum catches it)
            vals = lm.reshape(-1).tolist()
            lo, hi = (min(vals), max(vals)) if vals else (lm_max / 2, lm_max / 2)
            total = sum(vals)
            if total != total:
                lo = math.nan
        else:   # the extremes: two reductions, no temporary array; a NaN propagates into both
            lo, hi = np.minimum.reduce(lm, axis=None), np.maximum.reduce(lm, axis=None)
    if (lo >= 0.0 if zero_ok else lo > 0.0) and hi < lm_max:
        return
    lm = np.asarray(lm_h, dtype=float)
    bad = lm[~(((lm >= 0) if zero_ok else (lm > 0)) & (lm < lm_max))]   # (inf failed on an empty index once)
    raise ValueError(f"lm_h={float(bad.flat[0])!r} is invalid; valid range: {'[' if zero_ok else '('}0, "
                     f"{lm_max:.6g}) H ({'0 <=' if zero_ok else '0 <'} k < 1)")


def steady_state(p: LinkParams, v2_v, lm_h=None, v1_v=None):
    """Closed-form steady amplitudes ``(I1, I2)`` [A] for constant V1 and V2 [V] (phasor solution; eq. 3 with
    d/dt = 0, i.e. eq. 5 at s = 0).

    ``R1 I1 + w Lm I2 = V1`` and ``-w Lm I1 + R2 I2 = -V2`` give
    ``I2 = (w Lm V1 - R1 V2) / det`` and ``I1 = (R2 V1 + w Lm V2) / det`` with
    ``det = R1 R2 + (w Lm)^2`` (regular at Lm = 0: I1 = V1/R1, I2 = -V2/R2).
    RM is ``v2_v = (4/pi) VL``; SM is ``v2_v = 0``. Broadcasts over arrays. Refused (``ValueError``, naming the first
    bad value): a V2 that is not finite (:func:`check_v2`), an Lm outside ``[0, sqrt(L1 L2))`` (:func:`check_lm`),
    a V1 outside ``(0, inf)`` (:func:`wpt_receiver.params.check_v1`); then :func:`steady_state_unchecked`.
    """
    check_v2(v2_v)
    if lm_h is not None:
        check_lm(p, lm_h, zero_ok=True)
    lm = p.lm_h if lm_h is None else np.asarray(lm_h, dtype=float)
    v1 = p.v1_amp_v if v1_v is None else np.asarray(check_v1(v1_v, array_ok=True), dtype=float)
    return steady_state_unchecked(p, np.asarray(v2_v, dtype=float), lm, v1)


def steady_state_unchecked(p: LinkParams, v2, lm, v1):
    """:func:`steady_state`'s arithmetic without any input check (~2 us a call less), for a caller's inner loop.

    The caller guarantees what :func:`steady_state` would check: ``v2`` [V] finite, ``lm`` [H] in ``[0, sqrt(L1
    L2))``, ``v1`` [V] finite and > 0 (floats or float arrays; broadcast). Nothing is refused here: a NaN or an Lm at
    or above the coils' limit gives NaN or meaningless currents. (``policies.online``'s control step: its Lm is a
    controller's, checked by :class:`LinkParams` when it was built, its V2 from observations it checked finite.)"""
    wlm = p.omega_rad_s * lm
    det = p.r1_ohm * p.r2_ohm + wlm**2
    i2 = (wlm * v1 - p.r1_ohm * v2) / det
    i1 = (p.r2_ohm * v1 + wlm * v2) / det
    return i1, i2


def short_mode_rated_k(p: LinkParams, i2_a: float, v1_v: float | None = None, overshoot: float = 0.0) -> float:
    """The coupling ``k`` below which the steady short-mode I2, times ``1 + overshoot``, exceeds ``i2_a`` [A] (at V1
    ``v1_v``, default ``p.v1_amp_v``; ``p``'s resistances, with any devices' folded in by the caller): :func:`steady_state`
    at V2 = 0, ``I2 = x V1 / (R1 R2 + x^2)`` with ``x = w Lm = w k sqrt(L1 L2)``, equals ``I = i2_a / (1 + overshoot)``
    at the roots of ``I x^2 - V1 x + I R1 R2 = 0``; the larger, ``x = (V1 + sqrt(V1^2 - 4 I^2 R1 R2)) / (2 I)`` (~ V1 /
    I: the I2 ~ V1 / (w Lm) of a well-coupled pair), bounds from below the couplings where I2 stays within ``I``. 0.0
    when I2 never reaches ``I`` (its largest, ``V1 / (2 sqrt(R1 R2))`` at ``x = sqrt(R1 R2)``, is below it).
    ``overshoot`` (>= 0, a fraction): how far a transition into short mode peaks above the steady I2 (the peak
    ``(1 + overshoot) I2`` is what is bounded; 0: the steady state)."""
    if not (math.isfinite(overshoot) and overshoot >= 0.0):
        raise ValueError(f"overshoot={overshoot!r} is invalid; valid range: [0, inf)")
    v1 = p.v1_amp_v if v1_v is None else float(v1_v)
    i_a = i2_a / (1.0 + overshoot)
    disc = v1 * v1 - 4.0 * i_a * i_a * p.r1_ohm * p.r2_ohm
    if disc < 0.0:
        return 0.0
    return (v1 + math.sqrt(disc)) / (2.0 * i_a) / (p.omega_rad_s * math.sqrt(p.l1_h * p.l2_h))


_SERIES_MAX = 0.1   # zoh_discretise: Bd by its series below this ||A dt||


def zoh_discretise(a, b, dt_s: float):
    """Exact ZOH discretisation of a (batch of) 2x2 system(s): ``Ad = e^{A dt}``,
    ``Bd = A^{-1} (Ad - I) B``.

    Uses the closed form ``e^{At} = e^{st} [cosh(qt) I + sinh(qt)/q (A - sI)]`` with
    ``s = tr(A)/2``, ``q = sqrt(s^2 - det A)`` (real or imaginary), vectorised over leading
    axes, so a batch of 10^5 links discretises in milliseconds (``B`` (2, 2) or batched like ``A``; ``dt_s`` a
    scalar or one per link). ``A`` must be invertible
    (true for the link: det A = omega_n^2 > 0).

    Accuracy (tests/test_physics_properties.py, against a 40-digit matrix exponential): real poles take the slow
    one as ``det / (s - q)``, not ``s + q`` (a difference of two numbers ~1e9 apart for a stiff link), and ``sinh(qt)``
    directly below ``qt = 1`` (``(e^{(s+q)t} - e^{(s-q)t}) / 2`` cancels there). Bd: where ``||A dt|| < 0.1``,
    ``Bd = dt (I + A dt / 2 + ...) B`` by its series (``A^{-1} (Ad - I)`` lost ~eps / ||A dt|| of it); real poles
    with ``qt >= 1`` or ``2q >= |l_slow|`` take ``Bd = sum_k expm1(l_k dt) / l_k P_k B`` with the projectors
    ``P_k = (A - l_other I) / (l_k - l_other)`` (``A^{-1} (Ad - I)`` cancels in the slow direction when
    ``|l_slow dt|`` is tiny but ``||A dt||`` large: 2.9e-4 of a Bd column off at L1 1 H, L2 1 nH, k 1e-3, R1 1 uOhm,
    R2 100 Ohm, 10 kHz, dt 0.1 us, 2.6e-2 at 2.5 ns). Measured over ``LINK_PARAM_RANGES`` (its 64 corners and 600
    log-uniform links, dt 1 ns..1 s): worst Bd column 4.9e-9 relative (was 6.9e-2; 1.9e-11 at dt 0.1 us..10 ms),
    worst Ad entry 2e-7 absolute (the phase q dt of a 30 MHz link over 0.5 s, eps q dt).
    Table I's links at the rectifier period (||A dt|| ~ 0.5, complex poles) take neither branch: their Ad, Bd
    are the same to the bit.
    """
    a = np.asarray(a, dtype=float)
    s = 0.5 * (a[..., 0, 0] + a[..., 1, 1])
    det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    q2 = s * s - det
    qa = np.sqrt(np.abs(q2))
    qt = qa * dt_s
    osc = q2 < 0
    small = qt < 1e-8
    e = np.exp(s * dt_s)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        # real poles s -/+ q: e^{st} cosh(qt) = (e^{(s+q)t} + e^{(s-q)t})/2, no overflow for long steps; the slow
        # pole s + q as det / (s - q) (Vieta) when s < 0, free of the cancellation of s + q (computed once: the
        # projectors' branch below takes it too)
        vieta = det / (s - qa)
        slow = np.where(s < 0, vieta, s + qa)
        ep, em = np.exp(slow * dt_s), np.exp((s - qa) * dt_s)
        short = qt < 1.0
        c = np.where(osc, e * np.cos(qt), np.where(short, e * np.cosh(qt), 0.5 * (ep + em)))
        sq = np.where(small, e * dt_s, np.where(osc, e * np.sin(qt), np.where(short, e * np.sinh(qt), 0.5 * (ep - em)))
                      / np.where(small, 1.0, qa))
    eye = np.eye(2)
    ad = c[..., None, None] * eye + sq[..., None, None] * (a - s[..., None, None] * eye)
    # A^{-1} for 2x2
    ainv = np.empty_like(a)
    ainv[..., 0, 0] = a[..., 1, 1]
    ainv[..., 1, 1] = a[..., 0, 0]
    ainv[..., 0, 1] = -a[..., 0, 1]
    ainv[..., 1, 0] = -a[..., 1, 0]
    ainv /= det[..., None, None]
    bd = ainv @ (ad - eye) @ b
    dt = np.asarray(dt_s, dtype=float)[..., None, None]    # a step per link, or one for all
    adt = a * dt
    tiny = np.max(np.abs(adt), axis=(-2, -1)) < _SERIES_MAX
    if np.any(tiny):   # int_0^dt e^{As} ds = dt sum_n (A dt)^n / (n+1)!, n <= 11: truncation < 0.1^12 / 13! ~ 2e-22
        at = adt[tiny]
        phi = eye + at / 12.0
        for n in range(11, 1, -1):
            phi = eye + (at @ phi) / n
        bd[tiny] = np.broadcast_to(dt, tiny.shape + (1, 1))[tiny] * (phi @ _rows(b, bd.shape, tiny))
    # real poles, well separated (qt >= 1, or 2q >= |slow pole|: the projectors' cancellation ~eps ||A|| / 2q is then
    # below A^-1 (Ad - I)'s ~eps ||A|| / |slow pole|): Bd = sum_k expm1(l_k dt) / l_k P_k B
    with np.errstate(invalid="ignore"):
        spec = (q2 > 0) & ~tiny & ((qt >= 1.0) | (2.0 * qa >= np.abs(vieta)))
    if np.any(spec):
        bd[spec] = _real_pole_phi(np.broadcast_to(a, spec.shape + (2, 2))[spec], (s - qa)[spec], vieta[spec],
                                  np.broadcast_to(np.asarray(dt_s, dtype=float), spec.shape)[spec]
                                  ) @ _rows(b, bd.shape, spec)
    return ad, bd


def _rows(b, shape, mask):
    """``b`` (2, 2), or batched like A: its matrices where ``mask`` is set (a 2x2 ``b`` as it is: the same
    matmul, the same bits)."""
    b = np.asarray(b, dtype=float)
    return b if b.ndim == 2 else np.broadcast_to(b, shape)[mask]


def _real_pole_phi(a, l2, l1, dt):
    """``int_0^dt e^{As} ds = sum_k expm1(l_k dt) / l_k P_k`` for 2x2 ``a`` (N, 2, 2) with real poles ``l2`` (the
    fast one, s - q) and ``l1`` (the slow one, ``det / l2`` by Vieta: :func:`zoh_discretise`'s); ``P_k = (A - l_other
    I) / (l_k - l_other)`` with the cancelling diagonal entry taken from ``(a00 - l)(a11 - l) = a01 a10``."""
    prod = a[:, 0, 1] * a[:, 1, 0]

    def proj(lo, den):   # (A - lo I) / den; the smaller diagonal entry from (a00 - lo)(a11 - lo) = a01 a10
        d0, d1 = a[:, 0, 0] - lo, a[:, 1, 1] - lo
        big0 = np.abs(d0) >= np.abs(d1)
        d0, d1 = np.where(big0, d0, prod / d1), np.where(big0, prod / d0, d1)
        pm = a.copy()
        pm[:, 0, 0], pm[:, 1, 1] = d0, d1
        return pm / den[:, None, None]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):   # np.where evaluates both sides
        return ((np.expm1(l1 * dt) / l1)[:, None, None] * proj(l2, l1 - l2)
                + (np.expm1(l2 * dt) / l2)[:, None, None] * proj(l1, l2 - l1))


class EnvelopeLink:
    """A batch of ``n`` independent envelope-model links stepped by exact ZOH.

    The discretisation is cached and recomputed only when ``lm_h`` or ``dt_s`` changes (the
    closed form of :func:`zoh_discretise`, vectorised: cheap even when Lm moves every step).

    The hot loop runs in modal coordinates: the link's two poles are a complex pair
    ``lambda = -zeta wn +/- j wd`` (true for any Lm above a few nH with Table I), so the state is
    ``x = 2 Re(z v)`` with one complex mode ``z`` per link, and a ZOH step is the exact recursion
    ``z <- e^{lambda dt} z + g1 V1 + g2 V2``: four numpy operations per step for the whole batch.
    Batches with a non-oscillatory link (real poles) fall back to the real 2x2 recursion.

    Parameters
    ----------
    params : LinkParams
        Common link parameters; ``lm_h`` can differ per link through :meth:`step`.
    n : int
        Batch size.

    Notes
    -----
    ``x``, ``i1``, ``i2`` are computed from the modal state: they are copies. Set the state by
    assigning ``link.x = values`` (shape (n, 2)), :meth:`set_state` (optionally for a mask) or
    :meth:`set_steady_state`.
    """

    def __init__(self, params: LinkParams, n: int = 1):
        if int(n) < 1:
            raise ValueError(f"n={n!r} is invalid; valid range: n >= 1")
        self.params = params
        self.n = int(n)
        self._xt = np.zeros((2, self.n))  # real state (real mode) rows I1, I2
        self._z = None                    # complex modal state (modal mode)
        self._dt = None                   # step of the cached discretisation
        self._lm = np.full(self.n, params.lm_h)  # current mutual inductance per link [H]
        self._ad = self._bd = None

    # ------------------------------------------------------------------ state access
    @property
    def x(self) -> np.ndarray:
        """State ``[I1, I2]`` per link [A], shape (n, 2) (a copy)."""
        return self._real().T.copy()

    @x.setter
    def x(self, value) -> None:
        self.set_state(value)

    @property
    def i1(self) -> np.ndarray:
        """Primary current amplitude I1 [A], shape (n,) (a copy)."""
        if self._z is None:
            return self._xt[0].copy()
        return 2.0 * self._v0 * self._z.real

    @property
    def i2(self) -> np.ndarray:
        """Secondary current amplitude I2 [A], shape (n,) (a copy)."""
        if self._z is None:
            return self._xt[1].copy()
        z = self._z
        return 2.0 * (z.real * self._v1.real - z.imag * self._v1.imag)

    def _real(self) -> np.ndarray:
        if self._z is not None:
            self._xt[0] = self.i1
            self._xt[1] = self.i2
        return self._xt

    def set_state(self, x, mask=None) -> None:
        """Set ``[I1, I2]`` (shape (n, 2) or (2,)) for all links, or for ``mask`` (bool (n,)) only."""
        new = np.broadcast_to(np.asarray(x, dtype=float), (self.n, 2)).T
        if self._z is None:
            if mask is None:
                self._xt[...] = new
            else:
                self._xt[:, mask] = new[:, mask]
        elif mask is None:
            self._z = self._u0 * new[0] + self._u1 * new[1]
        else:
            self._z[mask] = self._u0[mask] * new[0, mask] + self._u1[mask] * new[1, mask]

    def set_steady_state(self, v2_v, lm_h=None, v1_v=None, mask=None) -> None:
        """Put every link (or those in ``mask``) at its closed-form steady state for the given inputs."""
        i1, i2 = steady_state(self.params, v2_v, lm_h, v1_v)
        x = np.empty((self.n, 2))
        x[:, 0] = i1
        x[:, 1] = i2
        self.set_state(x, mask)

    # ------------------------------------------------------------------ discretisation
    @property
    def lm_h(self) -> np.ndarray:
        """Current mutual inductance per link [H] (a copy)."""
        return self._lm.copy()

    def discretisation(self, dt_s: float, lm_h=None):
        """``(Ad, Bd)`` for the batch at step ``dt_s``, shapes (n, 2, 2) (cached)."""
        self._update(dt_s, lm_h)
        return self._ad, self._bd

    def _update(self, dt_s, lm_h):
        if lm_h is None:
            if dt_s == self._dt:
                return
            lm = self._lm
        else:
            lm = np.broadcast_to(np.asarray(lm_h, dtype=float), (self.n,))
            if dt_s == self._dt and np.array_equal(lm, self._lm):
                return
        if not np.isfinite(dt_s) or dt_s <= 0:
            raise ValueError(f"dt_s={dt_s!r} is invalid; valid range: (0, inf)")
        check_lm(self.params, lm)
        self._dt, self._lm = float(dt_s), lm.copy()
        xt = self._real()
        a, b = state_matrices(self.params, lm)
        self._ad, self._bd = zoh_discretise(a, b, dt_s)
        s = 0.5 * (a[:, 0, 0] + a[:, 1, 1])
        det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
        if np.all(det - s * s > 0):
            # modal form: right eigenvector v = [a01, lam - a00], left u = [lam - a11, a01] / (u.v)
            lam = s + 1j * np.sqrt(det - s * s)
            a01 = a[:, 0, 1]
            uv = a01 * (2.0 * lam - a[:, 0, 0] - a[:, 1, 1])
            self._v0 = a01
            self._v1 = lam - a[:, 0, 0]
            self._u0 = (lam - a[:, 1, 1]) / uv
            self._u1 = a01 / uv
            self._lamd = np.exp(lam * dt_s)
            phi = (self._lamd - 1.0) / lam
            self._g1 = phi * self._u0 * b[0, 0]
            self._g2 = phi * self._u1 * b[1, 1]
            self._g1v1 = self._g1 * self.params.v1_amp_v
            self._z = self._u0 * xt[0] + self._u1 * xt[1]
        else:
            self._z = None
            # structure of arrays for the real recursion: 8 contiguous coefficient vectors
            self._c = [np.ascontiguousarray(m[:, i, j]) for m in (self._ad, self._bd) for i in (0, 1) for j in (0, 1)]

    # ------------------------------------------------------------------ stepping
    def step(self, v2_v, dt_s: float, lm_h=None, v1_v=None) -> None:
        """Advance all links by ``dt_s`` with V2 (and V1) held constant (exact ZOH).

        ``v2_v``, ``v1_v``, ``lm_h`` are scalars or arrays of shape (n,). V1 defaults to
        ``(4/pi) Vdc``; ``lm_h=None`` keeps the current coupling (initially ``params.lm_h``),
        which skips even the comparison of Lm arrays. The discretisation is reused while
        ``dt_s`` and Lm are unchanged. Read the result through ``i1``, ``i2`` or ``x``.
        """
        self._update(dt_s, lm_h)
        z = self._z
        if z is not None:
            z *= self._lamd
            z += self._g2 * v2_v
            z += self._g1v1 if v1_v is None else self._g1 * v1_v
            return
        a00, a01, a10, a11, b00, b01, b10, b11 = self._c
        v1 = self.params.v1_amp_v if v1_v is None else v1_v
        x0, x1 = self._xt
        n0 = a00 * x0
        n0 += a01 * x1
        n0 += b00 * v1
        n0 += b01 * v2_v
        x1 *= a11
        x1 += a10 * x0
        x1 += b10 * v1
        x1 += b11 * v2_v
        x0[...] = n0


def simulate(params: LinkParams, v2_v, dt_s: float, x0=None, lm_h=None, v1_v=None):
    """Simulate one link (eq. 4, the fundamental envelope) for a V2 sequence held over steps of ``dt_s``.

    ``v2_v``: the rectifier's fundamental amplitudes [V], one per step (zero-order hold, exact discretisation);
    ``dt_s`` [s]; ``lm_h`` [H] replaces ``params.lm_h`` for the run, ``v1_v`` [V] the inverter's fundamental
    amplitude (default ``params.v1_amp_v``, (4/pi) Vdc). Returns ``(t_s, i1_a, i2_a)`` [s, A, A] of length
    ``len(v2_v) + 1`` (the initial state first). ``x0``: the (I1, I2) amplitudes [A] at t = 0, default the
    closed-form steady state for ``v2_v[0]`` (:func:`steady_state`).
    """
    v2 = np.asarray(v2_v, dtype=float)
    check_v2(v2, sequence=True)
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s={dt_s!r} is invalid; valid range: (0, inf) s")
    if lm_h is not None:
        if np.ndim(lm_h):   # (one Lm for the run)
            raise ValueError(f"lm_h of shape {np.shape(lm_h)} is invalid; valid: one number [H]")
        check_lm(params, lm_h)
    a, b = state_matrices(params, lm_h)
    ad, bd = zoh_discretise(a, b, dt_s)
    v1 = params.v1_amp_v if v1_v is None else check_v1(v1_v)
    if x0 is None:
        x0 = steady_state(params, v2[0], lm_h, v1)
    elif np.shape(x0) != (2,) or not np.all(np.isfinite(x0)):   # was numpy's "could not broadcast" or a NaN run
        raise ValueError(f"x0={np.asarray(x0).tolist()!r} is invalid; valid: the (I1, I2) amplitudes [A], shape (2,), "
                         "finite")
    x = np.empty((len(v2) + 1, 2))
    x[0] = x0
    # linear recursion; inputs precomputed
    bu = np.outer(np.full(len(v2), v1), bd[:, 0]) + np.outer(v2, bd[:, 1])
    xk = np.asarray(x0, dtype=float)
    for k in range(len(v2)):
        xk = ad @ xk + bu[k]
        x[k + 1] = xk
    t = np.arange(len(v2) + 1) * dt_s
    return t, x[:, 0], x[:, 1]


# ============================================================================ complex envelope (detuning)
def complex_envelope_matrices(p: LinkParams, c1_f: float | None = None, c2_f: float | None = None,
                              cross: bool = True):
    """Complex envelope model with detuned series capacitors: ``dX/dt = A X + B [V1, -V2c]``.

    ``X = [J1, J2]`` with ``i1 = Im(J1 e^{jwt})`` and ``i2 = Im(J2 e^{jwt})``: ``Re J1`` is eq. 4's
    I1 (the sin component), ``Im J2`` its I2 (the cos component); the other parts are the
    quadrature components a detuned link develops. From eq. 1 with ``d/dt -> D + jw`` and the
    capacitor ``1/(C (D + jw)) ~ (1/(jwC))(1 - D/(jw))``::

        (L1 + 1/(w^2 C1)) D J1 + (R1 + j X1) J1 - Lm (D + jw) J2 = V1
        -Lm (D + jw) J1 + (L2 + 1/(w^2 C2)) D J2 + (R2 + j X2) J2 = -V2c

    with ``Xk = w Lk - 1/(w Ck)``. At resonance and with ``cross=False`` (no ``Lm D`` terms) this
    is eq. 4 exactly; ``cross=True`` keeps them, which moves the two coupled modes to
    ``+-j w k / (2 -+ k)`` from the drive (the exact ones sit at ``w/sqrt(1 -+ k)``: the same to
    first order in k, much closer than eq. 4's symmetric ``+-w k / 2``). ``V2c`` is the complex
    fundamental of v2 (``j f(d)`` when in phase with a cos-phased i2). Returns complex (A, B)."""
    w = p.omega_rad_s
    c1 = 1.0 / (w * w * p.l1_h) if c1_f is None else float(c1_f)
    c2 = 1.0 / (w * w * p.l2_h) if c2_f is None else float(c2_f)
    for name, c in (("c1_f", c1), ("c2_f", c2)):   # 0 raised ZeroDivisionError, NaN gave NaN currents
        if not (math.isfinite(c) and c > 0):
            raise ValueError(f"{name}={c!r} is invalid; valid range: (0, inf) F or None (resonant)")
    lm_d = p.lm_h if cross else 0.0
    m = np.array([[p.l1_h + 1.0 / (w * w * c1), -lm_d], [-lm_d, p.l2_h + 1.0 / (w * w * c2)]], dtype=complex)
    z = np.array([[p.r1_ohm + 1j * (w * p.l1_h - 1.0 / (w * c1)), -1j * w * p.lm_h],
                  [-1j * w * p.lm_h, p.r2_ohm + 1j * (w * p.l2_h - 1.0 / (w * c2))]])
    minv = np.linalg.inv(m)
    return -minv @ z, minv


def _complex_steady(a, b, v1, v2_amp):
    """Steady X with V2c in phase with i2 (fixed point on the phase of J2)."""
    x = np.zeros(2, dtype=complex)
    ph = 1j
    for _ in range(50):
        x = np.linalg.solve(-a, b @ np.array([v1, -v2_amp * ph]))
        new = x[1] / abs(x[1]) if abs(x[1]) > 0 else 1j
        if abs(new - ph) < 1e-14:
            break
        ph = new
    return x


def simulate_complex(p: LinkParams, v2_amp_v, dt_s: float, c1_f=None, c2_f=None, cross: bool = True, x0=None):
    """Complex envelope run for a V2 magnitude sequence held over steps of ``dt_s`` (the SBAR's V2
    stays in phase with the instantaneous i2, so its phase follows J2 from step to step).

    Returns ``(t_s, j1, j2)`` complex amplitudes (``|j2|`` is the I2 envelope). ``x0`` defaults to
    the steady state of the first V2."""
    from scipy.linalg import expm
    v2 = np.asarray(v2_amp_v, dtype=float)
    a, b = complex_envelope_matrices(p, c1_f, c2_f, cross)
    ad = expm(a * dt_s)
    bd = np.linalg.solve(a, (ad - np.eye(2)) @ b)
    x = _complex_steady(a, b, p.v1_amp_v, v2[0]) if x0 is None else np.asarray(x0, dtype=complex)
    out = np.empty((len(v2) + 1, 2), dtype=complex)
    out[0] = x
    for k in range(len(v2)):
        ph = x[1] / abs(x[1]) if abs(x[1]) > 0 else 1j
        x = ad @ x + bd @ np.array([p.v1_amp_v, -v2[k] * ph])
        out[k + 1] = x
    return np.arange(len(v2) + 1) * dt_s, out[:, 0], out[:, 1]
