"""The envs' exact-mode plant (``EnvConfig(link_model="modal")``, envs/modal_step.py; the default since 2026-11-26):
its link is the mission's exact-mode estimator (wpt_receiver.modal_kernel): its peak on the paper's
trajectories (Table I, fixed Lm, a stiff 30 V battery, ideal devices) agrees with the switching model, at
the paper's control period (the rectifier period) and at the env's 100 us; its energy balance closes; the
env and the mission give the same peak on the same window; the single env is the vector env's row; a
constant of the step changed once moves both; full rectification settles at the exact modes' RM state
(tuned and detuned)."""

import numpy as np
import pytest

from envs import EnvConfig, SbarChargingEnv, SbarChargingVectorEnv
from envs import modal_step as vk
from envs.layout import CZ_MODES, CZ_STEP, N_CZ
from test_env_kernel import _run
from test_mission_modal import _kernel_run
from wpt_receiver import TABLE_I
from wpt_receiver import modal_kernel as mk
from wpt_receiver.devices import IDEAL, preset
from wpt_receiver.references import reference_duty

P = TABLE_I
T = P.rectifier_period_s
ENV_DT = 17 * T


def _trajectory(name, kind, dt):
    return reference_duty(name, P, 0.5e-3, 2.5e-3 if name == "step" else 6.5e-3, dt, ramp_kind=kind)[1]


def _link(devices=IDEAL):
    return mk.link_constants(P, devices), mk.modal_table(P, devices)


def _env_run(d_seq, dt, devices=IDEAL, hold_tol=1e-3, energy=False, levels=None):
    """The env's link step (envs.vector_kernel._link_step, compiled) over ``d_seq`` (one duty per control
    period ``dt``) at Table I's Lm and a stiff 30 V battery, from the steady state of the first duty.
    Returns the instantaneous and the fundamental's peak [A], the steps run in sub-steps, and per step
    (source, coil, rect, jumps, W_start, W_end, V2 before, I_L) when ``energy``; ``levels`` the sub-steps'
    refinement levels (None: the default's)."""
    cfg = EnvConfig(dt_s=dt) if levels is None else EnvConfig(dt_s=dt, v2_refine_levels=levels)
    n_sub, n_q = cfg.modal_n_sub, cfg.modal_n_q
    lc, tab = _link(devices)
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, dt, n_sub, n_q, cz, True, cfg.v2_refine_tol, cfg.v2_refine_levels)
    mc = cz[CZ_MODES:CZ_STEP]
    v1 = -1j * P.v1_amp_v
    vf, dr = devices.rect_vf_v, devices.short_r_ohm - devices.rect_rd_ohm
    z = np.zeros(4)
    v2 = mk.steady_state(lc, mc, tab, float(d_seq[0]), v1, P.vl_v + vf, z)
    out, en = np.empty(9), np.zeros(4)
    pk = pke = 0.0
    n_split, rec, e = 0, [], -1.0
    for d in d_seq:
        w0 = mk.stored_energy_j(lc, mc, z, v1, v2, P.lm_h)
        en[3] = np.nan if energy else 0.0
        v2n, e, _, _, pe, p, il, _, split = vk._link_step(z, v2, e, P.vl_v, d, lc, tab, cz, dt, n_sub, n_q, vf, dr,
                                                          P.v1_amp_v, hold_tol, out, en)
        if energy:
            rec.append((*en, w0, mk.stored_energy_j(lc, mc, z, v1, v2n, P.lm_h), il))
        v2 = v2n
        pk, pke, n_split = max(pk, p), max(pke, pe), n_split + split
    return pk, pke, n_split, np.array(rec)


def _switching(d, dt):
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    env = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64)).simulate(d, dt).envelope()
    return env["i2_env_a"].max(), env["i2_fund_a"].max()


@pytest.mark.parametrize("dt", [T, ENV_DT], ids=["T", "100us"])
@pytest.mark.parametrize("name,kind", [("ramp", "v2"), ("ramp", "duty"), ("step", "v2"), ("proposed", "v2")])
def test_env_peak_on_the_paper_trajectories_against_the_switching_model(name, kind, dt):
    """The instantaneous peak within 0.5 % of the switching model's at the paper's control period, within
    1 % at the env's 100 us (measured: V2* ramp +0.14 % / -0.46 %, d_short ramp +0.08 % / -0.15 %, step
    +0.07 % / +0.18 %, proposed -0.07 % / -0.00 %); the eq. 4 + ripple estimator the env had was 2.85 %
    low on the V2* ramp. The fundamental's peak within 0.5 % too. Held over 100 us without sub-steps,
    V2 (which follows i2's phase) would put the peak 2-16 % low: the sub-steps are what the physics
    needs (one per rectifier period, EnvConfig.v2_updates)."""
    d = _trajectory(name, kind, dt)
    sw_inst, sw_fund = _switching(d, dt)
    inst, fund, n_split, _ = _env_run(d, dt)
    assert inst == pytest.approx(sw_inst, rel=0.005 if dt == T else 0.01)
    assert fund == pytest.approx(sw_fund, rel=0.005)
    if dt == ENV_DT and name != "step":
        held, _, n0, _ = _env_run(d, dt, hold_tol=np.inf)
        assert n0 == 0 and n_split > 0.7 * len(d)
        assert held < sw_inst * 0.985


@pytest.mark.parametrize("name,dt", [("ramp", ENV_DT), ("proposed", ENV_DT), ("step", T), ("step", ENV_DT)])
def test_env_and_mission_give_the_same_peak_on_the_same_window(name, dt):
    """The env's link step and the mission's fine step (mission_sim.world.loop_kernel) on the same duties:
    the same instantaneous peak within 1 %, the env's the nearer to the switching model's. The mission
    samples a sub-stepped fine step's quarter points, the env its sub-step ends: on the V2* ramp at 100 us
    the mission is 0.47 % below the switching model, the env 0.23 % (measured). The step at 100 us: both
    50.30 A (a short-mode fine step samples its peak once per rectifier period)."""
    d = _trajectory(name, "v2", dt)
    env_inst, env_fund, _, _ = _env_run(d, dt)
    mis_inst, mis_fund = _kernel_run(d, dt)
    sw_inst, _ = _switching(d, dt)
    assert env_inst == pytest.approx(mis_inst, rel=0.01)
    assert env_fund == pytest.approx(mis_fund, rel=0.01)
    assert abs(env_inst / sw_inst - 1.0) <= abs(mis_inst / sw_inst - 1.0) + 1e-3


