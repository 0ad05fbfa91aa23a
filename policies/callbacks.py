"""stable-baselines3 callbacks of ``train``: a progress bar with return and cost, and an
``EvalCallback`` that also records the episode cost of its fixed evaluation windows."""

from __future__ import annotations

import json
from collections import deque
from pathlib import Path

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

__all__ = ["ProgressCallback", "CostEvalCallback", "StopOnRequest"]


class ProgressCallback(BaseCallback):
    """tqdm over environment steps; the postfix shows the mean return and cost of the last 100
    episodes (from ``VecMonitor``'s ``info["episode"]`` and the adapter's ``episode_cost``)."""

    def __init__(self, total: int, enabled: bool):
        super().__init__()
        self.total, self.enabled = int(total), bool(enabled)
        self.returns: deque = deque(maxlen=100)
        self.costs: deque = deque(maxlen=100)
        self.reached: deque = deque(maxlen=100)

    def _on_training_start(self):
        from tqdm import tqdm
        self.bar = tqdm(total=self.total, unit="step", desc="train", disable=not self.enabled,
                        initial=min(self.num_timesteps, self.total))

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            if "episode" in info:
                self.returns.append(info["episode"]["r"])
                self.costs.append(info.get("episode_cost", np.nan))
                self.reached.append(info.get("reached_short_mode", np.nan))
        self.bar.update(self.training_env.num_envs)
        if self.returns and self.n_calls % 50 == 0:
            self.bar.set_postfix(ret=f"{np.mean(self.returns):.1f}", cost=f"{np.mean(self.costs):.4f}",
                                 sm=f"{np.mean(self.reached):.2f}", refresh=False)
        return True

    def _on_training_end(self):
        self.bar.close()


class StopOnRequest(BaseCallback):
    """Ends ``learn`` at the next environment step once ``requests`` (the list
    :func:`mission_sim.signals.interrupts_requested` yields) holds a signal: SB3's own way to stop a run early
    (``_on_step`` returning False), so the model is whole (no gradient step cut half-way) and can be saved."""

    def __init__(self, requests: list):
        super().__init__()
        self.requests = requests

    def _on_step(self) -> bool:
        return not self.requests


class CostEvalCallback(EvalCallback):
    """``EvalCallback`` that also averages ``episode_cost`` / ``overshoot`` / ``reached_short_mode`` of
    the evaluation episodes, logs them (``eval/mean_cost`` ...) and writes the curve to
    ``<log_path>/eval_curve.json`` (timesteps, return mean/std, cost mean/std, overshoot, fraction in SM).

    With a cost ``budget`` (constrained runs) it also keeps the **best feasible model**: the
    evaluation with the highest mean return among those whose mean cost is within the budget and
    whose every window reached short mode is saved as ``best_feasible_model.zip`` next to
    ``best_model.zip``, with the training VecNormalize statistics of that moment
    (``best_feasible_vecnormalize.pkl``, and ``feasible["obs_norm"]`` for the metadata JSON)."""

    def __init__(self, *args, budget: float | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._ep: list[tuple[float, float, float]] = []
        self.curve: list[dict] = []
        self.budget = budget
        self.feasible: dict | None = None
        self.best: dict | None = None

    def _save_norm(self, pkl_name: str) -> dict | None:
        """The training VecNormalize of this moment saved as ``<best_model_save_path>/pkl_name``; its
        ``obs_norm`` metadata (None without normalisation)."""
        norm = self.model.get_vec_normalize_env()
        if norm is None:
            return None
        norm.save(str(Path(self.best_model_save_path) / pkl_name))
        from .obs_mask import obs_norm_meta
        return obs_norm_meta(norm)

    def _keep_if_feasible(self, point: dict) -> None:
        """Save the model when ``point`` (an eval_curve entry) is feasible and the best so far."""
        if self.budget is None or self.best_model_save_path is None:
            return
        if point["cost"] > self.budget or point["reached_short_mode"] < 1.0:
            return
        if self.feasible is not None and point["return_mean"] <= self.feasible["return_mean"]:
            return
        self.model.save(str(Path(self.best_model_save_path) / "best_feasible_model.zip"))
        self.feasible = {**point, "obs_norm": self._save_norm("best_feasible_vecnormalize.pkl")}

    def _keep_best_norm(self, point: dict) -> None:
        """``EvalCallback`` has just written ``best_model.zip`` (a new best mean return): keep the training
        VecNormalize statistics it was evaluated with (``best_vecnormalize.pkl``, ``best["obs_norm"]``),
        not the end of training's, which drift on (the policy's input scaling is part of the model)."""
        self.best = {**point, "obs_norm": self._save_norm("best_vecnormalize.pkl")}

    def _log_success_callback(self, locals_, globals_) -> None:
        super()._log_success_callback(locals_, globals_)
        if locals_["done"]:
            info = locals_["info"]
            self._ep.append((info.get("episode_cost", np.nan), info.get("overshoot", np.nan),
                             float(info.get("reached_short_mode", np.nan))))

    def _on_step(self) -> bool:
        self._ep = [] if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0 else self._ep
        best_before = self.best_mean_reward
        go_on = super()._on_step()
        if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0 and self._ep:
            c, o, s = (float(np.mean(x)) for x in zip(*self._ep))
            c_std = float(np.std([e[0] for e in self._ep]))
            self.logger.record("eval/mean_cost", c)
            self.logger.record("eval/mean_overshoot", o)
            self.logger.record("eval/reached_short_mode", s)
            self.curve.append({"timesteps": int(self.num_timesteps), "return_mean": float(self.last_mean_reward),
                               "return_std": float(np.std(self.evaluations_results[-1])), "cost": c, "cost_std": c_std,
                               "overshoot": o, "reached_short_mode": s})
            self._keep_if_feasible(self.curve[-1])
            if self.best_model_save_path is not None and self.best_mean_reward > best_before:
                self._keep_best_norm(self.curve[-1])
            if self.log_path is not None:
                Path(self.log_path).parent.mkdir(parents=True, exist_ok=True)
                (Path(self.log_path).parent / "eval_curve.json").write_text(json.dumps(self.curve, indent=1))
        return go_on
