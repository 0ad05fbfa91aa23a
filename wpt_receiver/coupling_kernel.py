"""The coupling table's lookup, Lm(pose) from the tabulated pad field: the one implementation (numba, ``cache=True``).

:meth:`CouplingModel.lm_h <.coupling.CouplingModel.lm_h>` keeps the orchestration (poses to rotation
matrices, shapes, the table's disk cache, the exact field below the table); every formula of the
lookup is written once, here:

* :func:`_point`: a receiver quadrature point and its tangent ``dl/dtheta`` in the pad frame
  (``x = R p + o``, ``t = R t_local``; the local tangents have no z component);
* :func:`_weights` / :func:`_mirror` / :func:`_spline`: the cubic B-spline of ``A_phi / rho`` with
  coefficients from ``scipy.ndimage.spline_filter(order=3, mode="mirror")``, evaluated as
  ``scipy.ndimage.map_coordinates(..., order=3, prefilter=False, mode="mirror")`` does (scipy's
  ``get_spline_interpolation_weights``, whole-sample mirror indices at the edges), so no
  ``scipy.ndimage`` import (~0.3 s) is needed at run time;
* :func:`_field`: the table's value at ``(rho, z)``: 0 beyond ``rho_max``/``z_max`` (uncoupled);
* :func:`_integrand`: the loop integrand ``A . dl / dtheta = (A_phi / rho) (x t_y - y t_x)``;

composed by :func:`flux_table` (the fast path, one pose per outer iteration) and exposed point-wise
(:func:`receiver_points`, :func:`table_field`, :func:`loop_sum`) for the poses whose receiver dips
below the table, where the caller puts the exact (elliptic-integral) field at those points, and for
:meth:`~.coupling.CouplingModel.lm_exact_h`. Each public kernel's ``.py_func`` runs the same source
in the interpreter (slow; the tests use it on a few points).

Imported lazily by :mod:`.coupling` (numba's import costs ~0.3 s), on the first ``lm_h``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["flux_table", "receiver_points", "table_field", "loop_sum"]


@njit(cache=True)
def _mirror(i, n):
    """Index ``i`` reflected about the edge samples (``d c b | a b c d | c b a``) into ``[0, n)``."""
    if n <= 1:
        return 0
    if 0 <= i < n:
        return i
    period = 2 * n - 2
    i = abs(i) % period
    return period - i if i >= n else i


@njit(cache=True)
def _weights(x):
    """First tap ``floor(x) - 1`` and the four cubic B-spline weights at ``x`` (the last one makes the sum 1)."""
    f = math.floor(x)
    y = x - f
    z = 1.0 - y
    w1 = (y * y * (y - 2.0) * 3.0 + 4.0) / 6.0
    w2 = (z * z * (z - 2.0) * 3.0 + 4.0) / 6.0
    w0 = z * z * z / 6.0
    return int(f) - 1, (w0, w1, w2, 1.0 - w0 - w1 - w2)


@njit(cache=True)
def _spline(coef, u, v):
    """The cubic B-spline with coefficients ``coef`` (n0, n1) at fractional indices ``(u, v)``."""
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
def _field(coef, h, z0, rho_last, z_last, rho, z):
    """Tabulated ``A_phi / rho`` [H/m^2 per A] at ``(rho, z)`` (pad frame, ``z >= z0``); 0 beyond the table."""
    if rho <= rho_last and z <= z_last:
        return _spline(coef, rho / h, (z - z0) / h)
    return 0.0


@njit(cache=True)
def _point(r, o, pts, tan, q):
    """Receiver point ``q`` and its tangent in the pad frame: ``(x, y, z, t_x, t_y)`` [m, m/rad]."""
    px, py, pz = pts[q, 0], pts[q, 1], pts[q, 2]
    x = r[0, 0] * px + r[0, 1] * py + r[0, 2] * pz + o[0]
    y = r[1, 0] * px + r[1, 1] * py + r[1, 2] * pz + o[1]
    z = r[2, 0] * px + r[2, 1] * py + r[2, 2] * pz + o[2]
    tx = r[0, 0] * tan[q, 0] + r[0, 1] * tan[q, 1]
    ty = r[1, 0] * tan[q, 0] + r[1, 1] * tan[q, 1]
    return x, y, z, tx, ty


@njit(cache=True)
def _integrand(f, x, y, tx, ty):
    """``A . dl/dtheta = (A_phi / rho) (x t_y - y t_x)`` for the field value ``f = A_phi / rho``."""
    return f * (x * ty - y * tx)


@njit(cache=True)
def flux_table(coef, h, z0, rho_last, z_last, rot, org, pts, tan, w):
    """Lm [H] of each pose (``rot`` (N, 3, 3), ``org`` (N, 3)) from the table: the trapezoid rule
    ``w sum_q A . dl/dtheta`` over the receiver points ``pts``, tangents ``tan`` (P, 3).

    ``coef`` are the spline coefficients on the grid ``rho = i h``, ``z = z0 + j h`` (last
    samples ``rho_last``, ``z_last``). Returns ``(lm, below)``: ``below[p]`` is True where a
    point of pose ``p`` lies below the table (``z < z0``); ``lm[p]`` is NaN there (the caller
    evaluates those poses with the exact field, :func:`receiver_points` .. :func:`loop_sum`).
    """
    n, m = org.shape[0], pts.shape[0]
    out = np.empty(n)
    below = np.zeros(n, np.bool_)
    for p in range(n):
        r, o = rot[p], org[p]
        acc = 0.0
        for q in range(m):
            x, y, z, tx, ty = _point(r, o, pts, tan, q)
            if z < z0:
                below[p] = True
                break
            acc += _integrand(_field(coef, h, z0, rho_last, z_last, math.hypot(x, y), z), x, y, tx, ty)
        out[p] = np.nan if below[p] else w * acc
    return out, below


@njit(cache=True)
def receiver_points(rot, org, pts, tan):
    """``(x, y, z, t_x, t_y)``, each (N, P): the receiver points and tangents of each pose in the pad frame."""
    n, m = org.shape[0], pts.shape[0]
    x, y, z, tx, ty = np.empty((n, m)), np.empty((n, m)), np.empty((n, m)), np.empty((n, m)), np.empty((n, m))
    for p in range(n):
        r, o = rot[p], org[p]
        for q in range(m):
            x[p, q], y[p, q], z[p, q], tx[p, q], ty[p, q] = _point(r, o, pts, tan, q)
    return x, y, z, tx, ty


@njit(cache=True)
def table_field(coef, h, z0, rho_last, z_last, rho, z):
    """:func:`_field` at the points ``(rho, z)`` (1-D); NaN below the table (``z < z0``: no table there)."""
    out = np.empty(rho.shape[0])
    for i in range(rho.shape[0]):
        out[i] = np.nan if z[i] < z0 else _field(coef, h, z0, rho_last, z_last, rho[i], z[i])
    return out


@njit(cache=True)
def loop_sum(f, x, y, tx, ty, w):
    """Lm [H] per pose: ``w sum_q A . dl/dtheta`` from the field ``f = A_phi / rho`` at the points (all (N, P))."""
    n, m = f.shape
    out = np.empty(n)
    for p in range(n):
        acc = 0.0
        for q in range(m):
            acc += _integrand(f[p, q], x[p, q], y[p, q], tx[p, q], ty[p, q])
        out[p] = w * acc
    return out
