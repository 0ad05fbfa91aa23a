"""Physics audit by property-based tests (hypothesis): the invariants of the envelope model (eq. 3-5), the SBAR
map (eq. 9), the inverse-model controller, the coupling Lm(pose) and a mission's bookkeeping, at random inputs in
the ranges the library itself declares (``mission_sim.config.LINK_PARAM_RANGES``, the control-period range, the
``coupling`` command's pose checks, ``PLAUSIBLE``), against references written here from the equations (the
paper's eq. 3 with the sign of eq. 4b/5b: ``2 L2 dI2/dt + R2 I2 - w Lm I1 + V2 = 0``), not from the library.

Every test is derandomized (the same examples in every run) and bounded by ``max_examples``; the tolerances are
derived in each test's docstring. docs/testing.md, "Property-based physics audit (2026-11-27 evening)".
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, assume, example, given, settings
from hypothesis import strategies as st

from wpt_receiver import LinkParams, simulate, state_matrices, steady_state, zoh_discretise
from wpt_receiver.envelope import EnvelopeLink

SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
EPS = np.finfo(float).eps


def log_uniform(lo: float, hi: float):
    """A float log-uniform in [lo, hi]."""
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: min(max(10.0 ** e, lo), hi))


@st.composite
def links(draw, v_lo=1e-3, corners=False):
    """A LinkParams inside ``LINK_PARAM_RANGES``: L 1 nH .. 1 H, 0 < k < 1, R 1 uOhm .. 100 Ohm, voltages up to
    1 kV, f 10 kHz .. 30 MHz (log-uniform, so every decade is visited). ``corners``: each of L1, L2, k, R1, R2, f is
    a range endpoint half the time (the stiff links live at the corners: log-uniform draws alone never reach them)."""
    def field(strategy, lo, hi):
        return draw(st.one_of(st.sampled_from([lo, hi]), strategy) if corners else strategy)
    l1, l2 = field(log_uniform(1e-9, 1.0), 1e-9, 1.0), field(log_uniform(1e-9, 1.0), 1e-9, 1.0)
    k = field(st.floats(1e-3, 0.999), 1e-3, 0.999)
    return LinkParams(l1_h=l1, l2_h=l2, lm_h=k * math.sqrt(l1 * l2), r1_ohm=field(log_uniform(1e-6, 100.0), 1e-6, 100.0),
                      r2_ohm=field(log_uniform(1e-6, 100.0), 1e-6, 100.0), vdc_v=draw(log_uniform(v_lo, 1000.0)),
                      vl_v=draw(log_uniform(v_lo, 1000.0)), f_hz=field(log_uniform(1e4, 3e7), 1e4, 3e7))


def eq3(p: LinkParams):
    """(A, B) of eq. 3 as printed with the sign of eq. 4b/5b, written here from the text (x = [I1, I2], u = [V1, V2]):
    2 L1 dI1/dt = V1 - R1 I1 - w Lm I2,  2 L2 dI2/dt = -V2 - R2 I2 + w Lm I1."""
    wlm = 2 * math.pi * p.f_hz * p.lm_h
    a = np.array([[-p.r1_ohm, -wlm], [wlm, -p.r2_ohm]]) / np.array([[2 * p.l1_h], [2 * p.l2_h]])
    b = np.array([[1 / (2 * p.l1_h), 0.0], [0.0, -1 / (2 * p.l2_h)]])
    return a, b


# ============================================================================ envelope model
@settings(max_examples=300, **SETTINGS)
@given(p=links(), frac=st.floats(0.0, 1.0))
def test_steady_state_solves_eq3_at_rest(p, frac):
    """steady_state against eq. 3 with d/dt = 0, written from the text: each equation's residual is a rounding
    error of its terms (a few eps of the largest; 64 eps allowed), and the power balance 1/2 V1 I1 = 1/2 R1 I1^2 +
    1/2 R2 I2^2 + 1/2 V2 I2 follows to the same order."""
    v1, v2 = p.v1_amp_v, frac * p.v2_rm_amp_v
    i1, i2 = steady_state(p, v2)
    wlm = 2 * math.pi * p.f_hz * p.lm_h
    for terms in ((p.r1_ohm * i1, wlm * i2, -v1), (p.r2_ohm * i2, -wlm * i1, v2)):
        assert abs(sum(terms)) <= 64 * EPS * max(abs(t) for t in terms), terms
    flows = (v1 * i1, -p.r1_ohm * i1 * i1, -p.r2_ohm * i2 * i2, -v2 * i2)
    assert abs(sum(flows)) <= 256 * EPS * max(abs(t) for t in flows)


def _expm_mp(m, t):
    """e^{M t} in 40 significant digits (mpmath): a reference whose own error is far below float64's."""
    mpmath.mp.dps = 40
    e = mpmath.expm(mpmath.matrix(np.asarray(m, float).tolist()) * mpmath.mpf(float(t)))
    return np.array([[float(e[i, j]) for j in range(e.cols)] for i in range(e.rows)])


