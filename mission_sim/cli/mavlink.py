"""``dronewpt replay`` and ``dronewpt telemetry``: flight logs in, MAVLink telemetry out."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .common import (
    CliError,
    add_progress_flag,
    check_out_file,
    float_arg,
    lazy_names_help,
    mass_override,
    parse_set,
    path_arg,
    peak_i2_line,
    policy_names,
    positive_float,
    prepare_out_dir,
    show_progress,
    write_mission,
)
from .mission import say_pads_note

#: the file ``replay`` (without ``--pads``) writes its summary to, last (present = complete), under ``--out``; the one
#: spelling (``replay --pads``'s: :data:`mission_sim.cli.refly.REFLY_SUMMARY`)
REPLAY_SUMMARY = "replay_summary.json"


def _mav_common(p):
    lazy_names_help(p.add_argument("--policy", default="model_based"), "receiver policy (default model_based)",
                    policy_names)
    p.add_argument("--config", type=path_arg("--config"), default=None, help="mission TOML (default: the embedded mission)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value by dotted key, e.g. --set drone.mass_kg=1.5 (repeatable)")
    p.add_argument("--drone", type=path_arg("--drone"), default=None, metavar="FILE",
                   help="a [drone] TOML (from `dronewpt calibrate`) laid over the config's drone; --set still wins")


def _mav_speed(text):
    """A number (its range is checked by :func:`mission_sim.mavlink.telemetry.check_pacing`)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"speed={text!r} is not a number") from None


def _mav_config(args, overrides=None, single_pad=False):
    """Mission config from --config (with telemetry's --plan / --pads: the mission and pads files), --set and
    ``overrides``; ``single_pad``: one pad at the origin."""
    from ..config import apply_overrides, config_from_dict, load_config_dict
    from .mission import mission_file_keys
    given = parse_set(args.set)
    d, file_keys = load_config_dict(args.config, getattr(args, "plan", None), getattr(args, "mission_pads", None),
                                    mission_file_keys(given), file_keys=True)
    if single_pad:
        d["pads"] = [{"x_m": 0.0, "y_m": 0.0, "z_m": 0.0}]
    drone = {}
    if getattr(args, "drone", None) is not None:
        from ..mavlink.calibrate import read_drone_toml
        drone = read_drone_toml(args.drone)
    cfg = config_from_dict(apply_overrides(d, {**drone, **(overrides or {}), **given}))
    if not single_pad:
        from ..config import check_file_route_keys
        check_file_route_keys(args.config, cfg, file_keys, given)   # (--set's and the file's own: a route flies its
        # own heights; replay's single pad flies the log)
        from .mission import default_pads_notice, note_pads
        note_pads(args, default_pads_notice(getattr(args, "command", "telemetry"), getattr(args, "plan", None),
                                            getattr(args, "mission_pads", None), d, given,
                                            "a config file with your own [[pads]]", cfg))   # said after the checks
    return cfg


def _mav_policy(cfg, name):
    """Policy ``name`` for the mission's link (see :func:`mission_sim.config.policy_context`)."""
    from policies import make

    from ..config import policy_context
    return make(name, policy_context(cfg))


def _mav_json_safe(obj):
    """Plain JSON: numpy scalars to Python, nan / inf to null (not measurable, e.g. no battery data)."""
    if isinstance(obj, dict):
        return {k: _mav_json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_mav_json_safe(v) for v in obj]
    if hasattr(obj, "item") and not isinstance(obj, (str, bytes)):
        obj = obj.item()
    if isinstance(obj, float) and obj != obj or obj in (float("inf"), float("-inf")):
        return None
    return obj


