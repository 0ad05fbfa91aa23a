"""Small single-input single-output LTI helpers that do not import :mod:`scipy.signal`.

``import scipy.signal`` costs about 1.2 s (it decorates every function for the array API), more
than a whole default mission. The controller (Fig. 5) and the wind hold loop only need a
transfer function in controller canonical form, its zero-order-hold discretisation and a
direct-form-II-transposed filter; these follow scipy's own algorithms step by step
(``normalize``, ``tf2ss``, ``cont2discrete(method="zoh")``, ``ss2tf``, ``lfilter`` with zero
initial state) so the results are bit-identical (tests/test_lti.py compares them).
"""

from __future__ import annotations

import numpy as np

from .diskcache import load as _cache_load, store as _cache_store

__all__ = ["normalize_tf", "tf2ss", "zoh_ss", "zoh_tf", "ss2tf", "lfilter"]


def normalize_tf(num, den):
    """``(num, den)`` divided by the leading denominator coefficient, leading zeros trimmed (1-D)."""
    num = np.atleast_1d(np.asarray(num, dtype=float))
    den = np.trim_zeros(np.atleast_1d(np.asarray(den, dtype=float)), "f")
    if den.size == 0:
        raise ValueError("den is invalid; valid: at least one nonzero coefficient")
    num, den = num / den[0], den / den[0]
    lead = int(np.argmax(np.abs(num) > 1e-14)) if np.any(np.abs(num) > 1e-14) else num.size - 1
    return num[lead:], den


def tf2ss(num, den):
    """``(A, B, C, D)`` of ``num(s)/den(s)`` in controller canonical form (scipy's ``tf2ss``)."""
    num, den = normalize_tf(num, den)
    m, k = num.size, den.size
    if m > k:
        raise ValueError(f"len(num)={m} > len(den)={k}: improper transfer function")
    num = np.hstack((np.zeros(k - m), num))[None, :]
    d = np.atleast_2d(num[:, 0])
    if k == 1:
        return np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), d.reshape(1, 1)
    a = np.r_[-np.array([den[1:]]), np.eye(k - 2, k - 1)]
    b = np.eye(k - 1, 1)
    c = num[:, 1:] - np.outer(num[:, 0], den[1:])
    return a, b, c, d.reshape((1, 1))


def zoh_ss(a, b, dt_s: float):
    """``(Ad, Bd)`` of ``x' = A x + B u`` under a zero-order hold of ``dt_s`` [s] (block expm).

    The result goes through the disk cache (:mod:`wpt_receiver.diskcache`, keyed by the exact bits of
    ``A``, ``B``, ``dt_s`` and the scipy version): ``import scipy.linalg`` costs 0.2-0.3 s, more
    than the mission it would serve, and the controller and the wind hold loop ask for the same few
    matrices every run. A cached result is the same array scipy computed."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n, m = a.shape[0], b.shape[1]
    key = _zoh_key(a, b, dt_s)
    ms = _ZOH_MEMO.get(key)
    if ms is None:
        ms = _cache_load("zoh", key, (n, n + m))
    if ms is None:
        from scipy.linalg import expm

        em = np.vstack((np.hstack((a, b)), np.hstack((np.zeros((m, n)), np.zeros((m, m))))))
        ms = expm(dt_s * em)[:n, :]
        _cache_store("zoh", key, ms)
    _ZOH_MEMO[key] = ms
    return ms[:, :n].copy(), ms[:, n:].copy()


_ZOH_MEMO: dict = {}


def _zoh_key(a: np.ndarray, b: np.ndarray, dt_s: float) -> str:
    """The disk-cache key of a ZOH (scipy's version: ``scipy.__version__`` when scipy is imported, else from its
    ``.dist-info`` folder when that is unambiguous, else ``scipy.__version__`` as before:
    :func:`.diskcache.package_version`; the same string for a pip-installed scipy; importing scipy for it cost a
    mission ~10 ms)."""
    from .diskcache import package_version
    return (f"zoh v1 a{a.shape}={a.tobytes().hex()} b{b.shape}={b.tobytes().hex()} dt={float(dt_s).hex()} "
            f"scipy={package_version('scipy')}")


def ss2tf(a, b, c, d):
    """``(num, den)`` of ``C (sI - A)^-1 B + D`` (SISO; scipy's ``ss2tf``)."""
    den = np.poly(a)
    num = np.poly(a - np.dot(b, np.atleast_2d(c[0, :]))) + (d[0] - 1) * den
    return num[None, :], den


def zoh_tf(num, den, dt_s: float):
    """``(num_d, den_d)`` of ``num(s)/den(s)`` discretised with a zero-order hold (``cont2discrete``)."""
    a, b, c, d = tf2ss(num, den)
    ad, bd = zoh_ss(a, b, dt_s)
    return ss2tf(ad, bd, c, d)


def lfilter(b, a, x, axis: int = 0, state: list | None = None) -> np.ndarray:
    """``y`` of the IIR filter ``b(z)/a(z)`` from rest along ``axis`` (direct form II transposed).

    The same recursion and operation order as ``scipy.signal.lfilter`` (b and a padded to one
    length and divided by ``a[0]``). A Python loop over samples: meant for the few thousand
    samples of a trajectory grid, not for audio-length signals. ``state`` (one list of
    ``max(len(a), len(b)) - 1`` floats per column, zeros to start from rest) continues the filter
    from where an earlier call left it and is updated in place, so a signal filtered in chunks
    gives the numbers of one call (``scipy``'s ``zi``/``zf``).
    """
    b = np.atleast_1d(np.asarray(b, dtype=float))
    a = np.atleast_1d(np.asarray(a, dtype=float))
    k = max(b.size, a.size)
    b, a = np.pad(b, (0, k - b.size)), np.pad(a, (0, k - a.size))
    if a[0] != 1.0:
        b, a = b / a[0], a / a[0]
    x = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    cols = x.reshape(len(x), -1)
    zs = state if state is not None else [None] * cols.shape[1]
    y = np.column_stack([_df2t(b.tolist(), a.tolist(), cols[:, j].tolist(), zs[j]) for j in range(cols.shape[1])])
    return np.moveaxis(y.reshape(x.shape), 0, axis)


def _df2t(b: list, a: list, xs: list, z: list | None = None) -> list:
    """One column of :func:`lfilter` on Python floats (``scipy.signal``'s inner loop); ``z`` the
    filter state (updated in place; None: from rest)."""
    k = len(b)
    if k == 1:
        return [b[0] * xv for xv in xs]
    z = [0.0] * (k - 1) if z is None else z
    out = []
    for xv in xs:
        yv = z[0] + b[0] * xv
        for i in range(1, k - 1):
            z[i - 1] = z[i] + xv * b[i] - yv * a[i]
        z[k - 2] = xv * b[k - 1] - yv * a[k - 1]
        out.append(yv)
    return out
