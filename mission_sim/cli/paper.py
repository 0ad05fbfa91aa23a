"""``dronewpt paper``: Table II and Fig. 6 of the paper on the exact-mode (default), switching or envelope model."""

from __future__ import annotations

import json
from pathlib import Path

from .common import CliError, check_out_file, figures_out, float_arg, path_arg, prepare_out_dir


def _add_paper(sub):
    p = sub.add_parser("paper", help="reproduce the paper's Table II and Fig. 6",
                       description="Run the step, ramp and proposed V2* trajectories (RM -> SM) on the "
                                   "Table I link, print Table II beside the paper's, write Fig. 6 as PNG.")
    p.add_argument("--model", default="modal",
                   help="plant model: modal (default: exact modes + SBAR ripple, compiled; the instantaneous peak "
                        "Table II measures, and the fundamental), switching, or envelope (eq. 4: the fundamental only)")
    p.add_argument("--out", type=path_arg("--out"), default=None,
                   help="folder for the figures (default out/paper; not with --no-plot)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--control-period", type=float_arg("control-period", positive=True, lo=1e-7, hi=1e-3), default=None,
                   help="controller update period in s, 1e-7 .. 1e-3 (default: rectifier period 1/(2f))")
    p.add_argument("--t-end", type=float_arg("t-end", positive=True, lo=5e-3, hi=1.0), default=31e-3,
                   help="end of the window in s, 0.005 .. 1 (default 0.031; the switch is at 0.001)")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    p.add_argument("--link", action="append", default=[], metavar="KEY=VALUE",
                   help="a link parameter other than Table I (repeatable), e.g. lm_h=5e-6; keys: l1_h, l2_h, lm_h, "
                        "r1_ohm, r2_ohm, vdc_v, vl_v, f_hz (the paper's columns stay Table I's)")
    p.add_argument("--waveforms", type=Path, default=None, metavar="FILE.csv|FILE.parquet",
                   help="with --model switching: write the instantaneous waveforms of the three runs (t_s, i1_a, "
                        "vc1_v, i2_a, vc2_v, v1_v, v2_v, i_load_a, sbar_gate, inverter_cmd, trajectory)")
    p.set_defaults(func=_cmd_paper)


#: the ``--model`` values whose runs use numba's compiled kernels (``envelope`` runs without numba: the hook,
#: which imports numba, is not installed for it)
COMPILED_MODELS = ("modal", "switching")


def _cmd_paper(args) -> int:
    from wpt_receiver import paper
    if args.model not in paper.MODELS:
        raise CliError(f"--model {args.model!r} is invalid; valid values: {', '.join(sorted(paper.MODELS))}")
    from .controller import _link_params
    _check_waveforms(args)
    args.out = figures_out(args, "out/paper")
    params = _link_params(args.link)
    link_text = _link_text(params)
    reason = paper.modal_range_problem(params) if args.model == "modal" else None   # (run_paper warns it)
    t_switch = 1e-3
    if not args.no_plot:
        prepare_out_dir(args.out)
    if args.model in COMPILED_MODELS:   # numba's cached kernels without its registries (~0.3-0.5 s of CPU)
        from wpt_receiver.numba_start import cache_loads_without_registries
        cache_loads_without_registries()
    import warnings
    with warnings.catch_warnings(record=True) as caught:   # the model's own warnings as one line each
        warnings.simplefilter("always", RuntimeWarning)
        runs = paper.run_paper(params, model=args.model, t_switch_s=t_switch, t_end_s=args.t_end,
                               control_period_s=args.control_period)
    _print_warnings(caught, range_problem=reason is not None)
    figs = []
    if not args.no_plot:
        from ..figures import paper as figures
        figs.append(figures.plot_paper_fig6(runs, args.out / f"fig6_{args.model}.png", t_switch,
                                            f"RM -> SM transition, {args.model} model, {link_text}"))
        if args.model == "switching":
            from ..figures.switching import plot_switching_waveforms
            figs.extend(plot_switching_waveforms(runs, args.out))
    rows = [_row(r, t_switch, args.model) for r in runs]
    if args.waveforms is not None:
        figs.append(_write_waveforms(runs, args.waveforms))
    if args.format == "json":
        print(json.dumps({"model": args.model, "link": dict(vars(params)), "rows": rows, "figures": figs}))
        return 0
    _print_table(runs, rows, args.model, link_text)
    for f in figs:
        print(f"{'waveforms' if str(f).endswith(('.csv', '.parquet')) else 'figure'}: {f}")
    return 0


