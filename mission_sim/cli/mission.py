"""``dronewpt mission`` (the main job) and ``dronewpt coupling`` (Lm at a pose)."""

from __future__ import annotations

import json
import math
import sys
import tomllib
from pathlib import Path

from ..files import folder_lock
from ..plans import FILE_READ_KEYS
from ..world.results import depletion_text
from .common import (
    CliError,
    add_progress_flag,
    check_out_dir,
    check_out_file,
    finite_float,
    lazy_names_help,
    parse_set,
    path_arg,
    policy_names,
    prepare_out_dir,
    show_progress,
    startup_gc_paused,
)


def _add_coupling(sub):
    p = sub.add_parser("coupling", help="inductances of the default pad/drone coils at a pose",
                       description="L1, L2 and Lm(dx, dy, dz, tilt) of the default coils by Neumann integrals "
                                   "(pad frame, z up; dz = height of the drone coil above the pad coil).")
    p.add_argument("--dx", type=finite_float("dx"), default=0.0, help="lateral offset x [m] (default 0)")
    p.add_argument("--dy", type=finite_float("dy"), default=0.0, help="lateral offset y [m] (default 0)")
    p.add_argument("--dz", type=finite_float("dz"), default=None, help="height above the pad coil [m] "
                   "(default: the nominal hover gap)")
    p.add_argument("--tilt-deg", type=finite_float("tilt-deg"), default=0.0,
                   help="tilt of the drone coil about the y axis [deg] (default 0)")
    p.add_argument("--exact", action="store_true", help="direct Neumann integral instead of the lookup table")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--map", type=path_arg("--map"), default=None, metavar="PNG",
                   help="also write a PNG map of Lm over dx, dy at this dz and tilt")
    p.set_defaults(func=_cmd_coupling)


def _cmd_coupling(args) -> int:
    import math

    from wpt_receiver.coupling import NOMINAL_GAP_M, default_coupling
    m = default_coupling()
    dz = NOMINAL_GAP_M if args.dz is None else args.dz
    try:   # (coils that would touch, a receiver below the pad's plane: the library's rule,
        #    CouplingModel.check_clearance, in the flags' words; lm_h itself computes any pose)
        m.check_clearance(args.dx, args.dy, dz, math.radians(args.tilt_deg), above_pad=True)
    except ValueError as exc:
        from .notices import flag_words
        raise CliError(flag_words("coupling", str(exc))) from None
    if abs(args.tilt_deg) >= 90:
        raise CliError(f"--tilt-deg {args.tilt_deg!r} is invalid; valid range: (-90, 90)")
    tilt = math.radians(args.tilt_deg)
    lm = float((m.lm_exact_h if args.exact else m.lm_h)(args.dx, args.dy, dz, tilt))
    tx, rx = m.turn_positions(args.dx, args.dy, dz, tilt)
    out = {"dx_m": args.dx, "dy_m": args.dy, "dz_m": dz, "tilt_rad": tilt, "lm_h": lm, "l1_h": m.l1_h,
           "l2_h": m.l2_h, "k": float(m.k(lm)), "tx_turns": tx, "rx_turns": rx}
    if args.map is not None:
        from ..figures import mission as mission_figures
        _check_map_path(args.map)
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


def _check_map_path(path: Path) -> None:
    """``--map`` must name a PNG file in a writable folder."""
    check_out_file(path, "--map", ".png")


