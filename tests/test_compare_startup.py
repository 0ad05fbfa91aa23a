"""``dronewpt compare``'s start-up cuts change its cost, not its numbers (issue 22):

* the MPC's steady-state Kalman gain goes through the disk cache: the cached gain is the array scipy's
  ``solve_discrete_are`` gives (the same bits), and an MPC built on a warm cache does not import the
  ``scipy.linalg`` package (0.3-1 s of CPU in compare's forked MPC child);
* numba's cache loads without its registries (``wpt_receiver.numba_start.cache_loads_without_registries``):
  the same machine code runs (the same bits out), a cache miss still compiles;
* the MPC's forked child imports neither ``policies.rl`` nor ``policies.residual`` (``batched.stackable`` looks
  their classes up instead of importing them), while a learned policy is still told apart and stacked;
* the cyclic garbage collector is paused through the command's start-up and on again (the start-up's objects
  frozen) once the runs start: the rows are the same with and without the pause.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("daqp")


def _filter_matrices():
    """The MPC's filter problem (A, C, Q, R) as ``_Model._kalman`` builds it for the default link."""
    from policies.mpc import MPCPolicy

    m = MPCPolicy()._model
    A = np.zeros((3, 3))
    A[:2, :2], A[:2, 2], A[2, 2] = m.ad, m.b2, 1.0
    return A, np.array([[0.0, 1.0, 0.0]]), np.diag([1e-3 ** 2, 1e-3 ** 2, 0.05 ** 2]), np.array([[0.1 ** 2]])


def test_cached_kalman_gain_is_scipys_to_the_bit(tmp_path, monkeypatch):
    from scipy.linalg import solve_discrete_are

    from policies.mpc import _steady_kalman_gain

    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path))
    A, C, Q, R = _filter_matrices()
    P = solve_discrete_are(A.T, C.T, Q, R)
    want = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    fresh = _steady_kalman_gain(A, C, Q, R)          # computed, then stored
    assert list(tmp_path.glob("kalman-*.npy"))
    cached = _steady_kalman_gain(A, C, Q, R)         # loaded
    assert fresh.tobytes() == want.tobytes() and cached.tobytes() == want.tobytes()
    # a stationary filter: the gain's closed loop is stable and the gain moves the I2 estimate most
    assert np.max(np.abs(np.linalg.eigvals(A - want @ C @ A))) < 1.0
    # another noise level is another key: a different gain, not the cached one
    other = _steady_kalman_gain(A, C, Q, 4.0 * R)
    assert other[1, 0] < want[1, 0]


_NO_LINALG = """
import sys
from wpt_receiver.numba_start import prepare
prepare()
from mission_sim.contract import PolicyContext
from policies.mpc import MPCPolicy
MPCPolicy(PolicyContext(link_model="{link}"))
print("scipy.linalg" in sys.modules)
"""


@pytest.mark.parametrize("link", ["envelope", "modal"])
def test_mpc_on_a_warm_cache_does_not_import_scipy_linalg(tmp_path, link):
    """eq. 4's MPC and the modal one (its modes and ZOH from wpt_receiver.modal_kernel, its filter through the
    same cache)."""
    import os
    env = {**os.environ, "DRONEWPT_CACHE_DIR": str(tmp_path)}
    code = _NO_LINALG.replace("{link}", link)
    out = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
           .stdout.strip() for _ in range(2)]
    assert out == ["True", "False"]   # the first run solves the equation (and stores it), the second loads it


_KERNEL = '''
import numpy as np
from numba import njit, prange

@njit(cache=True)
def energy(i, r, dt):
    """sum(i^2 r dt) [J] with a temporary array (numba's runtime allocates it)"""
    p = np.empty_like(i)
    for k in range(i.size):
        p[k] = i[k] * i[k] * r
    return p.sum() * dt

@njit(cache=True, parallel=True)
def scaled(x, a):
    out = np.empty_like(x)
    for k in prange(x.size):
        out[k] = np.sin(a * x[k])
    return out
'''

_USE = '''
import json, sys
import numpy as np
from wpt_receiver.numba_start import cache_loads_without_registries
lazy = sys.argv[1] == "lazy" and cache_loads_without_registries()
import kern
i = np.linspace(0.0, 2.0, 1001)
e = kern.energy(i, 0.5, 1e-3)
s = kern.scaled(i, 3.0)
import hashlib
print(json.dumps({"lazy": lazy, "e": e.hex(), "s": hashlib.sha256(s.tobytes()).hexdigest(), "s_sum": float(s.sum()).hex(),
                  "registries": "numba.np.polynomial.polynomial_core" in sys.modules,
                  "hits": sum(kern.energy.stats.cache_hits.values()) + sum(kern.scaled.stats.cache_hits.values())}))
'''


