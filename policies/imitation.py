"""Imitation of a teacher on the batched env: behaviour cloning and DAgger into an SB3 policy network.

``dronewpt train --imitate TEACHER`` (issue 21). The student is the actor of a stable-baselines3
PPO ``MlpPolicy`` (so it loads and runs like every learned policy, :class:`policies.rl.RLPolicy`,
and can be fine-tuned with the Lagrangian PPO from there), fitted by supervised regression of the
Gaussian's mean on (observation history, teacher action):

* **behaviour cloning** (iteration 0): the teacher drives ``episodes`` seeded windows of the batched
  env (:class:`envs.vector.SbarChargingVectorEnv`); every step gives (the student's input, the
  teacher's action);
* **DAgger** (Ross, Gordon & Bagnell 2011; ``dagger`` iterations): the *student* drives fresh windows
  (with probability ``beta_i = 0.5^i`` per window the teacher), the teacher runs beside it in shadow
  on the same states (it reads the duty that was applied from the observation's ``last_d_short``, so
  its filters follow the real plant) and labels every state the student visits; the network is refit
  on the aggregate of all data;
* **residual student** (``residual_scale`` > 0): the student outputs a bounded correction of the
  budgeted model-based duty, as ``train --residual`` does (the base carries the timing of the
  RM -> SM manoeuvre to the period; the student learns where the teacher departs from it), run by
  :class:`policies.residual.ResidualPolicy`;
* **filtered student** (``action_filter`` alpha > 0): the student's duty passes the low-pass of
  :mod:`policies.smoothing` (at inference too); its label is the output the filter turns into the
  teacher's duty;
* **privileged teacher** (``privileged:NAME``; Chen et al. 2019, "Learning by cheating"): the teacher
  sees the current fields of the observation as they are *now* and without sensor noise (from the
  env's ``info``), the student the delayed, noisy observation of the scenario (``sense_delay``: the
  teacher gets the measurement the student cannot have, and the student has to learn to act without
  it, from its history of observations).

Any :func:`policies.make` name is a teacher (``mpc``, ``mpc:0.05``, ``model_based_budget:0.02``,
``model_based``). The oracle (:mod:`policies.oracle`) is open loop per window, so it could only be
cloned on its own trajectories; it is not a teacher here.

Inputs: the stacked observations (plus the base duty of a residual student), the previous duty
(``last_d_short``) masked by default (``masked``: cloning a smooth teacher with its last action
in view teaches ``d_k = d_{k-1}``, the copycat problem, and the student's loop dithers the duty).
Loss: mean squared error of the action in [-1, 1] (Adam, minibatches, ``epochs`` passes per fit).
Input normalisation: the running mean / variance of the collected inputs, stored like
``VecNormalize``'s (``obs_norm`` in the metadata JSON and ``vecnormalize.pkl``), so ``RLPolicy``,
``PPO.load`` + ``VecNormalize.load`` and ``train --resume`` (fine-tuning) all see the same numbers.
The masked fields are exactly 0 at the network's input, in cloning and in PPO fine-tuning (their
statistics frozen, ``obs_norm["masked"]``; :mod:`policies.obs_mask`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mission_sim.contract import OBS_INDEX, denormalise_obs, duty_to_action, normalise_obs

__all__ = ["ImitationSpec", "imitate", "privileged_obs", "collect", "fit_student", "student_actions"]

#: the observation's current fields a privileged teacher sees fresh and noise-free (info keys)
_PRIVILEGED = (("i2_amp_a", "i2_a"), ("battery_current_a", "battery_current_a"), ("rect_current_a", "rect_current_a"))


@dataclass(frozen=True)
class ImitationSpec:
    """What an imitation run is made of (see the module notes; times in control periods)."""

    teacher: str = "mpc"
    scenario: str = "nominal"
    history: int = 1
    dagger: int = 0
    episodes: int = 64
    epochs: int = 30
    batch_size: int = 1024
    learning_rate: float = 1e-3
    net_arch: tuple = (64, 64)
    seed: int = 0
    log_std_init: float = -2.5
    residual_scale: float = 0.0
    residual_base_budget: float = 0.0
    masked: tuple = ("last_d_short",)
    action_filter: float = 0.0

    def __post_init__(self):
        from mission_sim.contract import history_obs_dim
        history_obs_dim(self.history)
        bad = [f for f in self.masked if f not in OBS_INDEX]
        if bad:
            raise ValueError(f"masked field {bad[0]!r} is invalid; valid values: {', '.join(OBS_INDEX)}")
        for name, lo in (("dagger", 0), ("episodes", 1), ("epochs", 1), ("batch_size", 1)):
            v = getattr(self, name)
            if int(v) != v or v < lo:
                raise ValueError(f"{name}={v!r} is invalid; valid range: integer >= {lo}")
        if not (np.isfinite(self.residual_scale) and 0.0 <= self.residual_scale <= 1.0):
            raise ValueError(f"residual_scale={self.residual_scale!r} is invalid; valid range: [0, 1] (0: no residual)")
        if not (np.isfinite(self.action_filter) and 0.0 <= self.action_filter < 1.0) or \
                (self.action_filter and self.residual_scale):
            raise ValueError(f"action_filter={self.action_filter!r} is invalid; valid range: [0, 1), 0 with a residual")
        if not (np.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise ValueError(f"learning_rate={self.learning_rate!r} is invalid; valid range: (0, inf)")

    @property
    def privileged(self) -> bool:
        return self.teacher.startswith("privileged:")

    @property
    def teacher_name(self) -> str:
        return self.teacher.partition("privileged:")[2] if self.privileged else self.teacher


def privileged_obs(obs, info) -> np.ndarray:
    """``obs`` with its current fields replaced by the true present values of ``info`` (no delay, no noise)."""
    phys = denormalise_obs(obs)
    for field, key in _PRIVILEGED:
        phys[:, OBS_INDEX[field]] = np.abs(info[key]) if field == "i2_amp_a" else info[key]
    return normalise_obs(phys).astype(np.float32)


def student_actions(policy, x_norm) -> np.ndarray:
    """The deterministic action (the Gaussian's mean, unclipped) of an SB3 ``ActorCriticPolicy`` on
    normalised inputs (n, d), as a torch tensor with gradients."""
    import torch
    feats = policy.extract_features(torch.as_tensor(x_norm), policy.pi_features_extractor)
    return policy.action_net(policy.mlp_extractor.forward_actor(feats))


class _Norm:
    """Input normalisation of the student: ``VecNormalize``'s arithmetic on fixed statistics."""

    def __init__(self, mean, var, clip: float = 10.0, eps: float = 1e-8, masked=()):
        self.mean, self.var, self.clip, self.eps = np.asarray(mean), np.asarray(var), float(clip), float(eps)
        self.masked = np.asarray(masked, dtype=np.int64)   # columns held at exactly 0 (policies.obs_mask)

    def __call__(self, x) -> np.ndarray:
        out = np.clip((x - self.mean) / np.sqrt(self.var + self.eps), -self.clip, self.clip).astype(np.float32)
        out[..., self.masked] = 0.0
        return out


#: variance given to a masked input: its normalised value is ~0 whatever it is (dropped, in the same arithmetic)
_MASKED_VAR = 1e12


def _input_norm(X, spec: ImitationSpec) -> _Norm:
    """Mean / variance of the inputs; the ``masked`` fields of every frame are dropped (by default
    ``last_d_short`` (the "copycat" problem of cloning smooth actions with the previous action in the input: the
    student learns ``d_k = d_{k-1}`` and its closed loop dithers the duty next to the 4 kHz resonance)."""
    from .obs_mask import masked_indices

    mean, var = X.mean(axis=0), X.var(axis=0)
    idx = masked_indices(spec.masked, spec.history, X.shape[1])
    var[idx] = _MASKED_VAR   # also in the statistics, for loaders that ignore obs_norm["masked"]
    return _Norm(mean, var, masked=idx)


def collect(spec: ImitationSpec, seed: int, student=None, beta: float = 1.0, config=None):
    """One batch of ``spec.episodes`` windows (seeds ``seed + i``): the student's inputs (stacked
    observations, (T * n, K * OBS_DIM)) and the teacher's actions in [-1, 1]; ``student`` (a
    function of stacked observations -> duties) drives the windows not given to the teacher."""
    from envs import SbarChargingVectorEnv
    from envs.history import ObsHistory

    from . import make

    n = spec.episodes
    venv = SbarChargingVectorEnv(num_envs=n, scenario=spec.scenario, config=config)
    teacher = make(spec.teacher_name, venv.policy_context)
    teacher.reset(n)
    base = _Base(spec, venv.policy_context, n)
    obs, info = venv.reset(seed=seed)
    hist = ObsHistory(spec.history)
    x = hist.reset(base.row(obs))
    rng = np.random.default_rng(seed)
    by_teacher = np.ones(n, bool) if student is None else rng.random(n) < beta
    X, Y = [], []
    for _ in range(venv.config.n_steps):
        d_t = np.asarray(teacher.act(privileged_obs(obs, info) if spec.privileged else obs), dtype=float).reshape(n)
        X.append(x)
        Y.append(base.label(_unfiltered(obs, d_t, spec.action_filter)))
        d_s = None if student is None else _filtered(obs, base.duty(student(x)), spec.action_filter)
        d = d_t if student is None else np.where(by_teacher, d_t, d_s)
        obs, _, _, _, info = venv.step(duty_to_action(d)[:, None].astype(np.float32))
        x = hist.push(base.row(obs))
    venv.close()
    return np.concatenate(X), np.concatenate(Y).astype(np.float32)


def _unfiltered(obs, d_teacher, alpha: float):
    """The network output that the low-pass ``alpha`` (:mod:`policies.smoothing`) turns into ``d_teacher``."""
    if not alpha:
        return d_teacher
    from .smoothing import _last_duty
    return np.clip((d_teacher - alpha * _last_duty(obs)) / (1.0 - alpha), 0.0, 1.0)


def _filtered(obs, d, alpha: float):
    if not alpha:
        return d
    from .smoothing import filtered_duty
    return filtered_duty(obs, d, alpha)


class _Base:
    """The student's action space: the duty (``residual_scale`` 0), or a correction of the budgeted
    model-based duty (:class:`policies.constrained.ResidualVecEnv`'s: input = observation + base duty,
    action ``a`` -> ``clip(d_base + scale a, 0, 1)``, label = the teacher's correction, clipped to [-1, 1])."""

    def __init__(self, spec: ImitationSpec, ctx, n: int):
        self.scale = spec.residual_scale
        self.pol = None
        if self.scale:
            from .budgeted import BudgetedModelBasedPolicy
            self.pol = BudgetedModelBasedPolicy(ctx, budget=spec.residual_base_budget)
            self.pol.reset(n)
        self.d_base = None

    def row(self, obs):
        if self.pol is None:
            return obs
        from .constrained import residual_obs
        self.d_base = np.asarray(self.pol.act(obs), dtype=float).reshape(len(obs))
        return residual_obs(obs, self.d_base)

    def label(self, d_teacher):
        if self.pol is None:
            return duty_to_action(d_teacher)
        return np.clip((d_teacher - self.d_base) / self.scale, -1.0, 1.0)

    def duty(self, student_out):
        """The duty of the student's output (its own duty, or the residual's ``(a + 1) / 2`` mapped back)."""
        if self.pol is None:
            return student_out
        from .constrained import residual_duty
        return residual_duty(self.d_base, 2.0 * np.asarray(student_out) - 1.0, self.scale)


def fit_student(model, X, Y, norm: _Norm, spec: ImitationSpec, rng) -> float:
    """Fit the actor of ``model.policy`` to ``(X, Y)`` (MSE, Adam); returns the final training RMS error."""
    import torch

    pol = model.policy
    params = list(pol.mlp_extractor.policy_net.parameters()) + list(pol.action_net.parameters())
    opt = torch.optim.Adam(params, lr=spec.learning_rate)
    xn, y = torch.as_tensor(norm(X)), torch.as_tensor(Y[:, None])
    n = len(xn)
    for _ in range(spec.epochs):
        perm = torch.as_tensor(rng.permutation(n))
        for i in range(0, n, spec.batch_size):
            b = perm[i:i + spec.batch_size]
            loss = torch.mean((student_actions(pol, xn[b]) - y[b]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
    with torch.no_grad():
        return float(torch.sqrt(torch.mean((student_actions(pol, xn).clamp(-1, 1) - y) ** 2)))


def _student_fn(model, norm: _Norm):
    import torch

    def act(x):
        with torch.no_grad():
            a = student_actions(model.policy, norm(x)).numpy()[:, 0]
        return np.clip((a + 1.0) * 0.5, 0.0, 1.0)
    return act


def _new_model(spec: ImitationSpec, config=None, ppo_kwargs=None):
    """A PPO ``MlpPolicy`` on the stacked observation (the env stack ``train`` uses, for fine-tuning)."""
    import stable_baselines3 as sb3

    from envs.history import HistoryVecEnv

    from .obs_mask import MaskedVecNormalize
    from envs.sb3_vec import SbarSB3VecEnv

    venv = SbarSB3VecEnv(8, spec.scenario, config)   # 8 x n_steps 128 = one minibatch of 1024 when fine-tuned
    if spec.residual_scale:
        from .constrained import ResidualVecEnv
        venv = ResidualVecEnv(venv, spec.residual_scale, spec.residual_base_budget)
    venv = MaskedVecNormalize(HistoryVecEnv(venv, spec.history) if spec.history > 1 else venv, norm_obs=True,
                              norm_reward=True, clip_obs=10.0, gamma=0.98)   # the mask: set with the statistics
    kw = dict(net_arch=list(spec.net_arch), log_std_init=spec.log_std_init)
    return sb3.PPO("MlpPolicy", venv, seed=spec.seed, verbose=0, device="cpu", policy_kwargs=kw,
                   **(ppo_kwargs or {})), venv


def imitate(spec: ImitationSpec, out_dir, *, name: str = "ppo_sbar", config=None, progress: bool = True,
            base_meta: dict | None = None, ppo_kwargs: dict | None = None) -> dict:
    """BC (+ DAgger) of ``spec.teacher`` into a PPO actor; writes ``<name>.zip``, ``<name>.json``,
    ``vecnormalize.pkl`` and ``imitation.json`` (per-iteration data sizes and errors) into ``out_dir``."""
    import torch
    from tqdm.auto import tqdm

    torch.manual_seed(spec.seed)
    torch.set_num_threads(1)
    rng = np.random.default_rng(spec.seed)
    model, venv = _new_model(spec, config, ppo_kwargs)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed0 = 10_000 * (spec.seed + 1)   # training windows; evaluation in compare uses 1000..1099
    X, Y = collect(spec, seed0, config=config)
    norm = _input_norm(X, spec)
    log = []
    for it in tqdm(range(spec.dagger + 1), desc="imitation", disable=not progress):
        if it:
            Xi, Yi = collect(spec, seed0 + it * spec.episodes, _student_fn(model, norm), beta=0.5 ** it, config=config)
            X, Y = np.concatenate([X, Xi]), np.concatenate([Y, Yi])
        rms = fit_student(model, X, Y, norm, spec, rng)
        log.append({"iteration": it, "samples": int(len(X)), "train_rms_action": rms})
    venv.obs_rms.mean, venv.obs_rms.var = norm.mean.astype(np.float64), norm.var.astype(np.float64)
    venv.set_mask(norm.masked)   # fine-tuning keeps these columns at 0, their statistics frozen (policies.obs_mask)
    return _save(model, venv, spec, out, name, log, base_meta or {})


def _save(model, venv, spec: ImitationSpec, out: Path, name: str, log: list, base_meta: dict) -> dict:
    from dataclasses import asdict

    from .obs_mask import obs_norm_meta

    zip_path = out / f"{name}.zip"
    model.save(str(zip_path))
    venv.save(str(out / "vecnormalize.pkl"))
    meta = {"algo": "ppo", "discrete": False, "scenario": spec.scenario, "seed": spec.seed, "timesteps": 0,
            "control_period_s": float(venv.get_attr("config")[0].dt_s), "history": spec.history,
            "action_filter": spec.action_filter,
            "obs_dim": int(venv.observation_space.shape[0]),
            "policy_kwargs": {"net_arch": list(spec.net_arch), "log_std_init": spec.log_std_init},
            "obs_norm": obs_norm_meta(venv),
            **base_meta,
            "residual": {"scale": spec.residual_scale, "base_budget": spec.residual_base_budget,
                         "base": f"model_based_budget:{spec.residual_base_budget:g}"} if spec.residual_scale else None,
            "imitation": {**asdict(spec), "net_arch": list(spec.net_arch), "masked": list(spec.masked), "iterations": log}}
    meta_path = zip_path.with_suffix(".json")
    meta_path.write_text(json.dumps(meta, indent=2))
    (out / "imitation.json").write_text(json.dumps(log, indent=2))
    venv.close()
    return {"model": zip_path, "meta": meta_path, "vecnormalize": out / "vecnormalize.pkl"}
