"""The autoreset's plans when every window starts at one SoC (most scenarios: ``nominal`` draws no SoC):
:func:`envs.core._initial_state` takes the battery's equivalent circuit (:func:`envs.plant.battery_operating_point`)
once and broadcasts it, which must give every window the numbers of its own computation (the circuit is
elementwise). The reference is the same source run window by window (a one-element SoC array takes the general
path), not a second copy of the formulas."""

import numpy as np
import pytest

from envs.core import EnvConfig, _initial_state
from envs.plant import battery_operating_point


@pytest.mark.parametrize("n", [2, 7, 64, 4096])
@pytest.mark.parametrize("soc", [0.0, 0.02, 0.5, 0.95, 1.0])
def test_the_circuit_of_one_soc_is_each_windows_own(n, soc):
    """The identity the shortcut relies on: numpy's circuit of an array of one SoC repeated is, element by
    element and to the bit, the circuit of that SoC alone (whatever the array's length: numpy's vector loops
    and their tails)."""
    full = battery_operating_point(np.full(n, soc))
    one = battery_operating_point(np.array([soc]))
    for f, o in zip(full, one):
        assert np.broadcast_to(f, (n,)).tobytes() == np.broadcast_to(o, (n,)).tobytes()


@pytest.mark.parametrize("scenario_soc", [0.5, 0.13])
def test_initial_state_with_one_soc_equals_each_window_started_alone(scenario_soc):
    cfg = EnvConfig()
    link = cfg.link_folded
    rng = np.random.default_rng(5)
    n = 257
    lm0 = link.lm_h * rng.uniform(0.8, 1.25, n)
    cmd0 = rng.uniform(2.0, 7.0, n)
    load = np.full(n, 99.0)
    soc = np.full(n, scenario_soc)
    battery, state0 = _initial_state(link, lm0, soc, load, cmd0, cfg)
    assert battery.shape == (n, 9) and state0.shape == (n, 6)
    for i in range(n):
        b1, s1 = _initial_state(link, lm0[i:i + 1], soc[i:i + 1], load[i:i + 1], cmd0[i:i + 1], cfg)
        assert battery[i].tobytes() == b1[0].tobytes(), i
        assert state0[i].tobytes() == s1[0].tobytes(), i
    # and a draw of different SoCs (the general path) is unchanged by one window's SoC moving
    soc2 = soc.copy()
    soc2[3] = 0.9
    b2, s2 = _initial_state(link, lm0, soc2, load, cmd0, cfg)
    assert b2[4].tobytes() == battery[4].tobytes() and b2[3].tobytes() != battery[3].tobytes()
    # ... and the moved window gets its own circuit (a shortcut firing on different SoCs would give it the others')
    b3, s3 = _initial_state(link, lm0[3:4], soc2[3:4], load[3:4], cmd0[3:4], cfg)
    assert b2[3].tobytes() == b3[0].tobytes() and s2[3].tobytes() == s3[0].tobytes()
