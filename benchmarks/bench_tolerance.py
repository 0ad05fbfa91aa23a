"""``dronewpt tolerance`` at scale: in-process against 2 local Dask workers, end to end, in the same run.

Each repeat runs the CLI twice in fresh subprocesses into fresh folders, alternating: ``--workers 0``
(in-process on the sweep engine's serial path) and ``--workers N`` (a local Dask cluster: its
start-up, the workers' warm-up - imports, the nominal duty sequences, numba's cache - the chunks,
the store and the summary included), after ``--warmup`` untimed rounds of 200 draws each way
(numba's and the OS's caches warm). Prints per mode the end-to-end wall time (median [min, max]),
the sweep's own time as the CLI reports it (``wall_s``: cases, store, cluster start for Dask; not
the imports), the Dask / in-process ratio of the medians and pairwise, the in-process time per
draw of the estimator alone, and the 1-minute load average before each run (the machine is
shared; the target is 10^4 draws in under 2 minutes on 2 cores).

    PYTHONPATH=$PWD python benchmarks/bench_tolerance.py [--draws 10000] [--workers 2] [--repeat 3] [--json]
    PYTHONPATH=$PWD python benchmarks/bench_tolerance.py --draws 2000 --repeat 1      # a quick look

``--accuracy SEED`` instead checks the estimator against the switching model (20 ms of RM settling,
then each controller's transition) on 40 draws of that seed stratified over the RM power fraction,
and prints the errors per power band (the table of docs/tolerance.md: seeds 5 and 7).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time


def _serial_per_draw(n: int = 500) -> float:
    from wpt_receiver import tolerance as tol
    ts = tol.TransitionSet.build()
    rows = tol.draw_scales(tol.Spreads(), n, 99)
    tol.draw_metrics(*tol.draw_link(rows[0]), ts)   # numba cache load
    t0 = time.perf_counter()
    for s in rows:
        tol.draw_metrics(*tol.draw_link(s), ts)
    return (time.perf_counter() - t0) / n


def _switching(p, c1, c2, duties) -> tuple[float, dict]:
    """RM |i2| fundamental and each controller's peak fundamental from the switching model."""
    import numpy as np

    from wpt_receiver import TABLE_I
    from wpt_receiver.detuning import _settled_rm
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    link = SwitchingLink(p, SwitchingConfig(c1_f=c1, c2_f=c2))
    x0, i2rm = _settled_rm(link, 20e-3)
    peaks = {}
    for pol, d in duties.items():
        env = link.simulate(d, TABLE_I.rectifier_period_s, x0=x0).envelope()
        t, f = env["t_s"].to_numpy(), env["i2_fund_a"].to_numpy()
        peaks[pol] = float(np.max(f[t >= 1e-3]))
    return i2rm, peaks


