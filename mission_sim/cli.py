"""The ``dronewpt`` command line: parse, call, print. Subcommands import what they need lazily."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["main"]


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def _float_arg(name, positive=False, lo=0.0, hi=float("inf")):
    """argparse type: a finite float (in ``[lo, hi]`` and > 0 if ``positive``), errors naming the value and range."""
    if positive:
        valid = f"[{lo:g}, {hi:g}]" if lo > 0 else (f"(0, {hi:g}]" if hi < float("inf") else "(0, inf)")
    else:
        valid = "finite"

    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not a number") from None
        if v != v or abs(v) == float("inf") or (positive and not (0 < v <= hi and v >= lo)):
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: {valid}")
        return v
    return conv


def _positive_float(name):
    return _float_arg(name, positive=True)


def _finite_float(name):
    return _float_arg(name)


# ----------------------------------------------------------------------------- paper
def _add_paper(sub):
    p = sub.add_parser("paper", help="reproduce the paper's Table II and Fig. 6",
                       description="Run the step, ramp and proposed V2* trajectories (RM -> SM) on the "
                                   "Table I link, print Table II beside the paper's, write Fig. 6 as PNG.")
    p.add_argument("--model", default="envelope", help="plant model: envelope (default) or switching")
    p.add_argument("--out", type=Path, default=Path("out/paper"), help="folder for the figures (default out/paper)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--control-period", type=_float_arg("control-period", positive=True, lo=1e-7, hi=1e-3), default=None,
                   help="controller update period in s, 1e-7 .. 1e-3 (default: rectifier period 1/(2f))")
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
    final_src = "the closed-form SM current" if args.model == "envelope" else f"the {args.model} model's final amplitude"
    print(f"overshoot = (max - final) / final; the paper's final value is 10.5 A, ours is {final_src}")
    for f in figs:
        print(f"figure: {f}")
    return 0


# ----------------------------------------------------------------------------- replay / telemetry (MAVLink)
def _mav_common(p):
    p.add_argument("--policy", default="model_based", help="receiver policy (default model_based)")
    p.add_argument("--config", type=Path, default=None, help="mission TOML (default: the embedded mission)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value by dotted key, e.g. --set drone.mass_kg=1.5 (repeatable)")


def _mav_speed(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"speed={text!r} is not a number") from None
    if not v > 0:  # also rejects nan
        raise argparse.ArgumentTypeError(f"speed={text!r} is invalid; valid range: (0, inf] (inf = as fast as possible)")
    return v


def _mav_config(args, overrides=None, single_pad=False):
    """Mission config from --config, --set and ``overrides``; ``single_pad``: one pad at the origin."""
    from .config import apply_overrides, config_from_dict, config_to_dict, load_config
    d = config_to_dict(load_config(args.config))
    if single_pad:
        d["pads"] = [{"x_m": 0.0, "y_m": 0.0, "z_m": 0.0}]
    return config_from_dict(apply_overrides(d, {**(overrides or {}), **_parse_set(args.set)}))


def _mav_policy(cfg, name):
    """Policy ``name`` for the mission's link (see :func:`mission_sim.config.policy_context`)."""
    from policies import make

    from .config import policy_context
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
    p = sub.add_parser("replay", help="replay a real flight log (.tlog / DataFlash .bin) through the simulator",
                       description="Read a MAVLink telemetry log or an ArduPilot DataFlash log, build the flown "
                                   "track (3D GPS fix only) about a pad, run the mission world along it (Lm(t), "
                                   "SBAR, battery) and compare the logged electrical power with the propulsion "
                                   "power model.")
    p.add_argument("log", type=Path, help="flight log: .tlog or .bin")
    p.add_argument("--pad", default=None, metavar="LAT,LON[,ALT]",
                   help="pad position (degrees, degrees, m AMSL); default: the first armed position. "
                        "Write --pad=-35.36,149.16 when the latitude is negative")
    p.add_argument("--out", type=Path, default=Path("out/replay"), help="output folder (default out/replay)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--window", default=None, metavar="T0,T1", help="replay only log seconds T0..T1")
    p.add_argument("--ground-gap", type=float, default=None, metavar="M",
                   help="receiver coil height above the pad coil when landed (default: the nominal hover gap)")
    p.add_argument("--mass", type=_positive_float("mass"), default=None, metavar="KG",
                   help="drone mass for the propulsion model (same as --set drone.mass_kg=KG)")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    _mav_common(p)
    p.set_defaults(func=_cmd_replay)


