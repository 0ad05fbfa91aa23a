"""Property-based fuzz of the command line (issue 25): config files and CLI arguments drawn from the
config schema and the parsers themselves, run through ``mission_sim.cli.main`` in-process.

Every draw must end in one of three ways: exit status 0 or 3 (a run), the work function reached with
every argument checked (the expensive functions are replaced by a stub that stops there), or exit
status 2 with exactly one line on stderr that names a key or an option. Never a traceback, never a
hang (an alarm stops a draw after 30 s), never a temporary file left behind.

Draws per run: 300 config files + 200 argument lists + 100 study grids + 12 short missions run to the
end, in-process;
3 more missions as subprocesses (a traceback there would reach stderr unfiltered).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
from dataclasses import fields
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from mission_sim import config as mconfig
from mission_sim.cli import build_parser, main
from mission_sim.cli.common import parse_set

ROOT = Path(__file__).resolve().parents[1]
SECTIONS = {**mconfig._SECTIONS, "pads": mconfig.PadConfig}
#: (section, key, Range or None for strings) of every config key: the schema the draws come from
SCHEMA = [(sec, f.name, mconfig.plausible_range(sec, f.name)) for sec, cls in SECTIONS.items() for f in fields(cls)]
FUZZ = settings(deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
                derandomize=True)
#: the message names a key or an option: a dotted key, an --option, a named file or argument, or a key=value
NAMES_SOMETHING = re.compile(r"--[a-z][a-z-]*|\b[a-z_]+\.[a-z_0-9.]+|\bseed\b|\bpads\b|config file|study file|"
                             r"\blog\b|argument [a-z]|\b[a-z_]+=|hyperparams file|[a-z_]+ is not a valid key")


class _Reached(Exception):
    """A stubbed work function was called: every argument had been checked."""


class _Hang(BaseException):
    """A draw took longer than the alarm."""


def _alarm(signum, frame):
    raise _Hang


# ----------------------------------------------------------------------------- drawing values
def _numbers(rng):
    """In-range values, the range's ends, just outside, and the extremes of a float."""
    inside = (st.integers(int(rng.lo), int(rng.hi)) if rng.integer else
              st.floats(max(rng.lo, -1e300), min(rng.hi, 1e300), exclude_min=rng.lo_open, exclude_max=rng.hi_open))
    span = rng.hi - rng.lo
    outside = st.sampled_from([rng.lo - max(1.0, abs(rng.lo)), rng.hi + max(1.0, 0.5 * span), -rng.hi - 1.0,
                               rng.lo, rng.hi])
    return st.one_of(inside, inside, outside, st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 0, -1]))


WRONG_TYPE = st.one_of(st.text(max_size=5), st.booleans(), st.just([]), st.just({}), st.just([1.0, 2.0]),
                       st.just(""), st.integers(-2**70, 2**70))


def _value(rng):
    """A value for a key with range ``rng`` (None: a string key such as link.devices)."""
    if rng is None:
        return st.one_of(st.sampled_from(["schottky", "ideal", "sic", "default", "", "bogus"]), WRONG_TYPE)
    return st.one_of(_numbers(rng), _numbers(rng), WRONG_TYPE)


@st.composite
def config_docs(draw):
    """A mission config document: some keys of some sections (their values from :func:`_value`),
    sometimes a [[pads]] list, an unknown key or section, a seed, or a section that is not a table."""
    doc: dict = {}
    for sec, name, rng in draw(st.lists(st.sampled_from(SCHEMA), max_size=6)):
        if sec == "pads":
            pads = doc.setdefault("pads", [{} for _ in range(draw(st.integers(1, 3)))])
            pads[draw(st.integers(0, len(pads) - 1))][name] = draw(_value(rng))
        else:
            doc.setdefault(sec, {})[name] = draw(_value(rng))
    extra = draw(st.sampled_from(["none", "none", "none", "seed", "unknown key", "unknown section", "not a table",
                                  "empty table", "empty pads"]))
    if extra == "seed":
        doc["seed"] = draw(st.one_of(st.integers(-5, 2**64), st.floats(allow_nan=True), st.text(max_size=3)))
    elif extra == "unknown key":
        doc.setdefault("battery", {})["capacity_mah"] = 1300
    elif extra == "unknown section":
        doc["motors"] = {"kv": 900}
    elif extra == "not a table":
        doc["wind"] = 3.0
    elif extra == "empty table":
        doc["charger"] = {}
    elif extra == "empty pads":
        doc["pads"] = []
    return doc


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v) if -2**63 <= v < 2**63 else json.dumps(str(v))  # TOML integers are 64-bit
    if isinstance(v, float):
        return "nan" if v != v else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"


