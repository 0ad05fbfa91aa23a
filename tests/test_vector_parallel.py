"""The vector env's step parallel over sub-environments (numba ``prange`` over chunks) gives the serial
step's results to the bit, through autoresets, tuned and detuned windows alike; ``num_threads`` is
checked against numba's pool."""

import numpy as np
import pytest

from envs import EnvConfig, SbarChargingVectorEnv

SHORT = EnvConfig(n_steps=40)


def _pair(scenario, n, chunks, cfg=SHORT):
    serial = SbarChargingVectorEnv(n, scenario, cfg, num_threads=1)
    par = SbarChargingVectorEnv(n, scenario, cfg)
    par._n_chunks = chunks   # whatever N: uneven chunks, more chunks than threads
    assert serial._n_chunks == 1
    return serial, par


@pytest.mark.parametrize("link", ["modal", "envelope"])   # the default (modal since 2026-11-26) and eq. 4's step
@pytest.mark.parametrize("scenario", ["random", "detuned"])
def test_parallel_step_equals_serial_bitwise(scenario, link):
    n = 2 * 512 + 77   # the serial env's one chunk: three blocks of envs.vector_kernel._BLOCK, the last partial
    serial, par = _pair(scenario, n, 7, EnvConfig(n_steps=SHORT.n_steps, link_model=link))
    o1, i1 = serial.reset(seed=12)
    o2, i2 = par.reset(seed=12)
    assert np.array_equal(o1, o2)
    rng = np.random.default_rng(4)
    split = blocked = 0
    for _ in range(2 * SHORT.n_steps + 5):   # two autoresets
        a = rng.uniform(-1.0, 1.0, (n, 1)).astype(np.float32)
        prev = i1["i2_a"].copy()
        s1, s2 = serial.step(a), par.step(a)
        i1 = s1[4]
        for x, y in zip(s1[:4], s2[:4]):
            assert np.array_equal(x, y)
        assert list(s1[4]) == list(s2[4]) and all(np.array_equal(s1[4][k], s2[4][k]) for k in s1[4])
        split += int(np.sum(prev * i1["i2_a"] < 0.0))
        blocked += int(np.sum(i1["i2_a"] == 0.0))
    if scenario == "random":
        assert split > 100   # sub-stepped steps were compared (the envelope rings through zero)
        if link == "envelope":   # and blocked windows (eq. 4's rectifier holding I2 at exactly 0; 19,577 of
            assert blocked > 0   # the 93,585 window-steps, 2026-11-28; the modal link's I2 is never exactly 0)
    else:
        assert par._detuned.all() and np.abs(par._c_rel).max() > 0.01   # complex envelopes were compared


def test_num_threads_is_checked():
    import numba
    top = numba.config.NUMBA_NUM_THREADS
    for bad in (0, top + 1, 1.5):
        with pytest.raises(ValueError, match=r"num_threads=.* is invalid; valid range: integer 1\.\."):
            SbarChargingVectorEnv(4, num_threads=bad)
    assert SbarChargingVectorEnv(4).num_threads == top
    small = SbarChargingVectorEnv(SbarChargingVectorEnv.PARALLEL_MIN_ENVS - 1)
    assert small._n_chunks == 1   # below the threshold: one chunk on the calling thread


def test_auto_threads_follow_the_measured_times():
    """The default (num_threads=None) probes one thread against all and keeps the faster; re-probed
    every PERIOD steps (a busier machine later flips it)."""
    from envs.vector import _AutoThreads
    a = _AutoThreads()
    for t_serial, t_par, want in ((1.0, 0.4, 8), (0.3, 2.0, 1)):
        for _ in range(a.PERIOD):
            c = a.chunks(8)
            a.record(c, t_serial if c == 1 else t_par)
            if a.step % a.PERIOD >= a.PROBE:
                assert a.chunks(8) == want
    big = SbarChargingVectorEnv(SbarChargingVectorEnv.PARALLEL_MIN_ENVS, config=SHORT)
    assert big._auto is not None and SbarChargingVectorEnv(4096, num_threads=1, config=SHORT)._auto is None


_THREADS_SCRIPT = """
import sys, types
import numba, numpy as np
import numba.np.ufunc as ufunc
from numba.np.ufunc import parallel
from envs import EnvConfig, SbarChargingVectorEnv
from envs import vector

env = SbarChargingVectorEnv(2048, "random", EnvConfig(n_steps=40, link_model="envelope"), num_threads=2)
assert env._n_chunks > 1
seen = []
plant_step = env.parts.plant.step
def spy(*args):   # what the step's parallel kernel is called under
    seen.append((numba.get_num_threads(), numba.get_parallel_chunksize()))
    return plant_step(*args)
env.parts.plant.step = spy
env.reset(seed=3)
a = np.zeros((2048, 1), np.float32)
if sys.argv[1] == "fallback":   # a numba without the pool's private names: the public getters
    env.step(a)   # (compiled with the real module)
    vector._GETTERS[:] = []
    ufunc.parallel = types.SimpleNamespace()
numba.set_num_threads(1)   # the user's own settings on the calling thread
numba.set_parallel_chunksize(4)
env.step(a)
ufunc.parallel = parallel
print(seen[-1], numba.get_num_threads(), numba.get_parallel_chunksize(),
      vector._GETTERS[0] is parallel._get_num_threads, vector._GETTERS[1] is parallel._get_parallel_chunksize,
      vector._GETTERS[0] is numba.get_num_threads, vector._GETTERS[1] is numba.get_parallel_chunksize)
"""


@pytest.mark.parametrize("getters", ["private", "fallback"])
def test_a_parallel_step_sets_its_threads_and_chunk_size_over_the_users(getters):
    """The user's ``numba.set_num_threads(1)`` / ``set_parallel_chunksize(4)`` on the calling thread before a step of an
    env with ``num_threads=2`` (N = 2,048: parallel): the step runs on 2 threads with chunks handed out one at a time,
    and leaves them so (numba's settings are not restored: the env's contract is its own threads for its steps);
    the getters cached are the pool's private ones (:func:`envs.vector._getters`), numba's public ones when the
    private names are missing (a stub module)."""
    import os
    import subprocess
    import sys
    from pathlib import Path
    pytest.importorskip("numba")
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(root), "NUMBA_NUM_THREADS": "2"}
    proc = subprocess.run([sys.executable, "-c", _THREADS_SCRIPT, getters], cwd=root, env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    private = getters == "private"
    assert proc.stdout.split() == ["(2,", "1)", "2", "1", str(private), str(private), str(not private),
                                   str(not private)], proc.stdout