@pytest.mark.parametrize("devices", [IDEAL, preset("schottky")], ids=["ideal", "schottky"])
def test_env_link_energy_balance_closes(devices):
    """Per control period (held or in sub-steps): source = W_end - W_start + coil + rectifier - jumps (the
    feedthrough's stored energy when V2 changes between sub-steps) to rounding; with ideal devices the
    rectifier's energy is the battery's, VL I_L dt, exactly. The random duties make the sub-steps refine
    (``envs.modal_step._refine``: the run differs from one without refinement), so the pieces' book closes too."""
    rng = np.random.default_rng(7)
    d = np.concatenate([np.zeros(5), rng.uniform(0.0, 1.0, 40), np.full(40, 0.3)])
    pk, _, n_split, rec = _env_run(d, ENV_DT, devices=devices, energy=True)
    assert pk != _env_run(d, ENV_DT, devices=devices, levels=0)[0]
    src, coil, rect, jumps, w0, w1, il = rec.T
    assert 0 < n_split < len(d)                          # both kinds of step were taken
    scale = np.abs(src) + coil + np.abs(rect) + w0 + w1
    np.testing.assert_allclose(src, w1 - w0 + coil + rect - jumps, rtol=0, atol=1e-10 * scale.max())
    assert np.all(coil > 0.0)
    if devices is IDEAL:
        np.testing.assert_allclose(rect, P.vl_v * il * ENV_DT, rtol=1e-12, atol=1e-15)


def test_held_steps_are_within_hold_tol_of_the_sub_stepped_link():
    """In steady state (the transient below ``hold_tol_a``) a step holds V2 over the control period: the
    same state as in sub-steps to within the tolerance, for a tenth of the work."""
    lc, tab = _link()
    cfg = EnvConfig()
    n_sub, n_q = cfg.modal_n_sub, cfg.modal_n_q
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, ENV_DT, n_sub, n_q, cz, True)
    v1 = -1j * P.v1_amp_v
    for d in (0.0, 0.4, 0.9):
        z = np.zeros(4)
        v2 = mk.steady_state(lc, cz[CZ_MODES:CZ_STEP], tab, d, v1, P.vl_v, z)
        res = []
        for tol in (1e-3, -1.0):   # held, forced into sub-steps
            zz = z.copy()
            r = vk._link_step(zz, v2, -1.0, P.vl_v, d, lc, tab, cz, ENV_DT, n_sub, n_q, 0.0, 0.0, P.v1_amp_v, tol,
                              np.empty(9), np.zeros(4))
            res.append((zz, r))
        (za, ra), (zb, rb) = res
        assert not ra[-1] and rb[-1]
        i2a = mk.phasors(cz[CZ_MODES:CZ_STEP], za, v1, ra[0])[1]
        i2b = mk.phasors(cz[CZ_MODES:CZ_STEP], zb, v1, rb[0])[1]
        assert abs(i2a - i2b) < 1e-3 and abs(ra[5] - rb[5]) < 2e-3 and ra[6] == pytest.approx(rb[6], rel=1e-3)


@pytest.mark.parametrize("n_sub", [17, 6, 3])
def test_a_large_transient_settles_at_the_rm_state(n_sub):
    """A window at d = 0.32 dropped to RM rings and settles at the RM steady state when V2 follows i2 every
    rectifier period, refined where i2 moves fast (the default, 17 sub-steps per 100 us), its peak below 2x the
    RM current (the switching model's is 20.37 A, 1.84x; the default's 20.9 A). The kernel driven with fewer
    sub-steps (6, 3; |I2| sampled once per rectifier period) holds V2 while i2 turns: the held V2 feeds the tank,
    the peak of the ringing is higher (measured 27.5 A and 51 A) and it has not settled after 20 ms: why the
    default follows the circuit's once-per-half-cycle decision, and why EnvConfig refuses such ``v2_updates``."""
    lc, tab = _link()
    n_q = -(-17 // n_sub)
    cfg = EnvConfig()
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, ENV_DT, n_sub, n_q, cz, True, cfg.v2_refine_tol, cfg.v2_refine_levels)
    mc, v1 = cz[CZ_MODES:CZ_STEP], -1j * P.v1_amp_v
    z_rm = np.zeros(4)
    i2_rm = abs(mk.phasors(mc, z_rm, v1, mk.steady_state(lc, mc, tab, 0.0, v1, P.vl_v, z_rm))[1])
    z = np.zeros(4)
    v2, e, pk = mk.steady_state(lc, mc, tab, 0.32, v1, P.vl_v, z), -1.0, 0.0
    for _ in range(200):
        v2, e, _, i2, _, p, *_ = vk._link_step(z, v2, e, P.vl_v, 0.0, lc, tab, cz, ENV_DT, n_sub, n_q, 0.0,
                                               0.0, P.v1_amp_v, 1e-3, np.empty(9), np.zeros(4))
        pk = max(pk, p)
    if n_sub == 17:
        assert abs(i2) == pytest.approx(i2_rm, rel=1e-4) and pk < 2.0 * i2_rm
    else:
        assert pk > 2.0 * i2_rm and abs(abs(i2) / i2_rm - 1.0) > 1e-3


# ---------------------------------------------------------------------------------------------- the envs
MODAL = EnvConfig(link_model="modal")
SHORT = EnvConfig(n_steps=40, link_model="modal")


