"""Training side of :mod:`policies.oracle_imitation`: the stop observations of training windows, the
oracle's sequences on them (the teacher), and an open-loop scorer of a model on many windows.

Kept apart from the policy module because it calls the oracle (:mod:`policies.oracle`, which makes
policies by name): the policy, which ``policies.make`` builds, imports none of it.
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import OBS_DIM, denormalise_obs

from .oracle_imitation import _CMD, _D, HISTORY, HORIZON, check_base, predict, stop_features

__all__ = ["collect_stop_observations", "oracle_targets", "SearchWindows"]


def collect_stop_observations(scenario, seed: int, episodes: int, config=None, base: str = "model_based"):
    """Run ``base`` in closed loop on windows ``seed .. seed + episodes - 1`` and return
    ``(frames (n, HISTORY, OBS_DIM) physical, stop step k0 (n,))``: the policy's history at its first
    observation with command 0 (the one that chooses the duty of step k0)."""
    from envs import SbarChargingVectorEnv
    check_base(base)

    from . import make
    venv = SbarChargingVectorEnv(num_envs=episodes, scenario=scenario, config=config)
    pol = make(base, venv.policy_context)
    pol.reset(episodes)
    obs, _ = venv.reset(seed=seed)
    hist = np.repeat(denormalise_obs(obs)[:, None, :], HISTORY, axis=1)
    frames = np.full((episodes, HISTORY, OBS_DIM), np.nan)
    k_seen = np.full(episodes, -1)
    for k in range(venv.config.n_steps):
        phys = denormalise_obs(obs)
        hist = np.concatenate([hist[:, 1:], phys[:, None, :]], axis=1)
        new = (phys[:, _CMD] <= 0.0) & (k_seen < 0)
        frames[new], k_seen[new] = hist[new], k
        d = np.asarray(pol.act(obs), dtype=float).reshape(episodes)
        obs, *_ = venv.step((2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32))
    k0 = np.asarray(venv._stop_k, dtype=int).copy()
    if not np.array_equal(k0, k_seen):
        raise RuntimeError(f"stop seen at {k_seen.tolist()} but scored from {k0.tolist()}")
    return frames, k0


def oracle_targets(scenario, seeds, deltas, config=None, progress: bool = False, base: str = "model_based") -> dict:
    """The oracle on windows ``seeds`` of ``scenario``: the floor ``f`` (from the duties of ``base``, one of
    :data:`policies.oracle_imitation.BASES`, before the stop) and the best sequences within budgets
    ``f + delta`` (fractions) for every ``delta``; ``{"floor" (n,), "overshoot" (n, D), "energy_j" (n, D),
    "feasible" (n, D), "duties" (n, D, T)}`` (cached on disk by :mod:`policies.oracle`). With ``base="mpc"``
    every start sequence is the MPC's (its own after the stop, and the floor's), so the duties before the
    stop, and the state at the stop, are the MPC's; ``model_based`` keeps the oracle's default starts (the
    budgeted paper's controller, whose duties before the stop are ``model_based``'s)."""
    from tqdm import tqdm

    from .oracle import DEFAULT_STARTS, oracle_floor, oracle_window
    starts = DEFAULT_STARTS if check_base(base) == "model_based" else (base,)
    seeds = [int(s) for s in seeds]
    out = {"floor": [], "overshoot": [], "energy_j": [], "feasible": [], "duties": []}
    for s in tqdm(seeds, desc=f"oracle {scenario}", disable=not progress):
        f = oracle_floor(scenario, s, config, base=base)
        res = [oracle_window(scenario, s, f.overshoot + float(dl), starts=starts, config=config, extra_starts=(f.duties,))
               for dl in deltas]
        out["floor"].append(f.overshoot)
        out["overshoot"].append([r.overshoot for r in res])
        out["energy_j"].append([r.energy_after_stop_j for r in res])
        out["feasible"].append([r.feasible for r in res])
        out["duties"].append([r.duties for r in res])
    return {k: np.asarray(v) for k, v in out.items()}


class SearchWindows:
    """Windows to score a model on open loop (fast, no policy loop): the stop features seen in ``obs_scenario`` and, on the plant
    of ``plant_scenario`` (the same windows without the sensing delay, or the scenario itself), the
    paper's controller's duties before the stop and a :class:`envs.rollout.DutyRollout` per window."""

    def __init__(self, obs_scenario, plant_scenario, seeds, config=None):
        from envs.rollout import DutyRollout

        from .oracle import policy_duties
        seeds = [int(s) for s in seeds]
        frames, self.k0 = collect_stop_observations(obs_scenario, seeds[0], len(seeds), config)
        if seeds != list(range(seeds[0], seeds[0] + len(seeds))):
            raise ValueError("search windows must be consecutive seeds")
        self.features = stop_features(frames)
        self.d_pre = frames[:, -1, _D]
        self.base = policy_duties("model_based", plant_scenario, seeds[0], config, episodes=len(seeds))
        self.rolls = [DutyRollout(plant_scenario, s, config) for s in seeds]

    def run(self, models):
        """Energy after the stop (W, m), overshoot (W, m), largest I_L from 14 ms after the stop (W, m) of
        each of the ``m`` models on every window (the paper's controller before the stop, the model's
        sequence after it: what :class:`OracleImitationPolicy` does in closed loop)."""
        W, m = len(self.rolls), len(models)
        e, ov, il = np.empty((W, m)), np.empty((W, m)), np.empty((W, m))
        for w, roll in enumerate(self.rolls):
            y = np.vstack([predict(model, self.features[w:w + 1]) for model in models])
            d = np.repeat(self.base[w][None, :], m, axis=0)
            k0, T = self.k0[w], d.shape[1]
            n = min(HORIZON, T - k0)
            d[:, k0:k0 + n] = np.clip(self.d_pre[w] + y[:, :n], 0.0, 1.0)
            d[:, k0 + n:] = 1.0
            r = roll.run(d)
            late = np.arange(T) >= min(k0 + int(round(14e-3 / roll.config.dt_s)), T - 1)
            e[w], ov[w], il[w] = r.energy_after_stop_j, r.overshoot, r.rect_current_a[:, late].max(axis=1)
        return e, ov, il
