"""``dronewpt sizing``: the rectifier each policy needs (rating, part, losses, mass)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .common import (CliError, add_progress_flag, figures_out, float_arg, name_list, path_arg, prepare_out_dir,
                     show_progress)

_COLUMNS = ("peak_i2_a", "diode_rms_a", "diode_avg_a", "switch_rms_a", "required_rating_a", "part", "mass_g",
            "device_mass_g", "sink_mass_g", "conduction_loss_w", "switching_loss_w", "loss_w", "tj_diode_c",
            "tj_switch_c", "v_worst_v", "required_v_rating_v")


def _add_sizing(sub):
    p = sub.add_parser("sizing", help="rectifier rating, parts and mass per policy (the paper's claim)",
                       description="Simulate the RM -> SM transition of each policy with the switching model and "
                                   "real devices (--source mission: whole missions; --source sweep: a sweep's "
                                   "worst case per policy); size the SBAR: worst-case instantaneous |i2|, device "
                                   "RMS currents, required rating (margin x peak), voltage rating (the sizing "
                                   "rules' v_margin x the simulated open-load peak), smallest-mass combination of shipped parts, "
                                   "conduction and switching losses at the settled junction temperatures and "
                                   "rectifier mass (devices + plate-fin heat sink).")
    p.add_argument("--source", choices=("paper", "mission", "sweep"), default="paper",
                   help="paper: the RM -> SM transition on the switching model (default); mission: whole missions "
                        "per policy (envelope currents, instantaneous peak estimate); sweep: per policy, the "
                        "case of a sweep's results (--sweep DIR) with the largest peak |i2|, re-run and sized")
    p.add_argument("--sweep", type=path_arg("--sweep"), default=None, metavar="DIR",
                   help="for --source sweep: the --out folder of a finished `dronewpt sweep` (its base mission "
                        "is --config, default embedded; the fingerprint is checked)")
    p.add_argument("--policies", default=None,
                   help="comma-separated: transitions step, ramp, proposed (paper; default all three) or mission "
                        "policies (mission; default step,ramp,model_based)")
    p.add_argument("--config", type=path_arg("--config"), default=None, help="mission TOML for --source mission (default: embedded)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="mission config override for --source mission (repeatable)")
    p.add_argument("--link", action="append", default=[], metavar="KEY=VALUE",
                   help="for --source paper: a link parameter other than Table I (repeatable), e.g. vl_v=7.4; keys: "
                        "l1_h, l2_h, lm_h, r1_ohm, r2_ohm, vdc_v, vl_v, f_hz (missions: --set link.*, battery.*)")
    p.add_argument("--devices", default="schottky", help="device preset for the first run and the inverter "
                   "(default schottky; see wpt_receiver/parts.toml)")
    _rules_arg(p, "--margin", "margin", float_arg("margin", positive=True, lo=1.0, hi=10.0),
               "required rating = margin x worst-case |i2|, 1 .. 10")
    p.add_argument("--t-end", type=float_arg("t-end", positive=True, lo=3e-3, hi=0.1), default=10e-3,
                   help="end of the run in s, switch at 1 ms, 0.003 .. 0.1 (default 0.01)")
    _rules_arg(p, "--t-protect", "t_protect_s", float_arg("t-protect", positive=True, lo=1e-7, hi=0.1),
               "open-load study: time from the battery disconnect to the protective short, s, 1e-7 .. 0.1",
               lambda: f"; the voltage rating is {_default('v_margin'):g} x the simulated peak")
    _rules_arg(p, "--c-out", "c_out_f", float_arg("c-out", positive=True, lo=1e-7, hi=1.0),
               "open-load study: rectifier output capacitor, F, 1e-7 .. 1")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--out", type=path_arg("--out"), default=None,
                   help="folder for the figure (default out/sizing; not with --no-plot)")
    p.add_argument("--no-plot", action="store_true", help="skip the figure")
    add_progress_flag(p)
    p.set_defaults(func=_cmd_sizing)


def _names(args, valid, default):
    return name_list(default if args.policies is None else args.policies, "--policies", valid)


#: the options whose default is a field of :class:`wpt_receiver.sizing.SizingRules`: option dest -> field
_RULES_OPTIONS = {"margin": "margin", "t_protect": "t_protect_s", "c_out": "c_out_f"}


def _rules_arg(p, flag: str, field: str, type_, text: str, tail=lambda: "") -> None:
    """An option whose default is the ``field`` of :class:`wpt_receiver.sizing.SizingRules` (one source: the
    defaults of ``--margin``, ``--t-protect`` and ``--c-out`` and their help were copies of it, 1.25, 1e-4 s and
    4.7e-3 F). None at parse, the rules' value in the command (:func:`_resolve_rules_defaults`); the help names the
    value only when shown (``lazy_help``: the rules' module imports numpy, not when the parsers are built)."""
    action = p.add_argument(flag, type=type_, default=None, help=f"{text} (default: the sizing rules')")
    action.lazy_help = lambda: f"{text} (default {_default(field):g}, wpt_receiver.sizing.SizingRules){tail()}"


def _default(field: str) -> float:
    """The default ``field`` of :class:`wpt_receiver.sizing.SizingRules`."""
    from wpt_receiver.sizing import SizingRules
    return float(getattr(SizingRules(), field))


def _resolve_rules_defaults(args) -> None:
    """Each of ``--margin``, ``--t-protect``, ``--c-out`` not given: the rules' value (:data:`_RULES_OPTIONS`)."""
    for dest, field in _RULES_OPTIONS.items():
        if getattr(args, dest) is None:
            setattr(args, dest, _default(field))


def _rules(args):
    from wpt_receiver.sizing import SizingRules
    return SizingRules(margin=args.margin, t_protect_s=args.t_protect, c_out_f=args.c_out)


def _rows(args):
    from tqdm import tqdm

    from wpt_receiver.devices import link_preset, preset
    from wpt_receiver.references import TRAJECTORIES
    from wpt_receiver.sizing import size_policies
    try:
        base = preset(args.devices)
    except ValueError as e:
        raise CliError(f"--devices: {e}") from None
    _paper_link(args)   # (a bad --link, or --link with a mission source: refused before anything runs)
    if args.source == "mission":
        return _mission_rows(args, base)
    if args.source == "sweep":
        return _sweep_rows(args, base)
    names = _names(args, TRAJECTORIES, "step,ramp,proposed")
    params = _paper_link(args)
    base = link_preset(args.devices, params)   # (the capacitances at the link's VL and Vdc: Table I's 30 V = preset's)
    _kernels_from_cache()
    bar = tqdm(total=len(names), desc="sizing", disable=not show_progress(args), file=sys.stderr)
    with bar:
        rows = size_policies(names, params, base, _rules(args), t_end_s=args.t_end,
                             progress=lambda: bar.update(1))
    return [{"policy": r["policy"], **{c: r.get(c) for c in _COLUMNS}, "v_case": r.get("v_case"),
             "edge_ring_peak_v": r.get("edge_ring_peak_v"), "turn_off_peak_a": r.get("turn_off_peak_a")} for r in rows]



def _paper_link(args):
    """The link of ``--source paper``: Table I with ``--link`` (as ``paper`` / ``netlist`` take it); ``--link``
    with another source is refused (a mission's link is its config's)."""
    from .controller import _link_params
    if args.link and args.source != "paper":
        raise CliError(f"--link is invalid with --source {args.source}; valid: --source paper (a mission's link: "
                       "--set link.KEY=VALUE, battery.n_series=N)")
    return _link_params(args.link)


def _kernels_from_cache() -> None:
    """Once the input is checked (bad input imports no numba): numba's cached kernels load without its
    typing/lowering registries, 0.7-0.9 s less CPU (:func:`wpt_receiver.numba_start.cache_loads_without_registries`)."""
    from wpt_receiver.numba_start import cache_loads_without_registries
    cache_loads_without_registries()


def _mission_rows(args, base):
    """Sizing rows from whole missions (one per policy) with the link's devices = ``--devices``."""
    from tqdm import tqdm

    import policies

    from .mission import mission_config, say_pads_note
    names = _names(args, policies.available(), "step,ramp,model_based")
    args.set = [*args.set, f"link.devices={base.name}"]
    cfg = mission_config(args)
    say_pads_note(args)
    return [_size_mission(name, cfg, base, args)
            for name in tqdm(names, desc="sizing missions", disable=not show_progress(args), file=sys.stderr)]


def _size_mission(name, cfg, base, args) -> dict:
    """Run mission ``cfg`` with policy ``name`` and size its rectifier from the time series."""
    from wpt_receiver.sizing import envelope_currents, select_parts

    from ..world.runner import run_mission
    from .mission import make_policy
    _kernels_from_cache()
    res = run_mission(cfg, make_policy(name, cfg))
    ts, peak = res.timeseries, res.summary["peak_i2_a"]
    cols = [ts[c].to_numpy() for c in ("t_s", "dt_s", "d_short", "i1_amp_a", "i2_amp_a")]
    from wpt_receiver import TABLE_I
    from wpt_receiver.devices import link_preset
    vl, f = ts["battery_v"].to_numpy(), res.config.link.f_hz   # (the edges block each step's pack voltage)
    # the open-load voltage study and the parts' capacitances on Table I's coils (the design point) with the
    # mission's link settings at the run's highest pack voltage (module docstring: _mission_vl_v)
    params = res.config.link.link_params(TABLE_I.l1_h, TABLE_I.l2_h, TABLE_I.lm_h, vl_v=_mission_vl_v(vl))
    dev = link_preset(base.name, params)
    row = select_parts(lambda dv: envelope_currents(*cols, peak, dv, vl_v=vl, f_hz=f), params, dev, _rules(args))
    return {"policy": name, **{c: row.get(c) for c in _COLUMNS}}


def _mission_vl_v(battery_v) -> float:
    """The battery voltage [V] a mission row is sized at (the open-load study and the parts' charge-equivalent
    capacitances): the highest ``battery_v`` of the run the row is sized from (``--source sweep``: the re-run worst
    case's own run; the sweep stores summaries, not voltages). The highest, because the open-load fault's worst
    blocking voltage rises with the pack voltage at the disconnect (the tank's energy lands on top of VL): the
    part must block the worst moment of the run, and its capacitances are taken at the voltage that study runs at.
    (Until 2026-11-27 night: Table I's 30 V whatever the pack, e.g. 31.50 V worst blocking voltage on the default
    mission's 8S pack at 32.3-32.9 V.) The edge energies still take each step's own ``battery_v``."""
    return float(battery_v.max())


def _sweep_rows(args, base):
    """Sizing rows from a sweep: per policy, its stored case with the largest peak |i2| re-run with
    the link's devices = ``--devices`` (the sweep stores summaries, the sizing needs the time series)."""
    from tqdm import tqdm

    from ..config import check_file_route_keys, config_from_dict, config_to_dict, load_config_dict
    from ..studies.worst_cases import case_config, worst_cases
    if args.sweep is None:
        raise CliError("--source sweep needs --sweep DIR (the --out folder of a finished sweep)")
    if args.set:
        raise CliError("--set is invalid with --source sweep (the cases' own parameters are used); valid: "
                       "--config for the sweep's base mission")
    d, file_keys = load_config_dict(args.config, file_keys=True)
    base_dict = config_to_dict(config_from_dict(d))
    check_file_route_keys(args.config, base_dict, file_keys)   # (the cases fly its route, as the sweep's did)
    rows = []
    for wc in tqdm(worst_cases(args.sweep, "peak_i2_a", base_dict), desc="sizing worst cases",
                   disable=not show_progress(args), file=sys.stderr):
        cfg = case_config(base_dict, wc.params, {"link.devices": base.name})
        rows.append({**_size_mission(wc.policy, cfg, base, args), "case_id": wc.case_id, "cases": wc.n_cases,
                     "sweep_peak_i2_a": wc.value})
    return rows


def _preset_shortfall(devices: str, rows, rules) -> str | None:
    """One line when the preset's own rectifier parts (one leg / die per position) are below a row's required rating
    (:func:`wpt_receiver.sizing.rating_shortfall` at the row's peak with the preset, ``required_rating_a / margin``):
    the default mission's ``schottky`` (30CTT045, 15 A) at model_based's 13.32 A peak is 1.64 A short of 16.64 A.
    (Not the row's ``peak_i2_a``: with ``--source paper`` that is the peak with the parts the row chose, measured
    again with their resistances; the rule rated the preset's own peak, which ``required_rating_a`` carries.)"""
    from wpt_receiver.sizing import rating_shortfall
    below = [(r["policy"], s) for r in rows
             if (s := rating_shortfall(devices, r["required_rating_a"] / rules.margin, rules)) is not None]
    if not below:
        return None
    s0 = below[0][1]
    return (f"warning: devices {devices}'s own {s0['position']} {s0['part']} is rated {s0['rating_a']:g} A, below the "
            "required rating of " + ", ".join(f"{p} ({s['required_a']:.2f} A, {s['shortfall_a']:.2f} A short)"
                                              for p, s in below)
            + ": the parts above parallel it (or take another part)")


def _cmd_sizing(args) -> int:
    from .paper import _link_text
    _resolve_rules_defaults(args)
    args.out = figures_out(args, "out/sizing")
    if not args.no_plot:
        prepare_out_dir(args.out)  # before the simulation: a bad folder costs nothing
    rows = _rows(args)
    figs = []
    if not args.no_plot:
        from ..figures.sizing import plot_sizing
        what = {"paper": f"{_link_text(_paper_link(args))} link", "mission": "missions",
                "sweep": f"worst cases of sweep {args.sweep}"}[args.source]
        figs.append(plot_sizing(rows, args.out / "sizing.png",
                                f"SBAR sizing, {what}, devices {args.devices}, margin {args.margin:g}"))
        if args.source == "paper":
            from wpt_receiver.devices import link_preset
            from wpt_receiver.sizing import open_load_study

            from ..figures.sizing import plot_open_load
            link = _paper_link(args)
            figs.append(plot_open_load(open_load_study(link, link_preset(args.devices, link), _rules(args)),
                                       args.out / "open_load.png", rows[0]["required_v_rating_v"]))
    if args.format == "json":
        link = {"link": dict(vars(_paper_link(args)))} if args.source == "paper" else {}
        print(json.dumps({"source": args.source, "devices": args.devices, "margin": args.margin, **link, "rows": rows,
                          "figures": figs}))
        return 0
    model = {"paper": f"switching model, RM -> SM, {_link_text(_paper_link(args))}",
             "mission": "missions, exact-mode link + ripple peak",
             "sweep": f"worst case per policy of sweep {args.sweep}, re-run, exact-mode link + ripple peak"}[args.source]
    print(f"SBAR sizing ({model}, devices {args.devices}, rating = {args.margin:g} x peak |i2|; "
          "RMS and loss over the worst 1 ms)")
    print(f"{'policy':<11} {'peak i2':>8} {'diode rms':>9} {'switch rms':>10} {'rating':>8} {'cond.':>7} {'switch.':>7} "
          f"{'Tj diode':>8} {'Tj sw':>6} {'V rating':>8} {'mass':>7}  part")
    for r in rows:
        print(f"{r['policy']:<11} {r['peak_i2_a']:>6.2f} A {r['diode_rms_a']:>7.2f} A {r['switch_rms_a']:>8.2f} A "
              f"{r['required_rating_a']:>6.1f} A {r['conduction_loss_w']:>5.2f} W {r['switching_loss_w']:>5.2f} W "
              f"{r['tj_diode_c']:>6.1f} C {r['tj_switch_c']:>4.1f} C {r['required_v_rating_v']:>6.1f} V "
              f"{r['mass_g']:>5.1f} g  {r['part']}")
    r0 = rows[0]
    rules = _rules(args)   # (the printed rules are the ones sized with)
    short = _preset_shortfall(args.devices, rows, rules)
    if short:
        print(short)
    print(f"losses at the settled junction temperatures (ambient {rules.t_amb_c:g} C, sink +{rules.dt_sink_k:g} K); "
          f"V rating = {rules.v_margin:g} x the simulated "
          f"worst blocking voltage {r0['v_worst_v']:.2f} V" + (f" ({r0['v_case']})" if r0.get("v_case") else ""))
    if r0.get("edge_ring_peak_v") is not None:
        print(f"ring of the largest hard turn-off with {rules.l_stray_h * 1e9:g} nH stray loop inductance (edge model "
              "checked against ngspice; "
              "reported, not rated: snubber / layout / Schottky avalanche): " + ", ".join(
                  f"{r['policy']} {r['edge_ring_peak_v']:.1f} V at {r['turn_off_peak_a']:.1f} A" for r in rows))
    for r in rows:
        if "case_id" in r:
            print(f"{r['policy']}: worst of {r['cases']} ok cases is case {r['case_id']} "
                  f"(sweep peak {r['sweep_peak_i2_a']:.2f} A)")
    for f in figs:
        print(f"figure: {f}")
    return 0
