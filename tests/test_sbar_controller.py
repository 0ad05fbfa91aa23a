"""SBAR mapping (eq. 9), the inverse-model controller (Fig. 5) and Table II."""

import math

import numpy as np
import pytest

from wpt_receiver import TABLE_I, InverseModelController, LowPassFilter, duty_from_v2, steady_state, v2_from_duty
from wpt_receiver.paper import run_paper
from wpt_receiver.references import ramp_duration_s

P = TABLE_I
VMAX = 4 / math.pi * 30


def test_duty_mapping_endpoints_and_round_trip():
    assert v2_from_duty(0.0, 30.0) == pytest.approx(VMAX)
    assert v2_from_duty(1.0, 30.0) == pytest.approx(0.0, abs=1e-12)
    assert v2_from_duty(1 / 3, 30.0) == pytest.approx(VMAX * 0.5)  # sin(pi/6) = 1/2
    v = np.linspace(0, VMAX, 101)
    np.testing.assert_allclose(v2_from_duty(duty_from_v2(v, 30.0), 30.0), v, atol=1e-9)
    d = np.linspace(0, 1, 101)
    np.testing.assert_allclose(duty_from_v2(v2_from_duty(d, 30.0), 30.0), d, atol=1e-7)


@pytest.mark.parametrize("d", [-0.01, 1.01, float("nan")])
def test_duty_out_of_range_raises(d):
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        v2_from_duty(d, 30.0)


@pytest.mark.parametrize("v", [-1.0, VMAX + 0.1])
def test_v2_out_of_range_raises(v):
    with pytest.raises(ValueError, match="valid range"):
        duty_from_v2(v, 30.0)


def test_controller_dc_gain_gives_exact_steady_v2():
    ctl = InverseModelController(P)
    for v2 in (0.0, 10.0, VMAX):
        i2 = steady_state(P, v2)[1]
        ctl.reset(i2)
        d = ctl.step(i2)
        assert ctl.v2_cmd_v[0] == pytest.approx(v2, abs=1e-6)
        assert v2_from_duty(d[0], 30.0) == pytest.approx(v2, abs=1e-6)


def test_controller_v2_settles_as_the_paper_describes():
    """V2* decays with the slow zero of G22 (2 L1/R1 = 4.37 ms) and settles around 14 ms."""
    dt = P.rectifier_period_s
    i_rm, i_sm = steady_state(P, VMAX)[1], steady_state(P, 0)[1]
    ref = np.full(int(30e-3 / dt), i_sm)
    ref[0] = i_rm
    v2, _ = InverseModelController(P).run(ref)
    t = np.arange(len(v2)) * dt
    assert ramp_duration_s(P) == pytest.approx(2 * 236e-6 / 0.108)
    settle5 = t[np.nonzero(np.abs(v2) > 0.05 * VMAX)[0][-1]]
    assert 10e-3 < settle5 < 18e-3
    assert np.all(v2 <= VMAX + 1e-9)  # never asks for more than RM can give


def test_filter_validation():
    with pytest.raises(ValueError, match="order"):
        LowPassFilter(order=0)
    with pytest.raises(ValueError, match="tau_s"):
        LowPassFilter(tau_s=0.0)


@pytest.fixture(scope="module")
def table2():
    return {r.trajectory: r.metrics for r in run_paper()}


def test_table2_step_peak(table2):
    m = table2["step"]
    assert m.max_current_a == pytest.approx(49.1, rel=0.10)  # the paper
    assert m.max_current_a == pytest.approx(50.4, rel=0.02)  # independent SPICE
    assert m.final_current_a == pytest.approx(steady_state(P, 0)[1], rel=1e-3)
    assert m.rm_current_a == pytest.approx(steady_state(P, VMAX)[1], rel=1e-9)


def test_table2_proposed_has_no_overshoot_and_ordering_holds(table2):
    assert table2["proposed"].overshoot_pct <= 0.5
    assert table2["step"].max_current_a > table2["ramp"].max_current_a > table2["proposed"].max_current_a
    assert table2["step"].overshoot_pct > table2["ramp"].overshoot_pct > table2["proposed"].overshoot_pct
    # the proposed transfers more energy to the battery during the transition than the step
    assert table2["proposed"].energy_to_battery_j > table2["ramp"].energy_to_battery_j > table2["step"].energy_to_battery_j


def test_duty_from_v2_scalar_in_scalar_out():
    d = duty_from_v2(v2_from_duty(0.5, 30.0), 30.0)
    assert isinstance(d, float) and d == pytest.approx(0.5)
