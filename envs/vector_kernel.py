"""The steps of :class:`envs.vector.SbarChargingVectorEnv` and :class:`envs.charging.SbarChargingEnv`
compiled with numba (``cache=True``): one arithmetic, the scalar helpers below, for both.

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

The single env's step (:func:`single_step`) is the same helpers on one sub-environment: link step,
sub-steps, battery, reward, objective, observation and info values in one call, reading the
episode's plan arrays (packed by ``SbarChargingEnv._start_compiled``). It reproduces the single
env's pure float path (``compiled=False``, the reference) to the bit (``tests/test_envs.py``).

Imported only when an env is built (numba is not imported by ``import envs``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .objective import SHORT_MODE_IL_A, SHORT_MODE_WITHIN_S

__all__ = ["step_kernel", "duty_kernel", "single_step", "INFO_ROWS", "SINGLE_OUT", "PAR_ROWS", "PAR_TAIL"]

#: rows of the info block the kernel fills, in order
INFO_ROWS = ("t_s", "i2_a", "i2_peak_a", "i1_a", "d_short", "v2_v", "rect_current_a", "battery_v",
             "battery_current_a", "soc", "charge_cmd_a", "lm_h", "energy_j", "overcurrent", "cost", "overshoot",
             "episode_cost", "i2_peak_envelope_a")
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
def _link_step(i1, i2, vl, d, c, vf, dr):
    """The link part of ``envs.core.advance`` on floats (devices ``vf``, ``dr``): ``(i1n, i2n, pk, il,
    v2, split, |V2c|, rx)``; ``split``: the I2 envelope changes sign within the step (re-done in
    sub-steps with the clamp's |V2c| and the short-window excess ``rx I2``)."""
    vc = vl + vf
    s = math.sin(_HALF_PI * d)
    v2c = _FOUR_OVER_PI * vc * (1.0 - s) * _sign(i2)
    rx = dr * (d + 2.0 * s * math.sqrt(1.0 - s * s) / math.pi)
    v2 = v2c + rx * i2
    i2m = c[8] * i1 + c[9] * i2 + c[10] + c[11] * v2
    i1n = c[0] * i1 + c[1] * i2 + c[4] + c[6] * v2
    i2n = c[2] * i1 + c[3] * i2 + c[5] + c[7] * v2
    il = v2c * (i2 + 4.0 * i2m + i2n) / (12.0 * vc)
    pk = max(abs(i2m), abs(i2n))
    return i1n, i2n, pk, il, v2, (i2m * v2c < 0.0 or i2n * v2c < 0.0), abs(v2c), rx


@njit(cache=True)
def _inst_peak(pk, d, vl, tab, vlc, inv_imax):
    """Instantaneous peak: :func:`envs.peaks.inst_peak`, operation for operation (``tab`` the (n_d,
    n_i, 2) table of :func:`envs.peaks.fold_vl`; ``vlc``, ``inv_imax`` :data:`envs.peaks.LOOKUP_SCALARS`)."""
    nd, ni = tab.shape[0], tab.shape[1]
    x = d * (nd - 1)
    y = math.sqrt(min(pk * inv_imax, 1.0)) * (ni - 1)
    j = min(int(x), nd - 2)
    k = min(int(y), ni - 2)
    fx, fy = x - j, y - k
    ea = ((tab[j, k, 0] * (1.0 - fx) + tab[j + 1, k, 0] * fx) * (1.0 - fy)
          + (tab[j, k + 1, 0] * (1.0 - fx) + tab[j + 1, k + 1, 0] * fx) * fy)
    eb = ((tab[j, k, 1] * (1.0 - fx) + tab[j + 1, k, 1] * fx) * (1.0 - fy)
          + (tab[j, k + 1, 1] * (1.0 - fx) + tab[j + 1, k + 1, 1] * fx) * fy)
    return pk + (ea + eb * (vl - vlc))


@njit(cache=True)
def _link_pass(d, state, k, j, coef_all, coef_cur, slow_every, n_sub, vf, dr, sc, idx):
    """Pass 1: the link step of every sub-environment into ``sc`` (rows i1n, i2n, pk, il, v2), the
    current coefficients moved to the step's slow segment; returns how many steps are split (their
    indices in ``idx[:m]``, their clamp |V2c| and excess rx in ``sc[5:7, :m]``)."""
    m = 0
    sub = n_sub > 1
    for e in range(d.shape[0]):
        kk = k[e]
        jj = kk // slow_every
        if jj != j[e] or kk == 0:
            coef_cur[e] = coef_all[e, jj]
            j[e] = jj
        i1n, i2n, pk, il, v2, split, vm, rx = _link_step(state[0, e], state[1, e], state[2, e], d[e], coef_cur[e], vf,
                                                         dr)
        sc[0, e], sc[1, e], sc[2, e], sc[3, e], sc[4, e] = i1n, i2n, pk, il, v2
        # noted without a branch (about half the steps split, at random): the slot m is written
        # every time and kept when the step splits
        idx[m] = e
        sc[5, m], sc[6, m] = vm, rx
        m += split & sub
    return m


@njit(cache=True, error_model="numpy")
def _substep(i1, a, vm, rx, pk, tot, h00, h01, f0, g01, h10, h11, f1, g11):
    """One rectifier-period sub-step of ``envs.core._substeps_float`` (V2 = |V2c| sign(I2) + rx I2 at
    its start): ``(i1, i2, peak |I2|, sum of |I2| means)`` after it."""
    v2 = vm * _sign(a) + rx * a
    b = h10 * i1 + h11 * a + f1 + g11 * v2
    i1 = h00 * i1 + h01 * a + f0 + g01 * v2
    mb = abs(b)
    if mb > pk:
        pk = mb
    if a * b >= 0.0:
        tot += 0.5 * abs(a + b)
    else:
        tot += 0.5 * (a * a + b * b) / (abs(a) + abs(b))
    return i1, b, pk, tot


@njit(cache=True, error_model="numpy")
def _substeps_batch(w, h, n_sub):
    """``envs.core._substeps`` on floats for m steps at once: ``w`` (6, m) rows i1, i2, |V2c|, peak
    |I2| (start -1), sum of |I2| means (start 0), rx, updated in place; ``h`` (8, m) the sub-step
    coefficients (:data:`_SUB_COLS`). The arithmetic of each step is :func:`_substep`."""
    m = w.shape[1]
    i1, i2, vm, pk, tot, rx = w[0], w[1], w[2], w[3], w[4], w[5]
    for _ in range(n_sub):
        for q in range(m):
            i1[q], i2[q], pk[q], tot[q] = _substep(i1[q], i2[q], vm[q], rx[q], pk[q], tot[q], h[0, q], h[1, q],
                                                   h[2, q], h[3, q], h[4, q], h[5, q], h[6, q], h[7, q])


@njit(cache=True, error_model="numpy")
def _substeps_one(i1, i2, vm, rx, vc, c, n_sub):
    """One split step re-done in ``n_sub`` sub-steps (coefficients ``c[12:20]`` of the ZOH row; ``vc``
    the clamp voltage VL + Vf): ``(i1, i2, peak |I2|, mean I_L)``, the numbers of
    :func:`_substep_pass` for one sub-environment."""
    pk, tot = -1.0, 0.0
    h00, h01, h10, h11, f0, f1, g01, g11 = c[12], c[13], c[14], c[15], c[16], c[17], c[18], c[19]
    for _ in range(n_sub):
        i1, i2, pk, tot = _substep(i1, i2, vm, rx, pk, tot, h00, h01, f0, g01, h10, h11, f1, g11)
    return i1, i2, pk, vm * tot / (2.0 * n_sub * vc)


@njit(cache=True)
def _substep_pass(idx, m, state, coef_cur, n_sub, vf, sc):
    """Pass 2: the split steps ``idx[:m]`` re-done in ``n_sub`` sub-steps, batched; results into ``sc``
    (the clamp's |V2c| and the excess rx those of pass 1, ``sc[5:7, :m]``: a split step has
    sign(I2) = +-1, so |V2c| is the sub-steps' magnitude to the bit; no second sine)."""
    w = np.empty((6, m))
    h = np.empty((8, m))
    for q in range(m):
        e = idx[q]
        w[0, q], w[1, q], w[3, q], w[4, q] = state[0, e], state[1, e], -1.0, 0.0
        w[2, q], w[5, q] = sc[5, q], sc[6, q]
        for r in range(8):
            h[r, q] = coef_cur[e, _SUB_COLS[r]]
    _substeps_batch(w, h, n_sub)
    for q in range(m):
        e = idx[q]
        sc[0, e], sc[1, e], sc[2, e] = w[0, q], w[1, q], w[3, q]
        sc[3, e] = w[2, q] * w[4, q] / (2.0 * n_sub * (state[2, e] + vf))


@njit(cache=True)
def _battery(il, soc, vrc, vl, ocv0, docv, soc0, r0, rc_decay, rc_gain, dsoc, i_load, bus_decay):
    """The battery part of ``envs.core.advance``: ``(ib, soc, vrc, vl)`` (the battery row of the episode)."""
    ib = il - i_load
    soc = soc + dsoc * ib
    vrc = rc_decay * vrc + rc_gain * ib
    vl = bus_decay * vl + (1.0 - bus_decay) * (ocv0 + docv * (soc - soc0) + r0 * ib + vrc)
    return ib, soc, vrc, vl


@njit(cache=True)
def _reward(il, cmd, pk, inv_rated, w_track, w_over, i_ref):
    """``envs.core.reward_cost``: ``(reward, overcurrent)``."""
    over = abs(pk) * inv_rated - 1.0
    over = 0.0 if 0.0 > over else over   # max(x, 0.0)
    mn = cmd if cmd < il else il         # min(il, cmd)
    return (mn - w_track * abs(il - cmd)) / i_ref - w_over * over, over


@njit(cache=True)
def _objective(kk, pk, il, i2_sm, dt, run_max, stop_k, ok, checked):
    """:mod:`envs.objective` after step ``kk`` (``i2_sm`` the short-mode I2 of its slow segment):
    ``(running overshoot, ok, checked, step cost)``, the cost the rise of max(0, running overshoot)."""
    new = run_max
    if kk >= stop_k:
        ratio = abs(pk) / i2_sm - 1.0
        new = ratio if ratio > run_max else run_max
    if (kk + 1 - stop_k) * dt >= _SM_LATE_S:
        checked = True
        if il >= SHORT_MODE_IL_A:
            ok = False
    return new, ok, checked, (new if new > 0.0 else 0.0) - (run_max if run_max > 0.0 else 0.0)


@njit(cache=True)
def _t_since(kk, dt, t_stop, stop_k):
    """Observation field ``t_since_stop_s`` before step ``kk``."""
    t = kk * dt - t_stop
    return (t if t > 0.0 else 0.0) if kk >= stop_k else 0.0


@njit(cache=True)
def _put_obs(o, i2m, vl, ib, il, soc, cmd, d, t_since, scale, offset):
    """One observation row: the fields mapped to [-1, 1] and clipped, as float32."""
    vals = (i2m, vl, ib, il, soc, cmd, d, t_since)
    for f in range(8):
        o[f] = np.float32(_clip1(vals[f] * scale[f] + offset[f]))


@njit(cache=True)
def _put_info(row, t, i2, pk, i1, d, v2, il, vl, ib, soc, cmd, lm, energy, over, cost, rm, pk_env):
    """One sub-environment's info values in the order of :data:`INFO_ROWS` (written one by one:
    faster than a loop over a tuple)."""
    row[0], row[1], row[2], row[3], row[4], row[5], row[6], row[7] = t, i2, pk, i1, d, v2, il, vl
    row[8], row[9], row[10], row[11], row[12], row[13], row[14] = ib, soc, cmd, lm, energy, over, cost
    row[15] = rm
    row[16] = rm if rm > 0.0 else 0.0
    row[17] = pk_env


@njit(cache=True)
def _finish_pass(d, state, k, j, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, sc, ptab, obs, reward,
                 trunc, info):
    """Pass 3: instantaneous peak, battery, reward, objective, state, observation and info of every
    sub-environment. ``ep`` = (i2sm_all (n, S), stop_k, t_stop, run_max, sm_ok, sm_checked) of the
    episodes; ``par`` = (n_steps, dt, inv_rated, w_track, w_over, i_ref, vf, dr, vlc, inv_imax) as
    floats (a float64 array); ``ptab`` the peak table (:mod:`envs.peaks`)."""
    i2sm_all, stop_k, t_stop, run_max, ok, checked = ep
    n_steps, dt, inv_rated, w_track, w_over, i_ref = par[0], par[1], par[2], par[3], par[4], par[5]
    vlc, inv_imax = par[8], par[9]
    for e in range(d.shape[0]):
        kk, jj = k[e], j[e]
        vl_old = state[2, e]
        i1, i2, pk_env, il, v2 = sc[0, e], sc[1, e], sc[2, e], sc[3, e], sc[4, e]
        pk = _inst_peak(pk_env, d[e], vl_old, ptab, vlc, inv_imax)
        ib, soc, vrc, vl = _battery(il, state[3, e], state[4, e], vl_old, bat[0, e], bat[1, e], bat[2, e], bat[3, e],
                                    bat[4, e], bat[5, e], bat[6, e], bat[7, e], bat[8, e])
        cmd = cmd_all[kk, e]
        reward[e], over = _reward(il, cmd, pk, inv_rated, w_track, w_over, i_ref)
        rm, ok[e], checked[e], cost = _objective(kk, pk, il, i2sm_all[e, jj], dt, run_max[e], stop_k[e], ok[e],
                                                 checked[e])
        run_max[e] = rm
        state[0, e], state[1, e], state[2, e], state[3, e], state[4, e], state[5, e] = i1, i2, vl, soc, vrc, d[e]
        kk += 1
        k[e] = kk
        _put_obs(obs[e], i2 + noise_all[kk - 1, e], vl, ib, il, soc, cmd_all[kk, e], d[e],
                 _t_since(kk, dt, t_stop[e], stop_k[e]), scale, offset)
        trunc[e] = kk >= n_steps
        _put_info(info[e], kk * dt, i2, pk, i1, d[e], v2, il, vl, ib, soc, cmd, lm_all[jj, e], vl_old * il * dt, over,
                  cost, rm, pk_env)


@njit(cache=True)
def step_kernel(d, state, k, j, coef_all, coef_cur, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
                scale, offset, ptab, obs, reward, trunc, info):
    """Step every sub-environment with duty ``d``; ``state`` (6, n) = i1, i2, vl, soc, vrc, d and
    the step index ``k`` / slow index ``j`` are updated in place, and so are the current ZOH
    coefficients ``coef_cur`` (n, 20) when a sub-environment enters a new slow segment (copied from
    ``coef_all`` (n, S, 20)) and the objective's running values in ``ep`` (see :func:`_finish_pass`);
    ``cmd_all`` (T + 1, n), ``noise_all`` (T, n), ``lm_all`` (S, n) are step-major; ``par`` and
    ``ptab`` as in :func:`_finish_pass` (``par[6:8]`` the devices' Vf, dR). ``obs`` (n, 8)
    float32, ``reward``, ``trunc`` and ``info`` (n, len(INFO_ROWS)) are filled (one row per
    sub-environment: the writes go to one place in memory, not to 17 rows)."""
    n = d.shape[0]
    sc = np.empty((7, n))
    idx = np.empty(n, dtype=np.int64)
    vf, dr = par[6], par[7]
    m = _link_pass(d, state, k, j, coef_all, coef_cur, slow_every, n_sub, vf, dr, sc, idx)
    if m:
        _substep_pass(idx, m, state, coef_cur, n_sub, vf, sc)
    _finish_pass(d, state, k, j, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, sc, ptab, obs, reward, trunc,
                 info)


#: layout of the single env's ``st`` array: link state, objective, battery row (:func:`single_step`)
ST_ROWS = ("i1", "i2", "vl", "soc", "vrc", "d", "run_max", "sm_ok", "sm_checked", "stop_k", "t_stop", "ocv0", "docv",
           "soc0", "r0", "rc_decay", "rc_gain", "dsoc", "i_load", "bus_decay")
#: layout of the single env's ``par`` array (constants of the env), then OBS_SCALE (8), OBS_OFFSET (8) and
#: :data:`PAR_TAIL`
PAR_ROWS = ("n_steps", "dt", "inv_rated", "w_track", "w_over", "i_ref", "slow_every", "n_sub")
#: the last rows of the single env's ``par``: the devices (:attr:`envs.core.EnvConfig.device_terms`) and
#: :data:`envs.peaks.LOOKUP_SCALARS`
PAR_TAIL = ("vf", "dr", "vlc", "inv_imax")
#: the values :func:`single_step` writes to ``out``: :data:`INFO_ROWS`, then reached short mode (1.0 / 0.0)
SINGLE_OUT = INFO_ROWS + ("reached_short_mode",)


@njit(cache=True)
def single_step(k, d, st, steps, slow, par, obs, out):
    """Step ``k`` of one env with duty ``d``: the helpers of :func:`step_kernel` on one episode.
    ``st`` (:data:`ST_ROWS`) is updated in place; ``steps`` (T + 1, 2) = command, sensor noise per
    step; ``slow`` (S, 22) = the 20 ZOH coefficients, true Lm, short-mode I2 per slow segment;
    ``par`` = :data:`PAR_ROWS`, OBS_SCALE, OBS_OFFSET, :data:`PAR_TAIL`, the peak table's shape (3 values)
    and the table (:attr:`envs.peaks.PeakLookup.kernel_table`, flattened; one argument less to dispatch).
    Fills ``obs`` (8,) float32 and ``out`` (:data:`SINGLE_OUT`); returns the reward."""
    dt, n_sub, vf = par[1], int(par[7]), par[24]
    j = k // int(par[6])
    c = slow[j]
    vl_old = st[2]
    i1, i2, pk, il, v2, split, vm, rx = _link_step(st[0], st[1], vl_old, d, c, vf, par[25])
    if n_sub > 1 and split:
        i1, i2, pk, il = _substeps_one(st[0], st[1], vm, rx, vl_old + vf, c, n_sub)
    pk_env = pk
    ptab = par[31:].reshape((int(par[28]), int(par[29]), int(par[30])))
    pk = _inst_peak(pk_env, d, vl_old, ptab, par[26], par[27])
    ib, soc, vrc, vl = _battery(il, st[3], st[4], vl_old, st[11], st[12], st[13], st[14], st[15], st[16], st[17],
                                st[18], st[19])
    cmd = steps[k, 0]
    reward, over = _reward(il, cmd, pk, par[2], par[3], par[4], par[5])
    stop_k = int(st[9])
    rm, ok, checked, cost = _objective(k, pk, il, c[21], dt, st[6], stop_k, st[7] != 0.0, st[8] != 0.0)
    st[0], st[1], st[2], st[3], st[4], st[5] = i1, i2, vl, soc, vrc, d
    st[6], st[7], st[8] = rm, 1.0 if ok else 0.0, 1.0 if checked else 0.0
    kk = k + 1
    _put_obs(obs, i2 + steps[kk - 1, 1], vl, ib, il, soc, steps[kk, 0], d, _t_since(kk, dt, st[10], stop_k),
             par[8:16], par[16:24])
    _put_info(out, kk * dt, i2, pk, i1, d, v2, il, vl, ib, soc, cmd, c[20], vl_old * il * dt, over, cost, rm, pk_env)
    out[18] = 1.0 if (ok and checked) else 0.0
    return reward
