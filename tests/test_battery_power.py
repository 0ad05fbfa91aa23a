"""Battery, CC-CV charging (the mission kernel's, mission_sim.world.loop_kernel), momentum-theory power and
the wind model against closed forms."""

import math

import numpy as np
import pytest

from mission_sim.world.battery import TRIP_MARGIN_CELL_V, BatteryParams, CcCvParams, ocv_cell_v
from mission_sim.world.fastpath import battery_values, constants
from mission_sim.world.loop_kernel import STATE_DTYPE, _bat_step, _charger_command, _ocv_cell
from mission_sim.world.power import G_M_S2, DroneParams, hover_power_w, propulsion_power_w
from mission_sim.world.wind import WindParams, gust_series, hover_error_m, tilt_from_force


def _consts(p=BatteryParams(), cc=CcCvParams()):
    """The kernel's constants record with the battery's and the charger's fields (attribute access)."""
    return constants(battery_values(p, cc)).view(np.recarray)[0]


def _state(soc, vrc=0.0):
    s = np.zeros(1, STATE_DTYPE).view(np.recarray)
    s[0].soc, s[0].vrc = soc, vrc
    return s[0]


def _mean_terminal_v(p, soc, v1, i, dt):
    """Closed form of the mean terminal voltage over a held-current step: OCV + R0 i + mean(v1)."""
    e = math.exp(-dt / p.tau1_s)
    vinf = p.r1_ohm * i
    return p.ocv_v(soc) + p.r0_ohm * i + (vinf * dt + (v1 - vinf) * p.tau1_s * (1.0 - e)) / dt


def test_battery_step_energy_identity_and_substep_consistency():
    """The mission kernel's battery step (loop_kernel._bat_step): terminal energy = chem + R0 + R1 + dC1,
    one 7 s step == 7000 steps of 1 ms, coulomb counting."""
    p = BatteryParams()
    c = _consts(p)
    for soc, v1, i in ((0.2, 0.05, 2.0), (0.5, -0.1, -10.0), (0.9, 0.0, 0.7)):
        soc1, v1_1, chem, r0, r1, dc1 = _bat_step(c, soc, v1, i, 7.0)
        assert _mean_terminal_v(p, soc, v1, i, 7.0) * i * 7.0 == pytest.approx(chem + r0 + r1 + dc1, rel=1e-12)
        assert chem == pytest.approx(p.ocv_v(soc) * i * 7.0, rel=1e-12)
        s, v, r1_sum = soc, v1, 0.0
        for _ in range(7000):
            s, v, _, _, r1_k, _ = _bat_step(c, s, v, i, 1e-3)
            r1_sum += r1_k
        assert v == pytest.approx(v1_1, rel=1e-9) and r1_sum == pytest.approx(r1, rel=1e-9)
        assert soc1 - soc == pytest.approx(i * 7.0 / p.capacity_c, rel=1e-12)


def test_battery_terminal_voltage_settles_to_ocv_plus_r_i():
    p = BatteryParams()
    soc1, v1, *_ = _bat_step(_consts(p), p.initial_soc, 0.0, -3.0, 50 * p.tau1_s)
    assert p.ocv_v(soc1) + p.r0_ohm * -3.0 + v1 == pytest.approx(p.ocv_v(soc1) - 3.0 * (p.r0_ohm + p.r1_ohm), rel=1e-9)
    # OCV curve: monotone, 8S pack from ~21 V empty to ~32.8 V full (Chen & Rincon-Mora fit, 4.103 V/cell)
    s = np.linspace(0, 1, 101)
    assert np.all(np.diff(ocv_cell_v(s)) > 0)
    assert p.ocv_v(1.0) == pytest.approx(8 * 4.1033, rel=1e-4)
    # the kernel's curve (the mission's) and the numpy one (envs, config ranges) are the same fit
    np.testing.assert_allclose([_ocv_cell(x) for x in (-0.1, *s, 1.2)], ocv_cell_v(np.r_[-0.1, s, 1.2]), rtol=1e-14)


