"""Study files for parameter sweeps: TOML schema, case expansion (grid x Monte Carlo), case identity.

A study names a base mission and the parameters to vary. Parameter keys are the dotted override
keys of :func:`mission_sim.config.apply_overrides` (``"pads.1.hover_time_s"``, ``"pads.1.x_m"``,
``"wind.speed_m_s"``, ``"battery.capacity_ah"``, ``"seed"``, ...) plus the special key
``policy`` (a name for ``policies.make``; default ``"model_based"``)::

    [study]
    name = "small"            # optional (default: the file's stem)
    base = "mission.toml"     # optional, relative to this file; omitted = the built-in default mission
    # runner = "pkg.mod:factory"   # optional; default: the mission runner (see mission_sim.studies.sweep)
    # allow_single = true     # optional: a study that varies nothing (one case, the base) is then allowed

    [fixed]                   # applied to every case
    "pads.0.hover_time_s" = 30.0

    [grid]                    # full Cartesian product
    "pads.1.hover_time_s" = [10.0, 20.0, 40.0]
    "pads.1.x_m" = {linspace = [20.0, 60.0, 3]}   # = [20.0, 40.0, 60.0]
    policy = ["step", "model_based"]

    [monte_carlo]             # n random draws, combined with every grid point
    n = 8
    seed = 1
    [monte_carlo.params]
    "wind.speed_m_s" = {uniform = [0.0, 6.0]}
    "battery.capacity_ah" = {normal = [1.3, 0.05]}
    seed = {integers = [0, 1000000]}

    [report]                  # optional: axes of the trade-off plots (defaults: the first varied keys)
    x = "pads.1.hover_time_s"
    hue = "pads.1.x_m"

Keys may be quoted (``"mission.hover_time_s" = ...``) or written as TOML dotted keys / sub-tables
(``mission.hover_time_s = ...``); both flatten to the same dotted key.

A ``[replay]`` section makes every case a replay of one of your flight logs instead of a mission
(:mod:`mission_sim.studies.replay_cases`; ``[study] base`` is then the ``--config`` mission that
gives the drone, battery, link and charger, and the keys are what ``dronewpt replay --set`` takes)::

    [replay]
    log = "flight.tlog"       # required, relative to this file: .tlog, .bin or .ulg
    pads = "pads.csv"         # optional: re-fly with detours to these pads (replay --pads)
    pad = "-35.3632,149.1652" # optional: the pad (with pads: the frame origin) at LAT,LON[,ALT] (replay --pad),
    #                           or the array [-35.3632, 149.1652] / [lat, lon, alt]
    drone = "drone.toml"      # optional: a [drone] file from `dronewpt calibrate` (replay --drone)
    window = [440.0, 620.0]   # optional: log seconds T0, T1 (replay --window)
    # segment = 2             # optional, instead of window: boot segment N, 1-based (replay --segment)
    reach_m = 500.0           # optional: with pads, visit pads this close to the track (replay --reach)
    ground_gap_m = 0.17       # optional: coil gap when landed, [0, 1] m (replay --ground-gap)

Distributions (``[monte_carlo.params]``): ``uniform = [lo, hi]``, ``loguniform = [lo, hi]``,
``normal = [mean, std]``, ``integers = [lo, hi]`` (hi exclusive), ``choice = [v0, v1, ...]``.
Monte Carlo draw ``j`` uses its own generator ``default_rng(SeedSequence([seed, j]))`` and draws
the parameters in sorted key order, so draw ``j`` is the same whatever ``n`` is: raising ``n``
adds cases and keeps the old ones (which a resumed sweep then skips). Every grid point sees the same
``n`` draws (common random numbers: differences between grid points are not sampling noise).

Cases are generated lazily (:class:`CaseSpace`: grid points outer, Monte Carlo draws inner; a
``linspace`` axis is never materialised) and the study's size is computed arithmetically
(:func:`size_bound`), so :func:`check_size` refuses a 10^8-case study before anything is built.
Grid values are deduplicated per axis (``5`` and ``5.0`` are one value); Monte Carlo draws that
coincide (discrete distributions) are kept once.

Case identity: ``case_id = sha256(canonical JSON of {"base": sha256(base mission), "params": params})``
(first 16 hex digits). Canonical JSON sorts keys and writes integral floats as integers, so
``10`` and ``10.0`` are the same case. Changing the base mission changes every case_id.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..validation import check_table, window_ok
from . import DEFAULT_MAX_CASES

__all__ = ["Study", "Case", "CaseSpace", "Linspace", "load_study", "parse_study", "expand_cases", "case_space",
           "size_bound", "check_size", "case_id", "canonical_json", "DISTRIBUTIONS", "POLICY_KEY", "DEFAULT_POLICY",
           "DEFAULT_MAX_CASES"]

POLICY_KEY = "policy"
DEFAULT_POLICY = "model_based"
DISTRIBUTIONS = ("uniform", "loguniform", "normal", "integers", "choice")
_SPECS = DISTRIBUTIONS + ("linspace",)
_SECTIONS = ("study", "fixed", "grid", "monte_carlo", "report", "replay")
_REPLAY_KEYS = ("log", "pads", "pad", "drone", "window", "segment", "reach_m", "ground_gap_m")
_STUDY_KEYS = ("name", "base", "runner", "allow_single")
_CONTINUOUS = ("uniform", "loguniform", "normal")
_DRAW_CACHE = 10_000  # Monte Carlo draws kept in memory while iterating (more are recomputed per grid point)


@dataclass(frozen=True)
class Linspace:
    """A lazy grid axis: ``num`` evenly spaced floats from ``start`` to ``stop`` (both included).

    Value ``i`` is ``i * step + start`` and the last one is ``stop``, exactly as ``numpy.linspace``
    computes them, but nothing is materialised (a 10^8-point axis costs three numbers).
    """

    start: float
    stop: float
    num: int

    def __len__(self) -> int:
        return self.num

    def __getitem__(self, i: int) -> float:
        if not -self.num <= i < self.num:
            raise IndexError(f"linspace index {i} out of range 0..{self.num - 1}")
        i %= self.num
        if i == self.num - 1 and self.num > 1:
            return float(self.stop)
        step = (self.stop - self.start) / (self.num - 1) if self.num > 1 else 0.0
        return float(i * step + self.start)

    def __iter__(self):
        return (self[i] for i in range(self.num))


@dataclass(frozen=True)
class Case:
    """One mission of a sweep: its identity and its parameters (dotted override keys + ``policy``)."""

    case_id: str
    params: dict
    params_json: str | None = field(default=None, compare=False, repr=False)  # canonical_json(params), if known

    @property
    def canonical_params(self) -> str:
        """``canonical_json(params)`` (computed once when the case comes from a :class:`CaseSpace`)."""
        return self.params_json if self.params_json is not None else canonical_json(self.params)


@dataclass(frozen=True)
class Study:
    """A parsed study file (see the module docstring for the TOML schema).

    base_path : path of the base mission TOML, or None for the built-in default mission
    fixed : parameters applied to every case
    grid : key -> list of values or a lazy :class:`Linspace` (Cartesian product, in file order)
    mc_n, mc_seed : number of Monte Carlo draws (0 = none) and their seed
    mc_params : key -> (distribution name, arguments)
    runner : "module:factory" import path of a case-runner factory, or None for the mission runner
    report : plot axes, e.g. {"x": "mission.hover_time_s", "hue": "pads.1.x_m"}
    allow_single : a study that varies nothing (the base mission once) is allowed
    replay : the ``[replay]`` section (paths resolved against the study file's folder; ``pad`` a
        :class:`~mission_sim.mavlink.geodesy.GeoPoint`), or None for a mission study
    source : the TOML document it was parsed from (``dronewpt sweep --status`` re-reads it)
    """

    name: str
    base_path: Path | None = None
    fixed: dict = field(default_factory=dict)
    grid: dict = field(default_factory=dict)
    mc_n: int = 0
    mc_seed: int = 0
    mc_params: dict = field(default_factory=dict)
    runner: str | None = None
    report: dict = field(default_factory=dict)
    allow_single: bool = False
    replay: dict | None = None
    source: dict = field(default_factory=dict, repr=False, compare=False)  # the TOML document parsed

    @property
    def varied_keys(self) -> list[str]:
        """Keys that change between cases: grid keys (file order), then Monte Carlo keys (sorted)."""
        return list(self.grid) + sorted(k for k in self.mc_params if k not in self.grid)

    @property
    def parameter_keys(self) -> list[str]:
        """Every key a case sets (fixed, grid, Monte Carlo), ``policy`` included."""
        keys = list(self.fixed) + [k for k in self.varied_keys if k not in self.fixed]
        return keys if POLICY_KEY in keys else [POLICY_KEY] + keys

    @property
    def override_keys(self) -> list[str]:
        """The parameter keys that are mission-config overrides (all but ``policy``)."""
        return [k for k in self.parameter_keys if k != POLICY_KEY]

    @property
    def n_cases(self) -> int:
        """Grid points x Monte Carlo draws, arithmetically (coinciding discrete draws counted apart)."""
        return size_bound(self)


# ----------------------------------------------------------------------------- parsing
def load_study(path) -> Study:
    """Read and validate a study TOML file (``ValueError`` naming the bad entry)."""
    from ..validation import read_toml_file
    path = Path(path)
    doc = read_toml_file(path, "study file")  # a folder, a binary file, bad TOML: one line naming the file
    return parse_study(doc, name=path.stem, base_dir=path.parent)


#: what a value's spec is not, but a newcomer writes for one (numpy's and Python's names): refused naming the valid
#: specs, not flattened into a key (``"pads.1.x_m" = {range = [...]}`` was "override key 'pads.1.x_m.range' is invalid")
_NOT_SPECS = ("range", "arange", "logspace", "geomspace", "values", "list", "linear", "randint", "choices",
              "lognormal", "gauss", "random", "rand", "randn", "grid")


def _valid_specs(where: str) -> str:
    if where == "grid":
        return "a list of values, or {linspace = [start, stop, num]}"
    if where == "monte_carlo.params":
        return "one of " + ", ".join(f"{{{d} = [...]}}" for d in DISTRIBUTIONS)
    return "a number, string or boolean"


def _flatten(d: dict, prefix: str, where: str) -> dict:
    """Nested tables -> dotted keys; a one-key table naming a spec (``{uniform = [...]}``) is a value."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and (set(v) & set(_NOT_SPECS) or (len(v) > 1 and set(v) & set(_SPECS))):
            text = ", ".join(f"{a} = ..." for a in v)
            raise ValueError(f"[{where}] {key!r} = {{{text}}} is invalid; valid: {_valid_specs(where)}")
        if isinstance(v, dict) and not (len(v) == 1 and next(iter(v)) in _SPECS):
            if not v:
                raise ValueError(f"[{where}] {key!r} is an empty table; give it a value")
            out.update(_flatten(v, key + ".", where))
        else:
            out[key] = v
    return out


