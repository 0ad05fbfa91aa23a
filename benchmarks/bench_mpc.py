"""The MPC's cost per charging window, in-process, beside its peer ``model_based`` in the same run.

Each round rolls out ``model_based`` and ``mpc`` (and, with ``--baseline FILE``, an older
``policies/mpc.py`` loaded beside the current one, e.g. from ``git show REV:policies/mpc.py``) on the
same ``--episodes`` nominal windows in the batched vector env (``policies.compare.run_policy``, as
``dronewpt compare`` does). The MPC's cost per window is ``(t_mpc - t_model_based) / episodes``: the
env stepping and the rollout's bookkeeping, which every policy pays, are the peer's. Wall and CPU
(process) time, median over ``--rounds`` with the range; one warm-up round discarded; the load average
is printed with every figure. ``--baseline-threads N`` runs the baseline under N BLAS threads (the
default: as the library starts, i.e. OpenBLAS' all cores; the current MPC holds one,
:mod:`policies.threads`). The metrics of each MPC (mean overshoot, energy after the stop) are printed
so a faster MPC that is not the same MPC shows.

    python benchmarks/bench_mpc.py [--episodes 100] [--rounds 3] [--budget 0] [--baseline OLD_mpc.py]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _baseline_factory(path: Path, threads):
    """``make(ctx, budget)`` of the MPC class in ``path`` (loaded as ``policies._mpc_baseline``)."""
    spec = importlib.util.spec_from_file_location("policies._mpc_baseline", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)

    class Timed(mod.MPCPolicy):
        def act(self, obs):
            with _blas_threads(threads):
                return super().act(obs)

    return lambda ctx, budget: Timed(ctx, budget=budget)


def _blas_threads(n):
    if n is None:
        return contextlib.nullcontext()
    from threadpoolctl import threadpool_limits
    return threadpool_limits(int(n), user_api="blas")


def _run(name, make_pol, episodes, seed):
    """One rollout of a policy on the nominal windows: (wall s, cpu s, metrics)."""
    import policies
    from envs import EnvConfig
    from policies.compare import run_policy
    orig = policies.make
    if make_pol is not None:
        policies.make = lambda n, ctx: make_pol(ctx)
    try:
        t, c = time.perf_counter(), time.process_time()
        tr = run_policy(name, "nominal", episodes, seed, EnvConfig(link_model="envelope"))   # the figures quoted are eq. 4's
        return time.perf_counter() - t, time.process_time() - c, tr.metrics
    finally:
        policies.make = orig


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--budget", type=float, default=0.0)
    ap.add_argument("--baseline", type=Path, default=None, help="an older policies/mpc.py to time beside")
    ap.add_argument("--baseline-threads", type=int, default=None)
    a = ap.parse_args(argv)
    mpc = "mpc" if a.budget == 0 else f"mpc:{a.budget:g}"
    runs = [("model_based", None), (mpc, None)]
    if a.baseline is not None:
        base = _baseline_factory(a.baseline, a.baseline_threads)
        runs.append((f"{mpc} (baseline)", lambda ctx: base(ctx, a.budget)))
    res = {k: [] for k, _ in runs}
    for r in range(a.rounds + 1):
        for label, mk in runs:
            out = _run(label if mk is None else "mpc", mk, a.episodes, a.seed)
            if r:
                res[label].append(out)
    load = os.getloadavg()
    print(f"{a.episodes} nominal windows, {a.rounds} rounds (+1 warm-up), load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    peer_w = np.median([x[0] for x in res["model_based"]])
    peer_c = np.median([x[1] for x in res["model_based"]])
    for label, _ in runs:
        w = np.array([x[0] for x in res[label]])
        c = np.array([x[1] for x in res[label]])
        m = res[label][-1][2]
        line = (f"{label:<22} wall {np.median(w):7.3f} s [{w.min():.3f}, {w.max():.3f}]  cpu {np.median(c):7.3f} s "
                f"[{c.min():.3f}, {c.max():.3f}]")
        if label != "model_based":
            pw = 1e3 * (w - peer_w) / a.episodes
            pc = 1e3 * (c - peer_c) / a.episodes
            line += (f"  per window: wall {np.median(pw):.1f} ms [{pw.min():.1f}, {pw.max():.1f}], cpu {np.median(pc):.1f} ms"
                     f" [{pc.min():.1f}, {pc.max():.1f}]; overshoot {m['overshoot_pct'].mean():.3f} %, E after "
                     f"{m['energy_after_stop_j'].mean():.4f} J")
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
