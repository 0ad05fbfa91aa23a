"""The ``dronewpt`` command line: parse, call, print. Subcommands import what they need lazily."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["main"]


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def _positive_float(name):
    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not a number") from None
        if not v > 0 or v != v or v == float("inf"):
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: (0, inf)")
        return v
    return conv


# ----------------------------------------------------------------------------- paper
def _add_paper(sub):
    p = sub.add_parser("paper", help="reproduce the paper's Table II and Fig. 6",
                       description="Run the step, ramp and proposed V2* trajectories (RM -> SM) on the "
                                   "Table I link, print Table II beside the paper's, write Fig. 6 as PNG.")
    p.add_argument("--model", default="envelope", help="plant model: envelope (default) or switching")
    p.add_argument("--out", type=Path, default=Path("out/paper"), help="folder for the figures (default out/paper)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--control-period", type=_positive_float("control-period"), default=None,
                   help="controller update period in s (default: rectifier period 1/(2f))")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    p.set_defaults(func=_cmd_paper)


def _cmd_paper(args) -> int:
    from wpt_receiver import paper
    try:
        import wpt_receiver.switching  # noqa: F401  registers --model switching when available
    except ImportError:
        pass
    if args.model not in paper.MODELS:
        raise CliError(f"--model {args.model!r} is invalid; valid values: {', '.join(sorted(paper.MODELS))}")
    t_switch = 1e-3
    runs = paper.run_paper(model=args.model, t_switch_s=t_switch, control_period_s=args.control_period)
    figs = []
    if not args.no_plot:
        from . import figures
        args.out.mkdir(parents=True, exist_ok=True)
        figs.append(figures.plot_paper_fig6(runs, args.out / f"fig6_{args.model}.png", t_switch,
                                            f"RM -> SM transition, {args.model} model, Table I"))
        extra_plot = getattr(paper.MODELS[args.model], "plot_extra", None)
        if extra_plot is not None:
            figs.extend(extra_plot(runs, args.out))
    rows = []
    for r in runs:
        m = r.metrics
        row = {"trajectory": r.trajectory, "rm_current_a": m.rm_current_a, "final_current_a": m.final_current_a,
               "max_current_a": m.max_current_a, "overshoot_pct": m.overshoot_pct,
               "settling_time_s": m.settling_time_s, "peak_i1_a": m.peak_i1_a,
               "energy_to_battery_j": m.energy_to_battery_j}
        if args.model != "envelope":
            row["sim_wall_s"] = r.sim_wall_s
        rows.append(row)
    if args.format == "json":
        print(json.dumps({"model": args.model, "rows": rows, "figures": figs}))
        return 0
    print(f"Table II, {args.model} model (Table I parameters; RM steady state -> SM at t = 0)")
    print(f"{'trajectory':<10} {'paper max':>10} {'paper OS':>9} | {'RM':>7} {'final':>7} {'max':>7} {'OS':>8} {'settle':>8}")
    for r, row in zip(runs, rows):
        pm, po = paper.PAPER_TABLE_II[r.trajectory]
        print(f"{r.trajectory:<10} {pm:>8.1f} A {po:>7.1f} % | {row['rm_current_a']:>5.2f} A {row['final_current_a']:>5.2f} A "
              f"{row['max_current_a']:>5.2f} A {row['overshoot_pct']:>6.2f} % {row['settling_time_s'] * 1e3:>5.2f} ms")
    print("overshoot = (max - final) / final; the paper's final value is 10.5 A, ours is the closed-form SM current")
    for f in figs:
        print(f"figure: {f}")
    return 0


# ----------------------------------------------------------------------------- coupling
def _finite_float(name):
    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not a number") from None
        if v != v or abs(v) == float("inf"):
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: finite")
        return v
    return conv


def _add_coupling(sub):
    p = sub.add_parser("coupling", help="inductances of the default pad/drone coils at a pose",
                       description="L1, L2 and Lm(dx, dy, dz, tilt) of the default coils by Neumann integrals "
                                   "(pad frame, z up; dz = height of the drone coil above the pad coil).")
    p.add_argument("--dx", type=_finite_float("dx"), default=0.0, help="lateral offset x [m] (default 0)")
    p.add_argument("--dy", type=_finite_float("dy"), default=0.0, help="lateral offset y [m] (default 0)")
    p.add_argument("--dz", type=_finite_float("dz"), default=None, help="height above the pad coil [m] "
                   "(default: the nominal hover gap)")
    p.add_argument("--tilt-deg", type=_finite_float("tilt-deg"), default=0.0,
                   help="tilt of the drone coil about the y axis [deg] (default 0)")
    p.add_argument("--exact", action="store_true", help="direct Neumann integral instead of the lookup table")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--map", type=Path, default=None, metavar="PNG",
                   help="also write a PNG map of Lm over dx, dy at this dz and tilt")
    p.set_defaults(func=_cmd_coupling)


def _cmd_coupling(args) -> int:
    import math

    from wpt_receiver.coupling import NOMINAL_GAP_M, default_coupling
    m = default_coupling()
    dz = NOMINAL_GAP_M if args.dz is None else args.dz
    min_dz = m.tx.wire_radius_m + m.rx.wire_radius_m + max(m.rx.radius_m) * abs(math.sin(math.radians(args.tilt_deg)))
    if dz <= min_dz:
        raise CliError(f"--dz {dz!r} is invalid; valid range: > {min_dz:.4g} m (the coils would touch)")
    if abs(args.tilt_deg) >= 90:
        raise CliError(f"--tilt-deg {args.tilt_deg!r} is invalid; valid range: (-90, 90)")
    tilt = math.radians(args.tilt_deg)
    lm = float((m.lm_exact_h if args.exact else m.lm_h)(args.dx, args.dy, dz, tilt))
    tx, rx = m.turn_positions(args.dx, args.dy, dz, tilt)
    out = {"dx_m": args.dx, "dy_m": args.dy, "dz_m": dz, "tilt_rad": tilt, "lm_h": lm, "l1_h": m.l1_h,
           "l2_h": m.l2_h, "k": float(m.k(lm)), "tx_turns": tx, "rx_turns": rx}
    if args.map is not None:
        from . import mission_figures
        args.map.parent.mkdir(parents=True, exist_ok=True)
        out["map_png"] = mission_figures.plot_lm_map(m, dz, tilt, args.map)
    if args.format == "json":
        print(json.dumps(out))
        return 0
    print(f"pose: dx={args.dx:g} m dy={args.dy:g} m dz={dz:.4f} m tilt={args.tilt_deg:g} deg")
    print(f"L1 = {m.l1_h * 1e6:.3f} uH ({m.tx.n_turns} turns), L2 = {m.l2_h * 1e6:.3f} uH ({m.rx.n_turns} turns)")
    print(f"Lm = {lm * 1e6:.4f} uH, k = {out['k']:.4f}")
    if "map_png" in out:
        print(f"figure: {out['map_png']}")
    return 0


# ----------------------------------------------------------------------------- mission
def _parse_set(items):
    import tomllib
    out = {}
    for item in items or ():
        if "=" not in item:
            raise CliError(f"--set {item!r} is invalid; valid form: KEY=VALUE (e.g. battery.capacity_ah=2.0)")
        key, text = item.split("=", 1)
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text
        out[key.strip()] = value
    return out


def _add_mission(sub):
    p = sub.add_parser("mission", help="run a flight mission with in-flight charging (the main job)",
                       description="Simulate a drone mission over charging pads: coupling from the pose, the "
                                   "WPT link, the SBAR policy, battery and propulsion. Without CONFIG the embedded "
                                   "default mission runs. Writes the time series (Parquet, CSV), summary.json and "
                                   "PNG figures to --out.")
    p.add_argument("config", nargs="?", type=Path, default=None, help="mission TOML (default: embedded default)")
    p.add_argument("--policy", default="model_based", help="receiver policy (default model_based)")
    p.add_argument("--out", type=Path, default=Path("out/mission"), help="output folder (default out/mission)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a config value by dotted key, e.g. --set wind.speed_m_s=6 (repeatable)")
    p.add_argument("--no-charge", action="store_true", help="never energise the pads (baseline mission)")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    p.set_defaults(func=_cmd_mission)


def _cmd_mission(args) -> int:
    import tomllib

    from . import config as mconfig
    from .contract import PolicyContext
    from .runner import run_mission
    try:
        import policies
    except ImportError as exc:  # pragma: no cover - policies ships with dronewpt
        raise CliError(f"the policies package is not importable: {exc}") from None
    if args.config is not None and not args.config.is_file():
        raise CliError(f"config file {str(args.config)!r} does not exist")
    text = mconfig.DEFAULT_MISSION_TOML if args.config is None else args.config.read_text("utf-8")
    try:
        d = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CliError(f"{args.config or 'default mission'}: not valid TOML: {exc}") from None
    overrides = _parse_set(args.set)
    cfg = mconfig.config_from_dict(mconfig.apply_overrides(d, overrides) if overrides else d)
    if args.policy not in policies.available():
        raise CliError(f"--policy {args.policy!r} is invalid; valid values: {', '.join(policies.available())}")
    model = cfg.coupling.model()
    assumed = cfg.link.link_params(model.l1_h, model.l2_h, float(model.lm_h(0.0, 0.0, cfg.mission.hover_gap_m)))
    ctx = PolicyContext(link=assumed, control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a)
    pol = policies.make(args.policy, ctx)
    progress = args.format != "json" and sys.stderr.isatty()
    res = run_mission(cfg, pol, charge=not args.no_charge, progress=progress)
    files = [str(f) for f in res.write(args.out, figures=not args.no_plot)]
    s = res.summary
    if args.format == "json":
        print(json.dumps({**s, "files": files}))
        return 0
    rows = [
        ("policy", s["policy"], ""),
        ("simulated time", f"{s['sim_time_s']:.1f}", "s"),
        ("wall time", f"{s['wall_s']:.3f}", f"s ({s['realtime_factor']:.0f}x real time)"),
        ("energy from the pads", f"{s['energy_from_source_j']:.1f}", "J"),
        ("energy to the battery node", f"{s['energy_to_battery_j']:.1f}", "J"),
        ("losses (coils + battery)", f"{s['losses_j']:.1f}", f"J ({s['coil_losses_j']:.1f} + {s['battery_losses_j']:.1f})"),
        ("propulsion energy", f"{s['propulsion_energy_j']:.1f}", "J"),
        ("energy balance error", f"{s['energy_balance_error_rel']:.2e}", "relative"),
        ("SoC start -> end", f"{s['initial_soc']:.4f} -> {s['final_soc']:.4f}",
         f"(without charging {s['final_soc_without_charging']:.4f}; full: {s['battery_full']})"),
        ("peak I2", f"{s['peak_i2_a']:.2f}", f"A (rated {s['rated_i2_a']:g} A)"),
        ("time above rated", f"{s['time_above_rated_s'] * 1e3:.2f}", "ms"),
        ("pad on", f"{s['charge_time_s']:.1f}", "s"),
        ("flight time gain", f"{s['flight_time_gain_s']:.1f}", "s of hover"),
        ("steps fine / coarse", f"{s['fine_steps']} / {s['coarse_steps']}", f"({s['fine_windows']} fine windows)"),
    ]
    if s.get("battery_depleted"):
        rows.append(("WARNING", "battery depleted", f"(min SoC {s['min_soc']:.3f}; OCV held at its SoC = 0 value)"))
    w = max(len(r[0]) for r in rows)
    for name, val, unit in rows:
        print(f"{name:<{w}}  {val:>24}  {unit}")
    for f in files:
        print(f"wrote: {f}")
    return 0


# ----------------------------------------------------------------------------- sweep
def _nonneg_int(name):
    def conv(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not an integer") from None
        if v < 0:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: integer >= 0")
        return v
    return conv


def _add_sweep(sub):
    p = sub.add_parser("sweep", help="run a parameter study (grid / Monte Carlo) on Dask, resumable",
                       description="Run every case of STUDY.toml (a base mission and the parameters to vary) "
                                   "on a Dask cluster and store one Parquet row per mission under DIR/cases. "
                                   "Re-running the same command skips the cases already stored. Prints a "
                                   "summary table and writes trade-off plots to DIR/plots. Exit status 1 if "
                                   "some cases failed (stored with their error) or did not finish.")
    p.add_argument("study", type=Path, metavar="STUDY.toml", help="study TOML file (see examples/study_small.toml)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder (created; reused to resume)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="address of an existing Dask scheduler "
                                                      "(e.g. tcp://10.0.0.5:8786); default: a local cluster")
    p.add_argument("--connect-timeout", type=_positive_float("connect-timeout"), default=10.0, metavar="S",
                   help="seconds to wait for --scheduler (default 10)")
    p.add_argument("--workers", type=_nonneg_int("workers"), default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per CPU; 0 = run serially "
                        "in this process without Dask)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG plots")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_sweep)


def _cmd_sweep(args) -> int:
    import signal

    import pandas as pd

    from . import study as study_mod
    from . import sweep, sweep_report

    if args.scheduler is not None and args.workers is not None:
        raise CliError("--scheduler and --workers exclude each other "
                       "(the cluster at --scheduler has its own workers)")
    st = study_mod.load_study(args.study)
    make_policy = policy_names = None
    if not st.runner:
        import policies  # lazy: mission_sim never imports policies at module level

        make_policy, policy_names = policies.make, policies.available()
    runner, cases, _ = sweep.prepare_study(st, make_policy, policy_names)

    def _term(signum, frame):  # SIGTERM -> KeyboardInterrupt: pending cases cancelled, cluster closed
        raise KeyboardInterrupt

    factory = None  # --workers 0: serially in this process
    if args.scheduler is not None or args.workers != 0:
        def factory():
            return sweep.dask_client(args.scheduler, args.workers, connect_timeout_s=args.connect_timeout)
    if args.scheduler is not None:
        with factory():  # a bad address fails now, before the store is touched
            pass
    old = signal.signal(signal.SIGTERM, _term)
    try:
        res = sweep.run_sweep(cases, runner, args.out, client_factory=factory, progress=not args.no_progress,
                              progress_desc=st.name)
    finally:
        signal.signal(signal.SIGTERM, old)

    table = sweep_report.summary_table(res.results, st)
    errors = sweep_report.error_table(res.results)
    figs = [] if args.no_plot else sweep_report.plot_sweep(res.results, st, args.out / "plots")
    if not table.empty:
        table.to_csv(args.out / "summary.csv")
    counts = {"study": st.name, "out": str(args.out), "cases": res.n_cases, "skipped": res.n_skipped,
              "run": res.n_run, "ok": res.n_ok, "errors": res.n_error, "missing": res.n_missing,
              "wall_s": round(res.wall_s, 3),
              "cases_per_s": None if res.n_run == 0 else round(res.cases_per_s, 3)}
    if args.format == "json":
        summary = json.loads(table.reset_index().to_json(orient="records")) if not table.empty else []
        print(json.dumps({**counts, "summary": summary, "failed": errors.to_dict(orient="records"),
                          "figures": figs}))
    else:
        rate = f" in {res.wall_s:.1f} s ({res.cases_per_s:.2f} cases/s)" if res.n_run else ""
        print(f"study {st.name}: {res.n_cases} cases, {res.n_skipped} already done, {res.n_run} run{rate}, "
              f"{res.n_ok} ok, {res.n_error} failed; results in {args.out / 'cases'}")
        if not table.empty:
            with pd.option_context("display.width", 200, "display.max_columns", 40,
                                   "display.float_format", "{:.4g}".format):
                print(table.T.to_string())
        if len(errors):
            print("failed cases (first 10):")
            print(errors.to_string(index=False, max_colwidth=120))
        for f in figs:
            print(f"figure: {f}")
    if res.n_missing:
        print(f"dronewpt sweep: {res.n_missing} of {res.n_cases} cases did not finish (tasks lost); "
              "run the same command again to resume", file=sys.stderr)
        return 1
    if res.n_error:
        print(f"dronewpt sweep: {res.n_error} of {res.n_cases} cases failed (stored with status 'error')",
              file=sys.stderr)
        return 1
    return 0


# ----------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="dronewpt", description="Flight-mission energy simulator for drones "
                                     "that charge wirelessly in flight (WPT link with an SBAR receiver).")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for add in (_add_paper, _add_coupling, _add_mission, _add_sweep):
        add(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (CliError, ValueError, FileNotFoundError, OSError) as exc:
        print(f"dronewpt {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dronewpt {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
