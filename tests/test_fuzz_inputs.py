"""Property-based fuzz of what a newcomer brings (2026-11-27 night): command lines for every subcommand drawn from its
own argparse parser with harsher values than ``tests/test_fuzz_cli.py``'s (spaces, unicode, newlines, ``-0``,
``0x10``, ``1_000``, unwritable paths, options given twice, ``--set`` items without ``=``), and the files a user hands
over (``.plan`` JSON, ``.waypoints`` text, pads CSV / GeoJSON, ``--drone`` TOML, flight logs) truncated, re-encoded,
emptied, with NaN / huge / wrong-typed fields and missing keys.

Every draw must end as one of: a valid run (exit 0; ``mission --dry-run`` checks and simulates nothing), the
expensive work function reached with every argument checked (stubbed: it stops there), or exit 2 with exactly one
line on stderr that starts ``dronewpt`` and **names the bad value**: one of the command line's own tokens (an
option, its value, a ``--set`` key) or, for a file, the file's name. Never a traceback, never an exception other
than ``SystemExit``, and for a refused input **nothing created** in the folder the draw runs in (no output folder,
no temporary file).

Draws per run (derandomized: the same inputs every run): 250 argument lists, 150 mission files, 80 pads files,
60 ``--drone`` files, 40 flight logs through ``mission --plan LOG --dry-run`` and ``calibrate``. Regression cases
for what it found are at the end.
"""

from __future__ import annotations

import copy
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

from mission_sim import config as mconfig
from test_fuzz_cli import FUZZ as CLI_FUZZ
from test_fuzz_cli import _WORK, SUBPARSERS, _check_outcome, _run, _stub, _temporaries

ROOT = Path(__file__).resolve().parents[1]
MISSIONS = ROOT / "tests" / "data" / "missions"
LOGS = ROOT / "tests" / "data" / "flightlogs"
#: ``DRONEWPT_FUZZ_SCALE=N``: N times the draws, random ones (a search by hand); CI: the same draws every run
SCALE = int(os.environ.get("DRONEWPT_FUZZ_SCALE", "1"))
FUZZ = settings(CLI_FUZZ, derandomize=SCALE == 1)   # test_fuzz_cli's settings, at random when scaled


def _n(k: int) -> int:
    return k * SCALE


# ----------------------------------------------------------------------------- the run folder and its snapshot
@pytest.fixture(scope="module")
def folder():
    """The folder the draws run in (its fixed contents below); ``main`` reuses one parser meanwhile."""
    import mission_sim.cli as cli

    parser, build = cli.build_parser(), cli.build_parser
    cli.build_parser = lambda: parser
    d = Path(tempfile.mkdtemp(prefix="dronewpt-fuzz-night-"))
    (d / "a_folder").mkdir()
    (d / "a_file").write_text("")
    (d / "space name.toml").write_text("[wind]\nspeed_m_s = 2.0\n")
    (d / "ünïcödé.toml").write_text("[wind]\nspeed_m_s = 2.0\n")
    (d / "empty.toml").write_text("")
    (d / "utf16.toml").write_bytes("[wind]\nspeed_m_s = 2.0\n".encode("utf-16"))
    (d / "nan.toml").write_text("[wind]\nspeed_m_s = nan\n")
    (d / "drone.toml").write_text("[drone]\nmass_kg = 1.5\n")
    (d / "hp.json").write_text('{"learning_rate": 1e308}')
    shutil.copy(ROOT / "examples" / "study_small.toml", d / "study.toml")
    shutil.copy(MISSIONS / "qgc_simple_square.plan", d / "square.plan")
    shutil.copy(MISSIONS / "qgc_missionplanner.waypoints", d / "mp.waypoints")
    shutil.copy(MISSIONS / "dronekit_flight_pads.csv", d / "pads.csv")
    (d / "short.tlog").write_bytes((LOGS / "uavlogviewer_vtol_sitl.tlog").read_bytes()[:20_000])
    os.mkfifo(d / "fifo")
    yield d
    cli.build_parser = build
    shutil.rmtree(d, ignore_errors=True)


