"""The compiled fast path of :class:`~.loop.MissionLoop`: when it applies, packing, running, unpacking.

:meth:`MissionLoop.run <.loop.MissionLoop.run>` uses it when :func:`usable` says so: numba is
installed, the policy offers the optional ``kernel`` hook of :class:`mission_sim.contract.Policy`
(a compiled per-step function and its parameter / state arrays) and there is no sensor noise
(``sim.i2_noise_a = 0``; the reference draws it from numpy's generator). Any other policy runs the
pure-Python reference loop. :func:`run_compiled` packs the loop's constants and state into arrays
(names in :mod:`.loop_kernel`), runs :func:`.loop_kernel.run_kernel` in chunks of trajectory
samples (progress bar; handing full blocks of rows to :meth:`~.loop.MissionLoop.flush` and reusing
the buffer, which grows only when one interval needs more) and writes the state back to the loop, so
:meth:`MissionLoop.result <.loop.MissionLoop.result>` assembles the result as for the reference.
On an error status (a propulsion power the battery cannot supply, a non-finite duty) it returns
False and the loop reruns the reference path, which raises the error with its message.

This module does not import numba; :mod:`.loop_kernel` does, on the first compiled run.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np

from .stream import BLOCK_ROWS

__all__ = ["usable", "run_compiled", "N_COLUMNS"]

N_COLUMNS = 26        # len(loop._COLUMNS): the kernel writes rows in that order (checked by the tests)
_CHUNK = 256          # trajectory samples per kernel call (progress bar updates between calls)
_MAX_ROWS = 5_000_000  # beyond this many rows for one interval the reference path runs instead


def usable(loop) -> bool:
    """True if ``loop`` (a MissionLoop) can run compiled: numba, the policy's kernel hook, no noise."""
    return (callable(getattr(loop.policy, "kernel", None)) and loop.sim.i2_noise_a == 0
            and importlib.util.find_spec("numba") is not None)


def pack_constants(loop) -> np.ndarray:
    """The loop's constants in :data:`.loop_kernel.C_NAMES` order."""
    from .loop_kernel import C_NAMES
    st, sim, dev, ch = loop.st, loop.sim, loop.dev, loop.charger.p
    val = {
        "dtc": loop.dtc, "k_on": loop.k_on, "k_off": loop.k_off, "ramp_rate": loop.ramp_rate, "rated": loop.rated,
        "inv_sqrt_l1l2": loop.inv_sqrt_l1l2, "t_rect": loop.t_rect, "r0": loop.r0, "r1b": loop.r1b,
        "n_cells": float(loop.n_cells), "tau1": loop.tau1, "vf": loop.vf, "dr_short": loop.dr_short,
        "v1_nom": loop.v1_nom, "l1": st.l1, "l2": st.l2, "st_r1": st.r1, "st_r2": st.r2, "omega": st.w, "b0": st.b0,
        "b1": st.b1, "bat_c1": loop.bp.c1_f, "capacity_c": loop.bp.capacity_c, "tx_off_delay": sim.tx_off_delay_s,
        "bms_period": sim.bms_period_s, "cmd_deadband": sim.cmd_deadband_a, "min_fine": sim.min_fine_s,
        "max_fine": sim.max_fine_s, "flight_dt": sim.flight_dt_s, "lm_rel_tol": sim.lm_rel_tol,
        "coarse_period": sim.coarse_policy_period_s, "duty_event_tol": sim.duty_event_tol,
        "settle_duty_tol": sim.settle_duty_tol, "settle_i2_tol": sim.settle_i2_tol_a, "cc_a": ch.cc_current_a,
        "v_cv": ch.cv_cell_v * loop.bp.n_series, "cutoff_a": ch.cutoff_current_a, "inv_r": dev.inv_r_ohm,
        "vf0": dev.rect_diode.vf0_v, "rd": dev.rect_diode.rd_ohm, "is_ideal": float(dev.is_ideal),
        "coil_r1": loop.lk.r1_ohm, "coil_r2": loop.lk.r2_ohm,
        "v_recharge": (ch.cv_cell_v - ch.recharge_drop_cell_v) * loop.bp.n_series,
    }
    return np.array([float(val[name]) for name in C_NAMES])