@settings(max_examples=150, **SETTINGS)
@given(p=links(corners=True), dt=st.one_of(st.sampled_from([1e-7, 1e-2]), log_uniform(1e-7, 1e-2)))
@example(p=LinkParams(l1_h=1.0, l2_h=1e-9, lm_h=1e-3 * math.sqrt(1e-9), r1_ohm=1e-6, r2_ohm=100.0, f_hz=1e4), dt=1e-7)
@example(p=LinkParams(l1_h=1.0, l2_h=1e-9, lm_h=1e-3 * math.sqrt(1e-9), r1_ohm=100.0, r2_ohm=1e-6, f_hz=1e4),
         dt=2.56e-7)
@example(p=LinkParams(l1_h=0.4564877508293096, l2_h=4.6732334860490155e-08, lm_h=3.5411826829967994e-05,
                      r1_ohm=0.43013477104350856, r2_ohm=77.00676577535725, f_hz=26898.590094515457),
         dt=4.070279424831159e-06)
@example(p=LinkParams(l1_h=1.0, l2_h=1.0, lm_h=0.001953125, r1_ohm=1.0, r2_ohm=1.0, f_hz=1e4), dt=1e-7)
@example(p=LinkParams(l1_h=1.3823722273578997e-07, l2_h=0.31622776601683794, lm_h=0.00010454000206393592, r1_ohm=1.0,
                      r2_ohm=10.0, f_hz=1e4), dt=1e-7)
def test_zoh_discretisation_against_40_digit_expm(p, dt):
    """zoh_discretise (closed form) against e^{[[A, B], [0, 0]] dt} in 40 digits, over the envelope's step range
    (the control-period range 1e-7 .. 1e-2 s). A float64 evaluation of e^{A dt} has an absolute error of a few eps
    times ||A dt|| (the phase q dt of cos / sin, the exponent s dt), so Ad is held to 16 eps (1 + ||A dt||) absolute;
    Bd column by column to 1e-9 of the column's size plus 4 eps dt |Ad| |B| (the same phase error: e^{A dt} evaluated
    in float64 is the exact one at a step dt (1 + ~4 eps), which moves Bd by ~4 eps dt Ad B; it dominates only for
    oscillatory links with q dt >~ 1e5, e.g. L1 1 nH, L2 1 H, 30 MHz, dt 10 ms: 1.7e-7 of a column): 1e-9 is 50 times the worst measured with the spectral
    Bd (1.9e-11 over LINK_PARAM_RANGES' 64 corners and 600 log-uniform links at dt 0.1 us .. 10 ms), 40 times below
    the smallest error this test exists for (3.8e-8: the third example before the slow pole by Vieta). The links
    take each range endpoint half the time (the stiff links are corners: 150 log-uniform draws passed the old real-pole
    formula). Before the spectral Bd (real poles: sum_k expm1(l_k dt) / l_k P_k B): 2.9e-4 in the first example
    (L1 1 H, R1 1 uOhm: a stiff real-pole link whose slow pole has |l dt| ~ 1e-13 beside ||A dt|| = 5e3; A^-1 (Ad - I)
    cancels in that direction), 2.4e-8 in the second (R1 100 Ohm, R2 1 uOhm); before the slow pole by Vieta 3.8e-8
    in the third, 9e-7 in another."""
    a, b = eq3(p)
    m = np.zeros((4, 4))
    m[:2, :2], m[:2, 2:] = a, b
    ref = _expm_mp(m, dt)
    ad, bd = zoh_discretise(state_matrices(p, np.array([p.lm_h]))[0], state_matrices(p)[1], dt)
    norm = float(np.abs(a).max()) * dt
    assert np.abs(ad[0] - ref[:2, :2]).max() <= 16 * EPS * (1.0 + norm)
    for j in range(2):
        col = ref[:2, 2 + j]
        phase = 4 * EPS * dt * float((np.abs(ref[:2, :2]) @ np.abs(b[:, j])).max())   # dt (1 + 4 eps): dt Ad B
        assert np.abs(bd[0][:, j] - col).max() <= 1e-9 * np.abs(col).max() + phase, (j, bd[0][:, j], col)


def _poles(p):
    return np.linalg.eigvals(eq3(p)[0])


