"""Head-to-head comparison: every policy through the same closed loop on the same seeded episodes.

Each scenario runs ``episodes`` charging windows at once in the batched vector env (sub-env ``i``
seeded ``seed + i``, the same for every policy), the policy acting on the whole batch of contract
observations every control period. Metrics per episode (from the physical values in ``info``):

==================  =======================================================================
peak_i2_a           largest |I2| envelope sample (mid- and end-of-step) in the window [A] (a
                    negative envelope amplitude is a real coil current of that size)
overshoot_pct       (max |I2| after the stop command - |final I2|) / |final I2|, final = mean
                    of the last 10 steps (the SM steady state) [%]; NaN when |final I2| <
                    0.1 A (no steady current to overshoot)
time_above_rated_s  time with the step's peak |I2| above the rated value [s]
energy_j            energy delivered to the battery node, sum of VL I_L dt [J]
energy_after_stop_j the part of it delivered after the stop command (unwanted) [J]
tracking_rmse_a     RMS of (I_L - command) over the window [A]
cost                sum of the env's cost (relative excess over the rated I2)
return              sum of the env's reward
==================  =======================================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["METRICS", "EpisodeTraces", "run_policy", "compare", "DEFAULT_POLICIES", "DEFAULT_SCENARIOS",
           "plot_transitions"]

METRICS = ("peak_i2_a", "overshoot_pct", "time_above_rated_s", "energy_j", "energy_after_stop_j", "tracking_rmse_a",
           "cost", "return")
DEFAULT_POLICIES = ("step", "ramp", "hysteresis", "model_based", "model_based_online", "rl", "random")
DEFAULT_SCENARIOS = ("nominal", "lm_mismatch", "windy", "battery")
FINAL_I2_MIN_A = 0.1   # below this final |I2| the overshoot ratio is undefined (NaN)


@dataclass
class EpisodeTraces:
    """Time series (n_steps, episodes) of one policy on one scenario."""

    t_s: np.ndarray
    i2_peak_a: np.ndarray
    i2_a: np.ndarray
    d_short: np.ndarray
    rect_current_a: np.ndarray
    charge_cmd_a: np.ndarray
    t_stop_s: np.ndarray
    metrics: dict


def _spec(name: str):
    """'rl:path/to/model.zip' -> ('rl', {'path': ...}); other names unchanged."""
    if ":" in name:
        base, path = name.split(":", 1)
        return base, {"path": path}
    return name, {}


def run_policy(name: str, scenario: str, episodes: int, seed: int, config=None) -> EpisodeTraces:
    """Run policy ``name`` (a :func:`policies.make` name, or ``rl:PATH``) on ``episodes`` windows."""
    from envs import SbarChargingVectorEnv

    from . import make

    venv = SbarChargingVectorEnv(num_envs=episodes, scenario=scenario, config=config)
    base, kwargs = _spec(name)
    pol = make(base, venv.policy_context, **kwargs)
    pol.reset(episodes)
    obs, info = venv.reset(seed=seed)
    t_stop = info["t_stop_s"]
    T = venv.config.n_steps
    keys = ("i2_peak_a", "i2_a", "d_short", "rect_current_a", "charge_cmd_a", "cost", "energy_j")
    rec = {k: np.empty((T, episodes)) for k in keys}
    rew = np.empty((T, episodes))
    for k in range(T):
        d = np.asarray(pol.act(obs), dtype=float).reshape(episodes)
        obs, r, term, trunc, info = venv.step((2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32))
        rew[k] = r
        for key in keys:
            rec[key][k] = info[key]
    dt = venv.config.dt_s
    t = (np.arange(T) + 1) * dt
    after = t[:, None] >= t_stop[None, :]
    pk = np.abs(rec["i2_peak_a"])   # the env reports it by magnitude already; abs keeps this self-evident
    final = np.abs(rec["i2_a"][-10:].mean(axis=0))
    peak_after = np.where(after, pk, -np.inf).max(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        over = np.where(final >= FINAL_I2_MIN_A, 100.0 * (peak_after - final) / final, np.nan)
    m = {
        "peak_i2_a": pk.max(axis=0),
        "overshoot_pct": over,
        "time_above_rated_s": (pk > venv.config.rated_i2_a).sum(axis=0) * dt,
        "energy_j": rec["energy_j"].sum(axis=0),
        "energy_after_stop_j": np.where(after, rec["energy_j"], 0.0).sum(axis=0),
        "tracking_rmse_a": np.sqrt(np.mean((rec["rect_current_a"] - rec["charge_cmd_a"]) ** 2, axis=0)),
        "cost": rec["cost"].sum(axis=0),
        "return": rew.sum(axis=0),
    }
    venv.close()
    return EpisodeTraces(t, rec["i2_peak_a"], rec["i2_a"], rec["d_short"], rec["rect_current_a"],
                         rec["charge_cmd_a"], t_stop, m)


def compare(policies=DEFAULT_POLICIES, scenarios=DEFAULT_SCENARIOS, episodes: int = 20, seed: int = 1000,
            progress: bool = False, config=None):
    """Run every policy on every scenario (same seeds); returns ``(rows, traces)``: rows are dicts
    (policy, scenario, episodes, mean of each metric (overshoot_pct over the episodes where it is
    defined), and ``peak_i2_max_a``), traces maps (policy, scenario) -> :class:`EpisodeTraces`."""
    from tqdm import tqdm

    if int(episodes) != episodes or not 1 <= episodes <= 100_000:
        raise ValueError(f"episodes={episodes!r} is invalid; valid range: integer 1..100000")
    rows, traces = [], {}
    jobs = [(p, s) for s in scenarios for p in policies]
    for p, s in tqdm(jobs, desc="compare", unit="run", disable=not progress):
        tr = run_policy(p, s, int(episodes), int(seed), config)
        traces[(p, s)] = tr
        row = {"policy": p, "scenario": s, "episodes": int(episodes)}
        # nanmean: overshoot_pct is NaN for an episode without a steady final current
        row.update({k: float(np.nanmean(v)) if np.isfinite(v).any() else float("nan") for k, v in tr.metrics.items()})
        row["peak_i2_max_a"] = float(np.max(tr.metrics["peak_i2_a"]))
        rows.append(row)
    return rows, traces


def plot_transitions(traces: dict, scenario: str, out_png, episode: int = 0, window_s=(-2e-3, 12e-3),
                     rated_i2_a: float = 15.0):
    """Figure of representative RM -> SM transitions: step peak |I2| and d_short of every policy
    (but ``random``, whose duty noise rings the link and would hide the rest) on one episode of
    ``scenario``, time relative to the stop command."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    items = [(p, tr) for (p, s), tr in traces.items() if s == scenario and p != "random"]   # random: noise
    if not items:
        raise ValueError(f"scenario={scenario!r} has no traces; valid: {sorted({s for _, s in traces})}")
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1])
    for p, tr in items:
        t = (tr.t_s - tr.t_stop_s[episode]) * 1e3
        sel = (t >= window_s[0] * 1e3) & (t <= window_s[1] * 1e3)
        a1.plot(t[sel], tr.i2_peak_a[sel, episode], lw=1.2, label=p)
        a2.plot(t[sel], tr.d_short[sel, episode], lw=1.0, label=p)
    a1.axhline(rated_i2_a, color="r", lw=0.8, ls="--", label="rated")
    a1.axvline(0, color="k", lw=0.8, ls=":")
    a1.set_ylabel("|I2| envelope, step peak [A]")
    a1.set_title(f"RM -> SM at the stop command ({scenario}, episode {episode})")
    a1.grid(alpha=0.3)
    a1.legend(fontsize=8, ncol=2)
    a2.set_ylabel("d_short")
    a2.set_xlabel("time after the stop command [ms]")
    a2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return out_png