def test_link_model_is_an_option_modal_the_default():
    """``modal`` (the exact-mode link) is the default since 2026-11-26 (issue 23), ``envelope`` (eq. 4) an option;
    an unknown model is refused naming the valid ones; the env's plant part is the one of the config (its state
    has the link's mode amplitudes only on the modal link)."""
    assert EnvConfig().link_model == "modal"
    with pytest.raises(ValueError, match=r"link_model='exact' is invalid; valid values: envelope, modal"):
        EnvConfig(link_model="exact")
    a, b = SbarChargingVectorEnv(2, "nominal", EnvConfig(link_model="envelope")), SbarChargingVectorEnv(2, "nominal")
    assert not hasattr(a.parts.plant, "mstate") and b.parts.plant.mstate.shape == (7, 2)
    assert type(a.parts.plant).__name__ == "PlantPart" and type(b.parts.plant).__name__ == "ModalPlantPart"
    # the repr (the oracle's disk-cache key) always names the link (the keys of the two links never meet, whichever
    # is the default), the modal step's options only when not at their defaults
    assert "link_model='modal'" in repr(EnvConfig()) and "hold_tol_a" not in repr(EnvConfig())
    assert "link_model='envelope'" in repr(EnvConfig(link_model="envelope"))
    assert "link_model='modal'" in repr(MODAL) and "v2_updates=34" in repr(EnvConfig(link_model="modal", v2_updates=34))
    # the sub-steps' refinement: named only when not the default's; bad values refused naming the valid range
    assert "v2_refine" not in repr(MODAL) and "v2_refine_levels=0" in repr(EnvConfig(v2_refine_levels=0))
    with pytest.raises(ValueError, match=r"v2_refine_levels=6 is invalid; valid range: integer 0\.\.5"):
        EnvConfig(v2_refine_levels=6)
    with pytest.raises(ValueError, match=r"v2_refine_tol=0.0 is invalid; valid range: \(0, inf\)"):
        EnvConfig(v2_refine_tol=0.0)
    with pytest.raises(ValueError, match=r"v2_refine_levels=True is invalid"):
        EnvConfig(v2_refine_levels=True)
    # one criterion for the env and the mission: EnvConfig's defaults are the kernel's constants
    from wpt_receiver.modal_kernel import REFINE_LEVELS, REFINE_TOL
    assert (EnvConfig().v2_refine_tol, EnvConfig().v2_refine_levels) == (REFINE_TOL, REFINE_LEVELS)
    # the CLI's --env form builds the same config (an int, so the same repr: the oracle's cache key)
    from policies.train import env_config
    assert repr(env_config({"link_model": "modal", "v2_refine_levels": "2"})) == \
        repr(EnvConfig(link_model="modal", v2_refine_levels=2))


def test_fewer_v2_updates_than_rectifier_periods_are_refused():
    """``v2_updates`` 1 .. n_sub - 1 (n_sub the rectifier periods per step: 17 at the default 100 us) hold V2 while i2
    turns (test_a_large_transient_settles_at_the_rm_state): under random duties 16 windows x 300 steps measured
    1 update 138 % / 450 % off the default's energy (nominal / random), 4 updates 21 %, 16 0.55-1.1 %. Refused
    with one line naming the value and the valid set at this ``dt_s``; 0, n_sub .. 1000 accepted, and at ``dt_s`` =
    one rectifier period (n_sub = 1) every count is."""
    assert EnvConfig().n_sub == 17
    for bad in (1, 4, 16):
        with pytest.raises(ValueError, match=rf"^v2_updates={bad} is invalid; valid: 0 \(one per rectifier period\) "
                                             r"or 17\.\.1000 at dt_s=0\.0001 s \(17 rectifier periods per step\)"):
            EnvConfig(v2_updates=bad)
    for ok in (0, 17, 18, 1000):
        assert EnvConfig(v2_updates=ok).modal_n_sub == (ok or 17)
    with pytest.raises(ValueError, match=r"v2_updates=33 is invalid; valid: 0 .* or 34\.\.1000 at dt_s=0\.0002 s"):
        EnvConfig(dt_s=2 * ENV_DT, v2_updates=33)
    assert EnvConfig(dt_s=T, v2_updates=1).modal_n_sub == 1
    with pytest.raises(ValueError, match=r"v2_updates=1000 is invalid; valid: 0 .* or none above 1000 at dt_s=0\.01 s"):
        EnvConfig(dt_s=1e-2, v2_updates=1000)
    with pytest.raises(ValueError) as e:
        EnvConfig(v2_updates=4)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("scenario", ["random", "detuned"])
def test_single_env_is_the_vector_row_on_the_modal_link(scenario):
    """The single env and row 0 of the vector env step the same compiled helpers: equal to the bit, through
    the vector env's autoreset, tuned and detuned (a detuned window: its C1, C2 in the link constants)."""
    fs, fv, fo = _run(scenario, cfg=SHORT)
    assert np.array_equal(fs, fv) and np.array_equal(fo[:, 0], fo[:, 1])
    assert np.ptp(fs[:, 1]) > 1.0   # the random duties move the link


def _wide_short(d):
    """A wrong short-window weight (3x): the shorted switches' excess in V2 tripled."""
    return 3.0 * (d + np.sin(np.pi * d) / np.pi)


def test_one_change_moves_single_and_vector_alike(monkeypatch):
    """A function of the modal step changed once (in envs/modal_step.py's source, run by the interpreter)
    changes the single env's and the vector env's trajectories alike: equal before and after, different."""
    for name in dir(vk):
        f = getattr(vk, name)
        if hasattr(f, "py_func"):
            monkeypatch.setattr(vk, name, f.py_func)
    cfg = EnvConfig(n_steps=12, link_model="modal")
    s0, v0, _ = _run("random", cfg=cfg, steps=12)
    monkeypatch.setattr(vk, "short_weight", _wide_short)
    s1, v1, _ = _run("random", cfg=cfg, steps=12)
    assert np.array_equal(s0, v0) and np.array_equal(s1, v1)
    # more resistance in the short window: less current where the duty is high, in both envs alike
    assert np.abs(s1 - s0)[:, 1:3].max() > 1e-3