@settings(max_examples=150, **SETTINGS)
@given(p=links(), frac=st.floats(0.0, 1.0), start=st.sampled_from(["rest", "other"]))
def test_simulate_converges_to_the_steady_state(p, frac, start):
    """simulate() from rest (or from the other mode's steady state) for 60 time constants of the slowest pole
    (e^-60 ~ 1e-26 of the start left) lands on eq. 3's steady state: within 1e-9 of the state's size (a ZOH step's
    rounding, ~eps (1 + ||A dt||) per step, compounded over 60 steps and the steady state's own conditioning)."""
    slow = float(np.min(np.abs(_poles(p).real)))
    dt = 3.0 / slow
    v2 = frac * p.v2_rm_amp_v
    x0 = (0.0, 0.0) if start == "rest" else steady_state(p, p.v2_rm_amp_v - v2)
    _, i1, i2 = simulate(p, np.full(20, v2), dt, x0=np.array(x0, float))
    a, b = eq3(p)
    want = np.linalg.solve(-a, b @ [p.v1_amp_v, v2])
    scale = np.abs(want).max()
    assert abs(i1[-1] - want[0]) <= 1e-9 * scale and abs(i2[-1] - want[1]) <= 1e-9 * scale


_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


@settings(max_examples=60, **SETTINGS)
@given(p=links(), theta=log_uniform(0.05, 3.0), fracs=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=6))
def test_envelope_energy_balance_over_a_transient(p, theta, fracs):
    """Energy over a transient of simulate() (V2 switched between random levels each step): source energy
    int V1 I1 / 2 = coil losses int (R1 I1^2 + R2 I2^2) / 2 + energy to the rectifier int V2 I2 / 2 + the change
    of the stored energy (L1 I1^2 + L2 I2^2) / 2 (eq. 3 times I1 / 2, I2 / 2 summed: the w Lm I1 I2 terms cancel).

    The integrals are exact: within each step the state is e^{M t} z0 (M = [[A, B], [0, 0]] of eq. 3 as written
    here, z0 = [simulate's state, V1, V2]) at 24 Gauss-Legendre nodes, steps of theta / |fastest pole| with theta
    <= 3, where a 24-node rule is exact to rounding. The library's states enter the stored energy: a wrong sign or
    factor in its A, B moves its end state off this one. Residual held to 1e-10 of the largest flow (rounding:
    ~1e-14 measured)."""
    from scipy.linalg import expm
    dt = theta / float(np.max(np.abs(_poles(p))))
    v2 = np.array(fracs) * p.v2_rm_amp_v
    t, i1, i2 = simulate(p, v2, dt)
    a, b = eq3(p)
    m = np.zeros((4, 4))
    m[:2, :2], m[:2, 2:] = a, b
    nodes = 0.5 * dt * (_GL_X + 1.0)
    e_nodes = expm(m[None] * nodes[:, None, None])   # e^{M t} at the 24 nodes, one batched call for every step
    e_src = e_loss = e_rect = 0.0
    for k in range(len(v2)):
        z0 = np.array([i1[k], i2[k], p.v1_amp_v, v2[k]])
        z = e_nodes @ z0
        w = 0.5 * dt * _GL_W
        e_src += 0.5 * p.v1_amp_v * (w @ z[:, 0])
        e_loss += 0.5 * (w @ (p.r1_ohm * z[:, 0] ** 2 + p.r2_ohm * z[:, 1] ** 2))
        e_rect += 0.5 * v2[k] * (w @ z[:, 1])
    stored = 0.5 * (p.l1_h * i1 ** 2 + p.l2_h * i2 ** 2)
    flows = (e_src, e_loss, e_rect, stored[0], stored[-1])
    resid = e_src - e_loss - e_rect - (stored[-1] - stored[0])
    assert abs(resid) <= 1e-10 * max(abs(f) for f in flows), (resid, flows)
    # the batched modal recursion (EnvelopeLink) runs the same trajectory
    link = EnvelopeLink(p, 1)
    link.set_state(np.array([i1[0], i2[0]]))
    for k in range(len(v2)):
        link.step(v2[k], dt)
    scale = max(np.abs(i1).max(), np.abs(i2).max())
    assert np.abs(link.x[0] - [i1[-1], i2[-1]]).max() <= 1e-9 * scale


# ============================================================================ SBAR map (eq. 9) and the controller
@settings(max_examples=300, **SETTINGS)
@given(vl=log_uniform(1e-3, 1000.0), d=st.floats(0.0, 1.0), frac=st.floats(0.0, 1.0))
def test_sbar_map_round_trips_and_balances_power(vl, d, frac):
    """V2 = (4/pi) VL (1 - sin(pi/2 d)) (eq. 9, written here) and its inverse, for VL in (0, 1 kV]: d -> V2 is
    the formula to 4 eps of (4/pi) VL; V2 -> d -> V2 round trips to 8 eps of (4/pi) VL; d -> V2 -> d to 4e-8 (near
    d = 1 the map is flat, V2 ~ (4/pi) VL (pi^2/8)(1 - d)^2, so d is known to sqrt(eps) there: (8 eps / (pi^2 / 2))^0.5
    ~ 1.9e-8, doubled). The lossless rectifier's DC current gives V2 I2 / 2 = VL I_L for either sign of I2, and
    V2 I2 >= 0 (the rectifier absorbs power)."""
    from wpt_receiver import duty_from_v2, v2_from_duty
    from wpt_receiver.sbar import rectifier_current, rectifier_v2
    vmax = 4.0 / math.pi * vl
    v = v2_from_duty(d, vl)
    assert abs(v - vmax * (1.0 - math.sin(0.5 * math.pi * d))) <= 4 * EPS * vmax
    v2 = frac * vmax
    assert abs(v2_from_duty(duty_from_v2(v2, vl), vl) - v2) <= 8 * EPS * vmax
    assert abs(duty_from_v2(v, vl) - d) <= 4e-8
    for i2 in (-7.5, 3.25):
        v2s = rectifier_v2(d, vl, i2)
        assert v2s * i2 >= 0.0
        assert 0.5 * v2s * i2 == pytest.approx(vl * rectifier_current(d, abs(i2)), rel=4 * EPS, abs=4 * EPS * vmax)