def _check_scalar(where: str, key: str, v) -> Any:
    if isinstance(v, bool) or isinstance(v, (int, str)):
        return v
    if isinstance(v, (np.bool_, np.integer, np.floating)):   # a study built in Python: np.arange, np.linspace
        v = v.item()
        if not isinstance(v, float):
            return v
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"[{where}] {key!r} = {v!r} is invalid; valid: a finite number")
        return v
    raise ValueError(f"[{where}] {key!r} = {v!r} is invalid; valid: a number, string or boolean")


def _grid_values(key: str, v) -> list:
    if isinstance(v, dict):
        (spec, args), = v.items()
        if spec != "linspace":
            raise ValueError(f"[grid] {key!r} = {{{spec} = ...}} is invalid; a grid takes a list or "
                             f"{{linspace = [start, stop, num]}} ({spec!r} belongs in [monte_carlo.params])")
        if (not isinstance(args, list) or len(args) != 3 or isinstance(args[2], bool)
                or not isinstance(args[2], int) or args[2] < 1):
            raise ValueError(f"[grid] {key!r} = {{linspace = {args!r}}} is invalid; valid: [start, stop, num] "
                             f"with num an integer >= 1")
        if not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in args[:2]):
            raise ValueError(f"[grid] {key!r} = {{linspace = {args!r}}} is invalid; valid: [start, stop, num] "
                             f"with start and stop numbers")
        start, stop = (_check_scalar("grid", key, float(a)) for a in args[:2])
        return Linspace(start, stop, args[2] if start != stop else 1)
    if isinstance(v, np.ndarray) and v.ndim == 1 or isinstance(v, tuple):   # a study built in Python
        v = list(v)
    if not isinstance(v, list):
        v = [v]
    if not v:
        raise ValueError(f"[grid] {key!r} is an empty list; valid: at least one value")
    unique = {}
    for x in v:  # 5 and 5.0 are the same case: keep the first
        x = _check_scalar("grid", key, x)
        unique.setdefault(canonical_json(x), x)
    return list(unique.values())


