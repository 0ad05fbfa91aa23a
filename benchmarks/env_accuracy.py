"""Accuracy of a change to the vector env's step against another tree: whole episodes of
:class:`envs.vector.SbarChargingVectorEnv` (eq. 4's link, ``reset(seed=123)``, uniform random actions with every
97th step's action held, as :mod:`benchmarks.env_bits`), every step's outputs saved; then the largest difference of
each against the other tree's run, relative to the quantity's scale (its largest magnitude over the run), and the
count of discrete outcomes that differ (the short-mode check; the reward's sign of overcurrent).

    PYTHONPATH=<old tree> python benchmarks/env_accuracy.py dump old.npz
    PYTHONPATH=<new tree> python benchmarks/env_accuracy.py dump new.npz
    python benchmarks/env_accuracy.py compare old.npz new.npz

``splits --rev REV`` (run in the new tree) counts the windows whose split decision (the I2 envelope changes sign
within the step: the step re-done in rectifier-period sub-steps) differs between this tree's link step and
revision ``REV``'s on the same states (this tree's trajectory of the ``random`` case).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]   # (the tree under test is PYTHONPATH's, not this file's)

#: (scenario, N, steps): 2-3 whole episodes (301 steps) each, autoresets included
CASES = [("nominal", 256, 700), ("random", 256, 700), ("windy", 128, 400), ("detuned", 64, 400)]
KEYS = ("i2_a", "i2_peak_a", "i2_peak_envelope_a", "i1_a", "rect_current_a", "battery_v", "soc", "energy_j", "cost",
        "overshoot", "reached_short_mode")


def run(scenario, n, steps, hold_every=97):
    from envs.core import EnvConfig
    from envs.vector import SbarChargingVectorEnv

    env = SbarChargingVectorEnv(n, scenario=scenario, config=EnvConfig(link_model="envelope"), num_threads=1)
    env.reset(seed=123)
    rng = np.random.default_rng(7)
    a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
    out = {k: [] for k in KEYS + ("obs", "reward")}
    for t in range(steps):
        if t % hold_every:
            a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        obs, r, term, trunc, info = env.step(a)
        out["obs"].append(obs.copy())
        out["reward"].append(r.copy())
        for k in KEYS:
            out[k].append(np.asarray(info[k], dtype=float).copy())
    return {k: np.array(v) for k, v in out.items()}


def dump(path):
    arrays = {}
    for scenario, n, steps in CASES:
        for k, v in run(scenario, n, steps).items():
            arrays[f"{scenario}/{k}"] = v
    np.savez_compressed(path, **arrays)


def compare(old_path, new_path):
    old, new = np.load(old_path), np.load(new_path)
    for scenario, n, steps in CASES:
        print(f"{scenario} (N = {n}, {steps} steps):")
        for k in KEYS + ("obs", "reward"):
            a, b = old[f"{scenario}/{k}"].astype(float), new[f"{scenario}/{k}"].astype(float)
            if k == "reached_short_mode":
                print(f"  {k}: {int(np.sum(a != b))} of {a.size} window-steps differ")
                continue
            fin = np.isfinite(a)   # (the running overshoot starts at -inf)
            scale = np.max(np.abs(a[fin]))
            diff = np.where(a == b, 0.0, np.abs(a - b))
            rel = diff.max() / scale if scale else 0.0
            print(f"  {k}: max |delta| {diff.max():.3g} (scale {scale:.4g}: {rel:.2e}), median {np.median(diff):.3g}, "
                  f"bit-equal {np.mean(a == b):.1%}")
        a, b = old[f"{scenario}/cost"], new[f"{scenario}/cost"]
        print(f"  cost > 0 (overshoot rises): {int(np.sum((a > 0) != (b > 0)))} window-steps differ")


def splits(rev):
    from ab_env_kernel import load_revision
    from envs import vector_kernel as vk
    from envs.core import EnvConfig
    from envs.layout import STATE
    from envs.vector import SbarChargingVectorEnv

    old = load_revision(rev)
    for scenario, n, steps in CASES[:2]:
        env = SbarChargingVectorEnv(n, scenario=scenario, config=EnvConfig(link_model="envelope"), num_threads=1)
        env.reset(seed=123)
        rng = np.random.default_rng(7)
        kern, seen = env.parts.plant.kernel, []

        def record(*a):
            d, state, k, j, coef_tab, coef_ix = a[:6]
            par = a[13]
            from envs.layout import PAR
            slow_every = a[11]
            seen.append((d.copy(), state.copy(), (k // slow_every).copy(), coef_tab, coef_ix.copy(), par[PAR.vf],
                         par[PAR.dr]))
            return kern(*a)

        env.parts.plant.kernel = record
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        for t in range(steps):
            if t % 97:
                a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
            env.step(a)
        flips = total = nsplit = 0
        for d, state, j, coef_tab, coef_ix, vf, dr in seen:
            for e in range(n):
                args = (state[STATE.i1, e], state[STATE.i2, e], state[STATE.vl, e], d[e], coef_tab,
                        coef_ix[j[e], e], vf, dr)
                s_new = vk._link_step(*args)[5]
                s_old = old._link_step(*args)[5]
                flips += s_new != s_old
                nsplit += s_old
                total += 1
        print(f"{scenario}: split decisions differing: {flips} of {total} window-steps ({nsplit} split by {rev}'s)")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("dump").add_argument("out")
    c = sub.add_parser("compare")
    c.add_argument("old")
    c.add_argument("new")
    sub.add_parser("splits").add_argument("--rev", required=True)
    a = p.parse_args(argv)
    if a.cmd == "dump":
        dump(a.out)
    elif a.cmd == "compare":
        compare(a.old, a.new)
    else:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        splits(a.rev)


if __name__ == "__main__":
    main()
