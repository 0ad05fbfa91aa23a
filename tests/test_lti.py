"""wpt_receiver.lti reproduces scipy.signal bit for bit (it replaces it on the mission path)."""

import numpy as np
import pytest
from scipy import signal

from wpt_receiver import TABLE_I, lti
from wpt_receiver.inverse_controller import LowPassFilter, inverse_tf


@pytest.mark.parametrize("order", [1, 2, 3])
def test_tf2ss_and_zoh_match_scipy_exactly(order):
    num, den = inverse_tf(TABLE_I, LowPassFilter(order=order))
    ref = signal.tf2ss(num, den)
    got = lti.tf2ss(num, den)
    for r, g in zip(ref, got):
        assert np.array_equal(r, g)
    dt = TABLE_I.rectifier_period_s
    ad, bd, _, _, _ = signal.cont2discrete(ref, dt, method="zoh")
    gad, gbd = lti.zoh_ss(got[0], got[1], dt)
    assert np.array_equal(ad, gad) and np.array_equal(bd, gbd)


def test_zoh_tf_matches_cont2discrete_and_holds_dc_gain():
    w, z, dt = 2.5, 0.7, 0.2
    num, den, _ = signal.cont2discrete(([1.0], [1.0, 2 * z * w, w * w]), dt, method="zoh")
    gnum, gden = lti.zoh_tf([1.0], [1.0, 2 * z * w, w * w], dt)
    assert np.array_equal(num, gnum) and np.array_equal(den, gden)
    # ZOH keeps the DC gain 1/w^2 of the continuous system
    assert np.sum(gnum) / np.sum(gden) == pytest.approx(1 / w**2, rel=1e-12)


def test_lfilter_matches_scipy_on_several_filters():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((500, 3))
    for b, a in (([1.0], [1.0, -0.95]), ([0.0, 0.2, 0.1], [1.0, -1.1, 0.4]), ([0.5, 0.3], [2.0, -0.4, 0.1])):
        assert np.array_equal(signal.lfilter(b, a, x, axis=0), lti.lfilter(b, a, x, axis=0))
    # FIR (a of length 1): scipy convolves instead, so equal only to round-off
    assert np.allclose(signal.lfilter([1.0, 2.0, 1.0], [1.0], x, axis=0), lti.lfilter([1.0, 2.0, 1.0], [1.0], x, axis=0),
                       rtol=1e-13, atol=1e-15)
    assert np.array_equal(signal.lfilter([1.0], [1.0, -0.5], x[:, 0]), lti.lfilter([1.0], [1.0, -0.5], x[:, 0]))


def test_first_order_filter_impulse_response_is_geometric():
    y = lti.lfilter([1.0], [1.0, -0.5], np.r_[1.0, np.zeros(9)])
    assert np.array_equal(y, 0.5 ** np.arange(10))


def test_bad_denominator_is_rejected():
    with pytest.raises(ValueError, match="den"):
        lti.tf2ss([1.0], [0.0, 0.0])
