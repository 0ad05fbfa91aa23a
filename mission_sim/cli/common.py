"""What every subcommand shares: the user-error type and argument converters that name the bad value and its range."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

__all__ = ["CliError", "OneLineParser", "float_arg", "positive_float", "finite_float", "nonneg_int", "seed_int",
           "parse_set", "write_mission", "prepare_out_dir", "add_progress_flag", "show_progress", "names_help",
           "lazy_names_help", "policy_names", "scenario_names", "int_in", "max_workers", "path_arg", "name_list",
           "check_out_dir", "check_out_file"]


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def _nearest(arg: str, parser) -> list:
    """The option of ``parser`` nearest ``arg`` (difflib, cutoff 0.75), as a one-element list, or []."""
    import difflib
    known = [o for a in parser._actions for o in a.option_strings]
    return difflib.get_close_matches(arg.split("=", 1)[0], known, n=1, cutoff=0.75)


class OneLineParser(argparse.ArgumentParser):
    """argparse with its usage errors on one line (``dronewpt mission: error: ... (see --help)``), exit 2."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # A value starting with '-' and a digit is a value, as CPython's newer argparse (3.14) reads it: on 3.11 - 3.13.0
        # `--home -35.36,149.16,584` or `--pad -35.36,149.16` (southern latitudes, SITL's own home) failed with
        # "expected one argument" (only a plain number such as -35.36 was taken as one); 2026-11-28
        import re
        self._negative_number_matcher = re.compile(r"-\.?\d")

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None):
        """As argparse's, but an unknown option is named with the command it was given to and the nearest valid
        option (``dronewpt: error: unrecognized arguments: --polcy`` named neither)."""
        argv = list(sys.argv[1:] if args is None else args)
        ns, extras = self.parse_known_args(argv, namespace)
        if extras:
            cmd, sub = self, None
            for action in self._actions:   # the subcommand's own parser, when there is one
                if isinstance(action, argparse._SubParsersAction) and getattr(ns, action.dest, None) in action.choices:
                    name = getattr(ns, action.dest)
                    sub = action.choices[name]
                    # given before the command's name: the top-level parser got it (`dronewpt --polcy mission`)
                    before = name in argv and extras[0] in argv and argv.index(extras[0]) < argv.index(name)
                    cmd = self if before else sub
            near = _nearest(extras[0], cmd) if extras[0].startswith("-") else []
            hint = f" (did you mean {near[0]}?)" if near else ""
            after = _nearest(extras[0], sub) if not near and cmd is self and sub is not None else []
            if after:
                hint = f" (did you mean {sub.prog} {after[0]}? a command's options go after its name)"
            at = argv.index(extras[0]) if extras[0] in argv else -1
            if not hint and at > 0 and argv[at - 1].endswith(",") and not extras[0].startswith("-"):
                # `--policies step, ramp, mpc`: the shell split the list at the spaces; joined while a part ends in ','
                joined, k = argv[at - 1] + argv[at], at
                while joined.endswith(",") and k + 1 < len(argv) and not argv[k + 1].startswith("-"):
                    k += 1
                    joined += argv[k]
                hint = (f" (a space after the comma in {argv[at - 1]!r}? a list is one argument: "
                        f"{joined}, or quote it)")
            self.exit(2, f"{cmd.prog}: error: unrecognized argument {extras[0]!r}{hint}; valid: the options and "
                         f"arguments of {cmd.prog} --help\n")
        return ns

    def format_help(self):
        for action in self._actions:  # help texts listing names that need a slow import: only for --help
            fill = getattr(action, "lazy_help", None)
            if fill is not None:
                action.help, action.lazy_help = fill().replace("%", "%%"), None   # (argparse %-formats help texts)
        return super().format_help()