def _distribution(key: str, v) -> tuple[str, tuple]:
    if not (isinstance(v, dict) and len(v) == 1 and next(iter(v)) in DISTRIBUTIONS):
        raise ValueError(f"[monte_carlo.params] {key!r} = {v!r} is invalid; valid: one of "
                         + ", ".join(f"{{{d} = [...]}}" for d in DISTRIBUTIONS))
    (dist, args), = v.items()
    bad = f"[monte_carlo.params] {key!r} = {{{dist} = {args!r}}} is invalid; valid: "
    if not isinstance(args, list):
        raise ValueError(bad + "a list of arguments")
    if dist == "choice":
        if not args:
            raise ValueError(bad + "a non-empty list of values")
        return dist, tuple(_check_scalar("monte_carlo.params", key, a) for a in args)
    if len(args) != 2 or not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in args) \
            or not all(math.isfinite(a) for a in args):
        raise ValueError(bad + "two finite numbers")
    a, b = args
    if dist == "uniform" and not a < b:
        raise ValueError(bad + "[lo, hi] with lo < hi")
    if dist == "loguniform" and not 0 < a < b:
        raise ValueError(bad + "[lo, hi] with 0 < lo < hi")
    if dist == "normal" and not b >= 0:
        raise ValueError(bad + "[mean, std] with std >= 0")
    if dist == "integers" and not (isinstance(a, int) and isinstance(b, int) and a < b):
        raise ValueError(bad + "[lo, hi] integers with lo < hi (hi exclusive)")
    return dist, (a, b)


