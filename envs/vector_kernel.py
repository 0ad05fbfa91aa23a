"""The step of :class:`envs.vector.SbarChargingVectorEnv` compiled with numba (``cache=True``).

The step of every sub-environment in three passes over the sub-environments: (1) the link step
(:func:`envs.core.advance` with the scalar operations of the single env), noting the steps where
the I2 envelope changes sign; (2) those steps re-done in rectifier-period sub-steps, the sub-step
loop outside and the sub-environments inside (independent iterations the CPU overlaps, instead
of one long chain of dependent operations per sub-environment); (3) the battery, the reward
(:func:`envs.core.reward_cost`), the objective (:mod:`envs.objective`: running overshoot, step cost,
short-mode flag, observation field ``t_since_stop_s``), the state update, the normalised observation
and the info values, reading the episode's ZOH coefficients, command and noise where they are
stored (no per-step copies). The expressions are those of the single env's scalar path,
operation for operation, so the batched env reproduces single envs and the numpy path of
:class:`envs.vector.SbarChargingVectorEnv` (``compiled=False``, the reference) to the bit
(``tests/test_envs.py``, ``tests/test_vector_fast.py``).

Imported only when a vector env is built (numba is not imported by ``import envs``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .objective import SHORT_MODE_IL_A, SHORT_MODE_WITHIN_S

__all__ = ["step_kernel", "duty_kernel", "INFO_ROWS"]

#: rows of the info block the kernel fills, in order
INFO_ROWS = ("t_s", "i2_a", "i2_peak_a", "i1_a", "d_short", "v2_v", "rect_current_a", "battery_v",
             "battery_current_a", "soc", "charge_cmd_a", "lm_h", "energy_j", "overcurrent", "cost", "overshoot",
             "episode_cost")
_FOUR_OVER_PI = 4.0 / np.pi
_HALF_PI = 0.5 * np.pi
_SM_LATE_S = SHORT_MODE_WITHIN_S - 1e-12
#: columns of the ZOH coefficients used by the sub-steps: h00, h01, f0, g01, h10, h11, f1, g11
_SUB_COLS = np.array([12, 13, 16, 18, 14, 15, 17, 19], dtype=np.int64)


@njit(cache=True)
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True)
def _clip1(x):
    return -1.0 if x < -1.0 else (1.0 if x > 1.0 else x)


@njit(cache=True)
def duty_kernel(a, d):
    """``d = clip((a + 1) / 2, 0, 1)`` (:meth:`envs.vector.SbarChargingVectorEnv._duty`, same arithmetic
    in float64) for actions ``a`` (n,) of any float type; returns the index of the first non-finite
    action (``d`` then unusable) or -1."""
    for e in range(a.shape[0]):
        x = np.float64(a[e])
        if not np.isfinite(x):
            return e
        x = (x + 1.0) * 0.5
        d[e] = 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)
    return -1


@njit(cache=True)
def _link_step(i1, i2, vl, d, c):
    """The link part of ``envs.core.advance`` on floats: ``(i1n, i2n, pk, il, v2, split)``; ``split``:
    the I2 envelope changes sign within the step (re-done in sub-steps)."""
    v2 = _FOUR_OVER_PI * vl * (1.0 - math.sin(_HALF_PI * d)) * _sign(i2)
    i2m = c[8] * i1 + c[9] * i2 + c[10] + c[11] * v2
    i1n = c[0] * i1 + c[1] * i2 + c[4] + c[6] * v2
    i2n = c[2] * i1 + c[3] * i2 + c[5] + c[7] * v2
    il = v2 * (i2 + 4.0 * i2m + i2n) / (12.0 * vl)
    pk = max(abs(i2m), abs(i2n))
    return i1n, i2n, pk, il, v2, (i2m * v2 < 0.0 or i2n * v2 < 0.0)


@njit(cache=True)
def _link_pass(d, state, k, j, coef_all, coef_cur, slow_every, n_sub, sc, idx):
    """Pass 1: the link step of every sub-environment into ``sc`` (rows i1n, i2n, pk, il, v2), the
    current coefficients moved to the step's slow segment; returns how many steps are split
    (their indices in ``idx[:m]``)."""
    m = 0
    for e in range(d.shape[0]):
        kk = k[e]
        jj = kk // slow_every
        if jj != j[e] or kk == 0:
            coef_cur[e] = coef_all[e, jj]
            j[e] = jj
        i1n, i2n, pk, il, v2, split = _link_step(state[0, e], state[1, e], state[2, e], d[e], coef_cur[e])
        sc[0, e], sc[1, e], sc[2, e], sc[3, e], sc[4, e] = i1n, i2n, pk, il, v2
        if n_sub > 1 and split:
            idx[m] = e
            m += 1
    return m


@njit(cache=True, error_model="numpy")
def _substeps_batch(w, h, n_sub):
    """``envs.core._substeps`` on floats for m steps at once: ``w`` (5, m) rows i1, i2, |V2|, peak
    |I2| (start -1), sum of |I2| means (start 0), updated in place; ``h`` (8, m) the sub-step
    coefficients (:data:`_SUB_COLS`). The arithmetic of each step is unchanged."""
    m = w.shape[1]
    i1, i2, vm, pk, tot = w[0], w[1], w[2], w[3], w[4]
    for _ in range(n_sub):
        for q in range(m):
            a = i2[q]
            v2 = vm[q] * _sign(a)
            b = h[4, q] * i1[q] + h[5, q] * a + h[6, q] + h[7, q] * v2
            i1[q] = h[0, q] * i1[q] + h[1, q] * a + h[2, q] + h[3, q] * v2
            i2[q] = b
            mb = abs(b)
            if mb > pk[q]:
                pk[q] = mb
            if a * b >= 0.0:
                tot[q] += 0.5 * abs(a + b)
            else:
                tot[q] += 0.5 * (a * a + b * b) / (abs(a) + abs(b))


@njit(cache=True)
def _substep_pass(idx, m, state, coef_cur, n_sub, sc):
    """Pass 2: the split steps ``idx[:m]`` re-done in ``n_sub`` sub-steps, batched; results into ``sc``."""
    w = np.empty((5, m))
    h = np.empty((8, m))
    for q in range(m):
        e = idx[q]
        w[0, q], w[1, q], w[2, q], w[3, q], w[4, q] = state[0, e], state[1, e], abs(sc[4, e]), -1.0, 0.0
        for r in range(8):
            h[r, q] = coef_cur[e, _SUB_COLS[r]]
    _substeps_batch(w, h, n_sub)
    for q in range(m):
        e = idx[q]
        sc[0, e], sc[1, e], sc[2, e] = w[0, q], w[1, q], w[3, q]
        sc[3, e] = w[2, q] * w[4, q] / (2.0 * n_sub * state[2, e])


@njit(cache=True)
def _battery(il, soc, vrc, vl, b, e):
    """The battery part of ``envs.core.advance``: ``(ib, soc, vrc, vl)`` (battery rows ``b[:, e]``)."""
    ib = il - b[7, e]
    soc = soc + b[6, e] * ib
    vrc = b[4, e] * vrc + b[5, e] * ib
    vl = b[8, e] * vl + (1.0 - b[8, e]) * (b[0, e] + b[1, e] * (soc - b[2, e]) + b[3, e] * ib + vrc)
    return ib, soc, vrc, vl


@njit(cache=True)
def _objective(e, kk, pk, il, i2_sm, dt, run_max, stop_k, ok, checked):
    """:mod:`envs.objective` after step ``kk`` of sub-environment ``e`` (``i2_sm`` the short-mode I2 of
    its slow segment): running overshoot ``run_max[e]`` and the short-mode flags updated in place;
    returns the step cost (the rise of max(0, running overshoot))."""
    old = run_max[e]
    new = old
    if kk >= stop_k[e]:
        ratio = abs(pk) / i2_sm - 1.0
        new = ratio if ratio > old else old
        run_max[e] = new
    if (kk + 1 - stop_k[e]) * dt >= _SM_LATE_S:
        checked[e] = True
        if il >= SHORT_MODE_IL_A:
            ok[e] = False
    return (new if new > 0.0 else 0.0) - (old if old > 0.0 else 0.0)


@njit(cache=True)
def _put_info(row, t, i2, pk, i1, d, v2, il, vl, ib, soc, cmd, lm, energy, over, cost, rm):
    """One sub-environment's info values in the order of :data:`INFO_ROWS` (written one by one:
    faster than a loop over a tuple)."""
    row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7] = t, i2, pk, i1, d, v2, il, vl
    row[8], row[9], row[10], row[11], row[12], row[13], row[14] = ib, soc, cmd, lm, energy, over, cost
    row[15] = rm
    row[16] = rm if rm > 0.0 else 0.0


@njit(cache=True)
def _finish_pass(d, state, k, j, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, sc, obs, reward, trunc,
                 info):
    """Pass 3: battery, reward, objective, state, observation and info of every sub-environment.
    ``ep`` = (i2sm_all (n, S), stop_k, t_stop, run_max, sm_ok, sm_checked) of the episodes; ``par`` =
    (n_steps, dt, inv_rated, w_track, w_over, i_ref) as floats."""
    i2sm_all, stop_k, t_stop, run_max, ok, checked = ep
    n_steps, dt, inv_rated, w_track, w_over, i_ref = par
    for e in range(d.shape[0]):
        kk, jj = k[e], j[e]
        i1, i2, pk, il, v2 = sc[0, e], sc[1, e], sc[2, e], sc[3, e], sc[4, e]
        vl_old = state[2, e]
        ib, soc, vrc, vl = _battery(il, state[3, e], state[4, e], vl_old, bat, e)
        cmd = cmd_all[kk, e]
        over = abs(pk) * inv_rated - 1.0
        over = 0.0 if 0.0 > over else over   # max(x, 0.0)
        mn = cmd if cmd < il else il         # min(il, cmd)
        reward[e] = (mn - w_track * abs(il - cmd)) / i_ref - w_over * over
        cost = _objective(e, kk, pk, il, i2sm_all[e, jj], dt, run_max, stop_k, ok, checked)
        state[0, e], state[1, e], state[2, e], state[3, e], state[4, e], state[5, e] = i1, i2, vl, soc, vrc, d[e]
        kk += 1
        k[e] = kk
        t_since = kk * dt - t_stop[e]
        t_since = (t_since if t_since > 0.0 else 0.0) if kk >= stop_k[e] else 0.0
        vals = (i2 + noise_all[kk - 1, e], vl, ib, il, soc, cmd_all[kk, e], d[e], t_since)
        for f in range(8):
            obs[e, f] = np.float32(_clip1(vals[f] * scale[f] + offset[f]))
        trunc[e] = kk >= n_steps
        _put_info(info[e], kk * dt, i2, pk, i1, d[e], v2, il, vl, ib, soc, cmd, lm_all[jj, e], vl_old * il * dt, over,
                  cost, run_max[e])


@njit(cache=True)
def step_kernel(d, state, k, j, coef_all, coef_cur, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
                scale, offset, obs, reward, trunc, info):
    """Step every sub-environment with duty ``d``; ``state`` (6, n) = i1, i2, vl, soc, vrc, d and
    the step index ``k`` / slow index ``j`` are updated in place, and so are the current ZOH
    coefficients ``coef_cur`` (n, 20) when a sub-environment enters a new slow segment (copied from
    ``coef_all`` (n, S, 20)) and the objective's running values in ``ep`` (see :func:`_finish_pass`);
    ``cmd_all`` (T + 1, n), ``noise_all`` (T, n), ``lm_all`` (S, n) are step-major. ``obs`` (n, 8)
    float32, ``reward``, ``trunc`` and ``info`` (n, len(INFO_ROWS)) are filled (one row per
    sub-environment: the writes go to one place in memory, not to 17 rows)."""
    n = d.shape[0]
    sc = np.empty((5, n))
    idx = np.empty(n, dtype=np.int64)
    m = _link_pass(d, state, k, j, coef_all, coef_cur, slow_every, n_sub, sc, idx)
    if m:
        _substep_pass(idx, m, state, coef_cur, n_sub, sc)
    _finish_pass(d, state, k, j, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, sc, obs, reward, trunc, info)