def startup_gc_paused(command, args) -> int:
    """``command(args, started)`` with Python's cyclic garbage collector off through its start-up.

    A command's start-up (numba, gymnasium, the kernels, the config) allocates ~10^5 objects that live as
    long as the command; the collector's passes over them (~0.05-0.15 s of CPU before the runs, measured in
    ``compare`` and ``mission``) free nothing. ``command`` calls ``started()`` before its runs: the start-up's
    objects are frozen (never scanned again) and collection is back on (a forked child inherits both). The
    collector is on again when the command returns, however it ends. Results are unchanged: no cycle that
    holds a result is freed earlier or later."""
    import gc

    def started() -> None:
        gc.freeze()
        gc.enable()

    gc.disable()
    try:
        return command(args, started)
    finally:
        gc.enable()


def lazy_names_help(action, text: str, names) -> None:
    """Give ``action`` (from ``add_argument``) the help ``text; one of: <names()>``, computed only when
    the help is shown (``names`` imports policies / envs, which takes a second or two)."""
    action.help = text
    action.lazy_help = lambda: names_help(text, names())


def policy_names() -> list[str]:
    import policies
    return [*policies.available(), "rl:PATH / residual:PATH (a model trained with `dronewpt train`)",
            "model_based_budget:B (B, e.g. 0.02: on the exact-mode link the measured overshoot allowed above F, "
            "the overshoot the controller predicts at the stop for its plan at B = 0, the paper's controller (within "
            "0.2 point of model_based's measured overshoot; not the window's oracle floor, which is lower); B = 0.02: "
            "measured 0.5-1.9 points above F, bound 2.6; on eq. 4's link (--link envelope) the relaxation of its "
            "reference, measured overshoot about 100 B + 3.3 %, 5.45 % at B = 0.02)",
            "mpc:B (B: the measured overshoot allowed, or the window's floor if higher)"]


def scenario_names() -> list[str]:
    from envs import SCENARIOS
    return list(SCENARIOS)


def float_arg(name, positive=False, lo=0.0, hi=float("inf")):
    """argparse type: a finite float (in ``[lo, hi]`` and > 0 if ``positive``), errors naming the value and range:
    :func:`range_arg` of that :class:`~mission_sim.validation.Range` (``(0, hi]`` for ``lo <= 0``, ``finite`` when not
    ``positive``)."""
    from ..validation import Range
    inf = float("inf")
    rng = Range(max(lo, 0.0), hi, lo_open=lo <= 0, hi_open=hi == inf) if positive else \
        Range(-inf, inf, lo_open=True, hi_open=True)   # (positive: > 0 whatever lo; a lo <= 0 is 0, open)
    return range_arg(name, rng)


def positive_float(name):
    return float_arg(name, positive=True)


def finite_float(name):
    return float_arg(name)


def parse_set(items, flag: str = "--set"):
    """``KEY=VALUE`` options (``--set``, train's ``--env``: ``flag``) as a dict, each value read as TOML (else the
    text); ``CliError`` naming ``flag`` for an item without '=' and for a key given twice with different values."""
    import tomllib
    out = {}
    for item in items or ():
        if "=" not in item or not item.split("=", 1)[0].strip():   # (no key: "override key '' is invalid")
            raise CliError(f"{flag} {item!r} is invalid; valid form: KEY=VALUE (e.g. "
                           f"{'n_steps=200' if flag == '--env' else 'battery.capacity_ah=2.0'})")
        key, text = item.split("=", 1)
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text
        except ValueError:   # an integer over Python's 4,300 digits: was "Exceeds the limit (4300 digits)", no key
            raise CliError(_too_many_digits(flag, key.strip(), text)) from None
        key = key.strip()
        if key in out and repr(out[key]) != repr(value) and out[key] != value:   # (the last one won without a word)
            raise CliError(f"{flag} {key} is given twice ({out[key]!r} and {value!r}); valid: each key once")
        out[key] = value
    return out


