"""The env step, once, compiled with numba (``cache=True``): every formula of a step of
:class:`envs.vector.SbarChargingVectorEnv` and :class:`envs.charging.SbarChargingEnv` is one
function here (the link, its rectifier-period sub-steps, the detuned tank's complex envelope, the
instantaneous peak, the battery, the reward, the objective, the observation, the info values);
the envs keep the orchestration (reset, seeding, plans, info dicts, rendering) and call it.

* :func:`env_step` steps sub-environments ``[0, n)`` of the vector env, in chunks that run in parallel
  (``prange``) when ``n_chunks > 1``; each sub-environment's arithmetic does not depend on the chunk
  it is in, so the parallel step is the serial one to the bit (``tests/test_vector_parallel.py``).
  A chunk runs three passes over its sub-environments: (1) the link step (:func:`_link_step_s`, or
  :func:`_complex_step` for a detuned window), noting the steps where the I2 envelope changes sign;
  (2) those steps re-done in rectifier-period sub-steps, the sub-step loop outside and the
  sub-environments inside (independent iterations the CPU overlaps); (3) the instantaneous peak,
  battery, reward, objective, state, observation and info (:func:`_finish_pass`). Passes (1) and (3)
  first take the block's sines / instantaneous peaks in a short loop of their own (the same arithmetic:
  the long per-window chains split so that the CPU overlaps windows; ~5-10 % of the step's CPU).
* :func:`step_kernel` is :func:`env_step` serial and without detuned windows (the signature
  :mod:`envs.rollout` replays).
* :func:`single_step` is the single env's per-env entry: the same helpers on one window (a call
  with 8 arguments: the single env is stepped from Python one step at a time); what follows its link
  (battery, reward, objective, observation, info) is :func:`single_finish`, which the exact-mode link's
  single step (:mod:`envs.modal_step`) calls too.

The slots of every array are named (:mod:`envs.layout`). Tests run the same source uncompiled
through each function's ``.py_func`` (``tests/test_env_kernel.py``: a change to one constant here
changes the single and the vector env alike). The link step is one function (:func:`_link_step`,
sub-steps :func:`_substep`) and its coefficients are made in one place
(:func:`envs.core._zoh_coefficients`), so another link model is a local swap.

Imported only when an env is built (numba is not imported by ``import envs``).
"""

from __future__ import annotations

import math
import os

import numpy as np
from numba import njit, prange

from .duty_sine import sin_cos_half_pi
from .layout import BAT, COEF, INFO, PAR, SINGLE, SINGLE_PAR, SLOW, STATE, XC

from wpt_receiver.kernel_cache import drop_stale_cache

from .objective import SHORT_MODE_IL_A, SHORT_MODE_WITHIN_S

__all__ = ["env_step", "step_kernel", "duty_kernel", "single_step", "single_finish", "inst_peak_rows", "obs_rows", "INFO_ROWS",
           "kernel_function", "compiled_or_python"]


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


# numba's cache of this module holds the layout's / objective's constants:
# dropped when those files change (numba keys the cache on this file alone)
drop_stale_cache(_here, [os.path.join(os.path.dirname(__file__), f) for f in ("layout.py", "objective.py", "duty_sine.py")])

#: rows of the info block the kernel fills, in order
INFO_ROWS = INFO._fields
_FOUR_OVER_PI = 4.0 / np.pi
_TWO_OVER_PI = 2.0 / np.pi
#: ``(sin(pi d/2), cos(pi d/2))`` of a duty: :func:`envs.duty_sine.sin_cos_half_pi` compiled (inlined: no libm call)
_sin_cos = njit(cache=True, inline="always")(sin_cos_half_pi)
_SM_LATE_S = SHORT_MODE_WITHIN_S - 1e-12
#: sub-environments per block of a chunk (the three passes' scratch: 24 doubles each, in L2). Each pass call takes and
#: drops a reference to every array argument (atomic operations on counts both threads share): 512 instead of 128
#: windows per block took 4.7-7.0 % off the kernel's one-thread CPU at N = 4,096 (medians, load 2.5-3.7; 2,048: no
#: further gain)
_BLOCK = 512
#: columns of the ZOH coefficients used by the sub-steps, in the order of :func:`_substep`'s arguments
_SUB_COLS = np.array([COEF.h00, COEF.h01, COEF.f0, COEF.g01, COEF.h10, COEF.h11, COEF.f1, COEF.g11], dtype=np.int64)
#: the passes' loop indices are unsigned: numba adds a negative-index fix-up (``i < 0 ? i + size : i``) to every
#: array access with a signed index and none with an unsigned one (~5 % of the kernel's CPU at N = 4,096)
_U = np.uint64


def compiled_or_python(f, compiled: bool = True):
    """``f`` (a numba dispatcher or a plain function) as given, or with ``compiled=False`` the same source run by the
    interpreter (its ``py_func``; a plain function is itself): the one pick both modules' :func:`kernel_function` make
    (:func:`envs.modal_step.kernel_function` held its own copy)."""
    return f if compiled else getattr(f, "py_func", f)