def _add_mission(sub):
    p = sub.add_parser("mission", help="run a flight mission with in-flight charging (the main job)",
                       description="Simulate a drone mission over charging pads: coupling from the pose, the "
                                   "WPT link, the SBAR policy, battery and propulsion. Without CONFIG the embedded "
                                   "default mission runs. Streams the time series to Parquet as it is produced "
                                   "(CSV with --csv; thinned with --every), writes PNG figures and "
                                   "summary.json (last: its presence means the set is complete) to --out. Exit "
                                   "status 0: done; 2: bad input (one line on stderr); 3: the battery was "
                                   "depleted, the mission ended there (results written).")
    p.add_argument("config", nargs="?", type=path_arg("config file"), default=None, help="mission TOML (default: embedded default)")
    p.add_argument("--config", dest="config_option", type=path_arg("--config"), default=None, metavar="CONFIG",
                   help="the same as CONFIG, as telemetry, calibrate and sizing take it")
    add_plan_args(p)
    lazy_names_help(p.add_argument("--policy", default="model_based"), "receiver policy (default model_based)",
                    policy_names)
    p.add_argument("--out", type=path_arg("--out"), default=Path("out/mission"), help="output folder (default out/mission)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a config value by dotted key, e.g. --set wind.speed_m_s=6 (repeatable)")
    p.add_argument("--drone", type=path_arg("--drone"), default=None, metavar="FILE",
                   help="a [drone] TOML (from `dronewpt calibrate`) laid over the config's drone; --set still wins")
    p.add_argument("--no-charge", action="store_true", help="never energise the pads (baseline mission)")
    p.add_argument("--no-plot", action="store_true", help="skip the figures")
    p.add_argument("--csv", action="store_true", help="also write timeseries.csv (Parquet is always written)")
    p.add_argument("--every", type=finite_float("every"), default=None, metavar="DT",
                   help="store one time-series row per DT seconds of simulated time (0: every step; default: "
                        f"every step unless the run would store more than {MAX_STORED_ROWS:,} rows, then "
                        "thinned to about that many; the summary always uses every step)")
    p.add_argument("--force", action="store_true", help="run even when the estimated memory or output size "
                   "exceeds the limit (1 GiB each; see docs/robustness.md)")
    p.add_argument("--dry-run", action="store_true", help="check the config, the policy and the run size, print "
                   "the size estimate and stop: nothing simulated or written")
    add_progress_flag(p)
    p.set_defaults(func=_cmd_mission)


#: --set keys read together with the mission file (they decide what is read), not laid over it afterwards


def mission_file_keys(overrides: dict) -> dict:
    """The ``[mission]`` keys of ``overrides`` that :func:`mission_sim.config.load_config_dict` reads with the file."""
    return {k.split(".", 1)[1]: v for k, v in overrides.items() if k in FILE_READ_KEYS}


def add_plan_args(p, pads_dest: str = "pads") -> None:
    """``--plan FILE`` and ``--pads FILE``: a mission file and a pads file instead of the config's route."""
    p.add_argument("--plan", type=path_arg("--plan"), default=None, metavar="FILE",
                   help="fly this mission file instead of the config's route: QGroundControl .plan, .waypoints "
                        "(QGC WPL 110), or a flight log (.tlog / .bin: the mission it uploaded, else the track it "
                        "flew); pad frame = ENU about its home (same as [mission] file)")
    p.add_argument("--pads", dest=pads_dest, type=path_arg("--pads"), default=None, metavar="FILE",
                   help="charging pads from a CSV (lat,lon[,alt][,hover_time_s]) or GeoJSON Points file "
                        "(same as [mission] pads_file); a loiter item within mission.pad_radius_m of a pad charges there")


def mission_config(args):
    """Validated MissionConfig from ``args.config`` (None: the embedded default) and ``--set``; the run
    size is checked against the limits unless ``--force`` (see :mod:`mission_sim.world.budget`)."""
    from .. import config as mconfig
    from ..world.budget import check_run_size
    overrides = given = parse_set(args.set)
    if getattr(args, "drone", None) is not None:
        from ..mavlink.calibrate import read_drone_toml
        overrides = {**read_drone_toml(args.drone), **overrides}
    files = mission_file_keys(overrides)
    d, file_keys = mconfig.load_config_dict(args.config, getattr(args, "plan", None), getattr(args, "pads", None),
                                            files, file_keys=True)
    cfg = mconfig.config_from_dict(mconfig.apply_overrides(d, overrides) if overrides else d)
    mconfig.check_file_route_keys(args.config, cfg, file_keys, given)   # (--set's and the file's own: a route flies
    # its own heights)
    note_pads(args, None if getattr(args, "no_charge", False) else   # (pads never energised: nothing to say)
              default_pads_notice(getattr(args, "command", "mission"), getattr(args, "plan", None),
                                  getattr(args, "pads", None), d, overrides, "--no-charge to fly it without charging",
                                  cfg))
    check_run_size(cfg, force=getattr(args, "force", False))
    return cfg


