"""The mission kernel's link step is the exact-mode estimator (wpt_receiver.modal_kernel): its peak on
the paper's ramp (Table I, fixed Lm, the ramp's duty sequence fed to the kernel's fine step at the
rectifier period, a stiff 30 V battery) agrees with the switching model within 1 %."""

import math

import numpy as np
import pytest

from mission_sim.world import fastpath
from mission_sim.world import loop_kernel as kern
from wpt_receiver import TABLE_I
from wpt_receiver import modal_kernel as mk
from wpt_receiver.references import reference_duty

P = TABLE_I
T = P.rectifier_period_s


def _ocv_soc(v_cell):
    """SoC whose cell OCV is ``v_cell`` [V] (bisection on the kernel's OCV curve)."""
    ocv = getattr(kern._ocv_cell, "py_func", kern._ocv_cell)
    lo, hi = 0.05, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ocv(mid) < v_cell else (lo, mid)
    return 0.5 * (lo + hi)


def _kernel_run(d_seq, dt=T, levels=mk.REFINE_LEVELS, per_step=False, book=None, rest=False):
    """The kernel's fine step over ``d_seq`` (one duty per control period ``dt``, the rectifier period by
    default) from the steady state of the first duty, sub-steps refined up to ``levels`` (the mission's
    default; 0: off); returns the instantaneous and the fundamental's peak [A] the kernel tracked (with
    ``per_step``: the instantaneous peak of each step, an array). ``book`` (a dict) gets the link's energies
    summed over the rows [J] (source, coil + devices, rectifier) and its stored energy at the start and end.
    ``rest``: start from rest (the pad switched on at full V1, coil currents 0) instead."""
    vals = {**fastpath.link_values(P.l1_h, P.l2_h, P.r1_ohm, P.r2_ohm, P.omega_rad_s), "t_rect": T, "rated": 1e9,
            "v1_nom": P.v1_amp_v, "is_ideal": True, "coil_r1": P.r1_ohm, "coil_r2": P.r2_ohm, "n_cells": 8.0,
            "r0": 1e-7, "r1b": 1e-7, "tau1": 1.0, "bat_c1": 1e7, "capacity_c": 1e15,
            "refine_tol": mk.REFINE_TOL, "refine_levels": levels}
    c = fastpath.constants(vals)
    s = np.zeros(1, kern.STATE_DTYPE)
    lc, tab = mk.link_constants(P), mk.modal_table(P)
    lk = (lc, tab, np.full(kern.LW_SIZE, np.nan, dtype=complex))
    mc = np.empty(mk.N_MODES_C, dtype=complex)
    mk.modes(lc, P.lm_h, mc)
    z = np.zeros(4)
    v1c = -1j * P.v1_amp_v
    v2 = 0j if rest else mk.steady_state(lc, mc, tab, float(d_seq[0]), v1c, P.vl_v, z)
    st = s[0]
    for name, v in {"soc": _ocv_soc(P.vl_v / 8), "last_vl": P.vl_v, "v1": P.v1_amp_v, "tx_on": True, "d": d_seq[0],
                    "depleted_at": math.nan, "v2re": v2.real, "v2im": v2.imag,
                    "w_end": mk.stored_energy_j(lc, mc, z, v1c, v2, P.lm_h)}.items():
        st[name] = v
    s[0]["z"] = z
    rows = np.empty((64 + 2 ** (levels + 1) * int(round(dt / T)), fastpath.N_COLUMNS))
    pk, sums, w0 = [], np.zeros(3), float(s[0]["w_end"])
    for k, d in enumerate(d_seq):
        s[0]["d"], s[0]["n_rows"], s[0]["peak_inst"] = d, 0, 0.0 if per_step else s[0]["peak_inst"]
        assert kern._fine_step(s, c[0], lk, rows, k * dt, dt, P.lm_h, 0.0, 0) == kern.OK
        assert s[0]["n_rows"] == 1   # the sub-steps (and their pieces) merged into one row per fine step
        pk.append(float(s[0]["peak_inst"]))
        sums += rows[0, 15:18]   # e_source_j, e_coil_loss_j (ideal devices: every link loss), e_rectifier_j
    if book is not None:
        book.update(src=sums[0], coil=sums[1], rect=sums[2], w0=w0, w1=float(s[0]["w_end"]))
    assert abs(s[0]["last_vl"] - P.vl_v) < 1e-3
    return np.array(pk) if per_step else (float(s[0]["peak_inst"]), float(s[0]["peak_env"]))


