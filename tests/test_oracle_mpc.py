"""The per-window oracle (policies.oracle), the fast duty replay (envs.rollout) and the MPC baseline
(policies.mpc): the oracle, solved from its own starts (not the policy's), bounds the fixed policies by the margins
the docs quote, the replay is the env,
the MPC with the true model and budget 0 stays within the window's floor. The first tests are eq. 4's oracle, replay
and MPC on eq. 4's link (``EQ4``, pinned since the envs' default became the exact-mode link on 2026-11-26); the
exact-mode link's are at the end (and in tests/test_mpc_modal.py, tests/test_rollout_modal.py)."""

import numpy as np
import pytest

from envs.rollout import DutyRollout
from policies.compare import run_policy

daqp = pytest.importorskip("daqp")


def _eq4():
    from envs import EnvConfig
    return EnvConfig(link_model="envelope")


EQ4 = _eq4()


@pytest.fixture(scope="module")
def budgeted():
    """The fixed policies of the oracle test on two nominal windows (closed loop, recorded): the budgeted
    and the paper's controller, ramp, and the MPC (deterministic given the window: a fixed sequence)."""
    return {p: run_policy(p, "nominal", 2, 1000, EQ4) for p in ("model_based_budget:0.02", "ramp", "model_based", "mpc:0.05")}


def test_replay_reproduces_the_closed_loop(budgeted):
    """A policy's duties replayed open loop give its energy, overshoot and short-mode flag (overshoot and flag to the bit, the energy up to the order of the sum)."""
    tr = budgeted["model_based_budget:0.02"]
    for i in range(2):
        r = DutyRollout("nominal", 1000 + i, EQ4).run(np.stack([tr.d_short[:, i]] * 3))
        assert r.energy_after_stop_j == pytest.approx(np.full(3, tr.metrics["energy_after_stop_j"][i]), rel=1e-12)
        assert np.all(100.0 * r.overshoot == tr.metrics["overshoot_pct"][i])
        assert np.all(r.reached_short_mode)
        assert r.ratios.max(axis=1)[0] == pytest.approx(r.overshoot[0], abs=1e-12)


def _independent_oracle(window: int, budget: float, cfg):
    """The oracle of ``window`` at ``budget`` from the starts that do not depend on the policy it is compared with:
    :data:`policies.oracle.DEFAULT_STARTS` and the window's floor sequence (the frontier's start set,
    :func:`policies.oracle.oracle_frontier`). Not seeded with the policy's own sequence (``compare``'s gap is, so
    there "oracle <= policy" holds by construction: the search keeps its start when it finds nothing better)."""
    from policies.oracle import oracle_floor, oracle_window
    floor = oracle_floor("nominal", window, cfg)
    return oracle_window("nominal", window, budget, config=cfg, extra_starts=(floor.duties,))


#: the oracle's energy after the stop at a fixed policy's measured overshoot, at most this fraction of the policy's
#: (per window). From the margins docs quote: issue 21's independent search on eq. 4's link delivered 30 % less than
#: model_based, 23 % less than model_based_budget:0.02 and 37 % less than ramp (20-window means; here 30 / 15 / 30 %
#: less, model_based_budget:0.02's with room for its per-window ratios, 0.77 / 0.74, near its mean); the README's
#: modal gaps: 48 % (model_based), 46 % (ramp), 29 % (mpc). The MPC at b = 0.05 on eq. 4's link and the shipped
#: clone of the oracle (oracle_imitation) on the modal link are held to the bound alone (factor 1.0: a tighter one
#: for the clone would test the clone's quality, not the oracle; the MPC's gap is 5.6 % on window 1000). Measured
#: 2026-11-28 (independent oracle / policy, per window): eq. 4 model_based 0.52 / 0.54, model_based_budget:0.02
#: 0.77 / 0.74, ramp 0.65 / 0.47, mpc:0.05 0.94 / 0.78 (windows 1000 / 1001); modal (window 1001) model_based 0.53,
#: ramp 0.38, mpc 0.44, oracle_imitation_s1 0.95.
BOUND_FACTOR = {"model_based": 0.70, "model_based_budget:0.02": 0.85, "ramp": 0.70, "mpc:0.05": 1.0, "mpc": 0.80,
                "oracle_imitation": 1.0}