def note_pads(args, note: str | None) -> None:
    """Keep :func:`default_pads_notice`'s ``note`` for :func:`say_pads_note`; ``args.pads_noted``: there is one (the
    run then skips its own warnings about unreached pads)."""
    args.pads_note, args.pads_noted = note, note is not None


def say_pads_note(args) -> None:
    """Print the note kept by :func:`note_pads`, once, when every input has been checked: a refused input is one
    line (a bad ``--policy``, a run too large, an unwritable ``--out`` after the note gave two)."""
    note = getattr(args, "pads_note", None)
    if note is not None:
        print(note, file=sys.stderr)
        args.pads_note = None


def default_pads_notice(command: str, plan, pads, d: dict, overrides: dict, none_hint: str, cfg=None) -> str | None:
    """``--plan`` without ``--pads`` (and no pads of the user's: a config's ``[[pads]]`` or ``pads_file``, a ``--set
    pads.*``): the one line for stderr saying the built-in mission's pads are kept, about the plan's home, which of
    them the plan's route charges at (``cfg``'s, :func:`mission_sim.setup_warnings.energised_pads`: the run's own
    warnings about unreached pads would repeat it; the caller skips them) and how to give one's own or none
    (``none_hint``); None when there is nothing to say. Printed by :func:`say_pads_note` after the checks."""
    if plan is None or pads is not None or any(str(k).startswith("pads.") for k in overrides):
        return None
    from ..config import DEFAULT_MISSION_TOML
    default = tomllib.loads(DEFAULT_MISSION_TOML)["pads"]
    if d.get("pads") != default:
        return None
    where = " and ".join(f"({p.get('x_m', 0.0):g}, {p.get('y_m', 0.0):g})" for p in default)
    reached = ""
    if cfg is not None:
        from ..setup_warnings import energised_pads
        hit = sorted(energised_pads(cfg))
        reached = ("; the plan's route charges at none of them" if not hit else "" if len(hit) == len(default) else
                   f"; the plan's route charges at pad {', '.join(map(str, hit))} only")
    return (f"dronewpt {command}: note: --plan without --pads keeps the built-in mission's {len(default)} pads, at "
            f"{where} m about the plan's home{reached} (a loiter within mission.pad_radius_m of one charges there); "
            f"give your own with --pads FILE (CSV lat,lon[,alt][,hover_time_s] or GeoJSON), or {none_hint}")


def make_policy(name: str, cfg):
    """Policy ``name`` for the mission's link; ``CliError`` naming the valid names."""
    import policies

    from ..config import policy_context
    if name.partition(":")[0] not in policies.available():
        raise CliError(f"--policy {name!r} is invalid; valid values: {', '.join(policies.available())} (or rl:PATH)")
    return policies.make(name, policy_context(cfg))


#: stored time-series rows above which the default ``--every`` thins the series (~70 MB of Parquet)
MAX_STORED_ROWS = 500_000

#: the writer lock of ``mission --out`` (``flock``; the file exists only while a mission runs there)
MISSION_LOCK = ".mission.lock"


def _cmd_mission(args) -> int:
    return startup_gc_paused(_mission_command, args)   # (cli/common.py: the collector off through the start-up)


def _config_option(args) -> None:
    """``--config FILE`` (telemetry's, calibrate's and sizing's spelling; ``mission --config`` was an unrecognized
    argument, 2026-11-28) as the positional CONFIG; both, naming different files: ``CliError``."""
    opt = getattr(args, "config_option", None)
    if opt is None:
        return
    if args.config is not None and Path(args.config).resolve() != Path(opt).resolve():
        raise CliError(f"config {str(args.config)!r} and --config {str(opt)!r} name two mission files; valid: one of them")
    args.config = opt


def _mission_command(args, started) -> int:
    _config_option(args)
    worker = _figure_worker(args)   # first: matplotlib imports in the child while this process checks and runs
    try:
        return _checked_run(args, started, worker)
    finally:
        if worker is not None:
            worker.close(wait_s=0.0)   # bad input, a refused --out, a long mission: ended at once (no-op if reaped)