def _charge_to_full(p, cc, c, st):
    """Charge at the kernel charger's target (no propulsion) in 1 s steps until full; True if CC was seen."""
    v_cv, seen_cc = cc.cv_cell_v * p.n_series, False
    for _ in range(20000):
        tgt = _charger_command(st, c, 0.0)
        if st.full:
            return seen_cc
        seen_cc |= tgt == cc.cc_current_a
        # terminal voltage over the step never exceeds the CV limit (model-based CV)
        assert _mean_terminal_v(p, st.soc, st.vrc, tgt, 1.0) <= v_cv + 1e-6 or tgt == cc.cc_current_a
        st.soc, st.vrc = _bat_step(c, st.soc, st.vrc, tgt, 1.0)[:2]
    raise AssertionError("never full")


def test_cccv_charges_to_full_without_exceeding_cv_and_then_stops():
    p, cc = BatteryParams(initial_soc=0.93), CcCvParams()
    c, st = _consts(p, cc), _state(0.93)
    assert _charge_to_full(p, cc, c, st)
    assert st.full and st.cv and st.soc > 0.98
    # full: the power path, the command is the load current alone (the pack gets 0); no load -> short mode
    assert _charger_command(st, c, 5.0) == 5.0 and _charger_command(st, c, 0.0) == 0.0
    # a full pack pushed above the CV voltage (a receiver delivering more than the load): the command is the load
    # less the CV law's (negative) current, so the pack is drawn back to CV in proportion, no on-off switching; 0
    # (short mode) only when the command would be negative or above the over-voltage trip (TRIP_MARGIN_CELL_V)
    v_cv = cc.cv_cell_v * p.n_series
    for excess in (1e-3, 0.1, TRIP_MARGIN_CELL_V * p.n_series - 1e-6):
        st.vrc = v_cv - float(p.ocv_v(st.soc)) + excess
        assert _charger_command(st, c, 5.0) == pytest.approx(5.0 - excess / p.r0_ohm, rel=1e-9, abs=1e-9) and st.full
    assert 5.0 - excess / p.r0_ohm < 4.0        # the trip is well into the proportional range
    st.vrc = v_cv - float(p.ocv_v(st.soc)) + 0.1
    assert _charger_command(st, c, 0.5) == 0.0 and st.full               # 0.5 A - 1.04 A: clipped at 0
    st.vrc = v_cv - float(p.ocv_v(st.soc)) + TRIP_MARGIN_CELL_V * p.n_series + 1e-6
    assert _charger_command(st, c, 5.0) == 0.0 and st.full               # the trip
    st.vrc = v_cv - float(p.ocv_v(st.soc)) - 1e-3
    assert _charger_command(st, c, 5.0) == 5.0 and st.full               # at or below CV: the load current alone


def test_full_battery_recharges_below_the_recharge_threshold_and_not_above():
    """A full battery under load: the command stays the load current (the power path: no battery current) while
    (OCV + v1)/n >= cv_cell_v - recharge_drop_cell_v, and a new CC cycle (cv flag cleared, command = propulsion +
    CC current) starts at the first BMS call below."""
    p, cc = BatteryParams(initial_soc=0.93), CcCvParams(recharge_drop_cell_v=0.1)
    c, st = _consts(p, cc), _state(0.93)
    _charge_to_full(p, cc, c, st)
    threshold = (cc.cv_cell_v - cc.recharge_drop_cell_v) * p.n_series
    i_prop = 5.0
    for _ in range(100_000):
        v_rest = float(p.ocv_v(st.soc) + st.vrc)
        cmd = _charger_command(st, c, i_prop)
        if v_rest >= threshold:
            assert cmd == i_prop and st.full
        else:
            assert not st.full and not st.cv        # a new cycle, in CC (far below CV)
            assert cmd == pytest.approx(i_prop + cc.cc_current_a)
            break
        st.soc, st.vrc = _bat_step(c, st.soc, st.vrc, -i_prop, 1.0)[:2]
    else:
        raise AssertionError("never recharged")
    # it took a real discharge: OCV below the threshold plus the RC pair's drop at 5 A (R1 i / n = 30 mV)
    assert ocv_cell_v(st.soc) < cc.cv_cell_v - cc.recharge_drop_cell_v + p.r1_ohm_cell * i_prop + 1e-3
    assert st.soc < 0.95
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