@pytest.mark.parametrize("devices", ["ideal", "schottky"])
def test_modal_env_settles_at_the_exact_mode_rm_state(devices):
    """Full rectification settles at the periodic steady state of the exact-mode link
    (wpt_receiver.modal_kernel.steady_state: the harmonic balance's v2) at the window's Lm and VL, its
    peak the phase-aware instantaneous one, and within 0.3 % of eq. 4's closed-form RM current (the
    fundamentals agree in RM): with ideal devices and with R1 + 2 Ron, R2 + Rd, clamp VL + Vf."""
    cfg = EnvConfig(n_steps=400, devices=devices, link_model="modal")
    env = SbarChargingEnv(scenario="nominal", config=cfg)
    _, info = env.reset(seed=5)
    for _ in range(cfg.n_steps):
        _, _, _, _, info = env.step(np.array([-1.0], np.float32))   # RM
    dev, p = preset(devices), TABLE_I
    lc, tab = mk.link_constants(p, dev), mk.modal_table(p, dev)
    mc, z = np.empty(mk.N_MODES_C, dtype=complex), np.zeros(4)
    mk.modes(lc, info["lm_h"], mc)
    v1 = -1j * p.v1_amp_v
    vc = info["battery_v"] + dev.rect_vf_v
    v2 = mk.steady_state(lc, mc, tab, 0.0, v1, vc, z)
    i1, i2 = mk.phasors(mc, z, v1, v2)
    assert info["i2_a"] == pytest.approx(abs(i2), rel=1e-5) and info["i1_a"] == pytest.approx(abs(i1), rel=1e-5)
    assert info["i2_peak_a"] == pytest.approx(mk.inst_peak(lc, tab, 0.0, i2, vc), rel=1e-5)
    r1, r2, x = p.r1_ohm + 2 * dev.inv_switch.ron_ohm, p.r2_ohm + dev.rect_diode.rd_ohm + dev.rect_switch.body.rd_ohm, \
        p.omega_rad_s * p.lm_h
    vf = dev.rect_diode.vf0_v + dev.rect_switch.body.vf0_v
    i2_rm = (x * p.v1_amp_v - r1 * 4 / np.pi * (info["battery_v"] + vf)) / (r1 * r2 + x * x)
    assert info["i2_a"] == pytest.approx(i2_rm, rel=3e-3)


def test_modal_env_starts_in_its_steady_state():
    """Windows start at the exact-mode link's periodic steady state of their first duty: held at that duty the
    link stays (I2 within 1e-5 over 20 steps; measured 6e-8, only VL drifts). The duty is planned on eq. 4
    (the duty that delivers the first command there), whose v2 in phase with i2 is above the exact one's:
    the exact link delivers a little less than the command, measured 0.4-2.5 % on nominal windows (more at
    the small commands, where the duty is large)."""
    v = SbarChargingVectorEnv(64, "nominal", MODAL)
    _, info = v.reset(seed=1)
    d0, i2_0, cmd0 = info["d_short"].copy(), info["i2_a"].copy(), info["charge_cmd_a"].copy()
    ratio = info["rect_current_a"] / cmd0
    assert np.all(ratio < 1.0) and np.all(ratio > 0.97)
    for _ in range(20):
        _, _, _, _, info = v.step((2 * d0 - 1)[:, None].astype(np.float32))
    np.testing.assert_allclose(info["i2_a"], i2_0, rtol=1e-5)


def test_detuned_modal_rm_state_is_the_detuned_modes():
    """Detuned capacitors (C off by up to 2 %): held in RM the modal env settles at the exact-mode steady state
    of the detuned link (its C1, C2 in the modes), which differs from the tuned link's."""
    v = SbarChargingVectorEnv(num_envs=3, scenario={"base": "nominal", "c_detune": (-0.02, 0.02)}, config=MODAL)
    _, info = v.reset(seed=11)
    for _ in range(300):
        _, _, _, _, info = v.step(np.full((3, 1), -1.0, np.float32))
    link, dev = v.config.link, v.config.device_set()
    w, vf = link.omega_rad_s, dev.rect_vf_v
    cc1 = 1.0 / (w * w * link.l1_h) * (1.0 + v._c_rel[0])
    cc2 = 1.0 / (w * w * link.l2_h) * (1.0 + v._c_rel[1])
    v1 = -1j * link.v1_amp_v
    for e in range(3):
        got = []
        for c1, c2 in ((cc1[e], cc2[e]), (None, None)):
            lc = mk.link_constants(link, dev, c1, c2) if c1 is not None else mk.link_constants(link, dev)
            mc, z = np.empty(mk.N_MODES_C, dtype=complex), np.zeros(4)
            mk.modes(lc, float(v._lm_all[-1, e]), mc)
            v2e = mk.steady_state(lc, mc, v._tab, 0.0, v1, float(info["battery_v"][e]) + vf, z)
            got.append(abs(mk.phasors(mc, z, v1, v2e)[1]))
        assert info["i2_a"][e] == pytest.approx(got[0], rel=1e-6)
        assert abs(got[0] / got[1] - 1.0) > 1e-3   # the detuning matters


