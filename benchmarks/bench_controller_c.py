"""Time per control step of the exported C controller (``dronewpt export-controller``) on this host.

Compiles the generated ``dwpt_ctl_f32.c`` / ``dwpt_ctl_f64.c`` with ``cc -O2 -std=c99`` and a small
harness that runs ``dwpt_<p>_step`` over the paper's proposed I2ref step (RM -> SM) repeated to
``--steps`` steps (the state is reset every 2,720 steps), and the Python controller
(``InverseModelController.update1`` + ``duty_from_v2_clipped``, what ``ModelBasedPolicy`` does per
step for one receiver) on the same inputs. Median and range of ``--repeat`` runs, in-process
times (the C harness times itself with ``clock_gettime``); ``os.getloadavg()`` before and after.
This is an x86-64 host, not a DSP: the DSP budget is argued from the operation count
(``docs/controller.md``).

    python benchmarks/bench_controller_c.py [--steps 10000000] [--repeat 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from wpt_receiver import c_export, duty_from_v2_clipped

_HARNESS = """\
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "dwpt_ctl_%(p)s.h"
int main(int argc, char **argv)
{
    long n = atol(argv[1]), i;
    double acc = 0.0, i2rm = atof(argv[2]), i2sm = atof(argv[3]);
    dwpt_%(p)s_state st;
    struct timespec a, b;
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (i = 0; i < n; ++i) {
        long k = i %% 2720;
        if (k == 0) dwpt_%(p)s_reset(&dwpt_%(p)s_default_params, &st, (dwpt_%(p)s_real)i2rm);
        acc += (double)dwpt_%(p)s_step(&dwpt_%(p)s_default_params, &st, (dwpt_%(p)s_real)(k < 170 ? i2rm : i2sm),
                                        (dwpt_%(p)s_real)30.0);
    }
    clock_gettime(CLOCK_MONOTONIC, &b);
    printf("%%.6g %%.17g\\n", ((double)(b.tv_sec - a.tv_sec) * 1e9 + (double)(b.tv_nsec - a.tv_nsec)) / (double)n, acc);
    return 0;
}
"""


def _python_ns(spec, steps: int, i2rm: float, i2sm: float) -> float:
    ctl = spec.controller()
    refs = [i2rm if k < 170 else i2sm for k in range(2720)]
    t0 = time.perf_counter()
    n = 0
    while n < steps:
        ctl.reset(i2rm)
        for r in refs:
            duty_from_v2_clipped(ctl.update1(r), 30.0)
        n += len(refs)
    return (time.perf_counter() - t0) / n * 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=10_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    spec = c_export.controller_spec()
    from wpt_receiver import TABLE_I, steady_state
    i2rm, i2sm = float(steady_state(TABLE_I, TABLE_I.v2_rm_amp_v)[1]), float(steady_state(TABLE_I, 0.0)[1])
    load0 = os.getloadavg()
    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        c_export.write_export(tmp, spec, vectors=c_export.test_vectors(spec, t_end_s=3e-3))
        for p in ("f32", "f64"):
            src = Path(tmp) / f"bench_{p}.c"
            src.write_text(_HARNESS % {"p": p})
            exe = Path(tmp) / f"bench_{p}"
            subprocess.run(["cc", "-O2", "-std=c99", "-o", str(exe), str(src), str(Path(tmp) / f"dwpt_ctl_{p}.c"), "-lm"],
                           check=True)
            res[f"c_{p}_ns"] = [float(subprocess.run([str(exe), str(args.steps), repr(i2rm), repr(i2sm)],
                                                     capture_output=True, text=True, check=True).stdout.split()[0])
                                for _ in range(args.repeat)]
    res["python_ns"] = [_python_ns(spec, min(args.steps, 200_000), i2rm, i2sm) for _ in range(args.repeat)]
    out = {k: {"median": statistics.median(v), "min": min(v), "max": max(v)} for k, v in res.items()}
    out["load"] = [load0, os.getloadavg()]
    out["control_period_ns"] = spec.control_period_s * 1e9
    if args.json:
        print(json.dumps(out))
        return
    for k, v in out.items():
        if isinstance(v, dict):
            print(f"{k:<12} median {v['median']:9.1f} ns per step (range {v['min']:.1f}-{v['max']:.1f})")
    print(f"control period {out['control_period_ns']:.0f} ns; load {load0} -> {os.getloadavg()}")


if __name__ == "__main__":
    np.seterr(all="raise")
    main()
