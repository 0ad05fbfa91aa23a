"""Battery, CC-CV charging, momentum-theory power and the wind model against closed forms."""

import math

import numpy as np
import pytest

from mission_sim.world.battery import Battery, BatteryParams, CcCvCharger, CcCvParams, ocv_cell_v
from mission_sim.world.power import G_M_S2, DroneParams, hover_power_w, propulsion_power_w
from mission_sim.world.wind import WindParams, gust_series, hover_error_m, tilt_from_force


def test_battery_step_energy_identity_and_substep_consistency():
    p = BatteryParams()
    big = Battery(p, n=3, soc=[0.2, 0.5, 0.9])
    big.v1_v[:] = [0.05, -0.1, 0.0]
    small = Battery(p, n=3, soc=[0.2, 0.5, 0.9])
    small.v1_v[:] = big.v1_v
    i = np.array([2.0, -10.0, 0.7])
    e = big.step(i, 7.0)
    np.testing.assert_allclose(e.terminal_j, e.chem_j + e.r0_loss_j + e.r1_loss_j + e.c1_delta_j, rtol=1e-12)
    # the RC state is exact: one 7 s step == 7000 steps of 1 ms; R1 losses converge to the closed form
    r1 = np.zeros(3)
    for _ in range(7000):
        r1 += small.step(i, 1e-3).r1_loss_j
    np.testing.assert_allclose(small.v1_v, big.v1_v, rtol=1e-9)
    np.testing.assert_allclose(r1, e.r1_loss_j, rtol=1e-9)
    # coulomb counting
    np.testing.assert_allclose(big.soc - [0.2, 0.5, 0.9], i * 7.0 / p.capacity_c, rtol=1e-12)


def test_battery_terminal_voltage_settles_to_ocv_plus_r_i():
    p = BatteryParams()
    b = Battery(p)
    b.step(-3.0, 50 * p.tau1_s)
    v = b.terminal_v(-3.0)
    assert v == pytest.approx(p.ocv_v(b.soc) - 3.0 * (p.r0_ohm + p.r1_ohm), rel=1e-9)
    # OCV curve: monotone, 8S pack from ~21 V empty to ~32.8 V full (Chen & Rincon-Mora fit, 4.103 V/cell)
    s = np.linspace(0, 1, 101)
    assert np.all(np.diff(ocv_cell_v(s)) > 0)
    assert p.ocv_v(1.0) == pytest.approx(8 * 4.1033, rel=1e-4)


def test_cccv_charges_to_full_without_exceeding_cv_and_then_stops():
    p = BatteryParams(initial_soc=0.93)
    cc = CcCvParams()
    b = Battery(p)
    ch = CcCvCharger(cc, b)
    v_cv = cc.cv_cell_v * p.n_series
    seen_cc = False
    for _ in range(20000):
        tgt = ch.battery_target_a()[0]
        if ch.full[0]:
            break
        seen_cc |= tgt == cc.cc_current_a
        # terminal voltage over the step never exceeds the CV limit (model-based CV)
        assert b.mean_terminal_v(tgt, 1.0)[0] <= v_cv + 1e-6 or tgt == cc.cc_current_a
        b.step(tgt, 1.0)
    assert seen_cc and ch.full[0] and ch.cv[0]
    assert b.soc[0] > 0.98
    assert ch.command_a(5.0)[0] == 0.0  # full -> short mode whatever the propulsion draw


def test_full_battery_recharges_below_the_recharge_threshold_and_not_above():
    """A full battery under load: the command stays 0 while (OCV + v1)/n >= cv_cell_v - recharge_drop_cell_v
    and a new CC cycle (cv flag cleared, command = propulsion + CC current) starts at the first BMS call below."""
    p, cc = BatteryParams(initial_soc=0.93), CcCvParams(recharge_drop_cell_v=0.1)
    b = Battery(p)
    ch = CcCvCharger(cc, b)
    while not ch.full[0]:
        b.step(ch.battery_target_a()[0], 1.0)
    threshold = (cc.cv_cell_v - cc.recharge_drop_cell_v) * p.n_series
    i_prop = 5.0
    for _ in range(100_000):
        v_rest = float(b.ocv_v()[0] + b.v1_v[0])
        cmd = ch.command_a(i_prop)[0]
        if v_rest >= threshold:
            assert cmd == 0.0 and ch.full[0]
        else:
            assert not ch.full[0] and not ch.cv[0]        # a new cycle, in CC (far below CV)
            assert cmd == pytest.approx(i_prop + cc.cc_current_a)
            break
        b.step(-i_prop, 1.0)
    else:
        raise AssertionError("never recharged")
    # it took a real discharge: OCV below the threshold plus the RC pair's drop at 5 A (R1 i / n = 30 mV)
    assert ocv_cell_v(b.soc[0]) < cc.cv_cell_v - cc.recharge_drop_cell_v + p.r1_ohm_cell * i_prop + 1e-3
    assert b.soc[0] < 0.95
    for bad in (0.0, 0.6, math.nan):
        with pytest.raises(ValueError, match="recharge_drop_cell_v"):
            CcCvParams(recharge_drop_cell_v=bad)


