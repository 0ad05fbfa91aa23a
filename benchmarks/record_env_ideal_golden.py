"""Record ``tests/data/env_ideal_golden.npz``: eq. 4's single env as it was before devices (commit ffada78), its
info values along whole windows with the duty held, for ``tests/test_env_devices.py``
(``devices="ideal"`` reproduces them).

Run on ffada78's tree (not this one: the env then had no devices; this script refuses a tree that has them)::

    git archive ffada78 | (mkdir -p /tmp/ffada78 && tar -x -C /tmp/ffada78)
    PYTHONPATH=/tmp/ffada78 python benchmarks/record_env_ideal_golden.py tests/data/env_ideal_golden.npz

Held duties (2026-11-28): from that day eq. 4's rectifier-period sub-steps take the clamp implicitly, and a
random duty every step (the golden file's runs until then) moves the trajectory through the rectifier's blocking
band, where the old explicit sub-steps were wrong by design (I2 chattered about 0; docs/performance.md, "Eighth
pass"). With the duty held the windows' I2 never changes sign, no step is re-done in sub-steps and the two models
are the same arithmetic: what the test compares is then only what it is about (ideal devices == no devices).
"""

from __future__ import annotations

import sys

import numpy as np

#: (scenario, seed, held action) per run: one duty in each half of [0, 1]
RUNS = (("random", 5, -0.3), ("battery", 8, 0.2))
KEYS = ("i1_a", "i2_a", "i2_peak_a", "v2_v", "rect_current_a", "battery_v", "battery_current_a", "soc", "energy_j")


def record():
    from envs import EnvConfig, SbarChargingEnv
    if "devices" in getattr(EnvConfig, "__dataclass_fields__", {}):
        raise SystemExit("this tree's env has devices: run on ffada78's tree (PYTHONPATH), see the docstring")
    out = {"keys": np.array(KEYS), "actions": np.array([a for _, _, a in RUNS])}
    for scn, seed, action in RUNS:
        env = SbarChargingEnv(scenario=scn)
        _, info = env.reset(seed=seed)
        rows = [[info[k] for k in KEYS]]
        for _ in range(env.config.n_steps):
            _, _, _, _, info = env.step(np.array([action], np.float32))
            rows.append([info[k] for k in KEYS])
        out[scn] = np.array(rows, dtype=float)
    return out


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: record_env_ideal_golden.py OUT.npz")
    np.savez(sys.argv[1], **record())
