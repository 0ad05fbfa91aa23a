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
    False when the reference path has to run instead (error status, or an interval too long)."""
    from . import loop_kernel as kern
    from ..contract import _INV_SPAN, _LO
    hook = loop.policy.kernel()
    if hook is None:
        return False
    fn, params, state = hook
    cst = pack_constants(loop)
    vals = _state_values(loop)
    s = np.array([float(vals[name]) for name in kern.S_NAMES])
    t_all = np.ascontiguousarray(loop.t_all, dtype=float)
    if len(t_all) < 2:
        return False
    need = kern._rows_needed.py_func(cst, float(np.max(np.diff(t_all))))  # the kernel's bound, in Python
    if need > _MAX_ROWS:
        return False
    arrays = (t_all, np.ascontiguousarray(loop.lm_all, dtype=float), np.ascontiguousarray(loop.k_all, dtype=float),
              np.ascontiguousarray(loop.p_all, dtype=float), loop.eligible.astype(float))
    rows = np.empty((max(2 * need, BLOCK_ROWS + need), N_COLUMNS))  # pages are touched only as rows are written
    k, params, state = 0, np.ascontiguousarray(params, dtype=float), np.ascontiguousarray(state, dtype=float)
    lo, inv = np.ascontiguousarray(_LO, dtype=float), np.ascontiguousarray(_INV_SPAN, dtype=float)
    i_rows, i_peak = kern.S_NAMES.index("n_rows"), kern.S_NAMES.index("peak_env")
    while k < len(t_all) - 1:
        k_new, status = kern.run_kernel(k, k + _CHUNK, s, cst, *arrays, rows, fn, params, state, lo, inv)
        if bar is not None:
            bar.update(float(t_all[k_new]) - float(t_all[k]))
        k = k_new
        if status == kern.FULL and s[i_rows] == 0:
            rows = np.concatenate([rows, np.empty_like(rows)])
        elif status == kern.DEPLETED:
            break
        elif status not in (kern.OK, kern.FULL):
            return False
        if s[i_rows] >= BLOCK_ROWS or status == kern.FULL:
            _hand_over(loop, rows, s, i_rows, i_peak)   # the block is final: the buffer is reused
    loop.rows = rows[:int(s[i_rows])]
    _unpack_state(loop, s)
    return True


def _hand_over(loop, rows, s, i_rows, i_peak):
    """Give the rows written so far to the loop (:meth:`~.loop.MissionLoop.flush`, which copies them) and
    empty the kernel's buffer."""
    loop.rows, loop.peak_env = rows[:int(s[i_rows])], float(s[i_peak])
    loop.flush()
    s[i_rows] = 0.0
