"""compare's statistics: bootstrap intervals cover, paired differences are per episode, seeds
aggregate with a t interval, the Pareto front is the non-dominated set."""

import json
from pathlib import Path

import numpy as np
import pytest

from policies.compare import compare
from policies.stats import bootstrap_ci, pareto_front, seed_ci


def test_bootstrap_interval_covers_the_true_mean_about_95_percent():
    rng = np.random.default_rng(1)
    hits = 0
    for i in range(200):
        lo, hi = bootstrap_ci(rng.exponential(2.0, 60), n_boot=1000, seed=i)
        hits += lo <= 2.0 <= hi
    assert 0.88 <= hits / 200 <= 0.99


def test_seed_interval_is_students_t():
    from scipy import stats
    x = np.array([1.0, 1.4, 0.7, 1.2, 0.9])
    m, lo, hi = seed_ci(x)
    elo, ehi = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert m == pytest.approx(x.mean()) and lo == pytest.approx(elo) and hi == pytest.approx(ehi)


def test_pareto_front():
    cost = [0.5, 1.0, 2.0, 1.5, 3.0]
    value = [10, 30, 40, 20, 39]
    assert pareto_front(cost, value).tolist() == [0, 1, 2]


def test_paired_differences_and_train_seed_rows():
    rows, _ = compare(("ramp", "model_based"), ("nominal",), episodes=12, seed=50,
                      train_seeds={"twice_ramp": ["ramp", "ramp"]})
    r = {row["policy"]: row for row in rows}
    assert "d_return" not in r["model_based"]
    for k in ("return", "energy_after_stop_j", "overshoot_pct"):
        assert r["ramp"][f"d_{k}"] == pytest.approx(r["ramp"][k] - r["model_based"][k])
        assert r["ramp"][f"{k}_lo"] <= r["ramp"][k] <= r["ramp"][f"{k}_hi"]
    # the paired interval is narrower than the unpaired spread: same windows, the window-to-window
    # variation of the return (command levels) cancels
    assert (r["ramp"]["d_return_hi"] - r["ramp"]["d_return_lo"]) < (r["ramp"]["return_hi"] - r["ramp"]["return_lo"])
    tw = r["twice_ramp"]
    assert tw["train_seeds"] == 2 and tw["return"] == pytest.approx(r["ramp"]["return"])
    assert tw["return_lo"] == pytest.approx(tw["return_hi"])    # identical "seeds": no spread