@pytest.mark.parametrize("c_rel", [0.0, 0.02])
def test_detuned_link_settles_where_the_switching_model_does(c_rel):
    """A window with C1 +c, C2 -c (schottky devices, stiff 30 V) dropped from d = 0.3 to RM: the modal link's
    |I2| settles within 1 % of the switching model's fundamental of the same circuit (measured -0.43 % at
    2 %, 0.00 % tuned). At +-4.3 % both block: test_detuned_modal_link_blocks_where_the_switching_model_does."""
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    dev = preset("schottky")
    w = P.omega_rad_s
    c1, c2 = (1 + c_rel) / (w * w * P.l1_h), (1 - c_rel) / (w * w * P.l2_h)
    d = np.r_[np.full(10, 0.3), np.zeros(190)]
    sw = SwitchingLink(P, SwitchingConfig(c1_f=c1, c2_f=c2, devices=dev)).simulate(d, ENV_DT).envelope()
    sw_end = sw["i2_fund_a"].to_numpy()[-50:]
    lc, tab = mk.link_constants(P, dev, c1, c2), mk.modal_table(P, dev)
    cfg = EnvConfig()
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, ENV_DT, cfg.modal_n_sub, cfg.modal_n_q, cz, True)
    v1, vf, dr = -1j * P.v1_amp_v, dev.rect_vf_v, dev.short_r_ohm - dev.rect_rd_ohm
    z = np.zeros(4)
    v2, e = mk.steady_state(lc, cz[CZ_MODES:CZ_STEP], tab, 0.3, v1, P.vl_v + vf, z), -1.0
    for dd in d:
        v2, e, _, i2, *_ = vk._link_step(z, v2, e, P.vl_v, dd, lc, tab, cz, ENV_DT, cfg.modal_n_sub, cfg.modal_n_q, vf,
                                         dr, P.v1_amp_v, 1e-3, np.empty(9), np.zeros(4))
    assert np.ptp(sw_end) < 1e-3 * sw_end.mean()                 # the switching model has settled
    assert abs(i2) == pytest.approx(sw_end.mean(), rel=0.01)
    if c_rel:   # the detuning matters: against the tuned link's RM steady state
        lt = mk.link_constants(P, dev)
        mt, zt = np.empty(mk.N_MODES_C, dtype=complex), np.zeros(4)
        mk.modes(lt, P.lm_h, mt)
        i2_tuned = abs(mk.phasors(mt, zt, v1, mk.steady_state(lt, mt, tab, 0.0, v1, P.vl_v + vf, zt))[1])
        assert sw_end.mean() < 0.75 * i2_tuned


def _random_run(n, h, seed=3):
    """Random duties (redrawn every 100 us) on ``random`` windows of the modal env with the step divided by
    ``h``; per-step arrays (T, n) of the info fields."""
    base = EnvConfig()
    cfg = EnvConfig(dt_s=base.dt_s / h, n_steps=base.n_steps * h, slow_every=base.slow_every * h, link_model="modal")
    venv = SbarChargingVectorEnv(num_envs=n, scenario="random", config=cfg)
    _, info = venv.reset(seed=seed)
    rng = np.random.default_rng(seed)
    rec = {k: [] for k in ("i2_a", "i2_peak_a", "i2_peak_envelope_a", "v2_v", "rect_current_a")}
    for k in range(cfg.n_steps - 1):   # one window each (no autoreset)
        if k % h == 0:
            a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        _, _, _, _, info = venv.step(a)
        for key in rec:
            rec[key].append(info[key].copy())
    return {k: np.array(v) for k, v in rec.items()}


def test_rectifier_absorbs_power_with_random_duties_on_the_modal_link():
    """(envmodal2's test_envs check, on the modal plant.) The SBAR's v2 follows i2's phase: with random duties
    the I2 envelope swings through zero, yet the SBAR output current stays >= 0 up to the fundamental's
    approximation of the diodes' current (where i2 reverses inside a rectifier period its projection on v2
    dips a little below 0) and the rectifier absorbs power on average; the instantaneous peak adds the
    ripple's excess (as low as -0.65 A: the 3rd harmonic flattens the crest when i2 is 0.4 rad off v2);
    the ringing is not pumped (halving the step does not raise the peak)."""
    r = _random_run(64, 1)
    assert r["i2_a"].min() < -5.0
    il = r["rect_current_a"]
    assert il.min() >= -0.2 and (il < 0.0).mean() < 1e-3 and il.mean() > 1.0
    assert (r["v2_v"] * np.abs(r["i2_a"])).mean() > 0.0
    assert np.all(r["i2_peak_envelope_a"] >= np.abs(r["i2_a"]))
    assert np.all(r["i2_peak_a"] >= r["i2_peak_envelope_a"] - 0.66)
    assert (r["i2_peak_a"] > r["i2_peak_envelope_a"] + 0.2).any()
    r2 = _random_run(64, 2)
    pk1, pk2 = np.abs(r["i2_a"]).max(), np.abs(r2["i2_a"][1::2]).max()
    assert pk2 < 1.05 * pk1 and pk1 < 100.0


@pytest.mark.parametrize("duty", [0.0, 0.4])
def test_modal_env_steady_state_is_the_missions_link_with_devices(duty):
    """(envmodal2's test_env_devices check, on the modal plant.) Held at a duty, the env settles at the
    mission's link's steady state (the exact modes with the schottky devices): |I1|, |I2| and I_L within
    1e-5; real parts cost 2-6 points of DC efficiency against ideal devices."""
    res = {}
    for devices in ("schottky", "ideal"):
        env = SbarChargingEnv(scenario="nominal", config=EnvConfig(devices=devices, n_steps=600, link_model="modal"))
        env.reset(seed=0)
        for _ in range(600):
            _, _, _, _, info = env.step(np.array([2 * duty - 1], np.float32))
        dev = preset(devices)
        lc, tab = mk.link_constants(P, dev), mk.modal_table(P, dev)
        mc, z = np.empty(mk.N_MODES_C, dtype=complex), np.zeros(4)
        mk.modes(lc, info["lm_h"], mc)
        v1, vc = -1j * P.v1_amp_v, info["battery_v"] + dev.rect_vf_v
        v2 = mk.steady_state(lc, mc, tab, duty, v1, vc, z)
        i1, i2 = mk.phasors(mc, z, v1, v2)
        il = 0.5 * (mk.sbar_v2(lc, tab, duty, i2, vc)[1] * i2.conjugate()).real
        assert info["i2_a"] == pytest.approx(abs(i2), rel=1e-5) and info["i1_a"] == pytest.approx(abs(i1), rel=1e-5)
        assert info["rect_current_a"] == pytest.approx(il, rel=1e-5)
        res[devices] = info["battery_v"] * il / (0.5 * (v1 * i1.conjugate()).real)
    assert res["ideal"] - 0.06 < res["schottky"] < res["ideal"] - 0.02


