"""The compiled exact-mode link step (wpt_receiver.modal_kernel) against the numpy exact-mode model
(wpt_receiver.modal, eig + harmonic balance per step), the harmonic balance itself
(wpt_receiver.peak), the switching model on the ramp, and across the default mission's Lm and
battery range; its energy balance closes to rounding."""

import numpy as np
import pytest

from wpt_receiver import TABLE_I
from wpt_receiver import modal_kernel as mk
from wpt_receiver.devices import IDEAL, preset
from wpt_receiver.modal import ModalEnvelope, simulate_modal
from wpt_receiver.peak import SbarHarmonics
from wpt_receiver.references import reference_duty
from wpt_receiver.sbar import v2_from_duty

P = TABLE_I
T = P.rectifier_period_s
SCHOTTKY = preset("schottky")


def _modes(p, devices=IDEAL):
    lc = mk.link_constants(p, devices)
    mc = np.empty(mk.N_MODES_C, dtype=complex)
    mk.modes(lc, p.lm_h, mc)
    return lc, mc


@pytest.mark.parametrize("lm_h, devices", [(6.25e-6, IDEAL), (5.2e-6, SCHOTTKY), (6.9e-6, SCHOTTKY), (2e-7, IDEAL)])
def test_modes_equal_the_eigendecomposition(lm_h, devices):
    p = P.with_(lm_h=lm_h)
    _, mc = _modes(p, devices)
    me = ModalEnvelope(p, devices)
    a, b = np.argsort(me.lam.imag), np.argsort(mc[:2].imag)
    assert mc[:2][b] == pytest.approx(me.lam[a], rel=1e-9)
    shape_i2 = np.array([mc[mk.MC_S + 1], mc[mk.MC_S + 5]])[b]
    for g_ref, g in ((me.g1, mc[mk.MC_G1:mk.MC_G1 + 2]), (me.g2, mc[mk.MC_G2:mk.MC_G2 + 2])):
        # the mode's transfer from an input to i2 (residue) does not depend on how the mode is scaled
        assert shape_i2 * g[b] == pytest.approx((me.v_i2 * g_ref)[a], rel=1e-8, abs=1e-9 * np.abs(me.v_i2 * g_ref).max())
    assert mc[mk.MC_D + 2:mk.MC_D + 4] == pytest.approx(me.d_i2, rel=1e-8, abs=1e-12)
    assert mc[mk.MC_D:mk.MC_D + 2] == pytest.approx(me.d_i1, rel=1e-8, abs=1e-12)


def _random_step(rng, lc, mc, dt):
    z = rng.normal(0, 10, 4)
    v1 = complex(*rng.normal(0, 30, 2))
    v2 = complex(*rng.normal(0, 30, 2))
    zc = np.empty(mk.N_ZOH_C, dtype=complex)
    mk.zoh(mc, dt, zc)
    return z, v1, v2, zc


@pytest.mark.parametrize("dt", [1e-7, T, 1e-4, 0.3])
def test_step_energy_balance_closes(dt):
    lc, mc = _modes(P.with_(lm_h=5.5e-6), SCHOTTKY)
    rng = np.random.default_rng(4)
    for _ in range(20):
        z, v1, v2, zc = _random_step(rng, lc, mc, dt)
        w0 = mk.stored_energy_j(lc, mc, z, v1, v2, 5.5e-6)
        out = np.empty(9)
        mk.step(lc, mc, zc, dt, z, v1, v2, out)
        w1 = mk.stored_energy_j(lc, mc, z, v1, v2, 5.5e-6)
        src, coil, rect = out[6:9]
        scale = abs(src) + coil + abs(rect) + w0 + w1
        assert src == pytest.approx(w1 - w0 + coil + rect, abs=1e-11 * scale)
        assert coil > 0


def test_step_integrals_against_quadrature():
    lc, mc = _modes(P)
    rng = np.random.default_rng(5)
    z0, v1, v2, _ = _random_step(rng, lc, mc, 1.0)
    h = 3e-4
    ts = np.linspace(0.0, h, 2001)
    i1 = np.empty(len(ts), dtype=complex)
    i2 = np.empty(len(ts), dtype=complex)
    zc, out = np.empty(mk.N_ZOH_C, dtype=complex), np.empty(9)
    for n, t in enumerate(ts):
        z = z0.copy()
        if t > 0:
            mk.zoh(mc, t, zc)
            mk.step(lc, mc, zc, t, z, v1, v2, out)
        i1[n], i2[n] = mk.phasors(mc, z, v1, v2)
    z = z0.copy()
    mk.zoh(mc, h, zc)
    mk.step(lc, mc, zc, h, z, v1, v2, out)
    from scipy.integrate import simpson
    assert complex(out[2], out[3]) == pytest.approx(simpson(i2, x=ts), rel=1e-8)
    assert complex(out[0], out[1]) == pytest.approx(simpson(i1, x=ts), rel=1e-8)
    assert out[4] == pytest.approx(simpson(np.abs(i1) ** 2, x=ts), rel=1e-8)
    assert out[5] == pytest.approx(simpson(np.abs(i2) ** 2, x=ts), rel=1e-8)


