"""Accuracy and cost of the exact-mode env step with fewer V2 updates per control period (issue 23, "one peak
estimator everywhere": a cheaper estimator within 0.5 % of the exact-mode one).

The reference is :mod:`envs.modal_step`'s step as the envs run it (``EnvConfig(link_model="modal")``: 17
rectifier-period sub-steps, V2 implicit in the commutation at each). The variants drive the same kernel with K
sub-steps of equal length per 100 us, |I2| sampled once per rectifier period within them (``n_sub=K``,
``n_q=ceil(17/K)``): the link runs call ``envs.modal_step._link_step`` with them, the env runs use
:class:`SubstepConfig` (a study-only ``EnvConfig`` whose ``modal_n_sub`` / ``modal_n_q`` are K's). ``EnvConfig``'s
``v2_updates`` refuses 1..16 at 100 us since 2026-11-28 (V2 held while i2 turns; this study's findings).

* ``traj``: the paper's three trajectories (step, V2* ramp, proposed; Table I, fixed Lm, stiff 30 V, ideal
  devices, 100 us control period; as ``tests/test_env_modal.py`` runs them): instantaneous and fundamental
  peak, charge delivered (sum of I_L), each variant against the reference.
* ``converge``: two large transients (d = 0.32 dropped to RM, random duties) and the paper's trajectories:
  the largest instantaneous peak per V2 update count (2 ... 136 per 100 us) and scheme (the kernel's V2
  implicit at the sub-step's end current; the experiment :func:`_substeps_mid`, implicit at its midpoint
  current) against the switching model and the reference.
* ``env``: ``--windows`` windows of the vector env per scenario (nominal, detuned) under model_based, mpc and
  random actions: the policy runs on the reference env, its duties are replayed open loop on each variant
  (same seeds: same windows, commands, Lm), per window the energy delivered (sum of ``energy_j``), the largest
  instantaneous peak and the measured overshoot (``overshoot`` at the window's end) against the reference's.
* ``cost``: thread CPU time of the plant's compiled step (one thread, ``n_chunks = 1``) per env-step, the
  variants, the reference and eq. 4's envelope env stepped alternately in one process, held duty and random
  actions, median over the timed steps.
* ``finer``: the link part's CPU with 17, 34, 68, 136 V2 updates per 100 us (what converging the reference in
  large transients would cost; replay of captured steps, ``benchmarks/profile_modal_step.py``).

    python benchmarks/modal_substeps_study.py [traj] [converge] [env] [cost] [finer] [--k 1 2 4 8] [--windows 100] [--json out.json]

Every variant here is uniform (``v2_refine_levels=0``): the study of the kernel before its adaptive refinement
(``benchmarks/modal_refine_study.py`` studies that).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import EnvConfig, SbarChargingVectorEnv  # noqa: E402
from envs import modal_step as vk  # noqa: E402
from envs.layout import CZ_MODES, CZ_STEP, FAST, N_CZ  # noqa: E402
from wpt_receiver import TABLE_I  # noqa: E402
from wpt_receiver import modal_kernel as mk  # noqa: E402
from wpt_receiver.devices import IDEAL  # noqa: E402
from wpt_receiver.references import reference_duty  # noqa: E402

P = TABLE_I
ENV_DT = 17 * P.rectifier_period_s
TRAJECTORIES = (("step", "v2"), ("ramp", "v2"), ("ramp", "duty"), ("proposed", "v2"))


@dataclass(frozen=True, repr=False)
class SubstepConfig(EnvConfig):
    """STUDY ONLY: an ``EnvConfig`` whose modal step runs ``study_n_sub`` sub-steps per control period (0: the
    config's own), |I2| sampled once per rectifier period (``n_q = ceil(n_sub / study_n_sub)``), whatever
    ``v2_updates`` allows (it refuses fewer updates than rectifier periods)."""

    study_n_sub: int = 0

    @property
    def modal_n_sub(self) -> int:
        return self.study_n_sub or super().modal_n_sub

    @property
    def modal_n_q(self) -> int:
        return -(-self.n_sub // self.modal_n_sub)


def variants(ks, extra=()) -> dict:
    """``{label: SubstepConfig kwargs}``: the reference (``ref``) first, then ``K=k`` per sub-step count."""
    out = {"ref": dict(v2_refine_levels=0)}   # uniform sub-steps: the kernel before the refinement (modal_refine_study)
    for k in ks:
        out[f"K={k}"] = dict(study_n_sub=k, v2_refine_levels=0)
    for label, kw in extra:
        out[label] = kw
    return out


# ------------------------------------------------------------------------------------------ trajectories
def trajectory(name, kind, dt=ENV_DT):
    return reference_duty(name, P, 0.5e-3, 2.5e-3 if name == "step" else 6.5e-3, dt, ramp_kind=kind)[1]


def link_run(d_seq, n_sub, n_q, scheme="end", devices=IDEAL, hold_tol=1e-3):
    """The env's link step (``envs.modal_step._link_step``) over ``d_seq`` (one duty per 100 us) at Table I's
    Lm and a stiff 30 V battery from the steady state of the first duty, in ``n_sub`` sub-steps with ``n_q``
    peak samples each: per step ``(instantaneous peak, fundamental peak, I_L)`` [A] arrays. ``scheme``
    ``"end"``: the kernel's V2 (implicit in the sub-step's end current); ``"mid"``: the experiment
    :func:`_substeps_mid` (uncompiled driver on the compiled helpers)."""
    lc, tab = mk.link_constants(P, devices), mk.modal_table(P, devices)
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, ENV_DT, n_sub, n_q, cz, True, 0.05, 0)   # uniform: no refinement (modal_refine_study)
    mc, v1 = cz[CZ_MODES:CZ_STEP], -1j * P.v1_amp_v
    zc = np.zeros(mk.N_ZOH_C, dtype=complex)
    mk.zoh(mc, ENV_DT / n_sub / 2, zc)
    _MID["cf"] = np.zeros(len(FAST), dtype=complex)
    vk._fast_coefs(mc, zc, ENV_DT / n_sub / 2, _MID["cf"])
    z = np.zeros(4)
    v2 = mk.steady_state(lc, mc, tab, float(d_seq[0]), v1, P.vl_v, z)
    rows, e = [], -1.0
    step, orig = (vk._link_step, vk._substeps) if scheme == "end" else (vk._link_step.py_func, vk._substeps)
    if scheme == "mid":
        vk._substeps = _substeps_mid
    try:
        for d in d_seq:
            v2, e, _, _, pe, p, il, _, _ = step(z, v2, e, P.vl_v, d, lc, tab, cz, ENV_DT, n_sub, n_q, 0.0, 0.0,
                                                P.v1_amp_v, hold_tol, np.empty(9), np.zeros(4))
            rows.append((p, pe, il))
    finally:
        vk._substeps = orig
    return np.array(rows).T


_MID = {}


def _substeps_mid(z, v2, i2, k, vc, d, ws, lc, tab, mc, zs, cf, zq, h, n_sub, n_q, v1c, out, en, book, lm, block, cr=None):
    """EXPERIMENT (not shipped): ``envs.modal_step._substeps`` with V2 implicit in the sub-step's MIDPOINT
    current (``_v2_closed`` on the affine map of ``h/2``, ``_MID["cf"]``), held over the sub-step (an implicit
    midpoint rule for V2 instead of the kernel's implicit end point); falls back to the end point where the
    closed form has no root; no energy book."""
    cm = _MID["cf"]
    z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
    q1, a0, a1, bv = cf[FAST.q1], cf[FAST.a0], cf[FAST.a1], cf[FAST.b] * v1c
    e0, e1, k0, k1 = cf[FAST.e0], cf[FAST.e1], cf[FAST.k0] * v1c, cf[FAST.k1] * v1c
    l0, l1, c0, c1, p0, p1 = cf[FAST.l0], cf[FAST.l1], cf[FAST.c0], cf[FAST.c1], cf[FAST.p0] * v1c, cf[FAST.p1]
    ma0, ma1, mbv = cm[FAST.a0], cm[FAST.a1], cm[FAST.b] * v1c
    km = vk._solve_consts(cm[FAST.q1], ws, vc, k[4], k[5], k[6])
    pk, i2_pk, qsum, t = -1.0, 0j, 0.0, 0j
    sgn = -1.0 if i2.real < 0.0 else 1.0
    r_ref = abs(i2)
    for _ in range(n_sub):
        f, i2m, t, ok = vk._v2_closed(ma0 * z0 + ma1 * z1 + mbv, sgn, km, block)
        if not ok:
            f, i2m, t, ok = vk._v2_closed(a0 * z0 + a1 * z1 + bv, sgn, k, block)
        v2 = f * vc + ws * i2m
        i2e = a0 * z0 + a1 * z1 + bv + q1 * v2
        if n_q > 1:
            z[0], z[1], z[2], z[3] = z0.real, z0.imag, z1.real, z1.imag
            pk, i2_pk = vk._samples(mc, zq, z, v1c, v2, n_q, pk, i2_pk)
        qsum += mk.rect_current_a(f, c0 * z0 + c1 * z1 + p0 + p1 * v2, h)
        z0, z1 = e0 * z0 + k0 + l0 * v2, e1 * z1 + k1 + l1 * v2
        a = i2e.real ** 2 + i2e.imag ** 2
        if a > pk * abs(pk):
            pk, i2_pk = math.sqrt(a), i2e
        sgn = -1.0 if i2e.real < 0.0 else 1.0
        if a > 1.44 * r_ref * r_ref or 1.44 * a < r_ref * r_ref:   # as the kernel: the shift looked up again
            r_ref = math.sqrt(a)
            dl = mk.sbar_shift(lc, tab, d, i2e * sgn, vc)
            kw = complex(math.cos(dl), -math.sin(dl))
            k = (k[0], k[1], k[2], 4.0 / math.pi * k[1] * kw, kw, k[5], k[6], k[7])
            km = (km[0], km[1], km[2], 4.0 / math.pi * km[1] * kw, kw, km[5], km[6], km[7])
    z[0], z[1], z[2], z[3] = z0.real, z0.imag, z1.real, z1.imag
    return v2, t, pk, i2_pk, qsum


def traj_study(var: dict) -> dict:
    res = {}
    for name, kind in TRAJECTORIES:
        d = trajectory(name, kind)
        runs = {}
        for lab, kw in var.items():
            c = SubstepConfig(**kw)
            pk, pe, il = link_run(d, c.modal_n_sub, c.modal_n_q)
            runs[lab] = (pk.max(), pe.max(), il.sum())
        ref = runs["ref"]
        res[f"{name}/{kind}"] = {lab: dict(inst_a=r[0], fund_a=r[1], charge=r[2],
                                           inst_pct=100 * (r[0] / ref[0] - 1), fund_pct=100 * (r[1] / ref[1] - 1),
                                           charge_pct=100 * (r[2] / ref[2] - 1)) for lab, r in runs.items()}
    return res


# ------------------------------------------------------------------------------------------ convergence
def switching_peaks(d_seq):
    """The switching model's instantaneous |i2| peak per 100 us step (64 samples per half cycle)."""
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    env = SwitchingLink(P, SwitchingConfig(samples_per_half_cycle=64)).simulate(d_seq, ENV_DT).envelope()
    k = np.minimum((env["t_s"].to_numpy() / ENV_DT).astype(int), len(d_seq) - 1)
    pk = np.zeros(len(d_seq))
    np.maximum.at(pk, k, env["i2_env_a"].to_numpy())
    return pk


def transient_cases(pre=40) -> dict:
    """``{name: (duties per 100 us, first step compared)}``: two large transients (a window at d = 0.32
    dropped to RM; random duties redrawn every step), each after ``pre`` steps at its first duty (the switching
    model starts at rest), and the paper's trajectories."""
    rng = np.random.default_rng(1)
    out = {"drop 0.32->RM": (np.r_[np.full(pre, 0.32), np.zeros(150)], pre),
           "random duties": (np.r_[np.full(pre, 0.5), rng.uniform(0.0, 1.0, 150)], pre)}
    for name, kind in TRAJECTORIES:
        out[f"{name}/{kind}"] = (trajectory(name, kind), 0)
    return out


def converge_study(rows=(("end", 2), ("end", 4), ("end", 8), ("end", 17), ("end", 34), ("end", 68), ("end", 136),
                         ("mid", 2), ("mid", 4), ("mid", 8), ("mid", 17), ("mid", 34))) -> dict:
    """Largest instantaneous peak after the transient's start, against the switching model's and the
    reference's (end point, 17 sub-steps), and the charge (sum of I_L) against the reference's, per V2 update
    count and scheme; |I2| sampled once per rectifier period at least (``n_q``)."""
    res = {}
    for name, (d, p0) in transient_cases().items():
        sw = switching_peaks(d)[p0:]
        ref_pk, _, ref_il = link_run(d, 17, 1)
        ref_pk, ref_il = ref_pk[p0:], ref_il[p0:]
        row = {"switching_a": float(sw.max()), "ref_a": float(ref_pk.max())}
        for scheme, k in rows:
            pk, _, il = link_run(d, k, max(1, -(-17 // k)), scheme)
            pk, il = pk[p0:], il[p0:]
            row[f"{scheme} K={k}"] = dict(peak_a=float(pk.max()), vs_switching_pct=100 * (pk.max() / sw.max() - 1),
                                          vs_ref_pct=100 * (pk.max() / ref_pk.max() - 1),
                                          charge_vs_ref_pct=100 * (il.sum() / ref_il.sum() - 1))
        res[name] = row
        print(name, f"switching {sw.max():.3f} A, ref {ref_pk.max():.3f} A |",
              "  ".join(f"{lab}: {r['vs_switching_pct']:+.2f}%/{r['vs_ref_pct']:+.2f}%" for lab, r in row.items()
                        if isinstance(r, dict)), flush=True)
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
            acts, ref = _record(pol, sc, n, seed, SubstepConfig(link_model="modal", **var["ref"]))
            row = {}
            for lab, kw in var.items():
                if lab == "ref":
                    continue
                got = _replay(acts, sc, n, seed, SubstepConfig(link_model="modal", **kw))
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
            cfgs = {"eq4": EnvConfig(link_model="envelope"), **{lab: SubstepConfig(link_model="modal", **kw) for lab, kw in var.items()}}
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


def finer_cost(n=1024, ks=(17, 34, 68, 136), steps=10, reps=3) -> dict:
    """CPU [ns per env-step] of the link part alone (``benchmarks/profile_modal_step.py``'s replay of captured
    steps) with ``k`` V2 updates per 100 us (17: the env's default; ``v2_updates`` takes 17..1000), one
    sample per sub-step; every window rebuilds its segment (modes and ZOHs for ``k``) in each timed step, the
    same ~1.2 us for every ``k``."""
    import profile_modal_step as pm
    dt = EnvConfig().dt_s
    res = {}
    for actions in ("held", "random"):
        shots = pm.captured_steps(n, actions, "random", 60, steps, 0)
        row = {}
        for k in ks:
            sh = []
            for s in shots:
                c = pm._copy(s)
                c["n_sub"], c["par"] = k, c["par"].copy()
                c["par"][pm.MPAR.n_q] = 1
                c["j"] = c["j"] - 1   # every window enters "a new slow segment": _segment for k at its true Lm
                sh.append(c)
            pm._link(pm._copy(sh[0]))
            row[k] = pm._time(sh, pm._link, reps)
        res[actions] = dict(ns=row, vs_17={k: v / row[ks[0]] for k, v in row.items()}, load_avg_1min=os.getloadavg()[0],
                            dt_s=dt)
        print("finer", n, actions, json.dumps(res[actions]), flush=True)
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
    if "converge" in a.parts:
        out["converge"] = converge_study()
    if "env" in a.parts:
        out["env"] = env_study(var, a.windows, a.seed, tuple(a.policies))
    if "finer" in a.parts:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        out["finer"] = finer_cost()
    if "cost" in a.parts:
        out["cost"] = cost_study(var)
    out["load_avg_end"] = os.getloadavg()
    if a.json:
        tmp = Path(a.json).with_suffix(".tmp")
        tmp.write_text(json.dumps(out, indent=1))
        tmp.replace(a.json)


if __name__ == "__main__":
    main()
