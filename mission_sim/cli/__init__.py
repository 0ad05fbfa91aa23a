"""The ``dronewpt`` command line: parse, call, print. The one place that reaches every package;
subcommands import what they need lazily, inside the function that runs them.

============  ==================================================================
``__main__``  ``python -m mission_sim.cli``
``common``    :class:`CliError` (one line, exit 2) and the argument converters
``paper``     ``paper``: Table II and Fig. 6
``mission``   ``mission`` (the main job) and ``coupling``
``mavlink``   ``replay`` (flight logs) and ``telemetry`` (live MAVLink, follow mode)
``refly``     ``replay LOG --pads FILE``: the what-if re-flight with charging pads
``learning``  ``train`` and ``compare`` (envs and policies, imported lazily)
``sweep``     ``sweep`` (parameter studies on Dask)
``sizing``    ``sizing`` (rectifier rating, parts and mass per policy)
``warmup``    ``warmup`` (compile the numba kernels ahead, once per machine)
``notices``   the one-line notice when numba compiles kernels (first run on a machine), warnings as one line
``calibrate`` ``calibrate`` (the drone power model fitted to a flight log's battery power)
``controller``  ``export-controller`` (the paper's controller as C99 for a DSP)
``netlist``   ``netlist`` (SPICE netlist of the switching model's circuit and devices)
``tolerance``  ``tolerance`` (component-tolerance Monte Carlo on the sweep engine: yield)
============  ==================================================================
"""

from __future__ import annotations

import argparse
import sys

from ..files import OutputError
from . import calibrate, controller, learning, mavlink, mission, netlist, paper, sizing, sweep, tolerance, warmup
from .common import CliError, OneLineParser, show_progress

__all__ = ["main", "build_parser"]


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("dronewpt")
    except PackageNotFoundError:  # run from a source tree without installing
        return "unknown (not installed)"


class _LazyVersion(argparse._VersionAction):
    """``--version``: the version looked up only when asked (importing importlib.metadata costs every command ~30 ms)."""

    def __call__(self, parser, namespace, values, option_string=None):
        self.version = f"dronewpt {_version()}"
        super().__call__(parser, namespace, values, option_string)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="dronewpt", description="Flight-mission energy simulator for drones "
                           "that charge wirelessly in flight (WPT link with an SBAR receiver).",
                           epilog="Exit status: 0 done, 1 some sweep cases failed, 2 bad input (one line on "
                           "stderr), 3 mission ended by a depleted battery, 4 an output could not be written (disk full, file-size "
                           "limit; the file named), 130 interrupted by Ctrl-C (SIGINT), 143 terminated (SIGTERM).")
    parser.add_argument("--version", action=_LazyVersion)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for add in (paper._add_paper, mission._add_coupling, mission._add_mission, mavlink._add_replay, mavlink._add_telemetry,
                learning._add_train, learning._add_compare, sweep._add_sweep, sizing._add_sizing,
                warmup._add_warmup, calibrate._add_calibrate, controller._add_export_controller, netlist._add_netlist,
                tolerance._add_tolerance):
        add(sub)
    return parser


def main(argv=None) -> int:
    """Run one command (``argv``: the arguments, None for ``sys.argv[1:]``) and return its exit status."""
    from ..signals import interrupts_raised
    from .common import forget_created_dirs, remove_created_dirs
    forget_created_dirs()
    with interrupts_raised():  # SIGTERM like Ctrl-C: temporary files removed, one line, 143 (130 for SIGINT)
        rc = _main(argv)
    if rc == 2:   # refused: an output folder made before the refusal is removed again (when still empty)
        remove_created_dirs()
    return rc


def console_main() -> int:
    """The command line's entry point (the ``dronewpt`` console script, ``python -m mission_sim.cli``): runs
    :func:`main` and then ends the process at once (:func:`_exit_now`). Code that calls :func:`main` keeps its
    process."""
    rc = main(sys.argv[1:])
    _exit_now(rc)
    return rc


def _flush_all() -> None:
    """Flush Python's standard streams (a closed one is None) and C's stdio buffers (extensions' printf)."""
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    try:
        import ctypes
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):   # no C library to ask: nothing buffered there by us
        pass