def _state_values(loop) -> dict:
    """The loop's state by :data:`.loop_kernel.S_NAMES` (booleans as 0/1, None as NaN)."""
    ch = loop.charger
    return {
        "x0": loop.x[0], "x1": loop.x[1], "v1": loop.v1, "tx_on": loop.tx_on, "cmd": loop.cmd, "d": loop.d,
        "soc": loop.soc, "vrc": loop.vrc, "last_vl": loop.last_vl, "last_ib": loop.last_ib, "last_il": loop.last_il,
        "in_fine": loop.in_fine, "fine_until_min": loop.fine_until_min, "fine_deadline": loop.fine_deadline,
        "t_cmd_zero": loop.t_cmd_zero, "t_last_bms": loop.t_last_bms, "t_last_act": loop.t_last_act,
        "peak_env": loop.peak_env, "peak_d": loop.peak_d, "above": loop.above, "n_fine": loop.n_fine,
        "n_coarse": loop.n_coarse, "n_windows": loop.n_windows, "n_cut": loop.n_cut, "n_rows": 0,
        "cv": ch.cv[0], "full": ch.full[0], "depleted_at": math.nan, "depleted_k": -1, "p11": 0.0, "p22": 0.0,
        "tmp_ib": 0.0,
    }


def _unpack_state(loop, s):
    from .loop_kernel import S_NAMES
    v = dict(zip(S_NAMES, s.tolist()))
    loop.x = (v["x0"], v["x1"])
    for name in ("v1", "cmd", "d", "soc", "vrc", "last_vl", "last_ib", "last_il", "fine_until_min", "fine_deadline",
                 "t_cmd_zero", "t_last_bms", "t_last_act", "peak_env", "peak_d", "above"):
        setattr(loop, name, v[name])
    loop.tx_on, loop.in_fine = v["tx_on"] != 0.0, v["in_fine"] != 0.0
    for name in ("n_fine", "n_coarse", "n_windows", "n_cut"):
        setattr(loop, name, int(v[name]))
    loop.charger.cv[0], loop.charger.full[0] = v["cv"] != 0.0, v["full"] != 0.0
    loop.bat.soc[0], loop.bat.v1_v[0] = loop.soc, loop.vrc
    loop.st.last_p = (v["p11"], v["p22"])
    if not math.isnan(v["depleted_at"]):
        loop.depleted_at, loop.depleted_k = v["depleted_at"], int(v["depleted_k"])


def run_compiled(loop, bar=None) -> bool:
    """Run ``loop`` (freshly reset) compiled; True when done (rows, state written back to ``loop``),
    False when the reference path has to run instead (error status, or an interval too long).

    The per-sample arrays come chunk by chunk (:meth:`.samples.MissionSamples.chunk`, samples
    ``[k, k + SAMPLE_CHUNK)`` plus the look-ahead the quiet-flight merge may use); the kernel runs on
    a chunk with local sample indices and the rows' sample column is shifted back to global ones."""
    from . import loop_kernel as kern
    from ..contract import _INV_SPAN, _LO
    hook = loop.policy.kernel()
    if hook is None or loop.n < 2:
        return False
    fn, params, state = hook
    cst = pack_constants(loop)
    vals = _state_values(loop)
    s = np.array([float(vals[name]) for name in kern.S_NAMES])
    pol = (fn, np.ascontiguousarray(params, dtype=float), np.ascontiguousarray(state, dtype=float),
           np.ascontiguousarray(_LO, dtype=float), np.ascontiguousarray(_INV_SPAN, dtype=float))
    idx = {name: kern.S_NAMES.index(name) for name in ("n_rows", "peak_env", "depleted_k")}
    k, rows = 0, np.empty((0, N_COLUMNS))
    while k < loop.n - 1:
        got = _chunk(loop, cst, k)
        if got is None:
            return False
        ch, k_end, need = got
        if rows.shape[0] < max(2 * need, BLOCK_ROWS + need):
            if s[idx["n_rows"]] > 0:
                _hand_over(loop, rows, s, idx)
            rows = np.empty((max(2 * need, BLOCK_ROWS + need), N_COLUMNS))  # pages touched only as rows are written
        k, status = _run_chunk(kern, loop, ch, k, k_end, s, cst, rows, pol, idx, bar)
        if status is None:
            return False
        if s[idx["n_rows"]] > 0 and (k < loop.n - 1 and status != kern.DEPLETED):
            _hand_over(loop, rows, s, idx)   # the rows of this chunk, while its poses are at hand
        if status == kern.DEPLETED:
            break
    loop.rows = rows[:int(s[idx["n_rows"]])]
    _unpack_state(loop, s)
    return True


