"""The autoreset's paths of the vector env that a speed pass changed (2026-11-27, branch vecenv3): the one rule
for the compiled parts run over chunks (:func:`envs.chunked.run_chunks`: one chunk calls the serial loop, so no
thread pool is started), and the true Lm of windows that share one wind level written by slice instead of a
gather (:func:`envs.plant.lm_window_h`): the same numbers as the gather, to the bit."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from envs.chunked import run_chunks
from envs.plant import lm_window_h


def test_one_chunk_runs_the_serial_loop_more_the_parallel_function():
    calls = []

    def serial(lo, hi, *args):
        calls.append(("serial", lo, hi, args))

    def parallel(*args):
        calls.append(("parallel",) + args)

    run_chunks(serial, parallel, 10, 1, "a", 2.0)
    run_chunks(serial, parallel, 10, 0, "a", 2.0)
    run_chunks(serial, parallel, 10, 3, "a", 2.0)
    assert calls == [("serial", 0, 10, ("a", 2.0)), ("serial", 0, 10, ("a", 2.0)), ("parallel", "a", 2.0, 3)]


@pytest.mark.parametrize("wind", [0.0, 4.0])
def test_one_wind_level_by_slice_is_the_gather_to_the_bit(wind):
    """Windows of one wind level (the whole batch: slices) against the same windows in a batch with a second level
    (a gather of their rows), windless (constant record) and windy (interpolated)."""
    u = np.array([0.0, 0.31, 0.77, 0.999])
    t = np.arange(30) * 0.01
    alone = lm_window_h(np.full(4, wind), u, t)
    mixed = lm_window_h(np.r_[np.full(4, wind), 7.0], np.r_[u, 0.5], t)
    assert alone.tobytes() == mixed[:4].tobytes()
    assert not np.array_equal(mixed[4], mixed[0])


_NO_POOL = """
import numpy as np
from numba.np.ufunc import parallel
from envs import EnvConfig
from envs.vector import SbarChargingVectorEnv
env = SbarChargingVectorEnv(64, config=EnvConfig(n_steps=20, link_model="envelope"))
env.reset(seed=1)
env.restart(np.arange(0, 64, 3))
print(parallel._is_initialized)
"""


def test_a_serial_env_resets_without_starting_numbas_pool():
    """Below the parallel width a reset's draws and command profile (one chunk) run their serial loops: numba's
    thread pool is not started (a started pool forbids the fork ``compare`` runs its MPC in; the step, a
    ``parallel=True`` function, starts it at its first call)."""
    numba = pytest.importorskip("numba")
    parallel = pytest.importorskip("numba.np.ufunc.parallel")
    if not hasattr(parallel, "_is_initialized"):   # numba's private flag: gone or renamed in this version
        pytest.skip(f"numba {numba.__version__} has no numba.np.ufunc.parallel._is_initialized to read")
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", _NO_POOL], capture_output=True, text=True, cwd=root,
                         env={**os.environ, "PYTHONPATH": str(root)}, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[-1] == "False"
