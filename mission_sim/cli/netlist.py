"""``dronewpt netlist``: the switching model's circuit and devices as a SPICE netlist
(``wpt_receiver.switching.netlist``), to check any case in one's own ngspice or LTspice."""

from __future__ import annotations

import sys
from pathlib import Path

from .common import CliError, float_arg


def _add_netlist(sub):
    p = sub.add_parser("netlist", help="write a SPICE netlist (ngspice / LTspice) of the link and its devices",
                       description="Write the circuit of the switching model (inverter, tanks, coupling, SBAR "
                                   "with its diodes and switches, battery) with the devices of a preset as a "
                                   "SPICE netlist: RM from the phasor steady state, then the SBAR duty from "
                                   "--t-step to --t-end, with .meas of the RM, peak and final currents. The "
                                   "same generator wrote the SPICE-checked netlists in tests/spice/.")
    p.add_argument("--out", type=Path, default=None, help="netlist file (default: print to stdout)")
    p.add_argument("--devices", default="ideal", help="device preset (default ideal; see wpt_receiver/parts.toml)")
    p.add_argument("--d-short", type=float_arg("d-short", positive=False), default=None,
                   help="SBAR short duty from --t-step on, 0 .. 1 (default 1: short mode)")
    p.add_argument("--dead-time", type=float_arg("dead-time", positive=False), default=None,
                   help="inverter as a full bridge with this dead time in s (default: square-wave source)")
    p.add_argument("--t-step", type=float_arg("t-step", positive=True, lo=1e-5, hi=1.0), default=3e-3,
                   help="RM -> duty switch in s (default 0.003)")
    p.add_argument("--t-end", type=float_arg("t-end", positive=True, lo=1e-5, hi=1.0), default=9e-3,
                   help="end of the transient in s (default 0.009)")
    p.add_argument("--link", action="append", default=[], metavar="KEY=VALUE",
                   help="a link parameter other than Table I (repeatable), e.g. lm_h=5e-6")
    p.set_defaults(func=_cmd_netlist)


def _cmd_netlist(args) -> int:
    from wpt_receiver.devices import preset, preset_names
    from wpt_receiver.switching.netlist import netlist

    from ..files import atomic_output
    from .controller import _link_params
    if args.out is not None:
        from .common import check_out_file
        check_out_file(args.out, "--out")
    if args.devices not in preset_names():
        raise CliError(f"--devices {args.devices!r} is invalid; valid values: {', '.join(preset_names())}")
    params = _link_params(args.link)
    bridge = "" if args.dead_time is None else f", full bridge, dead time {args.dead_time!r} s"
    duty = "" if args.d_short is None else f", d_short {args.d_short!r}"
    try:
        text = netlist(params, preset(args.devices), f"{args.devices}{bridge}{duty}", args.dead_time,
                       args.t_step, args.t_end, args.d_short)
    except ValueError as exc:
        raise CliError(str(exc).replace("t_step_s", "--t-step").replace("t_end_s", "--t-end")
                       .replace("d_short", "--d-short").replace("dead_time_s", "--dead-time")) from None
    if args.out is None:
        sys.stdout.write(text)
        return 0
    if args.out.is_dir():
        raise CliError(f"--out {str(args.out)!r} is a folder; valid: a file name")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(args.out) as tmp:
        tmp.write_text(text)
    print(f"netlist: {args.out} (run: ngspice -b {args.out})")
    return 0
