"""The start-up cuts of ``dronewpt mission`` (issue 22): numba's BLAS probe answered without importing the
``scipy.linalg`` package (:mod:`wpt_receiver.numba_start`), and the figure worker's forked helper
(:func:`mission_sim.figures.worker._draw_split`): every figure drawn once, in order, also when the
helper dies or fails; the mission's cached kernels loaded without numba's registries
(``cache_loads_without_registries``): the same bits for every kernel policy, a cache miss still compiled."""

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from mission_sim.figures import worker as fw

ROOT = Path(__file__).resolve().parents[1]


def _run(code: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_numba_finds_blas_without_the_scipy_linalg_package_and_dot_is_blas():
    """After prepare(): numba's registries load with BLAS available (np.dot compiles to the BLAS call,
    equal to numpy's product), the package scipy.linalg is not imported; importing it later gives the
    package with its cython_blas attribute (the same module) and working functions."""
    code = """
import json, sys
import numpy as np
from wpt_receiver.numba_start import prepare
first, again = prepare(), prepare()
from numba import njit
@njit
def dot(a, b):
    return np.dot(a, b)
rng = np.random.default_rng(3)
a, b = rng.random((40, 30)), rng.random((30, 20))
err = float(np.max(np.abs(dot(a, b) - a @ b)))
import numba.np.arraymath as am
before = "scipy.linalg" in sys.modules
import scipy.linalg
same = scipy.linalg.cython_blas is sys.modules["scipy.linalg.cython_blas"]
from scipy.linalg import cython_blas
e = float(scipy.linalg.expm(np.array([[0.0, 1.0], [-1.0, 0.0]]))[0, 1])
print(json.dumps([first, again, am._HAVE_BLAS, err, before, same, cython_blas is scipy.linalg.cython_blas, e]))
"""
    first, again, have_blas, err, before, same, same2, e = _run(code)
    assert first is True and again is False
    assert have_blas is True and err < 1e-12
    assert before is False and same and same2
    assert e == pytest.approx(np.sin(1.0), rel=1e-12)





def test_prepare_does_nothing_once_scipy_linalg_is_imported():
    assert _run("import json, scipy.linalg\nfrom wpt_receiver.numba_start import prepare\n"
                "print(json.dumps(prepare()))") is False


def _fake_mission(tmp_path, plot):
    names = ("trajectory", "lm", "i2", "soc", "power")
    return types.SimpleNamespace(FIGURES=names, plot_mission=plot), names


class _Conn:
    def close(self):
        pass


def _writer(tmp_path, log):
    parent = os.getpid()

    def plot(result, out, which=None):
        paths = []
        for n in which:
            p = Path(out) / f"{n}.txt"
            p.write_text(f"{n} {result}")
            paths.append(str(p))
            with open(log, "a") as f:
                f.write(f"{n} {'worker' if os.getpid() == parent else 'helper'}\n")
        return paths
    return plot


def test_split_draws_every_figure_once_in_order_half_in_the_helper(tmp_path):
    log = tmp_path / "log"
    mission, names = _fake_mission(tmp_path, _writer(tmp_path, log))
    files = fw._draw_split(mission, "R", tmp_path, _Conn())
    assert files == [str(tmp_path / f"{n}.txt") for n in names]
    who = dict(line.split() for line in log.read_text().splitlines())
    assert sorted(who) == sorted(names)   # each once
    assert {n for n, w in who.items() if w == "helper"} == set(fw.HELPER_FIGURES)
    assert all((tmp_path / f"{n}.txt").read_text() == f"{n} R" for n in names)


def test_a_helper_that_dies_is_replaced_by_the_worker(tmp_path):
    log = tmp_path / "log"
    parent = os.getpid()
    write = _writer(tmp_path, log)

    def plot(result, out, which=None):
        if os.getpid() != parent:
            os._exit(9)          # the helper killed before it answers
        return write(result, out, which)
    mission, names = _fake_mission(tmp_path, plot)
    files = fw._draw_split(mission, "R", tmp_path, _Conn())
    assert files == [str(tmp_path / f"{n}.txt") for n in names]
    assert sorted(line.split()[1] for line in log.read_text().splitlines()) == ["worker"] * len(names)


def test_an_error_in_the_helper_is_raised_by_the_worker(tmp_path):
    parent = os.getpid()
    write = _writer(tmp_path, tmp_path / "log")

    def plot(result, out, which=None):
        if os.getpid() != parent:
            raise OSError(28, "no space left on device", str(Path(out) / "soc.png"))
        return write(result, out, which)
    mission, _ = _fake_mission(tmp_path, plot)
    with pytest.raises(OSError, match="no space left"):
        fw._draw_split(mission, "R", tmp_path, _Conn())


def test_mission_command_line_ends_without_teardown_but_with_its_output_status_and_atexit(tmp_path):
    """``dronewpt mission`` from the command line ends with os._exit after the command (no module teardown),
    yet its piped output is complete, the atexit handlers ran, the status is the command's (3: a depleted
    battery) and every file is in place; a caller's main(argv) returns as before (the other tests)."""
    marker = tmp_path / "atexit_ran"
    out = tmp_path / "m"
    code = (f"import atexit, sys\natexit.register(lambda: open({str(marker)!r}, 'w').write('yes'))\n"
            f"sys.argv = ['dronewpt', 'mission', '--out', {str(out)!r}, '--no-plot', '--no-progress', "
            "'--set', 'battery.capacity_ah=0.01']\n"
            "import mission_sim.cli as cli\n"
            "real = cli._exit_now\n"
            "def spy(status):\n"
            "    print('quick exit', status, flush=True)\n"
            "    real(status)\n"
            "    print('not reached', flush=True)\n"
            "cli._exit_now = spy\n"
            "sys.exit(cli.console_main())")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert r.returncode == 3, r.stderr
    lines = r.stdout.splitlines()
    assert lines[-1] == "quick exit 3" and "not reached" not in r.stdout
    assert lines[-2] == f"wrote: {out / 'summary.json'}"
    assert marker.read_text() == "yes"
    assert json.loads((out / "summary.json").read_text())["battery_depleted"] is True
    assert "battery depleted" in r.stderr


def test_without_a_free_core_no_helper_is_forked(tmp_path, monkeypatch):
    log = tmp_path / "log"
    mission, names = _fake_mission(tmp_path, _writer(tmp_path, log))
    monkeypatch.setattr(os, "fork", lambda: pytest.fail("forked"))
    files = fw._draw_split(mission, "R", tmp_path, _Conn(), ())
    assert files == [str(tmp_path / f"{n}.txt") for n in names]
    assert [line.split()[1] for line in log.read_text().splitlines()] == ["worker"] * len(names)


def test_core_free_follows_the_running_count_else_the_load_average(monkeypatch):
    """Free: at most CPUs - 1 runnable tasks (this one included) in every read of /proc/loadavg; without that
    file, the 1-minute load average below CPUs - 0.5."""
    import builtins
    import io
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    real_open, reads = builtins.open, []

    def fake_open(path, *a, **k):
        if path != "/proc/loadavg":
            return real_open(path, *a, **k)
        if reads[0] is None:
            raise FileNotFoundError(path)
        return io.StringIO(f"3.10 2.00 1.50 {reads.pop(0)}/321 4567\n")
    monkeypatch.setattr(builtins, "open", fake_open)
    reads[:] = [1, 1, 1]
    assert fw.core_free() is True                  # only this process runs: the other core is free
    reads[:] = [1, 2, 1]
    assert fw.core_free() is False                 # something else ran in one of the reads
    reads[:] = [3]
    assert fw.core_free() is False
    reads[:] = [None]                              # no /proc/loadavg: the load average decides
    monkeypatch.setattr(os, "getloadavg", lambda: (1.2, 1.0, 1.0))
    assert fw.core_free() is True
    reads[:] = [None]
    monkeypatch.setattr(os, "getloadavg", lambda: (1.6, 1.0, 1.0))
    assert fw.core_free() is False


def test_numba_start_survives_a_find_spec_probe_and_fails_safe_without_the_extension():
    """A ``find_spec('scipy.linalg')`` probe before the import leaves the hook in place (the package still gets
    its ``cython_blas``), and with the extension missing ``prepare`` does nothing (numba imports as before)."""
    code = ("import importlib.util, sys\nfrom wpt_receiver import numba_start\n"
            "assert numba_start.prepare()\nimportlib.util.find_spec('scipy.linalg')\n"
            "import scipy.linalg\nassert scipy.linalg.cython_blas is sys.modules['scipy.linalg.cython_blas']\n"
            "print('ok')\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert r.stdout.strip() == "ok", r.stderr
    code = ("import importlib.machinery, sys\nimportlib.machinery.EXTENSION_SUFFIXES[:] = ['.nonexistent']\n"
            "from wpt_receiver import numba_start\nassert numba_start.prepare() is False\n"
            "assert 'scipy.linalg.cython_blas' not in sys.modules\nprint('ok')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert r.stdout.strip() == "ok", r.stderr


# ``dronewpt mission`` loads its cached kernels without numba's registries
# (``wpt_receiver.numba_start.cache_loads_without_registries``, installed by the CLI just before the run): each
# mission's summary and stored time series, bit for bit, in a fresh process per mode ("plain": the hook
# replaced by a no-op), and the registries' state and the kernels' cache statistics at the end.
_MISSIONS = r'''
import hashlib, json, sys
mode, out, seed, *pols = sys.argv[1:]
import wpt_receiver.numba_start as ns
if mode == "plain":
    ns.cache_loads_without_registries = lambda: False
from mission_sim.cli import main
from mission_sim.world import loop_kernel
import pyarrow.parquet as pq
at_loop = []   # numba's registries loaded when the loop came from the cache?
advance_for = loop_kernel.advance_for
def spy(compiled_policy):
    d = advance_for(compiled_policy)
    at_loop.append("numba.np.polynomial.polynomial_core" in sys.modules)
    return d
loop_kernel.advance_for = spy
res = {}
for pol in pols:
    rc = main(["mission", "--no-plot", "--no-progress", "--format", "json", "--policy", pol, "--out", f"{out}/{pol}",
               "--set", f"seed={seed}"])
    t, h = pq.read_table(f"{out}/{pol}/timeseries.parquet"), hashlib.sha256()
    for name in t.column_names:
        a = t.column(name).to_numpy(zero_copy_only=False)
        h.update(name.encode() + (a.tobytes() if a.dtype != object else "\x00".join(map(str, a)).encode()))
    s = json.load(open(f"{out}/{pol}/summary.json"))
    wall = {k: s.pop(k) for k in ("wall_s", "realtime_factor")}
    res[pol] = {"rc": rc, "rows": t.num_rows, "series": h.hexdigest(), "summary": s}
from numba.core import caching
from wpt_receiver import coupling_kernel
print(json.dumps({"hook": getattr(caching.Cache.load_overload, "_dronewpt_lazy", False), "runs": res,
                  "registries": "numba.np.polynomial.polynomial_core" in sys.modules, "at_loop": at_loop,
                  "loop_hits": sum(sum(d.stats.cache_hits.values()) for d in loop_kernel._ONE.values()),
                  "table_misses": sum(coupling_kernel.flux_table.stats.cache_misses.values())}))
'''

#: every policy ``dronewpt mission --policy`` accepts that has a compiled kernel (policies.kernels.KERNELS),
#: and one without (its duty computed in Python: the loop's other overload)
_KERNEL_POLICIES = ("model_based", "step", "ramp", "hysteresis")


def _missions(mode, out, seed, pols, **env_extra):
    """The missions of ``pols`` in a fresh process (``env_extra``: environment variables set, None: removed)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **env_extra}
    env = {k: v for k, v in env.items() if v is not None}
    r = subprocess.run([sys.executable, "-c", _MISSIONS, mode, str(out), str(seed), *pols], capture_output=True,
                       text=True, env=env, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def _check_physics(run):
    s = run["summary"]
    assert run["rc"] == 0 and run["rows"] > 100
    assert abs(s["energy_balance_error_rel"]) < 1e-3
    assert 0 < s["battery_charge_in_j"] < s["rectifier_output_j"] < s["energy_from_source_j"]
    assert s["final_soc"] > s["final_soc_without_charging"]


def _private_numba_cache(dest: Path) -> dict:
    """A ``NUMBA_CACHE_DIR`` of a test's own at ``dest``, seeded with the numba cache files (``.nbi``, ``.nbc``,
    ``.deps``) of the repository's packages from where this process's numba keeps them (the sources'
    ``__pycache__``, or the ``NUMBA_CACHE_DIR`` set), laid out as numba's user-provided locator reads them.

    Only this test's processes write there: in the shared cache another xdist worker compiling an overload of the same
    kernel at the same moment can replace the index another process just saved (numba's index update is a
    load-modify-replace, not a lock), so a later run misses and compiles (CI, 2026-11-28: the registries loaded)."""
    import shutil

    from numba.core.caching import UserProvidedCacheLocator
    shared = os.environ.get("NUMBA_CACHE_DIR")
    for pkg in ("wpt_receiver", "mission_sim", "envs", "policies"):
        for init in (ROOT / pkg).rglob("__init__.py"):
            sub = UserProvidedCacheLocator.get_suitable_cache_subpath(str(init))
            src = Path(shared) / sub if shared else init.parent / "__pycache__"
            if not src.is_dir():
                continue
            (dest / sub).mkdir(parents=True, exist_ok=True)
            for f in src.iterdir():
                if f.suffix in (".nbi", ".nbc", ".deps"):
                    try:
                        shutil.copy2(f, dest / sub / f.name)
                    except OSError:   # (replaced or removed by another worker meanwhile: a miss, compiled then)
                        pass
    return {"NUMBA_CACHE_DIR": str(dest)}


def test_mission_loads_its_kernels_without_registries_and_runs_the_same_bits(tmp_path):
    """The default mission with each kernel policy (and a Python one): the same summary and time series to the bit
    with and without the hook, the loop loaded from the cache either way, numba's registries never loaded with the
    hook (the compiled policies go to the cached loop as first-class functions all the same). The runs use a numba
    cache of their own (:func:`_private_numba_cache`), filled by the first."""
    from policies.kernels import KERNELS
    assert set(KERNELS) <= set(_KERNEL_POLICIES)
    own = _private_numba_cache(tmp_path / "numba")
    plain = _missions("plain", tmp_path / "plain", 0, _KERNEL_POLICIES, **own)   # also warms the cache (first run)
    lazy = _missions("lazy", tmp_path / "lazy", 0, _KERNEL_POLICIES, **own)
    assert lazy["hook"] and not plain["hook"]
    assert plain["registries"] and not lazy["registries"] and not any(lazy["at_loop"])
    assert lazy["loop_hits"] == 2          # both overloads of the loop (compiled policy, Python policy) from the cache
    for pol in _KERNEL_POLICIES:
        assert lazy["runs"][pol] == plain["runs"][pol], pol
        _check_physics(lazy["runs"][pol])


def _numba_cache_without(warm: Path, dest: Path, module: str) -> None:
    """The numba cache folder ``warm`` (a ``NUMBA_CACHE_DIR``) copied into ``dest``, except the files of ``module`` (a
    file stem): its kernels miss."""
    import shutil
    shutil.copytree(warm, dest, ignore=shutil.ignore_patterns(module + ".*"))


def test_mission_whose_kernel_misses_the_cache_compiles_it_after_a_registry_free_load(tmp_path):
    """A path never flown (its Lm not on disk) with the coupling kernels missing from numba's cache: the loop loads
    from the cache without the registries, then the Lm table kernel compiles (the compiler loads them) and the
    mission gives the bits of a run without the hook.

    The numba cache copied is the one the first two runs fill, a ``NUMBA_CACHE_DIR`` of the test's own (the tree's
    ``__pycache__`` was copied, the runs made to write there: the test wrote into the source tree and failed on a
    read-only checkout; before that, with ``NUMBA_CACHE_DIR`` set, the runs wrote elsewhere than the copy's source)."""
    import shutil
    disk = tmp_path / "disk"
    tree = dict(NUMBA_CACHE_DIR=str(tmp_path / "warm"))   # the numba cache _numba_cache_without copies
    _missions("plain", tmp_path / "other", 8, ("model_based",), DRONEWPT_CACHE_DIR=str(disk), **tree)  # tables, hover Lm
    shutil.copytree(disk, tmp_path / "disk2")     # ... without the Lm of seed 7's path
    plain = _missions("plain", tmp_path / "plain", 7, ("model_based",), DRONEWPT_CACHE_DIR=str(disk), **tree)
    _numba_cache_without(tmp_path / "warm", tmp_path / "numba", "coupling_kernel")
    miss = _missions("lazy", tmp_path / "lazy", 7, ("model_based",), DRONEWPT_CACHE_DIR=str(tmp_path / "disk2"),
                     NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    assert miss["hook"] and miss["at_loop"][0] is False and miss["registries"]   # loaded first, compiled later
    assert miss["loop_hits"] == 1 and miss["table_misses"] >= 1
    assert miss["runs"] == plain["runs"]
    _check_physics(miss["runs"]["model_based"])


_SWEEP_WORKER = r'''
import json, sys
import wpt_receiver.numba_start as ns
if sys.argv[1] == "plain":
    ns.cache_loads_without_registries = lambda: False
import policies
from mission_sim.config import load_config_dict
from mission_sim.studies.mission_cases import MissionCaseRunner
r = MissionCaseRunner(load_config_dict(), policies.make, policies.available())
r.warm()
out = [r(p) for p in ({"seed": 3}, {"policy": "step", "wind.speed_m_s": 4.0}, {"policy": "hysteresis"})]
for s in out:
    s.pop("wall_s"), s.pop("realtime_factor")
print(json.dumps({"registries": "numba.np.polynomial.polynomial_core" in sys.modules, "cases": out}))
'''


def test_sweep_worker_warmed_without_registries_gives_the_same_summaries():
    """A sweep worker's warm-up (``MissionCaseRunner.warm``) installs the hook: its cases' summaries are those of
    a worker without it, to the bit, and numba's registries are never loaded."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    res = {m: json.loads(subprocess.run([sys.executable, "-c", _SWEEP_WORKER, m], capture_output=True, text=True,
                                        env=env, cwd=ROOT, timeout=600, check=True).stdout.strip().splitlines()[-1])
           for m in ("plain", "lazy")}
    assert res["plain"]["registries"] and not res["lazy"]["registries"]
    assert res["lazy"]["cases"] == res["plain"]["cases"]
    for s in res["lazy"]["cases"]:
        assert abs(s["energy_balance_error_rel"]) < 1e-3 and s["final_soc"] > s["final_soc_without_charging"]


_PAPER = r'''
import contextlib, io, json, sys
import wpt_receiver.numba_start as ns
if sys.argv[1] == "plain":
    ns.cache_loads_without_registries = lambda: False
from mission_sim.cli import main
buf = io.StringIO()
with contextlib.redirect_stdout(buf):
    rc = main(["paper", "--no-plot", "--format", "json", "--model", sys.argv[2]])
rows = json.loads(buf.getvalue())["rows"]
for r in rows:
    r.pop("sim_wall_s")
print(json.dumps({"rc": rc, "registries": "numba.np.polynomial.polynomial_core" in sys.modules, "rows": rows}))
'''


@pytest.mark.parametrize("model", ["modal", "switching"])
def test_paper_with_its_kernels_loaded_without_registries_gives_the_same_table(model):
    """``dronewpt paper --model modal|switching`` installs the hook: Table II's rows to the bit as without it, the
    registries never loaded, and the paper's ordering (overshoot: step > ramp > proposed)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    res = {m: json.loads(subprocess.run([sys.executable, "-c", _PAPER, m, model], capture_output=True, text=True,
                                        env=env, cwd=ROOT, timeout=600, check=True).stdout.strip().splitlines()[-1])
           for m in ("plain", "lazy")}
    assert res["plain"]["registries"] and not res["lazy"]["registries"]
    assert res["lazy"]["rows"] == res["plain"]["rows"]
    over = {r["trajectory"]: r["overshoot_pct"] for r in res["lazy"]["rows"]}
    assert over["step"] > over["ramp"] > over["proposed"] >= 0.0


