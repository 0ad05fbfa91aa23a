"""``dronewpt compare``'s start-up cuts change its cost, not its numbers (issue 22):

* the MPC's steady-state Kalman gain goes through the disk cache: the cached gain is the array scipy's
  ``solve_discrete_are`` gives (the same bits), and an MPC built on a warm cache does not import the
  ``scipy.linalg`` package (0.3-1 s of CPU in compare's forked MPC child).
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
from policies.mpc import MPCPolicy
MPCPolicy()
print("scipy.linalg" in sys.modules)
"""


def test_mpc_on_a_warm_cache_does_not_import_scipy_linalg(tmp_path):
    import os
    env = {**os.environ, "DRONEWPT_CACHE_DIR": str(tmp_path)}
    out = [subprocess.run([sys.executable, "-c", _NO_LINALG], env=env, capture_output=True, text=True, check=True)
           .stdout.strip() for _ in range(2)]
    assert out == ["True", "False"]   # the first run solves the equation (and stores it), the second loads it
