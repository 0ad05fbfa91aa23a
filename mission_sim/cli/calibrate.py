"""``dronewpt calibrate``: fit the drone power model to a flight log's battery power; writes a ``[drone]`` TOML."""

from __future__ import annotations

import json
from pathlib import Path

from .common import CliError, finite_float, parse_set, path_arg, prepare_out_dir


def _add_calibrate(sub):
    p = sub.add_parser("calibrate", help="fit the drone power model (mass, FM, efficiency, drag, avionics) to a flight log",
                       description="Fit the momentum-theory power model's mass, figure of merit, drive efficiency, "
                                   "flat-plate area and avionics power to a log's battery power (V I) against its GPS "
                                   "speed and climb rate: scipy least squares with a robust (soft_l1) loss on the first "
                                   "70 % of the airborne time, judged on the last 30 %. Writes a [drone] TOML that "
                                   "mission / replay / telemetry take with --drone FILE (or a sweep as its base), and "
                                   "a fit report (figure, JSON, samples CSV) beside it.")
    p.add_argument("log", type=path_arg("log"), help="flight log with battery voltage and current: .tlog, .bin or .ulg")
    p.add_argument("--out", type=path_arg("--out"), default=Path("out/calibrate/drone.toml"),
                   help="the [drone] TOML to write (default out/calibrate/drone.toml); the report goes in its folder")
    p.add_argument("--mass", type=finite_float("mass"), default=None, metavar="KG",
                   help="the vehicle's weighed mass: fixed, and the figure of merit fitted (default: the mass is "
                        "fitted as an equivalent mass, the figure of merit held near 0.6)")
    p.add_argument("--segment", type=int, default=None, metavar="N",
                   help="a log with reboots: calibrate on boot segment N (default: the one with the most armed time)")
    p.add_argument("--window", default=None, metavar="T0,T1", help="use only log seconds T0..T1")
    p.add_argument("--config", type=path_arg("--config"), default=None,
                   help="mission TOML whose [drone] (rotors, radius, air density) the fit starts from")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value, e.g. --set drone.rotor_radius_m=0.12 (repeatable)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--no-plot", action="store_true", help="skip the figure")
    p.set_defaults(func=_cmd_calibrate)


def _cmd_calibrate(args) -> int:
    from ..config import apply_overrides, config_from_dict, load_config_dict
    from ..files import atomic_output
    from ..mavlink.calibrate import calibrate_log, check_mass, drone_toml
    from ..mavlink.logs import read_log
    from ..mavlink.replay import parse_window
    from ..validation import check_regular_file
    check_regular_file(args.log, "log", "a .tlog, .bin or .ulg file")  # a FIFO: refused without opening it
    if args.out.suffix.lower() != ".toml" or args.out.is_dir():
        raise CliError(f"--out {str(args.out)!r} is invalid; valid: a file name ending in .toml")
    if args.mass is not None:   # the library's range, said before the log is read
        check_mass(args.mass, "--mass")
    window = parse_window(args.window)
    sets = parse_set(args.set)
    other = [k for k in sets if not str(k).startswith("drone.")]   # (read into a config that only [drone] was taken from)
    if other:
        raise CliError(f"--set {other[0]} is not used by calibrate: it fits the [drone] power model; valid: drone.* "
                       "keys (e.g. drone.rotor_radius_m=0.12)")
    cfg = config_from_dict(apply_overrides(load_config_dict(args.config), sets))
    out_dir = prepare_out_dir(args.out.parent, "--out folder")
    log = read_log(args.log)
    cal = calibrate_log(log, cfg.drone, mass_kg=args.mass, window=window, segment=args.segment)
    files = []
    stem = args.out.stem
    with atomic_output(out_dir / f"{stem}_samples.csv") as tmp:
        cal.samples.table.to_csv(tmp, index=False)
    files.append(str(out_dir / f"{stem}_samples.csv"))
    if not args.no_plot:
        from ..figures.calibrate import plot_calibration
        files.append(plot_calibration(cal, out_dir / f"{stem}_fit.png", f"{args.log.name}: power model calibration"))
    report = {**cal.report, "drone_toml": str(args.out), "files": files}
    with atomic_output(out_dir / f"{stem}_report.json") as tmp:
        tmp.write_text(json.dumps(_json_safe(report), indent=2))
    files.append(str(out_dir / f"{stem}_report.json"))
    with atomic_output(args.out) as tmp:          # last: its presence means the calibration is complete
        tmp.write_text(drone_toml(cal))
    if args.format == "json":
        print(json.dumps(_json_safe({**report, "files": files})))
        return 0
    _print_calibration(report, args.out, files)
    return 0


def _json_safe(obj):
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if hasattr(obj, "item") and not isinstance(obj, (str, bytes)):
        obj = obj.item()
    return None if isinstance(obj, float) and obj != obj else obj


def _print_calibration(r: dict, out: Path, files) -> None:
    f, d = r["fitted"], r["default"]
    seg = f", boot segment {r['replayed_segment']} of {r['segments']}" if (r.get("segments") or 1) > 1 else ""
    print(f"{r['log']}: {r['n_train_airborne']} airborne battery samples train, {r['n_heldout']} held out "
          f"(from {r['split_t_s']:.1f} s), {r['n_disarmed']} disarmed (avionics){seg}; {r['battery_source']}")
    for name, unit, spec in (("mass_kg", "kg", ".3f"), ("figure_of_merit", "", ".3f"), ("drive_efficiency", "", ".3f"),
                             ("flat_plate_area_m2", "m^2", ".4f"), ("avionics_w", "W", ".2f")):
        print(f"  {name:<20} {f[name]:>10{spec}}  (default {d[name]:{spec}}) {unit}")
    print("  mass " + ("fixed by --mass" if r["mass_fixed"] else "fitted as the equivalent mass (figure of merit held "
                                                               "near 0.6 by a prior: mass and FM trade off in hover)"))
    print(f"held-out energy error: calibrated {100 * r['calibrated_heldout_energy_error_rel']:+.1f} %, default model "
          f"{100 * r['default_heldout_energy_error_rel']:+.1f} %; RMS {r['calibrated_heldout_rms_w']:.0f} W "
          f"(default {r['default_heldout_rms_w']:.0f} W)")
    for w in r.get("warnings", ()):
        print(f"warning: {w}")
    if r["at_bound"]:
        print(f"warning: at a bound of its physical range: {', '.join(r['at_bound'])}")
    print(f"wrote {out} (use: dronewpt mission --drone {out})")
    for path in files:
        print(f"wrote {path}")