def _cmd_replay(args) -> int:
    from .geodesy import parse_geo_point
    from .mavlink_io import read_log
    from .replay import parse_window, replay_log, track_from_log
    if not args.log.is_file():
        raise CliError(f"log {str(args.log)!r} does not exist or is not a file")
    pad = parse_geo_point(args.pad) if args.pad is not None else None
    window = parse_window(args.window)
    if args.ground_gap is not None and not (0 <= args.ground_gap <= 1.0):
        raise CliError(f"--ground-gap {args.ground_gap!r} is invalid; valid range: [0, 1] m")
    log = read_log(args.log)
    track_from_log(log, pad=pad, window=window)  # no usable position: one-line error before any simulation
    cfg = _mav_config(args, {"drone.mass_kg": args.mass} if args.mass else None, single_pad=True)
    policy = _mav_policy(cfg, args.policy)
    res = replay_log(log, cfg, policy, pad=pad, ground_gap_m=args.ground_gap, window=window,
                     progress=args.progress)
    s = res.summary
    s["log"] = str(args.log)
    s["policy"] = args.policy
    s["drone_mass_kg"] = cfg.drone.mass_kg
    args.out.mkdir(parents=True, exist_ok=True)
    files = [str(f) for f in res.mission.write(args.out / "mission", figures=not args.no_plot)]
    if res.power_table is not None:
        res.power_table.to_csv(args.out / "power_comparison.csv", index=False)
        files.append(str(args.out / "power_comparison.csv"))
    if not args.no_plot:
        from . import replay_figures
        title = f"{args.log.name}: replay, policy {args.policy}"
        files.append(replay_figures.plot_replay(res, args.out / "replay.png", title))
        if res.power_table is not None and len(res.power_table):
            files.append(replay_figures.plot_power_comparison(res, args.out / "power.png", title))
    s["files"] = files
    s = _mav_json_safe(s)
    (args.out / "replay_summary.json").write_text(json.dumps(s, indent=2, allow_nan=False))
    if args.format == "json":
        print(json.dumps(s, allow_nan=False))
        return 0
    print(f"{args.log.name}: {s['duration_s']:.1f} s logged, {s['n_position_samples']} positions "
          f"({s['bad_frames']} bad frames skipped), {s['distance_m']:.0f} m flown, max {s['max_alt_m']:.1f} m "
          f"above the pad, armed {s['armed_time_s']:.1f} s in {len(s['armed_periods_s'])} period(s)")
    print(f"mission world: {s['energy_to_battery_j']:.0f} J to the battery, propulsion {s['propulsion_energy_j']:.0f} J "
          f"(model, {cfg.drone.mass_kg:g} kg drone), final SoC {s['final_soc']:.3f}")
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
        print("the log has no battery data (no SYS_STATUS / BATTERY_STATUS / CURR / BAT values)")
    for f in files:
        print(f"wrote {f}")
    return 0


def _add_telemetry(sub):
    p = sub.add_parser("telemetry", help="run a mission and stream it as live MAVLink 2 telemetry",
                       description="Run a mission and send HEARTBEAT, SYS_STATUS, BATTERY_STATUS (charge state), "
                                   "GLOBAL_POSITION_INT, GPS_RAW_INT and NAMED_VALUE_FLOAT (I2, d_short, Lm [uH]) "
                                   "so a ground station shows the drone charging.")
    p.add_argument("--connect", default="udpout:127.0.0.1:14550",
                   help="where to send (default udpout:127.0.0.1:14550; 'none' = only --tlog)")
    p.add_argument("--rate", type=_positive_float("rate"), default=10.0, help="telemetry rate in Hz (default 10)")
    p.add_argument("--speed", type=_mav_speed, default=1.0,
                   help="simulated seconds per wall second (default 1 = real time; inf = as fast as possible)")
    p.add_argument("--tlog", type=Path, default=None, help="also write the telemetry to this .tlog")
    p.add_argument("--home", default=None, metavar="LAT,LON,ALT",
                   help="where the first pad is (default ArduPilot SITL home, CMAC: --home=-35.363261,149.165230,584)")
    p.add_argument("--duration", type=_positive_float("duration"), default=None, metavar="S",
                   help="stream at most S simulated seconds (default: the whole mission)")
    p.add_argument("--follow", default=None, metavar="udpin:HOST:PORT",
                   help="drive the simulation from a live vehicle's GLOBAL_POSITION_INT instead of the plan")
    p.add_argument("--follow-time", type=_positive_float("follow-time"), default=60.0, metavar="S",
                   help="with --follow: stop after S wall seconds (default 60)")
    p.add_argument("--follow-idle", type=_positive_float("follow-idle"), default=10.0, metavar="S",
                   help="with --follow: stop after S seconds without a position (default 10)")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    _mav_common(p)
    p.set_defaults(func=_cmd_telemetry)