def test_cli_compare_json_has_intervals_frontier_and_figures(tmp_path, capsys):
    from mission_sim.cli import main
    assert main(["compare", "--policies", "ramp,model_based_budget:0.02", "--scenarios", "nominal", "--episodes",
                 "8", "--format", "json", "--out", str(tmp_path), "--train-seeds", "mb=model_based,model_based"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert {r["policy"] for r in res["rows"]} == {"ramp", "model_based_budget:0.02", "mb"}
    assert [f["budget"] for f in res["frontier"]] == [0.0, 0.005, 0.01, 0.02, 0.05, 0.1]
    assert all((tmp_path / p).is_file() for p in ("transitions_nominal.png", "frontier_nominal.png"))
    assert main(["compare", "--train-seeds", "broken", "--no-plot"]) == 2


def test_shipped_learned_policies_have_five_seeds_small_files_and_their_commands():
    """Each learned kind is shipped with >= 5 training seeds (distinct), small files, and the exact
    command in its metadata; compare's default rows aggregate them."""
    from pathlib import Path

    from policies.compare import shipped_seed_groups

    groups = shipped_seed_groups()
    assert set(groups) == {"rl", "ppo_lagrangian", "residual", "imitation", "slow_budget"}
    for kind, specs in groups.items():
        paths = [Path(s.split(":", 1)[1]) for s in specs]
        metas = [json.loads(p.with_suffix(".json").read_text()) for p in paths]
        assert len(paths) >= 5 and len({m["seed"] for m in metas}) == len(paths)
        assert all(p.stat().st_size < 300_000 for p in paths)
        for m in metas:
            if kind == "rl":   # the unconstrained PPO: no multiplier, no budget
                assert m["lagrangian"] is None and m["budget"] is None
            else:   # imitation: a clone, not constrained RL
                assert (m["imitation"] if kind == "imitation" else m["lagrangian"])
            assert m["reproduce"].startswith("dronewpt train --algo ppo")
            assert f"--seed {m['seed']} " in m["reproduce"] and ("--residual" in m["reproduce"]) == (kind in ("residual", "imitation"))
            assert ("--slow-budget 0:0.15" in m["reproduce"]) == (kind == "slow_budget") == bool(m.get("slow_budget"))
            # one link per group (eq. 4's, the envs' default until 2026-11-26, or the exact-mode link for a group
            # retrained since): the record and the command name it
            link = metas[0]["env_config"]["link_model"]
            assert m["env_config"]["link_model"] == link in ("envelope", "modal")
            assert f" --link {link} " in m["reproduce"] or f" --env link_model={link} " in m["reproduce"]


@pytest.mark.parametrize("argv, message", [
    (["--policies", "step,ramp,step"], "--policies 'step,ramp,step' names 'step' twice; valid: each name once"),
    (["--policies", "step", "--scenarios", "nominal,nominal"],
     "--scenarios 'nominal,nominal' names 'nominal' twice; valid: each name once"),
    # a train-seeds label equal to a listed policy showed that policy's numbers in both rows
    (["--policies", "step", "--train-seeds", "step=ramp"],
     "train_seeds label 'step' is also one of the policies; valid: a label that names no listed policy"),
    # a repeated label kept only the last group, without a word
    (["--policies", "step", "--train-seeds", "a=ramp", "--train-seeds", "a=hysteresis"],
     "--train-seeds 'a=hysteresis': label 'a' is given twice; valid: one --train-seeds per label"),
])
def test_cli_compare_refuses_rows_that_would_share_a_label(argv, message, capsys):
    """Each row of the table has its own label (2026-11-27: `--policies step,step` printed the row twice, and
    `--train-seeds step=ramp` printed step's numbers under both rows)."""
    from mission_sim.cli import main
    assert main(["compare", "--episodes", "1", "--no-plot", "--no-frontier", "--no-progress", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_compare_api_refuses_a_repeated_row_label():
    with pytest.raises(ValueError, match="policies lists 'ramp' twice; valid: each policy once"):
        compare(("ramp", "ramp"), ("nominal",), episodes=1)
    with pytest.raises(ValueError, match="train_seeds label 'ramp' is also one of the policies"):
        compare(("ramp",), ("nominal",), episodes=1, train_seeds={"ramp": ["step", "step"]})


class _Reached(Exception):
    pass


@pytest.mark.parametrize("policies", [None, "step,residual"])
def test_cli_a_seed_group_labelled_as_a_default_row_replaces_it_without_policies(policies, monkeypatch, capsys):
    """docs/rl.md ('Comparison'): the default rows are 'equivalent to --train-seeds residual=residual:...'; that
    command without --policies exited 2 naming policies the user never listed (69cd052). Now the group replaces the
    default row; with --policies naming the label it is still refused."""
    import policies.compare as pc
    from mission_sim.cli import main
    seen = {}

    def fake_compare(pols, scns, *a, train_seeds=None, **k):   # the real label check, then stop before running
        pc.check_row_labels(pols, train_seeds)
        seen.update(pols=tuple(pols), groups=dict(train_seeds))
        raise _Reached

    monkeypatch.setattr(pc, "compare", fake_compare)
    argv = ["compare", "--episodes", "1", "--no-plot", "--no-frontier", "--no-progress",
            "--train-seeds", "residual=residual:policies/pretrained/residual_s*.zip"]
    if policies is not None:
        assert main([*argv, "--policies", policies]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "train_seeds label 'residual' is also one of the policies" in err[0], err
        return
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    with pytest.raises(_Reached):
        main(argv)
    assert seen["pols"] == tuple(p for p in pc.DEFAULT_POLICIES if p != "residual")
    assert list(seen["groups"]) == ["residual"] and len(seen["groups"]["residual"]) == 5
