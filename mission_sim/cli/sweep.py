"""``dronewpt sweep``: parameter studies on Dask."""

from __future__ import annotations

import dataclasses
import functools
import json
import sys
from pathlib import Path

from ..studies import DEFAULT_MAX_CASES
from .common import (CliError, add_progress_flag, float_arg, int_in, max_workers, path_arg, prepare_out_dir,
                     show_progress)


def _add_sweep(sub):
    p = sub.add_parser("sweep", help="run a parameter study (grid / Monte Carlo) on Dask, resumable",
                       description="Run every case of STUDY.toml (a base mission and the parameters to vary; "
                                   "with a [replay] section, replays of your own flight log: "
                                   "examples/study_replay.toml) on a Dask cluster and store one Parquet row per "
                                   "case under DIR/cases. "
                                   "Re-running the same command skips the cases already stored. Prints a "
                                   "summary table and writes trade-off plots to DIR/plots. Exit status 1 if "
                                   "some cases failed (stored with their error) or did not finish. "
                                   "`dronewpt sweep --status DIR` prints how many cases are done, failed, pending.")
    p.add_argument("study", type=path_arg("study file"), nargs="?", metavar="STUDY.toml",
                   help="study TOML file (see examples/study_small.toml, examples/study_replay.toml)")
    p.add_argument("--out", type=path_arg("--out"), metavar="DIR", help="output folder (created; reused to resume)")
    p.add_argument("--status", type=path_arg("--status"), metavar="DIR", default=None,
                   help="print the counts of done, failed and pending cases of the sweep in DIR and exit")
    p.add_argument("--max-cases", type=int_in("max-cases", 1), default=DEFAULT_MAX_CASES, metavar="N",
                   help=f"refuse a study of more than N cases before any work (default {DEFAULT_MAX_CASES:,})")
    p.add_argument("--retry-errors", action="store_true",
                   help="also re-run the cases stored with status 'error' (their new row replaces the old one)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="address of an existing Dask scheduler "
                                                      "(e.g. tcp://10.0.0.5:8786); default: a local cluster")
    p.add_argument("--connect-timeout", type=float_arg("connect-timeout", positive=True, hi=3600), default=10.0,
                   metavar="S", help="seconds to wait for --scheduler, at most 3600 (default 10)")
    p.add_argument("--workers", type=int_in("workers", 0, max_workers(), " (4 per CPU)"), default=None, metavar="N",
                   help="worker processes of the local cluster, 0 .. 4 per CPU (default: one per CPU; 0 = run "
                        "serially in this process without Dask)")
    p.add_argument("--force", action="store_true", help="add this study's cases to an --out folder that holds "
                   "another study (default: refused; the same study resumes)")
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


def _cmd_status(args) -> int:
    from ..studies.status import sweep_status

    st = sweep_status(args.status)
    if args.format == "json":
        print(json.dumps(dataclasses.asdict(st)))
    else:
        print(st.line())
    return 0


def _check_args(args) -> None:
    if args.study is None or args.out is None:
        raise CliError("give STUDY.toml and --out DIR (or --status DIR to see how far a sweep is)")
    if args.scheduler is not None:
        _check_scheduler_address(args.scheduler)
    if args.scheduler is not None and args.workers is not None:
        raise CliError("--scheduler and --workers exclude each other "
                       "(the cluster at --scheduler has its own workers)")


def _prepare(args):
    """Study, runner, lazy cases and fingerprint: size and every case's values checked, nothing run yet."""
    from ..studies import study as study_mod
    from ..studies.prepare import prepare_study

    st = study_mod.load_study(args.study)
    study_mod.check_size(st, args.max_cases)  # before policies are imported: a 10^8 grid is refused at once
    make_policy = policy_names = None
    if not st.runner:
        import policies  # lazy: mission_sim never imports policies at module level

        make_policy, policy_names = policies.make, policies.available()
    runner, cases, fingerprint = prepare_study(st, make_policy, policy_names, max_cases=args.max_cases,
                                               progress=show_progress(args), warn=False)   # warned in _run
    return st, runner, cases, fingerprint