def _cmd_telemetry(args) -> int:
    from . import telemetry
    from .geodesy import parse_geo_point
    connect = None if str(args.connect).lower() == "none" else telemetry.check_connect(args.connect)
    if connect is None and args.tlog is None:
        raise CliError("--connect none needs --tlog FILE (nothing to send to)")
    home = parse_geo_point(args.home, "--home") if args.home else telemetry.DEFAULT_HOME
    if home.alt_m is None:
        raise CliError(f"--home {args.home!r} needs an altitude; valid format: LAT,LON,ALT")
    if args.follow is not None:
        return _cmd_telemetry_follow(args, connect, home)
    cfg = _mav_config(args)
    from .runner import run_mission
    from .trajectory import plan_mission
    traj = plan_mission(cfg)
    res = run_mission(cfg, _mav_policy(cfg, args.policy), trajectory=traj, progress=args.progress)
    st = telemetry.stream(res.timeseries, connect=connect, rate_hz=args.rate, speed=args.speed, home=home,
                          tlog=args.tlog, duration_s=args.duration, ground_gap_m=cfg.mission.hover_gap_m,
                          track=(traj.t_s, traj.pos_m), progress=args.progress)
    print(f"sent {st.frames} MAVLink 2 frames in {st.ticks} ticks at {args.rate:g} Hz: {st.sim_s:.1f} s of the "
          f"mission in {st.wall_s:.1f} s wall to {connect or 'no link'}"
          + (f"; wrote {args.tlog}" if args.tlog else ""))
    return 0


def _cmd_telemetry_follow(args, connect, home) -> int:
    from . import follow
    vin = follow.open_follow(args.follow)  # listen first: the set-up below takes a while
    cfg = _mav_config(args)
    from .runner import run_mission
    st = follow.follow(args.follow, cfg, _mav_policy(cfg, args.policy), run_mission, connect=connect,
                          rate_hz=args.rate, home=home if args.home else None, tlog=args.tlog,
                          max_wall_s=args.follow_time, idle_timeout_s=args.follow_idle, in_conn=vin)
    print(f"followed {st.positions} live positions over {st.wall_s:.1f} s in {st.chunks} chunk(s); sent "
          f"{st.frames} frames to {connect or 'no link'}" + (f"; wrote {args.tlog}" if args.tlog else ""))
    return 0


# ----------------------------------------------------------------------------- coupling
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
    if args.config is not None:
        d = mconfig.layer_on_default(d)
    overrides = _parse_set(args.set)
    cfg = mconfig.config_from_dict(mconfig.apply_overrides(d, overrides) if overrides else d)
    if args.policy.partition(":")[0] not in policies.available():
        raise CliError(f"--policy {args.policy!r} is invalid; valid values: "
                       f"{', '.join(policies.available())} (or rl:PATH)")
    pol = policies.make(args.policy, mconfig.policy_context(cfg))
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

