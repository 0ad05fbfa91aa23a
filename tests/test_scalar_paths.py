"""n = 1 fast paths (issue 14) give the results of the vectorised code they shortcut.

Bit-identity holds where both paths do the same IEEE operations in the same order (the
normalisation's affine maps, the quadratic root with one ``sqrt``): those are compared exactly.
Where they cannot (the filter's state update as a Python sum against numpy's matmul, whose
summation order depends on the BLAS build; ``math.asin`` against numpy's vectorised ``arcsin``,
whose SIMD kernels vary with the numpy release and the CPU) they are compared to ``RTOL`` (issue 25:
a fresh install's numpy 2.4.6 differed in the last bits)."""

import numpy as np
import pytest

from mission_sim.contract import (OBS_DIM, OBS_FIELDS, PolicyContext, denormalise_obs, denormalise_obs_field,
                                  normalise_obs, normalise_obs_row)
from policies.classical import ModelBasedPolicy, _link_constants, _target_v2, _target_v2_scalar
from wpt_receiver.sbar import duty_from_v2_clipped

#: relative tolerance where the two paths round differently: 1e-12 is ~5000 ulp, far below any
#: physical resolution (a duty of 1e-12 is 1e-17 s of an 85 kHz period) and far above round-off
RTOL = 1e-12

_LO = np.array([f.lo for f in OBS_FIELDS])
_HI = np.array([f.hi for f in OBS_FIELDS])


def _physical(rng, n):
    span = _HI - _LO
    return rng.uniform(_LO - 0.3 * span, _HI + 0.3 * span, (n, OBS_DIM))


def test_normalise_row_equals_vector_path_bitwise():
    rng = np.random.default_rng(0)
    x = _physical(rng, 500)
    vec = normalise_obs(x)                           # (500, 7): numpy path
    rows = np.vstack([normalise_obs(x[i:i + 1]) for i in range(len(x))])
    assert np.array_equal(vec, rows)
    assert np.array_equal(normalise_obs_row(x[3].tolist()), vec[3:4])
    assert vec.min() == -1.0 and vec.max() == 1.0    # out-of-range values clipped
    for i in range(OBS_DIM):
        assert np.array_equal(denormalise_obs(vec)[:, i], [denormalise_obs_field(vec[k:k + 1], i) for k in range(500)])


def test_target_v2_and_duty_scalar_bitwise():
    rng = np.random.default_rng(1)
    consts = _link_constants(PolicyContext())
    cmd, vl = rng.uniform(-2, 25, 300), rng.uniform(18, 38, 300)
    v2 = _target_v2(consts, cmd, vl)
    assert np.array_equal(v2, [_target_v2_scalar(consts, float(c), float(v)) for c, v in zip(cmd, vl)])
    w = v2 * 1.1 - 0.5                               # also outside [0, (4/pi) VL]: saturates
    np.testing.assert_allclose(duty_from_v2_clipped(w, vl), [duty_from_v2_clipped(float(a), float(b)) for a, b in zip(w, vl)],
                               rtol=RTOL, atol=1e-15)


def test_model_based_scalar_path_equals_batch_path():
    """One receiver through the float path vs the same receiver as row 0 of a batch of two."""
    rng = np.random.default_rng(2)
    fast, batch = ModelBasedPolicy(), ModelBasedPolicy()
    fast.reset(1)
    batch.reset(2)
    x = _physical(rng, 1)[0]
    x[5] = 8.0                                       # a charge command
    for k in range(200):
        x[1] = 30.0 + 2.0 * np.sin(k / 17)           # battery voltage moves
        x[5] = 8.0 if k < 120 else 0.0               # then a stop command
        obs = normalise_obs(x[None, :])
        d1 = fast.act(obs)
        d2 = batch.act(np.vstack([obs, obs]))
        assert d1.shape == (1,) and d1[0] == pytest.approx(d2[0], rel=RTOL, abs=1e-15)
    assert 0.0 <= d1[0] <= 1.0