def test_momentum_theory_hover_and_forward_flight():
    p = DroneParams()
    w = p.total_mass_kg * G_M_S2
    ideal = w * math.sqrt(w / (2 * 1.225 * p.disk_area_m2))
    assert hover_power_w(p) == pytest.approx(ideal / 0.6 / 0.8 + 8.0, rel=1e-12)
    assert propulsion_power_w(p, 0.0, 0.0) == pytest.approx(hover_power_w(p), rel=1e-9)
    # power bucket: moderate speed needs less than hover, high speed more; climbing costs more
    v = propulsion_power_w(p, [0.0, 8.0, 25.0])
    assert v[1] < v[0] < v[2]
    assert propulsion_power_w(p, 0.0, 2.0) > hover_power_w(p) > propulsion_power_w(p, 0.0, -1.0)
    # high-speed Glauert limit: induced velocity -> vh^2 / V
    big_v = 40.0
    pw = propulsion_power_w(DroneParams(flat_plate_area_m2=1e-9, avionics_w=0.0, figure_of_merit=1.0,
                                        drive_efficiency=1.0), big_v)
    vh2 = w / (2 * 1.225 * p.disk_area_m2)
    assert pw == pytest.approx(w * vh2 / big_v, rel=1e-3)
    # hover induced power scales as m^1.5
    p2 = DroneParams(payload_kg=1.0, avionics_w=0.0)
    p1 = DroneParams(avionics_w=0.0)
    assert hover_power_w(p2) / hover_power_w(p1) == pytest.approx(2.0**1.5, rel=1e-12)
    with pytest.raises(ValueError, match="figure_of_merit"):
        DroneParams(figure_of_merit=1.5)


def test_gusts_are_stationary_markov_and_hover_error_is_seeded():
    rng = np.random.default_rng(1)
    g = gust_series(400_000, 0.05, 1.3, 2.0, rng)
    assert g.std() == pytest.approx(1.3, rel=0.03)
    lag = int(2.0 / 0.05)
    rho = np.corrcoef(g[:-lag], g[lag:])[0, 1]
    assert rho == pytest.approx(math.exp(-1), abs=0.03)
    wp = WindParams()
    f = np.zeros((2000, 3))
    f[1000:, 0] = 1.0  # a 1 N step on a 1 kg drone -> static error 1 / w_p^2 after the loop settles
    e = hover_error_m(wp, f, 1.0, 0.02)
    step = e[-1, 0] - e[999, 0]
    assert step == pytest.approx(1.0 / wp.hold_omega_rad_s**2, rel=1e-3)
    # tilt: thrust balances a horizontal drag of m g -> 45 degrees, leaning against the force
    tilt, axis = tilt_from_force(1.0, np.zeros((1, 3)), np.array([[G_M_S2, 0.0, 0.0]]))
    assert tilt[0] == pytest.approx(math.pi / 4) and math.sin(axis[0] - math.pi / 2) == pytest.approx(0, abs=1e-12)


def test_scalar_stepper_equals_batched_step():
    from mission_sim.world.battery import scalar_stepper
    p = BatteryParams()
    b = Battery(p, n=1, soc=0.4)
    b.v1_v[:] = 0.03
    out = scalar_stepper(p)(0.4, 0.03, -7.5, 2.5)
    vt = b.mean_terminal_v(-7.5, 2.5)[0]
    e = b.step(-7.5, 2.5)
    np.testing.assert_allclose(out[:6], [b.soc[0], b.v1_v[0], e.chem_j[0], e.r0_loss_j[0], e.r1_loss_j[0],
                                         e.c1_delta_j[0]], rtol=1e-13)
    assert out[6] == pytest.approx(vt, rel=1e-13)
    assert out[6] * -7.5 * 2.5 == pytest.approx(sum(out[2:6]), rel=1e-12)
