"""The event loop of :class:`~.link.SwitchingLink`, once, compiled with numba (``cache=True``).

Exact modal stepping between events, guard bracketing on the precomputed grid of exponentials,
safeguarded Newton on the exact solution (:func:`refine`), the diode and freewheel rules after an
event (:func:`_after_event`) and at a drive change (:func:`_modes`; both in the numba-free :mod:`.mode_rules`,
compiled in here). This is the one source of those
rules: :class:`~.link.SwitchingLink` builds the circuit and packs its arrays (:func:`pack`), then calls
:func:`run_kernel` (with ``compiled=False`` its ``py_func``: the same source run by the interpreter);
the slow ``solve_ivp`` reference (:mod:`.ivp`) calls :func:`_modes` and :func:`_after_event` of
:mod:`.mode_rules` for its mode decisions, as Python (no numba). (Until 2026-11-27 :mod:`.link` held a second,
pure-Python/numpy copy of this loop that the tests compared against to 1e-9.) All devices of the switching link are
covered because they only change the topology matrices, guard rows and threshold rows, which
are packed here as arrays.

This module imports numba at import time, so nothing imports it at module level:
:meth:`~.link.SwitchingLink.run` imports it on the first run (the compiled code is
cached on disk by numba; the first process compiles, ~10 s, later ones load it).

Packed arrays (``nk`` topologies in the order of :attr:`.circuit.Circuit.keys`, ``m`` states):

* ``lam`` (nk, m), ``vec``/``inv`` (nk, m, m), ``trans`` (nk, nk, m, m): modal decompositions;
* ``grid`` (nk, G + 2, m): ``exp(lam j h)``; ``grows`` (nk, 2, 3, 4, m) modal guard rows per
  (topology, gate, command index 1/-1/0), ``gnum``/``gsec`` (nk, 2, 3): number of rows and of
  secondary rows;
* ``v2open`` (5, m) per primary index, ``v1open`` (4, m) per secondary index, ``sec_th`` (m,).
"""

from __future__ import annotations

import cmath
from pathlib import Path

import numpy as np
from numba import njit
from numba.extending import register_jitable

from ..kernel_cache import drop_stale_cache
from .circuit import I1, I2, P_OPEN, PRIMARY, S_OPEN, SECONDARY
from .mode_rules import _after_event, _dot, _modes, _pidx, _primary_at_zero, _secondary_at_zero, _sidx, mode_rows

__all__ = ["pack", "mode_rows", "run_kernel", "refine", "OK", "FULL", "STUCK"]

OK, FULL, STUCK = 0, 1, 2


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


# the mode rules live, numba-free, in mode_rules.py (the solve_ivp reference calls them as Python): compiled where
# the kernel calls them, and this module's numba cache dropped when they (or the circuit's constants) change
drop_stale_cache(_here, (Path(__file__).with_name("mode_rules.py"), Path(__file__).with_name("circuit.py")))
for _f in (_pidx, _sidx, _dot, _secondary_at_zero, _primary_at_zero, _modes, _after_event):
    register_jitable(_f)
del _f


def pack(link) -> dict:
    """The arrays of a :class:`~.link.SwitchingLink` the kernel needs (see the module docstring)."""
    cir = link.cir
    nk, m = len(cir.keys), cir.m
    for k, (p, s) in enumerate(cir.keys):  # the kernel computes k from (p, s) by this rule
        assert k == PRIMARY.index(p) * len(SECONDARY) + SECONDARY.index(s)
    grows = np.zeros((nk, 2, 3, 4, m), dtype=complex)
    gnum = np.zeros((nk, 2, 3), dtype=np.int64)
    gsec = np.zeros((nk, 2, 3), dtype=np.int64)
    for (k, gate, cmd), (rows, ns) in link._guard_table.items():
        c = (1, -1, 0).index(cmd)
        if rows is not None:
            grows[k, gate, c, :len(rows)] = rows
            gnum[k, gate, c] = len(rows)
        gsec[k, gate, c] = ns
    v2open, v1open, sec_th, pri_th = mode_rows(cir)
    return {"lam": np.array(cir.lam), "vec": np.array(cir.vec), "inv": np.array(cir.inv),
            "trans": np.array([[t for t in row] for row in cir.trans]), "grid": np.array(link._grid),
            "grows": grows, "gnum": gnum, "gsec": gsec, "v2open": v2open, "v1open": v1open, "sec_th": sec_th,
            "pri_th": pri_th, "h": float(link._h), "T": float(link.T)}