def kernel_function(name: str, compiled: bool = True):
    """The function ``name`` of this module: compiled, or with ``compiled=False`` the same source run
    by the interpreter (its ``py_func``; looked up in the module at each call, so a test may swap the
    module's functions and constants): :func:`compiled_or_python`."""
    return compiled_or_python(globals()[name], compiled)


@njit(cache=True)
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True)
def _clip1(x):
    return -1.0 if x < -1.0 else (1.0 if x > 1.0 else x)


@njit(cache=True)
def duty_kernel(a, d):
    """``d = clip((a + 1) / 2, 0, 1)`` (:func:`mission_sim.contract.action_to_duty` in float64) for
    actions ``a`` (n,) of any float type; returns the index of the first non-finite action (``d``
    then unusable) or -1. (The check is or-ed over the loop, without an early exit, so that LLVM vectorises
    it: ~1.3 instead of ~8-16 us at n = 4,096; the index is looked for only when one is bad.)"""
    bad = False
    for e in range(a.shape[0]):
        x = np.float64(a[e])
        bad |= not abs(x) < np.inf   # NaN or +-inf
        x = (x + 1.0) * 0.5
        d[e] = 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)
    if bad:
        for e in range(a.shape[0]):
            if not np.isfinite(np.float64(a[e])):
                return e
    return -1


@njit(cache=True)
def _sbar(vc, d, dr):
    """The SBAR's V2 terms (eq. 9, :func:`wpt_receiver.sbar.rectifier_v2_folded`): the clamp's
    magnitude ``(4/pi) VC (1 - sin(pi/2 d))`` [V] for the clamp voltage ``VC = VL + Vf`` and the short
    window's excess resistance ``dR w(d)`` [ohm], ``w(d) = d + sin(pi d)/pi`` (``sin(pi d) = 2 s
    cos(pi d/2)``, d in [0, 1]; both by :func:`envs.duty_sine.sin_cos_half_pi`); ``V2 = mag sign(I2) + rx I2``."""
    s, c = _sin_cos(d)
    return _sbar_s(vc, s, c, d, dr)


@njit(cache=True, inline="always")
def _sbar_s(vc, s, c, d, dr):
    """:func:`_sbar` with ``s = sin(pi/2 d)``, ``c = cos(pi/2 d)`` given (the vector step takes them for a block in
    a loop of its own, which the CPU overlaps across windows)."""
    return _FOUR_OVER_PI * vc * (1.0 - s), dr * (d + _TWO_OVER_PI * s * c)


@njit(cache=True)
def _link_step(i1, i2, vl, d, c, r, vf, dr):
    """:func:`_link_step_s` with the duty's sine and cosine taken here (the single env's step)."""
    s, co = _sin_cos(d)
    return _link_step_s(i1, i2, vl, d, s, co, c, r, vf, dr)


@njit(cache=True, inline="always")
def _link_step_s(i1, i2, vl, d, s, co, c, r, vf, dr):
    """One control period of the envelope link (paper eq. 4, exact ZOH coefficients ``c``, :data:`COEF`)
    with duty ``d`` held (``s = sin(pi/2 d)``, ``co = cos(pi/2 d)``), the coefficients ``c[r]`` (row ``r`` of a table: no row view),
    the devices ``vf`` [V], ``dr`` [ohm]: ``(i1n, i2n, pk, il, v2, split, |V2c|, rx)``. ``pk`` the largest |I2|
    at mid-step and at the end, ``il`` the SBAR output current (the clamp's ``V2c I2 / (2 VC)``, Simpson's
    rule on I2), ``v2`` the V2 applied; ``split``: the I2 envelope changes sign within the step, or the step
    started blocked (I2 = 0) and the rectifier released (either re-done in rectifier-period sub-steps,
    :func:`_substep`, with the clamp's |V2c| and the short-window excess ``rx I2``)."""
    vc = vl + vf
    mag, rx = _sbar_s(vc, s, co, d, dr)
    sg = _sign(i2)
    if sg == 0.0:   # the rectifier blocked at the last step's end (I2 = 0): blocked through this step while the emf
        # w Lm I1 stays within the clamp (I1 monotone over the step: its ends decide); else released (split below: the
        # sub-steps take the release and the short window's excess rx I2 as I2 grows from 0)
        i1b = c[r, COEF.ka] * i1 + c[r, COEF.ke]
        v2h = c[r, COEF.wlm] * i1
        if abs(v2h) <= mag and abs(c[r, COEF.wlm] * i1b) <= mag:
            return i1b, 0.0, 0.0, 0.0, v2h, False, mag, rx
    v2c = mag * sg
    v2 = v2c + rx * i2
    i2m = c[r, COEF.m10] * i1 + c[r, COEF.m11] * i2 + c[r, COEF.me1] + c[r, COEF.mb11] * v2
    i1n = c[r, COEF.a00] * i1 + c[r, COEF.a01] * i2 + c[r, COEF.e0] + c[r, COEF.b01] * v2
    i2n = c[r, COEF.a10] * i1 + c[r, COEF.a11] * i2 + c[r, COEF.e1] + c[r, COEF.b11] * v2
    il = v2c * (i2 + 4.0 * i2m + i2n) / (12.0 * vc)
    pk = max(abs(i2m), abs(i2n))
    return i1n, i2n, pk, il, v2, (i2m * v2c < 0.0 or i2n * v2c < 0.0 or sg == 0.0), mag, rx


