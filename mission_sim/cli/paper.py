"""``dronewpt paper``: Table II and Fig. 6 of the paper on the envelope or switching model."""

from __future__ import annotations

import json
from pathlib import Path

from .common import CliError, float_arg, path_arg, prepare_out_dir


def _add_paper(sub):
    p = sub.add_parser("paper", help="reproduce the paper's Table II and Fig. 6",
                       description="Run the step, ramp and proposed V2* trajectories (RM -> SM) on the "
                                   "Table I link, print Table II beside the paper's, write Fig. 6 as PNG.")
    p.add_argument("--model", default="envelope", help="plant model: envelope (default) or switching")
    p.add_argument("--out", type=path_arg("--out"), default=Path("out/paper"), help="folder for the figures (default out/paper)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--control-period", type=float_arg("control-period", positive=True, lo=1e-7, hi=1e-3), default=None,
                   help="controller update period in s, 1e-7 .. 1e-3 (default: rectifier period 1/(2f))")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    p.set_defaults(func=_cmd_paper)


def _cmd_paper(args) -> int:
    from wpt_receiver import paper
    if args.model not in paper.MODELS:
        raise CliError(f"--model {args.model!r} is invalid; valid values: {', '.join(sorted(paper.MODELS))}")
    t_switch = 1e-3
    if not args.no_plot:
        prepare_out_dir(args.out)
    runs = paper.run_paper(model=args.model, t_switch_s=t_switch, control_period_s=args.control_period)
    figs = []
    if not args.no_plot:
        from ..figures import paper as figures
        figs.append(figures.plot_paper_fig6(runs, args.out / f"fig6_{args.model}.png", t_switch,
                                            f"RM -> SM transition, {args.model} model, Table I"))
        if args.model == "switching":
            from ..figures.switching import plot_switching_waveforms
            figs.extend(plot_switching_waveforms(runs, args.out))
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
    final_src = "the closed-form SM current" if args.model == "envelope" else f"the {args.model} model's final amplitude"
    print(f"overshoot = (max - final) / final; the paper's final value is 10.5 A, ours is {final_src}")
    for f in figs:
        print(f"figure: {f}")
    return 0
