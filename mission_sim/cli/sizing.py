"""``dronewpt sizing``: the rectifier each policy needs (rating, part, losses, mass)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .common import CliError, add_progress_flag, float_arg, prepare_out_dir, show_progress

_COLUMNS = ("peak_i2_a", "diode_rms_a", "diode_avg_a", "switch_rms_a", "required_rating_a", "part", "mass_g",
            "device_mass_g", "sink_mass_g", "conduction_loss_w")


def _add_sizing(sub):
    p = sub.add_parser("sizing", help="rectifier rating, parts and mass per policy (the paper's claim)",
                       description="Simulate the RM -> SM transition of each policy with the switching model and "
                                   "real devices; size the SBAR: worst-case instantaneous |i2|, device RMS currents, "
                                   "required rating (margin x peak), smallest-mass combination of shipped parts, "
                                   "conduction losses and rectifier mass (devices + plate-fin heat sink).")
    p.add_argument("--policies", default="step,ramp,proposed",
                   help="comma-separated transitions: step, ramp, proposed (default: all three)")
    p.add_argument("--devices", default="schottky", help="device preset for the first run and the inverter "
                   "(default schottky; see wpt_receiver/parts.toml)")
    p.add_argument("--margin", type=float_arg("margin", positive=True, lo=1.0, hi=10.0), default=1.25,
                   help="required rating = margin x worst-case |i2|, 1 .. 10 (default 1.25)")
    p.add_argument("--t-end", type=float_arg("t-end", positive=True, lo=3e-3, hi=0.1), default=10e-3,
                   help="end of the run in s, switch at 1 ms, 0.003 .. 0.1 (default 0.01)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--out", type=Path, default=Path("out/sizing"), help="folder for the figure (default out/sizing)")
    p.add_argument("--no-plot", action="store_true", help="skip the figure")
    add_progress_flag(p)
    p.set_defaults(func=_cmd_sizing)


def _rows(args):
    from tqdm import tqdm

    from wpt_receiver import TABLE_I
    from wpt_receiver.devices import preset
    from wpt_receiver.references import TRAJECTORIES
    from wpt_receiver.sizing import SizingRules, size_policies
    names = [n.strip() for n in args.policies.split(",") if n.strip()]
    bad = [n for n in names if n not in TRAJECTORIES]
    if bad or not names:
        raise CliError(f"--policies {args.policies!r} is invalid; valid values: {', '.join(TRAJECTORIES)}")
    base = preset(args.devices)
    bar = tqdm(total=len(names), desc="sizing", disable=not show_progress(args), file=sys.stderr)
    with bar:
        rows = size_policies(names, TABLE_I, base, SizingRules(margin=args.margin), t_end_s=args.t_end,
                             progress=lambda: bar.update(1))
    return [{"policy": r["policy"], **{c: r[c] for c in _COLUMNS}} for r in rows]


def _cmd_sizing(args) -> int:
    if not args.no_plot:
        prepare_out_dir(args.out)  # before the simulation: a bad folder costs nothing
    rows = _rows(args)
    figs = []
    if not args.no_plot:
        from ..figures.sizing import plot_sizing
        figs.append(plot_sizing(rows, args.out / "sizing.png",
                                f"SBAR sizing, Table I link, devices {args.devices}, margin {args.margin:g}"))
    if args.format == "json":
        print(json.dumps({"devices": args.devices, "margin": args.margin, "rows": rows, "figures": figs}))
        return 0
    print(f"SBAR sizing (switching model, devices {args.devices}, rating = {args.margin:g} x peak |i2|; "
          "RMS and loss over the worst 1 ms)")
    print(f"{'policy':<9} {'peak i2':>8} {'diode rms':>9} {'switch rms':>10} {'rating':>8} {'loss':>7} "
          f"{'mass':>7}  part")
    for r in rows:
        print(f"{r['policy']:<9} {r['peak_i2_a']:>6.2f} A {r['diode_rms_a']:>7.2f} A {r['switch_rms_a']:>8.2f} A "
              f"{r['required_rating_a']:>6.1f} A {r['conduction_loss_w']:>5.2f} W {r['mass_g']:>5.1f} g  {r['part']}")
    for f in figs:
        print(f"figure: {f}")
    return 0
