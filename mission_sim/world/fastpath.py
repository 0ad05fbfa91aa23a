"""The driver of the compiled mission loop: records in, the kernel run in chunks, Python's part on demand.

:meth:`MissionLoop.run <.loop.MissionLoop.run>` calls :func:`run`, the one way a mission runs:
:func:`pack_constants`, :func:`initial_state` and :func:`samples` fill the records of
:mod:`.loop_kernel` (named fields: :data:`~.loop_kernel.CONST_DTYPE`, :data:`~.loop_kernel.STATE_DTYPE`,
:data:`~.loop_kernel.SAMPLE_DTYPE`), then :func:`.loop_kernel.advance` runs the physics until Python
has something to do, by status:

* ``PAUSED`` every :data:`_CHUNK` trajectory samples (with a progress bar only): the bar;
* ``FULL``: the rows written so far go to :meth:`~.loop.MissionLoop.flush` (the buffer is reused);
* ``NEED_ACT``: a Python policy's turn (no ``kernel()`` hook, or ``compiled=False``):
  :meth:`~.loop.MissionLoop.act` on the observation the kernel wrote; the duty goes back in the state;
* ``NEED_NOISE``: the next :data:`NOISE_BLOCK` standard normals of the loop's generator (sensor noise,
  ``sim.i2_noise_a``; drawn in blocks, the same sequence as one draw per policy call);
* ``ERR_POWER`` / ``ERR_POLICY``: :meth:`~.loop.MissionLoop.fail` words the error with the numbers the
  kernel left in the state.

A policy with the ``kernel()`` hook (:class:`mission_sim.contract.Policy`) is called inside the kernel
(``compiled`` None or True); any other (``compiled=False``, RL, arbitrary Python) is called here at
``NEED_ACT``. The physics is the same compiled code either way.

This module does not import numba; :mod:`.loop_kernel` does, on the first run (not at all when the run uses the
loop's ahead-of-time build, :mod:`.aot`).
"""

from __future__ import annotations

import math

import numpy as np

from .stream import BLOCK_ROWS

__all__ = ["usable", "run", "pack_constants", "link_values", "battery_values", "constants", "initial_state",
           "samples", "N_COLUMNS", "NOISE_BLOCK"]

N_COLUMNS = 26        # len(loop._COLUMNS): the kernel writes rows in that order (checked by the tests)
_CHUNK = 256          # trajectory samples per kernel call (progress bar updates between calls)
NOISE_BLOCK = 4096    # sensor-noise normals drawn at once


def usable(loop) -> bool:
    """True if ``loop`` (a MissionLoop) runs its policy compiled: the policy offers the ``kernel`` hook."""
    return loop.compiled is not False and callable(getattr(loop.policy, "kernel", None))


def link_values(l1_h, l2_h, r1_ohm, r2_ohm, omega_rad_s) -> dict:
    """The link's constants of :data:`.loop_kernel.CONST_DTYPE` (paper eq. 4; R1, R2 with the folded devices)."""
    return {"l1": l1_h, "l2": l2_h, "st_r1": r1_ohm, "st_r2": r2_ohm, "omega": omega_rad_s,
            "b0": 1.0 / (2 * l1_h), "b1": -1.0 / (2 * l2_h)}


def battery_values(bp, ch) -> dict:
    """The battery's (:class:`.battery.BatteryParams` ``bp``) and the charger's (:class:`.battery.CcCvParams`
    ``ch``) constants of :data:`.loop_kernel.CONST_DTYPE`."""
    from .battery import TRIP_MARGIN_CELL_V
    return {"r0": bp.r0_ohm, "r1b": bp.r1_ohm, "tau1": bp.tau1_s, "bat_c1": bp.c1_f, "n_cells": bp.n_series,
            "capacity_c": bp.capacity_c, "cc_a": ch.cc_current_a, "v_cv": ch.cv_cell_v * bp.n_series,
            "cutoff_a": ch.cutoff_current_a, "v_recharge": (ch.cv_cell_v - ch.recharge_drop_cell_v) * bp.n_series,
            "v_trip": (ch.cv_cell_v + TRIP_MARGIN_CELL_V) * bp.n_series}


def constants(values: dict) -> np.ndarray:
    """A 1-element :data:`.loop_kernel.CONST_DTYPE` array with ``values`` by name (the others 0)."""
    from .loop_records import CONST_DTYPE
    c = np.zeros(1, CONST_DTYPE)
    for name, v in values.items():
        c[name] = v
    return c


