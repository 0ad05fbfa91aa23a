"""Compiled per-step functions of the classical policies (numba, ``cache=True``) for the mission's fast path.

Each has the signature of :data:`mission_sim.contract.POLICY_KERNEL_SIGNATURE`,
``d = fn(obs, params, state)`` (normalised observation in, duty out, ``state`` updated in place),
and does what the policy's ``act`` does for one receiver, in the same floating-point operations
(numpy's SIMD ``arcsin`` and BLAS dot products may round the last bit differently; the mission
tests bound the effect). The policies hand them out through their ``kernel()`` hook
(:mod:`policies.classical`), which imports this module (and numba) on first use.

``params`` layout (all three): ``[wlm_v1, det, r1, wlm_v1**2]`` (the assumed link's constants of
:func:`policies.classical.target_v2`), then per policy: ramp ``[4]`` the ramp length
``2 L1 / R1`` [s] and ``[5]`` the control period [s]; model_based ``[4]`` I2_sm [A], ``[5]`` Dd,
``[6]`` the filter order k, then Ad (k x k, row-major), Bd (k), Cd (k), x_ss (k).
``state``: ``[0]`` 1 once started, then ramp ``[1]`` V2* [V]; model_based ``[1:1+k]`` the filter state.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

import mission_sim.contract as _contract
from mission_sim.contract import _LO_HALF, OBS_INDEX, POLICY_KERNEL_SIGNATURE
from wpt_receiver.kernel_cache import drop_stale_cache

__all__ = ["step_kernel", "ramp_kernel", "model_based_kernel", "KERNELS"]


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


# numba's cache of this module holds the contract's constants (the observation's slots and scales): dropped when
# mission_sim/contract.py changes (numba keys the cache on this file alone; the ahead-of-time mission module keys on both)
drop_stale_cache(_here, [_contract])

_I_CMD, _I_VL = OBS_INDEX["charge_cmd_a"], OBS_INDEX["battery_v"]
_CMD_LO, _CMD_HALF = _LO_HALF[_I_CMD]
_VL_LO, _VL_HALF = _LO_HALF[_I_VL]
_FOUR_OVER_PI = 4.0 / np.pi
_TWO_OVER_PI = 2.0 / np.pi


@njit(cache=True)
def _measure(obs):
    """Charge command [A] and battery voltage [V] from the normalised observation (``denormalise_obs_field``)."""
    return _CMD_LO + (obs[_I_CMD] + 1.0) * _CMD_HALF, _VL_LO + (obs[_I_VL] + 1.0) * _VL_HALF


@njit(cache=True)
def _target_v2(params, cmd, vl):
    """``classical._target_v2_scalar``."""
    wlm_v1, det, r1 = params[0], params[1], params[2]
    disc = max(params[3] - 8.0 * r1 * vl * max(cmd, 0.0) * det, 0.0)
    v2 = (wlm_v1 - math.sqrt(disc)) / (2.0 * r1)
    return min(max(v2, 0.0), _FOUR_OVER_PI * vl)


@njit(cache=True, error_model="numpy")
def _duty(v2, vl):
    """``wpt_receiver.sbar.duty_from_v2_clipped``: its result at every input, VL = 0, negative, NaN and infinite ones
    included (numpy's error model: IEEE division, v2 / 0 is +-inf or NaN as in the Python function's numpy path;
    numba's default raised ZeroDivisionError at VL = 0), within the last bit of numpy's own ``arcsin`` elsewhere
    (this ``asin`` is the C library's, as ``math.asin``; ``tests/test_loose_ends_evening.py``)."""
    s = min(max(1.0 - v2 / (_FOUR_OVER_PI * vl), 0.0), 1.0)
    return _TWO_OVER_PI * math.asin(s)


@njit(POLICY_KERNEL_SIGNATURE, cache=True)
def step_kernel(obs, params, state):
    """:class:`policies.classical.StepPolicy`."""
    cmd, vl = _measure(obs)
    return _duty(_target_v2(params, cmd, vl), vl)


@njit(POLICY_KERNEL_SIGNATURE, cache=True)
def ramp_kernel(obs, params, state):
    """:class:`policies.classical.RampPolicy`."""
    cmd, vl = _measure(obs)
    tgt = _target_v2(params, cmd, vl)
    if state[0] == 0.0:
        state[0], state[1] = 1.0, tgt
    rate = _FOUR_OVER_PI * vl / params[4] * params[5]
    state[1] = state[1] + min(max(tgt - state[1], -rate), rate)
    return _duty(state[1], vl)


@njit(POLICY_KERNEL_SIGNATURE, cache=True)
def model_based_kernel(obs, params, state):
    """:class:`policies.classical.ModelBasedPolicy` (``InverseModelController.reset`` on the first call, then
    ``update1``)."""
    cmd, vl = _measure(obs)
    wlm_v1, det, r1 = params[0], params[1], params[2]
    u = (wlm_v1 - r1 * _target_v2(params, cmd, vl)) / det - params[4]
    k = int(params[6])
    ad, bd, cd, xss = params[7:7 + k * k], params[7 + k * k:7 + k * k + k], params[7 + k * k + k:7 + k * k + 2 * k], \
        params[7 + k * k + 2 * k:7 + k * k + 3 * k]
    x = state[1:1 + k]
    if state[0] == 0.0:
        state[0] = 1.0
        for i in range(k):
            x[i] = u * xss[i]
    v2 = 0.0
    for i in range(k):
        v2 += x[i] * cd[i]
    v2 = v2 + params[5] * u
    xn = np.empty(k)
    for i in range(k):
        acc = 0.0
        for j in range(k):
            acc += x[j] * ad[i * k + j]
        xn[i] = acc + u * bd[i]
    x[:] = xn
    return _duty(v2, vl)


#: the kernel of each classical policy by its ``name``
KERNELS = {"step": step_kernel, "ramp": ramp_kernel, "model_based": model_based_kernel}
