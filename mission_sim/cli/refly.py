"""``dronewpt replay LOG --pads FILE``: the what-if re-flight (:mod:`mission_sim.plans.refly`).

Reached from ``replay`` (``cli/mavlink.py``) by one hook when ``--pads`` is given; shares its
options (``--pad`` sets the frame origin, ``--window``, ``--segment``, ``--ground-gap``, ``--mass``,
``--config``, ``--drone``, ``--set``, ``--policy``) and adds ``--reach``. Without ``--window`` or
``--segment`` the whole log is re-flown (reboots included; ``replay`` without pads picks a segment).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .common import CliError, mass_override, parse_set, peak_i2_line, prepare_out_dir, show_progress, write_mission

__all__ = ["cmd_refly", "REFLY_SUMMARY"]

#: the file ``replay --pads`` writes its summary to, last (present = complete), under ``--out``; the one spelling
REFLY_SUMMARY = "refly_summary.json"


def _config(args, track):
    """The replay's mission config with the pads of ``--pads`` about the replay's frame origin, the
    ``--drone`` file, ``--mass`` and ``--set`` laid over it (as ``replay`` without pads does)."""
    from ..config import apply_overrides, config_from_dict, config_to_dict, load_config
    from ..plans.pads import read_pads
    from ..plans.refly import refly_base
    d = refly_base(config_to_dict(load_config(args.config)), read_pads(args.pads), track.pad, Path(args.pads).name)
    drone = {}
    if args.drone is not None:
        from ..mavlink.calibrate import read_drone_toml
        drone = read_drone_toml(args.drone)
    return config_from_dict(apply_overrides(d, {**drone, **mass_override(args), **parse_set(args.set)}))


def cmd_refly(args) -> int:
    """Check the inputs (one-line errors), re-fly the log with the pads, write the summary, the
    re-flight's mission files and the figure, print the gains."""
    from ..files import atomic_output
    from ..mavlink.geodesy import parse_geo_point
    from ..mavlink.logs import read_log
    from ..mavlink.replay import parse_window, track_from_log
    from ..plans.refly import plan_refly, refly_log
    from .mission import make_policy
    if not args.log.is_file():
        raise CliError(f"log {str(args.log)!r} does not exist or is not a file")
    if args.reach is None:
        from ..plans.refly import DEFAULT_REACH_M
        args.reach = DEFAULT_REACH_M
    if not (args.reach > 0):
        raise CliError(f"--reach {args.reach!r} is invalid; valid range: (0, inf) m")
    pad = parse_geo_point(args.pad) if args.pad is not None else None
    window = parse_window(args.window)
    if args.ground_gap is not None and not (0 <= args.ground_gap <= 1.0):
        raise CliError(f"--ground-gap {args.ground_gap!r} is invalid; valid range: [0, 1] m")
    log = read_log(args.log)
    if args.segment is not None:   # a log with reboots: re-fly boot segment N alone (no --window)
        from ..mavlink.replay import replay_span
        window = replay_span(log, window, args.segment)[0]
    track = track_from_log(log, pad=pad, window=window)
    from ..mavlink.replay import unknown_armed_check
    unknown_armed_check(log, track)   # the armed state unknown and the track on the ground: refused, as replay does
    cfg = _config(args, track)
    policy = make_policy(args.policy, cfg)
    plan = plan_refly(log, cfg, pad=track.pad, ground_gap_m=args.ground_gap, window=window, reach_m=args.reach,
                      track=track)   # errors first; the logged track made once, here
    prepare_out_dir(args.out)
    res = refly_log(log, cfg, policy, pad=track.pad, ground_gap_m=args.ground_gap, window=window,
                    reach_m=args.reach, progress=show_progress(args), plan=plan)
    s = {**res.summary, "policy": args.policy, "drone_mass_kg": cfg.drone.mass_kg, "pads_file": str(args.pads)}
    summary = args.out / REFLY_SUMMARY
    summary.unlink(missing_ok=True)  # written last: present = complete
    files = write_mission(res.refly, args.out / "refly", plots=False)
    if not args.no_plot:
        from ..figures.refly import plot_refly
        files.append(plot_refly(res, args.out / "refly.png", f"{args.log.name}: re-flown with pads from {args.pads.name}"))
    s["files"] = files
    with atomic_output(summary) as tmp:
        tmp.write_text(json.dumps(s, indent=2, allow_nan=False, default=float))
    from .notices import say_warning
    for w in s["warnings"]:
        say_warning("replay", w)   # (once: the library may have raised it)
    if args.format == "json":
        print(json.dumps(s, allow_nan=False, default=float))
        return 0
    _print(args, s, cfg, summary)
    return 0


def _print(args, s: dict, cfg, summary: Path) -> None:
    for k in s["skipped_pads"]:
        print(f"dronewpt replay: warning: pad {k['pad']} is {k['distance_m']:.0f} m from the airborne track "
              f"(--reach {args.reach:g} m): not visited", file=sys.stderr)
    print(f"{args.log.name}: re-flown with {len(s['detours'])} pad detour(s) ({cfg.drone.mass_kg:g} kg model drone, "
          f"policy {args.policy}):")
    for d in s["detours"]:
        p = s["pads"][d["pad"]]
        print(f"  pad {d['pad']} at ({p['x_m']:.1f}, {p['y_m']:.1f}) m: from log t = {d['from_log_t_s']:.0f} s, "
              f"{d['distance_m']:.1f} m off the track, {d['hover_s']:g} s charging hover")
    print(f"flight {s['logged_flight_time_s']:.0f} s logged -> {s['refly_time_s']:.0f} s re-flown "
          f"(+{s['detour_time_s']:.0f} s of detours, {s['detour_propulsion_j'] / 1e3:+.1f} kJ propulsion)")
    print(f"pads on {s['charge_time_s']:.0f} s: {s['energy_from_pads_j'] / 1e3:.1f} kJ from the pads, "
          f"{s['battery_charge_in_j'] / 1e3:.1f} kJ into the battery; "
          + peak_i2_line(s["peak_i2_a"], s.get("peak_i2_envelope_a"), s.get("rated_i2_a"),
                         s.get("time_above_rated_s")))
    print(f"final SoC {s['final_soc_logged_flight']:.3f} logged flight -> {s['final_soc_refly']:.3f} re-flight "
          f"({s['final_soc_refly_without_charging']:.3f} with the pads off)")
    print(f"flight time gain {s['flight_time_gain_s']:+.1f} s of hover against the logged flight "
          f"({s['net_battery_energy_gain_j'] / 1e3:+.2f} kJ usable battery energy), "
          f"{s['flight_time_gain_vs_refly_without_charging_s']:+.1f} s against the same re-flight with the pads off")
    for f in [*s["files"], summary]:   # the summary too (written last), as mission lists its
        print(f"wrote {f}")
