"""compare's batching (policies.batched): several policies side by side in one vector env, and the
training seeds of a learned kind as one stacked network, give each policy exactly (to the bit) the
traces and metrics of its own separate run on the same windows."""

import os
import subprocess
import sys

import numpy as np
import pytest

from policies import make
from policies.batched import BlockPolicy, StackedRL
from policies.compare import run_policies, run_policy, shipped_seed_groups

FIELDS = ("i2_peak_a", "i2_a", "d_short", "rect_current_a", "charge_cmd_a", "t_stop_s")



def _child(code: str, timeout: float):
    """Run ``code`` in a fresh interpreter with this one's import path; its completed process (exit 0)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout)
    assert out.returncode == 0, out.stderr[-2000:]
    return out

def _assert_same(batched, separate):
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(batched, f), getattr(separate, f), err_msg=f)
    assert batched.metrics.keys() == separate.metrics.keys()
    for k in separate.metrics:
        np.testing.assert_array_equal(batched.metrics[k], separate.metrics[k], err_msg=k)


def test_batched_classical_policies_equal_their_separate_runs_row_by_row():
    names = ["step", "ramp", "model_based", "model_based_budget:0.02", "hysteresis", "model_based_online", "random"]
    runs = run_policies(names, "lm_mismatch", episodes=5, seed=321)
    assert list(runs) == names
    for name in names:
        _assert_same(runs[name], run_policy(name, "lm_mismatch", 5, 321))
    # the blocks are the policies' own: different controllers give different duties on the same windows
    assert not np.array_equal(runs["step"].d_short, runs["ramp"].d_short)
    assert runs["model_based_budget:0.02"].metrics["energy_after_stop_j"].mean() < \
        runs["model_based"].metrics["energy_after_stop_j"].mean()


def test_model_based_family_is_one_controller_with_a_budget_per_row():
    pols = [make(s) for s in ("model_based", "ramp", "model_based_budget:0.02", "model_based_budget:0.1")]
    bp = BlockPolicy(pols, 4)
    assert [(b, k, type(p).__name__) for b, k, p in bp.units] == [(0, 3, "StackedModelBased"), (3, 1, "RampPolicy")]
    assert bp.block == [0, 3, 1, 2]
    np.testing.assert_array_equal(bp.units[0][2].budgets, [0.0, 0.02, 0.1])
    assert [type(p).__name__ for _, _, p in BlockPolicy(pols, 1).units] == [   # one row: each alone (scalar path)
        "ModelBasedPolicy", "RampPolicy", "BudgetedModelBasedPolicy", "BudgetedModelBasedPolicy"]
    runs = run_policies(["model_based_budget:0.1", "ramp", "model_based"], "battery", episodes=3, seed=11)
    for name in runs:
        _assert_same(runs[name], run_policy(name, "battery", 3, 11))


def test_duplicate_names_run_once_on_the_same_windows():
    runs = run_policies(["ramp", "ramp", "step"], "nominal", episodes=3, seed=7)
    assert list(runs) == ["ramp", "step"]
    np.testing.assert_array_equal(runs["ramp"].t_stop_s, runs["step"].t_stop_s)   # paired: same windows


@pytest.mark.parametrize("kind", ["rl", "ppo_lagrangian", "residual", "imitation"])
def test_stacked_training_seeds_equal_separate_runs_row_by_row(kind):
    pytest.importorskip("stable_baselines3")
    specs = shipped_seed_groups()[kind]
    runs = run_policies(specs, "nominal", episodes=4, seed=1000)
    for sp in specs:
        _assert_same(runs[sp], run_policy(sp, "nominal", 4, 1000))
    # the seeds are different networks: their duties differ
    assert not np.array_equal(runs[specs[0]].d_short, runs[specs[1]].d_short)


def test_block_policy_stacks_consecutive_seeds_only():
    pytest.importorskip("stable_baselines3")
    groups = shipped_seed_groups()
    pols = [make(s) for s in groups["ppo_lagrangian"]] + [make("ramp")] + [make(s) for s in groups["residual"][:2]]
    bp = BlockPolicy(pols, 3)
    assert [(b, k, type(p).__name__) for b, k, p in bp.units] == [
        (0, 5, "StackedRL"), (5, 1, "RampPolicy"), (6, 2, "StackedRL")]


def test_stacked_actor_equals_each_policys_act():
    pytest.importorskip("stable_baselines3")
    pols = [make(s) for s in shipped_seed_groups()["ppo_lagrangian"]]
    obs = np.random.default_rng(3).uniform(-1.0, 1.0, (len(pols) * 7, 8)).astype(np.float32)
    st = StackedRL(pols)
    st.reset(7)
    got = st.act(obs)
    for b, p in enumerate(pols):
        p.reset(7)
        np.testing.assert_array_equal(got[b * 7:(b + 1) * 7], p.act(obs[b * 7:(b + 1) * 7]))


def test_forked_mpc_runs_equal_in_process_runs():
    """The MPC's runs in a forked child (policies.forked) give the rows and traces of the same runs
    in-process; run in a fresh interpreter, where numba's thread pool has not started (fork allowed)."""
    pytest.importorskip("daqp")
    import json
    import os
    import subprocess
    import sys
    code = (
        "import json, numpy as np, policies.forked as f\n"
        "from policies.compare import compare\n"
        "made = []\n"
        "init = f.Forked.__init__\n"
        "def rec(self, *a):\n"
        "    init(self, *a); made.append(self.proc is not None)\n"
        "f.Forked.__init__ = rec\n"
        "args = (('ramp', 'mpc', 'model_based'), ('nominal', 'windy'))\n"
        "r1, t1 = compare(*args, episodes=3, seed=77)\n"
        "r2, t2 = compare(*args, episodes=3, seed=77, fork=False)\n"
        "same = list(t1) == list(t2) and all(np.array_equal(t1[k].d_short, t2[k].d_short) for k in t2)\n"
        "print(json.dumps({'made': made, 'rows': r1 == r2, 'traces': same, 'order': [r['policy'] for r in r1]}))\n")
    out = _child(code, timeout=600)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["made"] == [True]    # the first compare forked (the second had fork=False)
    assert res["rows"] and res["traces"]
    assert res["order"] == ["ramp", "mpc", "model_based"] * 2