def pack_constants(loop) -> np.ndarray:
    """The loop's constants as a 1-element :data:`.loop_kernel.CONST_DTYPE` array (every field set)."""
    from wpt_receiver.modal_link import REFINE_LEVELS, REFINE_TOL
    from ..contract import _INV_SPAN, _LO
    from .loop_records import CONST_DTYPE
    sim, dev, lk = loop.sim, loop.dev, loop.lk
    val = {
        "dtc": loop.dtc, "k_on": loop.k_on, "k_off": loop.k_off, "ramp_rate": loop.ramp_rate, "rated": loop.rated,
        "inv_sqrt_l1l2": loop.inv_sqrt_l1l2, "t_rect": loop.t_rect, "v1_nom": loop.v1_nom,
        **link_values(loop.l1, loop.l2, lk.r1_ohm + dev.inv_r_ohm, lk.r2_ohm + dev.rect_rd_ohm, loop.base.omega_rad_s),
        "vf": dev.rect_vf_v, "dr_short": dev.short_r_ohm - dev.rect_rd_ohm, "inv_r": dev.inv_r_ohm,
        "vf0": dev.rect_diode.vf0_v, "rd": dev.rect_diode.rd_ohm, "is_ideal": dev.is_ideal,
        "coil_r1": lk.r1_ohm, "coil_r2": lk.r2_ohm, **battery_values(loop.bp, loop.cfg.charger),
        "tx_off_delay": sim.tx_off_delay_s, "bms_period": sim.bms_period_s, "cmd_deadband": sim.cmd_deadband_a,
        "min_fine": sim.min_fine_s, "max_fine": sim.max_fine_s, "flight_dt": sim.flight_dt_s,
        "lm_rel_tol": sim.lm_rel_tol, "coarse_period": sim.coarse_policy_period_s,
        "duty_event_tol": sim.duty_event_tol, "settle_duty_tol": sim.settle_duty_tol,
        "settle_i2_tol": sim.settle_i2_tol_a, "noise_a": sim.i2_noise_a,
        "rectify_off": sim.rectify_after_pad_off,
        "obs_lo": _LO, "obs_inv": _INV_SPAN,
        "row_margin": math.ceil(loop.dtc / loop.t_rect) * 2 ** REFINE_LEVELS + 3,
        "refine_tol": REFINE_TOL, "refine_levels": REFINE_LEVELS,
    }
    assert set(val) == set(CONST_DTYPE.names)
    return constants(val)


def link_arrays(loop):
    """The exact-mode link's arrays for :func:`.loop_kernel.advance`: its constants
    (:func:`wpt_receiver.modal_kernel.link_constants`, devices folded), the SBAR table
    (:func:`wpt_receiver.modal_kernel.modal_table` at the hover-gap Lm; disk-cached) and the work array
    (cached modes and ZOH coefficients; NaN keys: computed on first use)."""
    from wpt_receiver.modal_link import cached_table, link_constants
    from .loop_records import LW_SIZE
    tab = cached_table(loop.base, loop.dev)
    if tab is None:   # a miss: built with numba (wpt_receiver.modal_kernel), stored for the next run
        from wpt_receiver.modal_kernel import modal_table
        tab = modal_table(loop.base, loop.dev)
    return link_constants(loop.base, loop.dev), tab, np.full(LW_SIZE, np.nan, dtype=complex)


def initial_state(loop) -> np.ndarray:
    """The state at the mission's start as a 1-element :data:`.loop_kernel.STATE_DTYPE` array (the
    receiver in short mode, the pad off, the battery at rest at ``initial_soc``)."""
    from .loop_records import STATE_DTYPE, ocv_cell
    s = np.zeros(1, STATE_DTYPE)
    st = s[0]
    soc = loop.bp.initial_soc
    for name, v in {"d": 1.0, "soc": soc, "last_vl": loop.bp.n_series * ocv_cell(soc),
                    "t_cmd_zero": -math.inf, "t_last_bms": -math.inf, "t_last_act": -math.inf,
                    "fine_until_min": -1.0, "fine_deadline": -1.0, "peak_d": 1.0, "depleted_at": math.nan,
                    "depleted_k": -1, "noise_i": NOISE_BLOCK}.items():
        st[name] = v
    return s


def samples(loop, a: int = 0, b: int | None = None) -> np.ndarray:
    """Trajectory samples ``[a, b)`` (from :class:`.samples.MissionSamples`) as a
    :data:`.loop_kernel.SAMPLE_DTYPE` array (the state's ``k0`` = ``a``)."""
    from .loop_records import SAMPLE_DTYPE
    ch = loop.samples.chunk(a, loop.samples.n if b is None else b)
    smp = np.empty(len(ch), SAMPLE_DTYPE)
    smp["t"], smp["lm"], smp["k"], smp["p"], smp["elig"] = ch.t_s, ch.lm_h, ch.k, ch.p_w, ch.elig
    return smp


def window(loop, a: int):
    """The samples the kernel runs from sample ``a``: ``(smp, k_end)``, to stop at ``k_end`` (at most
    :data:`.samples.SAMPLE_CHUNK` samples on) with enough samples after it for quiet flight's look-ahead
    (``sim.flight_dt_s``) to merge exactly as over the whole series."""
    from .samples import SAMPLE_CHUNK
    n = loop.samples.n
    k_end, extra = min(a + SAMPLE_CHUNK, n - 1), 64
    while True:
        smp = samples(loop, a, min(k_end + extra, n))
        if a + len(smp) == n or smp["t"][-1] - smp["t"][k_end - a] > loop.sim.flight_dt_s + 1e-6:
            return smp, k_end
        extra *= 4


