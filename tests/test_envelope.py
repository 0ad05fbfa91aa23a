"""Physics of the envelope model (eq. 3-8) against closed forms and independent numerics."""

import math

import numpy as np
import pytest
import scipy.linalg
from scipy import integrate, signal

from wpt_receiver import TABLE_I, EnvelopeLink, LinkParams, coefficients, g22, state_matrices, steady_state, zoh_discretise

P = TABLE_I
W = 2 * math.pi * 85e3


def test_steady_states_match_hand_phasor_solution():
    # Hand computation with Table I: w Lm = 2 pi 85e3 * 6.25e-6, V1 = V2_rm = 4/pi * 30
    wlm = W * 6.25e-6
    v = 4 / math.pi * 30
    det = 0.108 * 0.0325 + wlm**2
    i1_rm, i2_rm = steady_state(P, v)
    i1_sm, i2_sm = steady_state(P, 0.0)
    assert i2_rm == pytest.approx((wlm * v - 0.108 * v) / det, rel=1e-12)
    assert i2_sm == pytest.approx(wlm * v / det, rel=1e-12)
    # phasor KVL of the primary: R1 I1 + w Lm I2 = V1 in both modes
    for i1, i2 in ((i1_rm, i2_rm), (i1_sm, i2_sm)):
        assert 0.108 * i1 + wlm * i2 == pytest.approx(v, rel=1e-12)
    # independent SPICE of the same circuit: RM 11.18 A, SM 11.41 A -> within 2 %
    assert i2_rm == pytest.approx(11.18, rel=0.02)
    assert i2_sm == pytest.approx(11.41, rel=0.02)
    # power balance in RM: source = losses + rectifier
    p_src = 0.5 * v * i1_rm
    p_loss = 0.5 * (0.108 * i1_rm**2 + 0.0325 * i2_rm**2)
    p_rect = 0.5 * v * i2_rm
    assert p_src == pytest.approx(p_loss + p_rect, rel=1e-12)


def test_zeta_and_omega_n_match_state_matrix_eigenvalues():
    c = coefficients(P)
    a, _ = state_matrices(P)
    lam = np.linalg.eigvals(a)
    assert np.abs(lam[0]) == pytest.approx(c.omega_n, rel=1e-12)
    assert -lam[0].real / np.abs(lam[0]) == pytest.approx(c.zeta, rel=1e-12)
    assert 0.015 < c.zeta < 0.03  # "tiny damping" of the paper


def test_g22_matches_state_space_transfer_function():
    a, b = state_matrices(P)
    num, den = signal.ss2tf(a, b, np.array([[0.0, 1.0]]), np.zeros((1, 2)), input=1)
    tf = g22(P)
    s = 1j * np.array([10.0, 1e3, 2.5e4, 1e6])
    ref = np.polyval(num[0], s) / np.polyval(den, s)
    got = np.polyval(tf.num, s) / np.polyval(tf.den, s)
    np.testing.assert_allclose(got, ref, rtol=1e-10)
    # DC gain: dI2/dV2 = -R1/(R1 R2 + (w Lm)^2)
    assert tf.num[-1] / tf.den[-1] == pytest.approx(-0.108 / (0.108 * 0.0325 + (W * 6.25e-6) ** 2), rel=1e-12)


