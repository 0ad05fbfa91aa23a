"""The envelope-against-switching setup shared by tests/test_sizing.py and tests/test_peuser.py: a link held at one
duty, its exact switching waveform's device currents and losses, and ``sizing.envelope_currents`` on the envelope's
steady state at that duty (what ``sizing --source mission`` uses)."""

from __future__ import annotations

import numpy as np


def envelope_against_switching(p, devices, d: float, i2_guess_a: float, n: int = 400):
    """``(exact, envelope)``: ``exact`` the switching model's ``rectifier_currents`` over 20 periods after 20 periods
    from its periodic steady state at duty ``d`` (256 points a half cycle), ``envelope(vl_v=p.vl_v)`` the
    envelope's ``envelope_currents`` over ``n`` quarter-period rows of that duty's steady state (``i2_guess_a``: the
    I2 the folded V2 is first taken at), with the link's ``f_hz``; ``vl_v`` a number or one per row."""
    from wpt_receiver.devices import envelope_params
    from wpt_receiver.envelope import steady_state
    from wpt_receiver.sbar import rectifier_v2_folded
    from wpt_receiver.sizing import envelope_currents, rectifier_currents
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    t = p.rectifier_period_s
    link = SwitchingLink(p, SwitchingConfig(devices=devices))
    exact = rectifier_currents(link.run(link.schedule(0.0, 40 * t, d), link.periodic_steady_state(d)),
                               window_s=20 * t, per_half_cycle=256)
    pe = envelope_params(p, devices)
    i2 = float(steady_state(pe, rectifier_v2_folded(d, p.vl_v, i2_guess_a, devices))[1])
    i1 = float(steady_state(pe, rectifier_v2_folded(d, p.vl_v, i2, devices))[0])

    def envelope(vl_v=p.vl_v):
        return envelope_currents(np.arange(1, n + 1) * t / 4, np.full(n, t / 4), np.full(n, d), np.full(n, i1),
                                 np.full(n, i2), exact["peak_i2_a"], devices, window_s=20 * t, vl_v=vl_v, f_hz=p.f_hz)
    return exact, envelope
