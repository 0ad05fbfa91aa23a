"""The MPC's speed-ups change its cost, not its decisions (policies.mpc):

* batched over receivers: the MPC acting on a batch of windows gives every window what it gives that
  window alone (each receiver's after-stop decisions, QPs and delay bank are its own);
* warm-started daqp: the after-stop QPs solved from the last multipliers reach the same optimum as
  cold solves (the QP is strictly convex), so the closed loop is the same;
* one BLAS thread (policies.threads) holds inside ``act`` and is released after it;
* compare's frontier reuses the budgeted runs compare made (same rows, one rollout fewer each).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("daqp")

from policies.compare import run_policy  # noqa: E402

KEYS = ("overshoot_pct", "energy_after_stop_j", "reached_short_mode", "return")
WINDOWS = 3


def _metrics(name, scenario, episodes, seed, link="envelope"):
    from envs import EnvConfig
    m = run_policy(name, scenario, episodes, seed, config=EnvConfig(link_model=link)).metrics
    return np.array([m[k] for k in KEYS])


@pytest.mark.parametrize("scenario, link", [("nominal", "envelope"), ("sense_delay", "envelope"),
                                            ("nominal", "modal")])
def test_batched_mpc_equals_each_window_alone(scenario, link):
    """Windows 1000..1002 in one batch and each alone (a batch of one): the same overshoot, energy after
    the stop, short mode and return per window (to the QP solver's tolerance); on eq. 4's plant and on the
    exact-mode link (the modal model's MPC, with its duty tail and the after-stop QPs it skips)."""
    batch = _metrics("mpc", scenario, WINDOWS, 1000, link)
    alone = np.concatenate([_metrics("mpc", scenario, 1, 1000 + i, link) for i in range(WINDOWS)], axis=1)
    assert batch[2].min() == 1.0   # short mode reached: the after-stop path ran in every window
    np.testing.assert_allclose(batch, alone, rtol=1e-6, atol=1e-6)


def test_warm_started_qps_equal_cold_ones(monkeypatch):
    """The after-stop QPs solved cold (the full problem from an empty active set every time, as before the
    warm start) give the same closed loop as the warm-started ones, while the warm start needs fewer
    active-set iterations."""
    import daqp

    from policies import mpc

    iters = []
    solve = daqp.solve

    def counted(*a, **k):
        out = solve(*a, **k)
        iters.append(out[3]["iterations"])
        return out

    monkeypatch.setattr(daqp, "solve", counted)
    warm = _metrics("mpc:0.02", "nominal", 2, 1000)
    n_warm, iters[:] = np.mean(iters), []

    def cold(self, e, q, A, bu, bl):
        x, _, flag, _ = daqp.solve(self._stop_P, q, A, bu, bl, self._sense.copy())
        return x, flag

    monkeypatch.setattr(mpc.MPCPolicy, "_daqp", cold)
    cold_m = _metrics("mpc:0.02", "nominal", 2, 1000)
    np.testing.assert_allclose(warm, cold_m, rtol=1e-6, atol=1e-6)
    assert n_warm < 0.5 * np.mean(iters)


def test_act_holds_one_blas_thread_and_releases_it():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    from envs import SbarChargingVectorEnv
    from policies import make

    blas = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    if not blas or max(i["num_threads"] for i in blas) < 2:
        pytest.skip("a single-threaded BLAS: nothing to limit")
    before = [i["num_threads"] for i in blas]
    venv = SbarChargingVectorEnv(num_envs=2, scenario="nominal")
    pol = make("mpc", venv.policy_context)
    obs, _ = venv.reset(seed=1000)
    seen = []
    orig = pol._act

    def spy(o):
        seen.append(max(i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"))
        return orig(o)

    pol._act = spy
    pol.act(obs)
    assert seen == [1]
    assert [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"] == before


def test_frontier_reuses_compares_budgeted_runs(monkeypatch):
    """``frontier(traces=...)`` takes the ``model_based_budget:b`` rows compare already ran on the same
    windows (one rollout fewer each) and gives the rows a fresh run gives."""
    from policies import compare as cmp

    _, traces = cmp.compare(policies=("model_based_budget:0.01",), scenarios=("nominal",), episodes=3)
    fresh = cmp.frontier("nominal", budgets=(0.01, 0.05), episodes=3)
    ran = []
    run = cmp.run_policies   # the budgets not reused run side by side in one batched env

    def counted(names, *a, **k):
        ran.extend(names)
        return run(names, *a, **k)

    monkeypatch.setattr(cmp, "run_policies", counted)
    reused = cmp.frontier("nominal", budgets=(0.01, 0.05), episodes=3, traces=traces)
    assert ran == ["model_based_budget:0.05"]
    assert [r["energy_after_stop_j"] for r in reused] == [r["energy_after_stop_j"] for r in fresh]
    assert [r["overshoot_pct"] for r in reused] == [r["overshoot_pct"] for r in fresh]
    other = cmp.frontier("nominal", budgets=(0.01,), episodes=2, traces=traces)   # other windows: run again
    assert ran[-1] == "model_based_budget:0.01" and other[0]["episodes"] == 2


def test_compare_runs_the_frontiers_budgets_in_its_batch(monkeypatch):
    """``compare(extra=frontier_specs(...))`` runs the frontier's budgets in its own batched env (one
    rollout: ``frontier`` then runs nothing) and gives the frontier rows of separate runs, to the bit; the
    extra runs are not compare rows or traces."""
    from policies import compare as cmp

    budgets = (0.0, 0.01, 0.05)
    fresh = cmp.frontier("nominal", budgets=budgets, episodes=3)
    more = {}
    rows, traces = cmp.compare(policies=("ramp", "model_based_budget:0.01"), scenarios=("nominal", "windy"), episodes=3,
                               extra=cmp.frontier_specs(budgets), extra_traces=more)
    assert sorted(more) == sorted((sp, "nominal") for sp in cmp.frontier_specs(budgets))
    assert sorted(traces) == sorted((p, s) for p in ("ramp", "model_based_budget:0.01") for s in ("nominal", "windy"))
    assert [r["policy"] for r in rows] == ["ramp", "model_based_budget:0.01"] * 2
    ran = []
    monkeypatch.setattr(cmp, "run_policies", lambda names, *a, **k: ran.extend(names))
    reused = cmp.frontier("nominal", budgets=budgets, episodes=3, traces={**more, **traces})
    assert ran == []
    for key in ("overshoot_pct", "energy_after_stop_j", "return", "return_lo", "return_hi"):
        assert [r[key] for r in reused] == [r[key] for r in fresh], key
    assert [r["budget"] for r in reused] == list(budgets)
