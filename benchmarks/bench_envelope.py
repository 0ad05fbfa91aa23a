"""Batch envelope stepping throughput (links x steps per second) against solve_ivp, same run.

Problem: N links with different Lm, RM steady state, V2 switched to 0 (the step transition),
stepped at the rectifier period for K steps. Baseline: scipy.integrate.solve_ivp (RK45,
rtol 1e-8) on the same N links stacked into one vectorised ODE (the strongest way to use it),
output on the same grid. Target ratio >= 100x at batch sizes of 1024 and up.

    python benchmarks/bench_envelope.py [--links 1 64 1024 16384] [--steps 2000]
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


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--links", type=int, nargs="+", default=[1, 64, 1024, 16384])
    ap.add_argument("--steps", type=int, default=2000)
    a = ap.parse_args()
    print(f"{'links':>7} {'exact ZOH [link-steps/s]':>26} {'solve_ivp [link-steps/s]':>26} {'ratio':>7} {'max|diff| [A]':>14}")
    for n in a.links:
        r = run(n, a.steps)
        print(f"{n:>7} {r['exact_zoh_link_steps_per_s']:>26.3e} {r['solve_ivp_link_steps_per_s']:>26.3e} "
              f"{r['ratio']:>6.0f}x {r['max_abs_diff_a']:>14.1e}")
