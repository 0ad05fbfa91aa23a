"""The step of :class:`envs.vector.SbarChargingVectorEnv` compiled with numba (``cache=True``).

One loop over the sub-environments does the whole step of each: the link (:func:`envs.core.advance`
with the scalar operations of the single env, rectifier-period sub-steps where the I2 envelope
changes sign), the reward and cost (:func:`envs.core.reward_cost`), the state update, the
normalised observation and the info values, reading the episode's ZOH coefficients, command and
noise where they are stored (no per-step copies). The expressions are those of the single env's
scalar path, operation for operation, so the batched env reproduces single envs (checked in
``tests/test_envs.py``); the numpy path of :func:`envs.core.advance` stays as the reference.

Imported only when a vector env is built (numba is not imported by ``import envs``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["step_kernel", "INFO_ROWS"]

#: rows of the info block the kernel fills, in order
INFO_ROWS = ("t_s", "i2_a", "i2_peak_a", "i1_a", "d_short", "v2_v", "rect_current_a", "battery_v",
             "battery_current_a", "soc", "charge_cmd_a", "lm_h", "energy_j", "overcurrent")
_FOUR_OVER_PI = 4.0 / np.pi
_HALF_PI = 0.5 * np.pi


@njit(cache=True)
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True)
def _abs_mean(a, b):
    if a * b >= 0.0:
        return 0.5 * abs(a + b)
    return 0.5 * (a * a + b * b) / (abs(a) + abs(b))


@njit(cache=True)
def _substeps(i1, i2, v2_mag, vl, c, n_sub):
    """``envs.core._substeps`` on floats: ``(i1, i2, peak |I2|, mean I_L)``."""
    h00, h01, h10, h11, f0, f1, g01, g11 = c[12], c[13], c[14], c[15], c[16], c[17], c[18], c[19]
    pk = -1.0
    tot = 0.0
    for _ in range(n_sub):
        prev = i2
        v2 = v2_mag * _sign(i2)
        i1, i2 = h00 * i1 + h01 * i2 + f0 + g01 * v2, h10 * i1 + h11 * i2 + f1 + g11 * v2
        a = abs(i2)
        if a > pk:
            pk = a
        tot += _abs_mean(prev, i2)
    return i1, i2, pk, v2_mag * tot / (2.0 * n_sub * vl)


@njit(cache=True)
def _advance(i1, i2, vl, soc, vrc, d, c, b, e, n_sub):
    """``envs.core.advance`` with the scalar operations for sub-environment ``e`` (battery rows ``b[:, e]``)."""
    ocv0, docv, soc0, r0 = b[0, e], b[1, e], b[2, e], b[3, e]
    rc_decay, rc_gain, dsoc, i_load, bus_decay = b[4, e], b[5, e], b[6, e], b[7, e], b[8, e]
    v2 = _FOUR_OVER_PI * vl * (1.0 - math.sin(_HALF_PI * d)) * _sign(i2)
    i2m = c[8] * i1 + c[9] * i2 + c[10] + c[11] * v2
    i1n = c[0] * i1 + c[1] * i2 + c[4] + c[6] * v2
    i2n = c[2] * i1 + c[3] * i2 + c[5] + c[7] * v2
    il = v2 * (i2 + 4.0 * i2m + i2n) / (12.0 * vl)
    pk = max(abs(i2m), abs(i2n))
    if n_sub > 1 and (i2m * v2 < 0.0 or i2n * v2 < 0.0):
        i1n, i2n, pk, il = _substeps(i1, i2, abs(v2), vl, c, n_sub)
    ib = il - i_load
    soc = soc + dsoc * ib
    vrc = rc_decay * vrc + rc_gain * ib
    vl = bus_decay * vl + (1.0 - bus_decay) * (ocv0 + docv * (soc - soc0) + r0 * ib + vrc)
    return i1n, i2n, pk, il, ib, soc, vrc, vl, v2


@njit(cache=True)
def _clip1(x):
    return -1.0 if x < -1.0 else (1.0 if x > 1.0 else x)


@njit(cache=True)
def step_kernel(d, state, k, j, coef_all, coef_cur, bat, cmd_all, noise_all, lm_all, slow_every, n_sub, n_steps, dt,
                inv_rated, w_track, w_over, i_ref, scale, offset, obs, reward, trunc, info):
    """Step every sub-environment with duty ``d``; ``state`` (6, n) = i1, i2, vl, soc, vrc, d and
    the step index ``k`` / slow index ``j`` are updated in place, and so are the current ZOH
    coefficients ``coef_cur`` (n, 20) when a sub-environment enters a new slow segment (copied from
    ``coef_all`` (n, S, 20)); ``cmd_all`` (T + 1, n), ``noise_all`` (T, n), ``lm_all`` (S, n) are
    step-major. ``obs`` (n, OBS_DIM) float32 (fields 0-6; field 7 is filled by the caller), ``reward``, ``trunc`` and ``info`` (len(INFO_ROWS), n) are filled."""
    for e in range(d.shape[0]):
        kk = k[e]
        jj = kk // slow_every
        if jj != j[e] or kk == 0:
            coef_cur[e] = coef_all[e, jj]
            j[e] = jj
        vl_old = state[2, e]
        i1, i2, pk, il, ib, soc, vrc, vl, v2 = _advance(state[0, e], state[1, e], vl_old, state[3, e], state[4, e],
                                                        d[e], coef_cur[e], bat, e, n_sub)
        cmd = cmd_all[kk, e]
        cost = abs(pk) * inv_rated - 1.0
        cost = 0.0 if 0.0 > cost else cost   # max(x, 0.0)
        mn = cmd if cmd < il else il         # min(il, cmd)
        reward[e] = (mn - w_track * abs(il - cmd)) / i_ref - w_over * cost
        state[0, e], state[1, e], state[2, e], state[3, e], state[4, e], state[5, e] = i1, i2, vl, soc, vrc, d[e]
        kk += 1
        k[e] = kk
        cmd_next = cmd_all[kk, e]
        vals = (i2 + noise_all[kk - 1, e], vl, ib, il, soc, cmd_next, d[e])
        for f in range(7):
            obs[e, f] = np.float32(_clip1(vals[f] * scale[f] + offset[f]))
        trunc[e] = kk >= n_steps
        row = (kk * dt, i2, pk, i1, d[e], v2, il, vl, ib, soc, cmd, lm_all[jj, e], vl_old * il * dt, cost)
        for r in range(14):
            info[r, e] = row[r]
