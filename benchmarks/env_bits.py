"""SHA-1 fingerprints of the vector env's outputs, to check that a change to the env step keeps every
number (run it on two trees and compare the lines).

Each case steps :class:`envs.vector.SbarChargingVectorEnv` (``reset(seed=123)``) with uniform random
actions (every 97th step the previous action is held), autoresets included, optionally a partial
``restart`` of every third window, and hashes every step's observation, reward, terminated, truncated and
every info array (keys sorted). Cases: (link model, scenario, N, steps, threads, restart step).

    PYTHONPATH=<tree> python benchmarks/env_bits.py [case index ...]
"""

from __future__ import annotations

import argparse
import hashlib

import numpy as np

CASES = [("envelope", "random", 64, 1500, 1, 700), ("envelope", "detuned", 64, 700, 1, None),
         ("envelope", "sense_delay", 64, 700, 1, None), ("modal", "random", 64, 700, 1, 300),
         ("envelope", "random", 4096, 700, 1, 400), ("envelope", "random", 4096, 400, 2, None),
         ("envelope", "windy", 4096, 350, 2, None), ("modal", "nominal", 4096, 320, 2, None),
         # (2026-11-27, the autoreset's compiled draws and one-Lm shortcuts: the default scenario on both threads)
         ("envelope", "nominal", 4096, 700, 2, 400), ("envelope", "nominal", 16384, 320, 2, 310),
         ("envelope", "random", 16384, 320, 2, None), ("envelope", "lm_drift", 2100, 320, 1, 200)]


def fingerprint(link, scenario, n, steps, threads, restart_at=None) -> str:
    """The first 16 hex digits of the SHA-1 of every step's outputs of one case."""
    from envs.core import EnvConfig
    from envs.vector import SbarChargingVectorEnv

    env = SbarChargingVectorEnv(n, scenario=scenario, config=EnvConfig(link_model=link), num_threads=threads)
    h = hashlib.sha1()
    env.reset(seed=123)
    rng = np.random.default_rng(7)
    a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
    for t in range(steps):
        if t % 97:
            a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        obs, r, term, trunc, info = env.step(a)
        for x in (obs, r, term, trunc):
            h.update(np.ascontiguousarray(x).tobytes())
        for key in sorted(info):
            h.update(key.encode())
            h.update(np.ascontiguousarray(info[key]).tobytes())
        if restart_at and t == restart_at:
            h.update(env.restart(np.arange(0, n, 3)).tobytes())
    return h.hexdigest()[:16]


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                epilog="cases: " + "; ".join(f"{i} {c}" for i, c in enumerate(CASES)))
    p.add_argument("case", nargs="*", type=int, metavar="CASE",
                   help=f"case index 0..{len(CASES) - 1} (default: every case)")
    args = p.parse_args(argv)
    bad = [i for i in args.case if not 0 <= i < len(CASES)]   # (not choices=: Python 3.11 checks an empty list too)
    if bad:
        p.error(f"case {bad[0]} is invalid; valid range: 0..{len(CASES) - 1}")
    for case in [CASES[i] for i in args.case] or CASES:
        print(*case, fingerprint(*case), flush=True)


if __name__ == "__main__":
    main()