def test_detuned_modal_link_blocks_where_the_switching_model_does():
    """C1 +4.3 %, C2 -4.3 % (schottky, stiff 30 V): the open-circuit emf w Lm V1 / |Z1| (~25 V) is below the
    clamp VL + Vf, so the diodes cannot conduct in RM; the switching model settles at no transfer. Dropped
    from short mode (d = 1, conducting) to RM, the modal link's |I2| settles at 0 without ringing (it rang
    at 0-5.4 A: the closed-form commutation had no root and put V2 at a window edge, in quadrature), and
    the modal steady state in RM is the blocking one (it claimed 6.6 A: a fixed point without a root)."""
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    dev = preset("schottky")
    w = P.omega_rad_s
    c1, c2 = 1.043 / (w * w * P.l1_h), 0.957 / (w * w * P.l2_h)
    z1 = complex(P.r1_ohm + dev.inv_r_ohm, w * P.l1_h - 1.0 / (w * c1))
    assert w * P.lm_h * P.v1_amp_v / abs(z1) < P.vl_v + dev.rect_vf_v    # the premise: emf below the clamp
    d = np.r_[np.full(10, 1.0), np.zeros(190)]
    sw = SwitchingLink(P, SwitchingConfig(c1_f=c1, c2_f=c2, devices=dev)).simulate(d, ENV_DT).envelope()
    fund = sw["i2_fund_a"].to_numpy()
    assert fund[:10].max() > 1.0 and np.all(fund[-50:] < 1e-3)
    lc, tab = mk.link_constants(P, dev, c1, c2), mk.modal_table(P, dev)
    cfg = EnvConfig()
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, ENV_DT, cfg.modal_n_sub, cfg.modal_n_q, cz, True)
    v1, vf, dr = -1j * P.v1_amp_v, dev.rect_vf_v, dev.short_r_ohm - dev.rect_rd_ohm
    mc = cz[CZ_MODES:CZ_STEP]
    z = np.zeros(4)
    v2 = mk.steady_state(lc, mc, tab, 0.0, v1, P.vl_v + vf, z)
    assert abs(mk.phasors(mc, z, v1, v2)[1]) < 1e-9 and abs(v2) <= 4.0 / np.pi * (P.vl_v + vf)
    v2, e, got = mk.steady_state(lc, mc, tab, 1.0, v1, P.vl_v + vf, z), -1.0, []
    for dd in d:
        v2, e, _, i2, _, _, il, *_ = vk._link_step(z, v2, e, P.vl_v, dd, lc, tab, cz, ENV_DT, cfg.modal_n_sub,
                                                 cfg.modal_n_q, vf, dr, P.v1_amp_v, 1e-3, np.empty(9), np.zeros(4))
        got.append(abs(i2))
    assert max(got[:10]) > 1.0 and max(got[-50:]) < 1e-9 and abs(il) < 1e-4   # I_L: the held V2 within a sub-step


def test_parallel_chunks_are_the_serial_step_to_the_bit():
    """The modal step over chunks run with ``prange`` (``env_step``, n_chunks > 1) equals the serial step
    (``step_kernel``, the replay's entry) to the bit, on a step after random duties, a slow segment change
    and autoresets (SHORT: 40-step episodes): each window's arithmetic does not depend on its chunk."""
    from envs.core import OBS_OFFSET, OBS_SCALE
    from envs.layout import INFO
    n = 48
    env = SbarChargingVectorEnv(n, "random", SHORT, num_threads=1)
    env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(51):   # past one episode end (autoreset) and into a new slow segment
        env.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    plant, grabbed = env.parts.plant, []

    def grab(d, k, scenario, objective, par, *rest):
        grabbed.append((d.copy(), k.copy(), scenario, objective, par.copy(), plant.state.copy(), plant.mstate.copy(),
                        plant.j.copy(), plant.coef_cur.copy(), tuple(a.copy() for a in objective.ep)))
    plant.step = grab
    env.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    d, k, sc, _, par, state, mstate, j, cz, ep = grabbed[0]
    outs = []
    for chunks in (1, 5):
        a = [state.copy(), mstate.copy(), k.copy(), j.copy(), cz.copy(), tuple(x.copy() for x in ep)]
        obs, rew = np.empty((n, 8), np.float32), np.empty(n)
        trunc, info = np.empty(n, bool), np.empty((n, len(INFO)))
        args = (d, a[0], a[1], a[2], a[3], plant.lc, a[4], plant.bat, sc.cmd, sc.noise, plant.lm_all, a[5],
                SHORT.slow_every, plant.n_sub, par, OBS_SCALE, OBS_OFFSET, plant.tab, obs, rew, trunc, info)
        vk.step_kernel(*args) if chunks == 1 else vk.env_step(*args, chunks)
        outs.append((obs, rew, trunc, info, *a[:5], *a[5]))
    assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(*outs))
    assert not np.array_equal(outs[0][4], state) and np.ptp(outs[0][3][:, INFO.i2_peak_a]) > 1.0   # it stepped


