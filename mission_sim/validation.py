"""Validation of parameter dataclasses: one message format for every section of a mission."""

from __future__ import annotations

import functools
import math
import os
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["check_positive", "read_toml_file", "json_too_deep", "Range", "check_range", "check_regular_file", "shown", "real_array",
           "real_number", "check_number", "check_number_fields", "YAML_NUMBER_NOTE", "SEED_RANGE", "seed_range",
           "check_first_seed", "check_table"]


@dataclass(frozen=True)
class Range:
    """The values a real system can have for one parameter: ``[lo, hi]`` (``lo_open`` / ``hi_open``
    exclude an end; ``integer``: whole numbers only), ``unit`` as written after the range."""

    lo: float
    hi: float
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False

    def contains(self, v) -> bool:
        """True for a finite number (an integer if ``integer``) inside the range; never raises."""
        try:
            v = float(v)
        except (TypeError, ValueError, OverflowError):
            return False
        if not math.isfinite(v) or (self.integer and v != int(v)):
            return False
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return above and below

    def text(self) -> str:
        """``(0, 100] m/s``, ``integer 1..32``, ``integer >= 1``, ``finite`` (every real number: ``(-inf, inf)``): the
        text after "valid range:" in every message."""
        if self.integer:   # no upper end: "integer >= 1", the CLI's words
            body = f"integer >= {int(self.lo)}" if math.isinf(self.hi) else f"integer {int(self.lo)}..{int(self.hi)}"
        elif self.lo == -math.inf and self.hi == math.inf and self.lo_open and self.hi_open:
            body = "finite"
        else:
            body = f"{'(' if self.lo_open else '['}{self.lo:.6g}, {self.hi:.6g}{')' if self.hi_open else ']'}"
        return f"{body} {self.unit}".rstrip()


#: ranges shared by the mission config (:data:`mission_sim.config.PLAUSIBLE`) and the mission and pads file readers
#: (:mod:`mission_sim.plans`, which never import the config): a horizontal speed (``mission.cruise_speed_m_s``, a
#: route's ``speed_m_s``, a file's DO_CHANGE_SPEED), a hover or hold time (``mission.hover_time_s``, ``pads.*``, a
#: route's ``hold_s``, a file's loiter time or pad ``hover_time_s``), ``mission.pad_radius_m`` and the heights below
SPEED_RANGE = Range(0.0, 100.0, "m/s", lo_open=True)
HOLD_RANGE = Range(0.0, 1e6, "s")
PAD_RADIUS_RANGE = Range(0.0, 1000.0, "m", lo_open=True)
#: the built-in pattern's cruise altitude and the charging gap (``mission.cruise_altitude_m``, ``hover_gap_m``): a
#: re-flight (:func:`mission_sim.plans.refly.refly_base`) raises the one above its pads by the other's top
CRUISE_ALTITUDE_RANGE = Range(0.0, 500.0, "m", lo_open=True)
HOVER_GAP_RANGE = Range(0.03, 1.0, "m")
#: a route waypoint's height above home (``[[waypoints]] z_m``, a mission file's item altitude)
ALT_RANGE = Range(0.0, 5000.0, "m above home")


#: what a message adds for a number given as a string that reads as one (YAML 1.1, PyYAML's, reads 1e-4 as a string)
#: a random seed: what numpy's legacy seeding accepts (``--seed``, ``train(seed=)``, ``compare``'s, an SB3 adapter's
#: ``reset_seed``; one range for all)
SEED_RANGE = Range(0, 2**32 - 1, integer=True)


def seed_range(count: int) -> Range:
    """The seeds whose run of ``count`` seeds ``seed .. seed + count - 1`` stays in :data:`SEED_RANGE` (``--seed``,
    ``compare``'s episodes, a vector env's sub-environments)."""
    return Range(SEED_RANGE.lo, SEED_RANGE.hi + 1 - count, integer=True)


def check_first_seed(seed, count: int, runs: str, count_name: str) -> int:
    """``seed`` as an int when ``seed .. seed + count - 1`` are all seeds (:func:`seed_range`); else one ``ValueError``
    naming it, with ``runs`` (e.g. ``"episode"``) and ``count_name`` (e.g. ``"episodes"``) when ``count > 1``."""
    return check_number("seed", seed, seed_range(count),
                        f" ({runs} seeds go up to seed + {count_name} - 1, {count_name}={count})" if count > 1 else "")

YAML_NUMBER_NOTE = "a number, not a string (YAML 1.1 reads 1e-4 as a string: write 1.0e-4)"


