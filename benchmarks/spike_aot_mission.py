"""Feasibility check (issue 22, not wired into the mission): the mission loop compiled ahead of time.

``dronewpt mission`` spends ~0.7-0.8 s of its critical path in numba's start-up (import, registries,
the cached kernels' load: docs/performance.md, third pass) before the 0.2-0.3 s simulation. A module
compiled ahead of time by ``numba.pycc`` needs no numba at run time (numpy only). The loop takes the
policy as a first-class function, which AOT cannot export, so this builds one entry per compiled policy
with the policy's kernel bound in: ``advance_model_based(...)`` = :func:`mission_sim.world.loop_kernel._advance`
called with :func:`policies.kernels.model_based_kernel` (the same sources, nothing written twice).

It then runs the default mission (model_based, charged run + baseline, ``frame=True``) with the AOT entry
and with numba's JIT in two fresh processes and checks that the summaries (except the wall-time keys)
and the time series are identical, and reports the build time, the import time of the built module in a
fresh interpreter (numba not imported) and the warm run times.

    python benchmarks/spike_aot_mission.py [--out DIR]   # DIR default: a temporary folder

Measured 2026-11-26 02:11-02:17 UTC, load 6-7 on 2 shared cores, twice: build 27 s / 36 s, 885 KB; summary
and time series bit for bit identical; import 0.7 / 1.1 ms (numba not imported); warm run CPU 0.16 s for
both (AOT 0.157-0.167, JIT 0.152-0.165 in the same run: the compiled code is the same).
What wiring it in would need is in docs/performance.md ("What would reach it").
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_BUILD = r'''
import sys, time
from numba import njit, types
from numba.pycc import CC
from mission_sim.world import loop_kernel as lk
from policies.kernels import model_based_kernel
adv, mb = njit(lk._advance), model_based_kernel

def advance_model_based(k_stop, s, c, smp, rows, noise, obs, params, pstate, lc, tab, lw):
    return adv(k_stop, s, c, smp, rows, noise, obs, mb, params, pstate, lc, tab, lw)

cc = CC("mission_aot")
cc.output_dir = sys.argv[1]
cc.export("advance_model_based", types.int64(*lk._ARGS, lk._F8, lk._F8, *lk._LINK))(advance_model_based)
t = time.perf_counter()
cc.compile()
print(time.perf_counter() - t)
'''

_RUN = r'''
import argparse, json, sys, time
import numpy as np
out, mode = sys.argv[1], sys.argv[2]
import mission_sim.world.loop_kernel as kern
if mode == "aot":
    sys.path.insert(0, out)
    import mission_aot
    def advance_for(compiled_policy):
        assert compiled_policy
        def adv(k_stop, s, c, smp, rows, noise, obs, fn, params, pstate, lc, tab, lw):
            return mission_aot.advance_model_based(k_stop, s, c, smp, rows, noise, obs, params, pstate, lc, tab, lw)
        return adv
    kern.advance_for = advance_for
from mission_sim.cli.mission import mission_config, make_policy
from mission_sim.world.runner import run_mission
cfg = mission_config(argparse.Namespace(config=None, set=None, plan=None, pads=None, force=False, drone=None))
times = []
for i in range(4):
    pol = make_policy("model_based", cfg)
    t = time.process_time()
    res = run_mission(cfg, pol, charge=True, progress=False, frame=True)
    times.append(time.process_time() - t)
ts = res.timeseries
np.save(f"{out}/ts_{mode}.npy", ts.drop(columns=["phase"]).to_numpy(dtype=float))
(ts["phase"].astype(str)).to_csv(f"{out}/phase_{mode}.csv", index=False)
s = {k: v for k, v in res.summary.items() if k not in ("wall_s", "realtime_factor")}
print(json.dumps({"summary": s, "warm_cpu_s": times[1:]}))
'''

_IMPORT = r'''
import sys, time
import numpy
sys.path.insert(0, sys.argv[1])
t = time.process_time()
import mission_aot
print(time.process_time() - t, "numba" in sys.modules)
'''


def _py(code: str, *args: str) -> str:
    env = {"PYTHONPATH": str(ROOT)}
    import os
    env = {**os.environ, **env}
    return subprocess.run([sys.executable, "-c", code, *args], env=env, cwd=ROOT, check=True, capture_output=True,
                          text=True).stdout.strip().splitlines()[-1]


def main(argv=None) -> None:
    import numpy as np
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    out = a.out or Path(tempfile.mkdtemp(prefix="dronewpt-aot-"))
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    build_s = float(_py(_BUILD, str(out)))
    so = next(out.glob("mission_aot*.so"))
    imp = _py(_IMPORT, str(out)).split()
    aot, jit = (json.loads(_py(_RUN, str(out), m)) for m in ("aot", "jit"))
    same_series = np.array_equal(np.load(out / "ts_aot.npy"), np.load(out / "ts_jit.npy"), equal_nan=True) and \
        (out / "phase_aot.csv").read_text() == (out / "phase_jit.csv").read_text()
    import os
    print(f"load {os.getloadavg()[0]:.2f}; build {build_s:.1f} s ({so.stat().st_size / 1e3:.0f} KB, total "
          f"{time.perf_counter() - t0:.0f} s with the runs)")
    print(f"import of the built module in a fresh interpreter: {float(imp[0]) * 1e3:.2f} ms (numba imported: {imp[1]})")
    print(f"summary identical: {aot['summary'] == jit['summary']}; time series identical: {same_series}")
    print(f"warm run CPU s: AOT {', '.join(f'{x:.3f}' for x in aot['warm_cpu_s'])}; "
          f"JIT {', '.join(f'{x:.3f}' for x in jit['warm_cpu_s'])}")


if __name__ == "__main__":
    main()
