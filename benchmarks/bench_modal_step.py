"""Cost of one link step: the mission kernel's eq. 4 step against the exact-mode step (modal_kernel).

Each variant runs N steps in one compiled loop (in-process, per-step time in ns; compile excluded):

* ``eq4``: ``loop_kernel.link_step`` (eq. 4: what the mission kernel did every step before the exact
  modes, and the envs' link: the step with its energy integrals) with V2 from eq. 9; its ZOH coefficients
  from ``loop_kernel.link_disc`` (``wpt_receiver.envelope.zoh_discretise``, Python) once: since 2026-11-27 the
  2x2 ZOH is not compiled, so its cost per step is no longer in this figure;
* ``modal``: ``sbar_v2`` (table lookup, v2 with its quadrature) + ``step`` + ``inst_peak``, with
  the mode and ZOH coefficients cached (a fixed Lm and dt, as in most mission and env steps);
* ``modal_new_lm``: the same plus ``modes`` + ``zoh`` every step (Lm changing each step, as in the
  mission's fine windows over a moving pad).

    python benchmarks/bench_modal_step.py [--steps 1000000]
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
from numba import njit

from mission_sim.world import fastpath
from mission_sim.world import loop_kernel as lk
from wpt_receiver import TABLE_I
from wpt_receiver import modal_kernel as mk


@njit(cache=True)
def _eq4(c, dd, lm, dt, n):
    acc, a0, a1 = 0.0, 0.0, 0.0
    for k in range(n):
        d = 0.5 + 0.4 * math.sin(1e-3 * k)
        v2 = 4.0 / math.pi * 30.0 * (1.0 - math.sin(0.5 * math.pi * d))
        a0, a1, e_src, e_coil, e_rect, int_i2, p11, p22 = lk.link_step(c, dd, lm, dt, a0, a1, 38.2, v2)
        acc += e_src + abs(a1)
    return acc


@njit(cache=True)
def _modal(lc, mc, zc, tab, lm, dt, n, new_lm):
    z = np.zeros(4)
    out = np.empty(9)
    v1 = -38.2j
    v2 = 0j
    acc = 0.0
    for k in range(n):
        d = 0.5 + 0.4 * math.sin(1e-3 * k)
        if new_lm:
            mk.modes(lc, lm * (1.0 + 1e-9 * (k & 7)), mc)
            mk.zoh(mc, dt, zc)
        i2 = mk.phasors(mc, z, v1, v2)[1]
        v2 = mk.sbar_v2(lc, tab, d, i2, 30.0)[0]
        mk.step(lc, mc, zc, dt, z, v1, v2, out)
        acc += out[6] + mk.inst_peak(lc, tab, d, mk.phasors(mc, z, v1, v2)[1], 30.0)
    return acc


def run(steps: int = 1_000_000) -> dict:
    p, dt = TABLE_I, 1e-4
    c = fastpath.constants(fastpath.link_values(p.l1_h, p.l2_h, p.r1_ohm, p.r2_ohm, p.omega_rad_s))[0]
    lc = mk.link_constants(p)
    mc, zc = np.empty(mk.N_MODES_C, complex), np.empty(mk.N_ZOH_C, complex)
    mk.modes(lc, p.lm_h, mc)
    mk.zoh(mc, dt, zc)
    dd = lk.link_disc(c, p.lm_h, dt)
    tab = mk.modal_table(p)
    res = {"steps": steps, "load_avg_1min": os.getloadavg()[0]}
    runs = {"eq4": lambda n: _eq4(c, dd, p.lm_h, dt, n),
            "modal": lambda n: _modal(lc, mc, zc, tab, p.lm_h, dt, n, False),
            "modal_new_lm": lambda n: _modal(lc, mc, zc, tab, p.lm_h, dt, n, True)}
    for name, fn in runs.items():
        fn(10)                                   # compile / load from the cache
        best = math.inf
        for _ in range(3):
            t0 = time.perf_counter()
            fn(steps)
            best = min(best, time.perf_counter() - t0)
        res[f"{name}_ns_per_step"] = 1e9 * best / steps
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1_000_000)
    print(run(ap.parse_args().steps))


if __name__ == "__main__":
    main()
