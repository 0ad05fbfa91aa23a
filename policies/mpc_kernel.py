"""The MPC's ripple-excess lookups compiled (numba, ``cache=True``): one pass over the plans, no temporaries.

:meth:`policies.mpc.MPCPolicy._excess` linearises the SBAR's ripple excess at the short-mode current along a
V2 plan: the excess at the plan and at +- 0.5 V (clipped into the box), and the slope between them. In numpy
that was nine array passes over ``(3, n, N_PRED)`` temporaries (the duty from V2, eq. 9 inverted: an
``arcsin``; two ``np.interp`` of the fold's two curves) per QP batch, ~18 % of the MPC's CPU. Here it is one
loop with the same arithmetic in the same order, so the same bits:

* the duty: ``(2/pi) arcsin(min(max(1 - V2 / ((4/pi) (VL + Vf)), 0), 1))``
  (:func:`wpt_receiver.duty_from_v2_clipped`);
* the lookup: numpy's ``interp`` (its C loop: the interval ``xp[j] <= x < xp[j + 1]`` found by search,
  ``fp[j]`` where ``x`` is a grid point or at the right end, else ``slope_j (x - xp[j]) + fp[j]`` with
  ``slope_j = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])``), of the fold's ``A`` and ``B`` curves, combined
  as ``A(d) + (VL - 31 V) B(d)`` (:func:`envs.peaks.fold_vl`);
* the slope: ``max((e(hi) - e(lo)) / max(hi - lo, 1e-9), 0)``.

The constants (4/pi, 2/pi, the fold's 31 V, the duty grid and curves) are arguments, so this module depends on
no other module's source (its numba cache stays valid by itself). ``tests/test_mpc_kernel.py`` checks the
kernel against the numpy expressions bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["excess_rows", "excess_slope_rows"]


@njit(cache=True)
def _interp(x, xp, fp, slopes):
    """numpy's ``interp(x, xp, fp)`` of one value (default left/right: ``fp[0]``, ``fp[-1]``)."""
    n = xp.size
    if x > xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    j = np.searchsorted(xp, x, side="right") - 1   # xp[j] <= x < xp[j + 1] (j = n - 1 at the right end)
    if j == n - 1 or xp[j] == x:
        return fp[j]
    r = slopes[j] * (x - xp[j]) + fp[j]
    if math.isnan(r):   # numpy's other direction (not reached with finite data)
        r = slopes[j] * (x - xp[j + 1]) + fp[j + 1]
        if math.isnan(r) and fp[j] == fp[j + 1]:
            r = fp[j]
    return r


@njit(cache=True)
def _excess_one(v, den, vlc, c2, grid, a, b, sa, sb):
    """The excess [A] at V2 ``v`` [V]: ``den`` = (4/pi)(VL + Vf), ``vlc`` = VL - 31 V, ``c2`` = 2/pi."""
    s = 1.0 - v / den
    if not s >= 0.0:   # np.maximum(s, 0.0)
        s = 0.0
    if not s <= 1.0:   # np.minimum(s, 1.0)
        s = 1.0
    d = c2 * math.asin(s)
    return _interp(d, grid, a, sa) + vlc * _interp(d, grid, b, sb)


@njit(cache=True)
def excess_rows(v2, vl, vf, four_over_pi, c2, vl_fold, grid, a, b, sa, sb):
    """The excess (n, N) [A] at the V2 ``v2`` (n, N) [V], the battery voltages ``vl`` (n,) [V], forward drop ``vf``."""
    n, m = v2.shape
    out = np.empty((n, m))
    for i in range(n):
        den = four_over_pi * (vl[i] + vf)
        vlc = vl[i] - vl_fold
        for k in range(m):
            out[i, k] = _excess_one(v2[i, k], den, vlc, c2, grid, a, b, sa, sb)
    return out


@njit(cache=True)
def excess_slope_rows(v2, vl, vf, h, c4, four_over_pi, c2, vl_fold, grid, a, b, sa, sb):
    """The excess (n, N) [A] at ``v2`` (n, N) [V] and its slope [A/V] between ``min(v2 + h, vmax)`` and
    ``max(v2 - h, 0)`` (``vmax = c4 (VL + Vf)``, ``c4`` = 4/pi), clipped at 0."""
    n, m = v2.shape
    ex = np.empty((n, m))
    slope = np.empty((n, m))
    for i in range(n):
        vc = vl[i] + vf
        vmax = c4 * vc
        den = four_over_pi * vc
        vlc = vl[i] - vl_fold
        for k in range(m):
            v = v2[i, k]
            hi = v + h
            if not hi <= vmax:   # np.minimum(v2 + h, vmax)
                hi = vmax
            lo = v - h
            if not lo >= 0.0:    # np.maximum(v2 - h, 0.0)
                lo = 0.0
            ex[i, k] = _excess_one(v, den, vlc, c2, grid, a, b, sa, sb)
            e_hi = _excess_one(hi, den, vlc, c2, grid, a, b, sa, sb)
            e_lo = _excess_one(lo, den, vlc, c2, grid, a, b, sa, sb)
            w = hi - lo
            if not w >= 1e-9:    # np.maximum(hi - lo, 1e-9)
                w = 1e-9
            s = (e_hi - e_lo) / w
            if not s >= 0.0:     # np.maximum(slope, 0.0)
                s = 0.0
            slope[i, k] = s
    return ex, slope