def _snapshot(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _restore(folder: Path, before: set[str]) -> list[str]:
    """Remove what a draw created (so that the next draw sees the same folder); the names removed."""
    new = sorted(_snapshot(folder) - before, key=len, reverse=True)
    for rel in new:
        p = folder / rel
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
    return new


def _run_undone(argv: list[str], folder: Path):
    """``_run`` in ``folder``, then what it created there removed again: ``(rc, out, err, created)``."""
    before = _snapshot(folder)
    try:
        rc, out, err = _run(argv, folder)
        created = sorted(_snapshot(folder) - before)
    finally:
        _restore(folder, before)
    return rc, out, err, created


def _spellings(token: str) -> set[str]:
    """The ways a message may name a command-line token: as given, stripped, its repr, an option without its
    dashes, a ``KEY=VALUE``'s key, a number as Python prints it, a path as :class:`Path` prints it."""
    out = {token, token.strip(), repr(token), repr(token.strip()), " ".join(token.split())}
    if token.startswith("--"):
        out |= {token[2:] + "=", token[2:] + " "}
    if "=" in token:
        out.add(token.split("=", 1)[0].strip())
    try:
        v = float(token)
        out |= {repr(v), f"{v:g}", str(v)}
    except ValueError:
        pass
    try:
        out.add(str(Path(token)))
    except (ValueError, TypeError):
        pass
    return {s for s in out if s.strip()}


def _check(argv, rc, out, err, allowed=(0, 2, 3, "reached"), names=()):
    """test_fuzz_cli's outcome rules (no traceback, an allowed status, one ``dronewpt`` line) with this file's naming
    rule: the message names a token of the command line (``names``: more spellings that count, a file's name)."""
    spellings = {s for t in argv[1:] for s in _spellings(t)} | set(names)
    sp = SUBPARSERS.get(argv[0])   # an option the command needs and was not given, named
    spellings |= {o for o in (sp._option_string_actions if sp else ()) if o.startswith("--") and o not in argv}
    _check_outcome(argv, rc, out, err, allowed, names_it=lambda msg: (
        msg.startswith("the following arguments are required: ")   # argparse's, naming what is missing
        or any(s in msg for s in spellings)))


# ----------------------------------------------------------------------------- 1. command lines
#: values for any option: numbers at the edges, strings a shell passes through, paths of every kind
NASTY = ["", " ", "0", "-0", "-1", "1", "2", "0.5", "3.5", "nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-320",
         "0x10", "1_000", " 5 ", "4294967296", "18446744073709551616", "abc", "a b", "é☃", "two\nlines", "tab\there",
         ",", ",,", "0,1", "5,1", "nan,1", "-35,149,500", "95,0,10", "x=1", "=1", "a_folder", "a_file", "fifo",
         "missing.toml", "empty.toml", "utf16.toml", "nan.toml", "space name.toml", "ünïcödé.toml", "drone.toml",
         "hp.json", "square.plan", "mp.waypoints", "pads.csv", "short.tlog", "a_file/sub", "/proc/dronewpt/out",
         "/proc/version", "out/x", "out/é ☃", "out/x.png", "out/x.toml", "step", "model_based", "nominal", "none",
         "udpout:127.0.0.1:14550", "udpout:[::1]:14550", "udpout:localhost:99999", "tcp://:0", "bogus"]
SET_ITEMS = ["battery.capacity_ah", "battery.capacity_ah=", "=3", "battery.capacity_ah==3", "nosuch.key=1",
             "pads.-1.x_m=1", "pads.99999999999999999999.x_m=1", "pads.0.x_m=[1, 2]", "wind.speed_m_s={a=1}",
             "wind.speed_m_s=-0.0", "wind.speed_m_s=1e309", "drone.n_rotors=1e100", "drone.n_rotors=4.0",
             "battery.n_series=0x10", "link.devices=", "link.devices=é☃", "sim.control_period_s=1e-320",
             "mission.file=missing.plan", "mission.pads_file=a_folder", "seed=18446744073709551616", "seed=nan",
             "mission.cruise_altitude_m=-0.0", " wind.speed_m_s = 3 ", "wind.speed_m_s=3\n", "pads.0=1"]


#: a valid value for an option without a usable default, by dest (the others: their default written out)
GOOD = {"config": "space name.toml", "log": "short.tlog", "study": "study.toml", "plan": "square.plan",
        "pads": "pads.csv", "drone": "drone.toml", "out": "out/x", "map": "out/x.png", "tlog": "out/x.tlog"}


def _good(a, command: str):
    """A valid value for action ``a`` of ``command`` (None: none known, the option is left out)."""
    if a.dest == "out" and command == "calibrate":
        return "out/x.toml"
    if a.dest in GOOD:
        return GOOD[a.dest]
    if a.choices:
        return str(a.default) if a.default in a.choices else sorted(map(str, a.choices))[0]
    if a.default is not None and not isinstance(a.default, (bool, list)):
        return str(a.default)
    return None


@st.composite
def nasty_argvs(draw):
    """A subcommand, some of its options with valid values (:func:`_good`), and one or two of them (or a positional)
    with a value from :data:`NASTY` (``--set`` and the like from :data:`SET_ITEMS`; a valid choice sometimes), the
    last of them sometimes given twice."""
    name = draw(st.sampled_from(sorted(SUBPARSERS)))
    sp = SUBPARSERS[name]
    acts = [a for a in sp._actions if not (a.option_strings and a.dest in ("help", "progress"))]
    bad = draw(st.lists(st.sampled_from(acts), min_size=1, max_size=2, unique_by=id))
    argv = [name]
    for a in acts + [bad[-1]] * draw(st.booleans()):
        required = getattr(a, "required", False) or not a.option_strings and a.nargs != "?"
        flag = [draw(st.sampled_from(a.option_strings))] if a.option_strings else []
        if a in bad:
            if a.nargs == 0:
                argv += flag
            elif a.dest in ("set", "link", "env"):
                argv += [*flag, draw(st.one_of(st.sampled_from(SET_ITEMS), st.sampled_from(NASTY)))]
            elif a.choices:
                argv += [*flag, draw(st.one_of(st.sampled_from(sorted(map(str, a.choices))), st.sampled_from(NASTY)))]
            else:
                argv += [*flag, draw(st.sampled_from(NASTY))]
        elif a.nargs != 0 and (required or draw(st.integers(0, 3)) == 0):
            good = _good(a, name)
            if good is not None:
                argv += [*flag, good]
    if "--no-plot" in sp._option_string_actions and "--no-plot" not in argv and "--out" not in argv:
        argv.append("--no-plot")
    if "--no-progress" in sp._option_string_actions:
        argv.append("--no-progress")
    return argv


@settings(FUZZ, max_examples=_n(250))
@given(argv=nasty_argvs())
def test_nasty_arguments_are_refused_in_one_line_naming_them(folder, argv, monkeypatch):
    import importlib

    for target in _WORK:
        mod, _, attr = target.rpartition(".")
        monkeypatch.setattr(importlib.import_module(mod), attr, _stub)
    _stub_long_work(monkeypatch)
    before = _snapshot(folder)
    try:
        rc, out, err = _run(argv, folder)
        event(f"{argv[0]}: {rc}")
        _check(argv, rc, out, err)
        if rc == 2:
            assert _snapshot(folder) == before, ("a refused command created", argv, sorted(_snapshot(folder) - before))
        assert not _temporaries(folder)
    finally:
        _restore(folder, before)


def _stub_long_work(monkeypatch):
    """The work of the commands without a stub in ``test_fuzz_cli._WORK``, stubbed where their checks end."""
    import importlib

    import mission_sim.cli.warmup as warmup
    monkeypatch.setattr(warmup, "STAGES", [("stub", _stub)])
    for target in ["mission_sim.studies.tolerance.ToleranceRunner", "wpt_receiver.c_export.write_export",
                   "wpt_receiver.switching.netlist.netlist", "mission_sim.mavlink.calibrate.calibrate_log"]:
        mod, _, attr = target.rpartition(".")
        monkeypatch.setattr(importlib.import_module(mod), attr, _stub)


# ----------------------------------------------------------------------------- 2. files a user brings
#: replacement values for a JSON field
JSON_VALUES = [None, True, False, 0, -1, 1e308, -1e308, math.nan, math.inf, -math.inf, 2**64, "", "x", "12", "é☃",
               [], {}, [1, 2], {"a": 1}, 91.0, -181.0, 1e-320]


def _paths(doc, prefix=()):
    """Every (path, value) of a JSON document."""
    yield prefix, doc
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))