@njit(cache=True, error_model="numpy", inline="always")
def _substep(i1, a, vm, rx, pk, tot, h00, h01, f0, g01, h10, h11, f1, g11, ig):
    """One rectifier-period sub-step, the clamp taken implicitly: V2 = |V2c| sign(I2 at the sub-step's end) + rx I2
    (rx I2 at its start), and where neither sign is consistent (|the end I2 with the clamp's part of V2 at 0| <=
    |g11| |V2c|) the rectifier blocks: I2 = 0 at the end, V2's clamp part the one that holds it there (within the
    clamp; the diode rectifier's set-valued V2 at I2 = 0, as :func:`_clamp_implicit` for a detuned tank); ``ig`` =
    -1 / g11 (g11 < 0: V2 opposes I2; with g11 >= 0 the soft threshold would pump energy). g11 < 0 holds
    because the sub-step ``h`` is at most one rectifier period, ``h <= pi/w``: eq. 4's tanks exchange energy at
    ``w_n = k w / 2`` (``k = Lm / sqrt(L1 L2) < 1``), so ``w_n h < pi/2``, and g11 = -sin(w_n h) / (2 L2 w_n)
    (the lossless tank; the resistances damp it) is < 0 for ``w_n h < pi``; :func:`envs.core._zoh_coefficients`
    raises if a table has g11 >= 0 (a patched, too small n_sub). Without a branch: the end I2 is the soft threshold of the one with the clamp's
    part of V2 at 0, and that part its clip to the clamp. Returns
    ``(i1, i2, peak |I2|, sum of |I2| means)`` after it (mean |I2| on the linear sub-step from a to b: (|a| + |b|)/2,
    or (a^2 + b^2) / (2 (|a| + |b|)) when it crosses zero)."""
    xr = rx * a
    b0 = h10 * i1 + h11 * a + f1 + g11 * xr
    b = math.copysign(max(abs(b0) + g11 * vm, 0.0), b0)   # 0 when blocked
    v2 = min(max(b0 * ig, -vm), vm)
    i1 = h00 * i1 + h01 * a + f0 + g01 * (v2 + xr)
    mb = abs(b)
    if mb > pk:
        pk = mb
    if a * b >= 0.0:
        tot += 0.5 * abs(a + b)
    else:
        tot += 0.5 * (a * a + b * b) / (abs(a) + abs(b))
    return i1, b, pk, tot


@njit(cache=True, error_model="numpy")
def _substeps_one(i1, i2, vm, rx, vc, c, r, n_sub):
    """One split step re-done in ``n_sub`` sub-steps (``vc`` the clamp voltage VL + Vf): ``(i1, i2,
    peak |I2|, mean I_L)``, the numbers of :func:`_substep_pass` for one sub-environment."""
    pk, tot = -1.0, 0.0
    ig = -1.0 / c[r, COEF.g11]
    for _ in range(n_sub):
        i1, i2, pk, tot = _substep(i1, i2, vm, rx, pk, tot, c[r, COEF.h00], c[r, COEF.h01], c[r, COEF.f0],
                                   c[r, COEF.g01], c[r, COEF.h10], c[r, COEF.h11], c[r, COEF.f1], c[r, COEF.g11], ig)
    return i1, i2, pk, vm * tot / (2.0 * n_sub * vc)


@njit(cache=True, error_model="numpy")
def _clamp_implicit(m2r, m2i, hr, hi, v2c, rx):
    """The SBAR's V2 over a rectifier-period sub-step taken implicitly (V2 in phase with the sub-step's
    *end* J2, the describing function's set-valued clamp at J2 = 0): ``m2 = m2r + j m2i`` [A] the end J2
    with V2 = 0, ``h = hr + j hi`` [A/V] the end J2 per volt of the input ``U = -V2``, ``v2c`` [V] the
    clamp's magnitude (:func:`_sbar`), ``rx`` [ohm] the short window's excess. The end J2 = rho
    e^(j theta) solves ``|(1 + h rx) rho + h v2c| = |m2|``; when ``|h v2c| >= |m2|`` the rectifier blocks
    (the diodes see less than the clamp: J2 = 0 at the end, ``U = -m2 / h`` with ``|U| <= v2c``).
    Returns the input ``(Re U, Im U)`` [V]."""
    br, bi = hr * v2c, hi * v2c
    mm = m2r * m2r + m2i * m2i
    if br * br + bi * bi >= mm:   # blocking: the V2 that holds J2 at 0 is within the clamp
        hh = hr * hr + hi * hi
        return -(m2r * hr + m2i * hi) / hh, -(m2i * hr - m2r * hi) / hh
    ar, ai = 1.0 + hr * rx, hi * rx
    aa = ar * ar + ai * ai
    p = ar * br + ai * bi   # Re(A conj B)
    rho = (-p + math.sqrt(p * p - aa * (br * br + bi * bi - mm))) / aa
    # e^(j theta) = m2 / (A rho + B)
    dr_, di_ = ar * rho + br, ai * rho + bi
    dd = dr_ * dr_ + di_ * di_
    er, ei = (m2r * dr_ + m2i * di_) / dd, (m2i * dr_ - m2r * di_) / dd
    v2 = v2c + rx * rho
    return -v2 * er, -v2 * ei


