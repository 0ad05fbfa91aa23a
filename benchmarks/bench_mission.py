"""Default mission: simulated time over wall time (goal >= 1000x), against single-rate stepping, same run.

For each policy the default mission (``dronewpt mission``: the charged run *and* the uncharged
baseline run that ``flight_time_gain_s`` needs) is run ``--repeat`` times after one warm-up (the
warm-up builds the coupling table once per process, ~0.1 s; reported separately as cold).

Baseline: the same runner forced to single-rate (every step at the control period: settle
tolerance 0, unlimited fine windows) on a short mission (1 s over one pad); its wall time per
simulated second of powered flight, times the default mission's length, is the single-rate
estimate (extrapolated, labelled so).

    python benchmarks/bench_mission.py [--policies model_based step ramp] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config
from mission_sim.contract import PolicyContext
from mission_sim.world.runner import run_mission
from policies import make


def _policy(cfg, name):
    return make(name, PolicyContext(control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a))


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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policies", nargs="+", default=["model_based", "step", "ramp"])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    cfg = load_config()
    t0 = time.perf_counter()
    cold = run_mission(cfg, _policy(cfg, args.policies[0]))
    cold_wall = time.perf_counter() - t0
    print(f"default mission: {cold.summary['sim_time_s']:.1f} s simulated, control period "
          f"{cfg.sim.control_period_s * 1e6:.0f} us; cold first run {cold_wall:.3f} s "
          f"({cold.summary['sim_time_s'] / cold_wall:.0f}x)")
    print(f"{'policy':<12} {'wall [s]':>9} {'sim/wall':>9} {'sim/cpu':>8} {'fine':>6} {'coarse':>7} {'windows':>7} "
          f"{'single-rate est. [s]':>21} {'speed-up':>9} {'balance err':>11}")
    for name in args.policies:
        walls, cpus = [], []
        for _ in range(args.repeat):
            c0 = time.process_time()
            res = run_mission(cfg, _policy(cfg, name))
            cpus.append(time.process_time() - c0)
            walls.append(res.summary["wall_s"])
        s = res.summary
        w = statistics.median(walls)
        cpu = statistics.median(cpus)
        single = single_rate_wall_per_sim_s(name) * s["sim_time_s"]
        print(f"{name:<12} {w:>9.3f} {s['sim_time_s'] / w:>8.0f}x {s['sim_time_s'] / cpu:>7.0f}x {s['fine_steps']:>6} {s['coarse_steps']:>7} "
              f"{s['fine_windows']:>7} {single:>21.1f} {single / w:>8.0f}x {s['energy_balance_error_rel']:>11.1e}")
    print("goal: sim/wall >= 1000x (wall includes the uncharged baseline run for flight_time_gain_s; "
          "sim/cpu = simulated time over this process's CPU time, less sensitive to a loaded machine)")


if __name__ == "__main__":
    main()
