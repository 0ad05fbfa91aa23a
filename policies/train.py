"""Train an SB3 policy on the charging environment: PPO / SAC (continuous) or DQN (discrete ON-OFF),
optionally constrained (Lagrangian, :mod:`policies.constrained`) and / or residual on the paper's
model-based controller.

Environments: by default the batched adapter :class:`envs.sb3_vec.SbarSB3VecEnv` (all ``n_envs``
windows in one numpy step), ``vec="make_vec_env"`` the baseline path (SB3's ``DummyVecEnv`` loop
over single envs with a ``Monitor`` each, kept for the benchmark). The stack is
``adapter -> [ResidualVecEnv] -> VecMonitor (return, episode cost) -> [CostPenaltyVecEnv] -> VecNormalize``.

Writes into ``out_dir``:

* ``<name>.zip`` + ``<name>.json`` (model + metadata: algorithm, seed, timesteps, reward weights,
  cost definition, budget, env config, hyperparameters, the VecNormalize observation statistics as
  JSON, the Lagrange multiplier history, the reproduce command; loadable with
  :class:`policies.rl.RLPolicy` or :class:`policies.residual.ResidualPolicy`),
* ``vecnormalize.pkl`` (``VecNormalize.load(path, venv)``: the SB3 way to use the model),
* ``monitor.monitor.csv`` (VecMonitor: r, l, t, episode_cost, overshoot, reached_short_mode, ...),
* ``eval/`` (``EvalCallback`` on fixed held-out seeds: ``evaluations.npz``, ``eval_curve.json``
  with cost, ``best_model.zip``), ``checkpoints/`` (``CheckpointCallback`` with the VecNormalize
  statistics; ``resume=`` continues from one), ``tb/`` when tensorboard is installed,
* ``learning_curve.png``.

Ctrl-C / SIGTERM during the RL stage (the first one; a second raises at once) stops SB3 at the next environment step
and saves the model so far as ``<name>_interrupted.zip`` + ``.json`` (``interrupted``: signal, steps, of how many) +
``<name>_interrupted_vecnormalize.pkl`` (a policy, and ``resume=`` goes on from it) and the best models' metadata,
then raises :class:`mission_sim.signals.Interrupted` with a note naming them.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from mission_sim.files import atomic_output
from mission_sim.validation import check_number
from mission_sim.train_options import ONLY_WITH, RANGES, unused_option

from .rl import ALGOS

__all__ = ["train", "final_summary", "plot_learning_curve", "DEFAULT_HYPERPARAMS", "env_config", "env_overrides", "EVAL_SEED", "VEC_PATHS",
           "ONLY_WITH", "ONLY_WITH_DEFAULTS", "unused_option"]

#: fixed held-out evaluation seeds ``EVAL_SEED + i`` (training seeds are small integers)
EVAL_SEED = 900_000
CLONE_NAME = "clone"   #: ``train --imitate`` with fine-tuning: the clone's files are clone.zip / .json / _vecnormalize.pkl
VEC_PATHS = ("batched", "make_vec_env")

#: :func:`train`'s values of :data:`ONLY_WITH`'s options not given (``budget``'s None: the ramp policy's cost), read
#: here only (:func:`_only_with_values`; ``dronewpt train`` hands None on, but its own ``--imitation-epochs`` 60).
#: :data:`ONLY_WITH` and :func:`unused_option` live in the numpy-free :mod:`mission_sim.train_options`
ONLY_WITH_DEFAULTS = {"lambda_lr": 50.0, "probe_episodes": 32, "residual_scale": 0.25, "residual_base_budget": 0.0,
                      "dagger": 0, "imitation_episodes": 64, "imitation_epochs": 30, "imitation_mask": ("last_d_short",),
                      "slow_budget_every": "window"}


def _only_with_values(given: dict) -> dict:
    """``given`` (:func:`train`'s options of :data:`ONLY_WITH` and those they need) with :data:`ONLY_WITH_DEFAULTS`
    for the ones not given (None); ``ValueError`` naming an option given without the option it needs."""
    unused = unused_option(given)
    if unused is not None:
        opt, needs = unused
        raise ValueError(f"{opt}={given[opt]!r} is only used with {needs}; valid: set {needs} too, or leave {opt} out "
                         "(None)")
    return {k: ONLY_WITH_DEFAULTS[k] if v is None and k in ONLY_WITH_DEFAULTS else v for k, v in given.items()}


DEFAULT_HYPERPARAMS = {
    # log_std_init -1.5 (std 0.22 in action units): a wide Gaussian (std 1) dithers the duty at
    # 10 kHz next to the link's 4 kHz resonance and the early rollouts are all overcurrent penalty
    "ppo": dict(n_steps=128, batch_size=1024, n_epochs=5, learning_rate=3e-4, gamma=0.98, gae_lambda=0.95,
                ent_coef=0.0, policy_kwargs=dict(net_arch=[64, 64], log_std_init=-1.5)),
    "sac": dict(learning_rate=3e-4, buffer_size=100_000, batch_size=256, gamma=0.98, learning_starts=1000,
                train_freq=1, gradient_steps=4, policy_kwargs=dict(net_arch=[64, 64])),
    # TD3 (Fujimoto et al. 2018): exploration noise N(0, 0.1) on the action unless the hyperparameters set one
    "td3": dict(learning_rate=1e-3, buffer_size=100_000, batch_size=256, gamma=0.98, learning_starts=1000,
                train_freq=1, gradient_steps=4, policy_kwargs=dict(net_arch=[64, 64])),
    "dqn": dict(learning_rate=5e-4, buffer_size=100_000, batch_size=128, gamma=0.98, learning_starts=1000,
                exploration_fraction=0.3, target_update_interval=1000, train_freq=1, gradient_steps=4,
                policy_kwargs=dict(net_arch=[64, 64])),
}


def env_config(overrides: dict | None = None):
    """:class:`envs.EnvConfig` with ``overrides``: its fields but ``link`` and ``reward`` (n_steps, slow_every,
    rated_i2_a, bus_c_f, dt_s, device_tj_c, hold_tol_a, v2_updates, v2_refine_levels, v2_refine_tol, devices - a
    preset name, link_model - ``envelope`` or ``modal``) and the reward weights (tracking, overcurrent, i_ref_a) by
    name."""
    from envs import EnvConfig, RewardWeights

    ov = dict(overrides or {})
    rw_keys = {f.name for f in fields(RewardWeights)}
    cfg_keys = {f.name for f in fields(EnvConfig)} - {"link", "reward"}
    bad = set(ov) - rw_keys - cfg_keys
    if bad:
        raise ValueError(f"env config key {sorted(bad)[0]!r} is invalid; valid keys: {', '.join(sorted(rw_keys | cfg_keys))}")
    devices = ov.pop("devices", EnvConfig.devices)
    link_model = ov.pop("link_model", EnvConfig.link_model)
    for k, v in ov.items():
        if not np.isfinite(float(v)):
            raise ValueError(f"{k}={v!r} is invalid; valid range: a finite number")
    rw = RewardWeights(**{k: float(v) for k, v in ov.items() if k in rw_keys})
    # the integer fields as int only when whole: 2.5 reaches EnvConfig's check (refused), not int()'s 2
    ints = ("n_steps", "slow_every", "v2_updates", "v2_refine_levels")
    return EnvConfig(reward=rw, devices=devices, link_model=link_model,
                     **{k: (int(v) if k in ints and float(v).is_integer() else float(v))
                        for k, v in ov.items() if k in cfg_keys})


def env_overrides(env) -> dict | None:
    """``train``'s ``env`` as the flat overrides :func:`env_config` takes (and the metadata and ``reproduce``
    record): a dict as it is, or an :class:`envs.EnvConfig` (what a Python user has at hand; it was ``TypeError:
    'EnvConfig' object is not iterable``) as its fields and reward weights that differ from the defaults. Its
    link must be Table I's (the one ``train`` runs and its metadata assume). A dict with a ``reward`` entry (a
    trained model's metadata ``env_config``, as the envs, ``compare`` and the oracle take it: ``{"reward":
    {"overcurrent": 20}, ...}``) goes through :func:`envs.core.as_config` to the same flat form."""
    from envs import EnvConfig
    from envs.core import as_config

    if isinstance(env, Mapping) and "reward" in env:
        env = as_config(env)
    if env is None or isinstance(env, dict):
        return env
    if not isinstance(env, EnvConfig):
        raise ValueError(f"env={env!r} is invalid; valid: None, an envs.EnvConfig or a dict of its fields and reward "
                         "weights by name (e.g. {'link_model': 'envelope', 'overcurrent': 20})")
    if env.link != EnvConfig.link:
        raise ValueError(f"env=EnvConfig(link={env.link!r}) is invalid; valid: Table I's link (train's metadata "
                         "records the other fields only)")
    out = {f.name: getattr(env, f.name) for f in fields(EnvConfig)
           if f.name not in ("link", "reward") and getattr(env, f.name) != f.default}
    out.update({f.name: getattr(env.reward, f.name) for f in fields(env.reward)
                if getattr(env.reward, f.name) != f.default})
    return out


def config_dict(cfg) -> dict:
    """The metadata form of an EnvConfig (without the link, which is Table I): its stated fields
    (:meth:`envs.EnvConfig.stated_fields`: ``link_model`` always, so a record says which plant it was trained on
    whatever the default is; the exact-mode link's step options only where not at their defaults)."""
    d = {k: v for k, v in cfg.stated_fields() if k not in ("link", "reward")}
    return {**d, "reward": asdict(cfg.reward)}


def plot_learning_curve(monitor_csv, out_png, title: str, eval_curve=None) -> Path:
    """Episode return and episode cost against environment steps (Monitor CSV; evaluation points)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    df = pd.read_csv(monitor_csv, skiprows=1).sort_values("t")
    steps = np.cumsum(df["l"].to_numpy())
    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for ax, col, lab in zip(axes, ("r", "episode_cost"), ("episode return", "episode cost")):
        if col not in df:
            continue
        y = df[col].to_numpy(dtype=float)
        ax.plot(steps, y, ".", ms=2, alpha=0.3, label=f"training {lab}")
        w = max(1, len(y) // 20)
        if len(y):
            ax.plot(steps[w - 1:], np.convolve(y, np.ones(w) / w, mode="valid"), lw=2, label=f"mean of {w}")
        else:
            ax.text(0.5, 0.5, "no window finished yet", transform=ax.transAxes, ha="center")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    if eval_curve:
        ts = [e["timesteps"] for e in eval_curve]
        axes[0].plot(ts, [e["return_mean"] for e in eval_curve], "k-o", ms=3, label="evaluation (held-out seeds)")
        axes[1].plot(ts, [e["cost"] for e in eval_curve], "k-o", ms=3, label="evaluation")
    for ax in axes:
        ax.legend(fontsize=8)
    axes[0].set_title(title)
    axes[1].set_xlabel("environment steps")
    fig.tight_layout()
    out_png = Path(out_png)
    with atomic_output(out_png) as tmp:  # removed on failure (a full disk: the file named)
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return out_png


def _check_counts(o: dict) -> None:
    """train()'s ``seed``, ``eval_episodes``, ``eval_every``, ``checkpoint_every`` and ``lambda_lr`` (``o``: its
    keyword arguments) in dronewpt train's ranges, one table (:data:`mission_sim.train_options.RANGES`; seed 1.5 ran
    seed 1, eval_every=0 was taken, ...)."""
    for key in ("seed", "eval_episodes", "eval_every", "checkpoint_every"):
        check_number(key, o[key], RANGES[key])
    if o.get("lambda_lr") is not None:
        check_number("lambda_lr", o["lambda_lr"], RANGES["lambda_lr"])


def _check_args(algo, timesteps, n_envs, vec, lagrangian, residual, scenario, extra=None):
    import envs
    from mission_sim.contract import history_obs_dim
    from mission_sim.train_options import algo_conflict

    x = extra or {}
    if algo not in ALGOS:
        raise ValueError(f"algo={algo!r} is invalid; valid values: {', '.join(ALGOS)}")
    lo = 0 if x.get("imitate") else 1   # imitation alone: no RL steps
    if int(timesteps) != timesteps or timesteps < lo:
        raise ValueError(f"timesteps={timesteps!r} is invalid; valid range: integer >= {lo}")
    history_obs_dim(x.get("history", 1))
    if (x.get("history", 1) > 1 or x.get("action_filter") or x.get("smooth_penalty")) and vec != "batched":
        raise ValueError(f"vec={vec!r} is invalid with history / action smoothing; valid value: batched")
    bad = algo_conflict({"algo": algo, "residual": residual, **x})
    if bad:
        opt, algos, why = bad
        value = residual if opt == "residual" else x[opt]
        raise ValueError(f"algo={algo!r} is invalid with {opt}={value!r}; valid values: {', '.join(algos)} ({why})")
    check_number("n_envs", n_envs, RANGES["n_envs"])
    if vec not in VEC_PATHS:
        raise ValueError(f"vec={vec!r} is invalid; valid values: {', '.join(VEC_PATHS)}")
    if (lagrangian or residual) and vec != "batched":
        raise ValueError(f"vec={vec!r} is invalid with the Lagrangian or residual option; valid value: batched")
    if x.get("slow_budget") is not None:
        from .slow_budget import parse_budget_range
        parse_budget_range(x["slow_budget"])
        from .slow_budget import EVERY
        if x.get("slow_budget_every", "window") not in EVERY:
            raise ValueError(f"slow_budget_every={x.get('slow_budget_every')!r} is invalid; valid values: {', '.join(EVERY)}")
        if vec != "batched":
            raise ValueError(f"vec={vec!r} is invalid with slow_budget; valid value: batched")
        if algo == "dqn" or residual or x.get("imitate") or x.get("action_filter") or x.get("smooth_penalty"):
            raise ValueError("slow_budget is invalid with algo='dqn', residual, imitate or action smoothing; valid: "
                             "ppo / sac / td3 alone (the duty is the MPC's)")
    envs.get_scenario(scenario)


def _base_env(spec: dict, n_envs: int, monitor_path, reset_seed=None):
    """adapter -> [residual] -> VecMonitor (the batched path), or make_vec_env's loop."""
    import envs
    from envs.sb3_vec import EPISODE_KEYS, SbarSB3VecEnv
    from stable_baselines3.common.vec_env import VecMonitor

    from .constrained import ResidualVecEnv

    discrete = spec["algo"] == "dqn"
    if spec["vec"] == "make_vec_env":
        from stable_baselines3.common.env_util import make_vec_env
        return make_vec_env(envs.DISCRETE_ENV_ID if discrete else envs.ENV_ID, n_envs=n_envs, seed=spec["seed"],
                            monitor_dir=None if monitor_path is None else str(monitor_path) + "_mve",
                            env_kwargs={"scenario": spec["scenario"], "config": spec["config"]},
                            monitor_kwargs={"info_keywords": ("episode_cost", "overshoot", "reached_short_mode")})
    venv = SbarSB3VecEnv(n_envs, spec["scenario"], spec["config"], discrete=discrete, cost=spec["cost"],
                         reset_seed=reset_seed)
    if reset_seed is None:
        venv.seed(spec["seed"])
    if spec["action_filter"] or spec["smooth_penalty"]:
        from .smoothing import SmoothActionVecEnv
        venv = SmoothActionVecEnv(venv, spec["action_filter"], spec["smooth_penalty"])
    if spec.get("slow_budget"):
        from .slow_budget import SlowBudgetVecEnv
        venv = SlowBudgetVecEnv(venv, *spec["slow_budget"], every=spec["slow_budget_every"])
    if spec["residual"]:
        venv = ResidualVecEnv(venv, spec["residual_scale"], spec["residual_base_budget"])
    if spec["history"] > 1:
        from envs.history import HistoryVecEnv
        venv = HistoryVecEnv(venv, spec["history"])
    return VecMonitor(venv, None if monitor_path is None else str(monitor_path), info_keywords=EPISODE_KEYS)