# ---------------------------------------------------------------------------- indices
@njit(cache=True)
def _kidx(p, s):
    return _pidx(p) * 4 + _sidx(s)


@njit(cache=True)
def _cidx(cmd):
    return 0 if cmd == 1 else (1 if cmd == -1 else 2)


# ---------------------------------------------------------------------------- linear algebra
@njit(cache=True)
def _to_state(vk, z):
    """x = Re(V z)."""
    m = z.shape[0]
    x = np.empty(m)
    for i in range(m):
        acc = 0j
        for j in range(m):
            acc += vk[i, j] * z[j]
        x[i] = acc.real
    return x


@njit(cache=True)
def _matvec(a, v):
    """a @ v (complex a, real or complex v)."""
    m = a.shape[0]
    out = np.empty(m, dtype=np.complex128)
    for i in range(m):
        acc = 0j
        for j in range(a.shape[1]):
            acc += a[i, j] * v[j]
        out[i] = acc
    return out


# ---------------------------------------------------------------------------- events
@njit(cache=True)
def refine(c, lam, a, ga, b, gb, tol):
    """Root of ``g(t) = Re(sum c exp(lam t))`` in ``[a, b]`` with ``g(a) > 0 >= g(b)``: Newton on the exact
    solution, safeguarded by bisection."""
    if ga <= 0.0:
        return a
    t = a + (b - a) * ga / (ga - gb)
    for _ in range(60):
        g = 0j
        dg = 0j
        for i in range(c.shape[0]):
            e = cmath.exp(lam[i] * t)
            g += c[i] * e
            dg += (c[i] * lam[i]) * e
        gr, dgr = g.real, dg.real
        if gr > 0:
            a = t
        else:
            b = t
        tn = t - gr / dgr if dgr != 0 else 0.5 * (a + b)
        if not (a < tn < b):
            tn = 0.5 * (a + b)
        if abs(tn - t) <= tol or b - a <= tol:
            return t
        t = tn
    return b


@njit(cache=True)
def _guard_at(rows, g, gk, j, z):
    """Guard ``g`` at grid point ``j``: Re(sum (exp(lam j h) rows[g]) z)."""
    acc = 0j
    for i in range(z.shape[0]):
        acc += (gk[j, i] * rows[g, i]) * z[i]
    return acc.real


@njit(cache=True)
def _first_event(z, z_end, rows, ng, gk, lam, h, tau, tol):
    """First guard crossing in ``(0, tau]`` for modal state ``z``: ``(dt, guard index)``, guard index -1 =
    none. The first grid step where a guard is <= 0 brackets the root, refined by :func:`refine`."""
    nj = int(tau / h)
    jh = nj
    for j in range(min(nj, gk.shape[0] - 1)):
        for g in range(ng):
            if _guard_at(rows, g, gk, j + 1, z) <= 0.0:
                jh = j
                break
        if jh != nj:
            break
    vb = np.empty(ng)
    if jh == nj:
        any_bad = False
        for g in range(ng):
            acc = 0j
            for i in range(z.shape[0]):
                acc += rows[g, i] * z_end[i]
            vb[g] = acc.real
            any_bad = any_bad or vb[g] <= 0.0
        if not any_bad:
            return 0.0, -1
        b = tau
    else:
        for g in range(ng):
            vb[g] = _guard_at(rows, g, gk, jh + 1, z)
        b = (jh + 1) * h
    a = jh * h
    best, which = b, -1
    for g in range(ng):
        if vb[g] <= 0.0:
            c = rows[g] * z
            va = 0j
            for i in range(z.shape[0]):
                va += c[i] * gk[jh, i]
            r = refine(c, lam, a, va.real, b, vb[g], tol)
            if r < best or which < 0:
                best, which = r, g
    return best, which