# ------------------------------------------------------------- fewer V2 updates (issue 23: a cheaper estimator?)
def _updates_run(d_seq, n_sub, c_rel=(0.0, 0.0), devices=IDEAL, levels=None):
    """The link step in ``n_sub`` sub-steps per 100 us (|I2| sampled once per rectifier period at least) over
    ``d_seq`` from the exact-mode steady state of its first duty, C1, C2 off resonance by ``c_rel``, the
    sub-steps' refinement the default's (``levels`` None) or ``levels`` (0: none): the instantaneous peak per
    step [A]."""
    w = P.omega_rad_s
    c1, c2 = (1.0 + c_rel[0]) / (w * w * P.l1_h), (1.0 + c_rel[1]) / (w * w * P.l2_h)
    lc, tab = mk.link_constants(P, devices, c1, c2), mk.modal_table(P, devices)
    n_q = max(1, -(-17 // n_sub))
    cz = np.zeros(N_CZ, dtype=complex)
    cfg = EnvConfig() if levels is None else EnvConfig(v2_refine_levels=levels)
    vk._segment(lc, P.lm_h, ENV_DT, n_sub, n_q, cz, True, cfg.v2_refine_tol, cfg.v2_refine_levels)
    v1, vf, dr = -1j * P.v1_amp_v, devices.rect_vf_v, devices.short_r_ohm - devices.rect_rd_ohm
    z = np.zeros(4)
    v2, e, pk = mk.steady_state(lc, cz[CZ_MODES:CZ_STEP], tab, float(d_seq[0]), v1, P.vl_v + vf, z), -1.0, []
    for d in d_seq:
        v2, e, _, _, _, p, *_ = vk._link_step(z, v2, e, P.vl_v, d, lc, tab, cz, ENV_DT, n_sub, n_q, vf, dr,
                                              P.v1_amp_v, 1e-3, np.empty(9), np.zeros(4))
        pk.append(p)
    return np.array(pk)


def test_fewer_v2_updates_agree_on_the_paper_trajectories_not_on_detuned_windows():
    """The kernel driven with 2-8 V2 updates per 100 us instead of 17 (``v2_updates`` refuses them) gives the
    paper's three trajectories' peak within 0.3 % of the env's step (measured <= 0.22 %), but not a detuned window (C1 +4 %, C2 -0.5 %,
    schottky, d = 0.3 held from the harmonic balance's steady state, which the stepped link leaves): after
    10 ms 8 updates sit 61 % above 17 (4.39 A against 2.73 A) and 2 updates at 18 A, so no smaller count is a
    drop-in estimator of the env's step (benchmarks/modal_substeps_study.py: on 100 detuned windows under
    model_based duties 8 updates put a third of the windows' peaks > 0.5 % off, up to +156 %; and it would
    save at most 1.2-1.4x of the held-duty step's CPU, docs/performance.md)."""
    for name in ("step", "ramp", "proposed"):
        d = _trajectory(name, "v2", ENV_DT)
        ref = _updates_run(d, 17).max()
        for n_sub in (2, 4, 8):
            assert _updates_run(d, n_sub).max() == pytest.approx(ref, rel=3e-3)
    d, dev = np.full(100, 0.3), preset("schottky")
    ref = _updates_run(d, 17, (0.04, -0.005), dev)
    assert ref.max() > 2.0 * ref[-1]   # the window leaves its starting point (a large transient)
    for n_sub in (2, 8):
        assert _updates_run(d, n_sub, (0.04, -0.005), dev)[-1] > 1.4 * ref[-1]


@pytest.mark.parametrize("case", ["drop", "random"])
def test_large_transient_peak_converges_with_v2_updates(case):
    """Two large transients on Table I (a window at d = 0.32 dropped to RM; duties redrawn at random every 100
    us), after 4 ms at the first duty (the switching model starts at rest). One V2 update per rectifier period
    alone (refinement off, the kernel before the refinement) is not converged: its largest instantaneous peak
    is 21.7 % (drop) / 9.1 % (random) below the switching model's and 25 % / 10 % below the envelope's
    fine-step limit (1088 updates per 100 us). The default step (17 sub-steps, each whose I2 moves by more than
    5 % redone in up to 8 pieces, ``envs.modal_step._refine``) is within 3 % of that limit (measured -2.1 % /
    -0.5 % against 4352 updates) and within 5 % of the switching model (+2.5 % / +0.7 %; the envelope's limit
    itself is +4.7 % / +1.2 %: the model's own error in such a transient; docs/performance.md, "Adaptive
    refinement of the modal env step")."""
    pre, rng = 40, np.random.default_rng(1)
    d = (np.r_[np.full(pre, 0.32), np.zeros(150)] if case == "drop"
         else np.r_[np.full(pre, 0.5), rng.uniform(0.0, 1.0, 150)])
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    env = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64)).simulate(d, ENV_DT).envelope()
    t = env["t_s"].to_numpy()
    sw = env["i2_env_a"].to_numpy()[t >= pre * ENV_DT].max()
    coarse = _updates_run(d, 17, levels=0)[pre:].max()
    limit = _updates_run(d, 1088, levels=0)[pre:].max()
    got = _updates_run(d, 17)[pre:].max()
    assert got == pytest.approx(limit, rel=0.03) and got == pytest.approx(sw, rel=0.05)
    assert coarse < 0.95 * min(limit, sw)


def _energy_at(cfg, scenario, n=16, steps=300, seed=11):
    """Total rectified energy [J] of ``n`` windows over one episode of uniform random actions (a new duty every step)."""
    venv = SbarChargingVectorEnv(n, scenario, cfg, num_threads=1)
    venv.reset(seed=seed)
    rng = np.random.default_rng(seed)
    total = sum(venv.step(rng.uniform(-1.0, 1.0, (n, 1)).astype(np.float32))[4]["energy_j"].sum() for _ in range(steps))
    venv.close()
    return total


@pytest.mark.parametrize("scenario", ["nominal", "random"])
def test_one_rectifier_period_steps_are_refined_in_transients(scenario):
    """``dt_s`` = one rectifier period (``n_sub`` = 1): a step away from the steady state is split into its one
    sub-step, so the sub-step refinement applies, as at 17 (the eq. 4 env's n_sub = 1 fix, tests/test_env_substeps.py).
    Until 2026-11-28 the split was gated on ``n_sub > 1``: at ``n_sub`` = 1 no step was ever refined and the energy
    under random duties was 0.34 % (nominal) / 0.58 % (random) below 64 V2 updates per step (measured; the step
    without refinement, ``v2_refine_levels=0``, is that kernel to the bit); now +0.03 % / -0.01 %. Tolerance 0.1 %."""
    period = EnvConfig().link.rectifier_period_s
    one = EnvConfig(link_model="modal", dt_s=period)
    assert one.modal_n_sub == 1 and one.modal_n_q == 1
    ref = _energy_at(EnvConfig(link_model="modal", dt_s=period, v2_updates=64), scenario)
    unrefined = _energy_at(EnvConfig(link_model="modal", dt_s=period, v2_refine_levels=0), scenario)
    got = _energy_at(one, scenario)
    assert abs(unrefined - ref) / ref > 0.002   # (the case needs the refinement)
    assert abs(got - ref) / ref < 0.001, (got, ref, unrefined)


