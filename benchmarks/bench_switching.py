"""Switching-level model speed against ngspice and solve_ivp on the same circuit, in the same run.

Scenarios (ideal devices, Table I):

* ``step25``: the 25 ms step scenario (RM steady state, SM from 10 ms). The switching model runs
  ``link.simulate`` (periodic steady state + event-exact run). ngspice runs the repository's
  netlist generator (``tests/_spice.py``, the circuit of ``tests/spice/link_ideal.cir``) with the
  step at 10 ms and the end at 25 ms; ``solve_ivp`` (DOP853, rtol = atol = 1e-10) integrates eq. 1
  written out directly with the same events from the same initial state.
* ``netlist9``: the stored netlist ``tests/spice/link_ideal.cir`` itself (step at 3 ms, end 9 ms)
  against the switching model on the same schedule from the same initial state.

The switching model is timed with its compiled event loop (numba; compiled or loaded from the
disk cache in a warm-up run) and with the pure-Python reference loop. Times: median and range of
``--repeat`` runs for the switching model, one run each for ngspice (subprocess wall time, batch
mode, netlist parsing included) and solve_ivp. ``os.getloadavg()`` is printed before and after:
the machine is shared, only ratios of the same run count.

    python benchmarks/bench_switching.py [--repeat 7] [--no-ivp] [--no-spice] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import _spice  # noqa: E402  (the repository's netlist generator and ngspice runner)

from wpt_receiver import TABLE_I  # noqa: E402
from wpt_receiver.switching import SwitchingConfig, SwitchingLink, simulate_ivp  # noqa: E402


def step25_duty(link: SwitchingLink, t_end_s: float = 25e-3, t_switch_s: float = 10e-3):
    n = int(round(t_end_s / link.T))
    return (np.arange(n) * link.T >= t_switch_s - 1e-12).astype(float)


def _stats(xs):
    return {"median_s": statistics.median(xs), "min_s": min(xs), "max_s": max(xs), "n": len(xs)}


def _timed(fn, repeat):
    out, times = None, []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, _stats(times)


def _ngspice(text: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        _spice.run_ngspice(text, Path(tmp))
        return time.perf_counter() - t0


def _netlist(t_step_s: float, t_end_s: float) -> str:
    """The generator's netlist (:mod:`wpt_receiver.switching.netlist`) with another step/end time."""
    from wpt_receiver.switching.netlist import netlist
    return netlist(label="ideal, 25 ms step scenario", t_step_s=t_step_s, t_end_s=t_end_s)