def _too_many_digits(flag: str, key: str, text: str) -> str:
    """The one line for ``KEY=TEXT`` whose integer has more digits than Python converts (``sys.get_int_max_str_digits``):
    the key, the value cut, and the key's range when it is a config key."""
    import sys

    from ..config import PLAUSIBLE
    from ..validation import clipped
    rng = PLAUSIBLE.get(key)
    valid = f"valid range: {rng.text()}" if rng is not None else "valid: a number"
    return (f"{flag} {key}={clipped(text.strip(), text.strip())} is invalid: an integer of more than "
            f"{sys.get_int_max_str_digits()} digits; {valid}")


def mass_override(args) -> dict:
    """``--mass KG`` as the override ``drone.mass_kg`` (empty without it); ``CliError`` when ``--set``
    gives that key too (``--set`` won silently over ``--mass``)."""
    if not args.mass:
        return {}
    sets = parse_set(args.set)
    if "drone.mass_kg" in sets:
        raise CliError(f"--mass {args.mass:g} and --set drone.mass_kg={sets['drone.mass_kg']} both set the drone's mass; "
                       "valid: one of them")
    return {"drone.mass_kg": args.mass}


#: ``train --timesteps``: 0 (no RL steps) is valid only after a behaviour clone; the parser takes >= 0, the train
#: checks (``cli.learning._check_train``) the rest; both say this
TRAIN_TIMESTEPS_RANGE = "integer >= 1 (0 with --imitate)"


def int_in(name, lo: int, hi: int | None = None, why: str = "", valid: str | None = None):
    """argparse type: an integer in ``lo..hi`` (``hi`` None: no upper end; underscores allowed: 1_000),
    every error naming the value and the one range text (``why`` follows it, e.g. " (4 per CPU)"; ``valid``: the
    whole text instead, where a later check narrows ``lo..hi``, e.g. :data:`TRAIN_TIMESTEPS_RANGE`)."""
    valid = valid or (f"integer >= {lo}" if hi is None else f"integer {lo}..{hi}") + why

    def conv(text):
        try:
            v = int(text)
        except ValueError:
            try:   # 1e5, as SB3's examples write a step count: named with its integer spelling (2026-11-28)
                f = float(text)
                ok = f.is_integer() and abs(f) < 1e18 and lo <= f and (hi is None or f <= hi)
                hint = f" (write {int(f)})" if ok else ""   # (not for -1e4: that integer is out of range too)
            except ValueError:
                hint = ""
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not an integer; valid range: {valid}{hint}") from None
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: {valid}")
        return v
    return conv


def range_arg(name, rng):
    """argparse type of a number option whose range is the library's (a :class:`mission_sim.validation.Range`, e.g.
    :data:`mission_sim.train_options.RANGES`): an integer range in :func:`int_in`'s words, else a number inside it;
    every error naming the value and ``rng.text()``, the library's words."""
    if rng.integer:
        return int_in(name, int(rng.lo), None if rng.hi == float("inf") else int(rng.hi))

    def conv(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name}={text!r} is not a number") from None
        if not rng.contains(v):
            raise argparse.ArgumentTypeError(f"{name}={text!r} is invalid; valid range: {rng.text()}")
        return v
    return conv


def nonneg_int(name, hi: int | None = None):
    """argparse type: an integer >= 0 (and <= ``hi``), errors naming the value and the range."""
    return int_in(name, 0, hi)