@njit(cache=True, error_model="numpy")
def _complex_step(x, vl, d, cc, vf, dr, v1, n_sub):
    """One control period of a detuned tank (:mod:`envs.detuned`): ``x`` (:data:`XC`) the complex
    envelope ``[Re J1, Re J2, Im J1, Im J2]`` [A], updated in place over ``n_sub`` rectifier-period
    sub-steps with ``cc`` = Ad (16), Bd (16) of one sub-step; the SBAR's V2 in phase with J2,
    re-evaluated every sub-step (``V2 = |V2c| + rx |J2|``, :func:`_sbar`). Where the clamp alone could
    turn J2 within a sub-step (|J2| <= |h| |V2c|, ``h`` the end J2 per volt of V2) or the explicit V2
    would reverse J2, the sub-step is taken implicitly (:func:`_clamp_implicit`): the diode rectifier
    blocks (J2 held at 0) while the V2 that would hold it there is within the clamp, as the switching
    model does when the induced emf stays below the clamp (a strongly detuned C1), instead of an
    explicit sign that chatters about J2 = 0. Returns ``(|J1|, |J2|, peak |J2| over the sub-step ends,
    I_L (mean |J2|), |V2| at the start)``."""
    vc = vl + vf
    v2c, rx = _sbar(vc, d, dr)
    x0, x1, x2, x3 = x[XC.re_j1], x[XC.re_j2], x[XC.im_j1], x[XC.im_j2]
    r = math.hypot(x1, x3)
    v2_0 = v2c + rx * r
    hr, hi = cc[21], cc[29]   # end J2 per volt of U (the complex structure of Bd: cc[31] = hr, cc[23] = -hi)
    h_clamp = math.hypot(hr, hi) * v2c
    pk, tot = -1.0, 0.0
    for _ in range(n_sub):
        pr, pi_ = (x1 / r, x3 / r) if r > 0.0 else (0.0, 1.0)
        v2 = v2c + rx * r
        u1, u3 = -v2 * pr, -v2 * pi_   # inputs [V1, -V2 e^(j phase(J2))] as real parts, imaginary parts
        f1 = cc[4] * x0 + cc[5] * x1 + cc[6] * x2 + cc[7] * x3 + cc[20] * v1
        f3 = cc[12] * x0 + cc[13] * x1 + cc[14] * x2 + cc[15] * x3 + cc[28] * v1
        n1 = f1 + cc[21] * u1 + cc[23] * u3
        n3 = f3 + cc[29] * u1 + cc[31] * u3
        if r <= h_clamp or n1 * x1 + n3 * x3 <= 0.0:
            u1, u3 = _clamp_implicit(f1, f3, hr, hi, v2c, rx)
            n1 = f1 + cc[21] * u1 + cc[23] * u3
            n3 = f3 + cc[29] * u1 + cc[31] * u3
        n0 = cc[0] * x0 + cc[1] * x1 + cc[2] * x2 + cc[3] * x3 + cc[16] * v1 + cc[17] * u1 + cc[19] * u3
        n2 = cc[8] * x0 + cc[9] * x1 + cc[10] * x2 + cc[11] * x3 + cc[24] * v1 + cc[25] * u1 + cc[27] * u3
        x0, x1, x2, x3 = n0, n1, n2, n3
        rn = math.hypot(x1, x3)
        pk = max(pk, rn)
        tot += 0.5 * (r + rn)
        r = rn
    x[XC.re_j1], x[XC.re_j2], x[XC.im_j1], x[XC.im_j2] = x0, x1, x2, x3
    return math.hypot(x0, x2), r, pk, v2c * tot / (2.0 * n_sub * vc), v2_0


@njit(cache=True)
def _inst_peak(pk, d, vl, tab, vlc, inv_imax):
    """Instantaneous peak [A] (:mod:`envs.peaks`) for the envelope peak ``pk``, duty ``d``, battery
    voltage ``vl``: bilinear in (duty, sqrt(pk / I2_MAX_A)) on the (n_d, n_i, 2) table of
    :func:`envs.peaks.fold_vl`, then ``pk + A + B (VL - vlc)``; 0 for ``pk`` = 0 (the rectifier blocked the whole
    step: no current, where the table's row at pk = 0 would give its 0.25-1.0 A ripple excess)."""
    if pk == 0.0:
        return 0.0
    nd, ni = tab.shape[0], tab.shape[1]
    x = d * (nd - 1)
    y = math.sqrt(min(pk * inv_imax, 1.0)) * (ni - 1)
    j = min(int(x), nd - 2)
    k = min(int(y), ni - 2)
    fx, fy = x - j, y - k
    ea = ((tab[j, k, 0] * (1.0 - fx) + tab[j + 1, k, 0] * fx) * (1.0 - fy)
          + (tab[j, k + 1, 0] * (1.0 - fx) + tab[j + 1, k + 1, 0] * fx) * fy)
    eb = ((tab[j, k, 1] * (1.0 - fx) + tab[j + 1, k, 1] * fx) * (1.0 - fy)
          + (tab[j, k + 1, 1] * (1.0 - fx) + tab[j + 1, k + 1, 1] * fx) * fy)
    return pk + (ea + eb * (vl - vlc))


