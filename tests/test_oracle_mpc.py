"""The per-window oracle (policies.oracle), the fast duty replay (envs.rollout) and the MPC baseline
(policies.mpc): the oracle is a bound on the fixed policies it starts from, the replay is the env,
the MPC with the true model and budget 0 stays within the window's floor."""

import numpy as np
import pytest

from envs.rollout import DutyRollout
from policies.compare import run_policy

osqp = pytest.importorskip("osqp")


@pytest.fixture(scope="module")
def budgeted():
    """model_based_budget:0.02 and ramp on two nominal windows (closed loop, recorded)."""
    return {p: run_policy(p, "nominal", 2, 1000) for p in ("model_based_budget:0.02", "ramp")}


def test_replay_reproduces_the_closed_loop(budgeted):
    """A policy's duties replayed open loop give its energy, overshoot and short-mode flag (overshoot and flag to the bit, the energy up to the order of the sum)."""
    tr = budgeted["model_based_budget:0.02"]
    for i in range(2):
        r = DutyRollout("nominal", 1000 + i).run(np.stack([tr.d_short[:, i]] * 3))
        assert r.energy_after_stop_j == pytest.approx(np.full(3, tr.metrics["energy_after_stop_j"][i]), rel=1e-12)
        assert np.all(100.0 * r.overshoot == tr.metrics["overshoot_pct"][i])
        assert np.all(r.reached_short_mode)
        assert r.ratios.max(axis=1)[0] == pytest.approx(r.overshoot[0], abs=1e-12)


def test_oracle_bounds_fixed_policies(budgeted, tmp_path, monkeypatch):
    """At each policy's own measured overshoot the oracle delivers no more energy after the stop, within
    the budget and in short mode; the budgeted controller is beaten by a margin (it is not optimal)."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    from policies.oracle import oracle_window
    for name, tr in budgeted.items():
        i = 0
        b = tr.metrics["overshoot_pct"][i] / 100.0
        o = oracle_window("nominal", 1000 + i, b, starts=(), extra_starts=(tr.d_short[:, i],))
        assert o.feasible and o.reached_short_mode
        assert o.overshoot <= b + 1e-12
        assert o.energy_after_stop_j <= tr.metrics["energy_after_stop_j"][i]
        if name.startswith("model_based_budget"):
            assert o.energy_after_stop_j < 0.9 * tr.metrics["energy_after_stop_j"][i]
        # replaying the oracle's sequence gives what it claims (the cache holds the duties)
        r = DutyRollout("nominal", 1000 + i).run(o.duties)
        assert r.energy_after_stop_j[0] == pytest.approx(o.energy_after_stop_j, rel=1e-9)


def test_mpc_true_model_budget_zero_near_floor(tmp_path, monkeypatch):
    """Nominal windows (the MPC's model is the truth): every window reaches short mode and the measured
    overshoot stays within 3.5 points of the window's floor (the least any open-loop sequence found,
    policies.oracle.oracle_floor) and on average no worse than the paper's controller (measured: 0.5-3.3
    points above the floor; the floor itself is not reached, see docs/rl.md)."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    from policies.oracle import oracle_floor
    m = run_policy("mpc", "nominal", 3, 1000).metrics
    assert np.all(m["reached_short_mode"] == 1.0)
    floors = np.array([100.0 * oracle_floor("nominal", 1000 + i).overshoot for i in range(3)])
    assert np.all(m["overshoot_pct"] >= floors - 1e-9)   # the floor is a bound (the oracle searched from model_based)
    assert np.all(m["overshoot_pct"] <= floors + 3.5)
    base = run_policy("model_based", "nominal", 3, 1000).metrics
    assert m["overshoot_pct"].mean() <= base["overshoot_pct"].mean() + 0.5


def test_mpc_budget_is_measured_overshoot():
    """mpc:0.05 overshoots by the budget in the metric's units (within 1 point), not b + 3 points."""
    m = run_policy("mpc:0.05", "nominal", 3, 1000).metrics
    assert np.all(np.abs(m["overshoot_pct"] - 5.0) < 1.0)
    assert np.all(m["reached_short_mode"] == 1.0)