@pytest.mark.parametrize("lm", [1e-7, 6.25e-6, 2e-5])
@pytest.mark.parametrize("dt", [1e-7, 5.88e-6, 1e-3])
def test_closed_form_zoh_equals_scipy_expm(lm, dt):
    a, b = state_matrices(P, np.array([lm]))
    ad, bd = zoh_discretise(a, b, dt)
    m = np.zeros((4, 4))
    m[:2, :2] = a[0]
    m[:2, 2:] = b
    e = scipy.linalg.expm(m * dt)
    np.testing.assert_allclose(ad[0], e[:2, :2], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(bd[0], e[:2, 2:], rtol=1e-9, atol=1e-15)


def test_zoh_handles_overdamped_and_critically_damped():
    for a in (np.array([[-3.0, 0.5], [0.2, -1.0]]), np.array([[-2.0, 1.0], [0.0, -2.0]])):
        b = np.eye(2)
        ad, bd = zoh_discretise(a[None], b, 0.3)
        np.testing.assert_allclose(ad[0], scipy.linalg.expm(a * 0.3), rtol=1e-7)


def test_batched_link_against_solve_ivp_with_varying_lm():
    lms = np.array([4e-6, 6.25e-6, 9e-6])
    link = EnvelopeLink(P, n=3)
    link.set_steady_state(P.v2_rm_amp_v, lm_h=lms)
    dt, n = 2e-6, 500
    for _ in range(n):
        link.step(0.0, dt, lm_h=lms)
    for j, lm in enumerate(lms):
        a, b = state_matrices(P, lm)
        u = np.array([P.v1_amp_v, 0.0])
        x0 = steady_state(P, P.v2_rm_amp_v, lm)
        sol = integrate.solve_ivp(lambda t, x: a @ x + b @ u, (0, n * dt), x0, method="DOP853", rtol=1e-11, atol=1e-11)
        np.testing.assert_allclose(link.x[j], sol.y[:, -1], rtol=1e-7)


def test_link_converges_to_closed_form_steady_state():
    link = EnvelopeLink(P, n=2)
    for _ in range(4000):  # 40 ms >> 1/(zeta wn) = 1.8 ms
        link.step(np.array([P.v2_rm_amp_v, 0.0]), 1e-5)
    np.testing.assert_allclose(link.i2, [steady_state(P, P.v2_rm_amp_v)[1], steady_state(P, 0)[1]], rtol=1e-6)


@pytest.mark.parametrize("field,value", [("l1_h", 0.0), ("r2_ohm", -1.0), ("f_hz", float("nan")),
                                         ("vdc_v", float("inf")), ("lm_h", 1e-3)])
def test_bad_parameters_raise_with_field_name(field, value):
    with pytest.raises(ValueError, match=field if field != "lm_h" else "k ="):
        LinkParams(**{field: value})


def test_bad_step_inputs_raise():
    link = EnvelopeLink(P)
    with pytest.raises(ValueError, match="dt_s"):
        link.step(0.0, -1.0)
    with pytest.raises(ValueError, match="lm_h"):
        link.step(0.0, 1e-6, lm_h=-1.0)


def test_modal_and_real_recursions_agree():
    """A batch that includes a real-pole link (tiny Lm) runs the real recursion; compare with modal."""
    lms_osc = np.array([4e-6, 6.25e-6])
    both = np.array([4e-6, 6.25e-6, 1e-11])  # 1e-11 H: overdamped -> real path for the whole batch
    a, _ = state_matrices(P, both)
    s = 0.5 * (a[:, 0, 0] + a[:, 1, 1])
    det = np.linalg.det(a)
    assert det[2] - s[2] ** 2 < 0 < det[0] - s[0] ** 2
    modal, real = EnvelopeLink(P, 2), EnvelopeLink(P, 3)
    modal.set_steady_state(P.v2_rm_amp_v, lm_h=lms_osc)
    real.set_steady_state(P.v2_rm_amp_v, lm_h=both)
    for k in range(300):
        v2 = 0.0 if k > 10 else P.v2_rm_amp_v
        modal.step(v2, 3e-6, lm_h=lms_osc)
        real.step(v2, 3e-6, lm_h=both)
    np.testing.assert_allclose(modal.x, real.x[:2], rtol=1e-10)


def test_set_state_with_mask_only_touches_masked_links():
    link = EnvelopeLink(P, n=3)
    link.set_steady_state(P.v2_rm_amp_v)
    link.step(0.0, 1e-5)
    before = link.x
    link.set_steady_state(0.0, mask=np.array([False, True, False]))
    after = link.x
    np.testing.assert_array_equal(after[[0, 2]], before[[0, 2]])
    np.testing.assert_allclose(after[1], steady_state(P, 0.0), rtol=1e-12)


def test_zoh_long_steps_with_real_poles_do_not_overflow():
    a, b = state_matrices(P, np.array([1e-9, 0.0]))
    for dt in (3.0, 10.0):
        ad, bd = zoh_discretise(a, b, dt)
        assert np.all(np.isfinite(ad)) and np.all(np.isfinite(bd))
        np.testing.assert_allclose(ad[0], scipy.linalg.expm(a[0] * dt), atol=1e-300)
        # long enough to reach the steady state: Bd -> -A^-1 B
        np.testing.assert_allclose(bd[0], -np.linalg.solve(a[0], b), rtol=1e-9)


def test_steady_state_is_regular_at_zero_coupling():
    i1, i2 = steady_state(P, 10.0, lm_h=0.0)
    assert i1 == pytest.approx(P.v1_amp_v / P.r1_ohm)
    assert i2 == pytest.approx(-10.0 / P.r2_ohm)


# --------------------------------------------------------------------------- devices, averaged
def _device_steady_state(p, d, dv):
    """Envelope steady state with devices: V2 = a + b I2 (I2 > 0) is linear, so eq. 4 solves directly."""
    import math

    from wpt_receiver.devices import envelope_params
    from wpt_receiver.sbar import rectifier_v2_folded
    pf = envelope_params(p, dv)
    a = rectifier_v2_folded(d, p.vl_v, 1.0, dv) - rectifier_v2_folded(d, p.vl_v, 0.0, dv) * 0
    b = rectifier_v2_folded(d, p.vl_v, 2.0, dv) - rectifier_v2_folded(d, p.vl_v, 1.0, dv)
    a = a - b
    wlm = pf.omega_rad_s * pf.lm_h
    # R1 I1 + wLm I2 = V1 ; -wLm I1 + (R2 + b) I2 = -a
    m = np.array([[pf.r1_ohm, wlm], [-wlm, pf.r2_ohm + b]])
    i1, i2 = np.linalg.solve(m, [pf.v1_amp_v, -a])
    assert i2 > 0 and math.isfinite(i1)
    return i1, i2


@pytest.mark.parametrize("d", [0.0, 0.3, 0.6, 0.9])
def test_averaged_device_losses_match_switching_model(d):
    """Envelope-side averages (eq. 4 with devices folded, conduction_losses) against the exact
    switching model's per-group losses in the periodic steady state: I2 within 0.5 %, I1 within 2.5 % of its RM value,
    each group's loss within 5 % (harmonics of i2 are what the average leaves out), the total
    within 2 %; and the averaged balance closes exactly: V2 I2 / 2 = VL I_L + rectifier losses."""
    from wpt_receiver.devices import preset
    from wpt_receiver.sbar import conduction_losses, rectifier_current, rectifier_v2_devices
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink, fundamental
    dv = preset("schottky")
    link = SwitchingLink(P, SwitchingConfig(devices=dv))
    T = link.T
    res = link.run(link.schedule(0.0, 8 * T, d), link.periodic_steady_state(d))
    e = res.energy_balance(0.0, 8 * T)
    i1s, i2s = abs(fundamental(res, 0.0, 8 * T, "i1")), abs(fundamental(res, 0.0, 8 * T, "i2"))
    i1, i2 = _device_steady_state(P, d, dv)
    # I1 carries eq. 9's own error (window on the fundamental's peak, not the half-cycle's)
    assert i2 == pytest.approx(i2s, rel=5e-3) and i1 == pytest.approx(i1s, abs=0.3)  # 2.5 % of the RM I1
    avg = conduction_losses(d, i1s, i2s, dv)  # the averaging itself, on the same amplitudes
    for g in ("inverter_switches", "rectifier_diodes", "rectifier_switches"):
        assert avg[g] == pytest.approx(e[f"{g}_loss_j"] / (8 * T), rel=0.05, abs=5e-3), g
    assert sum(avg.values()) == pytest.approx(e["device_losses_j"] / (8 * T), rel=0.02)
    p_in = 0.5 * rectifier_v2_devices(d, P.vl_v, i2s, dv) * i2s
    p_out = P.vl_v * rectifier_current(d, i2s) + avg["rectifier_diodes"] + avg["rectifier_switches"]
    assert p_in == pytest.approx(p_out, rel=1e-12)


def test_zoh_with_a_step_per_link_equals_one_call_per_link():
    """``dt_s`` as an array (the envs' three step lengths in one call), some steps short enough for Bd's series
    (||A dt|| < 0.1), others not: each link's (Ad, Bd) is that of its own scalar call, to the bit."""
    a, b = state_matrices(P, np.array([6e-6, 5e-6, 4e-6]))
    dt = np.array([1e-7, 1e-4, 5.88e-6])
    ad, bd = zoh_discretise(a, b, dt)
    for i in range(3):
        ad1, bd1 = zoh_discretise(a[i:i + 1], b, dt[i])
        np.testing.assert_array_equal(ad[i], ad1[0])
        np.testing.assert_array_equal(bd[i], bd1[0])


def test_zoh_with_a_b_per_link_equals_one_call_per_link():
    """``B`` batched like ``A`` ((64, 2, 2): a link's own L1, L2) with a step per link, through all three Bd
    branches (the closed form, the series below ||A dt|| = 0.1, the real-pole projectors): each link's (Ad, Bd)
    is that of its own call, to the bit (a batched B raised in the two branches before)."""
    rng = np.random.default_rng(8)
    links = [LinkParams(l1_h=l1, l2_h=l2, lm_h=k * math.sqrt(l1 * l2), r1_ohm=r1, r2_ohm=r2, f_hz=f)
             for l1, l2, k, r1, r2, f in zip(10 ** rng.uniform(-9, 0, 61), 10 ** rng.uniform(-9, 0, 61),
                                             rng.uniform(1e-3, 0.999, 61), 10 ** rng.uniform(-6, 2, 61),
                                             10 ** rng.uniform(-6, 2, 61), 10 ** rng.uniform(4, 7.5, 61))]
    links += [P, LinkParams(l1_h=1.0, l2_h=1e-9, lm_h=1e-3 * math.sqrt(1e-9), r1_ohm=1e-6, r2_ohm=100.0, f_hz=1e4),
              LinkParams(l1_h=1.0, l2_h=1.0, lm_h=1e-3, r1_ohm=1.0, r2_ohm=1.0, f_hz=1e4)]
    a = np.array([state_matrices(p)[0] for p in links])
    b = np.array([state_matrices(p)[1] for p in links])
    dt = 10 ** rng.uniform(-9, -2, len(links))
    ad, bd = zoh_discretise(a, b, dt)
    norm = np.abs(a).max(axis=(1, 2)) * dt
    s = 0.5 * (a[:, 0, 0] + a[:, 1, 1])
    real = s * s > a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    assert np.any(norm < 0.1) and np.any((norm >= 0.1) & real) and np.any((norm >= 0.1) & ~real)
    for i in range(len(links)):
        ad1, bd1 = zoh_discretise(a[i:i + 1], b[i], dt[i])
        np.testing.assert_array_equal(ad[i], ad1[0])
        np.testing.assert_array_equal(bd[i], bd1[0])