def _window_peaks(cfg, acts_or_policy, n=16, seed=1000):
    """Largest instantaneous peak [A] per window of ``n`` nominal windows (seeds ``seed + i``) of the modal env
    with ``cfg``; ``acts_or_policy`` a policy name (its duties are returned) or the (T, n, 1) actions to replay."""
    from policies import make
    venv = SbarChargingVectorEnv(num_envs=n, scenario="nominal", config=cfg, num_threads=1)
    obs, _ = venv.reset(seed=[seed + i for i in range(n)])
    pol = make(acts_or_policy, venv.policy_context) if isinstance(acts_or_policy, str) else None
    if pol is not None and hasattr(pol, "reset"):
        pol.reset(n)
    acts, pk = [], np.zeros(n)
    for k in range(cfg.n_steps):
        if pol is None:
            a = acts_or_policy[k]
        else:
            a = (2.0 * np.clip(np.asarray(pol.act(obs), float).reshape(n), 0.0, 1.0) - 1.0)[:, None].astype(np.float32)
        acts.append(a)
        obs, _, _, _, info = venv.step(a)
        pk = np.maximum(pk, info["i2_peak_a"])
    venv.close()
    return pk, np.array(acts)


@pytest.mark.parametrize("policy", ["model_based", "random"])
def test_more_v2_updates_than_rectifier_periods_on_env_windows(policy):
    """``v2_updates`` above the rectifier periods per step (68 per 100 us; one |I2| sample per sub-step) is
    stepped as asked (it was capped at 17), and the sub-steps' refinement (``v2_refine_levels``) is what the
    default adds to one V2 per rectifier period. On nominal windows under the model-based controller (smooth
    control) the refinement never triggers: the default's windows' peaks equal those without it to the bit,
    and 68 updates move them by < 0.05 % (measured 0.006 % on 100 windows). Under random duties (a large
    transient every step) the step without refinement is low (here -3 % on average; on 100 windows up to
    -24 %) and the default agrees with 68 updates (here within 1 % on average)."""
    fine = EnvConfig(link_model="modal", v2_updates=68)
    coarse = EnvConfig(link_model="modal", v2_refine_levels=0)
    assert fine.modal_n_sub == 68 and fine.modal_n_q == 1 and MODAL.modal_n_sub == 17
    if policy == "model_based":
        ref, acts = _window_peaks(MODAL, policy)
    else:
        rng = np.random.default_rng(5)
        acts = rng.uniform(-1.0, 1.0, (MODAL.n_steps, 16, 1)).astype(np.float32)
        ref, _ = _window_peaks(MODAL, acts)
    got, _ = _window_peaks(fine, acts)
    old, _ = _window_peaks(coarse, acts)
    if policy == "model_based":
        np.testing.assert_array_equal(old, ref)
        np.testing.assert_allclose(got, ref, rtol=5e-4)
    else:
        assert np.mean(old / ref - 1.0) < -0.02 and np.sum(old < ref) >= 12
        assert abs(np.mean(got / ref - 1.0)) < 0.01


def test_substeps_compiled_without_reference_counting():
    """``_substeps`` runs without numba's reference counting (numba's private ``_nrt`` option: docs/performance.md,
    "The modal env step without reference counts"); a numba that drops or renames the option must show up here,
    not as a silent slowdown or an import error in the default env."""
    import envs.modal_step as ms
    assert ms._substeps.targetoptions.get("_nrt") is False


def test_modal_step_interpreted_to_the_bottom_matches_the_compiled_step(monkeypatch):
    """The compiled single step against the same sources *all* interpreted: every numba dispatcher of
    :mod:`envs.modal_step` (``_substeps``, compiled with ``_nrt=False``, and the helpers it inlines) replaced by its
    ``py_func`` in the module, so nothing below the entry runs compiled (``compiled=False`` alone swaps only the
    entry). Random actions through a whole episode; equal to rounding (the compiled code may fuse operations)."""
    import numba

    import envs.modal_step as ms
    from envs import EnvConfig, SbarChargingEnv
    cfg = EnvConfig(link_model="modal")
    fast = SbarChargingEnv(scenario="random", compiled=True, config=cfg)
    fast.reset(seed=3)
    fast.step(np.zeros(1, np.float32))   # compiled (or loaded) before the module's dispatchers are swapped
    swapped = [k for k, v in vars(ms).items() if isinstance(v, numba.core.registry.CPUDispatcher)]
    assert "_substeps" in swapped
    for k in swapped:
        monkeypatch.setattr(ms, k, getattr(ms, k).py_func)
    calls, sub = [0], ms._substeps

    def counted(*args):
        calls[0] += 1
        return sub(*args)
    monkeypatch.setattr(ms, "_substeps", counted)
    ref = SbarChargingEnv(scenario="random", compiled=False, config=cfg)
    (of, _), (orf, _) = fast.reset(seed=3), ref.reset(seed=3)
    assert np.array_equal(of, orf)
    rng = np.random.default_rng(11)
    for _ in range(fast.config.n_steps):
        a = rng.uniform(-1, 1, 1).astype(np.float32)
        f, r = fast.step(a), ref.step(a)
        np.testing.assert_allclose(f[0], r[0], rtol=1e-6, atol=1e-6)   # float32 observations
        assert f[1] == pytest.approx(r[1], rel=1e-9, abs=1e-12)
        assert f[4]["i2_peak_a"] == pytest.approx(r[4]["i2_peak_a"], rel=1e-9, abs=1e-12)
        if f[2] or f[3]:
            break
    assert calls[0] > 10   # the interpreted sub-step loop ran