def _add_replay(sub):
    p = sub.add_parser("replay", help="replay a real flight log (.tlog / DataFlash .bin / PX4 .ulg) through the simulator",
                       description="Read a MAVLink telemetry log, an ArduPilot DataFlash log or a PX4 ULog, build the flown "
                                   "track (3D GPS fix only) about a pad, run the mission world along it (Lm(t), "
                                   "SBAR, battery) and compare the logged electrical power with the propulsion "
                                   "power model; with --pads FILE, re-fly it with a detour to each pad and report "
                                   "the flight time gained (docs/mission_files.md).")
    p.add_argument("log", type=path_arg("log"), help="flight log: .tlog, .bin or .ulg")
    p.add_argument("--pad", default=None, metavar="LAT,LON[,ALT]",
                   help="pad position (degrees, degrees, m AMSL); default: the first armed position. "
                        "Write --pad=-35.36,149.16 when the latitude is negative")
    p.add_argument("--out", type=path_arg("--out"), default=Path("out/replay"), help="output folder (default out/replay)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--window", default=None, metavar="T0,T1", help="replay only log seconds T0..T1")
    p.add_argument("--segment", type=int, default=None, metavar="N",
                   help="a log with reboots: replay boot segment N (1-based; default: the one with the most armed time)")
    p.add_argument("--ground-gap", type=float, default=None, metavar="M",
                   help="receiver coil height above the pad coil when landed (default: the nominal hover gap)")
    p.add_argument("--mass", type=positive_float("mass"), default=None, metavar="KG",
                   help="drone mass for the propulsion model (same as --set drone.mass_kg=KG)")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    p.add_argument("--pads", type=Path, default=None, metavar="FILE",
                   help="what-if: re-fly the log with charging pads from this CSV (lat,lon[,alt][,hover_time_s]) "
                        "or GeoJSON file, a detour to each, and report the flight time gained (docs/mission_files.md, "
                        "'What-if re-flight')")
    p.add_argument("--reach", type=float, default=None, metavar="M",
                   help="with --pads: visit only pads within M metres of the airborne track (default 500)")
    add_progress_flag(p)
    _mav_common(p)
    p.set_defaults(func=_cmd_replay)


