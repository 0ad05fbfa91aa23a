"""Batch envelope stepping throughput (links x steps per second) against solve_ivp, same run.

Problem: N links with different Lm, RM steady state, V2 switched to 0 (the step transition),
stepped at the rectifier period for K steps. Baseline: scipy.integrate.solve_ivp (RK45,
rtol 1e-8) on the same N links stacked into one vectorised ODE (the strongest way to use it),
output on the same grid. Target ratio >= 100x at batch sizes of 1024 and up.

Accuracy: the exact ZOH is exact between steps (to rounding); solve_ivp at rtol 1e-8 is *less* accurate (its distance
from the ZOH is printed, ``max|diff|``), so the peer is not held to an over-tight tolerance: if anything the ratio
flatters solve_ivp. Each size gets a warm-up run (imports, first calls), then ``--repeat`` timed runs of both, peers
alternating; the medians and ranges of the rates and of the ratio, and the load average before and after, are printed.

    python benchmarks/bench_envelope.py [--links 1 64 1024 16384] [--steps 2000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import integrate

from wpt_receiver import TABLE_I, EnvelopeLink, state_matrices, steady_state


def run(links: int = 1024, steps: int = 2000, baseline_steps: int = 300):
    p = TABLE_I
    dt = p.rectifier_period_s
    lms = np.linspace(4e-6, 9e-6, links)

    link = EnvelopeLink(p, links)
    link.set_steady_state(p.v2_rm_amp_v, lm_h=lms)
    link.step(0.0, dt, lm_h=lms)  # sets the coupling; later steps keep it (lm_h=None)
    t0 = time.perf_counter()
    for _ in range(steps - 1):
        link.step(0.0, dt)
    fast = links * (steps - 1) / (time.perf_counter() - t0)

    lb = lms
    a, b = state_matrices(p, lb)
    u = np.array([p.v1_amp_v, 0.0])
    bu = b @ u
    x0 = np.stack(steady_state(p, p.v2_rm_amp_v, lb), axis=1)

    def rhs(t, y):
        x = y.reshape(-1, 2)
        return (np.einsum("nij,nj->ni", a, x) + bu).ravel()

    ks = min(steps, baseline_steps)
    t_eval = np.arange(1, ks + 1) * dt
    t0 = time.perf_counter()
    sol = integrate.solve_ivp(rhs, (0, ks * dt), x0.ravel(), t_eval=t_eval, rtol=1e-8, atol=1e-8)
    slow = links * ks / (time.perf_counter() - t0)
    link.set_steady_state(p.v2_rm_amp_v, lm_h=lms)
    for _ in range(ks):
        link.step(0.0, dt)
    err = np.max(np.abs(sol.y[:, -1].reshape(-1, 2) - link.x))
    return {"links": links, "steps": steps, "exact_zoh_link_steps_per_s": fast,
            "solve_ivp_link_steps_per_s": slow, "ratio": fast / slow, "max_abs_diff_a": float(err)}


def test_bench_envelope(benchmark):  # pytest-benchmark entry: pytest benchmarks/
    res = benchmark.pedantic(run, kwargs={"links": 256, "steps": 500}, rounds=1, iterations=1)
    print(res)


def repeated(links: int, steps: int, repeat: int) -> dict:
    """:func:`run` after a warm-up (a short run of the same size), ``repeat`` times: medians and ranges."""
    import statistics
    run(links, 10, 10)
    rs = [run(links, steps) for _ in range(repeat)]

    def med(key):
        xs = [r[key] for r in rs]
        return statistics.median(xs), min(xs), max(xs)
    return {"links": links, "fast": med("exact_zoh_link_steps_per_s"), "slow": med("solve_ivp_link_steps_per_s"),
            "ratio": med("ratio"), "max_abs_diff_a": max(r["max_abs_diff_a"] for r in rs), "n": repeat}


if __name__ == "__main__":
    import os
    ap = argparse.ArgumentParser()
    ap.add_argument("--links", type=int, nargs="+", default=[1, 64, 1024, 16384])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per size after one warm-up")
    a = ap.parse_args()
    if a.repeat < 1 or a.steps < 2 or min(a.links) < 1:
        ap.error(f"--repeat {a.repeat}, --steps {a.steps}, --links {a.links}: need repeat >= 1, steps >= 2, links >= 1")
    print(f"load average before {os.getloadavg()[0]:.2f} (1 min); medians (range) of {a.repeat} runs after a warm-up")
    print(f"{'links':>7} {'exact ZOH [link-steps/s]':>34} {'solve_ivp [link-steps/s]':>34} {'ratio':>18} {'max|diff| [A]':>14}")
    for n in a.links:
        r = repeated(n, a.steps, a.repeat)
        f, sl, q = r["fast"], r["slow"], r["ratio"]
        print(f"{n:>7} {f[0]:>10.3e} ({f[1]:.2e}-{f[2]:.2e}) {sl[0]:>10.3e} ({sl[1]:.2e}-{sl[2]:.2e}) "
              f"{q[0]:>6.0f}x ({q[1]:.0f}-{q[2]:.0f}x) {r['max_abs_diff_a']:>14.1e}")
    print(f"load average after {os.getloadavg()[0]:.2f} (1 min)")