def _checkpoint_pkl(zip_path: Path) -> Path:
    """The VecNormalize statistics saved with a model: ``<p>_vecnormalize_<n>_steps.pkl`` next to a
    ``CheckpointCallback`` file ``<p>_<n>_steps.zip``, else ``<stem>_vecnormalize.pkl`` next to ``<stem>.zip``
    (the imitation stage's ``clone.zip``), else ``vecnormalize.pkl`` in its folder."""
    import re

    m = re.fullmatch(r"(.*)_(\d+)_steps\.zip", zip_path.name)
    pkl = zip_path.with_name(f"{m.group(1)}_vecnormalize_{m.group(2)}_steps.pkl") if m else None
    if pkl is None or not pkl.is_file():
        pkl = zip_path.with_name(f"{zip_path.stem}_vecnormalize.pkl")   # e.g. clone.zip's clone_vecnormalize.pkl
    if not pkl.is_file():
        pkl = zip_path.with_name("vecnormalize.pkl")
    if not pkl.is_file():
        raise FileNotFoundError(f"resume={str(zip_path)!r}: no VecNormalize statistics next to it ({pkl.name})")
    return pkl


def _build(spec: dict, out: Path, resume):
    """Training env stack, evaluation env stack, model (new or resumed), Lagrange penalty or None."""
    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import VecNormalize

    from .constrained import CostPenaltyVecEnv
    from .obs_mask import MaskedVecNormalize

    venv = _base_env(spec, spec["n_envs"], out / "monitor")
    penalty = None
    if spec["lagrangian"]:
        venv = penalty = CostPenaltyVecEnv(venv, spec["lambda0"])
    eval_env = _base_env(spec, spec["eval_episodes"], None, reset_seed=EVAL_SEED)
    if penalty is not None:   # same wrapper chain as training (sync_envs_normalization walks both); the
        eval_env = CostPenaltyVecEnv(eval_env, 0.0)   # evaluation return is VecMonitor's, unpenalised
    cls = getattr(sb3, spec["algo"].upper())
    if resume is not None:   # a masked clone's / run's statistics load as a MaskedVecNormalize (policies.obs_mask)
        venv = VecNormalize.load(str(_checkpoint_pkl(Path(resume))), venv)
        model = cls.load(str(resume), env=venv, device="cpu")
    else:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=spec["hp"].get("gamma", 0.99))
        if spec["algo"] == "td3" and "action_noise" not in spec["hp"]:
            from stable_baselines3.common.noise import NormalActionNoise
            spec["hp"]["action_noise"] = NormalActionNoise(np.zeros(1), 0.1 * np.ones(1))
        model = cls("MlpPolicy", venv, seed=spec["seed"], verbose=0, device="cpu", tensorboard_log=spec["tb"],
                    **spec["hp"])
    kw = dict(training=False, norm_obs=True, norm_reward=False, clip_obs=10.0, gamma=spec["hp"].get("gamma", 0.99))
    eval_env = MaskedVecNormalize(eval_env, venv.masked, **kw) if isinstance(venv, MaskedVecNormalize) \
        else VecNormalize(eval_env, **kw)   # the training env's mask (policies.obs_mask)
    return venv, eval_env, model, penalty


