"""Issue 21: frame stack, privileged observation, smoothed actions, imitation of a teacher."""

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from mission_sim.contract import OBS_DIM, OBS_INDEX, history_obs_dim  # noqa: E402


def _cfg(n_steps=40):
    from policies.train import env_config
    return env_config({"n_steps": n_steps})


def test_history_obs_dim_and_bad_values():
    assert history_obs_dim(1) == OBS_DIM and history_obs_dim(4) == 4 * OBS_DIM
    for bad in (0, 33, 2.5):
        with pytest.raises(ValueError, match="history"):
            history_obs_dim(bad)


def test_frame_stack_equals_last_k_single_observations_across_autoreset():
    """The stacked observation is the last K observations of the same window, oldest first (K copies
    of the first one at a window's start), terminal observations included."""
    from envs.history import HistoryVecEnv
    from envs.sb3_vec import SbarSB3VecEnv

    k, n, T = 3, 4, 12
    plain = SbarSB3VecEnv(n, "random", _cfg(T))
    stacked = HistoryVecEnv(SbarSB3VecEnv(n, "random", _cfg(T)), k)
    plain.seed(5)
    stacked.venv.seed(5)
    window = [[o] for o in plain.reset()]
    s = stacked.reset()
    rng = np.random.default_rng(0)
    n_done = 0
    for _ in range(2 * T + 3):
        past = [np.stack(([w[0]] * k + w)[-k:]) for w in window]
        assert np.array_equal(s, np.stack([p.reshape(-1) for p in past]))
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        o, _, done, infos = plain.step(a)
        s, _, done2, infos2 = stacked.step(a)
        assert np.array_equal(done, done2)
        for i in range(n):
            if done[i]:
                n_done += 1
                term = np.stack(([window[i][0]] * k + window[i] + [infos[i]["terminal_observation"]])[-k:])
                assert np.array_equal(infos2[i]["terminal_observation"], term.reshape(-1))
                window[i] = [o[i]]
            else:
                window[i].append(o[i])
    assert n_done == 2 * n   # two autoresets of every window were checked
    assert s.shape == (n, k * OBS_DIM)


def test_privileged_observation_is_the_undelayed_one():
    """With a sensing delay of D periods the privileged current fields at step k equal the observed
    ones at step k + D (the observation's noise aside: I2 is compared within the sensor noise)."""
    from envs import SbarChargingVectorEnv
    from policies.imitation import privileged_obs

    delay = 2
    venv = SbarChargingVectorEnv(num_envs=3, scenario={"name": "d", "sense_delay_steps": (delay, delay)})
    obs, info = venv.reset(seed=3)
    priv, seen = [], []
    for _ in range(30):
        priv.append(privileged_obs(obs, info))
        seen.append(obs.copy())
        obs, _, _, _, info = venv.step(np.full((3, 1), -0.6, np.float32))
    for f in ("battery_current_a", "rect_current_a"):
        j = OBS_INDEX[f]
        for k in range(5, 25):
            np.testing.assert_allclose(priv[k][:, j], seen[k + delay][:, j], atol=2e-6)
            assert not np.allclose(priv[k][:, j], seen[k][:, j]) or np.allclose(priv[k][:, j], priv[k - delay][:, j])
    j = OBS_INDEX["i2_amp_a"]   # noise-free in the privileged view: within the sensor noise (0.1 A ~ 0.004 normalised)
    assert np.max(np.abs(np.array(priv[5:25])[:, :, j] - np.array(seen[5 + delay:25 + delay])[:, :, j])) < 0.05


def test_action_filter_and_smoothness_penalty_are_exact():
    from envs.sb3_vec import SbarSB3VecEnv
    from policies.smoothing import SmoothActionVecEnv, filtered_duty

    alpha, w, n = 0.6, 3.0, 4
    base = SbarSB3VecEnv(n, "nominal", _cfg())
    raw = SbarSB3VecEnv(n, "nominal", _cfg())
    env = SmoothActionVecEnv(base, alpha, w)
    base.seed(1)
    raw.seed(1)
    obs, obs_raw = env.reset(), raw.reset()
    rng = np.random.default_rng(2)
    for _ in range(20):
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        last = (obs[:, OBS_INDEX["last_d_short"]] + 1.0) / 2.0
        d = alpha * last + (1 - alpha) * (a[:, 0] + 1.0) / 2.0
        np.testing.assert_allclose(filtered_duty(obs, (a[:, 0] + 1) / 2, alpha), d, atol=1e-7)
        obs, r, _, _ = env.step(a)
        obs_raw, r_raw, _, _ = raw.step((2 * d - 1)[:, None].astype(np.float32))
        np.testing.assert_allclose(obs[:, OBS_INDEX["last_d_short"]], obs_raw[:, OBS_INDEX["last_d_short"]], atol=1e-6)
        np.testing.assert_allclose(r, r_raw - w * (d - last) ** 2, rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="action_filter"):
        SmoothActionVecEnv(base, 1.0)
