"""RL: brief training proves learning; the CLI trains, saves and compares; training is reproducible."""

import json

import numpy as np
import pytest

from mission_sim.cli import main
from policies.compare import run_policy

EVAL_SEEDS = 500      # fixed evaluation seeds 500..507 (nominal scenario)
EVAL_EPISODES = 8


@pytest.fixture(scope="module")
def brief_ppo(tmp_path_factory):
    """PPO, 24 576 steps on the nominal scenario (seed 0): a few seconds on one core."""
    from policies.train import train
    out = tmp_path_factory.mktemp("ppo")
    res = train("ppo", 24_576, out, seed=0, n_envs=4, scenario="nominal", progress=False, eval_every=8192,
                eval_episodes=8, hyperparams=dict(n_steps=512, batch_size=256,
                                                  policy_kwargs=dict(net_arch=[32, 32], log_std_init=-1.5)))
    return res


def test_brief_training_beats_random_by_a_stated_margin(brief_ppo):
    """Margin: the trained policy's mean return on the fixed seeds must exceed the random policy's
    by at least half of |random's return| (random ~ -1400: its duty noise rings the link to ~50 A),
    and its mean overcurrent cost must be below a tenth of random's."""
    trained = run_policy(f"rl:{brief_ppo['model']}", "nominal", EVAL_EPISODES, EVAL_SEEDS).metrics
    rnd = run_policy("random", "nominal", EVAL_EPISODES, EVAL_SEEDS).metrics
    r_t, r_r = np.mean(trained["return"]), np.mean(rnd["return"])
    assert r_t > r_r + 0.5 * abs(r_r)
    assert np.mean(trained["cost"]) < 0.1 * np.mean(rnd["cost"])


def test_brief_training_improves_on_its_own_initialisation(brief_ppo, tmp_path):
    """The same network before any update (seed 0, saved right after construction) does worse."""
    import stable_baselines3 as sb3
    from envs import SbarChargingEnv
    model = sb3.PPO("MlpPolicy", SbarChargingEnv(), seed=0, device="cpu",
                    policy_kwargs=dict(net_arch=[32, 32], log_std_init=-1.5))
    model.save(str(tmp_path / "untrained.zip"))
    meta = json.loads(brief_ppo["meta"].read_text())
    meta["obs_norm"] = None
    (tmp_path / "untrained.json").write_text(json.dumps(meta))
    untrained = run_policy(f"rl:{tmp_path / 'untrained.zip'}", "nominal", EVAL_EPISODES, EVAL_SEEDS).metrics
    trained = run_policy(f"rl:{brief_ppo['model']}", "nominal", EVAL_EPISODES, EVAL_SEEDS).metrics
    assert np.mean(trained["return"]) > np.mean(untrained["return"]) + 20.0


def test_training_writes_everything_and_is_reproducible(brief_ppo, tmp_path):
    assert brief_ppo["model"].stat().st_size < 1_000_000
    meta = json.loads(brief_ppo["meta"].read_text())
    assert meta["seed"] == 0 and meta["timesteps"] == 24_576 and len(meta["obs_norm"]["mean"]) == 8
    assert brief_ppo["learning_curve"].stat().st_size > 1000
    import pandas as pd
    mon = pd.read_csv(brief_ppo["monitor"], skiprows=1)
    assert len(mon) == 4 * (24_576 // 4 // 300) and {"episode_cost", "overshoot", "reached_short_mode"} <= set(mon)
    assert meta["cost"] == "overshoot" and meta["env_config"]["reward"]["overcurrent"] == 10.0
    from policies.train import train
    hp = dict(n_steps=256, batch_size=256, n_epochs=2, policy_kwargs=dict(net_arch=[16]))
    a = train("ppo", 512, tmp_path / "a", seed=3, n_envs=2, scenario="nominal", progress=False, hyperparams=hp)
    b = train("ppo", 512, tmp_path / "b", seed=3, n_envs=2, scenario="nominal", progress=False, hyperparams=hp)
    import stable_baselines3 as sb3
    pa = sb3.PPO.load(str(a["model"]), device="cpu").policy.state_dict()
    pb = sb3.PPO.load(str(b["model"]), device="cpu").policy.state_dict()
    for k in pa:
        assert np.array_equal(pa[k].numpy(), pb[k].numpy()), k


def test_cli_train_dqn_then_compare_json(tmp_path, capsys):
    out = tmp_path / "dqn"
    assert main(["train", "--algo", "dqn", "--timesteps", "300", "--out", str(out), "--seed", "1",
                 "--no-progress"]) == 0
    assert (out / "dqn_sbar.zip").is_file() and (out / "dqn_sbar.json").is_file()
    assert (out / "learning_curve.png").is_file()
    capsys.readouterr()
    assert main(["compare", "--policies", f"model_based,rl:{out / 'dqn_sbar.zip'}", "--scenarios", "nominal",
                 "--episodes", "2", "--format", "json", "--out", str(tmp_path / "cmp")]) == 0
    res = json.loads(capsys.readouterr().out)
    rows = {r["policy"]: r for r in res["rows"]}
    assert set(rows) == {"model_based", f"rl:{out / 'dqn_sbar.zip'}"}
    # instantaneous overshoot: the envelope's < 1 % (tests/test_policies.py) plus the SBAR's ripple at
    # the crest's duty, < 4.5 points (envs/peaks.py)
    assert rows["model_based"]["overshoot_pct"] < 1.0 + 4.5
    assert (tmp_path / "cmp" / "transitions_nominal.png").is_file()


def test_cli_errors_are_one_line(capsys):
    assert main(["train", "--algo", "ppo", "--timesteps", "0", "--out", "x"]) == 2
    assert main(["compare", "--policies", "bogus", "--no-plot"]) == 2
    assert main(["compare", "--scenarios", "stormy", "--no-plot"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("dronewpt ") and "valid" in line for line in err)