def window_ok(t0, t1, hi: float = math.inf) -> bool:
    """A replay window ``(t0, t1)`` [s of log time]: finite, ``0 <= t0 < t1 <= hi`` (the one predicate of
    ``--window``, a ``[replay]`` study's ``window`` and :func:`mission_sim.mavlink.replay.check_window`)."""
    return math.isfinite(t0) and math.isfinite(t1) and 0 <= t0 < t1 <= hi


def check_range(key: str, value, rng: Range) -> None:
    """``ValueError("key=value is invalid; valid range: <rng.text()>")`` unless ``rng`` contains ``value``."""
    if not rng.contains(value):
        raise ValueError(f"{key}={shown(value)} is invalid; valid range: {rng.text()}")   # (shown: one short line)


def shown(value) -> str:
    """``value`` as a message names it, on one line: ``array of shape (2, 1), dtype float64`` for an array (a numpy
    array, a torch tensor) of more than one element, whose repr spans lines; else its repr."""
    shape, dtype = getattr(value, "shape", None), getattr(value, "dtype", None)
    if shape is not None and dtype is not None and math.prod(shape) > 1:
        return f"array of shape {tuple(shape)}, dtype {dtype}"
    text = " ".join(repr(value).split()) if "\n" in repr(value) else repr(value)
    return clipped(text, value)


#: a value's text longer than this is cut in a one-line error (:func:`clipped`); a string's limit is larger
CLIP_AT, CLIP_STRING_AT, CLIP_HEAD = 80, 200, 60


def clipped(text: str, value=None) -> str:
    """``text`` (``value`` as a message spells it: its repr, its JSON) cut to its first 60 characters when longer than
    80 (:data:`CLIP_AT`), or for a string value (str, bytes) longer than 200 (:data:`CLIP_STRING_AT`: a name, a path or
    a header a user typed is shown whole; a pasted 3,000-digit number is not), with how long ``value`` is:
    ``[[8.5, 47.4], [8.50001, 47.4], ...... (2000 items)`` (a 10,000-item list was a 59 kB line; a pads file's 2,000-point
    coordinate array, a 34 kB one), ``'9999...... (3000 characters)``."""
    string = isinstance(value, (str, bytes))
    if len(text) <= (CLIP_STRING_AT if string else CLIP_AT):
        return text
    if isinstance(value, (list, tuple, set, dict)):
        size = f"{len(value)} items"
    elif string:
        size = f"{len(value)} characters"
    else:
        size = f"{len(text)} characters"
    return f"{text[:CLIP_HEAD]}... ({size})"


def real_array(value):
    """``value`` as a numpy array if it holds real numbers (dtype bool, integer or float: a Python or numpy
    number, a list of numbers, an array, a torch tensor); None for anything else (None, strings, complex
    values, objects, ragged lists). Never raises."""
    import numpy as np
    try:
        x = np.asarray(value)
    except Exception:   # noqa: BLE001 (ragged lists, a tensor that requires grad, ...): not real numbers either
        return None
    return x if x.dtype.kind in "biuf" else None


def real_number(value):
    """``float(value)`` for one real number that is not a bool (a Python or numpy number, a 0-d array, a torch
    scalar); None for anything else (a string such as YAML's ``"1e-4"``, None, a bool, a complex, a sequence)."""
    if type(value) is float:
        return value
    x = real_array(value)
    if x is None or x.ndim != 0 or x.dtype.kind == "b":
        return None
    return float(x)


def check_number(key: str, value, rng: Range, note: str = ""):
    """``value`` as a Python float (an int if ``rng.integer``) when it is one real number inside ``rng``
    (:func:`real_number`); else ``ValueError("key=value is invalid; valid range: <rng.text()><note>")``, one line
    (:func:`check_range`'s, which takes a numeric string)."""
    v = real_number(value)
    if v is None or not rng.contains(v):
        raise ValueError(f"{key}={shown(value)} is invalid; valid range: {rng.text()}{note}")
    return int(v) if rng.integer else v


#: the annotations of a dataclass's number fields (``from __future__ import annotations``: strings) -> the type
#: a message asks for
_NUMBER_FIELDS = {"float": "number", "int": "integer", "float | None": "number", "int | None": "integer"}


def check_table(name: str, value, hint: str = "", eq: str = "=") -> dict:
    """``value`` when it is a table (a dict); else ``ValueError("<name>=<value> is invalid; valid type: table
    (<hint>)")``: the one wording of a config file's, a study's or an override's section that is not a table
    (``eq``: how the file spells the assignment, ``" = "`` in a study's ``[grid] = 3``)."""
    if not isinstance(value, dict):
        raise ValueError(f"{name}{eq}{shown(value)} is invalid; valid type: table" + (f" ({hint})" if hint else ""))
    return value


