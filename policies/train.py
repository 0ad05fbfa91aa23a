"""Train an SB3 policy on the charging environment: PPO / SAC (continuous) or DQN (discrete ON-OFF).

Writes into ``out_dir``:

* ``<algo>_sbar.zip`` + ``<algo>_sbar.json`` (model + metadata with the VecNormalize observation
  statistics as JSON; loadable with :class:`policies.rl.RLPolicy`),
* ``monitor/*.monitor.csv`` (SB3 Monitor: episode return, length, time),
* ``learning_curve.png``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .rl import ALGOS

__all__ = ["train", "plot_learning_curve", "DEFAULT_HYPERPARAMS"]

DEFAULT_HYPERPARAMS = {
    # log_std_init -1.5 (std 0.22 in action units): a wide Gaussian (std 1) dithers the duty at
    # 10 kHz next to the link's 4 kHz resonance and the early rollouts are all overcurrent penalty
    "ppo": dict(n_steps=512, batch_size=256, n_epochs=10, learning_rate=3e-4, gamma=0.98, gae_lambda=0.95,
                ent_coef=0.0, policy_kwargs=dict(net_arch=[64, 64], log_std_init=-1.5)),
    "sac": dict(learning_rate=3e-4, buffer_size=100_000, batch_size=256, gamma=0.98, learning_starts=1000,
                policy_kwargs=dict(net_arch=[64, 64])),
    "dqn": dict(learning_rate=5e-4, buffer_size=100_000, batch_size=128, gamma=0.98, learning_starts=1000,
                exploration_fraction=0.3, target_update_interval=1000, policy_kwargs=dict(net_arch=[64, 64])),
}


def _progress_callback(total: int, enabled: bool):
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class _Tqdm(BaseCallback):
        def _on_training_start(self):
            self.bar = tqdm(total=total, unit="step", desc="train", disable=not enabled)

        def _on_step(self):
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self):
            self.bar.close()

    return _Tqdm()


def plot_learning_curve(monitor_dir, out_png, title: str) -> Path:
    """Episode return against environment steps from SB3 Monitor CSVs (all sub-envs pooled)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    frames = []
    for f in sorted(Path(monitor_dir).glob("*.monitor.csv")):
        df = pd.read_csv(f, skiprows=1)
        frames.append(df)
    if not frames:
        raise FileNotFoundError(f"no *.monitor.csv in {monitor_dir}")
    df = pd.concat(frames).sort_values("t")
    steps = np.cumsum(df["l"].to_numpy())
    ret = df["r"].to_numpy()
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(steps, ret, ".", ms=2, alpha=0.4, label="episode return")
    w = max(1, len(ret) // 20)
    if len(ret) >= w:
        ax.plot(steps[w - 1:], np.convolve(ret, np.ones(w) / w, mode="valid"), lw=2, label=f"mean of {w}")
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out_png = Path(out_png)
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return out_png


def train(algo: str, timesteps: int, out_dir, *, seed: int = 0, n_envs: int = 1, scenario: str = "random",
          progress: bool = True, hyperparams: dict | None = None, name: str | None = None) -> dict:
    """Train ``algo`` for ``timesteps`` environment steps; returns a dict of the written paths and the
    final mean episode return. Deterministic for a given seed on one thread (torch threads set to 1)."""
    import gymnasium as gym
    import stable_baselines3 as sb3
    import torch
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    import envs

    if algo not in ALGOS:
        raise ValueError(f"algo={algo!r} is invalid; valid values: {', '.join(ALGOS)}")
    if int(timesteps) != timesteps or timesteps < 1:
        raise ValueError(f"timesteps={timesteps!r} is invalid; valid range: integer >= 1")
    if int(n_envs) != n_envs or not 1 <= n_envs <= 256:
        raise ValueError(f"n_envs={n_envs!r} is invalid; valid range: integer 1..256")
    envs.get_scenario(scenario)
    torch.set_num_threads(1)
    out = Path(out_dir)
    (out / "monitor").mkdir(parents=True, exist_ok=True)
    for f in (out / "monitor").glob("*.monitor.csv"):
        f.unlink()
    env_id = envs.DISCRETE_ENV_ID if algo == "dqn" else envs.ENV_ID
    venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, monitor_dir=str(out / "monitor"),
                        env_kwargs={"scenario": scenario})
    venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=0.98)
    hp = dict(DEFAULT_HYPERPARAMS[algo])
    hp.update(hyperparams or {})
    cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "dqn": sb3.DQN}[algo]
    model = cls("MlpPolicy", venv, seed=seed, verbose=0, device="cpu", **hp)
    model.learn(total_timesteps=int(timesteps), callback=_progress_callback(int(timesteps), progress))
    stem = name or f"{algo}_sbar"
    zip_path = out / f"{stem}.zip"
    model.save(str(zip_path))
    probe = gym.make(env_id).unwrapped
    meta = {
        "algo": algo, "env_id": env_id, "discrete": algo == "dqn", "scenario": scenario, "seed": int(seed),
        "timesteps": int(timesteps), "n_envs": int(n_envs), "control_period_s": probe.config.dt_s,
        "hyperparams": {k: v for k, v in hp.items() if k != "policy_kwargs"},
        "policy_kwargs": hp.get("policy_kwargs", {}),
        "obs_norm": {"mean": venv.obs_rms.mean.tolist(), "var": venv.obs_rms.var.tolist(),
                     "clip": float(venv.clip_obs), "epsilon": float(venv.epsilon)},
        "reproduce": f"dronewpt train --algo {algo} --timesteps {int(timesteps)} --seed {int(seed)} "
                     f"--n-envs {int(n_envs)} --scenario {scenario} --out DIR",
    }
    meta_path = zip_path.with_suffix(".json")
    meta_path.write_text(json.dumps(meta, indent=2))
    venv.close()
    png = plot_learning_curve(out / "monitor", out / "learning_curve.png", f"{algo.upper()} on {env_id} ({scenario})")
    return {"model": zip_path, "meta": meta_path, "monitor_dir": out / "monitor", "learning_curve": png}