def _replace(doc, path, value, delete=False):
    if not path:
        return value
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if delete:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return doc


@st.composite
def mutated_json(draw, text: str):
    """A JSON text with 1-3 fields replaced by :data:`JSON_VALUES` or deleted (NaN and infinity as Python's json
    writes them, which Python's json also reads)."""
    doc = json.loads(text)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p, _ in _paths(doc)]
        path = draw(st.sampled_from(paths))
        if path and draw(st.integers(0, 4)) == 0:
            doc = _replace(doc, path, None, delete=True)
        else:
            doc = _replace(doc, path, copy.deepcopy(draw(st.sampled_from(JSON_VALUES))))   # (a shared [] mutated later)
    return json.dumps(doc)


@st.composite
def mangled_bytes(draw, data: bytes):
    """``data`` truncated, with bytes flipped, re-encoded (UTF-16, Latin-1 text), with CRLF, a BOM, or empty."""
    how = draw(st.sampled_from(["cut", "cut", "flip", "utf16", "latin1", "crlf", "bom", "empty", "nul", "as is"]))
    if how == "cut":
        return data[:draw(st.integers(0, len(data)))]
    if how == "flip":
        b = bytearray(data)
        for where, xor in draw(st.lists(st.tuples(st.integers(0, max(len(b) - 1, 0)), st.integers(1, 255)),
                                        min_size=1, max_size=8)):
            if b:
                b[where] ^= xor
        return bytes(b)
    if how == "utf16":
        return data.decode("utf-8", "replace").encode("utf-16")
    if how == "latin1":
        return data.decode("utf-8", "replace").replace("0", "é").encode("latin-1", "replace")
    if how == "crlf":
        return data.replace(b"\n", b"\r\n")
    if how == "bom":
        return b"\xef\xbb\xbf" + data
    if how == "nul":
        return data[: len(data) // 2] + b"\x00" + data[len(data) // 2:]
    if how == "empty":
        return b""
    return data


WPL_FIELDS = ["nan", "inf", "-inf", "1e308", "-1e308", "abc", "", "1.5", "-1", "99999999999999999999", "0x10",
              "é", "1e-320", "91", "-181", "65536"]


@st.composite
def mutated_wpl(draw, text: str):
    """A QGC WPL text with fields replaced by :data:`WPL_FIELDS`, rows dropped or duplicated, fields removed."""
    lines = text.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(1, len(lines) - 1)) if len(lines) > 1 else 0
        how = draw(st.sampled_from(["field", "field", "field", "drop row", "dup row", "drop field", "header"]))
        f = lines[i].split("\t")
        if how == "field":
            f[draw(st.integers(0, len(f) - 1))] = draw(st.sampled_from(WPL_FIELDS))
            lines[i] = "\t".join(f)
        elif how == "drop row" and len(lines) > 1:
            del lines[i]
        elif how == "dup row":
            lines.insert(i, lines[i])
        elif how == "drop field" and len(f) > 1:
            del f[draw(st.integers(0, len(f) - 1))]
            lines[i] = "\t".join(f)
        elif how == "header":
            lines[0] = draw(st.sampled_from(["QGC WPL 110", "QGC WPL 120", "QGC WPL", "", "QGC WPL 110 extra"]))
    return "\n".join(lines) + "\n"