@pytest.fixture(scope="module")
def table():
    return mk.modal_table(P)


def test_sbar_v2_is_eq9_without_ripple_and_the_balance_with_it(table):
    lc, _ = _modes(P)
    d = np.linspace(0, 1, 11)
    flat = np.zeros_like(table)            # no harmonics: the zero crossing stays at pi/2 - arg I2
    v = [mk.sbar_v2(lc, flat, x, 12.0 + 0j, P.vl_v)[0] for x in d]
    assert np.allclose(v, v2_from_duty(d, P.vl_v), atol=1e-12)
    sh = SbarHarmonics(P)
    rng = np.random.default_rng(6)
    d, amp, ph = rng.uniform(0, 1, 300), rng.uniform(3, 40, 300), rng.uniform(-0.16, 0.16, 300)
    i2 = amp * np.exp(1j * ph) * rng.choice([-1, 1], 300)
    ref = sh.v2_fundamental(d, i2)
    got = np.array([mk.sbar_v2(lc, table, d[k], complex(i2[k]), sh.clamp_v)[0] for k in range(300)])
    assert np.abs(got - ref).max() < 0.004 * P.v2_rm_amp_v      # 0.15 V: eq. 9 misses up to 3 V
    assert np.abs(v2_from_duty(d, P.vl_v) * np.sign(i2.real) - ref).max() > 1.0


def test_inst_peak_matches_the_harmonic_balance(table):
    lc, _ = _modes(P)
    sh = SbarHarmonics(P)
    rng = np.random.default_rng(7)
    d, amp, ph = rng.uniform(0, 1, 300), rng.uniform(8, 60, 300), rng.uniform(-0.16, 0.16, 300)
    i2 = amp * np.exp(1j * ph)
    got = np.array([mk.inst_peak(lc, table, d[k], complex(i2[k]), sh.clamp_v) for k in range(300)])
    assert got == pytest.approx(sh.peak(d, i2), rel=4e-3)
    got0 = np.array([mk.inst_peak(lc, table, d[k], complex(amp[k]), sh.clamp_v) for k in range(300)])
    assert got0 == pytest.approx(sh.peak(d, amp), rel=1e-3)


def _traj(name, p, kind="v2"):
    return reference_duty(name, p, 0.5e-3, 2.5e-3 if name == "step" else 6.5e-3, T, ramp_kind=kind)[1]


@pytest.mark.parametrize("name", ["step", "ramp", "proposed"])
def test_paper_trajectories_within_half_percent_of_the_exact_modes(name, table):
    d = _traj(name, P)
    ref = simulate_modal(P, d, T)
    got = mk.simulate(P, d, T, table=table)
    assert got["peak_i2_a"].max() == pytest.approx(ref["peak_i2_a"].max(), rel=5e-3)
    assert np.abs(got["i2"] - ref["i2"]).max() < 2e-3 * np.abs(ref["i2"]).max()
    src, coil, rect, dw, jumps = got["energy_j"]
    assert src == pytest.approx(dw + coil + rect - jumps, rel=1e-9)


@pytest.mark.parametrize("kind", ["v2", "duty"])
def test_ramp_within_1pct_of_the_switching_model(kind, table):
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    d = _traj("ramp", P, kind)
    sw = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64)).simulate(d, T).envelope()["i2_env_a"].to_numpy()
    got = mk.simulate(P, d, T, table=table)["peak_i2_a"]
    assert got.max() == pytest.approx(sw.max(), rel=0.01)


@pytest.fixture(scope="module")
def mission_lm():
    """Lm [H] along the default mission where its pads are energised (k above tx_min_k), and the hover-gap Lm."""
    from mission_sim.config import load_config
    from mission_sim.world.runner import _lm_along
    from mission_sim.world.trajectory import plan_mission
    cfg = load_config()
    model = cfg.coupling.model()
    lm, _ = _lm_along(cfg, model, plan_mission(cfg))
    on = lm / np.sqrt(model.l1_h * model.l2_h) >= cfg.coupling.tx_min_k
    return lm[on], float(model.lm_h(0.0, 0.0, cfg.mission.hover_gap_m))


