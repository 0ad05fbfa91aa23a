"""Accuracy and cost of the exact-mode env step with fewer V2 updates per control period (issue 23, "one peak
estimator everywhere": a cheaper estimator within 0.5 % of the exact-mode one).

The reference is :mod:`envs.modal_step`'s step as the envs run it (``EnvConfig(link_model="modal")``: 17
rectifier-period sub-steps, V2 implicit in the commutation at each). The variants are ``EnvConfig`` fields
(``v2_updates=K``: K sub-steps of equal length, |I2| sampled once per rectifier period within them).

* ``traj``: the paper's three trajectories (step, V2* ramp, proposed; Table I, fixed Lm, stiff 30 V, ideal
  devices, 100 us control period; as ``tests/test_env_modal.py`` runs them): instantaneous and fundamental
  peak, charge delivered (sum of I_L), each variant against the reference.
* ``env``: ``--windows`` windows of the vector env per scenario (nominal, detuned) under model_based, mpc and
  random actions: the policy runs on the reference env, its duties are replayed open loop on each variant
  (same seeds: same windows, commands, Lm), per window the energy delivered (sum of ``energy_j``), the largest
  instantaneous peak and the measured overshoot (``overshoot`` at the window's end) against the reference's.
* ``cost``: thread CPU time of the plant's compiled step (one thread, ``n_chunks = 1``) per env-step, the
  variants, the reference and eq. 4's envelope env stepped alternately in one process, held duty and random
  actions, median over the timed steps.

    python benchmarks/modal_substeps_study.py [traj] [env] [cost] [--k 1 2 4 8] [--windows 100] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import EnvConfig, SbarChargingVectorEnv  # noqa: E402
from envs import modal_step as vk  # noqa: E402
from envs.layout import CZ_MODES, CZ_STEP, N_CZ  # noqa: E402
from wpt_receiver import TABLE_I  # noqa: E402
from wpt_receiver import modal_kernel as mk  # noqa: E402
from wpt_receiver.devices import IDEAL  # noqa: E402
from wpt_receiver.references import reference_duty  # noqa: E402

P = TABLE_I
ENV_DT = 17 * P.rectifier_period_s
TRAJECTORIES = (("step", "v2"), ("ramp", "v2"), ("ramp", "duty"), ("proposed", "v2"))


def variants(ks, extra=()) -> dict:
    """``{label: EnvConfig kwargs}``: the reference (``ref``) first, then ``K=k`` per sub-step count."""
    out = {"ref": {}}
    for k in ks:
        out[f"K={k}"] = dict(v2_updates=k)
    for label, kw in extra:
        out[label] = kw
    return out


# ------------------------------------------------------------------------------------------ trajectories
def trajectory(name, kind, dt=ENV_DT):
    return reference_duty(name, P, 0.5e-3, 2.5e-3 if name == "step" else 6.5e-3, dt, ramp_kind=kind)[1]


def link_run(d_seq, cfg: EnvConfig, devices=IDEAL):
    """The env's link step (``envs.modal_step._link_step``) over ``d_seq`` at Table I's Lm and a stiff 30 V
    battery from the steady state of the first duty, with ``cfg``'s sub-steps: ``(instantaneous peak,
    fundamental peak, sum of I_L)`` [A, A, A]."""
    lc, tab = mk.link_constants(P, devices), mk.modal_table(P, devices)
    n_sub, n_q, dt = cfg.modal_n_sub, cfg.modal_n_q, cfg.dt_s
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, dt, n_sub, n_q, cz, True)
    mc, v1 = cz[CZ_MODES:CZ_STEP], -1j * P.v1_amp_v
    z = np.zeros(4)
    v2 = mk.steady_state(lc, mc, tab, float(d_seq[0]), v1, P.vl_v, z)
    pk = pke = q = 0.0
    e = -1.0
    for d in d_seq:
        v2, e, _, _, pe, p, il, _, _ = vk._link_step(z, v2, e, P.vl_v, d, lc, tab, cz, dt, n_sub, n_q, 0.0, 0.0,
                                                    P.v1_amp_v, cfg.hold_tol_a, np.empty(9), np.zeros(4))
        pk, pke, q = max(pk, p), max(pke, pe), q + il
    return pk, pke, q


def traj_study(var: dict) -> dict:
    res = {}
    for name, kind in TRAJECTORIES:
        d = trajectory(name, kind)
        runs = {lab: link_run(d, EnvConfig(**kw)) for lab, kw in var.items()}
        ref = runs["ref"]
        res[f"{name}/{kind}"] = {lab: dict(inst_a=r[0], fund_a=r[1], charge=r[2],
                                           inst_pct=100 * (r[0] / ref[0] - 1), fund_pct=100 * (r[1] / ref[1] - 1),
                                           charge_pct=100 * (r[2] / ref[2] - 1)) for lab, r in runs.items()}
    return res


# ------------------------------------------------------------------------------------------ env windows
def _record(policy, scenario, n, seed, cfg):
    """The policy on ``n`` windows of the env with ``cfg``: its actions (T, n) and per-window metrics."""
    from policies import make
    venv = SbarChargingVectorEnv(num_envs=n, scenario=scenario, config=cfg, num_threads=1)
    pol = make(policy, venv.policy_context)
    pol.reset(n) if hasattr(pol, "reset") else None
    obs, _ = venv.reset(seed=[seed + i for i in range(n)])
    acts = []
    met = _Metrics(cfg.n_steps, n)
    for k in range(cfg.n_steps):
        d = np.asarray(pol.act(obs), dtype=float).reshape(n)
        a = (2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32)
        acts.append(a)
        obs, _, _, _, info = venv.step(a)
        met.add(k, info)
    venv.close()
    return np.array(acts), met.done()


def _replay(acts, scenario, n, seed, cfg):
    venv = SbarChargingVectorEnv(num_envs=n, scenario=scenario, config=cfg, num_threads=1)
    venv.reset(seed=[seed + i for i in range(n)])
    met = _Metrics(cfg.n_steps, n)
    for k, a in enumerate(acts):
        _, _, _, _, info = venv.step(a)
        met.add(k, info)
    venv.close()
    return met.done()


class _Metrics:
    """Per window: energy delivered [J] (sum of ``energy_j``), largest instantaneous peak [A], the measured
    overshoot at the window's end (``overshoot``: the running max of peak / short-mode I2 - 1 after the stop)."""

    def __init__(self, t, n):
        self.energy, self.peak, self.over = np.zeros(n), np.zeros(n), np.zeros(n)
        self.t = t

    def add(self, k, info):
        self.energy += info["energy_j"]
        self.peak = np.maximum(self.peak, info["i2_peak_a"])
        if k == self.t - 1:
            self.over = np.asarray(info["overshoot"], float).copy()

    def done(self):
        return dict(energy=self.energy, peak=self.peak, over=self.over)