def _survey_plan() -> str:
    """The square plan with a survey (a ComplexItem with its VisualTransectPoints and CameraCalc) and a corridor scan
    (its generated TransectStyleComplexItem Items) inserted after the take-off: the shipped plans have none."""
    doc = json.loads((MISSIONS / "qgc_simple_square.plan").read_text())
    items = doc["mission"]["items"]
    survey = {"type": "ComplexItem", "complexItemType": "survey", "TransectStyleComplexItem": {
        "CameraCalc": {"DistanceToSurface": 25, "DistanceToSurfaceRelative": True},
        "VisualTransectPoints": [[47.3980, 8.5450], [47.3982, 8.5452], [47.3984, 8.5450]]}}
    corridor = {"type": "ComplexItem", "complexItemType": "CorridorScan", "TransectStyleComplexItem": {
        "Items": [{"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, None, 47.3981, 8.5455, 22]},
                  {"type": "SimpleItem", "command": 16, "frame": 3, "params": [0, 0, 0, None, 47.3983, 8.5457, 22]}]}}
    doc["mission"]["items"] = [items[0], survey, corridor, *items[1:]]
    return json.dumps(doc)


PLANS = {**{p.name: p.read_text() for p in MISSIONS.glob("*.plan")}, "survey.plan": _survey_plan()}
WPLS = {p.name: p.read_text() for p in MISSIONS.glob("*.waypoints")}


@st.composite
def mission_files(draw):
    """(suffix, bytes) of a mission file: a mutated .plan or .waypoints, or either mangled as bytes."""
    kind = draw(st.sampled_from(["plan", "plan", "wpl", "wpl", "bytes"]))
    if kind == "plan":
        name = draw(st.sampled_from(sorted(PLANS)))
        return ".plan", draw(mutated_json(PLANS[name])).encode()
    if kind == "wpl":
        name = draw(st.sampled_from(sorted(WPLS)))
        return ".waypoints", draw(mutated_wpl(WPLS[name])).encode()
    name = draw(st.sampled_from(sorted([*PLANS, *WPLS])))
    return Path(name).suffix, draw(mangled_bytes({**PLANS, **WPLS}[name].encode()))


def _dry_run(folder: Path, extra: list[str]):
    argv = ["mission", "--dry-run", "--format", "json", "--no-progress", "--out", "dry_out", *extra]
    rc, out, err, created = _run_undone(argv, folder)
    return argv, rc, out, err, created


@settings(FUZZ, max_examples=_n(150))
@given(f=mission_files())
def test_fuzzed_mission_files_are_refused_in_one_line_naming_the_file(folder, f):
    """``mission --plan FILE --dry-run`` with a mutated or mangled mission file: valid (checked, nothing
    simulated), or one line naming the file; nothing created either way."""
    suffix, data = f
    path = folder / f"fuzz{suffix}"
    path.write_bytes(data)
    argv, rc, out, err, created = _dry_run(folder, ["--plan", path.name])
    event(f"mission file: {rc}")
    _check(argv, rc, out, err, allowed=(0, 2), names=(path.name,))
    assert not created, (argv, created)
    if rc == 0:
        assert json.loads(out)["valid"] is True and math.isfinite(json.loads(out)["duration_s"])


PADS_CSV = (MISSIONS / "dronekit_flight_pads.csv").read_text()
PADS_GEOJSON = json.dumps({"type": "FeatureCollection", "features": [
    {"type": "Feature", "geometry": {"type": "Point", "coordinates": [149.1658531, -35.3620800, 584.0]},
     "properties": {"hover_time_s": 90}},
    {"type": "Feature", "geometry": {"type": "MultiPoint", "coordinates": [[149.1656661, -35.3622242]]},
     "properties": None}]})


@st.composite
def pads_files(draw):
    """(suffix, bytes) of a pads file: CSV with cells replaced or mangled, or mutated GeoJSON."""
    kind = draw(st.sampled_from(["csv", "csv", "geojson", "geojson", "bytes"]))
    if kind == "geojson":
        return ".geojson", draw(mutated_json(PADS_GEOJSON)).encode()
    if kind == "bytes":
        return ".csv", draw(mangled_bytes(PADS_CSV.encode()))
    rows = [r.split(",") for r in PADS_CSV.splitlines()]
    for _ in range(draw(st.integers(1, 3))):
        r = draw(st.integers(0, len(rows) - 1))
        c = draw(st.integers(0, len(rows[r]) - 1))
        rows[r][c] = draw(st.sampled_from(WPL_FIELDS + ["lat", "LAT", "hover_time", "alt", "\"1,2\""]))
    return ".csv", ("\n".join(",".join(r) for r in rows) + "\n").encode()


@settings(FUZZ, max_examples=_n(80))
@given(f=pads_files())
def test_fuzzed_pads_files_are_refused_in_one_line_naming_the_file(folder, f):
    suffix, data = f
    path = folder / f"fuzz_pads{suffix}"
    path.write_bytes(data)
    argv, rc, out, err, created = _dry_run(folder, ["--plan", "square.plan", "--pads", path.name])
    event(f"pads file: {rc}")
    _check(argv, rc, out, err, allowed=(0, 2), names=(path.name,))
    assert not created, (argv, created)


def _drone_keys():
    from dataclasses import fields
    return [f.name for f in fields(mconfig._SECTIONS["drone"])]


TOML_VALUES = ["nan", "inf", "-inf", "1e308", "-1", "0", "1.5", "\"1.5\"", "true", "[1]", "{a = 1}", "\"\"",
               "18446744073709551616", "1e-320", "-0.0"]


@st.composite
def drone_files(draw):
    """(bytes) of a ``--drone`` TOML: [drone] keys with drawn values, unknown keys, another table, or mangled."""
    kind = draw(st.sampled_from(["keys", "keys", "keys", "bytes"]))
    base = "[drone]\nmass_kg = 1.5\nrotor_radius_m = 0.12\n"
    if kind == "bytes":
        return draw(mangled_bytes(base.encode()))
    keys = draw(st.lists(st.sampled_from(_drone_keys() + ["mass", "nosuch"]), min_size=1, max_size=3, unique=True))
    lines = ["[drone]", *(f"{k} = {draw(st.sampled_from(TOML_VALUES))}" for k in keys)]
    if draw(st.integers(0, 5)) == 0:
        lines += ["[battery]", "capacity_ah = 2.0"]
    return ("\n".join(lines) + "\n").encode()


@settings(FUZZ, max_examples=_n(60))
@given(data=drone_files())
def test_fuzzed_drone_files_are_refused_in_one_line_naming_them(folder, data):
    path = folder / "fuzz_drone.toml"
    path.write_bytes(data)
    argv, rc, out, err, created = _dry_run(folder, ["--drone", path.name])
    event(f"drone file: {rc}")
    _check(argv, rc, out, err, allowed=(0, 2), names=(path.name, "drone."))
    assert not created, (argv, created)


LOG_PREFIX = 40_000
LOG_DATA = {n: (LOGS / n).read_bytes()[:LOG_PREFIX] for n in ("dronekit-python_flight.tlog",
                                                               "dronekit-la-testdata_log171.bin",
                                                               "uavlogviewer_vtol_sitl.tlog",
                                                               "pyulog_sample_log_small.ulg")}


@st.composite
def log_files(draw):
    name = draw(st.sampled_from(sorted(LOG_DATA)))
    suffix = draw(st.sampled_from([Path(name).suffix, Path(name).suffix, ".tlog", ".bin", ".ulg", ".log"]))
    return suffix, draw(mangled_bytes(LOG_DATA[name]))


@settings(FUZZ, max_examples=_n(40))
@given(f=log_files(), command=st.sampled_from(["mission", "calibrate", "replay"]))
def test_fuzzed_flight_logs_are_refused_in_one_line_naming_them(folder, f, command, monkeypatch):
    """A truncated / flipped / re-encoded / empty flight log as ``mission --plan LOG --dry-run``, ``calibrate LOG``
    (the fit stubbed) or ``replay LOG`` (the replay stubbed): valid, reached, or one line naming the log."""
    import mission_sim.mavlink.calibrate as cal
    import mission_sim.mavlink.replay as rep
    suffix, data = f
    path = folder / f"fuzz_log{suffix}"
    path.write_bytes(data)
    if command == "mission":
        argv, rc, out, err, created = _dry_run(folder, ["--plan", path.name])
    else:
        monkeypatch.setattr(cal, "calibrate_log", _stub)
        monkeypatch.setattr(rep, "replay_log", _stub)
        argv = [command, path.name, "--no-plot", "--out", "log_out/d.toml" if command == "calibrate" else "log_out"]
        rc, out, err, created = _run_undone([*argv, *(["--no-progress"] if command == "replay" else [])], folder)
    event(f"{command} log: {rc}")
    _check(argv, rc, out, err, allowed=(0, 2, "reached"), names=(path.name,))
    if rc == 2:
        assert not created, (argv, created)


# ----------------------------------------------------------------------------- 2b. study files and sweep folders
def _toml(doc: dict) -> str:
    """``doc`` as TOML, every top-level key an inline value (keys quoted: a dotted key is one key)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return "nan" if v != v else "inf" if v == math.inf else "-inf" if v == -math.inf else repr(v)
        if isinstance(v, int):
            return str(v) if -2**63 <= v < 2**63 else json.dumps(str(v))
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v if x is not None) + "]"
        return "{" + ", ".join(f"{json.dumps(str(k))} = {val(x)}" for k, x in v.items() if x is not None) + "}"
    if not isinstance(doc, dict):   # (the whole document replaced: not TOML)
        return json.dumps(doc)
    return "".join(f"{json.dumps(str(k))} = {val(v)}\n" for k, v in doc.items() if v is not None)


STUDIES = {p.name: p for p in (ROOT / "examples").glob("study_*.toml")}


@st.composite
def study_files(draw):
    """A shipped study (its paths made absolute) with 1-3 fields replaced by :data:`JSON_VALUES` or deleted."""
    import tomllib
    name = draw(st.sampled_from(sorted(STUDIES)))
    doc = tomllib.loads(STUDIES[name].read_text())
    for key in ("log", "pads"):
        if key in doc.get("replay", {}):
            doc["replay"][key] = str((ROOT / "examples" / doc["replay"][key]).resolve())
    return _toml(json.loads(draw(mutated_json(json.dumps(doc)))))


@settings(FUZZ, max_examples=_n(80))
@given(text=study_files())
def test_fuzzed_study_files_are_refused_in_one_line(folder, text, monkeypatch):
    """``sweep STUDY --workers 0`` with a mutated shipped study (any field, not only the grid: a section that is
    not a table, a base that is not a path, a window of strings): reached (the sweep stubbed) or one line naming the
    study's key or file; nothing created."""
    import mission_sim.studies.sweep as sweep_mod

    monkeypatch.setattr(sweep_mod, "run_sweep", _stub)
    path = folder / "fuzz_study.toml"
    path.write_text(text)
    argv = ["sweep", path.name, "--out", "fuzz_sweep", "--workers", "0", "--no-plot", "--no-progress"]
    rc, out, err, created = _run_undone(argv, folder)
    event(f"study: {rc}")
    _check(argv, rc, out, err, allowed=(2, "reached"), names=(path.name, "[", "study", "policy", "pads", "--"))
    if rc == 2:
        assert not created, (argv, created)


@st.composite
def manifests(draw):
    """A sweep folder's ``sweep.json``: a real manifest's fields replaced or deleted, or its bytes mangled."""
    man = {"study": "study_small", "n_cases": 48, "fingerprint": "0123456789abcdef", "physics_code": "abc",
           "doc": {"study": {"name": "study_small"}, "grid": {"policy": ["step"], "pads.1.x_m": [20.0]}}}
    if draw(st.booleans()):
        return draw(mangled_bytes(json.dumps(man).encode()))
    return draw(mutated_json(json.dumps(man))).encode()


@settings(FUZZ, max_examples=_n(40))
@given(data=manifests(), command=st.sampled_from(["status", "sizing"]))
def test_fuzzed_sweep_manifests_are_refused_in_one_line(folder, data, command):
    """``sweep --status DIR`` and ``sizing --source sweep --sweep DIR`` over a folder whose sweep.json is damaged:
    a result, or one line naming the folder or its sweep.json."""
    d = folder / "fuzz_sweep_dir"
    d.mkdir(exist_ok=True)
    (d / "sweep.json").write_bytes(data)
    argv = (["sweep", "--status", d.name] if command == "status" else
            ["sizing", "--source", "sweep", "--sweep", d.name, "--no-plot", "--no-progress"])
    rc, out, err, created = _run_undone(argv, folder)
    event(f"manifest {command}: {rc}")
    _check(argv, rc, out, err, allowed=(0, 2), names=(d.name, "sweep.json"))
    assert not created, (argv, created)


# ----------------------------------------------------------------------------- 3. what the fuzz found (each fails on the code before)
WPL = "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1\n{row}\n"
ROW = ["1", "0", "3", "16", "0", "0", "0", "0", "47.398742", "8.546594", "20", "1"]


def _wpl_row(col: int, value: str) -> str:
    f = list(ROW)
    f[col] = value
    return WPL.format(row="\t".join(f))


@pytest.mark.parametrize("col,value,text", [
    (3, "inf", "w.waypoints: line 3: command=inf is invalid; valid range: integer 0..65535"),
    (3, "16.5", "w.waypoints: line 3: command=16.5 is invalid; valid range: integer 0..65535"),
    (0, "nan", "w.waypoints: line 3: index=nan is invalid; valid range: integer 0..65535"),
    (2, "-inf", "w.waypoints: line 3: frame=-inf is invalid; valid range: integer 0..255"),
], ids=["command inf (OverflowError traceback)", "command 16.5 (taken as 16)", "index nan (no file named)",
        "frame -inf"])
def test_a_waypoints_integer_field_that_is_not_an_integer_is_refused(folder, col, value, text):
    (folder / "w.waypoints").write_text(_wpl_row(col, value))
    argv, rc, out, err, created = _dry_run(folder, ["--plan", "w.waypoints"])
    assert rc == 2 and err.strip().splitlines() == [f"dronewpt mission: error: {text}"], err
    assert "Traceback" not in err and not created


@pytest.mark.parametrize("col,value", [(8, "1e308"), (9, "inf")])
def test_a_far_off_latitude_is_refused_without_a_numpy_warning(folder, col, value):
    """Latitude 1e308 / longitude inf in a mission item: numpy's overflow RuntimeWarning (two more stderr lines) came
    before the one-line error (the ENU conversion ran before the range check)."""
    import warnings
    (folder / "w.waypoints").write_text(_wpl_row(col, value))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        argv, rc, out, err, created = _dry_run(folder, ["--plan", "w.waypoints"])
    assert rc == 2 and "w.waypoints: row 1: l" in err and len(err.strip().splitlines()) == 1, err
    assert [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)] == []