def _parse_head(head: dict, base_dir):
    """The ``[study]`` table: (table, base mission path or None, runner spec or None, allow_single)."""
    bad = sorted(set(head) - set(_STUDY_KEYS))
    if bad:
        raise ValueError(f"[study] key {bad[0]!r} is unknown; valid keys: {', '.join(_STUDY_KEYS)}")
    allow_single = head.get("allow_single", False)
    if not isinstance(allow_single, bool):
        raise ValueError(f"[study] allow_single = {allow_single!r} is invalid; valid: true or false")
    base_path = None
    if head.get("base") not in (None, "", "default"):
        if not isinstance(head["base"], str):   # (base = 3 was a TypeError traceback)
            raise ValueError(f"[study] base = {head['base']!r} is invalid; valid: a mission TOML's path (string)")
        base_path = Path(head["base"])
        if not base_path.is_absolute() and base_dir is not None:
            base_path = Path(base_dir) / base_path
        from ..validation import check_regular_file
        check_regular_file(base_path, f"[study] base = {head['base']!r}: mission file", "a TOML file")
    runner = head.get("runner")
    if runner is not None and (not isinstance(runner, str) or runner.count(":") != 1):
        raise ValueError(f"[study] runner = {runner!r} is invalid; valid: 'package.module:factory'")

    return head, base_path, runner, allow_single


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _parse_replay(rep, base_dir) -> dict:
    """The ``[replay]`` table, checked (types and ranges; the files are read by the replay runner), its
    paths resolved against ``base_dir``."""
    check_table("[replay]", rep, "[replay] with log = 'flight.tlog'", eq=" = ")
    bad = sorted(set(rep) - set(_REPLAY_KEYS))
    if bad:
        raise ValueError(f"[replay] key {bad[0]!r} is unknown; valid keys: {', '.join(_REPLAY_KEYS)}")
    if "log" not in rep:
        raise ValueError("[replay] has no log; valid: log = 'path/to/flight.tlog' (.tlog, .bin or .ulg, "
                         "relative to the study file)")
    out = {}
    for key in ("log", "pads", "drone"):
        if key in rep:
            v = rep[key]
            if not isinstance(v, str) or not v:
                raise ValueError(f"[replay] {key} = {v!r} is invalid; valid: a file path (string)")
            p = Path(v).expanduser()
            out[key] = p if p.is_absolute() or base_dir is None else Path(base_dir) / p
    w = rep.get("window")
    if w is not None:
        if not (isinstance(w, list) and len(w) == 2 and all(_number(x) for x in w) and window_ok(w[0], w[1])):
            raise ValueError(f"[replay] window = {w!r} is invalid; valid: [T0, T1] seconds of log time with "
                             "0 <= T0 < T1, e.g. [440.0, 620.0]")
        out["window"] = (float(w[0]), float(w[1]))
    seg = rep.get("segment")
    if seg is not None:
        if isinstance(seg, bool) or not isinstance(seg, int) or seg < 1:
            raise ValueError(f"[replay] segment = {seg!r} is invalid; valid range: integer >= 1 (a boot segment)")
        if "window" in out:
            raise ValueError(f"[replay] segment = {seg!r} and window = {list(out['window'])!r} exclude each other (a "
                             "window is log seconds, across boot segments); valid: one of them")
        out["segment"] = seg
    from ..plans.refly import DEFAULT_REACH_M
    reach = rep.get("reach_m", DEFAULT_REACH_M)
    if not _number(reach) or not reach > 0:
        raise ValueError(f"[replay] reach_m = {reach!r} is invalid; valid range: (0, inf) m")
    if "pads" not in rep and "reach_m" in rep:
        raise ValueError("[replay] reach_m is set without pads; valid: give pads = 'pads.csv' too, or drop reach_m")
    out["reach_m"] = float(reach)
    if "pad" in rep:   # the command's --pad, parsed and checked by its own parser (format, ranges; or an array)
        from ..mavlink.geodesy import parse_geo_point
        out["pad"] = parse_geo_point(rep["pad"], "[replay] pad =")
    gap = rep.get("ground_gap_m")
    if gap is not None:
        if not _number(gap) or not 0 <= gap <= 1.0:
            raise ValueError(f"[replay] ground_gap_m = {gap!r} is invalid; valid range: [0, 1] m")
        out["ground_gap_m"] = float(gap)
    return out


