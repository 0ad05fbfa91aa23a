""":meth:`CouplingModel.lm_h <.coupling.CouplingModel.lm_h>` from the tabulated field, compiled with numba (``cache=True``).

The same operations as the numpy path of :mod:`.coupling` (``_flux`` with ``_a_table``) and
:mod:`.bspline` (``map_cubic_mirror``), point by point: receiver points in the pad frame, the
cubic B-spline of ``A_phi / rho`` (16 products summed in scipy's order, mirrored edges), the
loop integrand, and the sum over the receiver's points in numpy's pairwise order (``np.sum`` of
a row), so the result is the numpy path's
to the last bit up to libm's ``hypot`` (the tests compare the two). Points below the table
(``z < z_min``, the exact field) are not handled here: :func:`flux_table` reports them and the
caller uses the numpy path.

This module imports numba at import time; :meth:`CouplingModel.lm_h` imports it only when asked
for the compiled path (``compiled=True``, e.g. by the mission runner's fast path).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["flux_table", "pairwise_sum"]


@njit(cache=True)
def _block_sum(a, lo, n):
    """numpy's ``pairwise_sum_DOUBLE`` for ``n <= 128``: 8 accumulators, then the rest in order."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def pairwise_sum(a, lo, n):
    """numpy's pairwise summation of ``a[lo:lo + n]`` (blocks of <= 128 split at ``n // 2`` rounded down to
    a multiple of 8), with an explicit stack (numba's cache mishandles recursive functions)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    los, ns, stage = np.empty(128, np.int64), np.empty(128, np.int64), np.empty(128, np.int64)
    vals = np.empty(128)
    los[0], ns[0], stage[0] = lo, n, 0
    sp, vp = 1, 0
    while sp > 0:
        sp -= 1
        l, m, st = los[sp], ns[sp], stage[sp]
        if m <= 128:
            vals[vp] = _block_sum(a, l, m)
            vp += 1
        elif st == 0:
            h = m // 2
            h -= h % 8
            los[sp], ns[sp], stage[sp] = l, m, 1          # combine after both halves
            los[sp + 1], ns[sp + 1], stage[sp + 1] = l + h, m - h, 0
            los[sp + 2], ns[sp + 2], stage[sp + 2] = l, h, 0
            sp += 3
        else:
            vals[vp - 2] = vals[vp - 2] + vals[vp - 1]   # left + right (whichever finished first: + commutes)
            vp -= 1
    return vals[0]


@njit(cache=True)
def _mirror(i, n):
    if n <= 1:
        return 0
    if 0 <= i < n:
        return i
    period = 2 * n - 2
    i = abs(i) % period
    return period - i if i >= n else i


@njit(cache=True)
def _weights(x):
    f = math.floor(x)
    y = x - f
    z = 1.0 - y
    w1 = (y * y * (y - 2.0) * 3.0 + 4.0) / 6.0
    w2 = (z * z * (z - 2.0) * 3.0 + 4.0) / 6.0
    w0 = z * z * z / 6.0
    return int(f) - 1, (w0, w1, w2, 1.0 - w0 - w1 - w2)


@njit(cache=True)
def _spline(coef, u, v):
    """``bspline.map_cubic_mirror`` at one point."""
    n0, n1 = coef.shape
    i0, wu = _weights(u)
    j0, wv = _weights(v)
    c0, c1, c2, c3 = _mirror(j0, n1), _mirror(j0 + 1, n1), _mirror(j0 + 2, n1), _mirror(j0 + 3, n1)
    out = 0.0
    for a in range(4):
        row = coef[_mirror(i0 + a, n0)]
        wa = wu[a]
        out += row[c0] * wa * wv[0]
        out += row[c1] * wa * wv[1]
        out += row[c2] * wa * wv[2]
        out += row[c3] * wa * wv[3]
    return out


@njit(cache=True)
def flux_table(coef, h, z0, rho_last, z_last, rot, org, pts, tan, w):
    """Lm [H] of each pose (``rot`` (N, 3, 3), ``org`` (N, 3)) over the receiver points ``pts``,
    tangents ``tan`` (P, 3) with weight ``w``; returns ``(lm, n_below)`` (``n_below`` > 0: some
    points were below the table and ``lm`` is not valid)."""
    n, m = org.shape[0], pts.shape[0]
    out = np.empty(n)
    prod = np.empty(m)
    for p in range(n):
        r = rot[p]
        o = org[p]
        for q in range(m):
            px, py, pz = pts[q, 0], pts[q, 1], pts[q, 2]
            x = r[0, 0] * px + r[0, 1] * py + r[0, 2] * pz + o[0]
            y = r[1, 0] * px + r[1, 1] * py + r[1, 2] * pz + o[1]
            z = r[2, 0] * px + r[2, 1] * py + r[2, 2] * pz + o[2]
            tx = r[0, 0] * tan[q, 0] + r[0, 1] * tan[q, 1]
            ty = r[1, 0] * tan[q, 0] + r[1, 1] * tan[q, 1]
            rho = math.hypot(x, y)
            if z < z0:
                return out, 1
            f = 0.0
            if rho <= rho_last and z <= z_last:
                f = _spline(coef, rho / h, (z - z0) / h)
            prod[q] = f * (x * ty - y * tx)
        out[p] = w * pairwise_sum(prod, 0, m)
    return out, 0
