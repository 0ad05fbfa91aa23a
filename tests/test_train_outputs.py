"""train's outputs follow SB3 habits (vecnormalize.pkl, eval, checkpoints, hyperparameter files) and
the constrained / residual machinery does what it says."""

import json
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from envs.sb3_vec import EPISODE_KEYS, SbarSB3VecEnv   # noqa: E402
from policies.compare import run_policy                 # noqa: E402
from policies.train import train                        # noqa: E402

SEED0, N = 4242, 8
SMALL = dict(n_steps=64, batch_size=256, n_epochs=2, policy_kwargs=dict(net_arch=[16, 16], log_std_init=-2.0))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("train")
    kw = dict(n_envs=16, scenario="nominal", progress=False, hyperparams=SMALL, eval_every=4096, eval_episodes=4,
              checkpoint_every=2048)
    return {"ppo": train("ppo", 8192, out / "ppo", seed=1, **kw),
            # budget 5 %: 2 % over the SBAR's ripple floor - the model-based base's instantaneous
            # overshoot is ~3 % on nominal windows (its envelope's 0.5 %, envs/peaks.py)
            "res": train("ppo", 8192, out / "res", seed=1, residual=True, lagrangian=True, budget=0.05, **kw)}


def _sb3_returns(res, residual: bool):
    """Episode returns of the model through the SB3 way: PPO.load + VecNormalize.load on the adapter."""
    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from policies.constrained import ResidualVecEnv

    venv = SbarSB3VecEnv(N, "nominal", reset_seed=SEED0)
    venv = VecMonitor(ResidualVecEnv(venv) if residual else venv, info_keywords=EPISODE_KEYS)
    venv = VecNormalize.load(str(res["vecnormalize"]), venv)
    venv.training, venv.norm_reward = False, False
    model = sb3.PPO.load(str(res["model"]), device="cpu")
    obs, out = venv.reset(), {}
    for _ in range(300):
        obs, _, done, infos = venv.step(model.predict(obs, deterministic=True)[0])
    out = {k: np.array([i[k] for i in infos]) for k in ("episode_cost",)}
    out["return"] = np.array([i["episode"]["r"] for i in infos])
    return out