def test_the_plan_note_is_not_printed_before_a_refusal(folder):
    """``--plan`` without ``--pads`` and a bad ``--policy``: the note on the built-in pads came first, two lines."""
    argv, rc, out, err, created = _dry_run(folder, ["--plan", "square.plan", "--policy", "bogus"])
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("dronewpt mission: error: --policy 'bogus'"), err
    argv, rc, out, err, created = _dry_run(folder, ["--plan", "square.plan"])   # a valid run still says it
    assert rc == 0 and "note: --plan without --pads keeps the built-in mission's 2 pads" in err


def test_a_refused_command_leaves_no_output_folder(folder):
    """``calibrate`` on a log without battery data: its --out folder was made before the log was read, and stayed."""
    shutil.copy(LOGS / "uavlogviewer_vtol_sitl.tlog", folder / "vtol.tlog")
    try:
        argv = ["calibrate", "vtol.tlog", "--out", "new_cal/sub/drone.toml", "--no-plot"]
        rc, out, err = _run(argv, folder)
        assert rc == 2 and "the log has no battery data" in err and len(err.strip().splitlines()) == 1, err
        assert not (folder / "new_cal").exists()
        (folder / "kept").mkdir()   # a folder that was there before stays
        rc, out, err = _run(["calibrate", "vtol.tlog", "--out", "kept/drone.toml", "--no-plot"], folder)
        assert rc == 2 and (folder / "kept").is_dir()
    finally:
        (folder / "vtol.tlog").unlink()
        shutil.rmtree(folder / "kept", ignore_errors=True)