def _checked_run(args, started, worker) -> int:
    from wpt_receiver.numba_start import prepare

    from ..world import aot
    from ..world.budget import estimate_run
    cfg = mission_config(args)
    pol = make_policy(args.policy, cfg)
    if args.dry_run:
        est = estimate_run(cfg)
        stored_every_s(args.every, est)   # --every checked (and a default thinning said) as the run does
        check_out_dir(args.out)   # a file in --out's place refused as the run refuses it (nothing created)
        say_pads_note(args)
        return _print_estimate(est, args)
    prepare_out_dir(args.out)
    say_pads_note(args)   # (every input checked: a refused one is one line)
    jit = not (aot.enable() and aot.covers(aot.policy_entry(pol)))   # else no numba (mission_sim.world.aot)
    if jit:
        prepare()   # numba's start-up without importing the scipy.linalg package (~0.3 s)
    est = estimate_run(cfg)
    every = stored_every_s(args.every, est)
    started()   # the start-up's objects frozen, the collector back on for the runs (startup_gc_paused)
    with folder_lock(args.out, MISSION_LOCK, f"--out {str(args.out)!r}: another mission is writing there; "
                     "wait for it or use another --out"):  # before any simulation; removed at the end
        if worker is not None and est.rows > FIGURE_WORKER_MAX_ROWS:
            worker.close(wait_s=0.0)   # a long run's memory is not held twice: drawn here after the run
            worker = None
        try:
            res, files = _run_and_write(args, cfg, pol, every, worker, jit)
        finally:
            if worker is not None:
                worker.close()
    return _report(args, res.summary, files)


def _figure_worker(args):
    """A :class:`~mission_sim.figures.worker.FigureWorker` (matplotlib imported in a forked process while
    this one checks its input and runs the mission), forked first thing for a mission with figures (once what
    both processes need is loaded: numpy, the config module, the coil model); None otherwise. The command ends
    it at once when the run does not happen (bad input, a refused ``--out``) and for a long mission (estimated rows above :data:`FIGURE_WORKER_MAX_ROWS`: drawn in process after
    the run, a long run's memory is not doubled by a second process)."""
    from ..figures.worker import FigureWorker, fork_available
    if args.no_plot or args.dry_run or not fork_available():
        return None
    # what both processes need, once before the fork instead of once in each (~0.15 s of CPU; the worker is
    # ready for the data no later, it skips them): numpy, the config module (unpickling the result imports
    # it), the coil model from the disk cache (the run's policy context; the figures' pad radius, L1 and L2)
    from wpt_receiver.coupling import default_coupling

    from .. import config  # noqa: F401
    default_coupling()
    return FigureWorker()


def _run_and_write(args, cfg, pol, every, worker, jit: bool):
    """The run streamed to ``args.out`` (whose writer lock the caller holds), then the figures and
    summary.json; the result and the files written. ``jit``: the run uses numba's JIT (not the loop built
    ahead of time, :mod:`mission_sim.world.aot`)."""
    from wpt_receiver.numba_start import cache_loads_without_registries

    from ..world.runner import run_mission
    from ..world.stream import SeriesWriter
    # every check passed and the figure worker forked: numba (imported by the run anyway) loads the cached
    # kernels without its typing/lowering registries (a cache miss still compiles; wpt_receiver.numba_start)
    if jit:   # (the ahead-of-time build runs it without numba)
        cache_loads_without_registries()
    writer = SeriesWriter(args.out, csv=args.csv, every_s=every, figure_points=None if args.no_plot else FIGURE_POINTS)
    try:
        res = run_mission(cfg, pol, charge=not args.no_charge, progress=show_progress(args),
                          frame=False, sink=writer, own_route=not getattr(args, "pads_noted", False))
        # an earlier run's set stays whole until this one replaces a file (a Ctrl-C in the simulation
        # lost its summary.json); present again only when this run's set is complete
        (args.out / "summary.json").unlink(missing_ok=True)
        files = [str(f) for f in writer.close()]
    except BaseException:
        writer.abort()
        raise
    files += _figures_and_summary(res, args.out, plots=not args.no_plot, thinned=writer.thinned, worker=worker)
    return res, files


def _report(args, s, files) -> int:
    """The summary ``s`` printed (table or JSON); the exit status (3 when the battery ran empty)."""
    if args.format == "json":
        print(json.dumps({**s, "files": files}))
    else:
        _print_mission(s, files)
    if s.get("battery_depleted"):
        print(f"dronewpt mission: {depletion_text(s)}", file=sys.stderr)
        return 3
    return 0