# ----------------------------------------------------------------------------- train
def _add_train(sub):
    p = sub.add_parser("train", help="train an RL mode-switching policy (stable-baselines3)",
                       description="Train PPO or SAC on dronewpt/SbarCharging-v0 or DQN on the discrete "
                                   "(ON-OFF) variant; writes the model zip, its metadata JSON with the "
                                   "observation normalisation statistics, Monitor CSVs and a learning curve PNG.")
    p.add_argument("--algo", choices=("ppo", "sac", "dqn"), required=True)
    p.add_argument("--timesteps", type=int, required=True, help="environment steps to train for")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-envs", type=int, default=1, help="parallel environments (default 1)")
    p.add_argument("--scenario", default="random", help="training scenario (default random: domain randomisation)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_train)


def _cmd_train(args) -> int:
    if args.timesteps < 1:
        raise CliError(f"--timesteps {args.timesteps} is invalid; valid range: >= 1")
    if not 1 <= args.n_envs <= 256:
        raise CliError(f"--n-envs {args.n_envs} is invalid; valid range: 1..256")
    from policies import require_sb3
    require_sb3()
    from policies.train import train
    res = train(args.algo, args.timesteps, args.out, seed=args.seed, n_envs=args.n_envs, scenario=args.scenario,
                progress=not args.no_progress)
    for key, path in res.items():
        print(f"{key}: {path}")
    return 0


# ----------------------------------------------------------------------------- compare
def _add_compare(sub):
    p = sub.add_parser("compare", help="compare mode-switching policies head to head",
                       description="Run every policy through the same closed loop on the same seeded charging "
                                   "windows (batched env) and print peak I2, overshoot, time above rated, "
                                   "energy, tracking error, cost and return; writes a figure of the "
                                   "RM -> SM transitions.")
    p.add_argument("--policies", default=None,
                   help="comma-separated policy names (default: step,ramp,hysteresis,model_based,"
                        "model_based_online,rl,random); rl:PATH loads a model trained with `dronewpt train`")
    p.add_argument("--scenarios", default=None, help="comma-separated scenarios (default: nominal,lm_mismatch,"
                   "windy,battery)")
    p.add_argument("--episodes", type=int, default=20, help="episodes per scenario (default 20)")
    p.add_argument("--seed", type=int, default=1000, help="seed of episode 0 (episode i uses seed + i)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--out", type=Path, default=Path("out/compare"), help="folder for the figure")
    p.add_argument("--no-plot", action="store_true", help="skip the figure")
    p.set_defaults(func=_cmd_compare)


def _cmd_compare(args) -> int:
    from envs import SCENARIOS
    from policies import available
    from policies.compare import DEFAULT_POLICIES, DEFAULT_SCENARIOS, compare, plot_transitions

    pols = tuple(x.strip() for x in args.policies.split(",") if x.strip()) if args.policies else DEFAULT_POLICIES
    scns = tuple(x.strip() for x in args.scenarios.split(",") if x.strip()) if args.scenarios else DEFAULT_SCENARIOS
    for p_ in pols:
        if p_.split(":", 1)[0] not in available():
            raise CliError(f"--policies {p_!r} is invalid; valid values: {', '.join(available())} (or rl:PATH)")
    if any(p_.split(":", 1)[0] == "rl" for p_ in pols):
        from policies import require_sb3
        require_sb3()
    for s_ in scns:
        if s_ not in SCENARIOS:
            raise CliError(f"--scenarios {s_!r} is invalid; valid values: {', '.join(SCENARIOS)}")
    if not 1 <= args.episodes <= 100_000:
        raise CliError(f"--episodes {args.episodes} is invalid; valid range: 1..100000")
    rows, traces = compare(pols, scns, args.episodes, args.seed, progress=args.format == "table")
    figs = []
    if not args.no_plot:
        args.out.mkdir(parents=True, exist_ok=True)
        figs.append(str(plot_transitions(traces, scns[0], args.out / f"transitions_{scns[0]}.png")))
    if args.format == "json":
        print(json.dumps({"episodes": args.episodes, "seed": args.seed, "rows": rows, "figures": figs}))
        return 0
    print(f"{args.episodes} episodes per scenario, seeds {args.seed}..{args.seed + args.episodes - 1}, "
          "means over episodes (peak max = worst episode)")
    hdr = (f"{'scenario':<12} {'policy':<20} {'peak I2':>8} {'peak max':>8} {'overshoot':>9} {'>rated':>8} "
           f"{'energy':>7} {'after':>7} {'track':>6} {'cost':>7} {'return':>8}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        print(f"{r['scenario']:<12} {r['policy'][:20]:<20} {r['peak_i2_a']:>6.2f} A {r['peak_i2_max_a']:>6.2f} A "
              f"{r['overshoot_pct']:>7.1f} % {r['time_above_rated_s'] * 1e3:>5.2f} ms {r['energy_j']:>5.2f} J "
              f"{r['energy_after_stop_j']:>5.2f} J "
              f"{r['tracking_rmse_a']:>4.2f} A {r['cost']:>7.2f} {r['return']:>8.1f}")
    print("overshoot = (max I2 after the stop - final I2) / final I2; >rated = time with I2 above the rated 15 A; "
          "energy into the battery node (after = of it, after the stop command); track = RMS(I_L - command); "
          "cost = sum of the env's overcurrent cost")
    for f in figs:
        print(f"figure: {f}")
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
    for add in (_add_paper, _add_coupling, _add_mission, _add_replay, _add_telemetry, _add_train, _add_compare, _add_sweep):
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
    except BrokenPipeError:  # output piped into head & co.: not an error of ours
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (CliError, ValueError, FileNotFoundError, OSError) as exc:
        print(f"dronewpt {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"dronewpt {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