def _row(r, t_switch: float, model: str) -> dict:
    """One Table II row; ``max_current_a`` is the model's own I2 (envelope: the fundamental amplitude,
    switching: the instantaneous peak |i2| per half cycle), ``max_fundamental_a`` the fundamental."""
    import numpy as np
    m = r.metrics
    row = {"trajectory": r.trajectory, "rm_current_a": m.rm_current_a, "final_current_a": m.final_current_a,
           "max_current_a": m.max_current_a, "overshoot_pct": m.overshoot_pct,
           "settling_time_s": m.settling_time_s, "peak_i1_a": m.peak_i1_a,
           "energy_to_battery_j": m.energy_to_battery_j}
    row["max_current_is"] = "fundamental" if model == "envelope" else "instantaneous"
    if model == "envelope":
        row["max_fundamental_a"] = m.max_current_a
    else:
        row["max_instantaneous_a"] = m.max_current_a
        fund = r.extra.get("i2_fund_a")
        if fund is not None:
            row["max_fundamental_a"] = float(np.max(np.asarray(fund)[np.asarray(r.t_s) >= t_switch]))
        row["sim_wall_s"] = r.sim_wall_s
    return row


def _print_warnings(caught, range_problem: bool = False) -> None:
    """The RuntimeWarnings of a run as ``dronewpt paper: warning: ...`` lines in the order raised, each distinct one
    once (the library's: a far-off f_hz, the model's range, per trajectory); any other warning caught with them is
    shown as Python shows it. ``range_problem``: the exact-mode range warning is among them (the per-trajectory
    "not physical" ones would only repeat it)."""
    import warnings

    from .notices import say_warning
    for w in caught:
        if range_problem and "exact-mode run is not physical" in str(w.message):
            continue
        if not issubclass(w.category, RuntimeWarning):   # not the model's: Python's own display, as uncaught
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        else:   # (in the flags' words: notices.FLAG_WORDS)
            say_warning("paper", str(w.message))


def _link_text(params) -> str:
    """``Table I`` or ``Table I with lm_h=4e-06, ...`` (the fields ``--link`` changed)."""
    from dataclasses import fields

    from wpt_receiver import TABLE_I
    changed = [f"{f.name}={getattr(params, f.name)!r}" for f in fields(params)
               if getattr(params, f.name) != getattr(TABLE_I, f.name)]
    return "Table I" if not changed else "Table I with " + ", ".join(changed)


def _print_table(runs, rows, model: str, link_text: str = "Table I") -> None:
    from wpt_receiver import paper
    inst = model != "envelope"
    print(f"Table II, {model} model ({link_text} parameters; RM steady state -> SM at t = 0)")
    head = f"{'max inst.':>9} {'max fund.':>9}" if inst else f"{'max fund.':>9}"
    print(f"{'trajectory':<10} {'paper max':>10} {'paper OS':>9} | {'RM':>7} {'final':>7} {head} {'OS':>8} {'settle':>8}")
    for r, row in zip(runs, rows):
        pm, po = paper.PAPER_TABLE_II[r.trajectory]
        mx = (f"{row['max_instantaneous_a']:>7.2f} A {row.get('max_fundamental_a', float('nan')):>7.2f} A" if inst
              else f"{row['max_fundamental_a']:>7.2f} A")
        print(f"{r.trajectory:<10} {pm:>8.1f} A {po:>7.1f} % | {row['rm_current_a']:>5.2f} A {row['final_current_a']:>5.2f} A "
              f"{mx} {row['overshoot_pct']:>6.2f} % {row['settling_time_s'] * 1e3:>5.2f} ms")
    if inst:
        print("max inst. = largest instantaneous |i2| (what the paper's Table II measures; RM, final, OS on the "
              "per-half-cycle peaks); max fund. = largest amplitude of the i2 fundamental per half cycle (what "
              "eq. 4 models; the harmonics can flatten the crest below it)")
    else:
        print("max fund. = largest amplitude of the i2 fundamental (the envelope model, eq. 4); the instantaneous "
              "peak |i2| the paper's Table II measures: --model modal (default) or switching")
    final_src = "the closed-form SM current" if model == "envelope" else f"the {model} model's final amplitude"
    print(f"overshoot = (max - final) / final; the paper's final value is 10.5 A, ours is {final_src}")
    if link_text != "Table I":   # (the columns beside an own link's numbers are not that link's)
        print("paper max / paper OS: the paper's Table II on its Table I link, for reference; not this link's")


def _check_waveforms(args) -> None:
    """``--waveforms`` only with the switching model and a .csv / .parquet name (checked before simulating)."""
    if args.waveforms is None:
        return
    if args.model != "switching":
        raise CliError(f"--waveforms needs --model switching (got --model {args.model}): only the switching model "
                       "has instantaneous waveforms")
    if args.waveforms.suffix.lower() not in (".csv", ".parquet"):
        raise CliError(f"--waveforms {str(args.waveforms)!r} is invalid; valid: a file name ending .csv or .parquet")
    check_out_file(args.waveforms, "--waveforms")   # a folder, a file in the folder's place, unwritable


def _write_waveforms(runs, path: Path) -> str:
    """All runs' instantaneous waveforms in one long table (``trajectory`` column), written atomically."""
    import pandas as pd

    from ..files import atomic_output
    df = pd.concat([r.extra["waveforms"].assign(trajectory=r.trajectory) for r in runs], ignore_index=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as tmp:
        if path.suffix.lower() == ".parquet":
            df.to_parquet(tmp, index=False)
        else:
            df.to_csv(tmp, index=False, float_format="%.9g")
    return str(path)