def _stratified(seed: int, n_bins: int, ts, nominal_w: float) -> list:
    """One conducting draw per power-fraction bin over (0, 1.05] (the bin's median draw of 3000)."""
    import numpy as np

    from wpt_receiver import tolerance as tol
    scales = tol.draw_scales(tol.Spreads(), 3000, seed)
    rows = [(s, tol.draw_metrics(*tol.draw_link(s), ts)) for s in scales]
    edges = np.linspace(0.0, 1.05, n_bins + 1)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        c = [(s, m) for s, m in rows if lo < m["rm_power_w"] / nominal_w <= hi and m["rm_i2_a"] >= tol.MIN_CONDUCTION_A]
        if c:
            out.append(c[len(c) // 2])
    return out


def accuracy(seed: int, n_bins: int = 40) -> None:
    """Estimator vs switching model per RM power band (module docstring)."""
    import numpy as np

    from wpt_receiver import TABLE_I
    from wpt_receiver import tolerance as tol
    from wpt_receiver.references import reference_duty
    ts = tol.TransitionSet.build()
    T = TABLE_I.rectifier_period_s
    duties = {pol: reference_duty(pol, TABLE_I, 1e-3, 11e-3, T)[1] for pol in ("step", "proposed")}
    nominal = tol.draw_metrics(*tol.draw_link([1.0] * len(tol.SCALES)), ts)["rm_power_w"]
    recs = []
    for s, m in _stratified(seed, n_bins, ts, nominal):
        i2, pk = _switching(*tol.draw_link(s), duties)
        recs.append((m["rm_power_w"] / nominal, m["clamp_margin"], 100 * (m["rm_i2_a"] / i2 - 1),
                     100 * (m["step_peak_a"] / pk["step"] - 1), 100 * (m["proposed_peak_a"] / pk["proposed"] - 1)))
    r = np.array(recs)
    for lo, hi in ((0.9, 9), (0.7, 0.9), (0.5, 0.7), (0.25, 0.5), (0.0, 0.25)):
        b = r[(r[:, 0] >= lo) & (r[:, 0] < hi)]
        if len(b):
            print(f"power {lo:.2f}-{min(hi, 1.05):.2f} x nominal: {len(b)} draws, clamp margin {b[:, 1].min():.2f}-"
                  f"{b[:, 1].max():.2f}; error RM |i2| {b[:, 2].min():+.0f}/{b[:, 2].max():+.0f} % (median |.| "
                  f"{np.median(np.abs(b[:, 2])):.0f} %), step peak {b[:, 3].min():+.1f}/{b[:, 3].max():+.1f} %, "
                  f"model-based peak {b[:, 4].min():+.1f}/{b[:, 4].max():+.1f} %")


def _run(draws: int, workers: int) -> dict:
    """One CLI run in a fresh folder: end-to-end wall [s], the CLI's own sweep wall [s], the load before."""
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "mission_sim.cli", "tolerance", "--draws", str(draws),
                            "--workers", str(workers), "--out", tmp, "--no-progress", "--format", "json"],
                           check=True, capture_output=True, text=True)
        wall = time.perf_counter() - t0
    s = json.loads(r.stdout)
    return {"wall_s": wall, "sweep_s": s["wall_s"], "n": s["n"], "load": load}


def _fmt(vals, nd=1):
    return f"{statistics.median(vals):.{nd}f} [{min(vals):.{nd}f}, {max(vals):.{nd}f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=10_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--warmup", type=int, default=1, help="untimed rounds of 200 draws each way (default 1)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--accuracy", type=int, default=None, metavar="SEED",
                    help="check the estimator against the switching model on 40 draws of SEED instead")
    args = ap.parse_args()
    if args.accuracy is not None:
        accuracy(args.accuracy)
        return
    for _ in range(args.warmup):
        _run(200, 0)
        _run(200, args.workers)
    inproc, dask = [], []
    for _ in range(args.repeat):
        inproc.append(_run(args.draws, 0))
        dask.append(_run(args.draws, args.workers))
    loads = [r["load"] for pair in zip(inproc, dask) for r in pair] + [os.getloadavg()[0]]
    out = {"draws": args.draws, "workers": args.workers, "in_process": inproc, "dask": dask,
           "serial_ms_per_draw": 1e3 * _serial_per_draw(), "loads": loads}
    if args.json:
        print(json.dumps(out))
        return
    wi, wd = [r["wall_s"] for r in inproc], [r["wall_s"] for r in dask]
    print(f"{args.draws} draws, end to end (fresh process, imports included), {args.repeat} repeats after "
          f"{args.warmup} warm-up round(s), all stored: {all(r['n'] == args.draws for r in inproc + dask)}")
    print(f"in-process (--workers 0)       {_fmt(wi)} s   (sweep part {_fmt([r['sweep_s'] for r in inproc])} s)")
    print(f"Dask (--workers {args.workers})              {_fmt(wd)} s   (sweep part, cluster start included "
          f"{_fmt([r['sweep_s'] for r in dask])} s)")
    print(f"in-process / Dask wall: {statistics.median(wi) / statistics.median(wd):.2f}x "
          f"(pairwise {_fmt([a / b for a, b in zip(wi, wd)], 2)}); the estimator alone in-process: "
          f"{out['serial_ms_per_draw']:.2f} ms per draw")
    print(f"load average (1 min) before each run and at the end: {_fmt(loads, 2)} "
          f"({', '.join(f'{x:.1f}' for x in loads)}; {os.cpu_count()} cores)")


if __name__ == "__main__":
    main()