def to_toml(doc: dict) -> str:
    """A TOML text of ``doc`` (values first, then tables, then [[pads]])."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in doc.items() if not isinstance(v, (dict, list)) or k == "pads"
             and not all(isinstance(p, dict) for p in v)]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += [f"[{k}]", *(f"{n} = {_toml_value(x)}" for n, x in v.items())]
    if isinstance(doc.get("pads"), list) and doc["pads"] and all(isinstance(p, dict) for p in doc["pads"]):
        for p in doc["pads"]:
            lines += ["[[pads]]", *(f"{n} = {_toml_value(x)}" for n, x in p.items())]
    elif doc.get("pads") == []:
        lines.insert(0, "pads = []")
    return "\n".join(lines) + "\n"


def _set_args(draw_pairs) -> list[str]:
    return [a for key, text in draw_pairs for a in ("--set", f"{key}={text}")]


SET_TEXT = st.sampled_from(["1e308", "-1e308", "nan", "inf", "-1", "0", "1", "2.5", "'x'", "", "true", "[1]", "1e-300"])
SET_KEY = st.one_of(st.sampled_from([f"{s}.{n}" if s != "pads" else f"pads.0.{n}" for s, n, _ in SCHEMA]),
                    st.sampled_from(["pads.9.x_m", "nosuch.key", "seed", "battery", "", "pads.x.y"]))


# ----------------------------------------------------------------------------- running main in-process
def _run(argv, cwd: Path, timeout_s: int = 30):
    """(outcome, stdout, stderr): outcome is the exit status or "reached" (a stubbed work function)."""
    out, err = io.StringIO(), io.StringIO()
    old_cwd, old = os.getcwd(), signal.signal(signal.SIGALRM, _alarm)
    os.chdir(cwd)
    signal.alarm(timeout_s)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = int(main(argv) or 0)
            except SystemExit as exc:
                rc = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
            except _Reached:
                rc = "reached"
    except _Hang:
        pytest.fail(f"hang: {argv!r} ran longer than {timeout_s} s")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
        os.chdir(old_cwd)
    return rc, out.getvalue(), err.getvalue()


def _temporaries(folder: Path) -> list[str]:
    return [str(p) for p in folder.rglob("*") if ".tmp" in p.name or p.name.startswith(".dronewpt-write-test")]


def _check_outcome(argv, rc, out, err, allowed=(0, 2, 3, "reached"), names_it=None):
    """No traceback, an allowed exit status, and for 2 one ``dronewpt`` line whose message names what was bad:
    ``names_it(message)`` is true (default: it matches :data:`NAMES_SOMETHING`)."""
    assert "Traceback" not in err and "Traceback" not in out, (argv, err)
    assert rc in allowed, (argv, rc, err)
    if rc == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1, (argv, err)
        assert lines[0].startswith("dronewpt"), (argv, err)
        msg = lines[0].split("error:", 1)[-1].strip()
        assert (names_it or NAMES_SOMETHING.search)(msg), ("names nothing", argv, lines[0])


@pytest.fixture(scope="module")
def folder():
    """The folder the draws run in: a_folder, a_file, a FIFO, a valid config, a study, hyperparameters.
    ``main`` reuses one parser meanwhile (building it is 70 % of a refused draw's time)."""
    import mission_sim.cli as cli

    parser, build = cli.build_parser(), cli.build_parser
    cli.build_parser = lambda: parser
    d = Path(tempfile.mkdtemp(prefix="dronewpt-fuzz-"))
    (d / "a_folder").mkdir()
    (d / "a_file").write_text("")
    os.mkfifo(d / "fifo")
    (d / "bad.toml").write_text("x = = 1\n")
    (d / "short.toml").write_text(SHORT_MISSION)
    shutil.copy(ROOT / "examples" / "study_small.toml", d / "study.toml")
    (d / "hp.json").write_text('{"learning_rate": "abc"}')
    (d / "hp.yml").write_text("learning_rate: [1,\n")
    yield d
    cli.build_parser = build
    shutil.rmtree(d, ignore_errors=True)


#: a mission of a few seconds: one pad, a 2 s hover, start and landing 3 m away
SHORT_MISSION = """
[[pads]]
x_m = 0.0
y_m = 0.0
hover_time_s = 2.0
[mission]
start_x_m = -3.0
land_x_m = 3.0
cruise_altitude_m = 1.0
"""


# ----------------------------------------------------------------------------- 1. config files
@settings(FUZZ, max_examples=300)
@given(doc=config_docs(), sets=st.lists(st.tuples(SET_KEY, SET_TEXT), max_size=2))
def test_fuzzed_config_files_are_checked_in_one_line(folder, doc, sets):
    """``mission CONFIG --dry-run``: a drawn config file and --set overrides are either valid (every
    value then lies in its plausible range, no NaN, no infinity) or refused in one line naming the key."""
    path = folder / "fuzz.toml"
    path.write_text(to_toml(doc))
    argv = ["mission", str(path), "--dry-run", "--format", "json", *_set_args(sets)]
    rc, out, err = _run(argv, folder)
    event(f"exit status {rc}")
    _check_outcome(argv, rc, out, err, allowed=(0, 2))
    if rc == 0:
        overrides = parse_set([f"{k}={t}" for k, t in sets])
        cfg = mconfig.config_from_dict(mconfig.apply_overrides(mconfig.load_config_dict(path), overrides))
        for sec, name, rng in SCHEMA:
            values = [getattr(p, name) for p in cfg.pads] if sec == "pads" else [getattr(getattr(cfg, sec), name)]
            for v in values:
                assert rng is None or v is None or rng.contains(v), (sec, name, v)
        assert json.loads(out)["valid"] is True
    assert not _temporaries(folder)


def test_a_nan_in_the_config_is_always_refused():
    """Not a draw: NaN and infinities for every numeric key, one by one, are refused naming that key
    (the config layer that ``mission``, ``replay``, ``telemetry``, ``sizing`` and ``sweep`` share)."""
    base = mconfig.load_config_dict()
    for sec, name, rng in SCHEMA:
        if rng is None:
            continue
        key = f"pads.0.{name}" if sec == "pads" else f"{sec}.{name}"
        for value in (math.nan, math.inf, -math.inf, 1e308):
            with pytest.raises(ValueError) as exc:
                mconfig.config_from_dict(mconfig.apply_overrides(base, {key: value}))
            assert str(exc.value).startswith(f"{key}={value!r} is invalid; valid "), str(exc.value)


# ----------------------------------------------------------------------------- 2. CLI arguments
_WORK = ["mission_sim.world.runner.run_mission", "wpt_receiver.paper.run_paper", "policies.compare.compare",
         "policies.compare.frontier", "policies.train.train", "mission_sim.studies.sweep.run_sweep",
         "mission_sim.studies.cluster.dask_client", "mission_sim.mavlink.replay.replay_log",
         "mission_sim.mavlink.follow.open_follow", "wpt_receiver.sizing.size_policies",
         "mission_sim.figures.mission.plot_lm_map"]
ARG_VALUES = ["", "0", "-1", "1", "2", "3.5", "nan", "inf", "-inf", "1e308", "-1e308", "1000000", "abc", ",",
              "a_folder", "a_file", "fifo", "missing.toml", "bad.toml", "short.toml", "study.toml", "hp.json",
              "hp.yml", "x=1", "battery.capacity_ah=1e308", "drone.mass_kg=nan", "step", "model_based",
              "nominal", "none", "udpout:127.0.0.1:14550", "bogus", "0,1", "-35,149,500", "out/x", "a_file/sub"]


def _subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return action.choices


SUBPARSERS = _subparsers()


@st.composite
def argvs(draw):
    """A subcommand and some of its options (and positionals) with values from :data:`ARG_VALUES`,
    a valid choice or a bogus one; required options are usually given."""
    name = draw(st.sampled_from(sorted(SUBPARSERS)))
    sp = SUBPARSERS[name]
    argv = [name]
    for a in sp._actions:
        if a.option_strings and a.dest == "help":
            continue
        required = getattr(a, "required", False) or not a.option_strings and a.nargs != "?"
        if not draw(st.booleans()) and not (required and draw(st.integers(0, 9)) > 0):
            continue
        flag = [a.option_strings[-1]] if a.option_strings else []
        if a.nargs == 0:
            argv += flag
        elif a.choices:
            argv += [*flag, draw(st.one_of(st.sampled_from(list(a.choices)), st.sampled_from(ARG_VALUES)))]
        elif a.default is not None and not isinstance(a.default, (bool, list)) and draw(st.booleans()):
            argv += [*flag, str(a.default)]  # its default written out: more draws get past the checks
        else:
            argv += [*flag, draw(st.sampled_from(ARG_VALUES))]
    if name in ("mission", "sizing", "compare", "replay", "paper", "coupling"):
        argv += ["--no-plot"] if "--no-plot" in sp._option_string_actions else []
    return argv


@settings(FUZZ, max_examples=200)
@given(argv=argvs())
def test_fuzzed_arguments_are_checked_before_any_work(folder, argv, monkeypatch):
    """Every subcommand with drawn options: refused in one line naming the option, or every check passed
    when the work starts (the work functions are stubs that stop there), or a cheap command's own result."""
    import importlib

    for target in _WORK:
        mod, _, attr = target.rpartition(".")
        monkeypatch.setattr(importlib.import_module(mod), attr, _stub)
    rc, out, err = _run(argv, folder)
    event(f"{argv[0]}: {rc}")  # pytest --hypothesis-show-statistics: the outcomes per subcommand
    _check_outcome(argv, rc, out, err)
    assert not _temporaries(folder)


def _stub(*args, **kwargs):
    raise _Reached


# ----------------------------------------------------------------------------- 2b. study files
@st.composite
def study_docs(draw):
    """A study varying one or two drawn keys over 1-3 drawn values each, and the policy."""
    grid = {}
    for sec, name, rng in draw(st.lists(st.sampled_from(SCHEMA), min_size=1, max_size=2, unique=True)):
        key = f"pads.0.{name}" if sec == "pads" else f"{sec}.{name}"
        grid[key] = draw(st.lists(_value(rng), min_size=1, max_size=3))
    grid["policy"] = draw(st.sampled_from([["step"], ["model_based", "ramp"], ["bogus"]]))
    return grid


@settings(FUZZ, max_examples=100)
@given(grid=study_docs())
def test_fuzzed_studies_are_checked_case_by_case_before_the_sweep(folder, grid, monkeypatch):
    """``sweep STUDY --workers 0`` with a drawn grid: refused in one line naming a key, or, when the sweep
    would start (a stub stops it there), every value of the grid lies in its plausible range."""
    import mission_sim.studies.sweep as sweep_mod

    monkeypatch.setattr(sweep_mod, "run_sweep", _stub)
    path = folder / "fuzz_study.toml"
    path.write_text("[grid]\n" + "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in grid.items()))
    argv = ["sweep", str(path), "--out", "fuzz_sweep", "--workers", "0", "--no-plot", "--no-progress"]
    rc, out, err = _run(argv, folder)
    event(f"sweep: {rc}")
    _check_outcome(argv, rc, out, err, allowed=(2, "reached"))
    if rc == "reached":
        for key, values in grid.items():
            if key == "policy":
                continue
            sec, _, name = key.rpartition(".")
            rng = mconfig.plausible_range(sec, name)
            assert all(rng is None or rng.contains(v) for v in values), (key, values)
    assert not _temporaries(folder)


# ----------------------------------------------------------------------------- 3. short missions run to the end
SHORT_KEYS = {"wind.speed_m_s", "wind.gust_sigma_m_s", "battery.initial_soc", "battery.capacity_ah", "drone.mass_kg",
              "drone.payload_kg", "charger.cc_current_a", "link.vdc_v", "link.rated_i2_a", "sim.i2_noise_a",
              "mission.cruise_speed_m_s", "link.r2_ohm", "battery.n_series", "drone.avionics_w"}


#: the alarm of a short-mission draw: there only to catch a hang (which never ends), so far above the slowest
#: honest draw. That draw is the first one, with empty caches (a changed loop source invalidates numba's): it compiles
#: the loop and the policy kernels and builds the link tables, 51.3 s of CPU on a quiet machine (11.1 s with numba's
#: cache warm, 1.0 s with both warm; 2026-11-27). The former 60 s tripped once at load ~5 (2 workers on 2 cores).
SHORT_MISSION_ALARM_S = 600


@settings(FUZZ, max_examples=12)
@given(values=st.lists(st.sampled_from([(s, n, r) for s, n, r in SCHEMA if f"{s}.{n}" in SHORT_KEYS])
                       .flatmap(lambda t: st.tuples(st.just(f"{t[0]}.{t[1]}"), _numbers(t[2]))), max_size=3),
       policy=st.sampled_from(["model_based", "step", "ramp", "hysteresis"]))
def test_fuzzed_short_missions_run_or_fail_in_one_line(folder, values, policy):
    """A short mission (a 2 s hover) with drawn values of physical keys runs to the end (exit 0, or 3 on
    a depleted battery: the summary says so) or is refused in one line naming a key."""
    out_dir = folder / "runs"
    argv = ["mission", "short.toml", "--out", str(out_dir), "--no-plot", "--no-progress", "--format", "json",
            "--policy", policy, *_set_args((k, repr(v) if isinstance(v, float) and math.isfinite(v) else
                                            ("nan" if v != v else "inf" if v == math.inf else "-inf"
                                             if v == -math.inf else str(v))) for k, v in values)]
    rc, out, err = _run(argv, folder, timeout_s=SHORT_MISSION_ALARM_S)
    _check_outcome(argv, rc, out, err, allowed=(0, 2, 3))
    if rc in (0, 3):
        s = json.loads(out)
        assert s["battery_depleted"] == (rc == 3)
        assert 0.0 <= s["final_soc"] <= 1.0 and s["energy_balance_error_rel"] < 1e-6
    assert not _temporaries(folder)


@pytest.mark.parametrize("argv,rc,text", [
    (["mission", "short.toml", "--no-plot", "--set", "drone.mass_kg=1e308"], 2,
     "drone.mass_kg=1e+308 is invalid; valid range: [0.01, 1000] kg"),
    (["mission", "short.toml", "--no-plot", "--set", "battery.initial_soc=0.001"], 3, "battery depleted at t = "),
    (["mission", "fifo"], 2, "config file 'fifo' is a FIFO (named pipe); valid: a TOML file"),
], ids=["mass 1e308", "depleting", "a FIFO as config"])
def test_subprocess_runs_show_no_traceback(folder, argv, rc, text):
    """End to end, as a user runs it: the exit status, one line on stderr naming the key, no traceback."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    fifo = folder / "fifo"   # a FIFO again, whatever the fuzzed draws before did with the name
    if not fifo.is_fifo():
        fifo.unlink(missing_ok=True)
        os.mkfifo(fifo)
    p = subprocess.run([sys.executable, "-m", "mission_sim.cli", *argv, "--out", "sub", "--no-progress"],
                       cwd=folder, env=env, capture_output=True, text=True, timeout=120)
    assert "Traceback" not in p.stderr
    assert p.returncode == rc and len(p.stderr.strip().splitlines()) == 1 and text in p.stderr, p.stderr
    assert not _temporaries(folder)