@settings(max_examples=200, **SETTINGS)
@given(vl=log_uniform(1e-3, 1000.0), over=log_uniform(1e-9, 1e3))
def test_sbar_clipping_at_both_ends(vl, over):
    """A command beyond the actuator saturates: V2 above (4/pi) VL gives d = 0 (rectification), below 0 gives d = 1
    (short), exactly, while the checked inverse refuses both by name; inside, the clipped and the checked inverse
    agree exactly and d falls as V2 rises."""
    from wpt_receiver import duty_from_v2, duty_from_v2_clipped
    vmax = 4.0 / math.pi * vl
    hi, lo = vmax * (1.0 + over), -vmax * over
    assert duty_from_v2_clipped(hi, vl) == 0.0 and duty_from_v2_clipped(lo, vl) == 1.0
    assert duty_from_v2_clipped(np.array([lo, hi]), vl).tolist() == [1.0, 0.0]
    for bad in (hi, lo):
        if bad > vmax * (1 + 1e-12) or bad < 0:
            with pytest.raises(ValueError, match="valid range"):
                duty_from_v2(bad, vl)
    inside = np.linspace(0.0, vmax, 17)
    d = duty_from_v2_clipped(inside, vl)
    np.testing.assert_array_equal(d, duty_from_v2(inside, vl))
    assert np.all(np.diff(d) < 0) and d[0] == 1.0 and d[-1] == 0.0


@settings(max_examples=120, **SETTINGS)
@given(p=links(v_lo=1.0), tau=log_uniform(1e-6, 0.1), order=st.integers(1, 4), period=log_uniform(1e-7, 1e-2),
       frac=st.floats(0.0, 1.0), v1_scale=st.floats(0.25, 4.0))
def test_controller_dc_gain_returns_the_steady_v2_of_eq3(p, tau, order, period, frac, v1_scale):
    """The inverse-model controller reset at a reference I2 (and a V1) asks for the V2 under which eq. 3's steady
    state (solved here) carries exactly that I2: V2 = (w Lm V1 - det I2) / R1 with det = R1 R2 + (w Lm)^2. The
    controller promises its DC gain to DC_GAIN_RTOL (1e-3) of 1/G22(0) and refuses a filter whose discretisation
    float64 has lost; so V2* is held to DC_GAIN_RTOL of |H(0) (I2 - I2_sm)| plus 1e-9 of the terms. After 30
    control periods at the same reference it still asks for that V2 (a steady state of the discretised H)."""
    from wpt_receiver import InverseModelController, LowPassFilter
    from wpt_receiver.inverse_controller import DC_GAIN_RTOL
    try:
        ctl = InverseModelController(p, control_period_s=period, lpf=LowPassFilter(tau_s=tau, order=order))
    except ValueError as exc:
        assert "float64 loses the discretised controller" in str(exc)
        assume(False)
    v1 = v1_scale * p.v1_amp_v
    wlm = 2 * math.pi * p.f_hz * p.lm_h
    det = p.r1_ohm * p.r2_ohm + wlm * wlm
    i2_sm, i2_rm = wlm * v1 / det, (wlm * v1 - p.r1_ohm * p.v2_rm_amp_v) / det
    i2 = i2_rm + frac * (i2_sm - i2_rm)
    want = (wlm * v1 - det * i2) / p.r1_ohm
    ctl.reset(i2, v1_v=v1)
    tol = DC_GAIN_RTOL * det / p.r1_ohm * abs(i2 - i2_sm) + 1e-9 * (wlm * v1 + det * abs(i2)) / p.r1_ohm
    assert abs(ctl.v2_cmd_v[0] - want) <= tol
    for _ in range(30):
        ctl.update(i2)
    assert abs(ctl.v2_cmd_v[0] - want) <= tol