def _refuse_unused_keys(args) -> None:
    """``CliError`` for a ``--set`` key that replay never reads: the files' keys and the built-in pattern's."""
    from ..config import check_replay_keys
    from ..plans import FILE_READ_KEYS
    given = parse_set(args.set)
    unused = [k for k in given if k in FILE_READ_KEYS]   # (read, then replaced by the log's route)
    if unused:
        raise CliError(f"--set {unused[0]} is not used by replay: the route is the log's, the pads are --pads FILE "
                       "(or --pad); valid: drop it (with pads: --pads FILE)")
    try:   # the built-in pattern's keys (mission.cruise_altitude_m=60 was ignored); one rule with the replay studies'
        check_replay_keys(list(given), args.pads is not None)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def _cmd_replay(args) -> int:
    from ..mavlink.geodesy import parse_geo_point
    from ..files import atomic_output
    from ..mavlink.logs import read_log
    from ..mavlink.replay import parse_window, replay_log, replay_span, track_from_log
    mass_override(args)   # --mass with --set drone.mass_kg: refused before the log is read
    if args.reach is not None and args.pads is None:   # (it was ignored: a replay without pads visits none)
        raise CliError("--reach is only used with --pads; add --pads FILE or drop --reach")
    _refuse_unused_keys(args)
    if getattr(args, "pads", None) is not None:  # what-if re-flight with pads: its own module
        from .refly import cmd_refly
        return cmd_refly(args)
    from ..validation import check_regular_file
    check_regular_file(args.log, "log", "a .tlog, .bin or .ulg file")  # a FIFO: refused without opening it
    pad = parse_geo_point(args.pad) if args.pad is not None else None
    window = parse_window(args.window)
    if args.ground_gap is not None and not (0 <= args.ground_gap <= 1.0):
        raise CliError(f"--ground-gap {args.ground_gap!r} is invalid; valid range: [0, 1] m")
    log = read_log(args.log)
    span, _ = replay_span(log, window, args.segment)
    from ..mavlink.replay import unknown_armed_check
    # no usable position, or the armed state unknown on the ground: one-line error before any simulation
    unknown_armed_check(log, track_from_log(log, pad=pad, window=span))
    cfg = _mav_config(args, mass_override(args), single_pad=True)
    policy = _mav_policy(cfg, args.policy)
    prepare_out_dir(args.out)
    from wpt_receiver.numba_start import cache_loads_without_registries
    cache_loads_without_registries()   # input checked: cached kernels without numba's registries (~0.5-1 s of CPU)
    res = replay_log(log, cfg, policy, pad=pad, ground_gap_m=args.ground_gap, window=window,
                     progress=show_progress(args), segment=args.segment)
    s = res.summary   # its warnings: replay_summary_warnings (the replay studies' n_warnings count the same list)
    from .notices import say_warning
    for w in s.get("warnings", ()):
        say_warning("replay", w)   # (once: the library may have raised it)
    s["log"] = str(args.log)
    s["policy"] = args.policy
    s["drone_mass_kg"] = cfg.drone.mass_kg
    summary = args.out / REPLAY_SUMMARY
    summary.unlink(missing_ok=True)  # written last: present = complete
    files = write_mission(res.mission, args.out / "mission", plots=not args.no_plot, progress=show_progress(args))
    if res.power_table is not None:
        with atomic_output(args.out / "power_comparison.csv") as tmp:
            res.power_table.to_csv(tmp, index=False)
        files.append(str(args.out / "power_comparison.csv"))
    if not args.no_plot:
        from ..figures import replay as replay_figures
        title = f"{args.log.name}: replay, policy {args.policy}"
        files.append(replay_figures.plot_replay(res, args.out / "replay.png", title))
        if res.power_table is not None and len(res.power_table):
            files.append(replay_figures.plot_power_comparison(res, args.out / "power.png", title))
    s["files"] = files
    s = _mav_json_safe(s)
    with atomic_output(summary) as tmp:
        tmp.write_text(json.dumps(s, indent=2, allow_nan=False))
    if args.format == "json":
        print(json.dumps(s, allow_nan=False))
        return 0
    _print_log_facts(args.log.name, s)
    print(f"mission world: rectifier output {s['rectifier_output_j']:.0f} J ({s['battery_charge_in_j']:.0f} J into "
          f"the battery while charging), propulsion {s['propulsion_energy_j']:.0f} J "
          f"(model, {cfg.drone.mass_kg:g} kg drone), final SoC {s['final_soc']:.3f}")
    ms = res.mission.summary
    print(peak_i2_line(s["peak_i2_a"], ms.get("peak_i2_envelope_a"), ms.get("rated_i2_a"), ms.get("time_above_rated_s")))
    c = s.get("power_comparison")
    if c and "logged_mean_w" in c:
        def f(key, spec, scale=1.0):
            return "n/a" if c.get(key) is None else format(scale * c[key], spec)
        print(f"power while airborne, {f('airborne_time_s', '.0f')} s ({c['battery_source']}): logged "
              f"{f('logged_mean_w', '.0f')} W, model {f('model_mean_w', '.0f')} W, RMS error {f('rms_error_w', '.0f')} W, "
              f"energy error {f('energy_error_rel', '+.1f', 100)} %, correlation {f('correlation', '.2f')}; "
              f"best-fit scale {f('best_fit_scale', '.2f')} leaves {f('rms_error_after_scale_w', '.0f')} W RMS; "
              f"the model matches the logged energy at a drone mass of {f('equivalent_mass_kg', '.2f')} kg")
    elif c:
        print(f"no airborne battery samples to compare ({c['battery_source']})")
    elif not s.get("battery_source"):
        from ..mavlink.logs import BATTERY_SOURCES
        print(f"the log has no battery data (no {BATTERY_SOURCES} values with a known voltage and current)")
    for f in [*files, summary]:   # the summary too (written last), as mission lists its
        print(f"wrote {f}")
    return 0


def _print_log_facts(name: str, s: dict) -> None:
    """The replay's first lines: what the log holds, where the armed state came from, what was dropped."""
    rejected = s.get("gps_rejected") or {}
    n_rej = sum(rejected.values())
    detail = f" ({', '.join(f'{k} {v}' for k, v in rejected.items() if v)})" if n_rej else ""
    print(f"{name}: {s['duration_s']:.1f} s logged, {s['n_position_samples']} positions "
          f"({s['bad_frames']} bad frames skipped, {n_rej} implausible GPS fixes rejected{detail}), "
          f"{s['distance_m']:.0f} m flown, max {s['max_alt_m']:.1f} m above the pad")
    if s.get("armed_source"):
        print(f"armed {s['log_armed_time_s']:.1f} s in the log, {s['armed_time_s']:.1f} s in "
              f"{len(s['armed_periods_s'])} period(s) of the replayed track, from {s['armed_source']}"
              + (" (armed from the start of the log)" if s.get("starts_armed") else ""))
    else:   # (no armed time to give: the log says nothing of arming)
        print(f"the armed state is unknown (no armed-state record and no motor output): the whole replayed track, "
              f"{s['flown_time_s']:.1f} s, counted as flown")
    if s.get("segments", 1) > 1:
        seg = s.get("replayed_segment")
        what = f"boot segment {seg} of {s['segments']} replayed" if seg else f"--window within {s['segments']} boot segments"
        print(f"the vehicle rebooted {s['segments'] - 1} time(s): {what}"
              + (f" (log {s['segment_span_s'][0]:.1f}..{s['segment_span_s'][1]:.1f} s)" if seg else ""))
    rates = [c["clock_rate"] for c in s.get("segment_clock", [])]
    if any(abs(r - 1.0) > 1e-3 for r in rates):
        print(f"time base: {s['clock']}; times are the vehicle's seconds")
    if not s.get("flown", True):
        print("NOT FLOWN: the vehicle never armed in the replayed part (distance and height are GPS drift on the ground)")
    for err in s.get("parse_errors") or []:
        print(f"warning: the log could not be parsed to its end: {err}; replayed what was decoded before it")


