"""In-process A/B of two versions of :mod:`envs.modal_step`: this tree's against another file (e.g. main's,
``git show main:envs/modal_step.py > /tmp/modal_step_main.py``), loaded as a second module of the ``envs``
package, their ``step_kernel`` alternated on the same captured steps of the modal vector env (one thread).

Per captured step, each kernel runs ``--reps`` times alternately on fresh copies of the step's inputs
(process CPU time); the least time of each is kept. Prints ns per env-step of both (sums of the least
times), the ratio B / A and its range over the captured steps, whether the two give the same outputs to the
bit, and the load average.

    python benchmarks/ab_modal_step.py /tmp/peer/modal_step.py [--peer-kernel /tmp/peer/modal_kernel.py] [--n 1024]
                                       [--actions held|random]

(the peer's ``modal_step.py`` next to copies of main's ``vector_kernel.py``, ``layout.py``, ``objective.py``:
its numba cache keys on them).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import profile_modal_step as pm  # noqa: E402
from envs import modal_step as ms_b  # noqa: E402
from envs.core import OBS_OFFSET, OBS_SCALE  # noqa: E402
from envs.layout import INFO  # noqa: E402


def _module(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def _load(path, kernel_path=None):
    """The other ``modal_step`` (as ``envs._modal_step_peer``), on the other ``modal_kernel`` when given (as
    ``wpt_receiver._modal_kernel_peer``, put in place of this tree's while the step module is imported)."""
    if kernel_path is None:
        return _module("envs._modal_step_peer", path)
    import wpt_receiver.modal_kernel as own
    peer_kernel = _module("wpt_receiver._modal_kernel_peer", kernel_path)
    sys.modules["wpt_receiver.modal_kernel"] = peer_kernel
    import wpt_receiver
    wpt_receiver.modal_kernel = peer_kernel
    try:
        return _module("envs._modal_step_peer", path)
    finally:
        sys.modules["wpt_receiver.modal_kernel"] = own
        wpt_receiver.modal_kernel = own


def _run(mod, s):
    n = len(s["d"])
    obs, reward = np.empty((n, 8), np.float32), np.empty(n)
    trunc, info = np.empty(n, bool), np.empty((n, len(INFO)))
    t0 = time.process_time()
    mod.step_kernel(s["d"], s["state"], s["mstate"], s["k"], s["j"], s["lc"], s["cz"], s["bat"], s["cmd"], s["noise"],
                    s["lm"], s["ep"], s["slow_every"], s["n_sub"], s["par"], OBS_SCALE, OBS_OFFSET, s["tab"], obs,
                    reward, trunc, info)
    dt = time.process_time() - t0
    return dt, (obs, reward, trunc, info, s["state"], s["mstate"])


def run(path, n=1024, actions="random", snaps=10, reps=9, warm=60, seed=0, scenario="random", kernel_path=None):
    mod_a = _load(path, kernel_path)
    shots = pm.captured_steps(n, actions, scenario, warm, snaps, seed)
    _run(mod_a, pm._copy(shots[0])), _run(ms_b, pm._copy(shots[0]))   # compile / cache load
    ta, tb, same = [], [], True
    for s in shots:
        ba = bb = np.inf
        for _ in range(reps):
            da, oa = _run(mod_a, pm._copy(s))
            db, ob = _run(ms_b, pm._copy(s))
            ba, bb = min(ba, da), min(bb, db)
        same &= all(np.array_equal(x, y, equal_nan=True) for x, y in zip(oa, ob))
        ta.append(ba)
        tb.append(bb)
    ta, tb = np.array(ta), np.array(tb)
    r = tb / ta
    k = 1e9 / n
    return {"n": n, "actions": actions, "scenario": scenario, "a_ns": k * ta.sum() / snaps, "b_ns": k * tb.sum() / snaps,
            "ratio_b_over_a": float(tb.sum() / ta.sum()), "ratio_min": float(r.min()), "ratio_max": float(r.max()),
            "bit_identical": bool(same), "load_avg_1min": os.getloadavg()[0]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("peer", help="the other modal_step.py (A); this tree's is B")
    ap.add_argument("--n", type=int, default=1024)
    ap.add_argument("--actions", choices=("held", "random"), default="random")
    ap.add_argument("--scenario", default="random")
    ap.add_argument("--snaps", type=int, default=10)
    ap.add_argument("--reps", type=int, default=9)
    ap.add_argument("--peer-kernel", help="the other wpt_receiver/modal_kernel.py for A (default: this tree's)")
    a = ap.parse_args(argv)
    print(json.dumps(run(a.peer, a.n, a.actions, a.snaps, a.reps, scenario=a.scenario, kernel_path=a.peer_kernel)))


if __name__ == "__main__":
    main()