# ============================================================================ coupling Lm(pose)
def _aphi_loop(a, rho, z):
    """A_phi [H/m per A] of a unit-current circular loop, radius a, at (rho, z) (Smythe; Jackson eq. 5.37) with
    scipy's complete elliptic integrals: mu0 / (pi k) sqrt(a / rho) [(1 - k^2 / 2) K(k) - E(k)]."""
    from scipy.special import ellipe, ellipk
    from wpt_receiver.coupling import MU0
    m = 4 * a * rho / ((a + rho) ** 2 + z * z)
    return MU0 / (math.pi * np.sqrt(m)) * np.sqrt(a / rho) * ((1 - 0.5 * m) * ellipk(m) - ellipe(m))


def _lm_quad(tx, rx, dx, dy, dz, tilt):
    """Neumann's Lm = oint A . dl over the receiver turns, by scipy's adaptive quad in the loop angle (the receiver
    tilted about the y axis through its origin: its normal (sin tilt, 0, cos tilt)), summed over every pad turn."""
    from scipy import integrate
    c, s = math.cos(tilt), math.sin(tilt)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    rr, rz = np.array(rx.radius_m), np.array(rx.z_m)

    def integrand(th):
        p = np.stack([rr * np.cos(th), rr * np.sin(th), rz], -1) @ rot.T + [dx, dy, dz]
        t = np.stack([-rr * np.sin(th), rr * np.cos(th), 0.0 * rr], -1) @ rot.T
        rho = np.hypot(p[:, 0], p[:, 1])
        a_phi = sum(_aphi_loop(a, rho, p[:, 2] - zt) for a, zt in zip(tx.radius_m, tx.z_m))
        return float(np.sum(a_phi * (p[:, 0] * t[:, 1] - p[:, 1] * t[:, 0]) / rho))
    return integrate.quad(integrand, 0.0, 2 * math.pi, epsabs=0.0, epsrel=1e-11, limit=200)[0]


def _min_dz(m, tilt):
    """The ``coupling`` command's lowest height: the wires' radii plus the drone coil's lift at this tilt."""
    return m.tx.wire_radius_m + m.rx.wire_radius_m + max(m.rx.radius_m) * abs(math.sin(tilt))


@settings(max_examples=25, **SETTINGS)
@given(dx=st.floats(-0.6, 0.6), dy=st.floats(-0.6, 0.6), lift=st.floats(0.0, 1.0), tilt=st.floats(-1.3, 1.3))
def test_lm_of_a_pose_against_an_independent_neumann_integral(dx, dy, lift, tilt):
    """Lm of the default coils at a random pose the ``coupling`` command accepts (|tilt| < 75 deg, offsets up to
    0.6 m, dz from 1 cm above the coils' touching height to 1 m) against Neumann's integral done here (scipy quad,
    relative 1e-11): the exact path (24 points a turn, 3 cm apart on the drone coil) and the table within 1e-4 of the
    hover Lm. Measured: 1.3e-6 over 50 random poses; 5e-5 with the drone coil's rim 1.3 cm over the pad's outer
    wire (dy = 0.25 m), which a 24-point loop rule cannot resolve (1.3e-4 at 1 cm above touching, 2e-4 at 2 %
    above it: not tested). Before
    the fix the table was off by up to 1.6e-3 here (and 2 % at a 2.2 cm gap): its spline's lower edge, now left to
    the exact field (``coupling.EXACT_ABOVE_EDGE_STEPS``). And |Lm| < sqrt(L1 L2) (k < 1)."""
    from wpt_receiver.coupling import NOMINAL_GAP_M, default_coupling
    m = default_coupling()
    lo = _min_dz(m, tilt) + 0.03
    dz = lo + lift * (1.0 - lo)
    ref = _lm_quad(m.tx, m.rx, dx, dy, dz, tilt)
    hover = _lm_quad(m.tx, m.rx, 0.0, 0.0, NOMINAL_GAP_M, 0.0)
    assert abs(m.lm_exact_h(dx, dy, dz, tilt) - ref) <= 1e-4 * hover
    lm = m.lm_h(dx, dy, dz, tilt)
    assert abs(lm - ref) <= 1e-4 * hover
    assert abs(lm) < math.sqrt(m.l1_h * m.l2_h)