def _client_factory(args):
    from ..studies.cluster import dask_client

    if args.scheduler is None and args.workers == 0:
        return None  # serially in this process
    factory = functools.partial(dask_client, args.scheduler, args.workers, connect_timeout_s=args.connect_timeout)
    if args.scheduler is not None:
        with factory():  # a bad address fails now, before the store is touched
            pass
    return factory


def _run(args, st, runner, cases, fingerprint):
    from ..studies import sweep
    from ..studies.prepare import warn_study
    from ..studies.status import check_same_study, write_manifest

    client_factory = _client_factory(args)   # a bad scheduler address fails first, --out not created
    prepare_out_dir(args.out)   # a file in its place, unwritable: one line naming --out (was "[Errno 17] File exists")

    inputs = getattr(runner, "input_files", None)   # a replay study's log and pads: their sha256 in sweep.json

    def before_run():  # under the store's lock: another study in --out is refused unless --force
        if not args.force:
            check_same_study(args.out, st, fingerprint, len(cases), inputs)
        # the study's setup warnings after the refusals (--out, a resume) and before the manifest: under -W error
        # a warning refuses the run without claiming --out for this study
        warn_study(st, runner)
        write_manifest(args.out, st, fingerprint, len(cases), inputs)
    return sweep.run_sweep(cases, runner, args.out, client_factory=client_factory,
                           progress=show_progress(args), progress_desc=st.name, retry_errors=args.retry_errors,
                           before_run=before_run)


def _cmd_sweep(args) -> int:
    # SIGTERM, like Ctrl-C, raises mission_sim.signals.Interrupted (installed by main for every command):
    # the rows received are stored, the cluster closed, one line
    if args.status is not None:
        return _cmd_status(args)
    _check_args(args)
    st, runner, cases, fingerprint = _prepare(args)
    res = _run(args, st, runner, cases, fingerprint)
    _report(args, st, res)
    if res.n_missing:
        print(f"dronewpt sweep: {res.n_missing} of {res.n_cases} cases did not finish (tasks lost); "
              "run the same command again to resume", file=sys.stderr)
        return 1
    if res.n_error:
        print(f"dronewpt sweep: {res.n_error} of {res.n_cases} cases failed (stored with status 'error'; "
              "--retry-errors runs them again)", file=sys.stderr)
        return 1
    return 0


def _report(args, st, res) -> None:
    import pandas as pd

    from ..studies import report as sweep_report

    table = sweep_report.summary_table(res.results, st)
    errors = sweep_report.error_table(res.results)
    figs = [] if args.no_plot else sweep_report.plot_sweep(res.results, st, args.out / "plots")
    if not table.empty:
        from ..files import atomic_output
        with atomic_output(args.out / "summary.csv") as tmp:  # a full disk: named, nothing partial
            table.to_csv(tmp)
    counts = {"study": st.name, "out": str(args.out), "cases": res.n_cases, "skipped": res.n_skipped,
              "run": res.n_run, "ok": res.n_ok, "errors": res.n_error, "missing": res.n_missing,
              "wall_s": round(res.wall_s, 3), "compact_s": round(res.compact_s, 3),
              "cases_per_s": None if res.n_run == 0 else round(res.cases_per_s, 3)}
    if args.format == "json":
        summary = json.loads(table.reset_index().to_json(orient="records")) if not table.empty else []
        print(json.dumps({**counts, "summary": summary, "failed": errors.to_dict(orient="records"),
                          "figures": figs}))
        return
    rate = f" in {res.wall_s:.1f} s ({res.cases_per_s:.2f} cases/s)" if res.n_run else ""
    depleted = int(table.loc["all", "battery depleted"]) if "battery depleted" in table else 0
    depleted = f" ({depleted} with the battery depleted: battery_depleted in the rows)" if depleted else ""
    print(f"study {st.name}: {res.n_cases} cases, {res.n_skipped} already done, {res.n_run} run{rate}, "
          f"{res.n_ok} ok{depleted}, {res.n_error} failed; results in {args.out / 'cases'}")
    if not table.empty:
        with pd.option_context("display.width", 200, "display.max_columns", 40,
                               "display.float_format", "{:.4g}".format):
            print(table.T.to_string())
    if len(errors):
        print("failed cases (first 10):")
        print(errors.to_string(index=False, max_colwidth=120))
    for f in figs:
        print(f"figure: {f}")
