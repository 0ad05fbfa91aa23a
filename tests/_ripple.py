"""The largest harmonic excess of the instantaneous peak over the envelope, from the physics
(:class:`wpt_receiver.peak.SbarHarmonics`), as a bound for the envs' overshoot tests."""

import numpy as np

from wpt_receiver import TABLE_I, steady_state
from wpt_receiver.devices import preset
from wpt_receiver.peak import SbarHarmonics


def ripple_bound_pts(devices: str = "schottky", vl_max_v: float = 33.0, i2_a: float = 11.5) -> float:
    """Max over duties of (instantaneous peak - |I2|) at ``i2_a`` and the top battery voltage of
    the envs' range, in percentage points of the Table I short-mode current."""
    h = SbarHarmonics(TABLE_I.with_(vl_v=vl_max_v), preset(devices))
    d = np.linspace(0.0, 1.0, 401)
    excess = h.peak(d, np.full_like(d, i2_a)) - i2_a
    return 100.0 * float(excess.max()) / float(steady_state(TABLE_I, 0.0)[1])