@njit(cache=True)
def inst_peak_rows(pk, d, vl, tab, vlc, inv_imax, out):
    """:func:`_inst_peak` of every element of the arrays ``pk``, ``d``, ``vl`` into ``out``."""
    for e in range(pk.shape[0]):
        out[e] = _inst_peak(pk[e], d[e], vl[e], tab, vlc, inv_imax)


@njit(cache=True)
def _battery(il, soc, vrc, vl, b):
    """The battery after a step delivering ``il`` [A] (equivalent circuit around the window's operating
    point, ``b`` the battery row, :data:`BAT`): ``(i_batt, soc, v_rc, VL)``; the DC bus follows ``OCV +
    R0 i_batt + v_rc`` with the time constant R0 C_bus."""
    ib = il - b[BAT.i_load]
    soc = soc + b[BAT.dsoc] * ib
    vrc = b[BAT.rc_decay] * vrc + b[BAT.rc_gain] * ib
    target = b[BAT.ocv0] + b[BAT.docv] * (soc - b[BAT.soc0]) + b[BAT.r0] * ib + vrc
    vl = b[BAT.bus_decay] * vl + (1.0 - b[BAT.bus_decay]) * target
    return ib, soc, vrc, vl


@njit(cache=True)
def _reward(il, cmd, pk, inv_rated, w_track, w_over, i_ref):
    """``(reward, overcurrent)``: reward = (min(I_L, I*) - w_track |I_L - I*|) / i_ref - w_over
    overcurrent, overcurrent = max(0, |I2_pk| / I2_rated - 1) (:class:`envs.core.RewardWeights`)."""
    over = abs(pk) * inv_rated - 1.0
    over = 0.0 if 0.0 > over else over   # max(x, 0.0)
    mn = cmd if cmd < il else il         # min(il, cmd)
    return (mn - w_track * abs(il - cmd)) / i_ref - w_over * over, over


@njit(cache=True)
def _objective(kk, pk, il, i2_sm, dt, run_max, stop_k, ok, checked):
    """:mod:`envs.objective` after step ``kk`` (``i2_sm`` the short-mode I2 of its slow segment):
    ``(running overshoot, ok, checked, step cost)``, the cost the rise of max(0, running overshoot)."""
    new = run_max
    if kk >= stop_k:
        ratio = abs(pk) / i2_sm - 1.0
        new = ratio if ratio > run_max else run_max
    if (kk + 1 - stop_k) * dt >= _SM_LATE_S:
        checked = True
        if il >= SHORT_MODE_IL_A:
            ok = False
    return new, ok, checked, (new if new > 0.0 else 0.0) - (run_max if run_max > 0.0 else 0.0)


@njit(cache=True)
def _t_since(kk, dt, t_stop, stop_k):
    """Observation field ``t_since_stop_s`` before step ``kk``."""
    t = kk * dt - t_stop
    return (t if t > 0.0 else 0.0) if kk >= stop_k else 0.0


@njit(cache=True)
def _put_obs(o, e, i2m, vl, ib, il, soc, cmd, d, t_since, scale, offset):
    """Observation row ``o[e]`` (:data:`mission_sim.contract.OBS_FIELDS`): the fields mapped to [-1, 1]
    and clipped, as float32."""
    vals = (i2m, vl, ib, il, soc, cmd, d, t_since)
    for f in range(8):
        o[e, f] = np.float32(_clip1(vals[f] * scale[f] + offset[f]))


@njit(cache=True)
def obs_rows(vals, scale, offset, obs):
    """Observation rows ``obs`` (n, 8) float32 from the physical fields ``vals`` (8, n) (:func:`_put_obs`;
    the envs' first observation after a reset)."""
    for e in range(obs.shape[0]):
        _put_obs(obs, e, vals[0, e], vals[1, e], vals[2, e], vals[3, e], vals[4, e], vals[5, e], vals[6, e],
                 vals[7, e], scale, offset)


@njit(cache=True)
def _put_info(row, e, t, i2, pk, i1, d, v2, il, vl, ib, soc, cmd, lm, energy, over, cost, rm, pk_env):
    """Sub-environment ``e``'s info values, ``row[e]`` (:data:`INFO`)."""
    row[e, INFO.t_s], row[e, INFO.i2_a], row[e, INFO.i2_peak_a], row[e, INFO.i1_a] = t, i2, pk, i1
    row[e, INFO.d_short], row[e, INFO.v2_v], row[e, INFO.rect_current_a], row[e, INFO.battery_v] = d, v2, il, vl
    row[e, INFO.battery_current_a], row[e, INFO.soc], row[e, INFO.charge_cmd_a], row[e, INFO.lm_h] = ib, soc, cmd, lm
    row[e, INFO.energy_j], row[e, INFO.overcurrent], row[e, INFO.cost] = energy, over, cost
    row[e, INFO.overshoot] = rm
    row[e, INFO.episode_cost] = rm if rm > 0.0 else 0.0
    row[e, INFO.i2_peak_envelope_a] = pk_env