def bench_step25(repeat: int, spice: bool, ivp: bool) -> dict:
    fast, ref = SwitchingLink(TABLE_I, compiled=True), SwitchingLink(TABLE_I, compiled=False)
    d = step25_duty(fast)
    fast.simulate(d)  # warm-up: numba compile or cache load
    res_f, t_fast = _timed(lambda: fast.simulate(d), repeat)
    res_r, t_ref = _timed(lambda: ref.simulate(d), max(1, repeat // 2))
    ts = res_f.sample_times()
    xf, _ = res_f.states(ts, cols=[2])
    xr, _ = res_r.states(ts, cols=[2])
    out = {"segments": len(res_f.seg_k), "compiled": t_fast, "reference_loop": t_ref,
           "compiled_vs_reference_max_i2_diff_a": float(np.max(np.abs(xf - xr))),
           "peak_i2_a": float(np.max(np.abs(xf)))}
    if spice:
        out["ngspice_s"] = _ngspice(_netlist(10e-3, 25e-3))
    if ivp:
        x0 = fast.periodic_steady_state(0.0)
        sch = fast.schedule(0.0, len(d) * fast.T, d)
        t0 = time.perf_counter()
        _, xi = simulate_ivp(TABLE_I, SwitchingConfig(), sch, x0, rtol=1e-10, atol=1e-10, t_eval=ts)
        out["solve_ivp_s"] = time.perf_counter() - t0
        out["solve_ivp_max_i2_diff_a"] = float(np.max(np.abs(xi[:, 2] - xf[:, 0])))
    return out


def bench_netlist9(repeat: int, spice: bool) -> dict:
    link = SwitchingLink(TABLE_I, compiled=True)
    x0 = np.zeros(link.cir.m)
    x0[:4] = _spice.initial_state(TABLE_I, link.cfg.devices)
    x0[-1] = 1.0
    _spice._run_step(link, x0)
    _, t_fast = _timed(lambda: _spice._run_step(link, x0), repeat)
    out = {"compiled": t_fast}
    if spice:
        out["ngspice_s"] = _ngspice(_spice.netlist_path("ideal").read_text())
    return out


def run(repeat: int = 7, spice: bool = True, ivp: bool = True) -> dict:
    spice = spice and shutil.which("ngspice") is not None
    load0 = os.getloadavg()
    out = {"load_before": load0, "step25": bench_step25(repeat, spice, ivp), "netlist9": bench_netlist9(repeat, spice)}
    out["load_after"] = os.getloadavg()
    return out


def _report(r: dict) -> None:
    s, n9 = r["step25"], r["netlist9"]
    f, ref = s["compiled"], s["reference_loop"]
    print(f"load average before {r['load_before'][0]:.2f}, after {r['load_after'][0]:.2f} (1 min)")
    print(f"25 ms step scenario, {s['segments']} exact segments, peak i2 {s['peak_i2_a']:.2f} A")
    print(f"  switching, compiled loop : {f['median_s'] * 1e3:8.2f} ms (range {f['min_s'] * 1e3:.2f}-{f['max_s'] * 1e3:.2f}, "
          f"n={f['n']})")
    print(f"  switching, Python loop   : {ref['median_s'] * 1e3:8.2f} ms (range {ref['min_s'] * 1e3:.2f}-"
          f"{ref['max_s'] * 1e3:.2f})  compiled {ref['median_s'] / f['median_s']:.1f}x faster; "
          f"max |i2 diff| {s['compiled_vs_reference_max_i2_diff_a']:.1e} A")
    if "ngspice_s" in s:
        print(f"  ngspice (same circuit)   : {s['ngspice_s'] * 1e3:8.0f} ms  -> switching model "
              f"{s['ngspice_s'] / f['median_s']:.0f}x faster (range {s['ngspice_s'] / f['max_s']:.0f}-"
              f"{s['ngspice_s'] / f['min_s']:.0f}x)")
    if "solve_ivp_s" in s:
        print(f"  solve_ivp DOP853 1e-10   : {s['solve_ivp_s'] * 1e3:8.0f} ms  -> switching model "
              f"{s['solve_ivp_s'] / f['median_s']:.0f}x faster; max |i2 diff| {s['solve_ivp_max_i2_diff_a']:.1e} A")
    g = n9["compiled"]
    print(f"stored netlist tests/spice/link_ideal.cir (9 ms): switching {g['median_s'] * 1e3:.2f} ms "
          f"(range {g['min_s'] * 1e3:.2f}-{g['max_s'] * 1e3:.2f})", end="")
    if "ngspice_s" in n9:
        print(f", ngspice {n9['ngspice_s'] * 1e3:.0f} ms -> {n9['ngspice_s'] / g['median_s']:.0f}x")
    else:
        print(" (ngspice not installed)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--no-ivp", action="store_true")
    ap.add_argument("--no-spice", action="store_true")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    r = run(a.repeat, not a.no_spice, not a.no_ivp)
    if a.json:
        print(json.dumps(r, indent=1))
    else:
        _report(r)


def test_bench_switching(benchmark):  # pytest-benchmark entry: pytest benchmarks/
    res = benchmark.pedantic(run, kwargs={"repeat": 1, "spice": False, "ivp": False}, rounds=1, iterations=1)
    print(res)


if __name__ == "__main__":
    main()