def test_tabulated_t_quantiles_are_scipys():
    from scipy.special import stdtrit

    from policies.stats import _t_quantile
    for df in range(1, 40):
        assert _t_quantile(df, 0.975) == float(stdtrit(df, 0.975))
    assert _t_quantile(4, 0.95) == float(stdtrit(4, 0.95))
    assert _t_quantile(4, 0.975) > _t_quantile(30, 0.975) > 1.959963984540054   # wider with fewer seeds; -> normal


def test_forked_child_that_dies_is_run_again_in_the_parent_and_errors_are_raised():
    import os
    import subprocess
    import sys
    code = (
        "import os\n"
        "from policies.forked import Forked, available\n"
        "parent = os.getpid()\n"
        "def work(x):\n"
        "    if os.getpid() != parent:\n"
        "        os._exit(3)   # the child dies without an answer\n"
        "    return x + 1\n"
        "def bad():\n"
        "    raise ValueError('in the child')\n"
        "print(available(), Forked(work, 41).result())\n"
        "try:\n"
        "    Forked(bad).result()\n"
        "except ValueError as exc:\n"
        "    print(exc)\n")
    out = _child(code, timeout=120)
    lines = out.stdout.strip().splitlines()
    assert lines[-2] == f"{len(os.sched_getaffinity(0)) > 1} 42" and lines[-1] == "in the child"


def test_split_moves_budgeted_seeds_to_the_child_on_the_modal_link_only():
    from envs import EnvConfig
    from policies.compare import _split
    seeds = [f"residual:r{k}" for k in range(5)] + [f"imitation:i{k}" for k in range(5)]
    specs = ["model_based", "ramp", "mpc", "model_based_budget:0.01"] + seeds
    child = _split(specs, "model_based", [], 1, EnvConfig(link_model="modal"))
    assert child[0] == "mpc" and len(child) > 1
    assert set(child[1:]) <= set(seeds) and child[1:] == [s for s in seeds if s in child]   # the last seeds, in order
    assert _split(specs, "model_based", [], 1, EnvConfig(link_model="envelope")) == ["mpc"]   # the MPC dominates
    assert _split(["model_based", "ramp", "step"], "model_based", [], 1, None) == []          # nothing worth a child
    assert _split(["model_based"] + seeds, "model_based", [], 1, None) != []                   # seeds alone: a child


def test_split_evens_out_with_the_finer_kinds_costliest_first(monkeypatch):
    """Given a cost table, the split moves the costliest movable spec first (the last first among equal costs)
    while that lowers the larger side, then the finer ones (learned seeds), and lists the child's specs in the
    order given; kinds that are not movable (random) stay in the parent whatever their cost."""
    import policies.compare as pc
    from envs import EnvConfig
    monkeypatch.setitem(pc.RUN_COST, "modal", {"mpc": 3.0, "residual": 1.0, "random": 0.3, "rl": 0.15,
                                               "model_based": 0.2, "ramp": 1.75})
    specs = ["model_based", "ramp", "random", "mpc"] + [f"rl:r{k}" for k in range(5)] + \
        [f"residual:s{k}" for k in range(5)]
    # parent / child 8.0 / 3.0 -> residual s4, s3 (6.0 / 5.0), not s2 (6.0 either way), rl r4, r3, r2 (5.55 / 5.45),
    # not r1 (5.6)
    assert pc._split(specs, "model_based", [], 1, EnvConfig(link_model="modal")) == \
        ["mpc", "rl:r2", "rl:r3", "rl:r4", "residual:s3", "residual:s4"]
    # the frontier's specs (first scenario only) count once over the scenarios: 1.75 / 2 more on the parent's side,
    # 8.875 / 3.0 -> residual s4, s3, s2 (5.875 / 6.0), then nothing lowers 6.0
    assert pc._split(specs, "model_based", ["ramp"], 2, EnvConfig(link_model="modal")) == \
        ["mpc", "residual:s2", "residual:s3", "residual:s4"]
    # without the rl seeds: 7.25 / 3.0 -> residual s4, s3 (5.25 / 5.0); random (0.3) would even it out, but stays
    assert pc._split(specs[:4] + specs[9:], "model_based", [], 1, EnvConfig(link_model="modal")) == \
        ["mpc", "residual:s3", "residual:s4"]