def env_study(var: dict, n: int, seed: int, policies=("model_based", "mpc", "random"),
              scenarios=("nominal", "detuned")) -> dict:
    res = {}
    for sc in scenarios:
        for pol in policies:
            acts, ref = _record(pol, sc, n, seed, EnvConfig(link_model="modal", **var["ref"]))
            row = {}
            for lab, kw in var.items():
                if lab == "ref":
                    continue
                got = _replay(acts, sc, n, seed, EnvConfig(link_model="modal", **kw))
                de = 100 * (got["energy"] / ref["energy"] - 1)
                dp = 100 * (got["peak"] / ref["peak"] - 1)
                do = 100 * (got["over"] - ref["over"])   # percentage points of overshoot
                row[lab] = dict(energy_pct_max=float(np.abs(de).max()), energy_pct_mean=float(de.mean()),
                                peak_pct_max=float(np.abs(dp).max()), peak_pct_p99=float(np.percentile(np.abs(dp), 99)),
                                over_pts_max=float(np.abs(do).max()), over_pts_mean=float(do.mean()))
            row["ref"] = dict(energy_j_mean=float(ref["energy"].mean()), peak_a_mean=float(ref["peak"].mean()),
                              over_pct_mean=float(100 * ref["over"].mean()))
            res[f"{sc}/{pol}"] = row
            print(sc, pol, json.dumps(row), flush=True)
    return res


# ------------------------------------------------------------------------------------------ cost
def _timed(env, bucket):
    """Wrap ``env``'s plant step: the compiled step on the calling thread (``chunks = 1``), its thread CPU
    time [ns] appended to ``bucket``."""
    plant = env.parts.plant
    orig = plant.step

    def step(*a):
        a = list(a)
        a[-1] = 1
        t0 = time.thread_time_ns()
        orig(*a)
        bucket.append(time.thread_time_ns() - t0)
    plant.step = step


def cost_study(var: dict, ns=(1024, 4096), steps=40, warm=20, seed=0) -> dict:
    res = {}
    for n in ns:
        for actions in ("held", "random"):
            cfgs = {"eq4": EnvConfig(), **{lab: EnvConfig(link_model="modal", **kw) for lab, kw in var.items()}}
            envs, times = {}, {}
            for lab, cfg in cfgs.items():
                envs[lab] = SbarChargingVectorEnv(num_envs=n, scenario="random", config=cfg, num_threads=1)
                envs[lab].reset(seed=seed)
                times[lab] = []
            rng = np.random.default_rng(seed)
            load0 = os.getloadavg()[0]
            for k in range(warm + steps):
                a = (rng.uniform(-1, 1, (n, 1)) if actions == "random" else np.zeros((n, 1))).astype(np.float32)
                for lab, env in envs.items():   # alternating, the same actions
                    if k == warm:
                        _timed(env, times[lab])
                    env.step(a)
            load1 = os.getloadavg()[0]
            med = {lab: float(np.median(t)) / n for lab, t in times.items()}
            row = {lab: dict(ns=med[lab], vs_ref=med["ref"] / med[lab], vs_eq4=med[lab] / med["eq4"]) for lab in med}
            row["load_avg_1min"] = (load0, load1)
            res[f"N={n}/{actions}"] = row
            print(n, actions, json.dumps(row), flush=True)
            for env in envs.values():
                env.close()
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("parts", nargs="*", default=["traj", "env", "cost"])
    ap.add_argument("--k", type=int, nargs="+", default=[1, 2, 4, 8])
    ap.add_argument("--windows", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--policies", nargs="+", default=["model_based", "mpc", "random"])
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    var = variants(a.k)
    out = {"load_avg_start": os.getloadavg()}
    if "traj" in a.parts:
        out["traj"] = traj_study(var)
        for key, row in out["traj"].items():
            print(key, "  ".join(f"{lab}: inst {r['inst_pct']:+.3f}% fund {r['fund_pct']:+.3f}% "
                                 f"q {r['charge_pct']:+.3f}%" for lab, r in row.items() if lab != "ref"))
    if "env" in a.parts:
        out["env"] = env_study(var, a.windows, a.seed, tuple(a.policies))
    if "cost" in a.parts:
        out["cost"] = cost_study(var)
    out["load_avg_end"] = os.getloadavg()
    if a.json:
        tmp = Path(a.json).with_suffix(".tmp")
        tmp.write_text(json.dumps(out, indent=1))
        tmp.replace(a.json)


if __name__ == "__main__":
    main()