@pytest.mark.parametrize("kind", ["v2", "duty"])
def test_mission_kernel_ramp_peak_within_1pct_of_the_switching_model(kind):
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    _, d, _ = reference_duty("ramp", P, 0.5e-3, 6.5e-3, T, ramp_kind=kind)
    sw = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64)).simulate(d, T).envelope()
    inst, fund = _kernel_run(d)
    assert inst == pytest.approx(sw["i2_env_a"].max(), rel=0.01)
    assert fund == pytest.approx(sw["i2_fund_a"].max(), rel=0.01)


def test_mission_kernel_step_peak_at_100us_within_1pct_of_the_switching_model():
    """The paper's step (RM -> SM) fed to the kernel's 100 us fine step: in short mode the fine step is not
    divided into rectifier periods (V2 = 0, nothing to follow), but its peak is sampled at least once per
    rectifier period, so the crest of the ringing is not missed (quarter points gave 48.66 A, 3.2 % low;
    the switching model 50.26 A)."""
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    dt = 17 * T
    _, d, _ = reference_duty("step", P, 0.5e-3, 2.5e-3, dt)
    sw = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64)).simulate(d, dt).envelope()
    inst, fund = _kernel_run(d, dt)
    assert inst == pytest.approx(sw["i2_env_a"].max(), rel=0.01)
    assert fund == pytest.approx(sw["i2_fund_a"].max(), rel=0.01)
    assert inst > 1.03 * 48.66   # the quarter points' value is out of reach


def _transient(case, pre=40):
    """A large transient at 100 us control periods (``benchmarks/modal_substeps_study.py``): a window at d = 0.32
    dropped to RM, or duties redrawn at random every step, after ``pre`` steps at the first duty."""
    rng = np.random.default_rng(1)
    return (np.r_[np.full(pre, 0.32), np.zeros(150)] if case == "drop"
            else np.r_[np.full(pre, 0.5), rng.uniform(0.0, 1.0, 150)])


@pytest.mark.parametrize("case", ["drop", "random"])
def test_mission_fine_step_large_transient_peak_refined(case):
    """The mission's fine step on two large transients (Table I, stiff 30 V battery, 100 us fine steps of 17
    rectifier-period sub-steps): with one implicit V2 per sub-step (refinement off, the kernel before) the
    largest instantaneous peak after the transient is 21 % (drop) / 6 % (random) below the switching model's,
    the ringing damped by the backward-Euler V2; with the sub-steps whose I2 moves by more than 5 % redone in
    up to 8 pieces (``wpt_receiver.modal_kernel.refine_level``, the env's criterion) it is within 5 % of the
    switching model (the envelope's own limit there is +4.7 % / +1.2 %, docs/performance.md) and within 3 % of
    the same fine step with 2^5 pieces wherever I2 moves by more than 2 % (closer to converged)."""
    pre, dt = 40, 17 * T
    d = _transient(case, pre)
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    env = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64)).simulate(d, dt).envelope()
    t = env["t_s"].to_numpy()
    sw = env["i2_env_a"].to_numpy()[t >= pre * dt].max()
    off = _kernel_run(d, dt, levels=0, per_step=True)[pre:].max()
    got = _kernel_run(d, dt, per_step=True)[pre:].max()
    assert off < 0.95 * sw   # the kernel before: damped
    assert got == pytest.approx(sw, rel=0.05)


def test_mission_fine_step_refinement_keeps_smooth_steps_and_the_energy_balance():
    """The paper's ramp (V2*) at 100 us: the refinement never triggers (I2 moves < 5 % per rectifier period),
    the fine step is the one before to the bit; on the drop transient it does (the peaks move), and the link's
    energies over the run still close (source = stored change + coil + rectifier, from the rows) to rounding,
    as without it."""
    _, d, _ = reference_duty("ramp", P, 0.5e-3, 6.5e-3, 17 * T, ramp_kind="v2")
    assert np.array_equal(_kernel_run(d, 17 * T, per_step=True), _kernel_run(d, 17 * T, levels=0, per_step=True))
    drop = _transient("drop")
    for levels in (0, mk.REFINE_LEVELS):
        b = {}
        pk = _kernel_run(drop, 17 * T, levels=levels, per_step=True, book=b)
        res = b["src"] - (b["w1"] - b["w0"]) - b["coil"] - b["rect"]
        assert abs(res) <= 1e-10 * b["src"]
        if levels == 0:
            pk0 = pk
    assert np.abs(pk / pk0 - 1).max() > 0.05