@pytest.mark.parametrize("step, top, tol", [(5e-3, 0.07, 1e-6), (1e-2, 0.12, 2e-6)])
def test_lm_table_near_the_pad_is_the_exact_field(step, top, tol):
    """Near-coaxial poses (offsets <= 2 cm, tilt <= 0.1 rad) at heights 3 cm .. ``top``: ``lm_h`` (table, or the
    exact field within ``EXACT_ABOVE_EDGE_STEPS`` grid steps of the table's lower edge) equals ``lm_exact_h`` to
    ``tol`` of the hover Lm. Measured 2.2e-7 at the default 5 mm grid (3-7 cm) and 7.2e-7 at a 10 mm grid
    (3-12 cm, above its 8 cm band); a 4-step (2 cm) band at 5 mm gives 3.0e-5 at 4.3 cm, a fixed 4 cm band at
    10 mm 6.1e-5 at 6.6 cm: this test pins the band's height and its scaling with the grid."""
    from wpt_receiver.coupling import CouplingModel, default_coupling
    d = default_coupling()
    m = d if step == 5e-3 else CouplingModel(d.tx, d.rx, grid_step_m=step)
    rng = np.random.default_rng(3)
    dz = np.linspace(0.03, top, 41)
    dx, dy, tilt = (rng.uniform(-w, w, dz.size) for w in (0.02, 0.02, 0.1))
    err = np.abs(m.lm_h(dx, dy, dz, tilt) - m.lm_exact_h(dx, dy, dz, tilt))
    assert err.max() <= tol * 6.25e-6, (err.max() / 6.25e-6, dz[err.argmax()])


@settings(max_examples=30, **SETTINGS)
@given(dx=st.floats(-0.4, 0.4), dy=st.floats(-0.4, 0.4), lift=st.floats(0.0, 0.8), tilt=st.floats(-1.0, 1.0))
def test_lm_is_symmetric_in_swapping_the_coils(dx, dy, lift, tilt):
    """Reciprocity M12 = M21: the receiver at (origin o, rotation R) over the pad is the pad at (-R^T o, R^T) under
    the receiver; R^T is the same axis turned by -tilt. Both by the exact path with 128 points a turn, from 2 cm
    above touching: to 1e-9 of the hover Lm (measured 6e-16 over 30 random poses; at 64 points and 3.5 mm gap the
    two sides' loop rules differ by 4e-5: quadrature, not physics)."""
    from wpt_receiver.coupling import CouplingModel, _rx_frame, default_coupling
    m = default_coupling()
    dz = _min_dz(m, tilt) + 0.02 + lift
    rot, org = _rx_frame(dx, dy, dz, tilt, math.pi / 2)
    back = -rot.T @ org
    swapped = CouplingModel(m.rx, m.tx)
    a = m.lm_exact_h(dx, dy, dz, tilt, n_theta=128)
    b = swapped.lm_exact_h(back[0], back[1], back[2], -tilt, n_theta=128)
    assert abs(a - b) <= 1e-9 * 6.25e-6


@settings(max_examples=40, **SETTINGS)
@given(dz=st.lists(st.floats(0.004, 1.0), min_size=2, max_size=8, unique=True))
def test_coaxial_lm_falls_with_height_and_stays_below_sqrt_l1_l2(dz):
    """Coaxial coils: Lm falls strictly with the height (every turn pair's Maxwell term does), from below
    sqrt(L1 L2) (k < 1) at the lowest pose the command accepts; table and exact path alike."""
    from wpt_receiver.coupling import default_coupling
    m = default_coupling()
    z = np.sort(np.array(dz))
    z = z[np.diff(z, prepend=-1.0) > 1e-6]
    for lm in (m.lm_h(0 * z, 0 * z, z), m.lm_exact_h(0 * z, 0 * z, z)):
        assert np.all(np.diff(lm) < 0) and lm[0] < math.sqrt(m.l1_h * m.l2_h) and lm[-1] > 0


# ============================================================================ a mission's bookkeeping
def _short_mission(**over):
    """A short mission over one pad (start 1 m before it, 1 m cruise height, land 1 m past it) with ``over``
    as ``--set`` overrides; returns (cfg, result) of the model-based policy."""
    from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config, policy_context
    from mission_sim.world.runner import run_mission
    from policies import make
    d = apply_overrides(config_to_dict(load_config()), {
        "mission.start_x_m": -1.0, "mission.cruise_altitude_m": 1.0, "mission.land_x_m": 1.0,
        "sim.traj_dt_s": 0.05, **over})
    d["pads"] = d["pads"][:1]
    cfg = config_from_dict(d)
    return cfg, run_mission(cfg, make("model_based", policy_context(cfg)))


def _ocv_cell(soc):
    """Chen & Rincon-Mora's OCV(SoC) per cell, as mission_sim/world/battery.py's notes give it."""
    return -1.031 * np.exp(-35 * soc) + 3.685 + 0.2156 * soc - 0.1178 * soc ** 2 + 0.3201 * soc ** 3


#: a mission is ~0.3 s: six each, and no shrinking (a failing mission example took hypothesis > 5 min to shrink)
MISSION_SETTINGS = dict(SETTINGS, max_examples=6, phases=[Phase.explicit, Phase.reuse, Phase.generate])


@settings(**MISSION_SETTINGS)
@given(soc=st.floats(0.3, 0.95), hover=st.floats(0.5, 3.0), avionics=st.floats(0.0, 60.0),
       cap=st.floats(0.8, 3.0), vdc=st.floats(20.0, 40.0), gap=st.floats(0.12, 0.2))
