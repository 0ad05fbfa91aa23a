"""A power-electronics researcher's own links (2026-11-27 night, branch ``peuser``): the library driven with links
other than Table I, each check against a closed form or the event-exact switching model. The links:

* ``LINK_2S``: 48 V source, 2S pack (7.4 V), L1 100 uH, L2 20 uH, k 0.1, R1 0.1, R2 0.03 ohm, 85 kHz;
* ``LINK_6S``: 24 V source, 6S pack (22.2 V), L1 60 uH, L2 30 uH, k 0.25, R1 0.06, R2 0.04 ohm, 85 kHz.
"""

import math

import numpy as np
import pytest

from wpt_receiver import LinkParams
from wpt_receiver.devices import envelope_params, preset

LINK_2S = LinkParams(l1_h=100e-6, l2_h=20e-6, lm_h=0.1 * math.sqrt(100e-6 * 20e-6), r1_ohm=0.10, r2_ohm=0.03,
                     vdc_v=48.0, vl_v=7.4, f_hz=85e3)
LINK_6S = LinkParams(l1_h=60e-6, l2_h=30e-6, lm_h=0.25 * math.sqrt(60e-6 * 30e-6), r1_ohm=0.06, r2_ohm=0.04,
                     vdc_v=24.0, vl_v=22.2, f_hz=85e3)
DV = preset("schottky")


@pytest.mark.parametrize("d", [0.3, 0.5])
def test_envelope_switching_loss_on_a_2s_link_matches_the_switching_model(d):
    """``sizing.envelope_currents`` (``sizing --source mission``) took the SBAR's edge energies at Table I's 30 V
    and 85 kHz whatever the run: on a 2S pack (7.4 V) 0.768 W at d = 0.5 against the switching model's exact edges
    0.217 W (3.5x). With the run's VL and f: 0.2166 W."""
    from wpt_receiver.envelope import steady_state
    from wpt_receiver.sbar import rectifier_v2_folded
    from wpt_receiver.sizing import envelope_currents, rectifier_currents
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    p, T = LINK_2S, LINK_2S.rectifier_period_s
    link = SwitchingLink(p, SwitchingConfig(devices=DV))
    exact = rectifier_currents(link.run(link.schedule(0.0, 40 * T, d), link.periodic_steady_state(d)),
                               window_s=20 * T, per_half_cycle=256)
    pe = envelope_params(p, DV)
    i2 = float(steady_state(pe, rectifier_v2_folded(d, p.vl_v, 20.0, DV))[1])
    i1 = float(steady_state(pe, rectifier_v2_folded(d, p.vl_v, i2, DV))[0])
    n = 400
    env = envelope_currents(np.arange(1, n + 1) * T / 4, np.full(n, T / 4), np.full(n, d), np.full(n, i1),
                            np.full(n, i2), exact["peak_i2_a"], DV, window_s=20 * T, vl_v=p.vl_v, f_hz=p.f_hz)
    assert env["switching_loss_w"] == pytest.approx(exact["switching_loss_w"], rel=0.05)
    assert env["conduction_loss_w"] == pytest.approx(exact["conduction_loss_w"], rel=0.03)
    # a per-step VL (a mission's battery_v) is the same as the number when constant
    env_rows = envelope_currents(np.arange(1, n + 1) * T / 4, np.full(n, T / 4), np.full(n, d), np.full(n, i1),
                                 np.full(n, i2), exact["peak_i2_a"], DV, window_s=20 * T, vl_v=np.full(n, p.vl_v),
                                 f_hz=p.f_hz)
    assert env_rows["switching_loss_w"] == pytest.approx(env["switching_loss_w"], rel=1e-12)


def test_envelope_currents_refuses_a_bad_vl():
    from wpt_receiver.sizing import envelope_currents
    with pytest.raises(ValueError, match=r"vl_v=-1.0 is invalid; valid range: \(0, inf\) V"):
        envelope_currents([1e-5], [1e-5], [0.5], [1.0], [1.0], 1.0, DV, vl_v=-1.0, f_hz=85e3)
    with pytest.raises(ValueError, match=r"f_hz=0.0 is invalid"):
        envelope_currents([1e-5], [1e-5], [0.5], [1.0], [1.0], 1.0, DV, vl_v=7.4, f_hz=0.0)