def _callbacks(spec: dict, out: Path, eval_env, penalty, progress: bool, requests: list):
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    from .callbacks import CostEvalCallback, ProgressCallback, StopOnRequest
    from .constrained import LagrangeCallback

    n = spec["n_envs"]
    cbs = [ProgressCallback(spec["timesteps"], progress),
           CheckpointCallback(max(1, spec["checkpoint_every"] // n), str(out / "checkpoints"), name_prefix=spec["name"],
                              save_vecnormalize=True),
           CostEvalCallback(eval_env, n_eval_episodes=spec["eval_episodes"], eval_freq=max(1, spec["eval_every"] // n),
                            log_path=str(out / "eval"), best_model_save_path=str(out / "eval"), verbose=0, warn=False,
                            budget=spec["budget"] if spec["lagrangian"] else None)]
    lag = None
    if penalty is not None:
        probe = _base_env(spec, spec["probe_episodes"], None) if spec["probe_episodes"] else None
        lag = LagrangeCallback(penalty, spec["budget"], lr=spec["lambda_lr"], path=out / "lagrange.json", probe=probe)
        cbs.append(lag)
    cbs.append(StopOnRequest(requests))   # Ctrl-C / SIGTERM: stop at the next step, the model saved (train())
    return CallbackList(cbs), lag, cbs[2]


def _training_episodes(model) -> dict:
    """The last training episodes SB3 kept (``model.ep_info_buffer``: VecMonitor's ``info["episode"]`` of the
    last 100 windows, its return unpenalised, with ``episode_cost``): count, mean and std of return and cost."""
    eps = list(model.ep_info_buffer or ())
    r = np.array([e["r"] for e in eps], float)
    c = np.array([e.get("episode_cost", np.nan) for e in eps], float)
    stats = {"timesteps": int(model.num_timesteps), "episodes": len(eps)}
    if eps:
        stats.update(return_mean=float(r.mean()), return_std=float(r.std()), cost=float(c.mean()),
                     cost_std=float(c.std()))
    return stats


def final_summary(meta: dict, model: str | None = None) -> str | None:
    """One line on how a run ended, from its metadata: the last evaluation's mean return and cost with their
    standard deviations over the held-out windows, else (no evaluation was due within the run's steps) the last
    training episodes'; imitation only (``timesteps`` 0: no RL step, no evaluation), the clone's fit: its teacher,
    fits, samples and the last fit's RMS action error on its training data, and how to evaluate it (``model``: its
    file, for the ``compare`` command shown); None for metadata with none of them. A constrained run
    (``--lagrangian``) adds its budget and whether that mean cost is within it (``; budget 0.05: within`` / ``above``)."""
    ev, tr = meta.get("final_eval"), meta.get("final_training")
    budget = meta.get("budget") if meta.get("lagrangian") else None

    def spread(e, key, std, fmt):
        return f"{e[key]:{fmt}} +- {e[std]:{fmt}}" if std in e else f"{e[key]:{fmt}}"

    def against_budget(e):
        return "" if budget is None else f"; budget {budget:.4g}: {'within' if e['cost'] <= budget else 'above'}"
    if ev:
        n = (meta.get("eval") or {}).get("episodes")
        return (f"final evaluation at {ev['timesteps']:,} steps ({n} held-out windows): return "
                f"{spread(ev, 'return_mean', 'return_std', '.4g')}, cost {spread(ev, 'cost', 'cost_std', '.4g')} "
                f"(mean +- std), in short mode {100 * ev['reached_short_mode']:.0f} %{against_budget(ev)}")
    import shlex   # (the command shown can be pasted: a model path with a space is quoted)

    im = meta.get("imitation")
    if tr is None and im and im.get("iterations") and not meta.get("timesteps"):
        last = im["iterations"][-1]
        fits = len(im["iterations"])
        teacher = im.get("teacher", "?")
        policies = shlex.quote(f"imitation:{model or 'MODEL.zip'},{teacher}")
        return (f"imitation only (--timesteps 0): {teacher} cloned in {fits} fit(s) ({fits - 1} DAgger "
                f"iteration(s)), {last['samples']:,} samples, the last fit's RMS action error {last['train_rms_action']:.4g} "
                f"on its training data; nothing was evaluated: `dronewpt compare --policies "
                f"{policies}` measures it against its teacher")
    if tr is None:
        return None
    if not tr["episodes"]:
        return (f"no evaluation was due and no training window finished within {tr['timesteps']:,} steps: no "
                "return or cost to show (more --timesteps, or --eval-every below them)")
    return (f"no evaluation was due (--eval-every above --timesteps); the last {tr['episodes']} training windows: "
            f"return {spread(tr, 'return_mean', 'return_std', '.4g')}, cost {spread(tr, 'cost', 'cost_std', '.4g')} "
            f"(mean +- std, stochastic actions){against_budget(tr)}")


def _write_best_meta(folder: Path, meta: dict, ev) -> None:
    """``best_model.json`` (best evaluation return) and, for constrained runs, ``best_feasible_model.json``
    (best return within the budget, every window in short mode): the run's metadata with the normalisation
    each model was evaluated with and the evaluation that selected it (``selected_at``); usable as
    ``rl:`` / ``residual:`` like the final model."""
    notes = {"best_model": "best evaluation return, with the training normalisation it was evaluated with",
             "best_feasible_model": "best evaluation return among evaluations with mean cost <= budget and every "
                                    "window in short mode"}
    for name, kept in (("best_model", ev.best), ("best_feasible_model", ev.feasible)):
        if kept is None or not (folder / f"{name}.zip").is_file():
            continue
        sel = {k: v for k, v in kept.items() if k != "obs_norm"}
        (folder / f"{name}.json").write_text(json.dumps(
            {**meta, "obs_norm": kept["obs_norm"] or meta["obs_norm"], "selected_at": sel, "note": notes[name]},
            indent=2))


def _one_thread_each() -> None:
    """torch and numba on one thread each. numba's OpenMP workers (its own libgomp) spin after every
    parallel env step and starve torch's one thread: measured 2026-11-26, a 64x64 tanh took 0.02 ms of CPU
    before the first env step, 0.2-4.7 ms after; PPO ran ~1,100 env-steps per CPU-second instead of
    several thousand. The env's rows are independent, so its results do not depend on its threads."""
    import numba
    import torch
    torch.set_num_threads(1)
    numba.set_num_threads(1)


def _reproduce(spec: dict) -> str:
    cmd = (f"dronewpt train --algo {spec['algo']} --timesteps {spec['timesteps']} --seed {spec['seed']} "
           f"--n-envs {spec['n_envs']} --scenario {spec['scenario']} --cost {spec['cost']}")
    if spec["lagrangian"]:
        cmd += (f" --lagrangian --budget {spec['budget']:.6g} --lambda-lr {spec['lambda_lr']:g}"
                f" --probe-episodes {spec['probe_episodes']}")
    if spec["residual"]:
        cmd += (f" --residual --residual-scale {spec['residual_scale']:g}"
                f" --residual-base-budget {spec['residual_base_budget']:g}")
    if spec["history"] > 1:
        cmd += f" --history {spec['history']}"
    if spec.get("slow_budget"):
        cmd += f" --slow-budget {spec['slow_budget'][0]:g}:{spec['slow_budget'][1]:g} --slow-budget-every {spec['slow_budget_every']}"
    if spec["action_filter"] or spec["smooth_penalty"]:
        cmd += f" --action-filter {spec['action_filter']:g} --smooth-penalty {spec['smooth_penalty']:g}"
    if spec["imitate"]:
        cmd += (f" --imitate {spec['imitate']} --dagger {spec['dagger']} --imitation-episodes {spec['imitation_episodes']}"
                f" --imitation-epochs {spec.get('imitation_epochs', 30)}"
                f" --imitation-mask {','.join(spec.get('imitation_mask', ('last_d_short',)))}")
    if spec["env_overrides"]:
        cmd += " " + " ".join(f"--env {k}={v}" for k, v in spec["env_overrides"].items())
    if "link_model" not in (spec["env_overrides"] or {}) and spec.get("config") is not None:
        cmd += f" --link {spec['config'].link_model}"   # always named: the envs' default changed once (2026-11-26)
    if spec["hyperparams_file"]:
        cmd += f" --hyperparams {spec['hyperparams_file']}"
    return cmd + " --out DIR"


def _meta(spec: dict, venv, lag, probe_dt: float) -> dict:
    from .obs_mask import obs_norm_meta

    hp = spec["hp"]
    return {
        "algo": spec["algo"], "env_id": spec["env_id"], "discrete": spec["algo"] == "dqn", "scenario": spec["scenario"],
        "seed": spec["seed"], "timesteps": spec["timesteps"], "n_envs": spec["n_envs"], "vec": spec["vec"],
        "control_period_s": probe_dt, "obs_dim": int(venv.observation_space.shape[0]),
        "hyperparams": {k: (v if k != "action_noise" else repr(v)) for k, v in hp.items() if k != "policy_kwargs"},
        "history": spec["history"], "action_filter": spec["action_filter"], "smooth_penalty": spec["smooth_penalty"],
        "policy_kwargs": hp.get("policy_kwargs", {}),
        "hyperparams_file": spec["hyperparams_file"], "env_config": config_dict(spec["config"]),
        "env_overrides": spec["env_overrides"], "cost": spec["cost"],
        "budget": spec["budget"], "budget_source": spec["budget_source"],
        "lagrangian": None if lag is None else {"lr": lag.lr, "lambda": lag.penalty.lam, "history": lag.history,
                                                "cost_from": f"{spec['probe_episodes']} deterministic windows per rollout"
                                                if spec["probe_episodes"] else "the stochastic rollouts"},
        "residual": {"scale": spec["residual_scale"], "base_budget": spec["residual_base_budget"],
                     "base": f"model_based_budget:{spec['residual_base_budget']:g}"} if spec["residual"] else None,
        "slow_budget": {"lo": spec["slow_budget"][0], "hi": spec["slow_budget"][1], "base": "mpc",
                        "every": spec["slow_budget_every"],
                        "action": "b = lo + (a + 1) / 2 (hi - lo): the MPC's measured-overshoot budget"}
        if spec.get("slow_budget") else None,
        "obs_norm": obs_norm_meta(venv),
        "eval": {"seed": EVAL_SEED, "episodes": spec["eval_episodes"], "every_steps": spec["eval_every"]},
        "reproduce": _reproduce(spec),
    }


def _spec(algo, timesteps, o: dict) -> dict:
    """Everything a run is made of (``o``: train's keyword arguments), hyperparameters merged
    (defaults < file < ``hyperparams``), the default budget measured when asked for."""
    import envs

    _check_counts(o)
    hp = dict(DEFAULT_HYPERPARAMS[algo])
    if o["hyperparams_file"] is not None:
        from .hyperparams import load_hyperparams
        hp.update(load_hyperparams(o["hyperparams_file"])[0])
    hp.update(o["hyperparams"] or {})
    import stable_baselines3 as sb3

    from .hyperparams import check_hyperparams
    check_hyperparams(hp, getattr(sb3, algo.upper()))  # before anything is created
    cfg = env_config(o["env"])
    spec = dict(algo=algo, timesteps=int(timesteps), seed=int(o["seed"]), n_envs=int(o["n_envs"]),
                scenario=o["scenario"], hp=hp, config=cfg, env_overrides=dict(o["env"] or {}), cost=o["cost"],
                hyperparams_file=None if o["hyperparams_file"] is None else str(o["hyperparams_file"]),
                lagrangian=bool(o["lagrangian"]), lambda_lr=float(o["lambda_lr"]), lambda0=0.0,
                residual=bool(o["residual"]), residual_scale=float(o["residual_scale"]),
                residual_base_budget=float(o["residual_base_budget"]), vec=o["vec"],
                name=o["name"] or f"{algo}_sbar", eval_episodes=int(o["eval_episodes"]),
                eval_every=int(o["eval_every"]), checkpoint_every=int(o["checkpoint_every"]),
                probe_episodes=int(o["probe_episodes"]), tb=None,
                env_id=envs.DISCRETE_ENV_ID if algo == "dqn" else envs.ENV_ID,
                budget=None if o["budget"] is None else float(o["budget"]), budget_source="given",
                history=int(o.get("history", 1)), action_filter=float(o.get("action_filter", 0.0)),
                smooth_penalty=float(o.get("smooth_penalty", 0.0)), imitate=o.get("imitate"),
                dagger=int(o.get("dagger", 0)), imitation_episodes=int(o.get("imitation_episodes", 64)))
    if o.get("slow_budget") is not None:
        from .slow_budget import parse_budget_range
        spec["slow_budget"] = parse_budget_range(o["slow_budget"])
        spec["slow_budget_every"] = o.get("slow_budget_every", "window")
    if spec["lagrangian"] and spec["budget"] is None:
        from .constrained import ramp_budget
        spec["budget"] = ramp_budget(spec["scenario"], cfg, spec["cost"])
        spec["budget_source"] = "ramp policy's mean episode cost"
    if not spec["lagrangian"]:
        spec["budget_source"] = None
    return spec


def _imitation_stage(spec: dict, out: Path, progress: bool, epochs: int, masked: tuple) -> dict:
    """BC / DAgger of ``spec["imitate"]`` into ``out`` (:func:`policies.imitation.imitate`), the student a
    PPO actor with the run's hyperparameters (so ``resume`` fine-tunes it); the stage's record is
    kept in ``imitation_stage.json``. Imitation only (``timesteps`` 0): the model is ``<name>.zip``; with
    fine-tuning to follow, the clone is ``clone.zip`` / ``clone.json`` / ``clone_vecnormalize.pkl``, kept
    beside the fine-tuned ``<name>.zip``."""
    from .imitation import ImitationSpec, imitate

    pk = dict(spec["hp"].get("policy_kwargs") or {})
    ispec = ImitationSpec(teacher=spec["imitate"], scenario=spec["scenario"], history=spec["history"],
                          dagger=spec["dagger"], episodes=spec["imitation_episodes"], epochs=int(epochs),
                          seed=spec["seed"], net_arch=tuple(pk.get("net_arch", (64, 64))),
                          residual_scale=spec["residual_scale"] if spec["residual"] else 0.0,
                          residual_base_budget=spec["residual_base_budget"], masked=masked,
                          action_filter=spec["action_filter"])
    base = {"env_id": spec["env_id"], "n_envs": spec["n_envs"], "vec": spec["vec"], "cost": spec["cost"],
            "env_config": config_dict(spec["config"]), "env_overrides": spec["env_overrides"],
            "hyperparams": {k: v for k, v in spec["hp"].items() if k != "policy_kwargs"}, "residual": None,
            "lagrangian": None, "budget": None, "reproduce": _reproduce({**spec, "timesteps": 0})}
    name = spec["name"] if not spec["timesteps"] else CLONE_NAME   # fine-tuned later: the clone keeps its own files
    res = imitate(ispec, out, name=name, config=spec["config"], progress=progress, base_meta=base,
                  ppo_kwargs={k: v for k, v in spec["hp"].items() if k != "policy_kwargs"})
    if name == CLONE_NAME:   # PPO's final vecnormalize.pkl would overwrite the clone's statistics
        os.replace(res["vecnormalize"], out / f"{CLONE_NAME}_vecnormalize.pkl")
        res["vecnormalize"] = out / f"{CLONE_NAME}_vecnormalize.pkl"
    (out / "imitation_stage.json").write_text(json.dumps(json.loads(res["meta"].read_text())["imitation"]))
    return res


def _imitation_meta(meta: dict, out: Path, start_log_std) -> None:
    """The fine-tuned model's metadata after ``--imitate``: the imitation stage's record, the clone's file and
    the ``log_std`` PPO really started from (the clone's, not the hyperparameters' ``log_std_init``)."""
    meta["imitation"] = json.loads((out / "imitation_stage.json").read_text())
    meta["imitation"]["clone"] = f"{CLONE_NAME}.zip"
    if start_log_std is not None:
        meta["policy_kwargs"] = {**meta["policy_kwargs"], "log_std_init": start_log_std}
        meta["imitation"]["ppo_start_log_std"] = (f"{start_log_std:g}: the clone's log_std; the hyperparameters' "
                                                  "log_std_init is not used when PPO starts from the clone")


def _written_dirs(dirs: dict) -> dict:
    """The folders of ``dirs`` that hold files; empty ones (no evaluation or checkpoint was due within
    ``--timesteps``: SB3 creates them up front) are removed and left out."""
    out = {}
    for key, d in dirs.items():
        if d.is_dir() and any(d.iterdir()):
            out[key] = d
        elif d.is_dir():
            d.rmdir()
    return out


def earlier_run(out_dir, name: str = "ppo_sbar") -> str | None:
    """What of an earlier training run ``out_dir`` holds that a run writing model ``name`` there would replace
    (``name``.zip, ``name``_interrupted.zip, ``monitor.monitor.csv``, files in ``eval/`` or ``checkpoints/``), as a
    short text, or None (``train`` refuses such a folder unless it resumes). Other files (notes.zip) do not count."""
    out = Path(out_dir)
    if not out.is_dir():
        return None
    held = [f for f in (f"{name}.zip", f"{name}_interrupted.zip", "monitor.monitor.csv") if (out / f).is_file()]
    held += [f"{d}/" for d in ("eval", "checkpoints") if (out / d).is_dir() and any((out / d).iterdir())]
    if not held:
        return None
    return ", ".join(held[:3]) + (f" and {len(held) - 3} more" if len(held) > 3 else "")


#: a run's learning-curve files, which SB3 starts afresh (VecMonitor opens its csv with "w", EvalCallback its
#: arrays empty): moved aside on --resume into a folder that holds them (:func:`_keep_curves`)
CURVE_FILES = ("monitor.monitor.csv", "eval/eval_curve.json", "eval/evaluations.npz")


def _keep_curves(out: Path) -> list:
    """Move the learning-curve files of the run being resumed aside (:func:`mission_sim.files.move_aside`,
    ``monitor.monitor.prev-<UTC time>.csv``): the resumed run writes its own from its start. Returns the new paths."""
    from mission_sim.files import move_aside
    return [move_aside(out / f) for f in CURVE_FILES if (out / f).is_file()]


def _policy_prefix(spec: dict) -> str:
    """The policies.make prefix of the model a spec trains (``rl:``, ``residual:``, ``slow_budget:``)."""
    return "slow_budget" if spec.get("slow_budget") else "residual" if spec["residual"] else "rl"


#: written to stderr at the first Ctrl-C / SIGTERM of a training run
STOP_NOTICE = ("{signal}: stopping at the next step to save the model so far; another Ctrl-C before the saving "
               "starts abandons it")


def train(algo: str, timesteps: int, out_dir, *, seed: int = 0, n_envs: int = 64, scenario: str = "random",
          progress: bool = True, hyperparams: dict | None = None, hyperparams_file=None, env=None,
          cost: str = "overshoot", lagrangian: bool = False, budget: float | None = None, lambda_lr: float | None = None,
          residual: bool = False, residual_scale: float | None = None, vec: str = "batched", name: str | None = None,
          eval_episodes: int = 32, eval_every: int = 50_000, checkpoint_every: int = 100_000, resume=None,
          probe_episodes: int | None = None, residual_base_budget: float | None = None, history: int = 1,
          action_filter: float = 0.0, smooth_penalty: float = 0.0, imitate: str | None = None, dagger: int | None = None,
          imitation_episodes: int | None = None, imitation_epochs: int | None = None, imitation_mask: tuple | None = None,
          slow_budget=None, slow_budget_every: str | None = None) -> dict:
    """Train ``algo`` for ``timesteps`` environment steps; returns a dict of the written paths.

    ``env``: None (the defaults), an :class:`envs.EnvConfig` (Table I's link), a dict of its fields with a nested
    ``reward`` dict (a model's metadata ``env_config``) or train's flat overrides (EnvConfig fields and reward weights
    by name, :func:`env_config`), all recorded flat (:func:`env_overrides`); ``cost``: ``overshoot`` or ``overcurrent``
    (:mod:`envs.sb3_vec`); ``lagrangian``: penalise the cost with a multiplier learned against ``budget``
    (default: the ramp policy's mean episode cost on ``scenario``); ``residual``: learn a bounded correction
    ``residual_scale * a`` of the model-based duty (of the budgeted controller with ``residual_base_budget`` > 0);
    ``probe_episodes``: the multiplier's cost is measured on this many deterministic windows after every rollout
    (0: on the stochastic rollouts themselves, see :class:`policies.constrained.LagrangeCallback`).
    ``history``: frame stack of K observations (:mod:`envs.history`); ``action_filter`` / ``smooth_penalty``:
    low-pass filtered duty / duty-change penalty (:mod:`policies.smoothing`); ``imitate``: first behaviour-clone
    (``dagger`` > 0: DAgger) the teacher policy of that name (``privileged:NAME``: the teacher sees the present,
    noise-free currents) on ``imitation_episodes`` windows per iteration, ``imitation_mask`` observation fields
    hidden from the student (:mod:`policies.imitation`), then fine-tune with PPO (Lagrangian with
    ``lagrangian``) for ``timesteps`` steps (0: imitation only; else the clone is kept, :func:`_imitation_stage`). ``slow_budget``: ``"LO:HI"``, the action is
    the MPC's overshoot budget, the duty the MPC's (:mod:`policies.slow_budget`); ``slow_budget_every``:
    ``window`` (taken at the stop, held) or ``step``. Options used only with another (:data:`ONLY_WITH`) default to None
    (not given: :data:`ONLY_WITH_DEFAULTS`); one given without the other is a ``ValueError``, as in ``dronewpt train``.
    Deterministic for a given seed on one thread (torch and numba threads set to 1)."""
    import importlib.util

    o = _only_with_values({k: v for k, v in locals().items() if k in ONLY_WITH or k in ONLY_WITH.values()})
    env = env_overrides(env)   # (o: the ONLY_WITH options' values, read by name)
    extra = dict(history=history, action_filter=action_filter, smooth_penalty=smooth_penalty, imitate=imitate,
                 dagger=o["dagger"], imitation_episodes=o["imitation_episodes"], slow_budget=slow_budget,
                 slow_budget_every=o["slow_budget_every"])
    _check_args(algo, timesteps, n_envs, vec, lagrangian, residual, scenario, extra)
    opts = dict(**extra, seed=seed, n_envs=n_envs, scenario=scenario, hyperparams=hyperparams,
                hyperparams_file=hyperparams_file, env=env, cost=cost, lagrangian=lagrangian, budget=budget,
                lambda_lr=o["lambda_lr"], residual=residual, residual_scale=o["residual_scale"],
                residual_base_budget=o["residual_base_budget"], vec=vec, name=name, eval_episodes=eval_episodes,
                eval_every=eval_every, checkpoint_every=checkpoint_every, probe_episodes=o["probe_episodes"])
    spec = _spec(algo, timesteps, opts)
    _one_thread_each()
    out = Path(out_dir)
    _refuse_earlier_run(out, spec["name"], resume)
    out.mkdir(parents=True, exist_ok=True)
    kept = _keep_curves(out) if resume is not None else []
    if importlib.util.find_spec("tensorboard") is not None:
        spec["tb"] = str(out / "tb")
    if resume is not None and (out / "lagrange.json").is_file():
        spec["lambda0"] = float(json.loads((out / "lagrange.json").read_text())["lambda"])
    if imitate:
        epochs, mask = o["imitation_epochs"], tuple(o["imitation_mask"])
        spec.update(imitation_epochs=int(epochs), imitation_mask=mask)
        res = _imitation_stage(spec, out, progress, epochs, mask)
        if not spec["timesteps"]:
            return res
        resume = res["model"]
    venv, eval_env, model, penalty = _build(spec, out, resume)
    start_log_std = float(model.policy.log_std.detach().mean()) if imitate else None   # PPO's start: the clone's
    from mission_sim.signals import Interrupted, interrupts_deferred, interrupts_requested
    with interrupts_requested(STOP_NOTICE) as requests:   # Ctrl-C / SIGTERM: stop at the next step, keep the model
        cbs, lag, ev = _callbacks(spec, out, eval_env, penalty, progress, requests)
        todo = spec["timesteps"] - (model.num_timesteps if resume is not None else 0)   # SB3 adds num_timesteps on resume
        model.learn(total_timesteps=max(todo, 1), callback=cbs, reset_num_timesteps=resume is None)
    stopped = requests[0] if requests else None   # interrupted: <name>_interrupted.zip + .json + _vecnormalize.pkl
    zip_path = out / (spec["name"] + ("_interrupted.zip" if stopped else ".zip"))
    norm_path = out / (spec["name"] + "_interrupted_vecnormalize.pkl" if stopped else "vecnormalize.pkl")
    late = None
    try:
        with interrupts_deferred():   # a signal during the saving is raised once all is saved, not half-way
            res = _save(spec, out, model, venv, lag, ev, zip_path, norm_path, stopped, imitate, start_log_std)
    except Interrupted as exc:
        late = exc.signum
    if stopped or late:
        raise _interrupted(spec, model.num_timesteps, zip_path, stopped, late)
    if kept:   # (the CLI prints each entry: where the resumed run's learning curve went)
        res["earlier_curves"] = ", ".join(str(k) for k in kept)
    return res


def _refuse_earlier_run(out: Path, name: str, resume) -> None:
    """A ``ValueError`` when ``out`` holds an earlier run of ``name`` and this is not a resume (a second run into the
    same folder replaced the first one's model and logs without a word); for a resume, its statistics file checked
    (``FileNotFoundError``) before the earlier run's curves are moved aside (a wrong ``resume`` moved them, then
    failed)."""
    if resume is not None:
        _checkpoint_pkl(Path(resume))
    held = None if resume is not None else earlier_run(out, name)
    if held:
        raise ValueError(f"out_dir={str(out)!r} holds an earlier training run ({held}), which this run would "
                         "replace; valid: a new folder, resume=<one of its models> to go on training it, or remove it")


def _interrupted(spec: dict, steps: int, zip_path: Path, stopped, late):
    """The ``Interrupted`` of a run stopped by a signal (``stopped``) or signalled while saving (``late``), with the
    note that names the saved model and how to go on."""
    from mission_sim.signals import Interrupted
    exc = Interrupted(stopped or late)
    done = (f"trained {steps:,} of {spec['timesteps']:,} steps" if stopped else
            f"trained all {steps:,} steps (the signal came while saving)")
    note = (f"{done}; the model is saved: '{zip_path}' with its metadata (compare --policies "
            f"{_policy_prefix(spec)}:{zip_path})")
    if stopped:
        note += (f"; to go on, the same command with --resume {zip_path} (it moves this run's learning-curve "
                 "files, monitor.monitor.csv, eval/eval_curve.json and eval/evaluations.npz, aside as *.prev-<UTC "
                 "time>.*)")
    exc.add_note(note)
    return exc


def _save(spec, out, model, venv, lag, ev, zip_path, norm_path, stopped, imitate, start_log_std) -> dict:
    """Save the model, its statistics, metadata, the best models' metadata and the learning curve; the paths."""
    from mission_sim.signals import Interrupted, signal_name
    model.save(str(zip_path))
    venv.save(str(norm_path))
    meta = _meta(spec, venv, lag, float(spec["config"].dt_s))
    meta.update(final_eval=ev.curve[-1] if ev.curve else None, final_training=_training_episodes(model))
    if stopped:
        meta["interrupted"] = {"signal": signal_name(Interrupted(stopped)), "timesteps": int(model.num_timesteps),
                               "of": int(spec["timesteps"])}
    if imitate:
        _imitation_meta(meta, out, start_log_std)
    meta_path = zip_path.with_suffix(".json")
    meta_path.write_text(json.dumps(meta, indent=2))
    # the best evaluated model is a whole model, not the interrupted one
    _write_best_meta(out / "eval", {k: v for k, v in meta.items() if k != "interrupted"}, ev)
    venv.close()
    mon = out / "monitor.monitor.csv"
    res = {"model": zip_path, "meta": meta_path, "vecnormalize": norm_path, "monitor": mon,
           **({"clone": out / f"{CLONE_NAME}.zip"} if imitate else {}), **_written_dirs({"eval_dir": out / "eval", "checkpoints": out / "checkpoints"})}
    if mon.is_file():
        res["learning_curve"] = plot_learning_curve(mon, out / "learning_curve.png",
                                                    f"{spec['algo'].upper()} on {spec['env_id']} ({spec['scenario']})",
                                                    ev.curve)
    return res