def _resolve_connect(text: str, timeout_s: float = 5.0) -> str:
    """Check that the host of a ``kind:HOST:PORT`` connection string is a valid IP address or resolves
    (within ``timeout_s``) before anything is simulated; ``CliError`` naming the host otherwise."""
    import ipaddress
    import socket
    import threading

    kind, _, rest = text.partition(":")
    host, _, port = rest.rpartition(":")
    if host.replace(".", "").isdigit():
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            raise CliError(f"--connect {text!r}: {host!r} is not a valid IPv4 address "
                           "(four numbers 0..255)") from None
        return text
    found: list = []

    def look_up():
        try:
            found.append(socket.getaddrinfo(host, int(port), type=socket.SOCK_DGRAM if "udp" in kind else 0))
        except (OSError, UnicodeError) as exc:
            found.append(exc)
    th = threading.Thread(target=look_up, daemon=True)
    th.start()
    th.join(timeout_s)
    if not found:
        raise CliError(f"--connect {text!r}: host {host!r} did not resolve within {timeout_s:g} s")
    if isinstance(found[0], Exception):
        reason = getattr(found[0], "strerror", None) or found[0]
        raise CliError(f"--connect {text!r}: host {host!r} cannot be resolved ({reason})")
    return text


def _add_telemetry(sub):
    p = sub.add_parser("telemetry", help="run a mission and stream it as live MAVLink 2 telemetry",
                       description="Run a mission and send it as an ArduCopter would: HEARTBEAT (1 Hz of simulated "
                                   "time, LOITER over a pad, AUTO in transit), SYS_STATUS, BATTERY_STATUS (charge "
                                   "state), GPS_RAW_INT, GLOBAL_POSITION_INT, ATTITUDE, VFR_HUD and NAMED_VALUE_FLOAT "
                                   "(I2, I1, DUTY, LM_UH, SBAR_MODE, PAD_ON, CHG_CMD, I_RECT; see docs/mavlink.md) so a "
                                   "ground station shows the drone charging.")
    p.add_argument("--connect", default="udpout:127.0.0.1:14550",
                   help="where to send (default udpout:127.0.0.1:14550; 'none' = only --tlog)")
    p.add_argument("--rate", type=positive_float("rate"), default=10.0, help="telemetry rate in Hz (default 10)")
    p.add_argument("--speed", type=_mav_speed, default=None,
                   help="simulated seconds per wall second, 0.001 .. inf (default 1 = real time; inf = as fast as "
                   "possible; not with --follow)")
    p.add_argument("--tlog", type=path_arg("--tlog"), default=None, help="also write the telemetry to this .tlog")
    p.add_argument("--home", default=None, metavar="LAT,LON,ALT",
                   help="where the pad frame's origin is (default: the home of the config's mission file, else the first "
                   "pad of its pads file, else ArduPilot SITL home, CMAC: --home=-35.363261,149.165230,584)")
    p.add_argument("--duration", type=positive_float("duration"), default=None, metavar="S",
                   help="stream at most S simulated seconds (default: the whole mission; not with --follow)")
    from .mission import add_plan_args
    add_plan_args(p, pads_dest="mission_pads")
    p.add_argument("--follow", default=None, metavar="udpin:HOST:PORT",
                   help="drive the simulation from a live vehicle's GLOBAL_POSITION_INT instead of the plan")
    p.add_argument("--follow-time", type=float_arg("follow-time", positive=True, hi=7 * 86400), default=None,
                   metavar="S", help="with --follow: stop after S wall seconds, at most 7 days (default 60)")
    p.add_argument("--follow-idle", type=float_arg("follow-idle", positive=True, hi=86400), default=None, metavar="S",
                   help="with --follow: stop after S seconds without a position once positions have come (before "
                        "the first, it waits up to --follow-time), at most a day (default 10)")
    p.add_argument("--sysid", type=int, default=1, metavar="ID",
                   help="MAVLink system id of the simulated vehicle, 1..255 (default 1; use another beside a SITL vehicle)")
    p.add_argument("--compid", type=int, default=1, metavar="ID",
                   help="MAVLink component id of the simulated vehicle, 1..255 (default 1, the autopilot)")
    p.add_argument("--force", action="store_true", help="run even when the estimated mission size exceeds "
                   "the limit (see dronewpt mission --help)")
    add_progress_flag(p)
    _mav_common(p)
    p.set_defaults(func=_cmd_telemetry)


