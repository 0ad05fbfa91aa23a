"""wpt_receiver.lti reproduces scipy.signal (it replaces it on the mission path).

Compared to round-off (``RTOL``), not bit for bit: scipy's implementation may change its operation
order between releases, and a user's install must not fail on that (issue 25)."""

import numpy as np
import pytest
from scipy import signal

from wpt_receiver import TABLE_I, lti
from wpt_receiver.inverse_controller import LowPassFilter, inverse_tf

RTOL = 1e-12


def _same(a, b):
    np.testing.assert_allclose(b, a, rtol=RTOL, atol=1e-14)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_tf2ss_and_zoh_match_scipy(order):
    num, den = inverse_tf(TABLE_I, LowPassFilter(order=order))
    ref = signal.tf2ss(num, den)
    got = lti.tf2ss(num, den)
    for r, g in zip(ref, got):
        _same(r, g)
    dt = TABLE_I.rectifier_period_s
    ad, bd, _, _, _ = signal.cont2discrete(ref, dt, method="zoh")
    gad, gbd = lti.zoh_ss(got[0], got[1], dt)
    _same(ad, gad)
    _same(bd, gbd)


def test_zoh_tf_matches_cont2discrete_and_holds_dc_gain():
    w, z, dt = 2.5, 0.7, 0.2
    num, den, _ = signal.cont2discrete(([1.0], [1.0, 2 * z * w, w * w]), dt, method="zoh")
    gnum, gden = lti.zoh_tf([1.0], [1.0, 2 * z * w, w * w], dt)
    _same(num, gnum)
    _same(den, gden)
    # ZOH keeps the DC gain 1/w^2 of the continuous system
    assert np.sum(gnum) / np.sum(gden) == pytest.approx(1 / w**2, rel=1e-12)


def test_lfilter_matches_scipy_on_several_filters():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((500, 3))
    for b, a in (([1.0], [1.0, -0.95]), ([0.0, 0.2, 0.1], [1.0, -1.1, 0.4]), ([0.5, 0.3], [2.0, -0.4, 0.1])):
        _same(signal.lfilter(b, a, x, axis=0), lti.lfilter(b, a, x, axis=0))
    # FIR (a of length 1): scipy convolves instead, so equal only to round-off
    assert np.allclose(signal.lfilter([1.0, 2.0, 1.0], [1.0], x, axis=0), lti.lfilter([1.0, 2.0, 1.0], [1.0], x, axis=0),
                       rtol=1e-13, atol=1e-15)
    _same(signal.lfilter([1.0], [1.0, -0.5], x[:, 0]), lti.lfilter([1.0], [1.0, -0.5], x[:, 0]))


def test_first_order_filter_impulse_response_is_geometric():
    y = lti.lfilter([1.0], [1.0, -0.5], np.r_[1.0, np.zeros(9)])
    assert np.array_equal(y, 0.5 ** np.arange(10))


def test_bad_denominator_is_rejected():
    with pytest.raises(ValueError, match="den"):
        lti.tf2ss([1.0], [0.0, 0.0])
