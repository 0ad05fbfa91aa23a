"""The numpy export of SB3 actors gives predict(deterministic=True)'s actions (float32 round-off)."""

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
from stable_baselines3 import DQN, PPO, SAC  # noqa: E402

from policies.inference import NumpyActor, export_actor  # noqa: E402
from policies.rl import RLPolicy  # noqa: E402


def _obs(space, n=400, seed=0):
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(space.low), space.low, -3.0)
    hi = np.where(np.isfinite(space.high), space.high, 3.0)
    span = hi - lo
    return rng.uniform(lo - 0.2 * span, hi + 0.2 * span, (n,) + space.shape).astype(np.float32)


def _compare(model, atol=1e-5):
    actor = export_actor(model)
    assert isinstance(actor, NumpyActor)
    obs = _obs(model.observation_space)
    ref, _ = model.predict(obs, deterministic=True)
    got = actor.act(obs).reshape(ref.shape)
    if np.issubdtype(ref.dtype, np.integer):
        assert np.mean(got == ref) > 0.99   # arg-max: a near tie may flip on round-off
    else:
        assert np.allclose(got, ref, rtol=0, atol=atol)
    return ref, got


def test_shipped_ppo_matches_predict_and_clips():
    pol = RLPolicy()
    assert pol._actor is not None
    obs = _obs(pol.model.observation_space, n=1000)
    ref, _ = pol.model.predict(obs, deterministic=True)
    got = pol._actor.act(obs)
    assert np.max(np.abs(got - ref)) <= 1e-6
    assert np.all(got >= -1.0) and np.all(got <= 1.0)
    # one receiver at a time (the mission loop) gives the same duty as the batch
    fast = [float(pol.act(o[None, :].astype(float))[0]) for o in obs[:50]]
    slow = RLPolicy(fast=False)
    ref_d = [float(slow.act(o[None, :].astype(float))[0]) for o in obs[:50]]
    assert np.allclose(fast, ref_d, rtol=0, atol=1e-6)


def test_ppo_relu_continuous_and_discrete():
    import torch.nn as nn
    kw = dict(policy_kwargs=dict(net_arch=[16, 8], activation_fn=nn.ReLU), device="cpu", seed=1)
    ref, _ = _compare(PPO("MlpPolicy", gym.make("Pendulum-v1"), **kw))
    assert ref.shape[1] == 1
    _compare(PPO("MlpPolicy", gym.make("CartPole-v1"), **kw))


def test_sac_tanh_squash_rescaled_to_the_box():
    model = SAC("MlpPolicy", gym.make("Pendulum-v1"), policy_kwargs=dict(net_arch=[16, 16]), device="cpu", seed=2)
    ref, got = _compare(model)
    assert np.all(np.abs(got) <= 2.0 + 1e-6)   # Pendulum's torque box is [-2, 2]


def test_dqn_argmax():
    _compare(DQN("MlpPolicy", gym.make("CartPole-v1"), policy_kwargs=dict(net_arch=[16]), device="cpu", seed=3))


def test_unsupported_architecture_falls_back_to_predict():
    model = PPO("MlpPolicy", gym.make("Pendulum-v1"), use_sde=True, device="cpu", seed=4)
    assert export_actor(model) is None