@pytest.mark.parametrize("kind", ["ppo", "res"])
def test_ppo_load_and_vecnormalize_load_reproduce_compare(runs, kind):
    res = runs[kind]
    name = f"residual:{res['model']}" if kind == "res" else f"rl:{res['model']}"
    m = run_policy(name, "nominal", N, SEED0).metrics
    sb = _sb3_returns(res, kind == "res")
    # the numpy actor of compare vs torch predict: float32 round-off only
    np.testing.assert_allclose(m["return"], sb["return"], rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(m["cost"], sb["episode_cost"], atol=1e-4)


def test_outputs_metadata_eval_and_checkpoints(runs):
    res = runs["res"]
    meta = json.loads(res["meta"].read_text())
    assert meta["residual"]["scale"] == 0.25 and meta["lagrangian"]["history"] and meta["budget"] == 0.05
    assert meta["obs_dim"] == 9 and "--residual" in meta["reproduce"] and "--lagrangian" in meta["reproduce"]
    curve = json.loads((res["eval_dir"] / "eval_curve.json").read_text())
    assert len(curve) == 2 and all({"cost", "overshoot", "reached_short_mode"} <= set(e) for e in curve)
    assert (res["eval_dir"] / "best_model.zip").is_file() and (res["eval_dir"] / "evaluations.npz").is_file()
    ck = sorted(res["checkpoints"].glob("*_steps.zip"))
    assert len(ck) == 4 and len(list(res["checkpoints"].glob("*vecnormalize*.pkl"))) == 4
    # best feasible model: the highest evaluation return among evaluations within the budget, all in SM
    feas = [e for e in curve if e["cost"] <= meta["budget"] and e["reached_short_mode"] == 1.0]
    path = res["eval_dir"] / "best_feasible_model.json"
    assert path.is_file() == bool(feas) == (res["eval_dir"] / "best_feasible_model.zip").is_file()
    if feas:
        sel = json.loads(path.read_text())["selected_at"]
        assert sel == max(feas, key=lambda e: e["return_mean"])
    assert not (runs["ppo"]["eval_dir"] / "best_feasible_model.zip").exists()   # unconstrained: no budget


@pytest.mark.parametrize("kind", ["ppo", "res"])
def test_best_model_json_carries_the_normalisation_it_was_evaluated_with(runs, kind):
    """best_model.zip is paired with the training statistics of its evaluation, not the final ones."""
    import pickle
    res = runs[kind]
    curve = json.loads((res["eval_dir"] / "eval_curve.json").read_text())
    best = json.loads((res["eval_dir"] / "best_model.json").read_text())
    first_max = max(range(len(curve)), key=lambda i: (curve[i]["return_mean"], -i))   # EvalCallback: strict >
    assert best["selected_at"] == curve[first_max]
    with open(res["eval_dir"] / "best_vecnormalize.pkl", "rb") as f:
        vn = pickle.load(f)
    np.testing.assert_array_equal(np.asarray(best["obs_norm"]["mean"]), vn.obs_rms.mean)
    final = json.loads(res["meta"].read_text())["obs_norm"]["mean"]
    # the statistics keep moving after an early best; equal only when the best is the last evaluation
    assert (np.asarray(best["obs_norm"]["mean"]) == np.asarray(final)).all() == (first_max == len(curve) - 1)


def test_a_killed_run_resumes_from_its_last_checkpoint(runs, tmp_path):
    import stable_baselines3 as sb3
    ck = sorted(runs["ppo"]["checkpoints"].glob("*_steps.zip"), key=lambda p: int(p.stem.split("_")[-2]))
    assert ck[-2].name == "ppo_sbar_6144_steps.zip"
    res = train("ppo", 10_240, tmp_path, seed=1, n_envs=16, scenario="nominal", progress=False, hyperparams=SMALL,
                eval_every=10**6, resume=ck[-2])
    assert sb3.PPO.load(str(res["model"]), device="cpu").num_timesteps == 10_240


def test_lagrange_penalty_and_multiplier_update():
    from stable_baselines3.common.vec_env import VecMonitor

    from policies.constrained import CostPenaltyVecEnv, LagrangeCallback

    inner = SbarSB3VecEnv(4, "nominal", reset_seed=3)
    pen = CostPenaltyVecEnv(VecMonitor(inner, info_keywords=EPISODE_KEYS), lam=7.0)
    ref = VecMonitor(SbarSB3VecEnv(4, "nominal", reset_seed=3), info_keywords=EPISODE_KEYS)
    pen.reset(), ref.reset()
    a = np.ones((4, 1), np.float32)
    a[:, 0] = -1.0
    for k in range(300):   # RM until 2 ms after the stop, then SM at once: a step overshoot
        act = a if k < 180 else -a
        _, r_pen, _, _ = pen.step(act)
        _, r_ref, _, _ = ref.step(act)
        np.testing.assert_allclose(r_pen, r_ref - 7.0 * inner.step_cost, rtol=1e-6, atol=1e-6)
    costs = pen.pop_episode_costs()
    assert len(costs) == 4 and min(costs) > 0.1
    cb = LagrangeCallback(pen, budget=0.05, lr=10.0)
    cb.penalty.episode_costs = [0.1] * 4            # 100 % over budget: lambda += lr
    cb.model = SimpleNamespace(logger=SimpleNamespace(record=lambda *a, **k: None))
    cb._on_rollout_end()
    assert pen.lam == pytest.approx(17.0)
    for _ in range(2):                              # under budget: lambda -= lr, clipped at 0
        cb.penalty.episode_costs = [0.0] * 4
        cb._on_rollout_end()
    assert pen.lam == 0.0


def test_short_constrained_run_ends_below_budget_and_beats_random(runs):
    """The residual Lagrangian run (8192 steps, budget 5 %): on fixed held-out windows its mean cost
    is below the budget, it reaches short mode, and its return beats random by at least |random| / 2."""
    m = run_policy(f"residual:{runs['res']['model']}", "nominal", 32, 77_000).metrics
    rnd = run_policy("random", "nominal", 32, 77_000).metrics
    assert np.mean(m["cost"]) < 0.05 and np.mean(m["reached_short_mode"]) == 1.0
    assert np.mean(m["return"]) > np.mean(rnd["return"]) + 0.5 * abs(np.mean(rnd["return"]))


def test_hyperparams_files_zoo_yaml_and_json(tmp_path):
    from policies.hyperparams import load_hyperparams

    (tmp_path / "a.yml").write_text("dronewpt/SbarCharging-v0:\n  n_timesteps: !!float 1e6\n  policy: MlpPolicy\n"
                                    "  n_steps: 64\n  policy_kwargs: \"dict(net_arch=[8, 8], log_std_init=-2)\"\n")
    hp, extra = load_hyperparams(tmp_path / "a.yml")
    assert hp == {"n_steps": 64, "policy_kwargs": {"net_arch": [8, 8], "log_std_init": -2}}
    assert extra == {"n_timesteps": 1_000_000}
    (tmp_path / "b.json").write_text(json.dumps({"learning_rate": "lin_3e-4"}))
    with pytest.raises(ValueError, match="schedules"):
        load_hyperparams(tmp_path / "b.json")
    (tmp_path / "c.yml").write_text("policy_kwargs: \"dict(activation_fn=nn.ReLU)\"\n")
    with pytest.raises(ValueError, match="literal"):
        load_hyperparams(tmp_path / "c.yml")


def test_cli_train_errors(capsys):
    from mission_sim.cli import main
    assert main(["train", "--algo", "ppo", "--timesteps", "10", "--out", "x", "--budget", "0.1"]) == 2
    assert main(["train", "--algo", "ppo", "--timesteps", "10", "--out", "x", "--env", "bogus=1"]) == 2
    assert main(["train", "--algo", "dqn", "--timesteps", "10", "--out", "x", "--residual"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all("valid" in line or "only used" in line for line in err)


@pytest.mark.parametrize("flag, value, shown, needs", [
    ("--residual-scale", "0.1", "0.1", "--residual"), ("--residual-base-budget", "0.01", "0.01", "--residual"),
    ("--lambda-lr", "10", "10.0", "--lagrangian"), ("--probe-episodes", "0", "0", "--lagrangian"),
    ("--dagger", "2", "2", "--imitate"), ("--imitation-episodes", "8", "8", "--imitate"),
    ("--imitation-epochs", "5", "5", "--imitate"), ("--imitation-mask", "", "''", "--imitate"),
    ("--slow-budget-every", "step", "'step'", "--slow-budget"),
    # given at its default value: the check compared the value with the default, so these trained and exited 0
    ("--residual-scale", "0.25", "0.25", "--residual"), ("--lambda-lr", "50", "50.0", "--lagrangian"),
    ("--dagger", "0", "0", "--imitate"), ("--imitation-mask", "last_d_short", "'last_d_short'", "--imitate"),
    ("--slow-budget-every", "window", "'window'", "--slow-budget")])
def test_cli_train_refuses_an_option_without_the_one_that_uses_it(flag, value, shown, needs, tmp_path, capsys):
    """2026-11-27: `train --residual-scale 0.1` without --residual (or --dagger 2 without --imitate, ...) trained a
    plain PPO and exited 0, the option silently ignored (as --budget without --lagrangian already was not); the
    same when the value given is the option's default (`--residual-scale 0.25`). The error names the value given
    (2026-11-27 midday: it named the two options only)."""
    from mission_sim.cli import main
    out = tmp_path / "run"
    assert main(["train", "--algo", "ppo", "--timesteps", "10", "--out", str(out), flag, value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dronewpt train: error: {flag} {shown} is only used with {needs}; valid: add {needs}, or drop {flag}"]
    assert not out.exists()


@pytest.mark.parametrize("argv, error", [
    (["--lambda-lr", "10"], "--lambda-lr 10.0 is only used with --lagrangian"),
    (["--timesteps", "0"], "--timesteps 0 is invalid; valid range: integer >= 1 (0 with --imitate)"),
    (["--imitate", "mpc", "--dagger", "-1"], "--dagger -1 is invalid; valid range: >= 0"),
    (["--action-filter", "1.5"], "--action-filter 1.5 is invalid; valid range: [0, 1)"),
    (["--lagrangian", "--probe-episodes", "2000"], "--probe-episodes 2000 is invalid; valid range: 0..1024")])
def test_cli_train_refuses_before_importing_numpy_or_policies(argv, error, tmp_path):
    """2026-11-27 midday: `dronewpt train` imported policies.train (numpy, the policies: ~0.3-0.4 s at the start of a
    process, more on a loaded machine) before refusing an option given without the one that uses it or a bad count;
    now those checks come first and read the numpy-free mission_sim.train_options."""
    import os
    import subprocess
    import sys
    code = ("import sys; from mission_sim.cli import main; rc = main(sys.argv[1:]); "
            "print(rc, sorted(m for m in ('numpy', 'policies', 'policies.train', 'envs', 'torch') if m in sys.modules))")
    base = ["train", "--algo", "ppo", "--timesteps", "10", "--out", str(tmp_path / "run")]
    args = base + argv if "--timesteps" not in argv else base[:3] + argv + base[5:]
    r = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert r.stdout.split() == ["2", "[]"], (r.stdout, r.stderr)
    assert r.stderr.strip() == f"dronewpt train: error: {error}" or r.stderr.strip().startswith(
        f"dronewpt train: error: {error};"), r.stderr


#: a value of each option that has an effect only with another one (the defaults' among them: given is given), and
#: the option it needs
_GIVEN = {"lambda_lr": (10.0, "lagrangian"), "probe_episodes": (32, "lagrangian"), "budget": (0.1, "lagrangian"),
          "residual_scale": (0.25, "residual"), "residual_base_budget": (0.01, "residual"), "dagger": (0, "imitate"),
          "imitation_episodes": (8, "imitate"), "imitation_epochs": (30, "imitate"), "imitation_mask": ((), "imitate"),
          "slow_budget_every": ("window", "slow_budget")}


def _stop_before_training(monkeypatch, seen=None):
    """train() stopped where the run's spec is made (its options recorded in ``seen``): nothing trains."""
    from policies import train as tr

    def spec(algo, timesteps, opts):
        (seen if seen is not None else {}).update(opts)
        raise RuntimeError("stop before training")
    monkeypatch.setattr(tr, "_spec", spec)


@pytest.mark.parametrize("opt", sorted(_GIVEN))
def test_train_refuses_an_option_without_the_one_that_uses_it(opt, tmp_path, monkeypatch):
    """2026-11-27: ``policies.train.train(..., residual_scale=0.1)`` without ``residual=True`` (and the like) trained a
    plain PPO, the option silently ignored, where ``dronewpt train`` refused it; now the same rule
    (``policies.train.ONLY_WITH``, which the command line reads) is a ValueError naming both options, before anything
    is written."""
    _stop_before_training(monkeypatch)
    out = tmp_path / "run"
    value, needs = _GIVEN[opt]
    with pytest.raises(ValueError) as e:
        train("ppo", 1000, out, progress=False, **{opt: value})
    assert str(e.value) == f"{opt}={value!r} is only used with {needs}; valid: set {needs} too, or leave {opt} out (None)"
    assert not out.exists()


def test_the_train_rule_is_one_list_and_its_defaults_are_trains_and_the_command_lines(monkeypatch, tmp_path):
    """Every option of the rule is tested above; not given (None), train() runs with its documented defaults
    (imitation_epochs 30), the command line hands train() None for an option whose option is off and its own
    defaults (--imitation-epochs 60) for one whose option is on; given with its option, an option passes."""
    from mission_sim.cli import main
    from policies import train as tr
    assert {k: n for k, (_, n) in _GIVEN.items()} == tr.ONLY_WITH
    seen = {}
    _stop_before_training(monkeypatch, seen)
    with pytest.raises(RuntimeError, match="stop before training"):
        train("ppo", 1000, tmp_path / "a", progress=False)
    assert {k: seen.get(k) for k in tr.ONLY_WITH} == {   # imitation_epochs / _mask: read by the imitation stage only
        "lambda_lr": 50.0, "probe_episodes": 32, "residual_scale": 0.25, "residual_base_budget": 0.0, "dagger": 0,
        "imitation_episodes": 64, "slow_budget_every": "window", "budget": None, "imitation_epochs": None,
        "imitation_mask": None}
    with pytest.raises(RuntimeError, match="stop before training"):
        train("ppo", 1000, tmp_path / "b", progress=False, residual=True, residual_scale=0.1, lagrangian=True,
              budget=0.05, lambda_lr=10.0)
    assert (seen["residual_scale"], seen["budget"], seen["lambda_lr"], seen["probe_episodes"]) == (0.1, 0.05, 10.0, 32)
    calls = []
    monkeypatch.setattr(tr, "train", lambda *a, **kw: calls.append(kw) or {})
    base = ["train", "--algo", "ppo", "--timesteps", "10", "--out", str(tmp_path / "c")]
    assert main(base) == 0 and main(base + ["--imitate", "mpc"]) == 0
    assert all(calls[0][k] is None for k in tr.ONLY_WITH)
    # its own --imitation-epochs 60 only; train()'s defaults are filled by train() (the command line filled them too)
    assert {k: v for k, v in calls[1].items() if k in tr.ONLY_WITH and v is not None} == {"imitation_epochs": 60}


def test_train_reads_its_defaults_by_name_and_the_command_line_takes_them_from_train(monkeypatch, tmp_path):
    """train() took its ONLY_WITH options' values in ONLY_WITH_DEFAULTS' key order (a reordered table swapped them:
    lambda_lr = 'window'); the command line repeated 7 of train()'s defaults (one edited in train() only would not
    reach ``dronewpt train``). Now train() reads ``policies.train.ONLY_WITH_DEFAULTS`` by name, alone: the command line
    hands None on, but its own --imitation-epochs 60 (it filled train()'s too, a second reader of the table)."""
    from mission_sim.cli import main
    from policies import train as tr
    reordered = dict(reversed(list(tr.ONLY_WITH_DEFAULTS.items())))
    monkeypatch.setattr(tr, "ONLY_WITH_DEFAULTS", reordered)
    seen = {}
    _stop_before_training(monkeypatch, seen)
    with pytest.raises(RuntimeError, match="stop before training"):
        train("ppo", 1000, tmp_path / "a", progress=False, lagrangian=True, residual=True)
    assert {k: seen[k] for k in ("lambda_lr", "probe_episodes", "residual_scale", "residual_base_budget",
                                 "slow_budget_every")} == {"lambda_lr": 50.0, "probe_episodes": 32, "residual_scale": 0.25,
                                                           "residual_base_budget": 0.0, "slow_budget_every": "window"}
    monkeypatch.setattr(tr, "ONLY_WITH_DEFAULTS", dict(reordered, lambda_lr=7.0, imitation_episodes=5, imitation_epochs=9))
    taken, only_with_values = {}, tr._only_with_values
    monkeypatch.setattr(tr, "_only_with_values", lambda given: taken.update(only_with_values(given)) or dict(taken))
    base = ["train", "--algo", "ppo", "--timesteps", "10", "--out", str(tmp_path / "c")]
    with pytest.raises(RuntimeError, match="stop before training"):
        main(base + ["--lagrangian", "--imitate", "mpc"])
    assert (taken["lambda_lr"], taken["imitation_episodes"], taken["imitation_epochs"],
            taken["imitation_mask"]) == (7.0, 5, 60, ("last_d_short",))


def test_final_summary_is_the_last_evaluation_else_the_last_training_episodes(runs):
    """2026-11-28: `dronewpt train` ended with the written paths only. The run's metadata now carries the last
    training episodes SB3 kept (ep_info_buffer) beside the last evaluation, and `final_summary` states the
    evaluation's return and cost with their spread, else the training episodes'."""
    import pandas as pd

    from policies.train import final_summary
    res = runs["ppo"]
    meta = json.loads(res["meta"].read_text())
    # the evaluation's return: SB3's own record (evaluations.npz), its last row
    last = np.load(res["eval_dir"] / "evaluations.npz")["results"][-1]
    ev = meta["final_eval"]
    assert ev["return_mean"] == pytest.approx(last.mean()) and ev["return_std"] == pytest.approx(last.std())
    assert ev["cost_std"] >= 0.0
    line = final_summary(meta)
    assert line.startswith(f"final evaluation at {ev['timesteps']:,} steps (4 held-out windows): ")
    assert f"return {ev['return_mean']:.4g} +- {ev['return_std']:.4g}, cost {ev['cost']:.4g} +- " in line
    # the training episodes: VecMonitor's CSV, its last (up to) 100 windows, independently of SB3's buffer
    mon = pd.read_csv(res["monitor"], skiprows=1).tail(100)
    tr = meta["final_training"]
    assert tr["episodes"] == len(mon) > 0 and tr["timesteps"] == 8192
    assert tr["return_mean"] == pytest.approx(mon["r"].mean(), abs=1e-5)
    assert tr["return_std"] == pytest.approx(mon["r"].std(ddof=0), abs=1e-5)
    assert tr["cost"] == pytest.approx(mon["episode_cost"].mean(), rel=1e-6)
    assert tr["cost_std"] == pytest.approx(mon["episode_cost"].std(ddof=0), rel=1e-6)
    no_eval = final_summary({**meta, "final_eval": None})
    assert f"the last {len(mon)} training windows: return {tr['return_mean']:.4g} +- {tr['return_std']:.4g}" in no_eval
    assert "no training window finished" in final_summary(
        {**meta, "final_eval": None, "final_training": {"timesteps": 64, "episodes": 0}})


def test_final_summary_of_a_lagrangian_run_states_its_budget(runs):
    """A constrained run's (``--lagrangian``) summary names its budget and whether the final mean cost is within it
    (it did not: the reader compared the cost with the budget by hand); an unconstrained run's does not."""
    from policies.train import final_summary
    meta = json.loads(runs["res"]["meta"].read_text())
    ev, b = meta["final_eval"], meta["budget"]
    assert meta["lagrangian"] and b == 0.05
    line = final_summary(meta)
    assert line.endswith(f"; budget 0.05: {'within' if ev['cost'] <= b else 'above'}")
    for cost, word in ((0.9 * b, "within"), (b, "within"), (1.1 * b, "above")):
        assert final_summary({**meta, "final_eval": {**ev, "cost": cost}}).endswith(f"; budget 0.05: {word}")
        tr = {**meta["final_training"], "cost": cost}
        assert final_summary({**meta, "final_eval": None, "final_training": tr}).endswith(f"; budget 0.05: {word}")
    assert "budget" not in final_summary(json.loads(runs["ppo"]["meta"].read_text()))


def test_cli_train_prints_the_final_summary_last(runs, monkeypatch, tmp_path, capsys):
    import policies.train as ptrain
    from mission_sim.cli import main
    monkeypatch.setattr(ptrain, "train", lambda *a, **k: runs["ppo"])   # the run above, not a second one
    assert main(["train", "--algo", "ppo", "--timesteps", "8192", "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[-1] == ptrain.final_summary(json.loads(runs["ppo"]["meta"].read_text()))
    assert out[-1].startswith("final evaluation at 8,192 steps")