@pytest.mark.parametrize("argv,kept", [
    (["calibrate", "vtol.tlog", "--out", "nonexist/../keep_me/drone.toml", "--no-plot"], "keep_me"),
    (["calibrate", "vtol.tlog", "--out", "{abs}/nonexist/../keep_me/drone.toml", "--no-plot"], "keep_me"),
    (["calibrate", "vtol.tlog", "--out", "nx/../user/empty_sub/drone.toml", "--no-plot"], "user/empty_sub"),
    (["telemetry", "--connect", "none", "--tlog", "nx/../tl_empty/x.tlog", "--policy", "bogus"], "tl_empty"),
], ids=["nonexist/../keep_me", "absolute", "nested user/empty_sub", "telemetry --tlog nx/../tl_empty"])
def test_a_refused_command_keeps_the_users_folders_named_after_dotdot(folder, argv, kept):
    """An out path with ``..`` after a missing folder: every level missing before ``mkdir(parents=True)`` was
    recorded as made by the command, ``nonexist/..`` and ``nonexist/../keep_me`` too, and the refusal (exit 2)
    removed the user's own empty ``keep_me`` (prepare_out_dir; reviewer's finding on the clifuzz branch)."""
    shutil.copy(LOGS / "uavlogviewer_vtol_sitl.tlog", folder / "vtol.tlog")
    (folder / kept).mkdir(parents=True)
    before = _snapshot(folder)
    try:
        rc, out, err = _run([a.replace("{abs}", str(folder)) for a in argv], folder)
        assert rc == 2 and len(err.strip().splitlines()) == 1, err
        assert (folder / kept).is_dir(), f"the refused command removed the user's folder {kept!r}"
        assert _snapshot(folder) == before, sorted(_snapshot(folder) ^ before)   # its own 'nonexist' removed
    finally:
        _restore(folder, before)
        (folder / "vtol.tlog").unlink()
        shutil.rmtree(folder / kept.split("/")[0], ignore_errors=True)


