"""Evaluation of a 2-D cubic B-spline (coefficients from ``scipy.ndimage.spline_filter``) in numpy.

``import scipy.ndimage`` costs ~0.3 s (it builds the array-API dispatch of every function), more
than a whole mission; the coupling table only needs the evaluation, so it is written out here
with the operations of ``scipy.ndimage.map_coordinates(coef, ..., order=3, prefilter=False,
mode="mirror")``: the weights of scipy's ``get_spline_interpolation_weights`` (ni_splines.c),
whole-sample mirror indices at the edges, and the 16 products summed in C order (``coef * w_0 *
w_1``, last axis fastest). The tests compare the two on random points, edges included.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cubic_weights", "mirror_index", "map_cubic_mirror"]


def cubic_weights(x):
    """First tap index ``floor(x) - 1`` and the four cubic B-spline weights at coordinates ``x``."""
    f = np.floor(x)
    y = x - f
    z = 1.0 - y
    w1 = (y * y * (y - 2.0) * 3.0 + 4.0) / 6.0
    w2 = (z * z * (z - 2.0) * 3.0 + 4.0) / 6.0
    w0 = z * z * z / 6.0
    w3 = 1.0 - w0 - w1 - w2  # the weights sum to 1 (scipy computes the last one so)
    return f.astype(np.intp) - 1, (w0, w1, w2, w3)


def mirror_index(i, n: int):
    """Indices reflected about the edge samples (``d c b | a b c d | c b a``) into ``[0, n)``."""
    if n <= 1:
        return np.zeros_like(i)
    if i.size and i.min() >= 0 and i.max() < n:  # nothing to reflect (points away from the edges)
        return i
    period = 2 * n - 2
    i = np.abs(i) % period
    return np.where(i >= n, period - i, i)


def map_cubic_mirror(coef, u, v):
    """Cubic B-spline with coefficients ``coef`` (n0, n1) at fractional indices ``(u, v)`` (N,)."""
    coef = np.asarray(coef, dtype=float)
    i0, wu = cubic_weights(np.asarray(u, dtype=float))
    j0, wv = cubic_weights(np.asarray(v, dtype=float))
    n0, n1 = coef.shape
    flat = coef.ravel()
    cols = [mirror_index(j0 + b, n1) for b in range(4)]
    out = np.zeros(i0.shape)
    tmp = np.empty(i0.shape)
    idx = np.empty(i0.shape, dtype=np.intp)
    for a in range(4):
        row = mirror_index(i0 + a, n0) * n1
        for b in range(4):
            np.add(row, cols[b], out=idx)
            flat.take(idx, out=tmp)
            tmp *= wu[a]   # (coef * w_a) * w_b, summed in C order: scipy's operations
            tmp *= wv[b]
            out += tmp
    return out