def _print_estimate(est, args) -> int:
    """``--dry-run``: the run-size estimate of the checked mission (table or JSON); exit status 0."""
    out = {"valid": True, "duration_s": est.duration_s, "trajectory_samples": est.samples, "rows": est.rows,
           "memory_bytes": est.memory_bytes, "output_bytes": est.output_bytes, "dominant_key": est.key}
    if args.format == "json":
        print(json.dumps(out))
    else:
        print(f"config valid: {est.duration_s:.1f} s simulated, about {est.rows:.3g} time-series rows, "
              f"~{est.memory_bytes / 1e6:.3g} MB in memory, ~{est.output_bytes / 1e6:.3g} MB of output "
              f"(largest contribution: {est.key}); nothing simulated (--dry-run)")
    return 0


def stored_every_s(every, est) -> float:
    """``--every`` checked (>= 0), or by default 0 (every row) unless the run's estimated rows exceed
    :data:`MAX_STORED_ROWS`: then the interval that stores about that many (said on stderr)."""
    if every is not None:
        if every < 0:
            raise CliError(f"--every {every!r} is invalid; valid range: >= 0 s (0: every step)")
        return float(every)
    if est.rows <= MAX_STORED_ROWS:
        return 0.0
    dt = float(f"{est.duration_s / MAX_STORED_ROWS:.2g}")
    print(f"dronewpt mission: ~{est.rows:,.0f} time-series rows; storing one per {dt:g} s of simulated time "
          "(--every 0 stores every step; the summary uses every step)", file=sys.stderr)
    return dt


#: most time-series points the figures read back from the Parquet file (evenly strided beyond)
FIGURE_POINTS = 20_000

#: estimated rows up to which the figures are drawn by a forked process that imports matplotlib during
#: the run (:mod:`mission_sim.figures.worker`; a run of a few seconds at most)
FIGURE_WORKER_MAX_ROWS = 100_000


def _figures_and_summary(res, out: Path, plots: bool, thinned=None, worker=None) -> list[str]:
    """The figures (from ``thinned``, the writer's bounded copy of the stored series, or else the stored
    series read back and thinned to :data:`FIGURE_POINTS`; drawn by ``worker`` if given, else here) and
    ``summary.json`` last (atomically); their paths."""
    from ..files import atomic_output
    files = []
    if plots and (out / "timeseries.parquet").exists():
        from ..figures.worker import FigureWorkerLost, for_figures
        from ..world.stream import read_series
        res.timeseries = thinned.frame(pandas=False) if thinned is not None else \
            read_series(out / "timeseries.parquet", max_points=FIGURE_POINTS, frame=False)
        try:
            files = [] if worker is None else [str(f) for f in worker.draw(for_figures(res), out)]
        except FigureWorkerLost:   # the child died (killed, out of memory): nothing is lost, draw here
            worker = None
        if worker is None:
            from ..figures.mission import plot_mission
            files = [str(f) for f in plot_mission(for_figures(res), out)]
        res.timeseries = None
    with atomic_output(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(res.summary, indent=2))
    return files + [str(out / "summary.json")]


def _rating_row(s: dict) -> list[tuple[str, str, str]]:
    """The rectifier's continuous current rating beside the peak, and what ``dronewpt sizing`` asks of it (the rule:
    ``wpt_receiver.sizing.SizingRules.required_rating_a``); a part below it gets a note in the same row, by how much
    and that the rule is conservative (it compares a millisecond peak with the part's average rating I_F(AV)), not a
    warning (:func:`wpt_receiver.sizing.rating_shortfall`: the default mission's 30CTT045, 1.64 A short); none for
    ideal devices (no parts)."""
    if s.get("rectifier_rating_a") is None:
        return []
    from wpt_receiver.sizing import SizingRules, rating_shortfall
    rules = SizingRules(margin=SizingRules.margin)   # (the class's margin: a patched one moves the row)
    text = (f"A continuous, {s['rectifier_rating_part']} (peak I2 {s['peak_i2_a']:.2f} A; dronewpt sizing requires "
            f"a rating >= {rules.margin:g} x peak = {rules.required_rating_a(s['peak_i2_a']):.2f} A)")
    short = rating_shortfall(s["devices"], s["peak_i2_a"], rules)
    if short is not None:
        text += (f"; note: {short['shortfall_a']:.2f} A ({100 * short['shortfall_rel']:.1f} %) below dronewpt sizing's "
                 f"rule ({rules.margin:g} x peak against the part's average rating, conservative): "
                 f"dronewpt sizing --source mission parallels {math.ceil(short['required_a'] / short['rating_a'])} "
                 "legs")
    return [("rectifier current rating", f"{s['rectifier_rating_a']:g}", text)]