def check_number_fields(obj, prefix: str = "") -> None:
    """Every field of the dataclass ``obj`` annotated ``float`` or ``int`` (``| None``: None too) holds one real
    number (:func:`real_number`), as a config file's key must (a string such as ``"3"``, a bool, None refused);
    else ``ValueError("<prefix>name=value is invalid; valid type: number")`` ("integer" for an ``int`` field),
    one line. First in a section's ``__post_init__``: ``float("3")`` passed its range checks and ``"1e-4" <= 1e-3``
    raised a TypeError. Whole numbers and ranges are the section's own checks."""
    for name, kind, none_ok in _number_fields(type(obj)):
        v = getattr(obj, name)
        if type(v) is not float and real_number(v) is None and not (v is None and none_ok):
            raise ValueError(f"{prefix}{name}={shown(v)} is invalid; valid type: {kind}")


@functools.lru_cache(maxsize=None)
def _number_fields(cls) -> tuple:
    """``(name, "number" | "integer", None allowed)`` of the number fields of dataclass ``cls``."""
    from dataclasses import fields
    out = []
    for f in fields(cls):
        kind = _NUMBER_FIELDS.get(f.type if isinstance(f.type, str) else getattr(f.type, "__name__", ""))
        if kind is not None:
            out.append((f.name, kind, "None" in str(f.type)))
    return tuple(out)


def check_regular_file(path, what: str, valid: str = "a regular file") -> Path:
    """``path`` as a :class:`~pathlib.Path` if it is an existing regular file (or a link to one); checked with
    ``os.stat`` only, so a FIFO, a socket or a device is refused without being opened (opening a FIFO
    blocks until a writer appears). ``FileNotFoundError`` when missing, ``ValueError`` for a folder or any
    other non-regular file, ``OSError`` when it cannot be examined; each one line naming ``what``, the path and
    ``valid`` (what is expected, e.g. "a TOML file")."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise FileNotFoundError(f"{what} {str(path)!r} does not exist") from None
    except OSError as exc:
        raise OSError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise ValueError(f"{what} {str(path)!r} is a folder; valid: {valid}")
    if not stat.S_ISREG(mode):
        kind = "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "not a regular file"
        raise ValueError(f"{what} {str(path)!r} is {kind}; valid: {valid}")
    return path


def check_positive(obj, *names: str, allow_zero: bool = False) -> None:
    """Raise ``ValueError`` naming the field, its value and the valid range unless every field
    ``names`` of ``obj`` is finite and > 0 (>= 0 with ``allow_zero``)."""
    for name in names:
        v = float(getattr(obj, name))
        if not (math.isfinite(v) and (v >= 0 if allow_zero else v > 0)):
            raise ValueError(f"{name}={v!r} is invalid; valid range: {'[0' if allow_zero else '(0'}, inf)")


def json_too_deep(name: str, what: str, valid: str) -> str:
    """The one-line error of a JSON file ``name`` nested deeper than Python's parser takes (its ``RecursionError``:
    a traceback until 2026-11-28): not ``what``, with its ``valid`` form."""
    import sys
    return (f"{name}: JSON nested deeper than the reader takes (about Python's recursion limit, {sys.getrecursionlimit()} "
            f"levels), not {what}; valid: {valid}")


def read_toml_file(path, what: str = "config file") -> dict:
    """Parse the TOML file ``path``; every failure is a one-line error naming ``what`` and the path:
    ``FileNotFoundError`` when missing, ``ValueError`` for a folder, a non-text (binary) file or bad
    TOML (with the parser's line and column), ``OSError`` when it cannot be read."""
    path = check_regular_file(path, what, "a TOML file")
    try:
        # utf-8-sig: a byte-order mark (Windows Notepad's "UTF-8 with BOM", PowerShell's Out-File) is read past, not
        # "Invalid statement (at line 1, column 1)"; tomllib refuses it and the file is otherwise good TOML
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{what} {str(path)!r} is not a UTF-8 text (TOML) file: byte {exc.object[exc.start]:#04x} "
                         f"at offset {exc.start}") from None
    except OSError as exc:
        raise OSError(f"{what} {str(path)!r} cannot be read: {exc.strerror or exc}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{what} {str(path)!r} is not valid TOML: {exc}") from None