def test_mission_bookkeeping_closes_from_its_rows(soc, hover, avionics, cap, vdc, gap):
    """From the time series alone (not the summary's own residuals), for random short missions in PLAUSIBLE's
    ranges: the SoC moves by the charge the battery current carries (soc_k = soc_k-1 + I_k dt_k / Q, to 1e-12);
    each row's battery node closes (rectifier DC = OCV dQ + R0, R1 losses + C1 energy + propulsion and avionics, to
    1e-9 J of the row's flows); the chemistry's energy is n OCV(soc at the step's start) dQ with OCV written here
    from the battery notes (to 1e-12 of the largest row; the last, partial step's tiny dQ is 3e-9 off relative); the pad's energy is the link's losses plus the rectifier's DC, summed
    over the mission (the link at rest at both ends, to 1e-9 of the pad's energy) and the summary says the same
    sums; propulsion is its power times dt. The hover gap stays below 0.2 m: higher, k is under the pad's
    switch-on threshold (0.075) and nothing is charged."""
    cfg, res = _short_mission(**{"battery.initial_soc": soc, "pads.0.hover_time_s": hover,
                                 "drone.avionics_w": avionics, "battery.capacity_ah": cap, "link.vdc_v": vdc,
                                 "mission.hover_gap_m": gap})
    ts, s = res.timeseries, res.summary
    q = cfg.battery.capacity_ah * 3600.0
    soc_prev = np.concatenate([[soc], ts["soc"].to_numpy()[:-1]])
    dq = (ts["battery_current_a"] * ts["dt_s"]).to_numpy()
    np.testing.assert_allclose(ts["soc"].to_numpy(), soc_prev + dq / q, rtol=0, atol=1e-12)
    assert s["final_soc"] == pytest.approx(soc + dq.sum() / q, abs=1e-12)
    node = ts[["e_battery_chem_j", "e_battery_r0_j", "e_battery_r1_j", "e_battery_c1_j", "e_propulsion_j"]]
    scale = np.abs(node).sum(axis=1).to_numpy() + np.abs(ts["e_rectifier_j"]).to_numpy()
    assert np.all(np.abs(ts["e_rectifier_j"].to_numpy() - node.sum(axis=1).to_numpy()) <= 1e-9 * scale + 1e-12)
    chem = cfg.battery.n_series * _ocv_cell(soc_prev) * dq
    np.testing.assert_allclose(ts["e_battery_chem_j"].to_numpy(), chem, rtol=1e-12, atol=1e-12 * np.abs(chem).max())
    np.testing.assert_allclose(ts["e_propulsion_j"], ts["propulsion_w"] * ts["dt_s"], rtol=1e-12, atol=1e-12)
    link = ["e_coil_loss_j", "e_inverter_switches_j", "e_rectifier_diodes_j", "e_rectifier_switches_j",
            "e_rectifier_j"]
    e_src = ts["e_source_j"].sum()
    assert e_src > 0 and abs(ts["i2_amp_a"].iloc[-1]) < 1e-6
    assert abs(e_src - ts[link].to_numpy().sum()) <= 1e-9 * e_src
    assert s["energy_from_source_j"] == pytest.approx(e_src, rel=1e-12)
    assert s["rectifier_output_j"] == pytest.approx(ts["e_rectifier_j"].sum(), rel=1e-12)


@settings(**MISSION_SETTINGS)
@given(soc=st.floats(0.3, 0.95), hover=st.floats(0.5, 3.0), avionics=st.floats(0.0, 40.0), more=st.floats(1.0, 40.0))
def test_more_hover_power_ends_with_less_charge(soc, hover, avionics, more):
    """All else equal, a drone that draws more power (avionics +1..40 W) ends the same mission with a lower SoC
    (strictly: the charger's command follows the load over the pad, but the flight to and from it is on the
    pack), and its loads draw exactly the extra power over the whole mission, motors on or off (to 1e-9)."""
    base = {"battery.initial_soc": soc, "pads.0.hover_time_s": hover}
    _, lo = _short_mission(**base, **{"drone.avionics_w": avionics})
    _, hi = _short_mission(**base, **{"drone.avionics_w": avionics + more})
    assert hi.summary["final_soc"] < lo.summary["final_soc"]
    extra = hi.summary["propulsion_energy_j"] - lo.summary["propulsion_energy_j"]
    assert extra == pytest.approx(more * lo.summary["sim_time_s"], rel=1e-9)
    assert hi.summary["sim_time_s"] == lo.summary["sim_time_s"]


# ============================================================================ environments
ENV_INFO = ("i2_a", "i2_peak_a", "i1_a", "d_short", "v2_v", "rect_current_a", "battery_v", "battery_current_a", "soc",
            "charge_cmd_a", "lm_h", "energy_j", "cost", "overcurrent", "episode_cost")