@njit(cache=True)
def _link_pass(lo, hi, d, state, k, j, coef_tab, coef_ix, slow_every, n_sub, vf, dr, cx, sc, idx):
    """Pass 1 on sub-environments ``[lo, hi)``: the link step of each into ``sc[:, e - lo]`` (rows i1n,
    i2n, pk, il, v2), ``j`` moved to the step's slow segment (coefficients ``coef_tab[coef_ix[j, e]]``,
    the table's row of the segment's Lm: windows sharing an Lm read one row); returns how many
    steps are split (their indices in ``idx[:m]``, their clamp |V2c| and excess rx in ``sc[5:7, :m]``).
    ``cx`` = (detuned (n,) bool, complex state (n, 4), coefficients (n, S, 32), V1 [V]): a detuned
    window steps its complex envelope (:func:`_complex_step`, never split)."""
    detuned, xc, ccoef, v1 = cx
    has_cx = detuned.shape[0] > 0
    m = 0
    ulo = _U(lo)
    for e in range(ulo, _U(hi)):   # the duty's sines and cosines first: a short loop, overlapped across windows
        sc[7, e - ulo], sc[8, e - ulo] = _sin_cos(d[e])
    for e in range(ulo, _U(hi)):
        q = e - ulo
        kk = k[e]
        jj = kk // slow_every
        j[e] = jj
        if has_cx and detuned[e]:
            sc[0, q], sc[1, q], sc[2, q], sc[3, q], sc[4, q] = _complex_step(xc[e], state[STATE.vl, e], d[e],
                                                                             ccoef[e, jj], vf, dr, v1, n_sub)
            continue
        i1n, i2n, pk, il, v2, split, vm, rx = _link_step_s(state[STATE.i1, e], state[STATE.i2, e], state[STATE.vl, e],
                                                           d[e], sc[7, q], sc[8, q], coef_tab, coef_ix[jj, e],
                                                           vf, dr)
        sc[0, q], sc[1, q], sc[2, q], sc[3, q], sc[4, q] = i1n, i2n, pk, il, v2
        # noted without a branch (about half the steps split, at random): the slot m is written
        # every time and kept when the step splits
        idx[m] = e
        sc[5, m], sc[6, m] = vm, rx
        m += split
    return m


@njit(cache=True, error_model="numpy")
def _substep_pass(lo, idx, m, state, j, coef_tab, coef_ix, n_sub, vf, sc, w, h):
    """Pass 2: the split steps ``idx[:m]`` re-done in ``n_sub`` sub-steps (:func:`_substep`), the sub-step
    loop outside; results into ``sc`` (the clamp's |V2c| and the excess rx those of pass 1: |V2c| does not depend
    on sign(I2), so pass 1's magnitude is the sub-steps' to the bit whether the split step starts at I2 != 0 or
    at I2 = 0, a release; no second sine). ``w``
    (6, >= m) i1, i2, |V2c|, peak |I2| (from -1), sum of |I2| means (from 0), rx and ``h`` (9, >= m)
    the sub-step coefficients: scratch."""
    for q in range(_U(m)):
        e = idx[q]
        w[0, q], w[1, q], w[3, q], w[4, q] = state[STATE.i1, e], state[STATE.i2, e], -1.0, 0.0
        w[2, q], w[5, q] = sc[5, q], sc[6, q]
        row = coef_ix[j[e], e]
        for r in range(8):
            h[r, q] = coef_tab[row, _SUB_COLS[r]]
        h[8, q] = -1.0 / h[7, q]
    for _ in range(n_sub):
        for q in range(_U(m)):
            w[0, q], w[1, q], w[3, q], w[4, q] = _substep(w[0, q], w[1, q], w[2, q], w[5, q], w[3, q], w[4, q],
                                                          h[0, q], h[1, q], h[2, q], h[3, q], h[4, q], h[5, q],
                                                          h[6, q], h[7, q], h[8, q])
    for q in range(m):
        e = idx[q]
        p = e - lo
        sc[0, p], sc[1, p], sc[2, p] = w[0, q], w[1, q], w[3, q]
        sc[3, p] = w[2, q] * w[4, q] / (2.0 * n_sub * (state[STATE.vl, e] + vf))