def _chunk(loop, cst, k):
    """The sample chunk from ``k``: ``(chunk, k_end, rows_needed)`` with the kernel to stop at ``k_end``
    (global) and enough samples after it for the quiet-flight merge (``sim.flight_dt_s``) to see what
    it would see in the whole series; None if one interval needs more than :data:`_MAX_ROWS` rows."""
    from . import loop_kernel as kern
    from .samples import SAMPLE_CHUNK
    n = loop.n
    k_end = min(k + SAMPLE_CHUNK, n - 1)
    extra = 64
    while True:
        ch = loop.samples.chunk(k, min(k_end + extra, n))
        t = ch.t_s
        if ch.k0 + len(ch) == n or t[-1] - t[k_end - 1 - k] > loop.sim.flight_dt_s + 1e-6:
            break
        extra *= 4
    need = kern._rows_needed.py_func(cst, float(np.max(np.diff(t))))  # the kernel's bound, in Python
    return None if need > _MAX_ROWS else (ch, k_end, need)


def _run_chunk(kern, loop, ch, k, k_end, s, cst, rows, pol, idx, bar):
    """Run the kernel over ``[k, k_end)`` of chunk ``ch`` in calls of :data:`_CHUNK` samples (progress
    between them, full row blocks handed over); ``(next k (global), status)``, status None when the
    reference path has to run."""
    arrays, k0 = ch.arrays, ch.k0
    i_rows = idx["n_rows"]
    kl, stop = k - k0, k_end - k0
    status = kern.OK
    while kl < stop:
        r0 = int(s[i_rows])
        kl_new, status = kern.run_kernel(kl, min(kl + _CHUNK, stop), s, cst, *arrays, rows, *pol)
        rows[r0:int(s[i_rows]), 2] += k0   # the rows' sample index, local -> global
        if bar is not None:
            bar.update(float(arrays[0][kl_new]) - float(arrays[0][kl]))
        kl = kl_new
        if status == kern.FULL and s[i_rows] == 0:
            return k0 + kl, None     # cannot happen: the buffer holds 2x an interval's bound
        if status == kern.DEPLETED:
            s[idx["depleted_k"]] += k0
            return k0 + kl, status
        if status not in (kern.OK, kern.FULL):
            return k0 + kl, None
        if s[i_rows] >= BLOCK_ROWS or status == kern.FULL:
            _hand_over(loop, rows, s, idx)   # the block is final: the buffer is reused
    return k0 + kl, status


def _hand_over(loop, rows, s, idx):
    """Give the rows written so far to the loop (:meth:`~.loop.MissionLoop.flush`, which copies them) and
    empty the kernel's buffer."""
    loop.rows, loop.peak_env = rows[:int(s[idx["n_rows"]])], float(s[idx["peak_env"]])
    loop.flush()
    s[idx["n_rows"]] = 0.0