def test_a_folder_made_meanwhile_by_another_run_is_not_removed(folder, monkeypatch):
    """A folder another run makes between this run's check and its mkdir is not this run's: a refusal keeps it
    (it was recorded as made here and removed). The other run is a patched ``Path.mkdir`` that makes it first."""
    import pathlib
    shutil.copy(LOGS / "uavlogviewer_vtol_sitl.tlog", folder / "vtol.tlog")
    real = pathlib.Path.mkdir
    race = folder / "race"

    def mkdir(self, *a, **k):
        if self.name == "race" and not race.exists():
            os.mkdir(race)   # the other run, just before ours
        return real(self, *a, **k)

    monkeypatch.setattr(pathlib.Path, "mkdir", mkdir)
    try:
        rc, out, err = _run(["calibrate", "vtol.tlog", "--out", "race/drone.toml", "--no-plot"], folder)
        assert rc == 2 and "the log has no battery data" in err, err
        assert race.is_dir(), "the refused command removed a folder another run had made"
    finally:
        (folder / "vtol.tlog").unlink()
        shutil.rmtree(race, ignore_errors=True)


def _cut_ulog() -> bytes:
    """A ULog whose last message header (in its definitions section) is corrupt (size 20,000) and cut by the end."""
    import struct
    pad = (struct.pack("<HB", 50, ord("Z")) + bytes(50)) * 420   # unknown messages: skipped
    return b"ULog\x01\x12\x35\x01" + bytes(8) + pad + struct.pack("<HB", 20000, ord("Z")) + b"abc"


def test_the_cut_ulog_guard_is_the_one_pyulog_calls(folder, monkeypatch):
    """``CutSafeULog`` overrides pyulog's private ``_check_packet_corruption``: a pyulog that renamed it would skip the
    guard silently and hang (caught only by an alarm). Here the override must run on the cut log and decide the end."""
    from mission_sim.mavlink import ulog as ulog_mod
    cls = ulog_mod._ulog_class()
    assert cls.__name__ == "CutSafeULog", "pyulog's internals changed: the cut-log guard is off"
    decided, real = [], cls._check_packet_corruption

    def spy(self, header):
        decided.append(real(self, header))
        return decided[-1]

    monkeypatch.setattr(cls, "_check_packet_corruption", spy)
    (folder / "cut.ulg").write_bytes(_cut_ulog())
    try:
        log = ulog_mod.read_ulog(folder / "cut.ulg")
    finally:
        (folder / "cut.ulg").unlink()
    assert decided and decided[-1] is False, decided   # the corrupt, cut header: ended by the override
    assert log.errors == [], log.errors


def test_a_pyulog_without_the_hooked_internals_is_said(folder, monkeypatch):
    """A pyulog without ``ULog._check_packet_corruption``: plain ``ULog`` and a RuntimeWarning naming it (not a guard
    that is never called); without ``ULog._file_handle``: the override raises, the log's error names it."""
    import pyulog

    from mission_sim.mavlink import ulog as ulog_mod

    class Renamed:   # a pyulog whose ULog has neither
        def __init__(self, fh):
            self._check_packet_corruption(None)

    monkeypatch.setattr(pyulog, "ULog", Renamed)
    ulog_mod._ulog_class.cache_clear()
    try:
        with pytest.warns(RuntimeWarning, match="no ULog._check_packet_corruption"):
            assert ulog_mod._ulog_class() is Renamed
        ulog_mod._ulog_class.cache_clear()
        Renamed._check_packet_corruption = lambda self, header: True
        (folder / "cut.ulg").write_bytes(_cut_ulog())
        log = ulog_mod.read_ulog(folder / "cut.ulg")
        assert len(log.errors) == 1 and "has no ULog._file_handle" in log.errors[0], log.errors
    finally:
        (folder / "cut.ulg").unlink(missing_ok=True)
        ulog_mod._ulog_class.cache_clear()