def max_workers() -> int:
    """The most worker processes a local cluster may start: 4 per CPU this process may use."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return 4 * cpus


def path_arg(flag: str):
    """argparse type: a non-empty path (``Path('')`` would silently be the current folder)."""
    def conv(text):
        if not text.strip():
            raise argparse.ArgumentTypeError(f"{text!r} is empty; valid: a path (for {flag})")
        return Path(text)
    return conv


def name_list(text: str, flag: str, valid) -> list[str]:
    """The names of a comma-separated option (``--policies a,b``); ``CliError`` naming ``flag`` when the
    list is empty (``''``, ``','``), a name's part before ':' is not in ``valid`` or a name is repeated."""
    names = [n.strip() for n in str(text).split(",") if n.strip()]
    if not names:
        raise CliError(f"{flag} {text!r} is empty; valid: comma-separated names out of {', '.join(valid)}")
    for n in names:
        if n.partition(":")[0] not in valid:
            raise CliError(f"{flag} {n!r} is invalid; valid values: {', '.join(valid)}")
    twice = next((n for i, n in enumerate(names) if n in names[:i]), None)
    if twice is not None:   # a repeated name ran (and printed) the same rows twice
        raise CliError(f"{flag} {text!r} names {twice!r} twice; valid: each name once")
    return names


def check_out_file(path, flag: str, suffix: str | None = None) -> Path:
    """An output file path, checked before any work: not a folder, ending in ``suffix`` when given, its
    folder created and writable (:func:`prepare_out_dir`); ``CliError`` naming ``flag`` otherwise."""
    path = Path(path)
    if path.exists() and not path.is_dir() and not path.is_file():   # a FIFO, socket or device: never replaced
        raise CliError(f"{flag} {str(path)!r} exists and is not a regular file (a FIFO or device); valid: a file path")
    if path.is_dir():
        example = f" e.g. {str(path / ('out' + (suffix or '')))!r}"
        raise CliError(f"{flag} {str(path)!r} is a folder; valid: a {suffix.lstrip('.').upper() + ' ' if suffix else ''}"
                       f"file path,{example}")
    if suffix is not None and path.suffix.lower() != suffix:
        raise CliError(f"{flag} {str(path)!r} is invalid; valid: a file name ending in {suffix}")
    prepare_out_dir(path.parent, f"{flag} folder")
    return path


def seed_int(name="seed"):
    """argparse type for a random seed: :data:`mission_sim.validation.SEED_RANGE` (what numpy's legacy seeding
    accepts)."""
    from ..validation import SEED_RANGE
    return int_in(name, int(SEED_RANGE.lo), int(SEED_RANGE.hi))


def names_help(text: str, names) -> str:
    """``text`` followed by the valid names, for ``--policy`` / ``--scenario`` help."""
    return f"{text}; one of: {', '.join(names)}"


