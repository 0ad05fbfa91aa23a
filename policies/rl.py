"""Reinforcement-learning policies: a stable-baselines3 model file behind the Policy protocol.

A trained policy is two files side by side (written by ``dronewpt train``):

* ``<name>.zip`` - the SB3 model (PPO, SAC or DQN),
* ``<name>.json`` - metadata: algorithm, environment id, control period, scenario, seed,
  timesteps and the observation normalisation statistics of ``VecNormalize`` (mean, var, clip,
  epsilon) as plain JSON (no pickle).

The wrapper takes contract observations (already in [-1, 1]), applies the stored normalisation,
asks the model for its deterministic action (the actor exported to numpy by
:mod:`policies.inference` when the architecture allows, else ``model.predict``) and maps it to ``d_short`` exactly like the env:
``(a + 1) / 2`` for continuous models, ``{0: RM, 1: SM}`` for DQN.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from mission_sim.contract import CONTROL_PERIOD_RANGE, OBS_DIM, PolicyContext, action_to_duty
from mission_sim.validation import real_number

from .inference import export_actor, load_ppo_actor
from .shipped import default_model

__all__ = ["RLPolicy", "PRETRAINED", "PRETRAINED_LAGRANGIAN", "load_meta", "ALGOS"]

PRETRAINED = default_model("rl")   # unconstrained PPO, seeds _s0.._s4 shipped (policies.shipped: the one table)
PRETRAINED_LAGRANGIAN = default_model("ppo_lagrangian")   # seeds _s0.._s4 shipped
ALGOS = ("ppo", "sac", "td3", "dqn")



def load_meta(path) -> dict:
    """The metadata JSON next to a model zip (``model.zip`` -> ``model.json``)."""
    path = Path(path)
    meta_path = path.with_suffix(".json")
    if not path.is_file():
        raise FileNotFoundError(f"RL model {str(path)!r} not found (train one with `dronewpt train`)")
    if not meta_path.is_file():
        raise FileNotFoundError(f"RL model metadata {str(meta_path)!r} not found (written by `dronewpt train`; for an "
                                'SB3 model of your own, {"algo": "ppo", "control_period_s": 0.0001} in that file, with '
                                '"obs_norm" if it was trained under VecNormalize: docs/rl.md, "From Python")')
    try:   # a broken file named (it was json's "Expecting property name ..." alone, or a traceback)
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"RL model metadata {str(meta_path)!r} is not valid JSON ({exc}); valid: a JSON object "
                         'such as {"algo": "ppo", "control_period_s": 0.0001}') from None
    if not isinstance(meta, dict):
        raise ValueError(f"RL model metadata {str(meta_path)!r} holds a JSON {type(meta).__name__}; valid: a JSON "
                         'object such as {"algo": "ppo", "control_period_s": 0.0001}')
    if meta.get("algo") not in ALGOS:
        raise ValueError(f"algo={meta.get('algo')!r} in {meta_path} is invalid; valid values: {', '.join(ALGOS)}")
    dt = real_number(meta.get("control_period_s"))
    if dt is None or not CONTROL_PERIOD_RANGE.contains(dt):
        raise ValueError(f"control_period_s={meta.get('control_period_s')!r} in {meta_path} is invalid; valid range: "
                         f"{CONTROL_PERIOD_RANGE.text()} (the control period it was trained at, e.g. 0.0001)")
    return meta


#: what reading a model zip that is not one (or is cut short, or lacks SB3's members) raises
_UNREADABLE = (zipfile.BadZipFile, KeyError, EOFError, ValueError, RuntimeError)


def _unreadable(path, exc) -> ValueError:
    why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return ValueError(f"RL model {str(path)!r} is not a readable stable-baselines3 model zip ({why}); valid: a model "
                      "zip written by `dronewpt train` (or SB3's model.save)")


class RLPolicy:
    """A stable-baselines3 policy (``path``: model zip; default the shipped pre-trained PPO).

    ``fast`` (default) evaluates the deterministic actor exported to numpy
    (:mod:`policies.inference`) instead of ``model.predict``.
    """

    name = "rl"

    def __init__(self, ctx: PolicyContext = PolicyContext(), path=None, deterministic: bool = True, fast: bool = True,
                 residual: bool = False):
        self.ctx = ctx
        self.path = Path(PRETRAINED if path is None else path)
        self.meta = load_meta(self.path)
        if self.meta.get("residual") and not residual:
            raise ValueError(f"{self.path.name} is a residual model: run it as residual:{self.path} "
                             "(it corrects the model-based duty)")
        if self.meta.get("slow_budget") and not residual:
            raise ValueError(f"{self.path.name} is a slow-budget model: run it as slow_budget:{self.path} "
                             "(its action is the MPC's budget, not a duty)")
        dt = float(self.meta["control_period_s"])
        if abs(ctx.control_period_s - dt) > 1e-9 * dt:
            raise ValueError(f"control_period_s={ctx.control_period_s!r} is invalid for {self.path.name}; "
                             f"valid value: {dt!r} (the period it was trained at)")
        self._model = None
        self.deterministic = bool(deterministic)
        # the shipped PPO models load their actor from the state dict (no SB3, no optimiser); others load
        # the SB3 model (predict() costs 0.15-1 ms a call; the actor exported to numpy ~10 us, same
        # actions to float32 round-off (1 ulp); fast=False keeps predict(), bit-identical to SB3)
        try:
            fast_actor = load_ppo_actor(self.path, self.meta) if self.deterministic and fast else None
        except _UNREADABLE as exc:   # not a zip, cut short, no data / policy.pth: was a traceback (BadZipFile, ...)
            raise _unreadable(self.path, exc) from None
        if fast_actor is not None or not (self.deterministic and fast):
            self._actor = fast_actor
        else:
            model = self.model   # its load errors come out as they are (the property words them)
            try:
                self._actor = export_actor(model)
            except _UNREADABLE as exc:
                raise _unreadable(self.path, exc) from None
        self.discrete = bool(self.meta.get("discrete", self.meta["algo"] == "dqn"))
        norm = self.meta.get("obs_norm")
        if norm:
            self._mean = np.asarray(norm["mean"], dtype=np.float32)
            self._scale = (1.0 / np.sqrt(np.asarray(norm["var"], dtype=np.float64) + norm["epsilon"])).astype(np.float32)
            self._clip = float(norm["clip"])
            self._scale[np.asarray(norm.get("masked", ()), dtype=np.int64)] = 0.0   # hidden fields: exactly 0 in
            # (policies.obs_mask; models without the key, trained before it, are unchanged)
        else:
            self._mean = None
        # models trained on the 7-field contract (before t_since_stop_s) see the first obs_dim fields
        self.obs_dim = int(self.meta.get("obs_dim") or (self._actor.layers[0][0].shape[0] if fast_actor is not None
                                                        else self.model.observation_space.shape[0]))
        self.name = f"rl_{self.meta['algo']}" if path is not None else "rl"
        self.history = int(self.meta.get("history") or 1)   # frame stack (envs.history): the policy keeps its own
        self._hist = None
        self.action_filter = float(self.meta.get("action_filter") or 0.0)   # low-pass on the duty (policies.smoothing)

    @property
    def model(self):
        """The stable-baselines3 model (loaded on first use: ``predict``, or an actor not exportable)."""
        if self._model is None:
            import stable_baselines3 as sb3
            cls = getattr(sb3, self.meta["algo"].upper())
            try:
                self._model = cls.load(str(self.path), device="cpu")
            except _UNREADABLE as exc:
                raise _unreadable(self.path, exc) from None
            except (AttributeError, TypeError) as exc:   # another algorithm's zip: SB3's AttributeError traceback
                raise ValueError(f"RL model {str(self.path)!r} cannot be loaded as algo={self.meta['algo']!r} (what "
                                 f"{self.path.with_suffix('.json').name} says: {type(exc).__name__}: {exc}); valid: "
                                 f"the algorithm it was trained with, one of {', '.join(ALGOS)}") from None
        return self._model

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        if self.history > 1:
            from envs.history import ObsHistory
            self._hist = ObsHistory(self.history)

    def normalise(self, obs) -> np.ndarray:
        o = np.atleast_2d(np.asarray(obs, dtype=np.float32))[:, :self.obs_dim]
        if self._mean is None:
            return o
        return np.minimum(np.maximum((o - self._mean) * self._scale, -self._clip), self._clip)  # np.clip: slow at n=1

    def act(self, obs):
        raw = obs
        if np.shape(obs)[-1] > OBS_DIM + 1:   # one contract frame per row (+ the base duty: a residual's input)
            raise ValueError(f"policy {self.name!r}: observations of shape {np.shape(obs)} are invalid; valid: "
                             f"(n, {OBS_DIM}), one contract frame per row, or (n, {OBS_DIM + 1}) for a residual's "
                             "input (the frame and the base duty) (an env made with history=K stacks K frames; a "
                             "policy keeps its own history: make the env without it)")
        if self.history > 1:
            if self._hist is None:
                self.reset(len(np.atleast_2d(obs)))
            obs = self._hist.push(obs)
        o = self.normalise(obs)
        if self._actor is not None:
            a = self._actor.act(o)
        else:
            a, _ = self.model.predict(o, deterministic=self.deterministic)
        a = np.asarray(a).reshape(len(o), -1)[:, 0]
        if self.discrete:
            return a.astype(float)
        if self.action_filter:
            from .smoothing import filtered_duty
            return filtered_duty(raw, action_to_duty(a), self.action_filter)
        return action_to_duty(a)
