"""Default mission: simulated time over wall time (goal >= 1000x), against single-rate stepping, same run.

For each policy the default mission (``dronewpt mission``: the charged run *and* the uncharged
baseline run that ``flight_time_gain_s`` needs) is run ``--repeat`` times after one warm-up (the
warm-up builds the coupling table once per process, ~0.1 s; reported separately as cold).

Baseline: the same runner forced to single-rate (every step at the control period: settle
tolerance 0, unlimited fine windows) on a short mission (1 s over one pad); its wall time per
simulated second of powered flight, times the default mission's length, is the single-rate
estimate (extrapolated, labelled so).

The issue-14 measure is sim/CPU (simulated time over this process's CPU time: less sensitive to a
shared machine than wall time), goal >= 3000x for model_based and >= 1000x for the shipped RL
policy (``rl``: the pre-trained PPO, actor evaluated in numpy). Medians and ranges over the
repeats; ``os.getloadavg()`` before and after.

Python-policy path, same run: each policy is also run with ``compiled=False`` (its Python ``act``
called whenever the compiled loop asks for a duty; since issue 22 the loop's physics exists only
compiled, so this is what RL and other Python policies get; ``rl``, which has no compiled policy
kernel, runs the same code on both), alternating with the default runs, and the ratio of the
median CPU times is printed (``py cpu/cpu``).

    python benchmarks/bench_mission.py [--policies model_based rl step ramp] [--repeat 3] [--no-single-rate]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config, policy_context
from mission_sim.world.runner import run_mission
from policies import make


def _policy(cfg, name):
    return make(name, policy_context(cfg))   # the mission's link (its pack's VL, the exact-mode model), as run_mission expects


def single_rate_wall_per_sim_s(name: str) -> float:
    d = apply_overrides(config_to_dict(load_config()), {
        "mission.start_x_m": -1.0, "mission.cruise_altitude_m": 1.0, "mission.land_x_m": 1.0,
        "pads.0.hover_time_s": 1.0, "sim.traj_dt_s": 0.05, "sim.settle_duty_tol": 1e-300, "sim.max_fine_s": 1e9})
    d["pads"] = d["pads"][:1]
    cfg = config_from_dict(d)
    res = run_mission(cfg, _policy(cfg, name))
    s = res.summary
    ts = res.timeseries
    fine_sim = float(ts["dt_s"][ts["fine"]].sum())
    # wall of the charged run only (the summary's wall includes the cheap uncharged baseline)
    return s["wall_s"] / max(fine_sim, 1e-9)


def _measure(cfg, name, repeat):
    """Default (the policy's kernel when it has one) and Python-policy (``compiled=False``) runs, alternating."""
    walls, cpus, ref_cpus = [], [], []
    run_mission(cfg, _policy(cfg, name), compiled=False)  # warm-up of the Python-policy path too
    for _ in range(repeat):
        pol = _policy(cfg, name)
        c0 = time.process_time()
        res = run_mission(cfg, pol)
        cpus.append(time.process_time() - c0)
        walls.append(res.summary["wall_s"])
        pol = _policy(cfg, name)
        c0 = time.process_time()
        run_mission(cfg, pol, compiled=False)
        ref_cpus.append(time.process_time() - c0)
    return res.summary, walls, cpus, ref_cpus


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policies", nargs="+", default=["model_based", "rl", "step", "ramp"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-single-rate", action="store_true", help="skip the single-rate baseline (slow)")
    args = ap.parse_args(argv)
    cfg = load_config()
    t0 = time.perf_counter()
    cold = run_mission(cfg, _policy(cfg, args.policies[0]))
    cold_wall = time.perf_counter() - t0
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) before")
    print(f"default mission: {cold.summary['sim_time_s']:.1f} s simulated, control period "
          f"{cfg.sim.control_period_s * 1e6:.0f} us; cold first run {cold_wall:.3f} s "
          f"({cold.summary['sim_time_s'] / cold_wall:.0f}x)")
    print(f"{'policy':<12} {'wall [s]':>9} {'sim/wall':>9} {'sim/cpu (range)':>22} {'py sim/cpu (range)':>22} "
          f"{'py cpu/cpu':>11} {'fine':>6} {'coarse':>7} {'single-rate est. [s]':>21} {'speed-up':>9} "
          f"{'balance err':>11}")
    for name in args.policies:
        s, walls, cpus, ref_cpus = _measure(cfg, name, args.repeat)
        w, cpu, sim = statistics.median(walls), statistics.median(cpus), s["sim_time_s"]
        ref = statistics.median(ref_cpus)
        rng = f"{sim / cpu:.0f}x ({sim / max(cpus):.0f}-{sim / min(cpus):.0f})"
        ref_rng = f"{sim / ref:.0f}x ({sim / max(ref_cpus):.0f}-{sim / min(ref_cpus):.0f})"
        single = float("nan") if args.no_single_rate else single_rate_wall_per_sim_s(name) * sim
        print(f"{name:<12} {w:>9.3f} {sim / w:>8.0f}x {rng:>22} {ref_rng:>22} {ref / cpu:>10.1f}x {s['fine_steps']:>6} "
              f"{s['coarse_steps']:>7} {single:>21.1f} {single / w:>8.0f}x {s['energy_balance_error_rel']:>11.1e}")
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) after")
    print("goals (issue 14): sim/cpu >= 3000x model_based, >= 1000x rl (wall includes the uncharged baseline run "
          "for flight_time_gain_s)")


if __name__ == "__main__":
    main()