@pytest.mark.parametrize("end, vl_v", [(0, 33.0), (1, 27.0)])
@pytest.mark.parametrize("name", ["ramp", "proposed"])
def test_default_mission_range_within_half_percent(mission_lm, end, vl_v, name):
    lm_on, lm_hover = mission_lm
    tab = mk.modal_table(P.with_(lm_h=lm_hover), SCHOTTKY)       # one table, at the hover gap and 30 V
    p = P.with_(lm_h=float(lm_on.min() if end == 0 else lm_on.max()), vl_v=vl_v)
    d = _traj(name, p)
    ref = simulate_modal(p, d, T, devices=SCHOTTKY)["peak_i2_a"].max()
    assert mk.simulate(p, d, T, devices=SCHOTTKY, table=tab)["peak_i2_a"].max() == pytest.approx(ref, rel=5e-3)


def test_rect_affine_is_the_steps_rectified_current(table):
    """The battery node's affine I_L(VL) equals the DC current of the step taken at that VL."""
    lc, mc = _modes(P.with_(lm_h=5.8e-6), SCHOTTKY)
    rng = np.random.default_rng(8)
    for dt in (T, 1e-4, 0.2):
        z, v1, _, zc = _random_step(rng, lc, mc, dt)
        i2 = mk.phasors(mc, z, v1, 0j)[1]
        d = rng.uniform(0, 0.9)
        _, f = mk.sbar_v2(lc, table, d, i2, 30.0 + lc[mk.LC_VF])
        v2x = f * lc[mk.LC_VF] + lc[mk.LC_DR_SHORT] * (d + np.sin(np.pi * d) / np.pi) * i2
        a0, a1 = mk.rect_affine(mc, zc, dt, z, v1, f, v2x)
        for vl in (27.0, 33.0):
            out = np.empty(9)
            mk.step(lc, mc, zc, dt, z.copy(), v1, f * vl + v2x, out)
            il = mk.rect_current_a(f, complex(out[2], out[3]), dt)
            assert a0 + a1 * vl == pytest.approx(il, rel=1e-9, abs=1e-12)


def test_compiled_table_equals_the_numpy_harmonic_balance(table):
    """build_table's compiled balance and peak search are SbarHarmonics' (numpy), point for point."""
    sh = SbarHarmonics(P)
    u = np.linspace(-1, 1, mk.N_PHI)
    phis, ds = 0.5 * np.pi * u * np.abs(u), np.linspace(0, 1, mk.N_D)
    rhos = mk.RHO_MAX * np.linspace(0, 1, mk.N_RHO) ** 2
    rng = np.random.default_rng(0)
    a, b, c = rng.integers(0, mk.N_PHI, 200), rng.integers(0, mk.N_D, 200), rng.integers(1, mk.N_RHO, 200)
    ip = rhos[c] * sh.clamp_v * np.exp(1j * phis[a])
    ip = np.where(ip.real < 0, ip + 1e-12, ip)
    _, ih, e = sh.balance(ds[b], ip)
    for _ in range(6):   # the crossing itself, harmonics held (the table's plane 0 is not clipped to the gate window)
        g, dg = sh._value(e, ip, ih, sh.n)
        e = np.clip(e - np.clip(np.where(dg < 0, g / np.where(dg < 0, dg, -1.0), 0.0), -0.3, 0.3), 0.0, np.pi)
    assert table[0, a, b, c] == pytest.approx(e - 0.5 * np.pi + np.angle(ip), abs=1e-10)
    assert table[1, a, b, c] == pytest.approx((sh.peak(ds[b], ip) - np.abs(ip)) / sh.clamp_v, abs=1e-10)


@pytest.mark.parametrize("dt", [1e-7, T, 1e-4])
def test_end_i2_is_advance_z_then_phasors_to_the_bit(dt):
    """:func:`end_i2` (scalars) is :func:`advance_z` then :func:`phasors` (the state array) to the last bit;
    the readout is phasors' I2 to the bit; a step from the steady amplitudes stays there (to rounding)."""
    lc, mc = _modes(P.with_(lm_h=5.5e-6), SCHOTTKY)
    rng = np.random.default_rng(11)
    for _ in range(20):
        z, v1, v2, zc = _random_step(rng, lc, mc, dt)
        z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
        assert mk.readout(mc, 1, z0, z1, v1, v2) == mk.phasors(mc, z, v1, v2)[1]
        ref = z.copy()
        mk.advance_z(mc, zc, ref, v1, v2)
        assert mk.end_i2(mc, zc, z0, z1, v1, v2) == mk.phasors(mc, ref, v1, v2)[1]
        zs0, zs1 = mk.steady_modes(mc, v1, v2)
        zs = np.array([zs0.real, zs0.imag, zs1.real, zs1.imag])
        held = zs.copy()
        mk.advance_z(mc, zc, held, v1, v2)
        assert held == pytest.approx(zs, rel=1e-12, abs=1e-12 * np.abs(zs).max())


