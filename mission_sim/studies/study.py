"""Study files for parameter sweeps: TOML schema, case expansion (grid x Monte Carlo), case identity.

A study names a base mission and the parameters to vary. Parameter keys are the dotted override
keys of :func:`mission_sim.config.apply_overrides` (``"pads.1.hover_time_s"``, ``"pads.1.x_m"``,
``"wind.speed_m_s"``, ``"battery.capacity_ah"``, ``"seed"``, ...) plus the special key
``policy`` (a name for ``policies.make``; default ``"model_based"``)::

    [study]
    name = "small"            # optional (default: the file's stem)
    base = "mission.toml"     # optional, relative to this file; omitted = the built-in default mission
    # runner = "pkg.mod:factory"   # optional; default: the mission runner (see mission_sim.studies.sweep)

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

Distributions (``[monte_carlo.params]``): ``uniform = [lo, hi]``, ``loguniform = [lo, hi]``,
``normal = [mean, std]``, ``integers = [lo, hi]`` (hi exclusive), ``choice = [v0, v1, ...]``.
Monte Carlo draw ``j`` uses its own generator ``default_rng(SeedSequence([seed, j]))`` and draws
the parameters in sorted key order, so draw ``j`` is the same whatever ``n`` is: raising ``n``
adds cases and keeps the old ones (which a resumed sweep then skips). Every grid point sees the same
``n`` draws (common random numbers: differences between grid points are not sampling noise).

Case identity: ``case_id = sha256(canonical JSON of {"base": sha256(base mission), "params": params})``
(first 16 hex digits). Canonical JSON sorts keys and writes integral floats as integers, so
``10`` and ``10.0`` are the same case. Changing the base mission changes every case_id.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Study", "Case", "load_study", "parse_study", "expand_cases", "case_id", "canonical_json",
           "DISTRIBUTIONS", "POLICY_KEY", "DEFAULT_POLICY"]

POLICY_KEY = "policy"
DEFAULT_POLICY = "model_based"
DISTRIBUTIONS = ("uniform", "loguniform", "normal", "integers", "choice")
_SPECS = DISTRIBUTIONS + ("linspace",)
_SECTIONS = ("study", "fixed", "grid", "monte_carlo", "report")


@dataclass(frozen=True)
class Case:
    """One mission of a sweep: its identity and its parameters (dotted override keys + ``policy``)."""

    case_id: str
    params: dict


@dataclass(frozen=True)
class Study:
    """A parsed study file (see the module docstring for the TOML schema).

    base_path : path of the base mission TOML, or None for the built-in default mission
    fixed : parameters applied to every case
    grid : key -> list of values (Cartesian product, in file order)
    mc_n, mc_seed : number of Monte Carlo draws (0 = none) and their seed
    mc_params : key -> (distribution name, arguments)
    runner : "module:factory" import path of a case-runner factory, or None for the mission runner
    report : plot axes, e.g. {"x": "mission.hover_time_s", "hue": "pads.1.x_m"}
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
        n_grid = math.prod(len(v) for v in self.grid.values())
        return n_grid * max(self.mc_n, 1)


# ----------------------------------------------------------------------------- parsing
def load_study(path) -> Study:
    """Read and validate a study TOML file (``ValueError`` naming the bad entry)."""
    from ..validation import read_toml_file
    path = Path(path)
    doc = read_toml_file(path, "study file")  # a folder, a binary file, bad TOML: one line naming the file
    return parse_study(doc, name=path.stem, base_dir=path.parent)


def _flatten(d: dict, prefix: str, where: str) -> dict:
    """Nested tables -> dotted keys; a one-key table naming a spec (``{uniform = [...]}``) is a value."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
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
        start, stop = (_check_scalar("grid", key, float(a)) for a in args[:2])
        return [float(x) for x in np.linspace(start, stop, args[2])]
    if not isinstance(v, list):
        v = [v]
    if not v:
        raise ValueError(f"[grid] {key!r} is an empty list; valid: at least one value")
    return [_check_scalar("grid", key, x) for x in v]


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


def parse_study(doc: dict, name: str = "study", base_dir=None) -> Study:
    """A study from its TOML document (a dict). ``base_dir`` resolves a relative ``[study] base``."""
    unknown = sorted(set(doc) - set(_SECTIONS))
    if unknown:
        raise ValueError(f"study section [{unknown[0]}] is unknown; valid sections: "
                         + ", ".join(f"[{s}]" for s in _SECTIONS))
    head = doc.get("study", {})
    bad = sorted(set(head) - {"name", "base", "runner"})
    if bad:
        raise ValueError(f"[study] key {bad[0]!r} is unknown; valid keys: name, base, runner")
    base_path = None
    if head.get("base") not in (None, "", "default"):
        base_path = Path(head["base"])
        if not base_path.is_absolute() and base_dir is not None:
            base_path = Path(base_dir) / base_path
        if not base_path.is_file():
            raise FileNotFoundError(f"[study] base = {head['base']!r}: mission file {str(base_path)!r} does not exist")
    runner = head.get("runner")
    if runner is not None and (not isinstance(runner, str) or runner.count(":") != 1):
        raise ValueError(f"[study] runner = {runner!r} is invalid; valid: 'package.module:factory'")

    fixed = {k: _check_scalar("fixed", k, v) for k, v in _flatten(doc.get("fixed", {}), "", "fixed").items()}
    grid = {k: _grid_values(k, v) for k, v in _flatten(doc.get("grid", {}), "", "grid").items()}

    mc = dict(doc.get("monte_carlo", {}))
    bad = sorted(set(mc) - {"n", "seed", "params"})
    if bad:
        raise ValueError(f"[monte_carlo] key {bad[0]!r} is unknown; valid keys: n, seed, params")
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
                  mc_seed=mc_seed, mc_params=mc_params, runner=runner, report=report)
    for k in (POLICY_KEY,):
        if k in mc_params and mc_params[k][0] != "choice":
            raise ValueError(f"[monte_carlo.params] {k!r} must use {{choice = [...]}}")
    return study


# ----------------------------------------------------------------------------- identity
def _canonical(v):
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


def case_id(params: dict, base_fingerprint: str = "") -> str:
    """Stable identity of a case: first 16 hex digits of sha256 over its canonical parameters."""
    text = canonical_json({"base": base_fingerprint, "params": params})
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


def expand_cases(study: Study, base_fingerprint: str = "") -> list[Case]:
    """All cases of a study, in a deterministic order (grid points outer, Monte Carlo draws inner).

    Each case's parameters are ``policy`` (default :data:`DEFAULT_POLICY`), then the fixed
    parameters, the grid point and the Monte Carlo draw. Duplicate cases (same case_id, e.g. a
    value listed twice in the grid) are kept once.
    """
    draws = [monte_carlo_draw(study, j) for j in range(study.mc_n)] or [{}]
    keys = list(study.grid)
    cases, seen = [], set()
    for point in itertools.product(*(study.grid[k] for k in keys)):
        for draw in draws:
            params = {POLICY_KEY: DEFAULT_POLICY, **study.fixed, **dict(zip(keys, point)), **draw}
            cid = case_id(params, base_fingerprint)
            if cid not in seen:
                seen.add(cid)
                cases.append(Case(cid, params))
    return cases