def check_out_dir(path, flag: str = "--out") -> Path:
    """An output folder's path checked without creating anything (``--dry-run``): ``CliError`` when a file is in
    its place."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise CliError(f"{flag} {str(path)!r} is an existing file; valid: a folder (created if missing)")
    return path


def figures_out(args, default: str) -> Path:
    """``args.out`` of a command whose ``--out`` holds only its figures (``paper``, ``compare``, ``sizing``): with
    ``--no-plot`` a given ``--out`` would change nothing (it was ignored, nothing written, exit 0), so it is refused
    (:class:`CliError`, one line); otherwise ``args.out`` or ``default``."""
    if args.no_plot and args.out is not None:
        raise CliError(f"--out {str(args.out)!r} is only used for the figures; valid: drop --no-plot, or drop --out")
    return Path(default) if args.out is None else args.out


#: the folders :func:`prepare_out_dir` created in this command, outermost first: a command refused afterwards (exit
#: status 2) removes those still empty (:func:`remove_created_dirs`), so that a refused input leaves nothing behind
_CREATED: list[Path] = []


def forget_created_dirs() -> None:
    """A new command starts: no folder created yet (:data:`_CREATED`)."""
    _CREATED.clear()


def remove_created_dirs() -> None:
    """Remove the folders this command created (:func:`prepare_out_dir`) that are still empty, innermost first; a
    folder holding anything stays. For a refused command: a check after the output folder was made (a log without
    battery data, a bad ``--policy`` after ``telemetry --tlog DIR/x.tlog``) left it behind, empty."""
    while _CREATED:
        try:
            _CREATED.pop().rmdir()
        except OSError:   # not empty, gone, not ours to remove: left as it is
            pass


def _make_dirs(path: Path) -> None:
    """``mkdir -p path``, recording in :data:`_CREATED` only the folders this call made: each missing level is made
    with a plain ``mkdir`` (no ``exist_ok``), outermost first, and recorded only when that call succeeded. A level
    that exists, or that appears meanwhile (another run made it: ``FileExistsError``), is not ours and is never
    removed. The levels are the path as spelled, ``..`` included: ``new/../keep_me`` makes ``new`` (recorded) and
    then finds ``new/..`` and ``new/../keep_me`` existing (not recorded). (Recording every level missing before one
    ``mkdir(parents=True)`` recorded ``new/..`` and ``new/../keep_me`` too, and a refused command then removed the
    user's empty ``keep_me``.)"""
    for level in (*reversed(path.parents), path):
        if level.name in ("", ".", "..") or level.is_dir():
            continue   # the root, '.', '..': never made here; an existing folder: not ours
        try:
            level.mkdir()
        except FileExistsError:
            continue   # made meanwhile by someone else (or a file: the next level or the probe says so)
        _CREATED.append(level)


def prepare_out_dir(path, flag: str = "--out") -> Path:
    """Create the output folder ``path`` now, before any simulation, and check that files can be
    written there; ``CliError`` naming the flag and the path otherwise (a file in its place, no
    permission, a read-only file system). The folders it creates are removed again if the command is refused
    later (:func:`remove_created_dirs`)."""
    path = check_out_dir(path, flag)
    try:
        _make_dirs(path)
        probe = path / f".dronewpt-write-test.{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise CliError(f"{flag} {str(path)!r} is not a writable folder: {exc.strerror or exc}") from None
    return path


def add_progress_flag(p) -> None:
    """``--no-progress`` (progress bars are on when stderr is a terminal); ``--progress`` forces them on."""
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (default: shown when stderr is a terminal)")
    p.add_argument("--progress", action="store_true", help=argparse.SUPPRESS)


def show_progress(args) -> bool:
    """Progress bars: off with ``--no-progress`` or ``--format json``, on with ``--progress``, else on a terminal."""
    if getattr(args, "no_progress", False):
        return False
    if getattr(args, "progress", False):
        return True
    return getattr(args, "format", "table") != "json" and sys.stderr.isatty()


def write_mission(result, out_dir, plots: bool, progress: bool = False) -> list[str]:
    """Write a mission's data files (Parquet and CSV: ``replay``'s ``mission/`` and ``refly/`` have always had the
    CSV), unless ``plots`` is false its figures, and ``summary.json`` last (see
    :meth:`mission_sim.world.results.MissionResult.write`; ``progress``: a bar); returns the paths."""
    figures = None
    if plots:
        from ..figures.mission import plot_mission as figures
    return [str(f) for f in result.write(out_dir, figures=figures, progress=progress, csv=True)]


def peak_i2_line(peak_a: float, envelope_a, rated_a, above_s) -> str:
    """The replay's line on the secondary coil current against its rating (2026-11-28: a replay printed none, and
    the dronekit tlog's 19.6 A against the 15 A rating, on the pad before take-off, was only in the JSON), worded as
    ``dronewpt mission``'s row. The time above the rating is the fundamental's (envelope's,
    ``loop_kernel._track_peak``), so ABOVE goes by that time, not by the instantaneous peak (ripple included)."""
    line = f"peak I2 {peak_a:.2f} A instantaneous"
    parts = [] if envelope_a is None else [f"envelope {envelope_a:.2f} A"]
    if rated_a is not None:
        above_s = above_s or 0.0
        parts += [f"rated {rated_a:g} A", f"{'ABOVE' if above_s > 0 else 'above'} it {1e3 * above_s:.2f} ms"]
    return line + (f" ({'; '.join(parts)})" if parts else "")