def test_cached_kernels_load_without_registries_and_run_the_same_code(tmp_path):
    """A kernel compiled and cached by one process, then loaded by others with and without the hook: the
    same results to the bit (a runtime-allocated array, a parallel loop), a cache hit, and with the hook
    numba's registries (``numba.np.polynomial``, imported only by them) never loaded; a cache miss under the hook compiles as usual."""
    import json
    import os
    (tmp_path / "kern.py").write_text(_KERNEL)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]),
           "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run(mode):
        r = subprocess.run([sys.executable, "-c", _USE, mode], env=env, capture_output=True, text=True, check=True)
        return json.loads(r.stdout)

    first = run("lazy")      # a cache miss under the hook: compiled (the compiler refreshes the registries)
    plain, lazy = run("plain"), run("lazy")
    assert first["lazy"] and lazy["lazy"] and not plain["lazy"]
    assert first["registries"] and plain["registries"] and not lazy["registries"]
    assert (first["hits"], plain["hits"], lazy["hits"]) == (0, 2, 2)
    for k in ("e", "s", "s_sum"):
        assert first[k] == plain[k] == lazy[k]
    i = np.linspace(0.0, 2.0, 1001)
    assert abs(float.fromhex(lazy["e"]) - float(np.sum(i * i) * 0.5e-3)) < 1e-12   # Joule heating sum


def test_frontier_rows_made_before_waiting_for_the_mpc_child(monkeypatch):
    """``compare(on_extra=...)`` hands over the frontier's traces before the forked MPC child's result is
    awaited, and the frontier's rows made from them then are the rows made from all traces afterwards (the
    budgets' curve: more budget, more overshoot and less energy after the stop)."""
    import policies.forked as forked
    from policies.compare import compare, frontier, frontier_specs

    events, early, more = [], [], {}
    result = forked.Forked.result

    def spy(self):
        events.append("child's result")
        return result(self)

    monkeypatch.setattr(forked.Forked, "result", spy)

    def on_extra(tr):
        events.append("frontier")
        early.append(frontier("nominal", budgets=(0.0, 0.02, 0.1), episodes=3, seed=1000, traces=tr))

    fork = forked.available()   # before compare (whose env steps may start numba's thread pool)
    rows, traces = compare(("model_based", "mpc"), ("nominal",), 3, 1000, extra=frontier_specs((0.0, 0.02, 0.1)),
                           extra_traces=more, on_extra=on_extra)
    later = frontier("nominal", budgets=(0.0, 0.02, 0.1), episodes=3, seed=1000, traces={**more, **traces})
    assert events[0] == "frontier" and events.count("frontier") == 1
    if fork:
        assert events == ["frontier", "child's result"]
    assert early[0] == later
    over = [r["overshoot_pct"] for r in later]
    after = [r["energy_after_stop_j"] for r in later]
    assert over == sorted(over) and after == sorted(after, reverse=True)


_NO_LEARNED = """
import sys
from policies import make
from policies.batched import BlockPolicy, stackable
pol = make("mpc")
BlockPolicy([pol, make("step")], 2)
print(stackable(pol) is None, "policies.rl" in sys.modules, "policies.residual" in sys.modules)
"""


def test_block_policy_of_an_mpc_imports_no_learned_policy_module():
    """The forked MPC child's BlockPolicy (a policy not of the learned kinds): ``stackable`` answers without
    importing ``policies.rl`` / ``policies.residual`` (~0.05 s of CPU on compare's critical path)."""
    out = subprocess.run([sys.executable, "-c", _NO_LEARNED], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "False", "False"]


def test_stackable_still_groups_learned_and_model_based_policies():
    """With their modules imported (a learned policy made), RL actors of the same layers share a key, a residual
    policy gets its own kind, the model-based family one key, anything else none."""
    from policies import make
    from policies.batched import stackable
    from policies.compare import shipped_seed_groups

    groups = shipped_seed_groups()
    if "ppo_lagrangian" not in groups or "residual" not in groups:
        pytest.skip("the shipped learned policies are not installed")
    rl = [make(spec) for spec in groups["ppo_lagrangian"][:2]]
    res = make(groups["residual"][0])
    assert stackable(rl[0]) is not None and stackable(rl[0]) == stackable(rl[1])
    assert stackable(res)[0] == "residual"
    assert stackable(make("model_based"))[0] == "model_based" == stackable(make("model_based_budget:0.02"))[0]
    assert stackable(make("step")) is None


def test_compare_pauses_the_collector_only_through_its_start_up(monkeypatch):
    """``dronewpt compare`` (``main``): the collector is off while the command starts, back on (and the start-up's
    objects frozen) when the runs start and after the command; the JSON output is that of a run with the
    collector on throughout (``gc.disable`` made a no-op), to the byte."""
    import contextlib
    import gc
    import io
    import json

    import policies.compare as pc
    from mission_sim.cli import main

    argv = ["compare", "--episodes", "3", "--scenarios", "nominal", "--policies", "model_based,step,mpc",
            "--no-plot", "--no-frontier", "--no-progress", "--format", "json"]
    seen = []
    runs = pc._compare_runs

    def spy(*a, **k):
        seen.append((gc.isenabled(), gc.get_freeze_count()))
        return runs(*a, **k)

    monkeypatch.setattr(pc, "_compare_runs", spy)
    gc.unfreeze()
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(argv) == 0
    assert gc.isenabled() and seen[0][0] and seen[0][1] > 0
    gc.unfreeze()
    monkeypatch.setattr(gc, "disable", lambda: None)
    monkeypatch.setattr(gc, "freeze", lambda: None)
    plain = io.StringIO()
    with contextlib.redirect_stdout(plain):
        assert main(argv) == 0
    gc.unfreeze()
    assert seen[1] == (True, 0)
    assert buf.getvalue() == plain.getvalue() and len(json.loads(buf.getvalue())["rows"]) == 3