@settings(max_examples=8, **SETTINGS)
@given(seed=st.integers(0, 2**32 - 2), scenario=st.sampled_from(["nominal", "random", "windy", "battery_low"]),
       link=st.sampled_from(["modal", "envelope"]), act_seed=st.integers(0, 2**31))
def test_vector_env_runs_the_single_envs_trajectories(seed, scenario, link, act_seed):
    """At a random seed, scenario, link and action sequence, the vector env's two windows are the single envs seeded
    seed, seed + 1 (observations to 1e-6, rewards and every info value to 1e-9), and each step's info is consistent
    with itself: overcurrent = max(peak I2 / rated - 1, 0), the rectifier's DC current >= 0 (it only absorbs), SoC
    in [0, 1]."""
    from envs import EnvConfig, SbarChargingEnv, SbarChargingVectorEnv
    cfg = EnvConfig(n_steps=40, link_model=link)
    acts = np.random.default_rng(act_seed).uniform(-1, 1, (cfg.n_steps, 2, 1)).astype(np.float32)
    venv = SbarChargingVectorEnv(num_envs=2, scenario=scenario, config=cfg)
    vobs, _ = venv.reset(seed=seed)
    singles = [SbarChargingEnv(scenario=scenario, config=cfg) for _ in range(2)]
    sobs = [e.reset(seed=seed + i)[0] for i, e in enumerate(singles)]
    np.testing.assert_allclose(vobs, np.stack(sobs), atol=1e-6)
    for k in range(cfg.n_steps):
        vobs, vr, _, _, vinfo = venv.step(acts[k])
        for i, e in enumerate(singles):
            o, r, _, _, info = e.step(acts[k, i])
            np.testing.assert_allclose(vobs[i], o, atol=1e-6)
            assert vr[i] == pytest.approx(r, rel=1e-9, abs=1e-12)
            for key in ENV_INFO:
                assert vinfo[key][i] == pytest.approx(info[key], rel=1e-9, abs=1e-12), key
            assert info["overcurrent"] == pytest.approx(max(info["i2_peak_a"] / cfg.rated_i2_a - 1.0, 0.0), abs=1e-12)
            assert info["rect_current_a"] >= 0.0 and 0.0 <= info["soc"] <= 1.0


@settings(max_examples=15, **SETTINGS)
@given(l1=log_uniform(1e-6, 1e-2), l2=log_uniform(1e-6, 1e-2), k=st.floats(0.02, 0.5), r1=log_uniform(1e-3, 1.0),
       r2=log_uniform(1e-3, 1.0), vl=st.floats(5.0, 60.0), f=log_uniform(2e4, 2e5), ratio=log_uniform(10.0, 1000.0),
       order=st.integers(1, 3))
def test_inverse_model_suppresses_the_overshoot_on_its_own_model(l1, l2, k, r1, r2, vl, f, ratio, order):
    """The paper's claim on the envelope model it inverts: RM -> SM with V2* from the controller (one duty per
    rectifier period T) leaves I2 with no overshoot but the discretisation's. Continuous-time, I2 = Q I2ref exactly
    (a real-pole Q: none); the controller's and the plant's zero-order holds leave an O(T / tau) mismatch: measured
    overshoot <= 0.24 T / tau of the step over 200 random links (tau 10-1000 T), held to 0.5 T / tau. Only where
    V2* stays inside [0, (4/pi) VL] (the controller promises nothing once the actuator clips) and the run, 8 slow-zero
    time constants 2 L1 / R1 plus 10 tau, is under 50,000 periods. Table-I-like links, not the full ranges: there
    most runs clip or take millions of periods."""
    from wpt_receiver import InverseModelController, LowPassFilter
    p = LinkParams(l1_h=l1, l2_h=l2, lm_h=k * math.sqrt(l1 * l2), r1_ohm=r1, r2_ohm=r2, vdc_v=30.0, vl_v=vl, f_hz=f)
    period = p.rectifier_period_s
    tau = ratio * period
    n = int((8 * 2 * l1 / r1 + 10 * tau) / period)
    i_rm, i_sm = steady_state(p, p.v2_rm_amp_v)[1], steady_state(p, 0.0)[1]
    assume(n <= 50_000 and i_rm > 0)
    ref = np.full(n, i_sm)
    ref[0] = i_rm
    v2, _ = InverseModelController(p, lpf=LowPassFilter(tau_s=tau, order=order)).run(ref)
    assume(v2.min() >= -1e-9 * p.v2_rm_amp_v and v2.max() <= p.v2_rm_amp_v * (1 + 1e-9))
    _, _, i2 = simulate(p, v2, period)
    step = i_sm - i_rm
    overshoot = (np.max(i2) - i_sm) / step if step > 0 else (i_sm - np.min(i2)) / -step
    assert overshoot <= 0.5 / ratio, (overshoot, ratio)
