"""A long multi-pad mission recharges at the pads it needs (issue 22): the charger's *full* state
clears below the recharge threshold, in the Python reference loop and the compiled loop alike."""

import numpy as np
import pytest

from mission_sim.config import config_from_dict, load_config_dict
from mission_sim.contract import PolicyContext
from mission_sim.world.runner import run_mission
from policies import make


#: hover at the default mission's long pad [s] (default 120 s). The CV taper of the default pack runs with
#: the time constant ``tau = r0 Q / (n dOCV/dSoC) = 0.096 ohm * 4680 C / (8 * 0.92 V) ~ 60 s`` (near full),
#: so from CC (1.3 A) to the C/10 cut-off takes >= ln(10) tau ~ 140 s of CV after the CC part. With 120 s
#: the charger reached *full* on eq. 4's link 7.6 s before the visit's end (the 4th visit), and on the
#: exact-mode link in none of the 20 visits (its taper is slower: the model-based policy picks its duty
#: from eq. 9, which the exact link's rectifier, v2's quadrature included, does not quite deliver).
#: The test is about what happens after *full*, so the visit is long enough for the taper to finish.
LONG_HOVER_S = 180.0


def _repeated(n: int):
    d = load_config_dict(None)
    d["pads"] = [dict(p, hover_time_s=LONG_HOVER_S) if p["hover_time_s"] >= 120.0 else p for p in d["pads"]] * n
    return config_from_dict(d)


def _charging_episodes(ts) -> list[tuple[float, float]]:
    """(start, end) [s] of the runs of rows with the battery charging (I_batt > 0.05 A)."""
    t, on = ts["t_s"].to_numpy(), ts["battery_current_a"].to_numpy() > 0.05
    episodes, start = [], None
    for ti, c in zip(t, on):
        if c and start is None:
            start = ti
        if not c and start is not None:
            episodes.append((start, ti))
            start = None
    merged = []   # rows of one pad visit are seconds apart, pad visits tens of seconds
    for a, b in episodes:
        if merged and a - merged[-1][1] < 10.0:
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    return merged


def test_default_pads_repeated_10x_recharge_at_later_pads_and_never_empty():
    cfg = _repeated(10)
    pol = make("model_based", PolicyContext(control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a))
    res = run_mission(cfg, pol)
    s, ts = res.summary, res.timeseries
    assert not s["battery_depleted"] and s["min_soc"] > 0.8
    assert s["sim_time_s"] > 2000.0                      # the whole mission flown (it used to end at 1,917 s)
    episodes = _charging_episodes(ts)
    assert len(episodes) >= 3 and episodes[-1][0] > 0.75 * s["sim_time_s"]   # charged again at late pads
    # full, pads passed without charging, then a new cycle once the battery fell to the threshold:
    # a charging episode that starts well below the SoC reached before it (by > 0.05)
    soc, t = ts["soc"].to_numpy(), ts["t_s"].to_numpy()
    restarts = [a for a, _ in episodes[1:] if soc[np.searchsorted(t, a)] < soc[t < a].max() - 0.05]
    assert restarts and max(restarts) > 0.5 * s["sim_time_s"]
    gaps = [b[0] - a[1] for a, b in zip(episodes, episodes[1:])]
    assert max(gaps) > 100.0      # pads with the battery full: passed without charging
    # energy: what went into the battery is what the pads' charging cycles put there (balance closes)
    assert s["energy_balance_error_rel"] < 1e-12 and s["battery_charge_in_j"] > 0


def test_recharge_is_the_same_in_the_compiled_and_the_reference_loop():
    pytest.importorskip("numba")
    from tests.test_mission_fast import assert_summaries_agree, assert_timeseries_agree
    cfg = _repeated(4)
    pol = lambda: make("model_based", PolicyContext(control_period_s=cfg.sim.control_period_s,  # noqa: E731
                                                    rated_i2_a=cfg.link.rated_i2_a))
    fast, ref = run_mission(cfg, pol(), compiled=True), run_mission(cfg, pol(), compiled=False)
    assert_summaries_agree(fast.summary, ref.summary)
    assert_timeseries_agree(fast.timeseries, ref.timeseries)
    assert len(_charging_episodes(ref.timeseries)) >= 2