def _payload_rows(s: dict) -> list:
    """The payload's rows (a mission with ``drone.payload_kg`` > 0): the masses, and the propulsion energy before
    and after the first release that dropped payload."""
    if "takeoff_mass_kg" not in s:
        return []
    n = s["payload_releases"]
    when = (f"{n} release{'s' if n > 1 else ''}, the first at t = {s['first_release_t_s']:.1f} s" if n else
            "never released")
    rows = [("mass take-off -> landing", f"{s['takeoff_mass_kg']:g} -> {s['landing_mass_kg']:g}", f"kg ({when})")]
    if "propulsion_energy_after_release_j" in s:
        rows.append(("propulsion before / after drop", f"{s['propulsion_energy_before_release_j']:.1f} / "
                     f"{s['propulsion_energy_after_release_j']:.1f}", "J"))
    return rows


def _print_mission(s: dict, files) -> None:
    rows = [
        ("policy", s["policy"], ""),
        ("simulated time", f"{s['sim_time_s']:.1f}", "s"),
        ("wall time", f"{s['wall_s']:.3f}", f"s ({s['realtime_factor']:.0f}x real time)"),
        ("energy from the pads", f"{s['energy_from_source_j']:.1f}", "J"),
        ("rectifier DC output", f"{s['rectifier_output_j']:.1f}",
         f"J (DC-to-battery-node efficiency {100 * s['dc_to_battery_efficiency']:.2f} %)"),
        ("into the battery (charging)", f"{s['battery_charge_in_j']:.1f}", "J (gross)"),
        ("losses (coils + devices + battery)", f"{s['losses_j']:.1f}",
         f"J ({s['coil_losses_j']:.1f} + {s['device_losses_j']:.1f} + {s['battery_losses_j']:.1f})"),
        ("device losses", f"{s['device_losses_j']:.1f}",
         f"J ({s['devices']}: inverter switches {s['inverter_switches_loss_j']:.1f}, rectifier diodes "
         f"{s['rectifier_diodes_loss_j']:.1f}, rectifier switches {s['rectifier_switches_loss_j']:.1f})"),
        ("propulsion energy", f"{s['propulsion_energy_j']:.1f}", "J"),
        *_payload_rows(s),
        ("energy balance error", f"{s['energy_balance_error_rel']:.2e}", "relative"),
        ("SoC start -> end", f"{s['initial_soc']:.4f} -> {s['final_soc']:.4f}",
         f"(without charging {s['final_soc_without_charging']:.4f}; full: {s['battery_full']})"),
        ("peak I2", f"{s['peak_i2_a']:.2f}",
         f"A instantaneous (envelope {s['peak_i2_envelope_a']:.2f} A; rated {s['rated_i2_a']:g} A)"),
        ("time above rated", f"{s['time_above_rated_s'] * 1e3:.2f}", "ms"),
        *_rating_row(s),
        ("pad on", f"{s['charge_time_s']:.1f}", "s"),
        ("flight time gain", f"{s['flight_time_gain_s']:.1f}", "s of hover"),
        ("steps fine / coarse", f"{s['fine_steps']} / {s['coarse_steps']}", f"({s['fine_windows']} fine windows)"),
    ]
    if s.get("battery_depleted"):
        rows.append(("BATTERY DEPLETED", depletion_text(s), ""))
    w = max(len(r[0]) for r in rows)
    for name, val, unit in rows:
        print(f"{name:<{w}}  {val:>24}  {unit}")
    for f in files:
        print(f"wrote: {f}")