def parse_study(doc: dict, name: str = "study", base_dir=None) -> Study:
    """A study from its TOML document (a dict). ``base_dir`` resolves a relative ``[study] base``."""
    unknown = sorted(set(doc) - set(_SECTIONS))
    if unknown:
        raise ValueError(f"study section [{unknown[0]}] is unknown; valid sections: "
                         + ", ".join(f"[{s}]" for s in _SECTIONS))
    for sec in ("study", "fixed", "grid", "monte_carlo", "report"):   # ([replay]: its own message below)
        if sec in doc:   # (grid = 3 was an AttributeError traceback)
            check_table(f"[{sec}]", doc[sec], f"[{sec}] and its keys", eq=" = ")
    head, base_path, runner, allow_single = _parse_head(doc.get("study", {}), base_dir)
    replay = None
    if "replay" in doc:
        if runner:
            raise ValueError(f"[study] runner = {runner!r} and a [replay] section exclude each other; valid: one "
                             "of them (a [replay] study runs the built-in replay runner)")
        replay = _parse_replay(doc["replay"], base_dir)

    fixed = {k: _check_scalar("fixed", k, v) for k, v in _flatten(doc.get("fixed", {}), "", "fixed").items()}
    grid = {k: _grid_values(k, v) for k, v in _flatten(doc.get("grid", {}), "", "grid").items()}

    mc = dict(doc.get("monte_carlo", {}))
    bad = sorted(set(mc) - {"n", "seed", "params"})
    if bad:
        raise ValueError(f"[monte_carlo] key {bad[0]!r} is unknown; valid keys: n, seed, params")
    check_table("[monte_carlo] params", mc.get("params", {}), "[monte_carlo.params]", eq=" = ")
    mc_params = {k: _distribution(k, v) for k, v in _flatten(mc.get("params", {}), "", "monte_carlo.params").items()}
    mc_n = mc.get("n", 1 if mc_params else 0)
    if isinstance(mc_n, bool) or not isinstance(mc_n, int) or mc_n < 0 or (mc_params and mc_n < 1):
        raise ValueError(f"[monte_carlo] n = {mc_n!r} is invalid; valid range: integer >= 1")
    if not mc_params:
        mc_n = 0
    mc_seed = mc.get("seed", 0)
    if isinstance(mc_seed, bool) or not isinstance(mc_seed, int) or mc_seed < 0:
        raise ValueError(f"[monte_carlo] seed = {mc_seed!r} is invalid; valid range: integer >= 0")

    for a_name, a, b_name, b in (("fixed", fixed, "grid", grid), ("fixed", fixed, "monte_carlo.params", mc_params),
                                 ("grid", grid, "monte_carlo.params", mc_params)):
        both = sorted(set(a) & set(b))
        if both:
            raise ValueError(f"parameter {both[0]!r} is set in both [{a_name}] and [{b_name}]; set it in one")

    report = dict(doc.get("report", {}))
    bad = sorted(set(report) - {"x", "hue"})
    if bad:
        raise ValueError(f"[report] key {bad[0]!r} is unknown; valid keys: x, hue")
    varied = list(grid) + list(mc_params)
    for k, v in report.items():
        if v not in varied:
            raise ValueError(f"[report] {k} = {v!r} is not a varied parameter; valid: {', '.join(varied) or '(none)'}")

    study = Study(name=str(head.get("name", name)), base_path=base_path, fixed=fixed, grid=grid, mc_n=mc_n,
                  mc_seed=mc_seed, mc_params=mc_params, runner=runner, report=report, allow_single=allow_single,
                  replay=replay, source=doc)
    for k in (POLICY_KEY,):
        if k in mc_params and mc_params[k][0] != "choice":
            raise ValueError(f"[monte_carlo.params] {k!r} must use {{choice = [...]}}")
    if not grid and not mc_params and not allow_single:
        once = "replay the log once" if study.replay is not None else "run the base mission once"
        raise ValueError(f"study {study.name!r} varies nothing (no [grid] or [monte_carlo.params] entries), so it "
                         f"would {once}; add parameters to vary, or set "
                         "[study] allow_single = true")
    return study