def _factor(name: str) -> float:
    return BOUND_FACTOR[name] if name in BOUND_FACTOR else BOUND_FACTOR[name.partition(":")[0]]


def test_oracle_bounds_fixed_policies(budgeted, tmp_path, monkeypatch):
    """The oracle is a bound that its own search finds: solved from its default starts and the window's floor
    (never from the policy's sequence, ``_independent_oracle``), at each fixed policy's own measured overshoot, on
    nominal windows 1000-1001 of eq. 4's link, it is feasible, in short mode, within that overshoot, and delivers at
    most ``BOUND_FACTOR`` times the policy's energy after the stop (the margins the docs quote).

    What it catches (checked 2026-11-28 by weakening policies/oracle.py): an oracle that does not move from its starts
    (``_MAXITER = 0``: 1.34-2.03 times the policy's energy for model_based_budget:0.02, ramp and mpc:0.05); one
    default start (with the floor's), one SLSQP pass of one iteration (start model_based_budget:0.01: ratios on
    windows 1000 / 1001 model_based_budget:0.02 0.84 / 0.88, ramp 0.77 / 0.65, mpc:0.05 1.04 / 0.98: caught by all
    three, model_based_budget:0.02 on window 1001, the others on 1000; start model_based_budget:0.05: 0.90 / 0.97,
    0.69 / 0.55, 1.10 / 1.07: caught by model_based_budget:0.02 and mpc:0.05); the floor's sequence left out of the
    starts (no feasible sequence within model_based's 1.69 % on window 1001: the budgeted controller's sequences start
    above it). It does not catch a search cut to 2-3 iterations (within 1.5 % of the full oracle's energy on these
    windows: SLSQP gains most in its first steps)."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    for name, tr in budgeted.items():
        for i in range(2):
            b, e = tr.metrics["overshoot_pct"][i] / 100.0, tr.metrics["energy_after_stop_j"][i]
            o = _independent_oracle(1000 + i, b, EQ4)
            assert o.feasible and o.reached_short_mode, (name, i)
            assert o.overshoot <= b + 1e-12
            assert o.energy_after_stop_j <= _factor(name) * e, (name, i, o.energy_after_stop_j / e)
            # replaying the oracle's sequence gives what it claims (the cache holds the duties)
            r = DutyRollout("nominal", 1000 + i, EQ4).run(o.duties)
            assert r.energy_after_stop_j[0] == pytest.approx(o.energy_after_stop_j, rel=1e-9)


#: tolerance [percentage points] of the MPC's measured overshoot above the floor (its Kalman estimate from the
#: noisy I2, sd 0.1 A, and the 0.2 % back-off; measured 0.1-0.3 points on windows 1000-1005)
FLOOR_TOL_PTS = 0.5
MPC_WINDOWS = 4


@pytest.fixture(scope="module")
def mpc_floors(tmp_path_factory):
    """The floor of each of the first MPC_WINDOWS nominal windows with the MPC's own duties before the stop
    (the state at the stop is the MPC's: policies.oracle.oracle_floor(base="mpc")), and the paper's
    controller's floor."""
    import os
    old = os.environ.get("DRONEWPT_CACHE_DIR")
    os.environ["DRONEWPT_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))
    try:
        from policies.oracle import oracle_floor
        own = np.array([100.0 * oracle_floor("nominal", 1000 + i, EQ4, base="mpc").overshoot for i in range(MPC_WINDOWS)])
        paper = np.array([100.0 * oracle_floor("nominal", 1000 + i, EQ4).overshoot for i in range(MPC_WINDOWS)])
    finally:
        if old is None:
            os.environ.pop("DRONEWPT_CACHE_DIR")
        else:
            os.environ["DRONEWPT_CACHE_DIR"] = old
    return own, paper


def test_mpc_true_model_budget_zero_within_floor(mpc_floors):
    """Nominal windows (the MPC's model is the truth), budget 0: every window reaches short mode and the
    measured overshoot is the window's floor (the least any post-stop sequence found from the state the MPC
    stops in, policies.oracle.oracle_floor) within FLOOR_TOL_PTS points; the floor is a bound (its search
    started from the MPC's own sequence). The paper's controller measures 0.8-2.0 points above its own floor."""
    own, paper = mpc_floors
    m = run_policy("mpc", "nominal", MPC_WINDOWS, 1000, EQ4).metrics
    assert np.all(m["reached_short_mode"] == 1.0)
    assert np.all(m["overshoot_pct"] >= own - 1e-9)
    assert np.all(m["overshoot_pct"] <= own + FLOOR_TOL_PTS)
    base = run_policy("model_based", "nominal", MPC_WINDOWS, 1000, EQ4).metrics
    assert np.mean(base["overshoot_pct"] - paper) > 2.0 * FLOOR_TOL_PTS   # the paper's controller is not at its floor
    assert m["overshoot_pct"].mean() < base["overshoot_pct"].mean()


@pytest.mark.parametrize("budget", [0.02, 0.05])
def test_mpc_budget_is_measured_overshoot(budget, mpc_floors):
    """mpc:b measures at most max(floor, b) + FLOOR_TOL_PTS (so at most floor + b + tolerance: the budget is in
    the metric's units), uses it (within 1 point of b where b is above the floor) and reaches short mode."""
    own, _ = mpc_floors
    b = 100.0 * budget
    m = run_policy(f"mpc:{budget:g}", "nominal", MPC_WINDOWS, 1000, EQ4).metrics
    assert np.all(m["reached_short_mode"] == 1.0)
    assert np.all(m["overshoot_pct"] <= np.maximum(own, b) + FLOOR_TOL_PTS)
    above = own < b - 0.5
    assert np.all(m["overshoot_pct"][above] >= b - 1.0)


def test_mpc_delay_bank_stabilises_sense_delay():
    """sense_delay (I2 measured 1-2 control periods late): the MPC with the bank of delayed Kalman filters
    (policies.mpc._DelayBank, Smith prediction over the chosen delay) reaches short mode in every window with
    an overshoot like nominal's (< 5 %), while the same MPC with a delay-blind filter (delays=(0,)) rings
    the link (overshoot > 10 % in some window: the plan starts from a state 1-2 steps old). Eq. 4's MPC on eq. 4's
    link (pinned: on the exact-mode link, the envs' default since 2026-11-26, the delay-blind modal MPC measured
    1.9-3.2 % on these windows and does not ring, so the contrast is eq. 4's)."""
    from envs import SbarChargingVectorEnv
    from policies.compare import _rollout
    from policies.mpc import MPCPolicy
    out = {}
    for delays in ((0,), (0, 1, 2, 3, 4, 5)):
        venv = SbarChargingVectorEnv(num_envs=3, scenario="sense_delay", config=EQ4)
        pol = MPCPolicy(venv.policy_context, delays=delays)
        pol.reset(3)
        _, _, _, last = _rollout(pol, venv, [1000 + i for i in range(3)])
        out[delays] = (100.0 * last["overshoot"], last["reached_short_mode"])
    over, sm = out[(0, 1, 2, 3, 4, 5)]
    assert np.all(sm) and np.all(over < 5.0)
    assert out[(0,)][0].max() > 10.0


def test_mpc_starts_a_new_window_afresh():
    """A receiver charging again after its stop is in a new window (a batched env that resets its windows,
    e.g. imitation on the training env): the MPC run on window 1000 and then, without reset, on 1001 gives
    on 1001 what a fresh MPC gives, to the bit (the floor's relaxation, counters and estimate start anew)."""
    from envs import SbarChargingVectorEnv
    from policies.compare import _rollout
    from policies.mpc import MPCPolicy

    def run(pol, seed):
        venv = SbarChargingVectorEnv(num_envs=1, scenario="nominal")
        _, _, _, last = _rollout(pol, venv, [seed])
        return float(last["overshoot"][0])

    ctx = SbarChargingVectorEnv(num_envs=1).policy_context
    used, fresh = MPCPolicy(ctx), MPCPolicy(ctx)
    run(used, 1000)
    assert run(used, 1001) == run(fresh, 1001)


#: the exact-mode link (its per-step peaks are kinked: the oracle differences with a smaller step there)
MODAL_POLICIES = ("model_based", "ramp", "mpc", "oracle_imitation:policies/pretrained/oracle_imitation_s1.npz")


@pytest.fixture(scope="module")
def modal_fixed():
    """The fixed policies of the modal oracle test on nominal windows 1000-1001 on the exact-mode link (closed
    loop, recorded): the paper's controller, ramp, the MPC (its modal-aware predictor) and a shipped clone of
    the oracle (an open-loop sequence after the stop, the paper's controller's duties before it; the shipped maps are
    fitted on the modal oracle since 2026-11-26, eq. 4's before)."""
    from envs import EnvConfig
    cfg = EnvConfig(link_model="modal")
    return cfg, {p: run_policy(p, "nominal", 2, 1000, cfg) for p in MODAL_POLICIES}


def test_oracle_bounds_fixed_policies_on_the_modal_link(modal_fixed, tmp_path, monkeypatch):
    """On the exact-mode link, window 1001: the oracle solved from its default starts and the window's floor (not from
    the policy's sequence, ``_independent_oracle``), at each fixed policy's own measured overshoot, is feasible, in
    short mode, within it, and delivers at most ``BOUND_FACTOR`` times the policy's energy after the stop: the
    paper's controller, ramp and the MPC (0.53 / 0.38 / 0.44 measured); a shipped clone of the oracle is held to the
    bound alone (factor 1.0, measured 0.95: a tighter factor would test the clone's quality, not the oracle).

    What it catches (checked 2026-11-28 by weakening policies/oracle.py): an oracle that does not move from its
    starts (``_MAXITER = 0``: 1.00 times model_based's energy); eq. 4's difference step on this link
    (``_FD_STEP_MODAL = 2e-3``: 2.08 times the clone's, the search stalled, docs/rl.md "Why the oracle stalled on the
    exact-mode link"). Not a search cut to one or two iterations (0.56 / 0.49 / 0.46 / 0.96 with one: within every
    factor here), nor the floor's sequence left out of the starts on this window."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    cfg, runs = modal_fixed
    i = 1
    for name, tr in runs.items():
        b, e = tr.metrics["overshoot_pct"][i] / 100.0, tr.metrics["energy_after_stop_j"][i]
        o = _independent_oracle(1000 + i, b, cfg)
        assert o.feasible and o.reached_short_mode and o.overshoot <= b + 1e-12, name
        assert o.energy_after_stop_j <= _factor(name) * e, (name, o.energy_after_stop_j / e)
        r = DutyRollout("nominal", 1000 + i, cfg).run(o.duties)
        assert r.energy_after_stop_j[0] == pytest.approx(o.energy_after_stop_j, rel=1e-9)


def test_modal_floor_is_below_every_sequence_from_the_same_state(modal_fixed, tmp_path, monkeypatch):
    """The floor is the least measured overshoot of any sequence after the stop from the paper's controller's
    state at the stop: on the exact-mode link (windows 1000-1001) it lies at or below what the clone, which
    applies the paper's controller's duties before the stop (checked), measures (with eq. 4's difference step
    the floor search stalled above it: 2.68 / 1.70 % against 2.61 / 1.22 %)."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    from policies.oracle import oracle_floor
    cfg, runs = modal_fixed
    clone, paper = runs[MODAL_POLICIES[-1]], runs["model_based"]
    for i in range(2):
        k0 = DutyRollout("nominal", 1000 + i, cfg).stop_k
        assert np.array_equal(clone.d_short[:k0, i], paper.d_short[:k0, i])
        f = oracle_floor("nominal", 1000 + i, cfg)
        assert f.reached_short_mode
        assert 100.0 * f.overshoot <= clone.metrics["overshoot_pct"][i]
        assert 100.0 * f.overshoot <= paper.metrics["overshoot_pct"][i]