def _exit_now(rc: int) -> None:
    """End the process with status ``rc`` once the command is done: stdout and stderr flushed (and C's stdio),
    the atexit handlers run (logging, multiprocessing, ``weakref.finalize``), but not the interpreter's teardown
    of every module and object (numba's and LLVM's, scipy's: 0.3-0.8 s of wall time after ``compare`` or
    ``mission`` had finished, measured under load). Not taken, so that Python exits as usual: off CPython
    (no ``atexit._run_exitfuncs``), while a non-daemon thread runs, under a tracer or profiler (``python -m
    cProfile``, coverage: they write their results at the normal exit), with ``DRONEWPT_NO_FAST_EXIT`` set, or
    when a stream cannot be flushed. The command's files are closed and renamed into place before this runs."""
    import atexit
    import os
    import threading
    run_exitfuncs = getattr(atexit, "_run_exitfuncs", None)   # CPython's; elsewhere the normal exit
    if (run_exitfuncs is None or os.environ.get("DRONEWPT_NO_FAST_EXIT") or sys.gettrace() is not None
            or sys.getprofile() is not None or "cProfile" in sys.modules or "profile" in sys.modules):
        return
    if any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        return
    try:
        _flush_all()
    except (OSError, ValueError, AttributeError):   # a closed pipe and the like: Python's own exit reports it
        return
    run_exitfuncs()
    try:
        _flush_all()
    except (OSError, ValueError, AttributeError):
        pass
    os._exit(rc)


def _main(argv=None) -> int:
    try:   # a Ctrl-C while the parser is built (~10-20 ms) is an interrupt too, not a traceback
        parser = build_parser()
        args = parser.parse_args(argv)
    except KeyboardInterrupt as exc:
        return _interrupted("dronewpt", exc)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        from .notices import compile_notices, is_dronewpt_warning, warning_lines
        # a terminal: say so when numba compiles (the first run's silent half-minute); the library's warnings as
        # one line each
        with compile_notices(show_progress(args)), warning_lines(args.command):
            try:
                rc = int(args.func(args) or 0)
            except Warning as exc:   # -W error: a DronewptWarning raised; other warnings as Python raises them
                if not is_dronewpt_warning(type(exc)):
                    raise
                print(f"dronewpt {args.command}: error: {_one_line(exc)} (a warning, an error under -W error)",
                      file=sys.stderr)
                return 2
        from ..signals import raise_lost
        raise_lost()   # a SIGTERM / Ctrl-C that landed in a callback is still an interrupt
        return rc
    except BrokenPipeError:  # output piped into head & co.: not an error of ours
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OutputError as exc:  # disk full, file-size limit: the file named, its temporary file removed
        print(f"dronewpt {args.command}: error: {_one_line(exc)}{_notes(exc)}", file=sys.stderr)
        return 4
    except (CliError, ValueError, FileNotFoundError, OSError) as exc:
        print(f"dronewpt {args.command}: error: {_one_line(exc)}{_notes(exc)}", file=sys.stderr)
        return 2
    except MemoryError as exc:  # numpy names the size: "Unable to allocate 37.3 GiB for an array ..."
        print(f"dronewpt {args.command}: error: out of memory: {_one_line(exc) or 'allocation failed'} "
              "(make the run smaller; see docs/robustness.md)", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM (mission_sim.signals.Interrupted)
        return _interrupted(f"dronewpt {args.command}", exc)


def _interrupted(who: str, exc: KeyboardInterrupt) -> int:
    """One line for an interrupt and its exit status (130 for SIGINT, 143 for SIGTERM)."""
    from ..signals import exit_status, signal_name
    print(f"{who}: interrupted ({signal_name(exc)}){_notes(exc)}", file=sys.stderr)
    return exit_status(exc)


def _notes(exc: BaseException) -> str:
    """The exception's notes (e.g. where a cut stream's frames are), each after '; ', on the one line."""
    return "".join(f"; {_one_line(note)}" for note in getattr(exc, "__notes__", ()))


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())
