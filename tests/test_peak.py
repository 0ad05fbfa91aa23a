"""Instantaneous peak of i2 from the envelope side (wpt_receiver.peak + wpt_receiver.modal) against
the event-exact switching model: fixed duties 0..0.9, the RM -> SM step (peak and the later
beats), the V2 ramp and the duty ramp, all within 1 %; eq. 4 alone misses them by several %."""

import numpy as np
import pytest
from scipy.signal import find_peaks

from wpt_receiver import TABLE_I
from wpt_receiver.envelope import simulate
from wpt_receiver.modal import ModalEnvelope, simulate_modal
from wpt_receiver.peak import SbarHarmonics
from wpt_receiver.references import reference_duty
from wpt_receiver.sbar import v2_from_duty
from wpt_receiver.switching import SwitchingConfig, SwitchingLink

P = TABLE_I
T = P.rectifier_period_s


@pytest.fixture(scope="module")
def link():
    # 64 dense samples per half cycle: at small duties the peak sits on the kink where the short
    # window ends, which 16 samples plus the parabola/Newton refinement miss by up to 0.45 %
    return SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64))


def _switching_peaks(link, d):
    return link.simulate(d, T).envelope()["i2_env_a"].to_numpy()


def test_modal_frequencies_are_the_exact_ones():
    lam = ModalEnvelope(P).lam.imag / P.omega_rad_s
    assert sorted(lam) == pytest.approx(sorted([1 / np.sqrt(1 - P.k) - 1, 1 / np.sqrt(1 + P.k) - 1]), rel=1e-3)


def test_harmonic_balance_reduces_to_eq9_without_ripple():
    sh = SbarHarmonics(P)
    d = np.linspace(0, 0.9, 10)
    v = sh.v2_harmonics(d, np.full(10, np.pi / 2), np.array([1]))[:, 0]
    assert np.allclose(v, v2_from_duty(d, P.vl_v), atol=1e-12)


@pytest.mark.parametrize("d", np.round(np.arange(0.0, 1.0, 0.1), 1))
def test_fixed_duty_peak_within_1pct(link, d):
    sw = _switching_peaks(link, np.full(24, d))[-8:].max()
    i2, est = ModalEnvelope(P).steady_peak(float(d))
    assert est == pytest.approx(sw, rel=0.01)
    assert abs(i2) == pytest.approx(link.simulate(np.full(24, d), T).envelope()["i2_fund_a"].iloc[-1], rel=2e-3)


def _transient(link, name, t_end_s, **kw):
    _, d, _ = reference_duty(name, P, 0.5e-3, t_end_s, T, **kw)
    return d, _switching_peaks(link, d), simulate_modal(P, d, T)["peak_i2_a"][1:]


def test_step_peak_and_beats_within_1pct(link):
    d, sw, est = _transient(link, "step", 2.5e-3)
    k0 = int(0.5e-3 / T)
    beats = [y[k0:][find_peaks(y[k0:], distance=15, prominence=1)[0][:3]] for y in (sw, est)]
    assert beats[1] == pytest.approx(beats[0], rel=0.01)
    _, _, i2e = simulate(P, v2_from_duty(d, P.vl_v), T)
    e4 = np.abs(i2e[1:])[k0:]
    e4_beats = e4[find_peaks(e4, distance=15, prominence=1)[0][:3]]
    assert np.max(np.abs(e4_beats / beats[0] - 1)) > 0.03      # eq. 4's symmetric modes miss them


@pytest.mark.parametrize("kind", ["v2", "duty"])
def test_ramp_peak_within_1pct(link, kind):
    d, sw, est = _transient(link, "ramp", 6.5e-3, ramp_kind=kind)
    assert est.max() == pytest.approx(sw.max(), rel=0.01)
    if kind == "v2":   # eq. 4 with eq. 9 misses the quadrature of v2 that collapses at d -> 1
        _, _, i2e = simulate(P, v2_from_duty(d, P.vl_v), T)
        assert np.abs(i2e).max() < 0.97 * sw.max()


def test_peak_table_matches_direct_evaluation():
    from wpt_receiver.peak import PeakTable
    sh = SbarHarmonics(P)
    pt = PeakTable(sh, i2_max_a=60.0)
    rng = np.random.default_rng(3)
    d, i2 = rng.uniform(0, 1, 500), rng.uniform(3, 60, 500) * rng.choice([-1, 1], 500)
    assert np.allclose(pt(d, i2), sh.peak(d, i2), rtol=2e-3)
    assert isinstance(pt(0.2, 11.0), float)
    with pytest.raises(ValueError, match="i2_max_a"):
        PeakTable(sh, i2_max_a=0.0)