#: telemetry's options that only one of its two modes reads: (option, default, with --follow?)
_MODE_OPTIONS = (("follow_time", 60.0, True), ("follow_idle", 10.0, True), ("duration", None, False),
                 ("speed", 1.0, False))


def _telemetry_modes(args) -> None:
    """An option the mode does not read is refused (``--follow-time`` without ``--follow``, ``--duration`` /
    ``--speed`` with it: ignored before, exit 0); then the defaults of the ones not given."""
    follows = args.follow is not None
    for dest, default, with_follow in _MODE_OPTIONS:
        value = getattr(args, dest)
        if value is not None and with_follow != follows:
            flag = "--" + dest.replace("_", "-")
            why = ("is only used with --follow; valid: add --follow udpin:HOST:PORT, or drop " + flag if with_follow
                   else "is not used with --follow (the live vehicle sets the pace and the length); valid: drop " + flag)
            raise CliError(f"{flag} {value:g} {why}")
        if value is None:
            setattr(args, dest, default)


def _cmd_telemetry(args) -> int:
    from ..mavlink import telemetry
    from ..mavlink.geodesy import parse_geo_point
    _telemetry_modes(args)
    connect = None if str(args.connect).lower() == "none" else _resolve_connect(telemetry.check_connect(args.connect))
    if connect is None and args.tlog is None:
        raise CliError("--connect none needs --tlog FILE (nothing to send to)")
    if args.tlog is not None:
        check_out_file(args.tlog, "--tlog")  # a folder, an unwritable place: refused before the simulation
    telemetry.check_ids(args.sysid, args.compid)
    telemetry.check_pacing(args.rate, args.speed)   # before the simulation, not after it
    home = parse_geo_point(args.home, "--home") if args.home else telemetry.DEFAULT_HOME
    if home.alt_m is None:
        raise CliError(f"--home {args.home!r} needs an altitude; valid format: LAT,LON,ALT")
    if args.follow is not None:
        return _cmd_telemetry_follow(args, connect, home)
    cfg = _mav_config(args)
    if not args.home:                                   # a mission file places the pad frame on Earth
        from ..plans.route import mission_home
        home = mission_home(cfg.mission) or home
    from ..world.budget import check_run_size
    from ..world.runner import run_mission
    from ..world.trajectory import plan_mission
    check_run_size(cfg, force=args.force, frame=True)   # the stream needs the whole series in memory
    policy = _mav_policy(cfg, args.policy)
    conn = _open_link(connect, args)                    # refused, port taken: said before the simulation
    say_pads_note(args)
    try:
        traj = plan_mission(cfg)
        res = run_mission(cfg, policy, trajectory=traj, progress=show_progress(args),   # cfg's own route
                          own_route=not getattr(args, "pads_noted", False))
        st = telemetry.stream(res.timeseries, conn=conn, rate_hz=args.rate, speed=args.speed, home=home,
                              tlog=args.tlog, duration_s=args.duration, ground_gap_m=cfg.mission.hover_gap_m,
                              track=(traj.t_s, traj.pos_m, traj.tilt_rad), progress=show_progress(args),
                              sysid=args.sysid, compid=args.compid)
    finally:
        if conn is not None:
            telemetry.close_link(conn)
    print(f"sent {st.frames} MAVLink 2 frames in {st.ticks} ticks at {args.rate:g} Hz: {st.sim_s:.1f} s of the "
          f"mission in {st.wall_s:.1f} s wall to {connect or 'no link'}"
          + (f"; wrote {args.tlog}" if args.tlog else ""))
    _warn_undelivered(connect, st.frames, st.delivered)
    if res.summary.get("battery_depleted"):
        from ..world.results import depletion_text
        print(f"dronewpt telemetry: warning: {depletion_text(res.summary)} (the stream ends there)", file=sys.stderr)
    return 0


