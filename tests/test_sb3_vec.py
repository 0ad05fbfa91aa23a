"""The SB3 VecEnv adapter over the batched env equals the single envs step by step."""

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from envs import SbarChargingEnv                      # noqa: E402
from envs.sb3_vec import EPISODE_KEYS, SbarSB3VecEnv  # noqa: E402


def test_adapter_equals_single_envs_step_by_step_with_resets():
    n, seed, T = 3, 11, 300
    venv = SbarSB3VecEnv(num_envs=n, scenario="random")
    venv.seed(seed)
    obs = venv.reset()
    singles = [SbarChargingEnv(scenario="random") for _ in range(n)]
    s_obs = np.stack([e.reset(seed=seed + i)[0] for i, e in enumerate(singles)])
    np.testing.assert_array_equal(obs, s_obs)
    rng = np.random.default_rng(0)
    ends = 0
    for k in range(2 * T + 17):
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        obs, rew, done, infos = venv.step(a)
        for i, e in enumerate(singles):
            o, r, term, trunc, info = e.step(a[i])
            assert rew[i] == pytest.approx(r, rel=1e-6, abs=1e-6)
            assert bool(done[i]) == (term or trunc)
            if term or trunc:
                ends += 1
                np.testing.assert_allclose(infos[i]["terminal_observation"], o, atol=1e-6)
                assert infos[i]["TimeLimit.truncated"] is True
                assert infos[i]["episode_cost"] == pytest.approx(info["episode_cost"], abs=1e-9)
                assert infos[i]["reached_short_mode"] == info["reached_short_mode"]
                assert set(EPISODE_KEYS) <= set(infos[i])
                o, _ = e.reset()                      # next window: the generator continues
            else:
                assert infos[i] == {}                 # slim info while the window runs
            np.testing.assert_allclose(obs[i], o, atol=1e-6)
    assert ends == 2 * n


def test_vecmonitor_logs_return_and_cost_per_episode(tmp_path):
    import pandas as pd
    from stable_baselines3.common.vec_env import VecMonitor

    venv = VecMonitor(SbarSB3VecEnv(num_envs=4, scenario="nominal"), str(tmp_path / "m"), info_keywords=EPISODE_KEYS)
    venv.seed(5)
    venv.reset()
    for _ in range(300):
        venv.step(np.full((4, 1), -1.0, np.float32))   # stays in RM: no cost, never SM
    for _ in range(300):
        venv.step(np.full((4, 1), 1.0, np.float32))    # jumps to SM at once: the step's overshoot
    venv.close()
    df = pd.read_csv(tmp_path / "m.monitor.csv", skiprows=1)
    assert len(df) == 8 and {"r", "l", "episode_cost", "overshoot", "reached_short_mode"} <= set(df.columns)
    rm, sm = df.iloc[:4], df.iloc[4:]
    assert (rm["episode_cost"] == 0).all() and not rm["reached_short_mode"].any()
    assert (sm["reached_short_mode"]).all()
    # always-SM: the whole window is short mode, so no stop transient: I2 sits at I2_sm (cost ~0)
    assert (sm["overshoot"].abs() < 0.02).all() and (sm["energy_after_stop_j"] < 1e-3).all()


def test_actions_nan_is_a_clear_error():
    venv = SbarSB3VecEnv(num_envs=2)
    venv.reset()
    with pytest.raises(ValueError, match="valid range"):
        venv.step(np.array([[0.0], [np.nan]], np.float32))
