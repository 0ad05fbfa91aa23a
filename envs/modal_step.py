"""The env step on the exact-mode link (``EnvConfig(link_model="modal")``), compiled with numba
(``cache=True``): the plant the single and the vector env step instead of eq. 4's envelope
(:mod:`envs.vector_kernel`, the default) when the config asks for it. Only the link is this module's; the
battery, reward, objective, observation and info are :mod:`envs.vector_kernel`'s functions (one source).

**The link** is the exact-mode envelope of :mod:`wpt_receiver.modal_kernel` (eq. 1's two coupled modes
in the frame rotating at w, the SBAR's v2 fundamental with its quadrature from the harmonic balance,
the instantaneous peak phase-aware), the mission's link (:mod:`mission_sim.world.loop_kernel`):
:func:`_segment` makes a window's modes and ZOH at its slow segment's Lm (kept while Lm is unchanged),
:func:`_link_step` steps one control period. Its v2 is the mission's implicit commutation
(:func:`wpt_receiver.modal_kernel.sbar_implicit`, here in closed form per sub-step, :func:`_v2_closed`);
v2 follows i2's phase every half cycle, so a step runs in rectifier-period sub-steps (as the mission's
fine step) unless the link is within ``hold_tol`` [A] of the steady state of the step's inputs (then V2
is held over the control period: the ringing, and so any error of the held V2, stays below
``hold_tol``). In a large transient a V2 held for a rectifier period is too coarse (the clamp loads the secondary
like a resistance (4/pi) Vc / |I2|, an envelope mode of 0.5-1.2 per period): a sub-step whose I2 moves by more
than ``EnvConfig.v2_refine_tol`` of |I2| is redone in up to 2^``v2_refine_levels`` pieces (:func:`_refine`);
below that tolerance the step's arithmetic is the one before (smooth control on tuned windows never triggers it:
nominal ``model_based`` / ``mpc`` windows bit-identical; detuned windows ring and do trigger it). Detuned windows (:mod:`envs.detuned`) are the same step with their C1, C2 in the
window's link constants.

* :func:`env_step` steps sub-environments ``[0, n)`` of the vector env, in chunks that run in parallel
  (``prange``) when ``n_chunks > 1``; each sub-environment's arithmetic does not depend on the chunk
  it is in, so the parallel step is the serial one to the bit.
* :func:`step_kernel` is :func:`env_step` serial (the signature :mod:`envs.rollout` replays).
* :func:`single_step` is the single env's per-env entry: the same helpers on one window.
* :func:`start_link` puts windows at the periodic steady state of their first duty.

State: the envs' :data:`envs.layout.STATE` (as eq. 4's step) plus the link's own :data:`envs.layout.MSTATE`
(mode amplitudes, V2 phasor); constants :data:`envs.layout.MPAR` / :data:`~envs.layout.MSINGLE_PAR`. Tests
(``tests/test_env_modal.py``) check the peak against the switching model on the paper's trajectories,
the energy balance, and the single env against the vector env's row.

Cost: with random actions the refinement made a step ~5x the unrefined one (docs/performance.md, "Adaptive
refinement of the modal env step"; ~0.72x of that since the sub-step loop runs without reference counts, below),
with the duty held the same. A step is sub-stepped in nearly every window (the link rarely rings below ``hold_tol``); the helpers called
once per step with arrays (:func:`_finish`, :func:`_link_of`, :func:`_transient_a`, and the link kernel's lookups
and readouts) are inlined (``inline="always"``): a call that passes arrays costs numba two atomic reference counts
per array, the arithmetic is the same (outputs equal to the bit). The sub-step loop (:func:`_substeps`, with
:func:`_refine` inlined into it) is compiled without numba's reference counting (``_nrt=False``: it allocates
nothing, and the inlined helpers' array arguments cost an atomic incref/decref pair each per piece, ~1/4 of a
refined step); the dispatchers it calls carry an explicit ``_nrt=True`` (numba's default), since a nested compile
inherits the caller's flag when the callee sets none (docs/performance.md, "The modal env step without reference
counts"). Profile, what was tried and the figures:
docs/performance.md ("The exact-mode (modal) env step"); ``benchmarks/profile_modal_step.py``,
``benchmarks/ab_modal_step.py``.

Imported only when an env with ``link_model="modal"`` is built.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit, prange

from wpt_receiver.modal_kernel import (MC_D, MC_G1, MC_G2, MC_LAM, MC_S, REFINE_LEVELS, REFINE_TOL, ZC_E, ZC_PHI,
                                       blocking_v2, inst_peak, modes, phasors, readout, rect_current_a, refine_level,
                                       sbar_implicit, sbar_shift, sbar_v2, short_weight, steady_modes, steady_state,
                                       stored_energy_j, zoh)
from wpt_receiver.modal_kernel import step as modal_step

from wpt_receiver.modal_link import SOURCES as _LINK_SOURCES
from wpt_receiver.kernel_cache import drop_stale_cache

from .layout import (CZ_FAST, CZ_FASTH, CZ_KEY, CZ_LEVEL_N, CZ_LEVELS, CZ_MODES, CZ_RPAR, CZ_SAMPLE, CZ_STEP, CZ_SUB,
                     FAST, MPAR, MSINGLE_PAR, REFINE_LEVELS_CAP,
                     MSTATE, SINGLE, SLOW, STATE)
from .vector_kernel import (_battery, _objective, _put_info, _put_obs, _reward, _t_since, compiled_or_python,
                            single_finish)

__all__ = ["env_step", "step_kernel", "single_step", "start_link", "kernel_function"]


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


# numba's cache of this module holds the link kernel's code, the env step's shared helpers and the layout's /
# objective's constants: dropped when those files change (numba keys the cache on this file alone)
drop_stale_cache(_here, (*_LINK_SOURCES, *(Path(__file__).with_name(f) for f in ("vector_kernel.py", "layout.py",
                                                                               "objective.py"))))

#: the commutation angle's tolerance [rad] (V2 to < 1e-6 V; the solve starts from the last angle)
_EDGE_TOL = 1e-8
_FOUR_OVER_PI = 4.0 / math.pi
#: the harmonics' shift is looked up again when |I2|^2 moved by more than this factor since (1.2^2)
_DELTA_RATIO2 = 1.44


def kernel_function(name: str, compiled: bool = True):
    """This module's ``name``, as :func:`envs.vector_kernel.kernel_function` gives that module's (the one pick:
    :func:`envs.vector_kernel.compiled_or_python`)."""
    return compiled_or_python(globals()[name], compiled)


# ---------------------------------------------------------------------- the link (exact modes)
@njit(cache=True)
def _segment(lc, lm_h, dt, n_sub, n_q, cz, force, rtol=REFINE_TOL, levels=REFINE_LEVELS):
    """The window's link coefficients ``cz`` (:data:`envs.layout.CZ_MODES` ...) at ``lm_h`` [H]: the modes
    and the ZOH of the step ``dt`` [s], of its ``n_sub``-th and of that one's ``n_q``-th, and the refinement's
    pieces (:func:`_refine`; its tolerance ``rtol`` and ``levels`` into ``cz[CZ_RPAR]``); kept when ``cz``
    is for ``lm_h`` already (unless ``force``: a new episode, whose link constants ``lc`` may differ)."""
    if not force and cz[CZ_KEY].real == lm_h:
        return
    mc = cz[CZ_MODES:CZ_STEP]
    modes(lc, lm_h, mc)
    zoh(mc, dt, cz[CZ_STEP:CZ_SUB])
    zoh(mc, dt / n_sub, cz[CZ_SUB:CZ_SAMPLE])
    zoh(mc, dt / (n_sub * n_q), cz[CZ_SAMPLE:CZ_FAST])
    _fast_coefs(mc, cz[CZ_SUB:CZ_SAMPLE], dt / n_sub, cz[CZ_FAST:CZ_FASTH])
    _fast_coefs(mc, cz[CZ_STEP:CZ_SUB], dt, cz[CZ_FASTH:CZ_KEY])
    for lev in range(REFINE_LEVELS_CAP):   # the refinement's pieces: made when first used (_refine)
        cz[CZ_LEVELS + lev * CZ_LEVEL_N] = 0j
    cz[CZ_RPAR] = complex(rtol, min(max(levels, 0), REFINE_LEVELS_CAP))   # never past cz's level slots
    cz[CZ_KEY] = lm_h


@njit(cache=True, _nrt=True)
def _fast_coefs(mc, zc, h, cf):
    """The affine maps of a sub-step of ``h`` [s] with V1, V2 held (:data:`envs.layout.FAST`, from the modes
    ``mc`` and their ZOH ``zc``): with ``e^{lam' h} = 1 + lam' phi`` the exact step is ``z+ = e z + phi (g1 V1
    + g2 V2)`` per mode, the end I2 and ``int I2 dt`` are :func:`wpt_receiver.modal_kernel.step`'s, written
    out as affine functions of the state and of V2."""
    b, q1 = mc[MC_D + 2], mc[MC_D + 3]
    p0, p1 = mc[MC_D + 2] * h, mc[MC_D + 3] * h
    for m in range(2):
        lam, g1, g2, sh = mc[MC_LAM + m], mc[MC_G1 + m], mc[MC_G2 + m], mc[MC_S + 4 * m + 1]
        e, phi = zc[ZC_E + m], zc[ZC_PHI + m]
        cf[FAST.e0 + m], cf[FAST.k0 + m], cf[FAST.l0 + m] = e, phi * g1, phi * g2
        cf[FAST.a0 + m], cf[FAST.c0 + m] = sh * e, sh * phi
        b += sh * phi * g1
        q1 += sh * phi * g2
        p0 -= sh * (h - phi) * g1 / lam
        p1 -= sh * (h - phi) * g2 / lam
    cf[FAST.b], cf[FAST.q1], cf[FAST.p0], cf[FAST.p1] = b, q1, p0, p1


@njit(cache=True, _nrt=True)
def _v2_closed(q0, sgn, k, block=False):
    """The SBAR's V2 over a sub-step whose end I2 is ``q0 + q1 V2``, implicit in the commutation as
    :func:`wpt_receiver.modal_kernel.sbar_implicit` (the commutation angle the end i2 has, with the v2 of
    that angle held; the sign ``sgn`` of the start's Re I2) with the harmonics' shift ``delta`` held.
    ``k`` = :func:`_solve_consts`. Unclipped, ``j e^{-j e} = sgn n kw`` with ``n = I2e / |I2e|``, ``kw =
    e^{-j delta}``, so ``V2 = (4/pi) Vc (n kw - sgn sin(pi d/2)) + ws I2e`` and ``I2e = A + B n``: ``|I2e| =
    r`` solves ``|r - B| = |A|``, one square root (``r = Re B + sqrt(|A|^2 - Im(B)^2)``, the root with r >
    0). Outside the conduction window (``Re(sgn n kw) < sin(pi d/2)``: the bracket's ``g`` is of one sign
    over the window) the angle is the window's edge on the solution's side, ``F = +-j sgn (4/pi) cos(pi
    d/2)``. Without such a solution (``|A| <= |B|``: the clamp alone would turn I2 within the sub-step) the
    diode rectifier blocks when the V2 that holds the end I2 at 0, ``F = -q0 / (den qv)``, is within the
    clamp (``|F| <= (4/pi)(1 - sin(pi d/2))``, the describing function's set-valued clamp at I2 = 0),
    on a window in the blocking regime (``block``: its steady state at this duty blocks,
    :func:`wpt_receiver.modal_kernel.blocking_v2`; a C1 detuned so that the emf stays below the clamp,
    where the switching model settles at no transfer): ``I2e = 0``; else :func:`_v2_edges` (every other
    window's step unchanged). Returns ``(F, I2e, t, ok)``, ``V2 = Vc F + ws I2e``, ``F = sgn (4/pi) (t - s)``:
    ``t = j e^{-j e}`` of the commutation angle ``e`` where the SBAR commutates (not when blocked)."""
    inv_den, qv, cs, bn, kw, s, c, wd = k
    a = q0 * inv_den - sgn * cs
    a2 = a.real * a.real + a.imag * a.imag
    disc = a2 - bn.imag * bn.imag
    if disc >= 0.0:
        r = bn.real + math.sqrt(disc)
        if r > 0.0:
            n = a * (r - bn).conjugate() * (1.0 / a2)   # a / (r - bn), |r - bn| = |a|
            nk = n * kw
            t = sgn * nk
            if t.real >= s:
                return _FOUR_OVER_PI * (nk - sgn * s), r * n, t, True
            t = complex(s, c if t.imag > 0.0 else -c)
            f = complex(0.0, sgn * _FOUR_OVER_PI * t.imag)
            return f, q0 * inv_den + qv * f, t, True
    if block:   # no conducting end current: the rectifier blocks if the V2 holding I2e at 0 is within the clamp
        f = -q0 * inv_den / qv if qv != 0.0 else 0j
        if abs(f) <= _FOUR_OVER_PI * (1.0 - s):
            # blocked: no commutation, so no angle; t is the point with F = sgn (4/pi) (t - s) as in every
            # other branch (inside the unit circle here). No caller reads it (_link_step keeps its ``e``).
            return f, 0j, s + sgn * (0.25 * math.pi) * f, True
    return _v2_edges(q0, sgn, k)


@njit(cache=True, _nrt=True)
def _solve_consts(q1, ws, vc, kw, s, c, wd=-1.0):
    """The step's constants of :func:`_v2_closed` for the end-current gain ``q1`` [A/V], the shorted
    switches' excess ``ws`` [ohm], the clamp ``vc`` [V], ``kw = e^{-j delta}`` (the harmonics' shift) and
    ``s, c = sin, cos(pi d/2)``: ``(1/den, q1 Vc/den, q1 K s/den, q1 K kw/den, kw, s, c, wd)``, ``den = 1 - q1
    ws``, ``K = (4/pi) Vc``, ``wd = atan2(s, c)`` [rad] the window's edge as :func:`_v2_edges` compares it (pass
    the step's, computed once: it depends on the duty only; negative: computed here)."""
    inv_den = 1.0 / (1.0 - q1 * ws)
    qv = q1 * vc * inv_den
    if wd < 0.0:
        wd = math.atan2(s, c)
    return inv_den, qv, _FOUR_OVER_PI * s * qv, _FOUR_OVER_PI * qv * kw, kw, s, c, wd


@njit(cache=True)
def _edge_angle(i2e, kw_arg, sgn):
    """The commutation angle [rad] of the end current ``i2e`` before the window's clip (``sbar_edge``'s
    ``pi/2 - arg + delta`` of the sign-folded phasor, its phase clipped to +-pi/2; ``kw_arg = arg(e^{-j delta})``,
    ``atan2`` of ``kw``)."""
    ih = i2e * sgn
    ph = min(max(math.atan2(ih.imag, ih.real), -0.5 * math.pi), 0.5 * math.pi)
    return 0.5 * math.pi - ph - kw_arg


@njit(cache=True, _nrt=True)
def _v2_edges(q0, sgn, k):
    """:func:`_v2_closed` when its closed form has no solution: the root of the bracket's increasing ``g(e) =
    e - e_end(e)`` at a window edge (``e = pi d/2`` when ``g >= 0`` there, ``pi - pi d/2`` when ``g <= 0``
    there), else at the jump of ``g`` where the end current reverses (i2 turns within the sub-step: the
    end I2 real and against ``sgn``; ``Im I2e(e) = 0`` is ``R sin(e + psi) = -Im A``); ``ok`` False when
    none is found (the caller's bracket)."""
    inv_den, qv, cs, bn, kw, s, c, wd = k
    kw_arg = math.atan2(kw.imag, kw.real)   # once per call (both sides use it); wd: once per step, in k
    for side in (1.0, -1.0):
        f = complex(0.0, sgn * side * _FOUR_OVER_PI * c)
        i2e = q0 * inv_den + qv * f
        g = (wd if side > 0.0 else math.pi - wd) - _edge_angle(i2e, kw_arg, sgn)
        if (side > 0.0 and g >= 0.0) or (side < 0.0 and g <= 0.0):
            return f, i2e, complex(s, side * c), True
    a = q0 * inv_den - sgn * cs
    bp = sgn * _FOUR_OVER_PI * qv
    rb = abs(bp)
    if rb > 0.0 and abs(a.imag) <= rb:
        psi, x = math.atan2(bp.real, bp.imag), math.asin(-a.imag / rb)
        for e in (x - psi, math.pi - x - psi):
            e = e % (2.0 * math.pi)
            if wd <= e <= math.pi - wd:
                t = complex(math.sin(e), math.cos(e))
                i2e = a + bp * t
                if sgn * i2e.real <= 0.0:
                    return sgn * _FOUR_OVER_PI * (t - s), i2e, t, True
    return 0j, 0j, 0j, False


@njit(cache=True, inline="always")
def _transient_a(mc, z0, z1, v1, v2):
    """Bound [A] of the ringing of I2 about the steady state of the inputs ``v1, v2`` held: the two
    modes' distances from their steady amplitudes, in I2 units (they only decay under held inputs)."""
    zs0, zs1 = steady_modes(mc, v1, v2)
    return abs(mc[MC_S + 1] * (z0 - zs0)) + abs(mc[MC_S + 5] * (z1 - zs1))


@njit(cache=True, _nrt=True)
def _samples(mc, zq, z, v1, v2, n_q, best, i2_best):
    """The largest |I2| [A] at the ``n_q - 1`` inner sample points of a sub-step from ``z`` with ``v1, v2``
    held (``zq`` the sample's ZOH; the modes advanced on scalars, :func:`~wpt_receiver.modal_kernel.end_i2`'s
    arithmetic): ``(best, its I2 phasor)``, starting from ``best``, ``i2_best``."""
    zs0, zs1 = steady_modes(mc, v1, v2)
    c0, c1 = complex(z[0], z[1]) - zs0, complex(z[2], z[3]) - zs1
    s0, s1 = mc[MC_S + 1], mc[MC_S + 5]
    i2s = readout(mc, 1, zs0, zs1, v1, v2)
    e0, e1 = zq[ZC_E], zq[ZC_E + 1]
    for _ in range(n_q - 1):
        c0, c1 = c0 * e0, c1 * e1
        i2 = i2s + s0 * c0 + s1 * c1
        a = abs(i2)
        if a > best:
            best, i2_best = a, i2
    return best, i2_best


@njit(cache=True, inline="always")
def _coef_tuple(cf, v1c):
    """A sub-step's affine maps (:data:`envs.layout.FAST`) as scalars, the V1 terms times the phasor ``v1c``:
    ``(e0, e1, k0, k1, l0, l1, c0, c1, p0, p1, a0, a1, b, q1)``."""
    return (cf[FAST.e0], cf[FAST.e1], cf[FAST.k0] * v1c, cf[FAST.k1] * v1c, cf[FAST.l0], cf[FAST.l1], cf[FAST.c0],
            cf[FAST.c1], cf[FAST.p0] * v1c, cf[FAST.p1], cf[FAST.a0], cf[FAST.a1], cf[FAST.b] * v1c, cf[FAST.q1])


@njit(cache=True, inline="always")
def _rekey(k, kw):
    """:func:`_solve_consts`'s tuple ``k`` with the harmonics' shift ``kw = e^{-j delta}`` replaced."""
    return (k[0], k[1], k[2], _FOUR_OVER_PI * k[1] * kw, kw, k[5], k[6], k[7])


@njit(cache=True, inline="always")
def _held(z, z0, z1, v2, v2n, f, co, v1c, zs, h, lc, mc, lm, book, out, en):
    """One sub-step of ``h`` [s] from the mode amplitudes ``z0, z1`` with ``v2n`` held (``v2`` the last one's; ``f``
    its clamp part per volt): by the affine maps ``co`` (:func:`_coef_tuple`), or with ``book`` by
    :func:`wpt_receiver.modal_kernel.step` on the ZOH ``zs`` (energies and the feedthrough's jump into ``en``;
    ``z`` scratch). Returns ``(z0, z1, mean I_L)`` [A]."""
    if book:
        z[0], z[1], z[2], z[3] = z0.real, z0.imag, z1.real, z1.imag
        en[3] += stored_energy_j(lc, mc, z, v1c, v2n, lm) - stored_energy_j(lc, mc, z, v1c, v2, lm)
        modal_step(lc, mc, zs, h, z, v1c, v2n, out)
        en[0] += out[6]
        en[1] += out[7]
        en[2] += out[8]
        return complex(z[0], z[1]), complex(z[2], z[3]), rect_current_a(f, complex(out[2], out[3]), h)
    il = rect_current_a(f, co[6] * z0 + co[7] * z1 + co[8] + co[9] * v2n, h)
    return co[0] * z0 + co[2] + co[4] * v2n, co[1] * z1 + co[3] + co[5] * v2n, il


@njit(cache=True, inline="always")
def _reshift(lc, tab, d, i2e, sgn, vc, a, r_ref, k):
    """The harmonics' shift looked up again at the end current ``i2e`` (``a = |i2e|^2``) when |I2| moved by more
    than ``sqrt(_DELTA_RATIO2)`` since ``r_ref`` [A]: ``(r_ref, k)``."""
    if a > _DELTA_RATIO2 * r_ref * r_ref or _DELTA_RATIO2 * a < r_ref * r_ref:
        r_ref = math.sqrt(a)
        dl = sbar_shift(lc, tab, d, i2e * sgn, vc)
        k = _rekey(k, complex(math.cos(dl), -math.sin(dl)))
    return r_ref, k


@njit(cache=True, inline="always")
def _solve(co, z0, z1, sgn, k, block, lc, tab, mc, zs, v1c, v2, d, vc, ws):
    """V2 of a sub-step (maps ``co``, ZOH ``zs``): :func:`_v2_closed`, else
    :func:`~wpt_receiver.modal_kernel.sbar_implicit`: ``(F, I2 end, j e^{-j e})``."""
    f, i2e, t, ok = _v2_closed(co[10] * z0 + co[11] * z1 + co[12], sgn, k, block)
    if not ok:
        f, i2e, e = sbar_implicit(lc, tab, mc, zs, z0, z1, v1c, v2, d, vc, ws, -1.0, 1e-13)
        t = complex(math.sin(e), math.cos(e))
    return f, i2e, t


@njit(cache=True, inline="always")
def _refine(z, z0, z1, v2, lev, sgn, k, r_ref, pk, i2_pk, vc, d, ws, lc, tab, mc, cr, h, v1c, out, en, book, lm, block):
    """A sub-step of ``h`` [s] redone in ``2^lev`` pieces, V2 implicit at each piece's end (:func:`_v2_closed` on
    the piece's maps; the refinement levels' coefficients ``cr`` = ``cz[CZ_RPAR:]``, made here at a level's first use
    in a segment), the shift looked up again as
    in :func:`_substeps`. Returns ``(z0, z1, V2, j e^{-j e}, end I2, sgn, k, r_ref, |I2| peak, its I2, mean I_L)``."""
    b, m = 1 + (lev - 1) * CZ_LEVEL_N, 1 << lev
    hl, il, t, i2e = h / m, 0.0, 0j, 0j
    zl = cr[b + 1:b + 8]
    if cr[b].real != hl:   # this level's pieces not made yet for this segment: the ZOH and the maps of h / 2^L
        zoh(mc, hl, zl)
        _fast_coefs(mc, zl, hl, cr[b + 8:b + CZ_LEVEL_N])
        cr[b] = hl
    co = _coef_tuple(cr[b + 8:b + CZ_LEVEL_N], v1c)
    kl = _solve_consts(co[13], ws, vc, k[4], k[5], k[6], k[7])
    for _ in range(m):
        f, i2e, t = _solve(co, z0, z1, sgn, kl, block, lc, tab, mc, zl, v1c, v2, d, vc, ws)
        v2n = f * vc + ws * i2e
        z0, z1, q = _held(z, z0, z1, v2, v2n, f, co, v1c, zl, hl, lc, mc, lm, book, out, en)
        v2, il = v2n, il + q / m
        a = i2e.real * i2e.real + i2e.imag * i2e.imag
        if a > pk * abs(pk):
            pk, i2_pk = math.sqrt(a), i2e
        sgn = -1.0 if i2e.real < 0.0 else 1.0
        r_new, k = _reshift(lc, tab, d, i2e, sgn, vc, a, r_ref, k)
        if r_new != r_ref:
            r_ref, kl = r_new, _rekey(kl, k[4])
    return z0, z1, v2, t, i2e, sgn, k, r_ref, pk, i2_pk, il


@njit(cache=True, _nrt=False)
def _substeps(z, v2, i2, k, vc, d, ws, lc, tab, mc, zs, cf, zq, h, n_sub, n_q, v1c, out, en, book, lm, block, cr):
    """``n_sub`` sub-steps of ``h`` [s] from the mode amplitudes ``z`` (4 reals, in place) and the start's
    I2 ``i2``, V2 updated at each (the circuit decides v2 once per half cycle) by :func:`_v2_closed`
    (constants ``k``; the harmonics' shift looked up again when |I2| moved by 20 % since), the state advanced by
    the sub-step's affine maps ``cf`` (:data:`envs.layout.FAST`; with ``book`` by
    :func:`wpt_receiver.modal_kernel.step` on the ZOH ``zs``, its energies into ``en``, the same state to
    rounding). A sub-step that the closed forms do not solve takes :func:`~wpt_receiver.modal_kernel.sbar_implicit`.
    A sub-step whose end I2 moved from its start's by more than ``cr[0].real`` of |I2| is redone in pieces
    (:func:`_refine`; the level :func:`wpt_receiver.modal_kernel.refine_level`, at most ``cr[0].imag``
    halvings; not with ``n_q > 1`` samples per sub-step): in large transients V2 held over a rectifier period is too coarse (docs/performance.md). Returns ``(V2, j e^{-j e},
    |I2| peak, its I2 phasor, sum of I_L over the sub-steps)``; ``lm`` [H] the Lm of ``mc`` (the stored energy);
    ``block``: the window blocks in steady state (:func:`_v2_closed`). The unrefined sub-step is written out
    here, not through :func:`_held` / :func:`_reshift` as in :func:`_refine`: the same arithmetic, but the
    helpers made the hot loop ~25 % slower (docs/performance.md). Compiled with ``_nrt=False`` (no reference
    counts; every dispatcher it calls sets ``_nrt=True`` itself, see the module docstring)."""
    z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
    q1, a0, a1, bv = cf[FAST.q1], cf[FAST.a0], cf[FAST.a1], cf[FAST.b] * v1c
    e0, e1, k0, k1 = cf[FAST.e0], cf[FAST.e1], cf[FAST.k0] * v1c, cf[FAST.k1] * v1c
    l0, l1, c0, c1, p0, p1 = cf[FAST.l0], cf[FAST.l1], cf[FAST.c0], cf[FAST.c1], cf[FAST.p0] * v1c, cf[FAST.p1]
    pk, i2_pk, qsum, t = -1.0, 0j, 0.0, 0j
    sgn = -1.0 if i2.real < 0.0 else 1.0
    r_ref, i2s = abs(i2), i2
    rtol, levels = cr[0].real, int(cr[0].imag) if n_q == 1 and len(cr) > 1 else 0   # held steps: never
    for _ in range(n_sub):
        f, i2e, t, ok = _v2_closed(a0 * z0 + a1 * z1 + bv, sgn, k, block)
        if not ok:
            f, i2e, e = sbar_implicit(lc, tab, mc, zs, z0, z1, v1c, v2, d, vc, ws, -1.0, 1e-13)
            t = complex(math.sin(e), math.cos(e))
        lev = refine_level(i2s, i2e, rtol, levels) if levels > 0 else 0
        if lev > 0:   # I2 moved too much for one held V2: this sub-step again, in 2^lev pieces
            z0, z1, v2, t, i2e, sgn, k, r_ref, pk, i2_pk, q = _refine(z, z0, z1, v2, lev, sgn, k, r_ref, pk, i2_pk, vc, d,
                                                                      ws, lc, tab, mc, cr, h, v1c, out, en, book, lm,
                                                                      block)
            qsum += q
            i2s = i2e
            continue
        i2s = i2e
        v2n = f * vc + ws * i2e
        if book or n_q > 1:
            z[0], z[1], z[2], z[3] = z0.real, z0.imag, z1.real, z1.imag
        if book:
            en[3] += stored_energy_j(lc, mc, z, v1c, v2n, lm) - stored_energy_j(lc, mc, z, v1c, v2, lm)
        v2 = v2n
        if n_q > 1:
            pk, i2_pk = _samples(mc, zq, z, v1c, v2, n_q, pk, i2_pk)
        if book:
            modal_step(lc, mc, zs, h, z, v1c, v2, out)
            qsum += rect_current_a(f, complex(out[2], out[3]), h)
            en[0] += out[6]
            en[1] += out[7]
            en[2] += out[8]
            z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
        else:
            qsum += rect_current_a(f, c0 * z0 + c1 * z1 + p0 + p1 * v2, h)
            z0, z1 = e0 * z0 + k0 + l0 * v2, e1 * z1 + k1 + l1 * v2
        a = i2e.real * i2e.real + i2e.imag * i2e.imag
        if a > pk * abs(pk):
            pk, i2_pk = math.sqrt(a), i2e
        sgn = -1.0 if i2e.real < 0.0 else 1.0
        if a > _DELTA_RATIO2 * r_ref * r_ref or _DELTA_RATIO2 * a < r_ref * r_ref:
            # |I2| moved by more than the ratio since delta was looked up: again, at this end's I2
            r_ref = math.sqrt(a)
            dl = sbar_shift(lc, tab, d, i2e * sgn, vc)
            k = _rekey(k, complex(math.cos(dl), -math.sin(dl)))
    z[0], z[1], z[2], z[3] = z0.real, z0.imag, z1.real, z1.imag
    return v2, t, pk, i2_pk, qsum


@njit(cache=True)
def _link_step(z, v2, e, vl, d, lc, tab, cz, dt, n_sub, n_q, vf, dr, v1, hold_tol, out, en):
    """One control period of the exact-mode link (:mod:`wpt_receiver.modal_kernel`) with duty ``d`` held,
    from the mode amplitudes ``z`` (4 reals, advanced in place), the V2 phasor ``v2`` [V] held over the
    last step, ``e`` the state's commutation slot (returned unchanged: the closed form needs no first guess), the battery at ``vl`` [V]
    (the clamp ``vl + vf``), the shorted switches' excess ``dr`` [ohm], the pad's amplitude ``v1`` [V]. V2
    is the implicit commutation's (:func:`_v2_closed`, the harmonics' shift looked up once at the step's
    start i2); held over the whole step when the link is within ``hold_tol`` [A] of the steady state of
    the step's inputs (the explicit v2 of the start's i2), else updated every one of ``n_sub`` sub-steps
    (:func:`_substeps`), with ``n_q`` samples of |I2| in each. Returns ``(V2, e, |I1|, I2, |I2| peak,
    instantaneous peak, I_L, v2 in phase with i2, split)``: I2 = |I2| signed by Re I2 at the end, the peaks
    over the sub-step ends (the instantaneous one, phase-aware, at the largest |I2|), ``I_L`` the mean DC
    current into the clamp [A]. ``out`` (9) scratch; ``en`` (4) gets, with ``en[3]`` NaN on entry, the
    step's source, coil + device, rectifier energies [J] and the stored-energy jumps of the feedthrough
    when V2 changes between sub-steps (the balance is ``source = dW + coil + rect - jumps``; zeros without)."""
    vc = vl + vf
    ws = dr * short_weight(d)
    v1c = complex(0.0, -v1)
    mc = cz[CZ_MODES:CZ_STEP]
    z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
    i2a = readout(mc, 1, z0, z1, v1c, v2)
    sgn = -1.0 if i2a.real < 0.0 else 1.0
    dl = sbar_shift(lc, tab, d, i2a * sgn, vc)
    kw = complex(math.cos(dl), -math.sin(dl))
    wd = 0.5 * math.pi * min(max(d, 0.0), 1.0)
    sw, cw = math.sin(wd), math.cos(wd)
    book = en[3] != en[3]   # a NaN in en[3]: book the energies and the jumps
    en[0], en[1], en[2], en[3] = 0.0, 0.0, 0.0, 0.0
    # held or not: the ringing about the steady state of the explicit v2 (the start's i2 direction)
    kx = _solve_consts(0.0, 0.0, vc, kw, sw, cw)
    ax = abs(i2a)
    v2x = vc * _v2_closed(i2a, sgn, kx)[0] + ws * i2a if ax > 0.0 else 0j
    # (also at n_sub = 1, dt_s <= one rectifier period: the one sub-step is then refined and sampled as at 17; gated
    # on n_sub > 1 until 2026-11-28, such steps were never refined: energy 0.3-0.6 % low under random duties)
    split = _transient_a(mc, z0, z1, v1c, v2x) > hold_tol
    n, h, zs, cf = 1, dt, cz[CZ_STEP:CZ_SUB], cz[CZ_FASTH:CZ_KEY]
    if split:
        n, h, zs, cf = n_sub, dt / n_sub, cz[CZ_SUB:CZ_SAMPLE], cz[CZ_FAST:CZ_FASTH]
    k = _solve_consts(cf[FAST.q1], ws, vc, kw, sw, cw, kx[7])
    block = abs(blocking_v2(mc, v1c)) <= _FOUR_OVER_PI * vc * (1.0 - sw)   # the window blocks in steady state
    v2, t, pk_env, i2_pk, qsum = _substeps(z, v2, i2a, k, vc, d, ws, lc, tab, mc, zs, cf, cz[CZ_SAMPLE:CZ_FAST], h,
                                           n, n_q if split else 1, v1c, out, en, book, cz[CZ_KEY].real, block,
                                           cz[CZ_RPAR:] if split else cz[CZ_RPAR:CZ_LEVELS])
    i1, i2 = phasors(mc, z, v1c, v2)
    a = abs(i2)
    if a > pk_env:   # the end's I2 from the state (the closed form's end current to rounding)
        pk_env, i2_pk = a, i2
    v2_row = (v2 * i2.conjugate()).real / a if a > 0.0 else v2.real   # v2's fundamental in phase with i2
    return (v2, e, abs(i1), (a if i2.real >= 0.0 else -a), pk_env,
            inst_peak(lc, tab, d, i2_pk, vc), qsum / n, v2_row, split)


@njit(cache=True, inline="always")
def _link_of(state, ms, e, lc, tab, cz, d, par, n_sub, out, en, zb):
    """:func:`_link_step` of window ``e`` of the vector env (battery voltage from ``state``, :data:`STATE`; the
    link's own state ``ms``, :data:`MSTATE`, updated): ``(|I1|, I2, |I2| peak, instantaneous peak, I_L, v2 in
    phase with i2)``."""
    zb[0], zb[1], zb[2], zb[3] = ms[MSTATE.z0r, e], ms[MSTATE.z0i, e], ms[MSTATE.z1r, e], ms[MSTATE.z1i, e]
    v2, ang, i1, i2, pk_env, pk, il, v2_row, _ = _link_step(zb, complex(ms[MSTATE.v2r, e], ms[MSTATE.v2i, e]),
                                                            ms[MSTATE.e, e], state[STATE.vl, e], d, lc, tab, cz,
                                                            par[MPAR.dt], n_sub, int(par[MPAR.n_q]), par[MPAR.vf],
                                                            par[MPAR.dr], par[MPAR.v1], par[MPAR.hold_tol], out, en)
    ms[MSTATE.e, e] = ang
    ms[MSTATE.z0r, e], ms[MSTATE.z0i, e], ms[MSTATE.z1r, e], ms[MSTATE.z1i, e] = zb[0], zb[1], zb[2], zb[3]
    ms[MSTATE.v2r, e], ms[MSTATE.v2i, e] = v2.real, v2.imag
    return i1, i2, pk_env, pk, il, v2_row


@njit(cache=True)
def start_link(lc_all, lm0, d0, vl0, vf, v1, tab, dt, n_sub, n_q, cz_all, z_out, v2_out, rows):
    """Every window ``e`` at the periodic steady state of its first duty ``d0[e]`` (battery ``vl0[e]`` [V],
    Lm ``lm0[e]`` [H], link constants ``lc_all[e]``): its coefficients into ``cz_all[e]`` (:func:`_segment`),
    the mode amplitudes into ``z_out[e]`` (4), the V2 phasor into ``v2_out[e]``, and ``rows[:, e]`` = |I1|,
    I2 (signed), instantaneous peak, I_L, v2 in phase with i2 [A, V]."""
    v1c = complex(0.0, -v1)
    for e in range(lm0.shape[0]):
        lc, cz, vc, d = lc_all[e], cz_all[e], vl0[e] + vf, d0[e]
        _segment(lc, lm0[e], dt, n_sub, n_q, cz, True)
        mc = cz[CZ_MODES:CZ_STEP]
        z = z_out[e]
        v2 = steady_state(lc, mc, tab, d, v1c, vc, z)
        i1, i2 = phasors(mc, z, v1c, v2)
        f = sbar_v2(lc, tab, d, i2, vc)[1]
        a = abs(i2)
        v2_out[e] = v2
        rows[0, e], rows[1, e] = abs(i1), (a if i2.real >= 0.0 else -a)
        rows[2, e] = inst_peak(lc, tab, d, i2, vc)
        rows[3, e] = 0.5 * (f * i2.conjugate()).real
        rows[4, e] = (v2 * i2.conjugate()).real / a if a > 0.0 else v2.real


@njit(cache=True, inline="always")
def _finish(e, d, state, kk, jj, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, link, obs, reward, trunc,
            info):
    """Battery, reward, objective, state, observation and info of window ``e`` after its link step
    ``link`` = (|I1|, I2, |I2| peak, instantaneous peak, I_L, v2); returns the new step index."""
    i2sm_all, stop_k, t_stop, run_max, ok, checked = ep
    dt = par[MPAR.dt]
    i1, i2, pk_env, pk, il, v2 = link
    vl_old = state[STATE.vl, e]
    ib, soc, vrc, vl = _battery(il, state[STATE.soc, e], state[STATE.vrc, e], vl_old, bat[:, e])
    cmd = cmd_all[kk, e]
    reward[e], over = _reward(il, cmd, pk, par[MPAR.inv_rated], par[MPAR.w_track], par[MPAR.w_over], par[MPAR.i_ref])
    rm, ok[e], checked[e], cost = _objective(kk, pk, il, i2sm_all[jj, e], dt, run_max[e], stop_k[e], ok[e],
                                             checked[e])
    run_max[e] = rm
    state[STATE.i1, e], state[STATE.i2, e], state[STATE.vl, e] = i1, i2, vl
    state[STATE.soc, e], state[STATE.vrc, e], state[STATE.d, e] = soc, vrc, d
    kk += 1
    _put_obs(obs, e, i2 + noise_all[kk - 1, e], vl, ib, il, soc, cmd_all[kk, e], d,
             _t_since(kk, dt, t_stop[e], stop_k[e]), scale, offset)
    trunc[e] = kk >= par[MPAR.n_steps]
    _put_info(info, e, kk * dt, i2, pk, i1, d, v2, il, vl, ib, soc, cmd, lm_all[jj, e], vl_old * il * dt, over,
              cost, rm, pk_env)
    return kk


@njit(cache=True)
def _chunk(lo, hi, d, state, mstate, k, j, lc_all, cz_all, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
           scale, offset, tab, obs, reward, trunc, info):
    """The step of sub-environments ``[lo, hi)``: link (:func:`_segment` at a new slow segment,
    :func:`_link_step`), then :func:`_finish`."""
    out, en, zb = np.empty(9), np.zeros(4), np.empty(4)
    dt = par[MPAR.dt]
    for e in range(lo, hi):
        kk = k[e]
        jj = kk // slow_every
        if jj != j[e] or kk == 0:
            _segment(lc_all[e], lm_all[jj, e], dt, n_sub, int(par[MPAR.n_q]), cz_all[e], kk == 0, par[MPAR.rtol],
                     int(par[MPAR.rlevels]))
            j[e] = jj
        link = _link_of(state, mstate, e, lc_all[e], tab, cz_all[e], d[e], par, n_sub, out, en, zb)
        k[e] = _finish(e, d[e], state, kk, jj, bat, cmd_all, noise_all, lm_all, ep, par, scale, offset, link, obs,
                       reward, trunc, info)


@njit(cache=True, parallel=True)
def env_step(d, state, mstate, k, j, lc_all, cz_all, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par, scale,
             offset, tab, obs, reward, trunc, info, n_chunks):
    """Step every sub-environment with duty ``d`` (n,), in ``n_chunks`` contiguous chunks run in
    parallel (``n_chunks = 1``: one chunk on the calling thread, no thread pool). ``state`` (:data:`STATE`,
    (6, n)), the link's ``mstate`` (:data:`MSTATE`, (7, n)) and the step index ``k`` / slow index ``j`` are updated in place, and so are the windows'
    current link coefficients ``cz_all`` (n, N_CZ) complex (made from the link constants ``lc_all`` (n, 12)
    and the slow segment's Lm when a sub-environment enters a new one) and the objective's running values
    in ``ep`` (:func:`_finish`); ``bat`` (:data:`BAT`, (9, n)); ``cmd_all`` (T + 1, n), ``noise_all``
    (T, n), ``lm_all`` (S, n) step-major; ``tab`` the link's :func:`wpt_receiver.modal_kernel.modal_table`.
    ``obs`` (n, 8) float32, ``reward``, ``trunc`` and ``info`` (n, len(INFO)) are filled."""
    n = d.shape[0]
    if n_chunks <= 1:
        _chunk(0, n, d, state, mstate, k, j, lc_all, cz_all, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
               scale, offset, tab, obs, reward, trunc, info)
        return
    for c in prange(n_chunks):
        _chunk(c * n // n_chunks, (c + 1) * n // n_chunks, d, state, mstate, k, j, lc_all, cz_all, bat, cmd_all,
               noise_all, lm_all, ep, slow_every, n_sub, par, scale, offset, tab, obs, reward, trunc, info)


@njit(cache=True)
def step_kernel(d, state, mstate, k, j, lc_all, cz_all, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub, par,
                scale, offset, tab, obs, reward, trunc, info):
    """:func:`env_step` on the calling thread (:mod:`envs.rollout`'s replay)."""
    _chunk(0, d.shape[0], d, state, mstate, k, j, lc_all, cz_all, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub,
           par, scale, offset, tab, obs, reward, trunc, info)


@njit(cache=True)
def single_step(k, d, st, steps, slow, par, obs, out, lc, cz, tab):
    """Step ``k`` of one env with duty ``d``: the helpers of :func:`env_step` on one window.
    ``st`` (:data:`SINGLE`, then the link's :data:`MSTATE`) is updated in place; ``steps`` (T + 1, 2) = command,
    sensor noise per step; ``slow`` (S, :data:`SLOW`) = true Lm, short-mode I2 per slow segment (its ZOH columns
    unused); ``par`` = :data:`MSINGLE_PAR`,
    OBS_SCALE, OBS_OFFSET; ``lc`` the window's link constants, ``cz`` (N_CZ) complex its current link
    coefficients, ``tab`` the link's table. Fills ``obs`` (8,) float32 and ``out`` (:data:`INFO`, then
    reached short mode 1.0 / 0.0); returns the reward."""
    P = MSINGLE_PAR
    dt, n_sub, se = par[P.dt], int(par[P.n_sub]), int(par[P.slow_every])
    j = k // se
    if k == 0 or j != (k - 1) // se:
        _segment(lc, slow[j, SLOW.lm_h], dt, n_sub, int(par[P.n_q]), cz, k == 0, par[P.rtol], int(par[P.rlevels]))
    vl_old = st[SINGLE.vl]
    ms = st[len(SINGLE):]   # the link's own state (MSTATE) after the SINGLE slots
    z = ms[MSTATE.z0r:MSTATE.z1i + 1]
    en = np.zeros(4)
    v2c, ang, i1, i2, pk_env, pk, il, v2, _ = _link_step(z, complex(ms[MSTATE.v2r], ms[MSTATE.v2i]), ms[MSTATE.e],
                                                         vl_old, d, lc, tab, cz, dt, n_sub, int(par[P.n_q]), par[P.vf],
                                                         par[P.dr], par[P.v1], par[P.hold_tol], np.empty(9), en)
    ms[MSTATE.v2r], ms[MSTATE.v2i], ms[MSTATE.e] = v2c.real, v2c.imag, ang
    return single_finish(k, d, st, steps, i1, i2, pk, pk_env, il, v2, vl_old, slow[j, SLOW.i2_sm_a], slow[j, SLOW.lm_h],
                         dt, par[P.inv_rated], par[P.w_track], par[P.w_over], par[P.i_ref], par[len(P):len(P) + 8],
                         par[len(P) + 8:len(P) + 16], obs, out)