_SIZING = r'''
import contextlib, io, json, sys
import wpt_receiver.numba_start as ns
if sys.argv[1] == "plain":
    ns.cache_loads_without_registries = lambda: False
from mission_sim.cli import main
buf = io.StringIO()
with contextlib.redirect_stdout(buf):
    rc = main(["sizing", "--no-plot", "--no-progress", "--format", "json", "--source", "mission"])
print(json.dumps({"rc": rc, "registries": "numba.np.polynomial.polynomial_core" in sys.modules,
                  "out": json.loads(buf.getvalue())}))
'''


def test_sizing_from_missions_without_registries_gives_the_same_rows():
    """``dronewpt sizing --source mission`` installs the hook once its input is checked: the same rows to the bit,
    the registries never loaded; the rating is the margin times the peak |i2|, the step's peak the largest."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    res = {m: json.loads(subprocess.run([sys.executable, "-c", _SIZING, m], capture_output=True, text=True,
                                        env=env, cwd=ROOT, timeout=600, check=True).stdout.strip().splitlines()[-1])
           for m in ("plain", "lazy")}
    assert res["plain"]["registries"] and not res["lazy"]["registries"]
    assert res["lazy"]["out"] == res["plain"]["out"]
    out = res["lazy"]["out"]
    peak = {r["policy"]: r["peak_i2_a"] for r in out["rows"]}
    assert peak["step"] > max(peak["ramp"], peak["model_based"]) > 0
    for r in out["rows"]:
        assert r["required_rating_a"] == pytest.approx(out["margin"] * r["peak_i2_a"], rel=1e-12)


_REPLAY = r'''
import contextlib, io, json, sys
import wpt_receiver.numba_start as ns
if sys.argv[1] == "plain":
    ns.cache_loads_without_registries = lambda: False
from mission_sim.cli import main
buf = io.StringIO()
with contextlib.redirect_stdout(buf):
    rc = main(["replay", sys.argv[2], "--no-plot", "--no-progress", "--format", "json", "--out", sys.argv[3]])
out = json.loads(buf.getvalue())
def strip(d):   # the run's timing: not a result
    return {k: strip(v) if isinstance(v, dict) else v for k, v in d.items() if "wall" not in k and "realtime" not in k}
print(json.dumps({"rc": rc, "registries": "numba.np.polynomial.polynomial_core" in sys.modules, "out": strip(out)}))
'''


def test_replay_without_registries_gives_the_same_summary(tmp_path):
    """``dronewpt replay`` of a real flight log installs the hook once its input is checked: the same summary to
    the bit as without it, the registries never loaded."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    log = ROOT / "tests" / "data" / "flightlogs" / "dronekit-python_flight.tlog"
    res = {m: json.loads(subprocess.run([sys.executable, "-c", _REPLAY, m, str(log), str(tmp_path / "out")],
                                        capture_output=True, text=True, env=env, cwd=ROOT, timeout=600,
                                        check=True).stdout.strip().splitlines()[-1]) for m in ("plain", "lazy")}
    assert res["plain"]["registries"] and not res["lazy"]["registries"]
    assert res["lazy"]["rc"] == res["plain"]["rc"] == 0
    assert res["lazy"]["out"] == res["plain"]["out"]