def _bms_setup(soc, cmd, **sim):
    """A kernel state over an energised pad (on, V1 nominal) with the last command ``cmd``, a sample with a 300 W
    load, and constants with the default battery and charger, a 4 s BMS period and a 0.25 A dead band."""
    from mission_sim.world.loop_records import SAMPLE_DTYPE
    p, cc = BatteryParams(), CcCvParams()
    vals = dict(battery_values(p, cc), v1_nom=100.0, bms_period=4.0, cmd_deadband=0.25, k_on=0.1, k_off=0.05)
    vals.update(sim)
    c = constants(vals).view(np.recarray)[0]
    st = _state(soc)
    st.tx_on, st.v1, st.cmd, st.last_vl, st.t_last_bms = True, 100.0, cmd, 30.0, -10.0
    here = np.zeros(1, SAMPLE_DTYPE).view(np.recarray)[0]
    here.t, here.k, here.p, here.elig = 0.0, 0.2, 300.0, True
    return p, cc, c, st, here


def test_entering_full_applies_the_command_despite_the_dead_band():
    """The CV command just above the cut-off and the full one (the load alone) differ by ~the cut-off current (0.13 A),
    less than the dead band (0.25 A): entering *full* applies the command anyway, so the pack is not left on the
    last CV current until the load moves. Leaving it (a new cycle below the recharge threshold) likewise."""
    from mission_sim.world.loop_kernel import _bms_command
    p, cc = BatteryParams(), CcCvParams()
    v_cv = cc.cv_cell_v * p.n_series
    # a SoC whose CV current (v1 = 0) is just below the cut-off: full at this update
    lo, hi = 0.9, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if (v_cv - float(p.ocv_v(mid))) / p.r0_ohm > 0.9 * cc.cutoff_current_a else (lo, mid)
    i_load = 300.0 / 30.0
    _, _, c, st, here = _bms_setup(hi, i_load + cc.cutoff_current_a)   # the last CV command, held since
    st.cv = True
    assert _bms_command(st, c, here, 0.0, False)
    assert st.full and st.cmd == i_load
    # the same step without the change of state is swallowed by the dead band
    st.cmd, st.t_last_bms = i_load + cc.cutoff_current_a, -10.0
    assert not _bms_command(st, c, here, 0.0, False) and st.cmd == i_load + cc.cutoff_current_a


def test_a_pad_switching_on_starts_a_new_charge_cycle():
    """The pad's off -> on edge clears *full* and *cv* (the host restarts the charge cycle on input power, e.g. TI
    BQ25601D's CE toggled), so a full pack that the flight drained a little is topped off at the next pad."""
    from mission_sim.world.loop_kernel import _charger_command, _gate_pad
    p, cc, c, st, here = _bms_setup(0.97, 0.0)
    st.full, st.cv, st.tx_on, st.v1 = True, True, False, 0.0
    v_rest = float(p.ocv_v(0.97))
    assert v_rest > (cc.cv_cell_v - cc.recharge_drop_cell_v) * p.n_series   # above the recharge threshold
    assert _charger_command(st, c, 10.0) == 10.0 and st.full               # full: the load alone
    assert _gate_pad(st, c, here, 0.0, False) and st.tx_on
    assert not st.full and not st.cv
    assert _charger_command(st, c, 10.0) == pytest.approx(10.0 + cc.cc_current_a)   # charging again (CC)