# ---------------------------------------------------------------------------- loop
@njit(cache=True)
def _drive_change(k, z, p, s, cmd, gate, vec, inv, trans, v2open, v1open, sec_th, pri_th):
    x = _to_state(vec[k], z)
    p2, s2 = _modes(x, cmd, gate, v2open, v1open, sec_th, pri_th)
    if p2 == p and s2 == s:
        return k, z, p, s
    k2 = _kidx(p2, s2)
    if p2 == P_OPEN or s2 == S_OPEN:
        if p2 == P_OPEN:
            x[I1] = 0.0
        if s2 == S_OPEN:
            x[I2] = 0.0
        return k2, _matvec(inv[k2], x), p2, s2
    return k2, _matvec(trans[k, k2], z), p2, s2


@njit(cache=True)
def run_kernel(ts, cmds, gates, x0, lam, vec, inv, trans, grid, grows, gnum, gsec, v2open, v1open, sec_th, pri_th,
               h, T, cap, max_zero):
    """Integrate the schedule exactly from ``x0``. Returns ``(status, n, seg_t, seg_k, seg_z, j)``:
    ``status`` OK, FULL (more than ``cap`` segments: call again with more) or STUCK (more than
    ``max_zero`` zero-length events in a row; :meth:`~.link.SwitchingLink.run` then raises); ``j`` the schedule
    interval the loop was in (STUCK: the one it is stuck in, which a search of its time in ``ts`` cannot tell among
    intervals that start at the same time)."""
    m = x0.shape[0]
    seg_t = np.empty(cap + 1)
    seg_k = np.empty(cap, dtype=np.int64)
    seg_z = np.empty((cap, m), dtype=np.complex128)
    x = x0.copy()
    x[m - 1] = 1.0
    p, s = _modes(x, cmds[0], gates[0], v2open, v1open, sec_th, pri_th)
    if p == P_OPEN:
        x[I1] = 0.0
    if s == S_OPEN:
        x[I2] = 0.0
    k = _kidx(p, s)
    z = _matvec(inv[k], x)
    t = ts[0]
    n = 0
    for j in range(cmds.shape[0]):
        cmd, gate = cmds[j], gates[j]
        if j > 0 and (cmd != cmds[j - 1] or gate != gates[j - 1]):
            k, z, p, s = _drive_change(k, z, p, s, cmd, gate, vec, inv, trans, v2open, v1open, sec_th, pri_th)
        t_b = ts[j + 1]
        c = _cidx(cmd)
        n_zero = 0
        while True:
            if n >= cap:
                return FULL, n, seg_t, seg_k, seg_z, j
            seg_t[n] = t
            seg_k[n] = k
            seg_z[n] = z
            n += 1
            tau = t_b - t
            ez = np.exp(lam[k] * tau)
            ng = gnum[k, gate, c]
            which = -1
            dt = 0.0
            if ng > 0:
                dt, which = _first_event(z, z * ez, grows[k, gate, c], ng, grid[k], lam[k], h, tau, 1e-12 * T)
            if which < 0:
                z = z * ez
                break
            n_zero = n_zero + 1 if dt <= 1e-13 * T else 0
            if n_zero > max_zero:
                return STUCK, n, seg_t, seg_k, seg_z, j
            z = z * np.exp(lam[k] * dt)
            t += dt
            x = _to_state(vec[k], z)
            p, s = _after_event(x, which < gsec[k, gate, c], p, s, n_zero > 4, v2open, v1open, sec_th, pri_th)
            k = _kidx(p, s)
            z = _matvec(inv[k], x)
            if t >= t_b:
                break
        t = t_b
    seg_t[n] = t
    return OK, n, seg_t, seg_k, seg_z, cmds.shape[0] - 1