# ----------------------------------------------------------------------------- identity
def _canonical(v):
    t = type(v)  # fast path: the scalars every case is made of
    if t is str or t is int or t is bool:
        return v
    if t is float:
        return int(v) if v.is_integer() and abs(v) < 2**53 else v
    if isinstance(v, dict):
        return {str(k): _canonical(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_canonical(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return int(v) if v.is_integer() and abs(v) < 2**53 else v
    return v


def canonical_json(obj) -> str:
    """Sorted-key compact JSON with integral floats written as integers (stable across runs)."""
    return json.dumps(_canonical(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


def case_id(params: dict, base_fingerprint: str = "", params_json: str | None = None) -> str:
    """Stable identity of a case: first 16 hex digits of sha256 over its canonical parameters
    (``canonical_json({"base": base_fingerprint, "params": params})``; pass ``params_json`` =
    ``canonical_json(params)`` if already known: the text is assembled from it, byte for byte the same)."""
    if params_json is None:
        params_json = canonical_json(params)
    text = f'{{"base":{json.dumps(base_fingerprint)},"params":{params_json}}}'
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# ----------------------------------------------------------------------------- expansion
def _draw(rng: np.random.Generator, dist: str, args: tuple):
    if dist == "uniform":
        return float(rng.uniform(*args))
    if dist == "loguniform":
        lo, hi = args
        return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    if dist == "normal":
        return float(rng.normal(*args))
    if dist == "integers":
        return int(rng.integers(*args))
    if dist == "choice":
        return args[int(rng.integers(len(args)))]
    raise ValueError(f"distribution {dist!r} is unknown; valid: {', '.join(DISTRIBUTIONS)}")


def monte_carlo_draw(study: Study, j: int) -> dict:
    """Monte Carlo draw ``j`` (independent of ``n`` and of the other draws)."""
    rng = np.random.default_rng(np.random.SeedSequence([study.mc_seed, j]))
    return {k: _draw(rng, *study.mc_params[k]) for k in sorted(study.mc_params)}


def size_bound(study: Study) -> int:
    """Grid points x Monte Carlo draws, from the axis lengths alone (nothing is generated)."""
    return math.prod(len(v) for v in study.grid.values()) * max(study.mc_n, 1)


def check_size(study: Study, max_cases: int = DEFAULT_MAX_CASES) -> int:
    """The study's size; ``ValueError`` (one line, with the size) if it exceeds ``max_cases``."""
    n = size_bound(study)
    if n > max_cases:
        parts = [f"{len(v):,} ({k})" for k, v in study.grid.items()] + \
                ([f"{study.mc_n:,} Monte Carlo draws"] if study.mc_n else [])
        raise ValueError(f"study {study.name!r} has {n:,} cases ({' x '.join(parts)}), more than the limit of "
                         f"{max_cases:,} (--max-cases); shrink the study or raise the limit")
    return n


def _draw_indices(study: Study):
    """Indices ``j`` of the Monte Carlo draws kept: all of them, or the first of coinciding draws."""
    if not study.mc_n:
        return range(0)
    if all(d in _CONTINUOUS and not (d == "normal" and a[1] == 0) for d, a in study.mc_params.values()):
        return range(study.mc_n)
    seen, keep = set(), []
    for j in range(study.mc_n):
        key = canonical_json(monte_carlo_draw(study, j))
        if key not in seen:
            seen.add(key)
            keep.append(j)
    return range(study.mc_n) if len(keep) == study.mc_n else np.asarray(keep, dtype=np.int64)


def _lazy_product(axes: list):
    """Cartesian product (last axis fastest) without materialising the axes (itertools.product does)."""
    if not axes:
        yield ()
        return
    for head in axes[0]:
        for rest in _lazy_product(axes[1:]):
            yield (head, *rest)


@dataclass(frozen=True)
class CaseSpace:
    """Every case of a study, generated lazily in a deterministic order (grid points outer, Monte
    Carlo draws inner). ``len()`` is arithmetic; iterating yields :class:`Case` objects one by one.

    Each case's parameters are ``policy`` (default :data:`DEFAULT_POLICY`), then the fixed
    parameters, the grid point and the Monte Carlo draw.
    """

    study: Study
    fingerprint: str = ""
    draws: Any = range(0)

    def __len__(self) -> int:
        n_grid = math.prod(len(v) for v in self.study.grid.values())
        return n_grid * (len(self.draws) if self.study.mc_n else 1)

    def params(self):
        """The cases' parameter dicts, lazily (no case ids computed)."""
        st = self.study
        keys = list(st.grid)
        draws = self.draws if st.mc_n else [None]
        cached = [monte_carlo_draw(st, j) for j in draws] if st.mc_n and len(draws) <= _DRAW_CACHE else None
        for point in _lazy_product([st.grid[k] for k in keys]):
            head = {POLICY_KEY: DEFAULT_POLICY, **st.fixed, **dict(zip(keys, point))}
            for i, j in enumerate(draws):
                draw = {} if j is None else (cached[i] if cached is not None else monte_carlo_draw(st, int(j)))
                yield {**head, **draw}

    def __iter__(self):
        for p in self.params():
            text = canonical_json(p)
            yield Case(case_id(p, self.fingerprint, text), p, text)


def case_space(study: Study, base_fingerprint: str = "") -> CaseSpace:
    """The lazy :class:`CaseSpace` of a study (one pass over the draws if a distribution is discrete)."""
    return CaseSpace(study, base_fingerprint, _draw_indices(study))


def expand_cases(study: Study, base_fingerprint: str = "") -> list[Case]:
    """All cases of a study as a list (small studies and tests; sweeps iterate :func:`case_space`)."""
    return list(case_space(study, base_fingerprint))