@njit(cache=True)
def _finish_pass(lo, hi, d, state, k, j, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, sc, ptab, obs,
                 reward, trunc, info):
    """Pass 3 on ``[lo, hi)``: instantaneous peak, battery, reward, objective, state, observation and
    info of each sub-environment. ``ep`` = (i2sm_all (S, n) step-major, stop_k, t_stop, run_max, sm_ok,
    sm_checked) of the episodes; ``par`` (:data:`PAR`) the env's constants; ``ptab`` the peak table."""
    i2sm_all, stop_k, t_stop, run_max, ok, checked = ep
    dt = par[PAR.dt]
    vlc, inv_imax = par[PAR.vlc], par[PAR.inv_imax]
    ulo = _U(lo)
    for e in range(ulo, _U(hi)):   # the peaks first (row 5 of the scratch is free here): a short loop the CPU overlaps
        sc[5, e - ulo] = _inst_peak(sc[2, e - ulo], d[e], state[STATE.vl, e], ptab, vlc, inv_imax)
    for e in range(ulo, _U(hi)):
        q = e - ulo
        kk, jj = k[e], j[e]
        vl_old = state[STATE.vl, e]
        i1, i2, pk_env, il, v2 = sc[0, q], sc[1, q], sc[2, q], sc[3, q], sc[4, q]
        pk = sc[5, q]
        ib, soc, vrc, vl = _battery(il, state[STATE.soc, e], state[STATE.vrc, e], vl_old, bat[:, e])
        cmd = cmd_all[kk, e]
        reward[e], over = _reward(il, cmd, pk, par[PAR.inv_rated], par[PAR.w_track], par[PAR.w_over],
                                  par[PAR.i_ref])
        rm, ok[e], checked[e], cost = _objective(kk, pk, il, i2sm_all[jj, e], dt, run_max[e], stop_k[e], ok[e],
                                                 checked[e])
        run_max[e] = rm
        state[STATE.i1, e], state[STATE.i2, e], state[STATE.vl, e] = i1, i2, vl
        state[STATE.soc, e], state[STATE.vrc, e], state[STATE.d, e] = soc, vrc, d[e]
        kk += 1
        k[e] = kk
        _put_obs(obs, e, i2 + noise_all[kk - 1, e], vl, ib, il, soc, cmd_all[kk, e], d[e],
                 _t_since(kk, dt, t_stop[e], stop_k[e]), scale, offset)
        trunc[e] = kk >= par[PAR.n_steps]
        _put_info(info, e, kk * dt, i2, pk, i1, d[e], v2, il, vl, ib, soc, cmd, lm_all[jj, e], vl_old * il * dt, over,
                  cost, rm, pk_env)


@njit(cache=True)
def _chunk(lo, hi, d, state, k, j, coef_tab, coef_ix, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
           scale, offset, ptab, obs, reward, trunc, info, cx):
    """The step of sub-environments ``[lo, hi)``: the three passes (module docstring) on blocks of
    :data:`_BLOCK` sub-environments (their scratch in cache, few pass calls)."""
    nb = min(_BLOCK, hi - lo)
    sc, idx = np.empty((9, nb)), np.empty(nb, dtype=np.int64)
    w, h = np.empty((6, nb)), np.empty((9, nb))
    vf, dr = par[PAR.vf], par[PAR.dr]
    for b0 in range(lo, hi, _BLOCK):
        b1 = min(b0 + _BLOCK, hi)
        m = _link_pass(b0, b1, d, state, k, j, coef_tab, coef_ix, slow_every, n_sub, vf, dr, cx, sc, idx)
        if m:
            _substep_pass(b0, idx, m, state, j, coef_tab, coef_ix, n_sub, vf, sc, w, h)
        _finish_pass(b0, b1, d, state, k, j, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, sc, ptab, obs,
                     reward, trunc, info)


@njit(cache=True, parallel=True)
def env_step(d, state, k, j, coef_tab, coef_ix, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par, scale,
             offset, ptab, obs, reward, trunc, info, cx, n_chunks):
    """Step every sub-environment with duty ``d`` (n,), in ``n_chunks`` contiguous chunks run in
    parallel (``n_chunks = 1``: one chunk on the calling thread, no thread pool). ``state`` (:data:`STATE`,
    (6, n)) and the step index ``k`` / slow index ``j`` are updated in place, and so are the
    objective's running values in ``ep`` (:func:`_finish_pass`); the ZOH coefficients of slow segment
    ``j`` of sub-environment ``e`` are ``coef_tab[coef_ix[j, e]]`` (``coef_tab`` (U, N_COEF) one row per
    distinct Lm, ``coef_ix`` (S, n) step-major);
    ``bat`` (:data:`BAT`, (9, n)); ``cmd_all`` (T + 1, n), ``noise_all`` (T, n), ``lm_all`` (S, n)
    step-major; ``cx`` the detuned windows (:func:`_link_pass`). ``obs`` (n, 8) float32, ``reward``,
    ``trunc`` and ``info`` (n, len(INFO)) are filled."""
    n = d.shape[0]
    if n_chunks <= 1:
        _chunk(0, n, d, state, k, j, coef_tab, coef_ix, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
               scale, offset, ptab, obs, reward, trunc, info, cx)
        return
    for c in prange(n_chunks):
        _chunk(c * n // n_chunks, (c + 1) * n // n_chunks, d, state, k, j, coef_tab, coef_ix, bat, cmd_all,
               noise_all, lm_all, ep, slow_every, n_sub, par, scale, offset, ptab, obs, reward, trunc, info, cx)