def test_split_of_the_default_rows_by_the_shipped_table():
    """compare's default rows: on the modal link the child takes the MPC, 7 of the 10 budgeted seeds and 4 of the 5
    ppo_lagrangian seeds (estimated 11.80 s against the parent's 11.87 s); on eq. 4's link the MPC alone (it
    outweighs the rest)."""
    from envs import EnvConfig
    from policies.compare import DEFAULT_POLICIES, SHIPPED_SEEDS, _split, frontier_specs
    seeds = [f"{k}:{k}_s{i}.zip" for k in ("rl", "ppo_lagrangian", "residual", "imitation") for i in range(5)]
    specs = list(dict.fromkeys(["model_based"] + [p for p in DEFAULT_POLICIES if p not in SHIPPED_SEEDS] + seeds))
    extra = [sp for sp in frontier_specs() if sp not in specs]
    assert _split(specs, "model_based", extra, 1, EnvConfig(link_model="modal")) == \
        ["mpc"] + [f"ppo_lagrangian:ppo_lagrangian_s{i}.zip" for i in range(1, 5)] + \
        ["residual:residual_s3.zip", "residual:residual_s4.zip"] + [f"imitation:imitation_s{i}.zip" for i in range(5)]
    assert _split(specs, "model_based", extra, 1, EnvConfig(link_model="envelope")) == ["mpc"]


def _forked_against_in_process(policies: tuple, kind: str, setup: str = "") -> dict:
    """compare of ``policies`` and the shipped seeds of ``kind`` on 2 nominal windows with the fork and without
    (``setup``: code run first, e.g. a cost table): the specs the split gave the child (their kinds), and whether
    the rows and the traces of the two runs are the same to the bit."""
    pytest.importorskip("stable_baselines3")
    pytest.importorskip("daqp")
    import json
    code = (
        "import json, numpy as np, policies.compare as pc\n"
        "from policies.compare import compare, shipped_seed_groups\n"
        f"{setup}\n"
        "split = pc._split\n"
        "moved = []\n"
        "def rec(*a):\n"
        "    r = split(*a); moved.extend(r); return r\n"
        "pc._split = rec\n"
        f"seeds = {{{kind!r}: shipped_seed_groups()[{kind!r}]}}\n"
        f"args = ({policies!r}, ('nominal',))\n"
        "r1, t1 = compare(*args, episodes=2, seed=1010, train_seeds=seeds)\n"
        "r2, t2 = compare(*args, episodes=2, seed=1010, train_seeds=seeds, fork=False)\n"
        "same = list(t1) == list(t2) and all(np.array_equal(t1[k].d_short, t2[k].d_short) for k in t2)\n"
        "print(json.dumps({'moved': [m.split(':')[0] for m in moved], 'rows': r1 == r2, 'traces': same}))\n")
    return json.loads(_child(code, timeout=900).stdout.strip().splitlines()[-1])


def test_seeds_split_between_parent_and_child_give_the_in_process_rows():
    """A seed group whose runs are shared between the parent and the forked child (the modal link: the residual's
    seeds) gives the rows and traces of the same compare without a fork, to the bit."""
    res = _forked_against_in_process(("model_based", "mpc", "ramp"), "residual")
    assert res["moved"][0] == "mpc" and "residual" in res["moved"]                   # the group is split
    assert len([m for m in res["moved"] if m == "residual"]) < 5
    assert res["rows"] and res["traces"]


def test_learned_seeds_split_between_parent_and_child_give_the_in_process_rows():
    """A stacked learned kind's seeds split between the two processes (the finer steps of the split: the rl stack
    4 / 1 here, by a cost table that moves them) give the rows and traces of the same compare without a fork, to the
    bit; the random policy, not movable, stays in the parent."""
    table = "pc.RUN_COST['modal'] = {'mpc': 0.1, 'random': 1.0, 'rl': 0.3, 'model_based': 0.1}"
    res = _forked_against_in_process(("model_based", "mpc", "random"), "rl", table)
    assert res["moved"] == ["mpc", "rl", "rl", "rl", "rl"]          # 2.6 / 0.1 -> r4, r3, r2, r1 (1.4 / 1.3)
    assert res["rows"] and res["traces"]
