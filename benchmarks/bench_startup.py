"""Start-up and the two user commands of issue 22, end to end as a user runs them: the ``dronewpt``
console script in a fresh process (numba's cache and the disk cache warm), against the bare
interpreter in the same run; beside them, labelled as such, where the time goes *in one process*.

End to end (wall and CPU = user + system of the child), each command ``--repeat`` times, interleaved
so a change of load hits all alike (the compare commands of each ``--link`` in their own rounds, one link after
the other), after one untimed warm-up round; median and range, and ``os.getloadavg()`` before and after:

* ``python -c pass``, ``dronewpt --help``;
* ``dronewpt mission`` (default mission, five figures; goal <= 1.0 s) and ``--no-plot``: the path is
  one flown before, so Lm along it comes from the disk cache (:meth:`wpt_receiver.coupling.CouplingModel.lm_h`);
* ``dronewpt mission --no-plot --set seed=K`` with a new K every run: a path never flown, so numba
  starts and the table kernel loads from its cache (what a changed route or wind costs);
* ``dronewpt compare --episodes 100 --scenarios nominal --no-plot`` (goal <= 2.5 s): ``--compare
  default`` (every default policy, MPC included: slow, see docs/performance.md) or ``no-mpc`` (the
  default policies and seed rows without ``mpc``; the default of this script) or ``none``. In ``no-mpc`` a
  policy that has a shipped seed group (``rl``) is its seed-group row only: until 2026-11-27 the command
  listed ``rl`` in ``--policies`` and as ``--train-seeds rl=...``, which printed two ``rl`` rows (the
  seed-0 one as well) and is now refused (exit 2), so its times are not comparable with earlier ones; on the link(s) of
  ``--link`` (``modal``, the env's default, ``envelope`` (eq. 4) or ``both``; default: the command as typed,
  no ``--link``). Each compare's printed table is hashed (SHA-1) in every run: the report says whether
  every run of every tree printed the same table per link.

Each tree runs with a disk cache folder of its own (``DRONEWPT_CACHE_DIR``): the measured tree with the one in the
environment, else a folder under the temporary directory named after the tree; a ``--before DIR`` tree with
``--before-cache`` or such a folder of its own. ``DRONEWPT_CACHE_DIR`` set but empty (the cache off) turns it off for
both trees (``--before-cache`` is then refused). When ``DRONEWPT_CACHE_DIR`` is unset, no tree's warmup goes to the
user's shared default folder; when it is set, the measured tree uses (and warms) that folder. The temporary folders,
``<tmp>/dronewpt-bench-cache/<tree name>-<hash of its path>``, persist between runs (so a second run starts warm);
remove them with ``rm -r /tmp/dronewpt-bench-cache`` (or the temporary directory's equivalent). ``dronewpt warmup`` removes other
sources' ahead-of-time mission modules from its cache folder (:func:`mission_sim.world.aot.build`), so two trees
sharing one folder do not both run without numba. Before anything is timed each tree's ``dronewpt warmup`` runs
with its own ``PYTHONPATH`` and cache folder (``--no-warmup`` skips it; seconds when the kernels are cached and the
module built, minutes otherwise), so both run on their ahead-of-time loop.

In process (``--phases``): the mission's and the compare's phases timed with ``time.process_time`` in
one fresh interpreter each (imports, config, policy, simulation, Parquet, figures; each policy's
rollout, statistics, frontier).

    python benchmarks/bench_startup.py [--repeat 5] [--compare no-mpc|default|none] [--link modal|envelope|both]
        [--phases] [--json] [--root DIR] [--before DIR [--before-cache DIR]] [--no-warmup] [--pyc DIR|inherit]
        [--mission-only | --compare-only]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NO_MPC = ("step,ramp,hysteresis,model_based,model_based_online,model_based_budget:0.01,model_based_budget:0.02,"
          "rl,random")


def _console_script() -> list[str]:
    """The ``dronewpt`` script of this interpreter (what ``pip install`` put beside it), else ``-m``."""
    script = Path(sys.executable).with_name("dronewpt")
    if script.is_file():
        return [str(script)]
    found = shutil.which("dronewpt")
    return [found] if found else [sys.executable, "-m", "mission_sim.cli"]


def _cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _run(argv, env) -> tuple[float, float, str]:
    """Wall and CPU time [s] of one fresh process (``env``'s PYTHONPATH: the tree it runs) and its stdout's SHA-1."""
    c0, t0 = _cpu_children(), time.perf_counter()
    r = subprocess.run(argv, cwd=env["PYTHONPATH"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    wall, cpu = time.perf_counter() - t0, _cpu_children() - c0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({r.returncode}): {r.stderr.decode(errors='replace').strip()[-400:]}")
    return wall, cpu, hashlib.sha1(r.stdout).hexdigest()


#: the disk cache variable (:data:`wpt_receiver.diskcache.ENV_VAR`; spelt here: the script imports no tree)
CACHE_VAR = "DRONEWPT_CACHE_DIR"


def tree_cache_dir(tree: Path) -> Path:
    """The default disk cache folder of a measured tree: one per tree (its name and a hash of its path) under the
    temporary directory (the ``--before`` tree's, and the measured tree's when ``DRONEWPT_CACHE_DIR`` is not set: a
    warmup in the user's shared default folder would remove other trees' ahead-of-time modules there)."""
    tree = tree.resolve()
    digest = hashlib.sha1(str(tree).encode()).hexdigest()[:10]
    return Path(tempfile.gettempdir()) / "dronewpt-bench-cache" / f"{tree.name}-{digest}"


def _tree_envs(env: dict, before: Path, before_cache: Path | None) -> dict:
    """The ``--before`` tree's environment: ``env`` with its ``PYTHONPATH`` and a cache folder of its own, or the
    cache off as the measured tree's (``DRONEWPT_CACHE_DIR`` empty: both trees alike)."""
    own = env.get(CACHE_VAR)
    if own is not None and not own.strip():
        if before_cache is not None:
            raise SystemExit(f"--before-cache {str(before_cache)!r} with {CACHE_VAR} empty (the cache off); valid: "
                             f"no --before-cache (both trees without the cache) or {CACHE_VAR} set to a folder")
        return {**env, "PYTHONPATH": str(before.resolve()), CACHE_VAR: own}
    cache = Path(before_cache) if before_cache is not None else tree_cache_dir(before)
    if own is not None and Path(own).resolve() == cache.resolve():
        raise SystemExit(f"--before-cache {str(cache)!r} is the measured tree's {CACHE_VAR}; valid: another folder "
                         "(a warmup removes the other tree's ahead-of-time module from a shared folder)")
    return {**env, "PYTHONPATH": str(before.resolve()), CACHE_VAR: str(cache)}


def _warm(env: dict) -> float:
    """``dronewpt warmup`` of the tree and cache folder of ``env`` (its kernels in numba's cache, its mission loop
    built ahead of time); its wall time [s]."""
    t0 = time.perf_counter()
    r = subprocess.run([*_console_script(), "warmup"], cwd=env["PYTHONPATH"], env=env, stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        raise SystemExit(f"dronewpt warmup of {env['PYTHONPATH']} failed ({r.returncode}): {r.stdout.strip()[-400:]}")
    if any("built ahead of time" in line and "): failed" in line for line in r.stdout.splitlines()):
        print(f"warning: {env['PYTHONPATH']}: the ahead-of-time build failed; that tree runs on numba's JIT",
              file=sys.stderr)
    return time.perf_counter() - t0


def _commands(tmp: str, compare: str, links=(None,)) -> dict:
    cli = _console_script()
    cmds = {"python -c pass": [sys.executable, "-c", "pass"],
            "python -c 'import numpy'": [sys.executable, "-c", "import numpy"],
            "dronewpt --help": [*cli, "--help"],
            "dronewpt mission": [*cli, "mission", "--no-progress", "--out", f"{tmp}/m"],
            "dronewpt mission --no-plot": [*cli, "mission", "--no-plot", "--no-progress", "--out", f"{tmp}/n"],
            "dronewpt mission --no-plot, new path": [*cli, "mission", "--no-plot", "--no-progress", "--out",
                                                     f"{tmp}/s", "--set", "seed={seed}"]}
    if compare != "none":
        extra = _no_mpc_args() if compare == "no-mpc" else []
        for link in links:
            name = f"dronewpt compare ({compare}{'' if link is None else ', --link ' + link})"
            cmds[name] = [*cli, "compare", "--episodes", "100", "--scenarios", "nominal", "--no-plot", "--no-progress",
                          *extra, *([] if link is None else ["--link", link])]
    return cmds


def _no_mpc_args() -> list[str]:
    """``--policies`` NO_MPC without the names that have a seed group (one row each, not a seed-0 row beside
    its group's row: compare refuses a ``--train-seeds`` label that is also a listed policy), and the groups."""
    groups = _seed_groups()
    return ["--policies", ",".join(p for p in NO_MPC.split(",") if p not in groups), *_seed_rows(groups)]


def _seed_groups() -> dict:
    """Every shipped seed group, label -> its rows (rl, ppo_lagrangian, residual, ...: the default rows' groups,
    which an explicit ``--policies`` otherwise drops, and the opt-in ones)."""
    sys.path.insert(0, str(ROOT))
    from policies.compare import shipped_seed_groups
    return shipped_seed_groups()


def _seed_rows(groups: dict) -> list[str]:
    """``--train-seeds`` of each seed group of ``groups``."""
    return [x for k, v in groups.items() for x in ("--train-seeds", f"{k}={','.join(v)}")]


def _expand(argv: list[str], seed: int) -> list[str]:
    return [a.replace("{seed}", str(seed)) for a in argv]


def _bytecode_env(env: dict, pyc: str | None) -> dict:
    """``env`` with Python's bytecode cache on in ``pyc`` (``PYTHONPYCACHEPREFIX``; None: as inherited).

    A user's installed package has its ``.pyc`` files; an environment with ``PYTHONDONTWRITEBYTECODE=1``
    (as the helpers' sessions on this machine have) compiles every module of the tree from source in
    every run (~0.15-0.3 s of CPU for ``dronewpt mission``). The prefix keeps the measured trees
    untouched (no ``__pycache__`` written into them); its first run compiles everything once (warm-up)."""
    if pyc is None:
        return env
    env = {k: v for k, v in env.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, "PYTHONPYCACHEPREFIX": pyc}


def _pick(cmds: dict, mission_only: bool, compare_only: bool) -> dict:
    if mission_only:
        return {k: v for k, v in cmds.items() if k in ("python -c pass", "dronewpt mission", "dronewpt mission --no-plot")}
    if compare_only:
        return {k: v for k, v in cmds.items() if k == "python -c pass" or k.startswith("dronewpt compare")}
    return cmds


def _by_link(cmds: dict) -> list[list[str]]:
    """The command names in timing groups: those without ``--link`` first, then each link's compare commands (all
    trees'), each group timed ``--repeat`` rounds before the next. Interleaved, each tree's eq. 4 compare ran right
    after its own modal one, which keeps both cores busy to its end (the forked child shares its work): the other
    sessions' jobs, held back meanwhile, then took their turn in the eq. 4 run (0.3-2 s more wall, the same CPU;
    docs/performance.md, "seventh pass")."""
    groups: dict[str, list[str]] = {}
    for name in cmds:
        link = name.split(", --link ", 1)[1].split(")", 1)[0] if ", --link " in name else ""
        groups.setdefault(link, []).append(name)
    return list(groups.values())


def end_to_end(repeat: int = 5, compare: str = "no-mpc", before: Path | None = None, pyc: str | None = None,
               mission_only: bool = False, links=(None,), compare_only: bool = False, warm: bool = False,
               before_cache: Path | None = None) -> dict:
    """``warm``: each tree's ``dronewpt warmup`` first (its own cache folder: ``$DRONEWPT_CACHE_DIR`` or
    :func:`tree_cache_dir` for this tree, :func:`_tree_envs` for the ``--before`` tree)."""
    env = _bytecode_env({**os.environ, "PYTHONPATH": str(ROOT)}, pyc)
    if env.get(CACHE_VAR) is None:   # its own folder, as the --before tree's (an empty value: the cache off, kept)
        env[CACHE_VAR] = str(tree_cache_dir(ROOT))
    envs = {}
    before_env = None if before is None else _tree_envs(env, before, before_cache)
    warmed = {}
    if warm:
        for e in (env, *([before_env] if before_env is not None else [])):
            warmed[e["PYTHONPATH"]] = {"cache": e[CACHE_VAR], "warmup_wall_s": _warm(e)}
    with tempfile.TemporaryDirectory() as tmp:
        cmds = _pick(_commands(tmp, compare, links), mission_only, compare_only)
        if before is not None:   # the same mission and compare commands on another tree, interleaved with these
            for name in [k for k in cmds if k.startswith(("dronewpt mission", "dronewpt compare")) and "new path" not in k]:
                cmds[f"{name} (before: {before.name})"] = [a.replace(f"{tmp}/", f"{tmp}/before-") for a in cmds[name]]
                envs[f"{name} (before: {before.name})"] = before_env
        seed = 1000 + int(time.time()) % 100_000 * 100   # new paths: seeds not flown before
        for name, argv in cmds.items():   # warm-up: .pyc, numba's cache, coupling table, Lm of the default path
            _run(_expand(argv, seed), envs.get(name, env))
        load0 = os.getloadavg()
        res = {k: ([], [], set()) for k in cmds}
        for group in _by_link(cmds):   # one link after the other: no eq. 4 run right after a modal one
            for i in range(repeat):
                for name in group:
                    w, c, h = _run(_expand(cmds[name], seed + 1 + i), envs.get(name, env))
                    res[name][0].append(w)
                    res[name][1].append(c)
                    res[name][2].add(h)
        load1 = os.getloadavg()
    out = {"load_before": load0, "load_after": load1, "console_script": _console_script()[0], "pyc": pyc,
           "caches": {env["PYTHONPATH"]: env[CACHE_VAR],
                      **({before_env["PYTHONPATH"]: before_env[CACHE_VAR]} if before_env is not None else {})},
           "warmed": warmed}
    for name, (w, c, h) in res.items():
        out[name] = {"median_s": statistics.median(w), "min_s": min(w), "max_s": max(w), "n": len(w),
                     "cpu_median_s": statistics.median(c), "cpu_min_s": min(c), "cpu_max_s": max(c), "stdout_sha1": sorted(h)}
    for name in [k for k in res if k.startswith("dronewpt compare") and "(before:" not in k]:
        peers = [k for k in res if k.startswith(name + " (before:")]
        out[name]["same_table_as_before"] = (None if not peers else
                                             len(res[name][2] | set().union(*(res[p][2] for p in peers))) == 1)
    return out


_MISSION_PHASES = r'''
import json, sys, time
c = time.process_time
t = [c()]
ph = {}
def lap(k):
    now = c(); ph[k] = now - t[0]; t[0] = now
import numpy; lap("import numpy")
import argparse
from mission_sim.cli.mission import mission_config, make_policy; lap("import the CLI")
cfg = mission_config(argparse.Namespace(config=None, set=None, plan=None, pads=None, force=False, drone=None))
lap("config: TOML, validation, run-size estimate")
pol = make_policy("model_based", cfg); lap("policy + Lm at the hover pose (" + ("numba" if "numba" in sys.modules else "disk cache") + ")")
from pathlib import Path
from mission_sim.world.runner import run_mission
from mission_sim.world.stream import SeriesWriter
out = Path(sys.argv[1]); out.mkdir(exist_ok=True)
w = SeriesWriter(out, csv=False, every_s=0.0, figure_points=20000); lap("import runner, stream, pyarrow")
from mission_sim.world import aot
if aot.enable() and aot.covers("model_based"):   # as dronewpt mission: no numba (mission_sim.world.aot)
    lap("the loop's ahead-of-time build: key, SHA-256, load")
else:
    from wpt_receiver.numba_start import prepare
    prepare(); lap("numba_start.prepare (scipy's cython_blas alone)")
    import numba; lap("import numba")
    from numba.core.registry import cpu_target
    cpu_target.target_context.refresh(); lap("numba's registries")
    import policies.kernels; lap("the policy's compiled kernel from numba's cache")
    from mission_sim.world import loop_kernel
    loop_kernel.advance_for(True); lap("the mission loop from numba's cache (one overload)")
res = run_mission(cfg, pol, charge=True, progress=False, frame=False, sink=w); lap("simulation + uncharged baseline")
w.close(); lap("Parquet close")
import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot; lap("import matplotlib")
from mission_sim.figures.mission import plot_mission
from mission_sim.figures.worker import for_figures
res.timeseries = w.thinned.frame(pandas=False); lap("the thinned copy (numpy columns)")
plot_mission(for_figures(res), out); lap("five figures: draw, PNG")
print(json.dumps(ph))
'''

_COMPARE_PHASES = r'''
import json, sys, time
c = time.process_time
t = [c()]
ph = {}
def lap(k):
    now = c(); ph[k] = ph.get(k, 0.0) + now - t[0]; t[0] = now
import numpy; lap("import numpy")
import envs, envs.vector_kernel, policies.compare as pc; lap("import envs (gymnasium, numba), policies")
orig = pc.run_policy
def timed(name, *a, **k):
    lap("(between rollouts)")
    r = orig(name, *a, **k); lap("rollout " + name.split(":/")[0].split("/")[-1]); return r
pc.run_policy = timed
pols = sys.argv[1].split(",")
groups = pc.shipped_seed_groups()
rows, traces = pc.compare(tuple(p for p in pols if p not in groups), ("nominal",), 100, 1000, train_seeds=groups)
lap("statistics")
pc.frontier("nominal", episodes=100, seed=1000)
lap("frontier statistics")
print(json.dumps(ph))
'''


def phases(policies: str = NO_MPC + ",ppo_lagrangian,residual") -> dict:
    """In-process CPU time per phase of one mission and one compare, each in a fresh interpreter."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with tempfile.TemporaryDirectory() as tmp:
        m = subprocess.run([sys.executable, "-c", _MISSION_PHASES, f"{tmp}/m"], env=env, cwd=ROOT, check=True,
                           capture_output=True, text=True)
        c = subprocess.run([sys.executable, "-c", _COMPARE_PHASES, policies], env=env, cwd=ROOT, check=True,
                           capture_output=True, text=True)
    return {"mission": json.loads(m.stdout.splitlines()[-1]), "compare": json.loads(c.stdout.splitlines()[-1])}


def _print(r: dict) -> None:
    print(f"end to end ({r['console_script']}); load average (1 min) before {r['load_before'][0]:.2f}, "
          f"after {r['load_after'][0]:.2f}; bytecode cache: {r.get('pyc') or 'as inherited'}")
    for tree, cache in r.get("caches", {}).items():
        w = r.get("warmed", {}).get(tree)
        print(f"  tree {tree}: cache {cache or 'off'}" + (f"; warmed ({w['warmup_wall_s']:.1f} s)" if w else "; not warmed here"))
    base = r["python -c pass"]["median_s"]
    goals = {"dronewpt mission": "goal <= 1.0 s", "dronewpt compare (default)": "goal <= 2.5 s",
             "dronewpt compare (no-mpc)": "goal <= 2.5 s (without mpc)"}
    for name, s in r.items():
        if not isinstance(s, dict) or name in ("caches", "warmed"):
            continue
        key = name.split(" (before:")[0].split(", --link")[0]
        goal = goals.get(key + ")" if key.startswith("dronewpt compare (") and not key.endswith(")") else key, "")
        same = "" if s.get("same_table_as_before") is None else \
            f"; every run's table the same as the peer's: {s['same_table_as_before']} ({s['stdout_sha1'][0][:12]})"
        print(f"  {name:<38} wall median {s['median_s']:.3f} s (range {s['min_s']:.3f}-{s['max_s']:.3f}, "
              f"n={s['n']}; {s['median_s'] / base:.1f}x python -c pass); CPU {s['cpu_median_s']:.3f} s "
              f"({s['cpu_min_s']:.3f}-{s['cpu_max_s']:.3f})  {goal}{same}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--compare", choices=("no-mpc", "default", "none"), default="no-mpc")
    ap.add_argument("--phases", action="store_true", help="also the in-process phase table")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--root", type=Path, default=None, help="measure the code tree in this folder (e.g. an older "
                    "commit's `git archive`; default this repository)")
    ap.add_argument("--before", type=Path, default=None, help="also run the two mission commands on this code "
                    "tree (e.g. `git archive` of an older commit), interleaved with this one's")
    ap.add_argument("--pyc", default=os.path.join(tempfile.gettempdir(), "dronewpt-bench-pyc"), metavar="DIR",
                    help="bytecode cache of the measured processes (PYTHONPYCACHEPREFIX; a user's install has its "
                         ".pyc files): default %(default)s; 'inherit' leaves the environment as it is")
    ap.add_argument("--before-cache", type=Path, default=None, metavar="DIR",
                    help="disk cache folder (DRONEWPT_CACHE_DIR) of the --before tree; default one per tree under "
                         "the temporary directory, kept between runs (never the measured tree's: a warmup removes "
                         "other sources' ahead-of-time modules from its folder); not allowed with DRONEWPT_CACHE_DIR "
                         "empty (the cache off for both trees)")
    ap.add_argument("--no-warmup", action="store_true", help="do not run each tree's `dronewpt warmup` (its own "
                    "cache folder) before timing")
    only = ap.add_mutually_exclusive_group()
    only.add_argument("--mission-only", action="store_true", help="only python -c pass and the two mission commands")
    only.add_argument("--compare-only", action="store_true", help="only python -c pass and the compare command(s)")
    ap.add_argument("--link", choices=("modal", "envelope", "both"), default=None,
                    help="compare on this link (`--link` of the command; both: one command each); default: none given")
    a = ap.parse_args(argv)
    if a.root is not None:
        global ROOT
        ROOT = a.root.resolve()
    links = (None,) if a.link is None else ("modal", "envelope") if a.link == "both" else (a.link,)
    r = {"end_to_end": end_to_end(a.repeat, a.compare, a.before, None if a.pyc == "inherit" else a.pyc,
                                  a.mission_only, links, a.compare_only, warm=not a.no_warmup,
                                  before_cache=a.before_cache)}
    if a.phases:
        r["in_process"] = phases()
        r["in_process_load"] = os.getloadavg()
    if a.json:
        print(json.dumps(r, indent=1))
        return
    _print(r["end_to_end"])
    for cmd, ph in r.get("in_process", {}).items():
        print(f"in process, one run (CPU s, load {r['in_process_load'][0]:.2f}): {cmd}, total {sum(ph.values()):.3f}")
        for k, v in ph.items():
            print(f"  {k:<48} {v:7.3f}")


if __name__ == "__main__":
    main()