def run(loop, bar=None):
    """Run ``loop`` (a fresh MissionLoop): the kernel until done, window by window of samples (memory
    bounded in the mission's length), Python's part at each status; leaves the final state in
    ``loop.state`` and the last rows in ``loop.rows``."""
    from . import loop_records as kern   # the status codes (numba-free)
    built = _ahead_of_time(loop)
    if built is not None:   # the loop built ahead of time with this policy's kernel bound in: no numba (.aot)
        advance, params, pstate = built
        fn, rec = None, False
    else:
        from . import loop_kernel
        hook = loop.policy.kernel() if usable(loop) else None
        if loop.compiled and hook is None:
            raise ValueError("compiled=True needs a policy with the kernel hook (mission_sim.contract.Policy); "
                             "pass compiled=None or False")
        fn, params, pstate = hook if hook is not None else (None, (), ())   # None: NEED_ACT for each duty
        advance = loop_kernel.advance_for(fn is not None)   # only the overload this policy needs is loaded
        rec = not hasattr(advance, "py_func")   # NUMBA_DISABLE_JIT=1: the kernel runs as Python on record views
    params, pstate = np.ascontiguousarray(params, dtype=float), np.ascontiguousarray(pstate, dtype=float)
    c, s = pack_constants(loop), initial_state(loop)
    loop.consts, loop.state = c, s
    if rec:
        c, s = c.view(np.recarray), s.view(np.recarray)
    n = loop.samples.n
    if n < 2:
        return
    rows = np.empty((max(BLOCK_ROWS, 2 * int(c[0]["row_margin"])), N_COLUMNS))  # blocks of at most BLOCK_ROWS rows (or twice the row margin)
    lc, tab, lw = link_arrays(loop)
    noise, obs = np.empty(NOISE_BLOCK if loop.sim.i2_noise_a > 0 else 0), np.empty(len(c[0]["obs_lo"]))
    duty_in, duty_ready, n_rows = s["duty_in"], s["duty_ready"], s["n_rows"]  # views into the state
    smp, k_end = window(loop, 0)
    smp = smp.view(np.recarray) if rec else smp
    # pauses for the progress bar and at window ends only (a call with a compiled policy converts its
    # function argument, ~0.1 ms)
    step = _CHUNK if bar is not None else loop.samples.n
    k_stop, t_done = min(step, k_end), float(smp["t"][0])
    while True:
        status = advance(k_stop, s, c, smp, rows, noise, obs, fn, params, pstate, lc, tab, lw)
        if status == kern.NEED_ACT:
            duty_in[0], duty_ready[0] = loop.act(obs), True
        elif status == kern.PAUSED or (status == kern.DONE and s[0]["k"] < n - 1):
            k = int(s[0]["k"])
            t_done = _progress(bar, float(smp["t"][k - s[0]["k0"]]), t_done)
            if k >= k_end or status == kern.DONE:     # the window is done: the next one from sample k
                if n_rows[0] > 0:
                    _hand_over(loop, rows, s)         # while the window's poses are at hand
                smp, k_end = window(loop, k)
                smp = smp.view(np.recarray) if rec else smp
                s[0]["k0"] = k
            k_stop = min(k + step, k_end)
        elif status == kern.FULL:
            _hand_over(loop, rows, s)
        elif status == kern.NEED_NOISE:
            noise[:] = loop.rng.standard_normal(NOISE_BLOCK)
            s[0]["noise_i"] = 0
        elif status in (kern.DONE, kern.DEPLETED):
            break
        else:
            loop.fail(kern.STATUS_NAMES[status], s[0])
    _progress(bar, loop.samples.t_last_s, t_done)
    loop.rows = rows[:int(n_rows[0])]


def _ahead_of_time(loop):
    """``(advance, params, state)`` when this process runs missions on the loop's ahead-of-time build
    (:func:`.aot.enable`: ``dronewpt mission``), the build is there for the policy's compiled kernel
    (:meth:`kernel_spec` by name) and loads; else None (numba's JIT, the same source)."""
    from . import aot
    if not aot.enabled() or not usable(loop):
        return None
    spec = getattr(loop.policy, "kernel_spec", None)
    got = spec() if callable(spec) else None
    if got is None:
        return None
    name, params, state = got
    advance = aot.advance(name)
    return None if advance is None else (advance, params, state)


def _progress(bar, t_now: float, t_done: float) -> float:
    if bar is not None:
        bar.update(t_now - t_done)
    return t_now


def _hand_over(loop, rows, s):
    """Give the rows written so far to the loop (:meth:`~.loop.MissionLoop.flush`, which copies them) and
    empty the kernel's buffer."""
    loop.rows = rows[:int(s[0]["n_rows"])]
    loop.flush()
    s[0]["n_rows"] = 0