def test_a_cut_ulog_with_a_corrupt_header_does_not_hang(folder):
    """A ULog whose last message header is corrupt (size > 10,000) and cut by the end of the file: pyulog 1.3 sought
    back 2 + that size, into the messages before it, and read them again forever (``replay``, ``mission --plan``)."""
    (folder / "cut.ulg").write_bytes(_cut_ulog())
    try:
        argv, rc, out, err, created = _dry_run(folder, ["--plan", "cut.ulg"])   # (_run: a 30 s alarm fails the test)
        assert rc == 2 and err.strip().splitlines() == [
            "dronewpt mission: error: cut.ulg: no flown track: 0 usable position(s) (GPS fix >= 3)"], err   # (no armed state read)
    finally:
        (folder / "cut.ulg").unlink()


def test_a_set_item_without_a_key_is_refused_in_the_flags_words(folder):
    argv, rc, out, err, created = _dry_run(folder, ["--set", "=3"])
    assert rc == 2 and err.strip() == ("dronewpt mission: error: --set '=3' is invalid; valid form: KEY=VALUE (e.g. "
                                       "battery.capacity_ah=2.0)"), err


def test_a_complex_item_whose_tables_are_not_objects_is_refused(folder):
    for key, value, text in (("TransectStyleComplexItem", True, "TransectStyleComplexItem=true"),
                             ("CameraCalc", [1, 2], "CameraCalc=[1, 2]")):
        doc = json.loads(_survey_plan())
        item = doc["mission"]["items"][1]
        if key == "CameraCalc":
            item["TransectStyleComplexItem"]["CameraCalc"] = value
        else:
            item[key] = value
        (folder / "c.plan").write_text(json.dumps(doc))
        argv, rc, out, err, created = _dry_run(folder, ["--plan", "c.plan"])
        assert rc == 2 and err.strip() == (f"dronewpt mission: error: c.plan: item 1 (survey): {text} is invalid; "
                                           "valid: a JSON object {...}"), err


@pytest.mark.parametrize("value,text", [(5, "5"), (None, "null")])
def test_a_generated_item_that_is_not_an_object_is_said_like_the_tables(folder, value, text):
    """A corridor scan's generated item that is not a JSON object: the wording of ``_json_object`` (it said
    ``... is not a JSON object``, a second wording of the same check); null is refused too."""
    doc = json.loads(_survey_plan())
    doc["mission"]["items"][2]["TransectStyleComplexItem"]["Items"][0] = value
    (folder / "c.plan").write_text(json.dumps(doc))
    argv, rc, out, err, created = _dry_run(folder, ["--plan", "c.plan"])
    assert rc == 2 and err.strip() == (f"dronewpt mission: error: c.plan: item 2 (CorridorScan), generated item 0={text}"
                                       " is invalid; valid: a JSON object {...}"), err


@pytest.mark.parametrize("text,message", [
    ("grid = 3\n", "[grid] = 3 is invalid; valid type: table ([grid] and its keys)"),
    ("monte_carlo = 2\n", "[monte_carlo] = 2 is invalid; valid type: table ([monte_carlo] and its keys)"),
    ("[monte_carlo]\nn = 3\nparams = 2\n",
     "[monte_carlo] params = 2 is invalid; valid type: table ([monte_carlo.params])"),
    ("[study]\nbase = 3\n[grid]\npolicy = [\"step\"]\n", "[study] base = 3 is invalid; valid: a mission TOML's path"),
], ids=["grid = 3", "monte_carlo = 2", "params = 2", "base = 3"])
def test_a_study_section_of_the_wrong_type_is_refused(folder, text, message, monkeypatch):
    import mission_sim.studies.sweep as sweep_mod
    monkeypatch.setattr(sweep_mod, "run_sweep", _stub)
    (folder / "s.toml").write_text(text)
    rc, out, err = _run(["sweep", "s.toml", "--out", "s_out", "--workers", "0", "--no-plot"], folder)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and message in err, err
    assert not (folder / "s_out").exists()


@pytest.mark.parametrize("manifest,what", [
    ("{}", "no 'study' (a string, the study's name)"), ("[]", "not a JSON object"),
    ('{"study": 3, "fingerprint": "f", "doc": {}}', "'study' = 3 is invalid; valid: a string, the study's name)"),
    ('{"study": "s", "fingerprint": "f", "doc": [1]}', "'doc' = [1] is invalid; valid: a JSON object, the study)"),
    ('{"study": "s", "fingerprint": "f", "doc": {}}', "its study: study 's' varies nothing"),
    ('{"study": "s", "fingerprint": "f", "doc": {"study": null}}', None),
], ids=["{}", "[]", "study 3 (was: no 'study')", "doc a list", "doc {}", "doc's study null"])
def test_a_damaged_sweep_manifest_is_refused_naming_it(folder, manifest, what):
    d = folder / "damaged"
    d.mkdir(exist_ok=True)
    (d / "sweep.json").write_text(manifest)
    for argv in (["sweep", "--status", "damaged"], ["sizing", "--source", "sweep", "--sweep", "damaged", "--no-plot"]):
        rc, out, err = _run(argv, folder)
        assert rc == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (argv, err)
        if what is not None and argv[0] == "sweep":
            assert f"'damaged/sweep.json' is not a valid sweep manifest ({what}" in err, err