@pytest.mark.parametrize("c1_scale, lm_h", [(1.0, 6.25e-6), (0.7, 6.25e-6), (1.3, 3e-6), (0.7, 9e-6)])
def test_blocking_v2_holds_the_steady_i2_at_zero(c1_scale, lm_h):
    """At V2 = :func:`blocking_v2` the steady state has I2 = 0 (to rounding against the short-mode I2), and
    then the secondary only carries the induced emf: ``|V2| = omega Lm |V1| / |Z1|``, ``|I1| = |V1| / |Z1|``
    with ``Z1 = R1 + j (omega L1 - 1 / (omega C1))`` (the phasor circuit, independent of the modes). A C1
    detuned enough puts it within the clamp: :func:`steady_state` then blocks (returns it, I2 = 0)."""
    w = P.omega_rad_s
    lc = mk.link_constants(P, c1_f=c1_scale / (w * w * P.l1_h))
    mc = np.empty(mk.N_MODES_C, dtype=complex)
    mk.modes(lc, lm_h, mc)
    v1 = complex(0.0, -P.vdc_v)
    v2b = mk.blocking_v2(mc, v1)
    zs0, zs1 = mk.steady_modes(mc, v1, v2b)
    i2_short = abs(mk.readout(mc, 1, *mk.steady_modes(mc, v1, 0j), v1, 0j))
    assert abs(mk.readout(mc, 1, zs0, zs1, v1, v2b)) < 1e-12 * i2_short
    z1_ohm = abs(complex(lc[mk.LC_R1], w * P.l1_h - 1.0 / (w * lc[mk.LC_C1])))
    assert abs(v2b) == pytest.approx(w * lm_h * P.vdc_v / z1_ohm, rel=1e-9)
    assert abs(mk.readout(mc, 0, zs0, zs1, v1, v2b)) == pytest.approx(P.vdc_v / z1_ohm, rel=1e-9)
    z = np.zeros(4)
    vc = P.vl_v
    v2 = mk.steady_state(lc, mc, mk.modal_table(P), 0.0, v1, vc, z)
    if abs(v2b) <= 4 / np.pi * vc:   # within the clamp at d = 0: the rectifier blocks
        assert c1_scale != 1.0 and v2 == v2b and abs(mk.phasors(mc, z, v1, v2)[1]) < 1e-12 * i2_short
    else:                            # the tuned link conducts: the emf far above the clamp
        assert c1_scale == 1.0 and abs(mk.phasors(mc, z, v1, v2)[1]) > 0.5 * i2_short


def test_held_peak_fused_substep_is_sbar_v2_then_inst_peak_to_the_bit(table):
    """:func:`held_peak`'s fused sub-step (i2's polar form and table cell shared by a sub-step's end peak and
    the next edge; the duty's terms once per duty) gives the same numbers to the last bit as the unfused
    :func:`sbar_v2`, :func:`advance_z`, :func:`phasors`, :func:`inst_peak` sequence, from states of any phase
    (Re I2 of both signs, so both folds), over duties with windows from none to short mode."""
    lc, mc = _modes(P, SCHOTTKY)
    tab = mk.modal_table(P, SCHOTTKY)
    rng = np.random.default_rng(5)
    vc, v1 = P.vl_v + SCHOTTKY.rect_vf_v, -1j * P.v1_amp_v
    zc = np.empty(mk.N_ZOH_C, dtype=complex)
    mk.zoh(mc, T, zc)
    no_tail = (np.zeros((3, 3), complex), np.zeros(3, complex), np.zeros(3), 0.0)
    signs = set()
    for _ in range(12):
        z0 = rng.normal(0.0, 1.0, 4) * 15.0
        v2_0 = complex(*rng.normal(0.0, 20.0, 2))
        d = np.clip(rng.uniform(0.0, 1.0) + np.cumsum(rng.normal(0.0, 0.15, 8)), 0.0, 1.0)
        sub = int(rng.integers(1, 4))
        z, v2, ref_max = z0.copy(), v2_0, -np.inf
        i2 = mk.phasors(mc, z, v1, v2)[1]
        for dk in d:
            for _ in range(sub):
                signs.add(i2.real < 0.0)
                v2 = mk.sbar_v2(lc, tab, dk, i2, vc)[0]
                mk.advance_z(mc, zc, z, v1, v2)
                i2 = mk.phasors(mc, z, v1, v2)[1]
                ref_max = max(ref_max, mk.inst_peak(lc, tab, dk, i2, vc))
        zf = z0.copy()
        pk, v2f = mk.held_peak(lc, mc, tab, zc, zf, v2_0, d, sub, v1, vc, len(d), *no_tail, 1.0, np.inf)
        assert (pk, v2f) == (ref_max, v2) and np.array_equal(zf, z)
    assert signs == {True, False}
