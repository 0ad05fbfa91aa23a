"""Record a seeded run of the vector env on the exact-mode link, for comparing two trees' modal steps.

Runs ``SbarChargingVectorEnv(num_envs=N, scenario=S, config=EnvConfig(link_model="modal"))`` for ``--steps``
steps with uniform random actions (seeded; autoresets included; ``--threads`` numba threads) and saves every
step's observation, reward and info values (float64) to ``--out`` (.npz). Run it once per tree (``PYTHONPATH``
set to that tree) and compare with ``--compare A.npz B.npz``: the max abs difference of each quantity, the
I2 peak's relative to its largest value, and whether the two are bit-identical.

    python benchmarks/record_modal_run.py --n 64 --scenario nominal --steps 3000 --out /tmp/a.npz
    python benchmarks/record_modal_run.py --compare /tmp/a.npz /tmp/b.npz
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def record(n, scenario, steps, seed, threads):
    from envs import EnvConfig, SbarChargingVectorEnv
    from envs.layout import INFO
    env = SbarChargingVectorEnv(num_envs=n, scenario=scenario, num_threads=threads,
                                config=EnvConfig(link_model="modal"))
    obs0, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed + 1)
    keys = [k for k in INFO._fields]
    rec = {"obs": np.empty((steps, n, obs0.shape[1])), "reward": np.empty((steps, n))}
    rec.update({k: np.empty((steps, n)) for k in keys})
    for t in range(steps):
        obs, reward, _, _, info = env.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
        rec["obs"][t], rec["reward"][t] = obs, reward
        for k in keys:
            rec[k][t] = info[k]
    return rec


def compare(a_path, b_path):
    a, b = np.load(a_path), np.load(b_path)
    out = {"bit_identical": all(np.array_equal(a[k], b[k], equal_nan=True) for k in a.files)}
    for k in a.files:
        with np.errstate(invalid="ignore"):
            d = np.abs(a[k] - b[k])
        out[k] = float(np.nanmax(d)) if d.size else 0.0
    ref = float(np.nanmax(np.abs(a["i2_peak_a"])))
    out["i2_peak_rel_of_max"] = out["i2_peak_a"] / ref
    out["i2_peak_max_a"] = ref
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--scenario", default="nominal")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out")
    ap.add_argument("--compare", nargs=2)
    a = ap.parse_args(argv)
    if a.compare:
        print(json.dumps(compare(*a.compare), indent=1))
        return 0
    rec = record(a.n, a.scenario, a.steps, a.seed, a.threads)
    tmp = a.out + ".part.npz"
    np.savez(tmp, **rec)
    Path(tmp).replace(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