@njit(cache=True)
def step_kernel(d, state, k, j, coef_tab, coef_ix, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
                scale, offset, ptab, obs, reward, trunc, info):
    """:func:`env_step` on the calling thread, without detuned windows (:mod:`envs.rollout`'s replay)."""
    cx = (np.zeros(0, np.bool_), np.zeros((0, 4)), np.zeros((0, 0, 32)), 0.0)
    _chunk(0, d.shape[0], d, state, k, j, coef_tab, coef_ix, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub,
           par, scale, offset, ptab, obs, reward, trunc, info, cx)


@njit(cache=True)
def single_step(k, d, st, steps, slow, par, obs, out, cc):
    """Step ``k`` of one env with duty ``d``: the helpers of :func:`env_step` on one window.
    ``st`` (:data:`SINGLE`, then the complex state (4) of a detuned window) is updated in place;
    ``steps`` (T + 1, 2) = command, sensor noise per step; ``slow`` (S, :data:`SLOW`) = the ZOH
    coefficients, true Lm, short-mode I2 per slow segment; ``par`` = :data:`SINGLE_PAR`, OBS_SCALE,
    OBS_OFFSET, the peak table (flattened); ``cc`` (S, 32) the detuned window's coefficients (0 rows:
    tuned). Fills ``obs`` (8,) float32 and ``out`` (:data:`INFO`, then reached short mode 1.0 / 0.0);
    returns the reward."""
    P = SINGLE_PAR
    dt, n_sub, vf, dr = par[P.dt], int(par[P.n_sub]), par[P.vf], par[P.dr]
    j = k // int(par[P.slow_every])
    vl_old = st[SINGLE.vl]
    if cc.shape[0]:
        x = st[len(SINGLE):]
        i1, i2, pk, il, v2 = _complex_step(x, vl_old, d, cc[j], vf, dr, par[P.v1], n_sub)
    else:
        i1, i2, pk, il, v2, split, vm, rx = _link_step(st[SINGLE.i1], st[SINGLE.i2], vl_old, d, slow, j, vf, dr)
        if split:   # also at n_sub = 1 (dt_s <= one rectifier period): the one sub-step takes the clamp implicitly
            i1, i2, pk, il = _substeps_one(st[SINGLE.i1], st[SINGLE.i2], vm, rx, vl_old + vf, slow, j, n_sub)
    pk_env = pk
    ptab = par[len(P) + 16:].reshape((int(par[P.nd]), int(par[P.ni]), int(par[P.nq])))
    pk = _inst_peak(pk_env, d, vl_old, ptab, par[P.vlc], par[P.inv_imax])
    return single_finish(k, d, st, steps, i1, i2, pk, pk_env, il, v2, vl_old, slow[j, SLOW.i2_sm_a],
                         slow[j, SLOW.lm_h], dt,
                         par[P.inv_rated], par[P.w_track], par[P.w_over], par[P.i_ref], par[len(P):len(P) + 8],
                         par[len(P) + 8:len(P) + 16], obs, out)


@njit(cache=True)
def single_finish(k, d, st, steps, i1, i2, pk, pk_env, il, v2, vl_old, i2_sm, lm_h, dt, inv_rated, w_track, w_over,
                  i_ref, scale, offset, obs, out):
    """The single env's step ``k`` after its link (either link's ``single_step``): battery, reward, objective,
    the state's :data:`SINGLE` slots, observation and info, from the link's end currents ``i1``, ``i2``, peak
    ``pk`` (its envelope ``pk_env``), ``I_L`` ``il``, ``v2`` and the segment's short-mode I2 ``i2_sm`` and Lm
    ``lm_h``. Fills ``obs`` and ``out`` (:data:`INFO`, then reached short mode 1.0 / 0.0); returns the reward."""
    ib, soc, vrc, vl = _battery(il, st[SINGLE.soc], st[SINGLE.vrc], vl_old, st[SINGLE.ocv0:SINGLE.bus_decay + 1])
    cmd = steps[k, 0]
    reward, over = _reward(il, cmd, pk, inv_rated, w_track, w_over, i_ref)
    stop_k = int(st[SINGLE.stop_k])
    rm, ok, checked, cost = _objective(k, pk, il, i2_sm, dt, st[SINGLE.run_max], stop_k,
                                       st[SINGLE.sm_ok] != 0.0, st[SINGLE.sm_checked] != 0.0)
    st[SINGLE.i1], st[SINGLE.i2], st[SINGLE.vl], st[SINGLE.soc], st[SINGLE.vrc], st[SINGLE.d] = i1, i2, vl, soc, vrc, d
    st[SINGLE.run_max], st[SINGLE.sm_ok], st[SINGLE.sm_checked] = rm, 1.0 if ok else 0.0, 1.0 if checked else 0.0
    kk = k + 1
    _put_obs(obs.reshape((1, obs.shape[0])), 0, i2 + steps[kk - 1, 1], vl, ib, il, soc, steps[kk, 0], d,
             _t_since(kk, dt, st[SINGLE.t_stop], stop_k), scale, offset)
    _put_info(out.reshape((1, out.shape[0])), 0, kk * dt, i2, pk, i1, d, v2, il, vl, ib, soc, cmd, lm_h,
              vl_old * il * dt, over, cost, rm, pk_env)
    out[len(INFO)] = 1.0 if (ok and checked) else 0.0
    return reward