def _open_link(connect, args):
    """The --connect link opened before any simulation (None for 'none'); CliError naming it."""
    from ..mavlink import telemetry
    if connect is None:
        return None
    try:
        return telemetry.open_link(connect, args.sysid, args.compid)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def _warn_undelivered(connect, frames: int, delivered: int) -> None:
    """Frames that did not reach a ground station on --connect: a listening link (udpin, udp, tcpin) that no
    ground station contacted, a TCP ground station that closed the connection. One warning line."""
    from ..mavlink.telemetry import SERVER_KINDS
    if connect is None or delivered >= frames:
        return
    listens = connect.partition(":")[0] in SERVER_KINDS
    if delivered == 0 and listens:
        what = "it listens and no ground station contacted it, so nothing was delivered"
    else:
        what = (f"{frames - delivered} of the {frames} frames were not delivered ("
                + ("no ground station had contacted it yet)" if listens else
                   "the ground station closed the connection, or read too slowly)"))
    hint = ("; a listening link sends only to a ground station that has sent to it first (QGroundControl and "
            "MAVProxy listen on UDP 14550 themselves: use --connect udpout:HOST:14550)") if listens else ""
    print(f"dronewpt telemetry: warning: --connect {connect}: {what}{hint}", file=sys.stderr)


def _cmd_telemetry_follow(args, connect, home) -> int:
    from ..mavlink import follow, telemetry
    vin = follow.open_follow(args.follow)  # listen first: the set-up below takes a while
    try:
        cfg = _mav_config(args)
        policy = _mav_policy(cfg, args.policy)
        if not args.home:   # a mission or pads file places the pads on Earth; else the first position is the pad
            from ..plans.route import mission_home
            home = mission_home(cfg.mission)
        out = _open_link(connect, args)
    except BaseException:
        vin.close()
        raise
    say_pads_note(args)
    from ..world.runner import run_mission
    try:
        st = follow.follow(args.follow, cfg, policy, run_mission, out_conn=out,
                           rate_hz=args.rate, home=home, tlog=args.tlog,
                           max_wall_s=args.follow_time, idle_timeout_s=args.follow_idle, in_conn=vin,
                           sysid=args.sysid, compid=args.compid)
    finally:
        if out is not None:
            telemetry.close_link(out)
    skipped = (f"{st.rejected} implausible position(s) skipped (the first: {st.first_rejected})" if st.rejected
               else "")
    if st.positions == 0:   # nothing simulated, nothing written (an existing --tlog untouched): said, not exit 0
        if st.rejected:
            raise CliError(f"--follow {args.follow}: no usable position in {st.wall_s:.1f} s: {skipped}; nothing was "
                           "simulated" + (f" and {str(args.tlog)!r} was not written" if args.tlog else "")
                           + "; valid: GLOBAL_POSITION_INT with lat, lon in 1e-7 degrees and alt in mm AMSL")
        raise CliError(f"--follow {args.follow}: no position arrived in {st.wall_s:.1f} s (--follow-time "
                       f"{args.follow_time:g}), nothing was simulated" + (f" and {str(args.tlog)!r} was not written"
                                                                           if args.tlog else "")
                       + "; valid: a vehicle or SITL sending GLOBAL_POSITION_INT with a GPS fix to that address "
                         "(e.g. ArduPilot SITL --out udp:HOST:PORT, MAVProxy --out udpout:HOST:PORT)")
    print(f"followed {st.positions} live positions over {st.wall_s:.1f} s in {st.chunks} chunk(s); sent "
          f"{st.frames} frames to {connect or 'no link'}" + (f"; wrote {args.tlog}" if args.tlog else ""))
    _warn_undelivered(connect, st.frames, st.delivered)
    if skipped:
        print(f"dronewpt telemetry: warning: --follow {args.follow}: {skipped}", file=sys.stderr)
    return 0
