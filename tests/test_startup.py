"""Start-up structure: the CLI and the mission path import only what they use (issue 14).

Each check runs in a fresh interpreter (``sys.modules`` of this test process is polluted by
other tests). No timings are asserted, only which modules got imported.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("pandas", "scipy", "scipy.signal", "matplotlib", "torch", "stable_baselines3", "dask", "pymavlink",
         "gymnasium", "numba")


def _imported(code: str, names=HEAVY) -> list[str]:
    """The subset of ``names`` in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps([m for m in {list(names)!r} if m in sys.modules]))"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=120, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_cli_import_is_argparse_level():
    assert _imported("import mission_sim.cli") == []


def test_cli_help_imports_nothing_heavy():
    code = ("import contextlib, io, mission_sim.cli as c\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        c.main(['--help'])\n    except SystemExit:\n        pass")
    assert _imported(code) == []


@pytest.mark.parametrize("module", ["mission_sim.config", "mission_sim.world.runner", "mission_sim.world.fastpath",
                                    "wpt_receiver.coupling", "policies", "envs"])
def test_mission_path_skips_signal_plotting_and_torch(module):
    # scipy.signal alone costs ~1.2 s to import; the mission needs none of it (wpt_receiver.lti)
    got = _imported(f"import {module}", ("scipy.signal", "matplotlib", "torch", "stable_baselines3", "dask",
                                          "pymavlink", "numba"))
    assert got == []


def test_mission_with_cached_coupling_table_skips_scipy_ndimage_and_special(tmp_path):
    """With the coupling table and coil inductances in the disk cache, a mission run loads neither
    scipy.ndimage nor scipy.special (~0.5 s of imports together): the table is evaluated by
    wpt_receiver.coupling_kernel. The first process fills the cache (a fresh cache dir: self-contained)."""
    code = ("import os\nfrom mission_sim.cli import main\n"
            f"main(['mission', '--out', {str(tmp_path / 'm')!r}, '--no-plot'])")
    os.environ["DRONEWPT_CACHE_DIR"] = str(tmp_path / "cache")
    try:
        first = _imported(code, ("scipy.ndimage", "scipy.special"))
        again = _imported(code, ("scipy.ndimage", "scipy.special"))
    finally:
        del os.environ["DRONEWPT_CACHE_DIR"]
    assert first == ["scipy.ndimage", "scipy.special"]  # built: the exact field needs both
    assert again == []


def test_switching_model_imports_numba_only_when_it_runs():
    """numba (~0.3 s import, compile or cache load) is paid by the first switching run, not by
    importing the model or by the CLI's paper command path."""
    assert "numba" not in _imported("import wpt_receiver.switching, wpt_receiver.paper")
    code = ("from wpt_receiver import TABLE_I\nfrom wpt_receiver.switching import SwitchingLink\n"
            "l = SwitchingLink(TABLE_I)\nl.run(l.schedule(0.0, 4 * l.T, 0.0), l.periodic_steady_state(0.0))")
    assert "numba" in _imported(code)


def test_model_based_policy_built_without_scipy_signal():
    code = ("import policies\nfrom mission_sim.contract import PolicyContext\n"
            "p = policies.make('model_based', PolicyContext())")
    assert "scipy.signal" not in _imported(code)


def test_cli_mission_loads_the_one_compiled_loop(tmp_path, monkeypatch):
    """``dronewpt mission`` runs every mission through the compiled loop (issue 22: the loop's physics exists
    only compiled, mission_sim.world.loop_kernel; so does the coupling table's lookup,
    wpt_receiver.coupling_kernel, on a path not in the disk cache); the CLI's import itself stays free
    of numba (test above)."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path / "cache"))
    code = ("from mission_sim.cli import main\n"
            f"main(['mission', '--out', {str(tmp_path / 'm')!r}, '--no-plot', '--no-progress'])")
    names = ("mission_sim.world.loop_kernel", "wpt_receiver.coupling_kernel")
    assert _imported(code, names) == list(names)


def _summary(path: Path) -> dict:
    return {k: v for k, v in json.loads((path / "summary.json").read_text()).items()
            if k not in ("wall_s", "realtime_factor")}


def test_mission_on_a_known_path_needs_no_coupling_kernel_and_gives_the_same_results(tmp_path, monkeypatch):
    """Lm along a path is kept in the disk cache keyed by the poses (wpt_receiver.coupling.MEMO_MAX_POSES):
    a second mission on the same path, here with another policy, does not load the table kernel and gives
    the summary and series of a run without any cache."""
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path / "cache"))
    run = ("from mission_sim.cli import main\n"
           "main(['mission', '--out', {out!r}, '--no-plot', '--no-progress', '--policy', {pol!r}])")
    names = ("wpt_receiver.coupling_kernel",)    # numba itself: the mission loop's kernel loads it anyway
    assert _imported(run.format(out=str(tmp_path / "a"), pol="model_based"), names) == list(names)
    assert _imported(run.format(out=str(tmp_path / "b"), pol="ramp"), names) == []
    assert len(list((tmp_path / "cache").glob("lm_poses-*.npy"))) >= 1
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", "")   # no disk cache at all: computed by the kernel
    _imported(run.format(out=str(tmp_path / "c"), pol="ramp"), names)
    assert _summary(tmp_path / "b") == _summary(tmp_path / "c")
    assert (tmp_path / "b" / "timeseries.parquet").read_bytes() == (tmp_path / "c" / "timeseries.parquet").read_bytes()


def test_compare_defaults_import_no_torch_sb3_scipy_stats_or_plotting():
    """``dronewpt compare --no-plot`` at its default policies (the shipped learned ones included, their
    training-seed rows with t intervals): the PPO actors come from the zips' state dicts read with numpy
    (policies.inference.read_state_dict), the t quantile from scipy.special; nothing plots."""
    pytest.importorskip("stable_baselines3")
    code = ("import contextlib, io\nfrom mission_sim.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
            "    main(['compare', '--episodes', '3', '--scenarios', 'nominal', '--no-plot', '--no-progress'])\n"
            "assert 'residual' in out.getvalue() and 'ppo_lagrangian' in out.getvalue()")
    assert _imported(code, ("torch", "stable_baselines3", "scipy.stats", "matplotlib", "pandas")) == []


def test_mission_figures_read_the_series_without_pandas(tmp_path):
    """The figures read the stored series back as numpy columns (world.stream.read_series(frame=False)):
    a default ``dronewpt mission`` with its five figures never imports pandas (~0.2-0.5 s). matplotlib is
    imported by the forked figure worker (mission_sim.figures.worker), not by the command's process."""
    code = ("from mission_sim.cli import main\n"
            f"main(['mission', '--out', {str(tmp_path / 'm')!r}, '--no-progress'])")
    assert _imported(code, ("pandas", "matplotlib", "scipy.stats", "torch")) == []
    assert len(list((tmp_path / "m").glob("*.png"))) == 5
