"""``dronewpt sweep``: parameter studies on Dask."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .common import CliError, add_progress_flag, nonneg_int, positive_float, show_progress


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
    p.add_argument("--connect-timeout", type=positive_float("connect-timeout"), default=10.0, metavar="S",
                   help="seconds to wait for --scheduler (default 10)")
    p.add_argument("--workers", type=nonneg_int("workers"), default=None, metavar="N",
                   help="worker processes of the local cluster (default: one per CPU; 0 = run serially "
                        "in this process without Dask)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.add_argument("--no-plot", action="store_true", help="skip the PNG plots")
    add_progress_flag(p)
    p.set_defaults(func=_cmd_sweep)


def _check_scheduler_address(address: str) -> None:
    """A malformed ``--scheduler`` fails here with one line: once a ``distributed.Client`` is half built
    its ``__del__`` prints "Exception ignored ..." and a traceback after our error."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import backends
    try:
        scheme, loc = parse_address(address)
        if scheme not in backends:
            raise ValueError(f"unknown scheme {scheme!r}; known: {', '.join(sorted(backends))}")
        if scheme in ("tcp", "tls", "ws", "wss"):
            port = parse_host_port(loc)[1]
            if not 0 < int(port) < 65536:
                raise ValueError(f"port {port} is not in 1..65535")
    except (ValueError, TypeError) as exc:
        raise CliError(f"--scheduler {address!r} is invalid ({exc}); valid format: tcp://HOST:PORT") from None


def _cmd_sweep(args) -> int:
    import signal

    import pandas as pd

    from ..studies import report as sweep_report
    from ..studies import study as study_mod
    from ..studies import sweep

    if args.scheduler is not None:
        _check_scheduler_address(args.scheduler)
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
        res = sweep.run_sweep(cases, runner, args.out, client_factory=factory, progress=show_progress(args),
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
