"""The exact-mode envelope (:mod:`.modal`) as compiled numba functions for hot loops (mission, envs).

:class:`wpt_receiver.modal.ModalEnvelope` is within 0.1 % of the switching model on the paper's
step, ramp and proposed trajectories, but steps in numpy with a harmonic balance per step. This
module is the same model, cheap enough for a mission or an env step:

* **Modes, per Lm** (:func:`modes`): the positive-frequency roots of eq. 1's characteristic
  quartic ``P(s) = s^2 det Z(s) = (L1 s^2 + R1 s + 1/C1)(L2 s^2 + R2 s + 1/C2) - Lm^2 s^4``
  (Newton from the lossless ``j w / sqrt(1 -+ k)``, the second pair by deflation), each with its
  residue ``s^2 adj Z(s) / P'(s)`` (rank 1: mode shape x input gain) and the quasi-static response
  of the two negative-frequency modes (feedthrough); closed form, no LAPACK. Equal to
  the eigen-decomposition of :func:`.modal.link_matrices` (tested to 1e-9).
* **ZOH, per (Lm, dt)** (:func:`zoh`): ``e^{lam' dt}``, ``(e^{lam' dt} - 1)/lam'`` per mode
  (``lam' = lam - j w``, the frame rotating at w) and the cross integrals of the quadratic terms.
* **Step** (:func:`step`): the two complex mode amplitudes ``z`` (4 reals, i1 or i2 units) under
  the held inputs ``U = [V1, V2]`` (complex phasors, ``x = Re(X e^{j w t})``, ``v1 = V1amp sin wt``
  is ``V1 = -j V1amp``): ``z+ = e z + phi g U``, exactly, with the step's integrals of I1, I2 and
  |I1|^2, |I2|^2 and so its energies (source ``Re(V1 conj I1)/2``, coil + device resistances
  ``(R1 |I1|^2 + R2 |I2|^2)/2``, rectifier ``Re(V2 conj I2)/2``). With ``W = X^H E X / 4``
  (``E`` the inductance and capacitance matrix) they satisfy ``source = dW + coil + rect``
  exactly within a step (the quasi-static negative-frequency part keeps ``dX/dt = (M - jw)X + BU``
  exact for a held U); :func:`stored_energy_j`.
* **SBAR, v2 with its quadrature** (:func:`sbar_v2`): eq. 9 generalised to a commutation angle
  ``e`` off ``pi/2``: ``V2 = sign * Vc (4/pi) (j e^{-j e} - sin(pi d/2))`` (``Vc = VL + Vf``,
  ``e`` clipped into ``[pi d/2, pi - pi d/2]``; ``e = pi/2`` is eq. 9). ``e = pi/2 - arg(I2) + delta``:
  the phase of the fundamental exactly, the harmonics' shift ``delta`` of the zero crossing from a
  table over (arg I2, duty, |I2| / Vc) built once from :class:`wpt_receiver.peak.SbarHarmonics`
  (:func:`build_table`, trilinear lookup). The harmonic balance is homogeneous in (I2, V1, Vc), and
  the inverter-driven part of the ripple is small, so ``delta`` depends on |I2|/Vc, the duty and
  the phase alone, to 0.005 rad over Lm 5.2-6.8 uH, VL 27-33 V, V1 x0.5-1 (the default mission's
  range): one table per link and device set, at its nominal Lm and VL.
* **Instantaneous peak** (:func:`inst_peak`): ``|I2| + Vc * excess(arg I2, d, |I2|/Vc)``, the
  excess of :meth:`SbarHarmonics.peak` over the fundamental from the same table (within 0.1 % of
  the direct evaluation in phase, 0.4 % for |arg I2| <= 0.16 rad (the paper's ramp swings 9 deg),
  |I2| >= 8 A; the phase grid is quadratic, 17 points).

Cost (``benchmarks/bench_modal_step.py``, in-process, 2026-11-25, load average 3.3 on 2 cores):
0.51 us per step (v2 lookup + step with energies + peak lookup) against 0.20 us for eq. 4's step;
1.46 us when Lm changes every step (modes + ZOH recomputed). The small functions a step calls with arrays
(``_lookup``, ``_bilinear``, ``sbar_shift``, ``inst_peak``, ``steady_modes``, ``readout``, ``phasors``) are
inlined (``inline="always"``): numba puts two atomic reference counts per array argument around a call
(~10 % of the modal env step); the arithmetic, and so every result, is unchanged.

The SBAR and peak formulas are small inlined pieces, each the one source of its formula: i2's fold and polar
form (``_fold``, ``_polar``), the table's cell on the phase and rho axes and on the duty axis
(``_phase_rho_coords``, ``_duty_coords``, ``_trilinear``; ``_lookup`` is the three), the window, the shift, the
commutation angle, the clamp part, V2 and the peak (``_window``, ``_shift``, ``_commutation``, ``_clamp_f``,
``_v2_of``, ``_peak_of``). :func:`sbar_edge`, :func:`sbar_v2`, :func:`inst_peak` are made of them, and so is
:func:`held_peak`'s fused sub-step, which shares one i2's polar form and table cell between a sub-step's end
peak and the next sub-step's edge and the duty's terms over its sub-steps (the same numbers bit for bit; ~1.5x
per budget-search stop, docs/budget_search_cost.md).

Validated (``tests/test_modal_kernel.py``) against :func:`wpt_receiver.modal.simulate_modal` on the
three paper trajectories (peak within 0.5 %, in fact ~0.05 %), the switching model on the ramp
(1 %), and across the default mission's Lm and battery range. This module imports numba at
import time; nothing imports it at module level (``wpt_receiver/__init__.py`` does not).
"""

from __future__ import annotations

import cmath
import math

import numpy as np
from numba import njit

from . import modal_link as _modal_link
from .kernel_cache import drop_stale_cache
from .modal_link import (  # noqa: F401 - the layout and constants, one definition each (numba-free module)
    LC_NAMES, LC_L1, LC_L2, LC_R1, LC_R2, LC_C1, LC_C2, LC_W, LC_RHO_MAX, LC_INV_HD, LC_DR_SHORT, LC_INV_HPHI,
    LC_VF, MC_LAM, MC_G1, MC_G2, MC_S, MC_D, N_MODES_C, ZC_E, ZC_PHI, ZC_PSI00, ZC_PSI11, ZC_PSI01, N_ZOH_C, N_D,
    N_RHO, N_PHI, RHO_MAX, _CACHE_VERSION, REFINE_TOL, REFINE_LEVELS, link_constants, table_key, cached_table)
from .devices import IDEAL, DeviceSet
from .params import LinkParams
from .sbar import check_duty_run

__all__ = ["link_constants", "modes", "zoh", "step", "steady_modes", "readout", "advance_z", "phasors", "stored_energy_j", "sbar_v2", "sbar_edge", "sbar_shift", "sbar_clamp_f", "sbar_implicit", "end_i2", "end_i2_affine", "blocking_v2", "short_weight", "inst_peak",
           "build_table", "modal_table", "run_duties", "held_peak", "steady_state", "rect_current_a", "rect_affine", "N_MODES_C", "N_ZOH_C",
           "LC_NAMES", "refine_level", "REFINE_TOL", "REFINE_LEVELS"]


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


# the layout's constants are frozen into this module's cached machine code: dropped when modal_link.py changes
drop_stale_cache(_here, (_modal_link,))


# ---------------------------------------------------------------------- modes (eq. 1), per Lm
@njit(cache=True)
def _poly(lc, lm_h):
    """Coefficients ``a4..a0`` of the characteristic quartic P(s) (module docstring)."""
    l1, l2, r1, r2, c1, c2 = lc[LC_L1], lc[LC_L2], lc[LC_R1], lc[LC_R2], lc[LC_C1], lc[LC_C2]
    return (l1 * l2 - lm_h * lm_h, l1 * r2 + r1 * l2, l1 / c2 + r1 * r2 + l2 / c1, r1 / c2 + r2 / c1, 1.0 / (c1 * c2))


@njit(cache=True)
def _newton_root(a, s):
    """Newton on the quartic ``a`` from ``s`` (complex) to machine precision (quadratic convergence:
    one more step after a relative step below 1e-9)."""
    last = False
    for _ in range(60):
        p = (((a[0] * s + a[1]) * s + a[2]) * s + a[3]) * s + a[4]
        dp = ((4.0 * a[0] * s + 3.0 * a[1]) * s + 2.0 * a[2]) * s + a[3]
        ds = p / dp
        s = s - ds
        if last:
            break
        last = abs(ds) <= 1e-9 * abs(s)
    return s


@njit(cache=True)
def _roots(lc, lm_h):
    """The two roots of P with positive imaginary part [1/s] (stationary frame)."""
    a = _poly(lc, lm_h)
    w = lc[LC_W]
    k = lm_h / math.sqrt(lc[LC_L1] * lc[LC_L2])
    damp = -0.25 * (lc[LC_R1] / lc[LC_L1] + lc[LC_R2] / lc[LC_L2])
    s0 = _newton_root(a, complex(damp, w / math.sqrt(1.0 - k)))
    # deflate by (s - s0)(s - conj s0) = s^2 + b s + c: the quotient a4 (s^2 + p s + q)
    b, c = -2.0 * s0.real, abs(s0) ** 2
    p = a[1] / a[0] - b
    q = a[2] / a[0] - b * p - c
    h = cmath.sqrt(complex(0.25 * p * p - q))
    s1 = -0.5 * p + h
    if s1.imag < 0.0:
        s1 = -0.5 * p - h
    return s0, _newton_root(a, s1)


@njit(cache=True)
def modes(lc, lm_h, mc):
    """Fill ``mc`` (complex, :data:`N_MODES_C`) with the two modes of eq. 1 at mutual inductance
    ``lm_h`` [H]: rotating-frame eigenvalues, input gains, state shapes and the feedthrough of the
    negative-frequency modes (module docstring)."""
    l1, l2, r1, r2, c1, c2, w = lc[LC_L1], lc[LC_L2], lc[LC_R1], lc[LC_R2], lc[LC_C1], lc[LC_C2], lc[LC_W]
    a = _poly(lc, lm_h)
    for m in range(4, N_MODES_C):
        mc[m] = 0.0
    roots = _roots(lc, lm_h)
    for m in range(2):
        s = roots[m]
        z11 = s * l1 + r1 + 1.0 / (s * c1)
        z22 = s * l2 + r2 + 1.0 / (s * c2)
        dp = ((4.0 * a[0] * s + 3.0 * a[1]) * s + 2.0 * a[2]) * s + a[3]
        if abs(z22) >= abs(z11):     # the better conditioned column of adj Z(s), normalised
            qa, qb, ajj = 1.0 + 0j, s * lm_h / z22, z22
        else:
            qa, qb, ajj = s * lm_h / z11, 1.0 + 0j, z11
        gam = s * s * ajj / dp      # residue s^2 adj Z / P' = gam q q^T; inputs [v1, -v2]
        g1, g2 = gam * qa, -gam * qb
        mc[MC_LAM + m] = s - 1j * w
        mc[MC_G1 + m], mc[MC_G2 + m] = g1, g2
        shape = (qa, qb, qa / (c1 * s), qb / (c2 * s))
        for r in range(4):
            mc[MC_S + 4 * m + r] = shape[r]
            den = 1j * w - s.conjugate()        # the conjugate mode, quasi-static at +w
            mc[MC_D + 2 * r] += shape[r].conjugate() * g1.conjugate() / den
            mc[MC_D + 2 * r + 1] += shape[r].conjugate() * g2.conjugate() / den


# ---------------------------------------------------------------------- ZOH, per (Lm, dt)
@njit(cache=True)
def _expm1_over(mu, h):
    """``(e^{mu h} - 1) / mu`` without cancellation (complex mu; h for mu -> 0)."""
    x = mu * h
    if abs(x) < 1e-12:
        return h + 0j
    a, b = x.real, x.imag
    em = math.expm1(a)
    sb, hb = math.sin(b), math.sin(0.5 * b)
    return complex(em * math.cos(b) - 2.0 * hb * hb, em * sb + sb) / mu


@njit(cache=True, _nrt=True)   # explicit: called from envs.modal_step._substeps' _nrt=False compile
def zoh(mc, dt_s, zc):
    """Fill ``zc`` (complex, :data:`N_ZOH_C`) for a held-input step of ``dt_s`` [s]: ``e^{lam' dt}``,
    ``phi = (e^{lam' dt} - 1)/lam'`` per mode, and ``psi_ij = int_0^dt e^{(lam'_i + conj lam'_j) t} dt``."""
    for m in range(2):
        lam = mc[MC_LAM + m]
        phi = _expm1_over(lam, dt_s)
        zc[ZC_PHI + m] = phi
        zc[ZC_E + m] = 1.0 + lam * phi
    l0, l1 = mc[MC_LAM], mc[MC_LAM + 1]
    zc[ZC_PSI00] = _expm1_over(complex(2.0 * l0.real, 0.0), dt_s)
    zc[ZC_PSI11] = _expm1_over(complex(2.0 * l1.real, 0.0), dt_s)
    zc[ZC_PSI01] = _expm1_over(l0 + l1.conjugate(), dt_s)


# ---------------------------------------------------------------------- state -> phasors, the step
@njit(cache=True, inline="always")
def steady_modes(mc, v1, v2):
    """The modes' steady amplitudes ``(zs0, zs1)`` (complex) under the inputs ``v1, v2`` (complex [V]) held:
    ``zs_m = -(g1_m V1 + g2_m V2) / lam'_m`` (eq. 1 in modal form, ``dz/dt = lam' z + g1 V1 + g2 V2``). The
    one source of this formula (the step, the ZOH, the steady state, the blocking V2, the env's and the
    mission's modal links)."""
    zs0 = -(mc[MC_G1] * v1 + mc[MC_G2] * v2) / mc[MC_LAM]
    zs1 = -(mc[MC_G1 + 1] * v1 + mc[MC_G2 + 1] * v2) / mc[MC_LAM + 1]
    return zs0, zs1


@njit(cache=True, inline="always")
def readout(mc, r, z0, z1, v1, v2):
    """State ``r`` of ``[i1, i2, vC1, vC2]`` (phasor [A or V]) of the mode amplitudes ``z0, z1`` (complex)
    under ``v1, v2``: ``S_r0 z0 + S_r1 z1 + D_r1 V1 + D_r2 V2`` (r = 1: I2 = ``S1 z0 + S5 z1 + D2 V1 + D3
    V2``). The one source of the modes' readout."""
    return mc[MC_S + r] * z0 + mc[MC_S + 4 + r] * z1 + mc[MC_D + 2 * r] * v1 + mc[MC_D + 2 * r + 1] * v2


@njit(cache=True, inline="always")
def phasors(mc, z, v1, v2):
    """``(I1, I2)`` phasors [A] of the mode state ``z`` (4 reals) under the inputs ``v1, v2`` (complex [V])."""
    z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
    return readout(mc, 0, z0, z1, v1, v2), readout(mc, 1, z0, z1, v1, v2)


@njit(cache=True)
def advance_z(mc, zc, z, v1, v2):
    """The state part of :func:`step` alone: ``z`` (4 reals) advanced in place over the ``zc`` step."""
    zs0, zs1 = steady_modes(mc, v1, v2)
    n0 = zs0 + zc[ZC_E] * (complex(z[0], z[1]) - zs0)
    n1 = zs1 + zc[ZC_E + 1] * (complex(z[2], z[3]) - zs1)
    z[0], z[1], z[2], z[3] = n0.real, n0.imag, n1.real, n1.imag


@njit(cache=True, _nrt=True)   # explicit: called from envs.modal_step._substeps' _nrt=False compile
def stored_energy_j(lc, mc, z, v1, v2, lm_h):
    """Cycle-averaged stored energy ``W = X^H E X / 4`` [J] of the coils and capacitors."""
    x = np.empty(4, dtype=np.complex128)
    z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
    for r in range(4):
        x[r] = readout(mc, r, z0, z1, v1, v2)
    wl = lc[LC_L1] * abs(x[0]) ** 2 + lc[LC_L2] * abs(x[1]) ** 2 - 2.0 * lm_h * (x[0] * x[1].conjugate()).real
    return 0.25 * (wl + lc[LC_C1] * abs(x[2]) ** 2 + lc[LC_C2] * abs(x[3]) ** 2)


@njit(cache=True)
def _quad(ss, c0, c1, phi0, phi1, zc, dt_s):
    """``(int X dt, int |X|^2 dt)`` of ``X(t) = ss + c0 e^{lam'_0 t} + c1 e^{lam'_1 t}``."""
    lin = c0 * phi0 + c1 * phi1
    sq = (abs(ss) ** 2 * dt_s + 2.0 * (ss.conjugate() * lin).real + abs(c0) ** 2 * zc[ZC_PSI00].real
          + abs(c1) ** 2 * zc[ZC_PSI11].real + 2.0 * (c0 * c1.conjugate() * zc[ZC_PSI01]).real)
    return ss * dt_s + lin, sq


@njit(cache=True, _nrt=True)   # explicit: called from envs.modal_step._substeps' _nrt=False compile
def step(lc, mc, zc, dt_s, z, v1, v2, out):
    """Advance the mode state ``z`` (4 reals, in place) over ``dt_s`` [s] with ``v1, v2`` (complex
    phasors [V]) held; ``out`` (float, 9): ``int I1 dt`` (re, im) [C], ``int I2 dt`` (re, im) [C],
    ``int |I1|^2 dt``, ``int |I2|^2 dt`` [A^2 s], and the energies [J]: source, coil (R1, R2 with the
    devices' resistances), rectifier (module docstring)."""
    z0, z1 = complex(z[0], z[1]), complex(z[2], z[3])
    zs0, zs1 = steady_modes(mc, v1, v2)
    c0, c1 = z0 - zs0, z1 - zs1
    e0, e1 = zc[ZC_E], zc[ZC_E + 1]
    n0, n1 = zs0 + e0 * c0, zs1 + e1 * c1
    z[0], z[1], z[2], z[3] = n0.real, n0.imag, n1.real, n1.imag
    s10, s20, s11, s21 = mc[MC_S], mc[MC_S + 1], mc[MC_S + 4], mc[MC_S + 5]
    ss1, ss2 = readout(mc, 0, zs0, zs1, v1, v2), readout(mc, 1, zs0, zs1, v1, v2)
    p0, p1 = zc[ZC_PHI], zc[ZC_PHI + 1]
    int1, sq1 = _quad(ss1, s10 * c0, s11 * c1, p0, p1, zc, dt_s)
    int2, sq2 = _quad(ss2, s20 * c0, s21 * c1, p0, p1, zc, dt_s)
    out[0], out[1], out[2], out[3], out[4], out[5] = int1.real, int1.imag, int2.real, int2.imag, sq1, sq2
    out[6] = 0.5 * (v1 * int1.conjugate()).real
    out[7] = 0.5 * (lc[LC_R1] * sq1 + lc[LC_R2] * sq2)
    out[8] = 0.5 * (v2 * int2.conjugate()).real


@njit(cache=True, _nrt=True)   # explicit: called from envs.modal_step._substeps' _nrt=False compile
def rect_current_a(f_clamp, int_i2, dt_s):
    """DC current [A] into the clamp (battery + diode drops) over a step: the rectifier's power on
    the clamp, ``Re(Vc F conj(I2))/2``, over Vc (``f_clamp`` = V2's clamp part per volt, from
    :func:`sbar_v2`; ``int_i2`` = the step's ``int I2 dt`` [C]); eq. 4's ``(V2/VL) I2 / 2`` for F real."""
    return 0.5 * (f_clamp * int_i2.conjugate()).real / dt_s


@njit(cache=True)
def rect_affine(mc, zc, dt_s, z, v1, f_clamp, v2x):
    """``(a0 [A], a1 [A/V])`` with the step's mean DC current into the clamp ``I_L = a0 + a1 VL`` when
    ``V2 = F (VL + Vf) + excess = F VL + v2x`` is held over the step from state ``z`` (the battery
    node's implicit VL solve: with ``VL = A0 + G (I_L - P/VL)`` a quadratic in VL, as eq. 4's loop).
    ``int I2 dt = s0 + s1 V2`` is affine in V2; ``I_L`` = :func:`rect_current_a`."""
    s1 = mc[MC_D + 3] * dt_s
    s0 = mc[MC_D + 2] * v1 * dt_s
    for m in range(2):
        lam, phi, sh = mc[MC_LAM + m], zc[ZC_PHI + m], mc[MC_S + 4 * m + 1]
        s0 += sh * (complex(z[2 * m], z[2 * m + 1]) * phi - mc[MC_G1 + m] * v1 / lam * (dt_s - phi))
        s1 -= sh * mc[MC_G2 + m] / lam * (dt_s - phi)
    a0 = 0.5 * (f_clamp * (s0 + s1 * v2x).conjugate()).real / dt_s
    a1 = 0.5 * abs(f_clamp) ** 2 * s1.real / dt_s
    return a0, a1


# ---------------------------------------------------------------------- SBAR (eq. 9 with its quadrature)
@njit(cache=True, inline="always")
def _bilinear(tab, plane, m, j, k, fx, fy):
    return ((tab[plane, m, j, k] * (1 - fx) + tab[plane, m, j + 1, k] * fx) * (1 - fy)
            + (tab[plane, m, j, k + 1] * (1 - fx) + tab[plane, m, j + 1, k + 1] * fx) * fy)


@njit(cache=True, inline="always")
def _phase_rho_coords(lc, tab, phi, rho):
    """The table's cell and fractions on the phase and |I2|/Vc axes, ``(m, k, fz, fy)``, at phase ``phi`` [rad]
    (its magnitude clamped at pi/2: a phase beyond +-pi/2 takes the edge's cell) and ``rho = |I2|/Vc`` [A/V]
    (both grids quadratic, :func:`build_table`; rho clamped at its top). Shared by both planes and every duty."""
    u = min(abs(phi) / (0.5 * math.pi), 1.0) ** 0.5
    z = (1.0 + (u if phi >= 0.0 else -u)) * lc[LC_INV_HPHI]
    y = math.sqrt(min(rho / lc[LC_RHO_MAX], 1.0)) * (tab.shape[3] - 1)
    m = min(int(z), tab.shape[1] - 2)
    k = min(int(y), tab.shape[3] - 2)
    return m, k, z - m, y - k


@njit(cache=True, inline="always")
def _duty_coords(lc, tab, d):
    """The table's cell and fraction on the duty axis, ``(j, fx)``, at duty ``d`` (clipped into [0, 1])."""
    x = min(max(d, 0.0), 1.0) * lc[LC_INV_HD]
    j = min(int(x), tab.shape[2] - 2)
    return j, x - j


@njit(cache=True, inline="always")
def _trilinear(tab, plane, m, j, k, fz, fx, fy):
    """Table plane ``plane`` interpolated in the cell ``(m, j, k)`` (phase, duty, rho) at the fractions ``fz,
    fx, fy`` (:func:`_phase_rho_coords`, :func:`_duty_coords`)."""
    return _bilinear(tab, plane, m, j, k, fx, fy) * (1 - fz) + _bilinear(tab, plane, m + 1, j, k, fx, fy) * fz


@njit(cache=True, inline="always")
def _lookup(lc, tab, plane, phi, d, rho):
    """Trilinear lookup of table plane ``plane`` at phase ``phi`` [rad] in [-pi/2, pi/2], duty ``d``
    and ``rho = |I2|/Vc`` (both grids quadratic, :func:`build_table`; rho clamped at its top)."""
    m, k, fz, fy = _phase_rho_coords(lc, tab, phi, rho)
    j, fx = _duty_coords(lc, tab, d)
    return _trilinear(tab, plane, m, j, k, fz, fx, fy)


@njit(cache=True, inline="always")
def _fold(i2):
    """``(sgn, ih)``: the sign of Re i2 (+1 at Re i2 = 0) and the sign-folded phasor ``ih = sgn i2`` (Re >= 0) [A]."""
    if i2.real < 0.0:
        return -1.0, -i2
    return 1.0, i2


@njit(cache=True, inline="always")
def _polar(ih, vc_v):
    """``(|ih| [A], rho = |ih|/Vc [A/V], arg ih [rad])`` of the sign-folded phasor ``ih`` at clamp ``vc_v`` [V]
    (rho 0 for Vc <= 0, the phase 0 at ih = 0): the table's coordinates of both planes."""
    amp = abs(ih)
    rho = amp / vc_v if vc_v > 0.0 else 0.0
    phi = math.atan2(ih.imag, ih.real) if amp > 0.0 else 0.0
    return amp, rho, phi


@njit(cache=True, inline="always")
def _window(d_short):
    """Half-width of the short window ``pi d / 2`` [rad] (d clipped into [0, 1]): the conduction window is
    ``[pi d/2, pi - pi d/2]``."""
    return 0.5 * math.pi * min(max(d_short, 0.0), 1.0)


@njit(cache=True, inline="always")
def _shift(lc, plane0, rho):
    """The harmonics' shift ``delta`` [rad] from the table's plane-0 value ``plane0`` at ``rho`` (beyond the
    table's top ``delta ~ 1/rho``)."""
    rmax = lc[LC_RHO_MAX]
    return plane0 * (1.0 if rho <= rmax else rmax / rho)


@njit(cache=True, inline="always")
def _commutation(delta, phi, wd):
    """The commutation angle ``e = pi/2 + delta - arg(ih)`` [rad] clipped into the window ``[wd, pi - wd]``."""
    return min(max(0.5 * math.pi + delta - phi, wd), math.pi - wd)


@njit(cache=True, inline="always")
def _clamp_f(sin_wd, e, sgn):
    """V2's clamp part per volt [1], ``sgn (4/pi) (j e^{-j e} - sin(pi d/2))``, with ``sin_wd = sin(pi d/2)``."""
    return sgn * (4.0 / math.pi) * complex(math.sin(e) - sin_wd, math.cos(e))


@njit(cache=True, inline="always")
def _v2_of(vc_v, f, ws_ohm, i2):
    """V2 [V] of the clamp part ``f`` at clamp ``vc_v`` [V] plus the shorted channels' excess ``ws_ohm i2``
    (``ws_ohm = (2 Ron - Rd) w(d)`` [ohm], :func:`short_weight`)."""
    return vc_v * f + ws_ohm * i2


@njit(cache=True, inline="always")
def _peak_of(amp, vc_v, plane1):
    """Instantaneous peak [A]: ``|I2| + Vc excess`` with the table's plane-1 value ``plane1``."""
    return amp + vc_v * plane1


@njit(cache=True)
def sbar_edge(lc, tab, d_short, ih, vc_v):
    """Commutation angle ``e`` [rad] of the SBAR (the falling zero crossing of i2, clipped into the
    conduction window ``[pi d/2, pi - pi d/2]``) for the sign-folded i2 phasor ``ih`` [A] (Re >= 0
    in use; a phase beyond +-pi/2 clips to a window edge) at duty ``d_short`` and clamp ``vc_v`` [V]:
    ``e = pi/2 - arg(ih) + delta`` with the harmonics' shift ``delta`` (module docstring)."""
    amp, rho, phi = _polar(ih, vc_v)
    pl = min(max(phi, -0.5 * math.pi), 0.5 * math.pi)
    delta = _shift(lc, _lookup(lc, tab, 0, pl, d_short, rho), rho)
    return _commutation(delta, phi, _window(d_short))


@njit(cache=True, inline="always")
def sbar_shift(lc, tab, d_short, ih, vc_v):
    """The harmonics' shift ``delta`` [rad] of the commutation angle (:func:`sbar_edge`'s ``e = pi/2 -
    arg(ih) + delta`` before the window's clip) for the sign-folded i2 phasor ``ih`` [A] at duty
    ``d_short`` and clamp ``vc_v`` [V]: the table's plane 0 (the envs hold it over a control period)."""
    amp, rho, phi = _polar(ih, vc_v)
    pl = min(max(phi, -0.5 * math.pi), 0.5 * math.pi)
    return _shift(lc, _lookup(lc, tab, 0, pl, d_short, rho), rho)


@njit(cache=True)
def sbar_clamp_f(d_short, e, sgn):
    """V2's clamp part per volt [1] at commutation angle ``e`` [rad] (:func:`sbar_edge`) and i2 sign
    ``sgn``: ``sgn (4/pi) (j e^{-j e} - sin(pi d/2))`` (eq. 9 for ``e = pi/2``)."""
    return _clamp_f(math.sin(_window(d_short)), e, sgn)


@njit(cache=True)
def sbar_v2(lc, tab, d_short, i2, vc_v):
    """``(V2, F)``: the SBAR's complex fundamental [V] at duty ``d_short`` and i2 phasor ``i2`` [A]
    with clamp ``vc_v = VL + Vf`` [V], and its clamp part per volt ``F`` (``V2 = Vc F + excess``;
    module docstring, eq. 9 for ``e = pi/2``)."""
    sgn, ih = _fold(i2)
    f = sbar_clamp_f(d_short, sbar_edge(lc, tab, d_short, ih, vc_v), sgn)
    return _v2_of(vc_v, f, lc[LC_DR_SHORT] * short_weight(d_short), i2), f


@njit(cache=True)
def short_weight(d_short):
    """Share of the short window in the conduction, ``w(d) = d + sin(pi d) / pi`` [1]: the shorted
    channels' excess resistance enters V2 as ``(2 Ron - Rd) w(d) I2`` (:func:`wpt_receiver.sbar.short_weight`)."""
    return d_short + math.sin(math.pi * d_short) / math.pi


@njit(cache=True, inline="always")
def refine_level(i2s, i2e, rtol, levels):
    """The refinement level of a sub-step whose I2 phasor went from ``i2s`` to ``i2e`` [A] (V2 held over it,
    decided at its end: a backward-Euler step on the envelope mode the clamp's load ``(4/pi) Vc / |I2|`` makes,
    ``2 L2 / R`` ~ 2 rectifier periods at 11 A, which damps and delays a large transient's ringing): 0 when
    ``|i2e - i2s| <= rtol max(|i2s|, |i2e|)``, else the least L with ``|i2e - i2s| / 2^L <= rtol max(...)``, at
    most ``levels``. The caller redoes the sub-step in 2^L pieces (the env's ``envs.modal_step._refine``, the
    mission's ``loop_kernel._sub_step``); below ``rtol`` its arithmetic is unchanged (docs/performance.md,
    "Adaptive refinement of the modal env step")."""
    dd = i2e - i2s
    d2 = dd.real * dd.real + dd.imag * dd.imag
    ref = rtol * rtol * max(i2s.real * i2s.real + i2s.imag * i2s.imag, i2e.real * i2e.real + i2e.imag * i2e.imag)
    lev = 0
    while d2 > ref and lev < levels:
        lev += 1
        d2 *= 0.25
    return lev


@njit(cache=True)
def end_i2(mc, zc, z0, z1, v1, v2):
    """I2 phasor [A] at the end of the ``zc`` step from the mode amplitudes ``z0, z1`` (complex) with
    ``v1, v2`` held (:func:`advance_z` then :func:`phasors`, the same arithmetic on scalars)."""
    zs0, zs1 = steady_modes(mc, v1, v2)
    n0 = zs0 + zc[ZC_E] * (z0 - zs0)
    n1 = zs1 + zc[ZC_E + 1] * (z1 - zs1)
    return readout(mc, 1, n0, n1, v1, v2)


@njit(cache=True)
def end_i2_affine(mc, zc, z0, z1, v1):
    """The step's end I2 phasor as affine in the held V2, ``i2_end = q0 + q1 V2``: ``(q0, q1)`` [A, A/V]
    (:func:`end_i2` at V2 = 0 and per volt)."""
    q0 = end_i2(mc, zc, z0, z1, v1, 0j)
    return q0, end_i2(mc, zc, z0, z1, v1, 1.0 + 0j) - q0


@njit(cache=True)
def _edge_gap(lc, tab, d, e, sgn, vc, ws, q0, q1, den):
    """``e - e_end`` [rad]: the commutation angle ``e`` against the one of the step's end i2 when the v2
    of ``e`` is held (:func:`sbar_implicit`)."""
    f = sbar_clamp_f(d, e, sgn)
    i2e = q0 + q1 * (f * vc + ws * q0) / den
    return e - sbar_edge(lc, tab, d, i2e * sgn, vc)


@njit(cache=True)
def _secant_edge(lc, tab, d, sgn, vc, ws, q0, q1, den, lo, hi, e0, tol):
    """Root of :func:`_edge_gap` in ``[lo, hi]`` by the secant from ``e0`` (its first step the fixed-point
    one, ``e0 - g(e0)``), iterates clipped to the window: ``(e, converged)``; converged when a step is
    below ``tol`` [rad] (at a window end when the root is beyond it, as the bracket gives)."""
    e0 = min(max(e0, lo), hi)
    g0 = _edge_gap(lc, tab, d, e0, sgn, vc, ws, q0, q1, den)
    if g0 == 0.0:
        return e0, True
    e1 = min(max(e0 - g0, lo), hi)
    for _ in range(8):
        if abs(e1 - e0) <= tol:
            return e1, True
        g1 = _edge_gap(lc, tab, d, e1, sgn, vc, ws, q0, q1, den)
        if g1 == 0.0:
            return e1, True
        if g1 == g0:
            return e1, False
        e0, g0, e1 = e1, g1, min(max(e1 - g1 * (e1 - e0) / (g1 - g0), lo), hi)
    return e1, False


@njit(cache=True, _nrt=True)   # explicit: called from envs.modal_step._substeps' _nrt=False compile
def sbar_implicit(lc, tab, mc, zc, z0, z1, v1, v2_held, d_short, vc_v, ws, e_guess=-1.0, tol=1e-13):
    """The SBAR's v2 held over the ``zc`` step from the mode amplitudes ``z0, z1`` (complex) under ``v1``:
    ``(F, i2e)``, its clamp part per volt and the step's end I2 [A], ``V2 = F vc_v + ws i2e`` (``ws``
    [ohm] the shorted switches' excess ``(2 Ron - Rd) w(d)``; ``vc_v = VL + Vf`` [V]); ``v2_held`` the V2
    of the last step (only the sign of the start's i2 is taken from it).

    Implicit (backward Euler in the commutation): the commutation angle ``e`` is the one the i2 at the
    step's *end* has, with the v2 of ``e`` held over the step. The quadrature of v2 turns i2's phase
    back towards the conduction window (negative feedback), with a gain ``(4/pi) Vc dt / (2 L2 |I2|)``
    per step that is > 1 at small |I2| near short mode (a window of a few hundredths of a rad) or for
    long steps: explicit v2 (or a predictor-corrector) then overshoots step to step (period-2 chatter
    that amplifies rounding by orders of magnitude), where the circuit pins the zero crossing in the
    window (sliding). ``i2_end = q0 + q1 V2`` is affine in the held V2 and ``e_end(e)`` decreases in
    ``e``, so ``g(e) = e - e_end(e)`` has one root in the window (``g <= 0`` at its start, ``>= 0`` at
    its end): bracketed (Illinois) to ``tol`` [rad] (1e-13), a continuous function of the state. The sign
    of i2 is the step start's (at Re I2 = 0 both signs give the same F). With ``e_guess >= 0`` (the last
    step's angle) a secant from it comes first (:func:`_secant_edge`: ``g`` is increasing with slope
    >= 1, so it converges in a few lookups), the bracket on the window only when it does not. Returns
    ``(F, i2e, e)``."""
    d = d_short
    vc = vc_v
    i2a = readout(mc, 1, z0, z1, v1, v2_held)
    sgn = -1.0 if i2a.real < 0.0 else 1.0
    q0, q1 = end_i2_affine(mc, zc, z0, z1, v1)
    den = 1.0 - ws * q1
    wd = 0.5 * math.pi * min(max(d, 0.0), 1.0)
    lo, hi = wd, math.pi - wd
    if hi - lo <= 0.0:
        e = 0.5 * math.pi
    else:
        warm, glo, ghi = False, 0.0, 0.0
        if e_guess >= 0.0:
            e, warm = _secant_edge(lc, tab, d, sgn, vc, ws, q0, q1, den, lo, hi, e_guess, tol)
            if warm:
                lo, hi = e, e
        if not warm:
            glo, ghi = _edge_gap(lc, tab, d, lo, sgn, vc, ws, q0, q1, den), _edge_gap(lc, tab, d, hi, sgn, vc, ws, q0, q1, den)
        e, side = lo, 0
        if warm:
            pass
        elif glo >= 0.0:
            e, hi = lo, lo
        elif ghi <= 0.0:
            e, lo = hi, hi
        for _ in range(100):
            if hi - lo <= tol:
                break
            e = (lo * ghi - hi * glo) / (ghi - glo)
            e = min(max(e, lo), hi)
            g = _edge_gap(lc, tab, d, e, sgn, vc, ws, q0, q1, den)
            if g == 0.0:
                break
            if g < 0.0:
                lo, glo = e, g
                if side == -1:
                    ghi *= 0.5
                side = -1
            else:
                hi, ghi = e, g
                if side == 1:
                    glo *= 0.5
                side = 1
    f = sbar_clamp_f(d, e, sgn)
    return f, q0 + q1 * (f * vc + ws * q0) / den, e


@njit(cache=True, inline="always")
def inst_peak(lc, tab, d_short, i2, vc_v):
    """Instantaneous peak |i2| [A] at duty ``d_short`` for the fundamental phasor ``i2`` [A] (complex)
    and clamp ``vc_v`` [V]: ``|I2| + Vc excess(arg I2, d, |I2|/Vc)`` (:meth:`SbarHarmonics.peak`, tabulated)."""
    amp, rho, phi = _polar(_fold(i2)[1], vc_v)
    return _peak_of(amp, vc_v, _lookup(lc, tab, 1, phi, d_short, rho))


# ---------------------------------------------------------------------- the table (built once, numpy)
@njit(cache=True)
def _ripple(hv1, y2, n, vc, d, ec, ih):
    """Harmonic phasors of i2 (n >= 3) into ``ih``: the inverter's plus the SBAR's with its falling edge
    at ``ec`` (:meth:`wpt_receiver.peak.SbarHarmonics.v2_harmonics`)."""
    wd = 0.5 * math.pi * d
    for k in range(len(n)):
        nk = n[k]
        v = (2.0 * vc / (1j * nk * math.pi)) * (cmath.exp(-1j * nk * wd) - 2.0 * cmath.exp(-1j * nk * ec)
                                                  + cmath.exp(-1j * nk * (math.pi - wd)))
        ih[k] = hv1[k] + y2[k] * v


@njit(cache=True)
def _wave(theta, i1h, ih):
    """``(i2, di2/dtheta)`` at ``theta`` from the fundamental and the odd harmonics 3, 5, ... (recurrence)."""
    e1 = cmath.exp(1j * theta)
    e2 = e1 * e1
    g = (i1h * e1).real
    dg = (1j * i1h * e1).real
    en = e1
    for k in range(len(ih)):
        en = en * e2
        t = ih[k] * en
        g += t.real
        dg -= (2 * k + 3) * t.imag
    return g, dg


@njit(cache=True)
def _newton_edge(e, i1h, ih, steps, lo, hi):
    """Newton on the falling zero crossing of i2 (harmonics held), steps clipped to 0.3 rad, e to [lo, hi]."""
    for _ in range(steps):
        g, dg = _wave(e, i1h, ih)
        step = g / dg if dg < 0.0 else 0.0
        e = min(max(e - min(max(step, -0.3), 0.3), lo), hi)
    return e


@njit(cache=True)
def _balance_point(hv1, y2, n, vc, d, i1h, ih):
    """:meth:`SbarHarmonics.balance` for one in-phase-folded phasor (Re >= 0): harmonics at the clipped
    edge into ``ih``; returns the zero crossing itself (not clipped to the gate window) [rad]."""
    wd = 0.5 * math.pi * d
    amp = abs(i1h)
    e = 0.5 * math.pi - (math.atan2(i1h.imag, i1h.real) if amp > 0 else 0.0)
    for _ in range(6):
        _ripple(hv1, y2, n, vc, d, min(max(e, wd), math.pi - wd), ih)
        e = _newton_edge(e, i1h, ih, 3, -1e300, 1e300)
    _ripple(hv1, y2, n, vc, d, min(max(e, wd), math.pi - wd), ih)
    return _newton_edge(min(max(e, wd), math.pi - wd), i1h, ih, 6, 0.0, math.pi)


@njit(cache=True)
def _peak_point(i1h, ih, n_theta):
    """``max_theta |i2|`` on ``n_theta`` phases of a period, refined by a parabola (``peak._grid_max``).
    Odd harmonics only: ``|i2|`` has period pi, so the first half of the grid (``n_theta`` even) holds
    every value once (and its wrap-around the neighbours)."""
    m = n_theta // 2
    y = np.empty(m)
    for i in range(m):
        y[i] = abs(_wave(-math.pi + 2.0 * math.pi * i / n_theta, i1h, ih)[0])
    j = int(np.argmax(y))
    ym, y0, yp = y[j - 1], y[j], y[(j + 1) % m]
    den = ym - 2 * y0 + yp
    u = min(max(0.5 * (ym - yp) / den, -0.5), 0.5) if den < 0 else 0.0
    return max(y0 - 0.25 * (ym - yp) * u, y0)


@njit(cache=True)
def _fill_table(hv1, y2, n, vc, phis, ds, rhos, n_theta, tab):
    ih = np.empty(len(n), dtype=np.complex128)
    for a in range(len(phis)):
        for b in range(len(ds)):
            for c in range(len(rhos)):
                amp = rhos[c] * vc
                i1h = complex(amp * max(math.cos(phis[a]), 0.0), amp * math.sin(phis[a]))
                e = _balance_point(hv1, y2, n, vc, ds[b], i1h, ih)
                # relative to the fundamental's own crossing pi/2 - phi also at |I2| = 0 (the ripple's
                # crossing there, the same for every phase): sbar_edge's e is continuous as |I2| -> 0
                tab[0, a, b, c] = e - 0.5 * math.pi + phis[a]
                tab[1, a, b, c] = (_peak_point(i1h, ih, n_theta) - amp) / vc


def build_table(params: LinkParams, devices: DeviceSet = IDEAL, n_d: int = N_D, n_rho: int = N_RHO,
                n_phi: int = N_PHI, c1_f=None, c2_f=None) -> np.ndarray:
    """``(2, n_phi, n_d, n_rho)`` table on the fundamental's phase ``arg I2`` on ``(pi/2) u |u|``,
    ``u = linspace(-1, 1, n_phi)`` [rad] (quadratic: dense near the in-phase operation; the
    sign-folded phasor has Re >= 0) x duty ``linspace(0, 1, n_d)`` x ``rho = |I2|/Vc`` [A/V] on
    ``RHO_MAX linspace(0, 1, n_rho)**2``: plane 0 the commutation shift ``delta = e - (pi/2 - arg I2)``
    [rad] (the zero crossing of fundamental + ripple against the fundamental's own, not clipped to
    the gate window; :func:`sbar_v2` clips), plane 1 the peak excess ``(peak - |I2|)/Vc`` [A/V].
    The harmonic balance and the peak search of :class:`wpt_receiver.peak.SbarHarmonics` (its
    coefficients at ``params``: Lm, VL, V1, and ``devices``; n <= 63, 512 phases), compiled
    (equal to the numpy class to rounding, ``tests/test_modal_kernel.py``)."""
    from .peak import SbarHarmonics
    sh = SbarHarmonics(params, devices, c1_f=c1_f, c2_f=c2_f)
    assert np.array_equal(sh.n, np.arange(3, 2 * len(sh.n) + 3, 2)) and len(sh.theta) % 2 == 0   # _wave, _peak_point
    u = np.linspace(-1.0, 1.0, n_phi)
    tab = np.empty((2, n_phi, n_d, n_rho))
    _fill_table(sh.i2_from_v1, sh.y2, sh.n.astype(np.float64), sh.clamp_v, 0.5 * np.pi * u * np.abs(u),
                np.linspace(0.0, 1.0, n_d), RHO_MAX * np.linspace(0.0, 1.0, n_rho) ** 2, len(sh.theta), tab)
    return tab


def modal_table(params: LinkParams, devices: DeviceSet = IDEAL) -> np.ndarray:
    """:func:`build_table` of a resonant link, from the disk cache (:mod:`wpt_receiver.diskcache`) when there
    (:func:`.modal_link.cached_table`), built and stored on a miss."""
    from . import diskcache
    tab = cached_table(params, devices)
    if tab is None:
        tab = build_table(params, devices)
        diskcache.store("modal_table", table_key(params, devices), tab)
    return tab


# ---------------------------------------------------------------------- runs of a duty sequence
@njit(cache=True)
def blocking_v2(mc, v1):
    """The V2 phasor [V] whose steady state under ``v1`` has I2 = 0 (I2 is affine in the held V2:
    ``I2 = c0 + c1 V2`` from the modes' steady amplitudes and the feedthrough). The rectifier can block
    in steady state at duty d iff ``|blocking_v2| <= (4/pi) Vc (1 - sin(pi d/2))`` (the induced emf
    below the clamp; a strongly detuned C1)."""
    zs0, zs1 = steady_modes(mc, v1, 0j)
    c0 = readout(mc, 1, zs0, zs1, v1, 0j)                  # the steady I2 at V2 = 0 [A]
    zs0, zs1 = steady_modes(mc, 0j, 1.0 + 0j)
    c1 = readout(mc, 1, zs0, zs1, 0j, 1.0 + 0j)            # the steady I2 per volt of V2 [A/V]
    return -c0 / c1


@njit(cache=True)
def steady_state(lc, mc, tab, d_short, v1, vc_v, z, iters=60):
    """Periodic steady state at a constant duty into ``z`` (fixed point on V2); returns V2 [V]. When the
    V2 that holds the steady I2 at 0 is within the clamp ``(4/pi) Vc (1 - sin(pi d/2))`` (the induced emf
    below the clamp: a strongly detuned C1) the rectifier blocks: that V2, I2 = 0 (the fixed point has
    no conducting solution there and would not converge)."""
    clamp = (4.0 / math.pi) * vc_v * (1.0 - math.sin(0.5 * math.pi * d_short))
    v2b = blocking_v2(mc, v1)
    if abs(v2b) <= clamp:
        zs0, zs1 = steady_modes(mc, v1, v2b)
        z[0], z[1], z[2], z[3] = zs0.real, zs0.imag, zs1.real, zs1.imag
        return v2b
    v2 = clamp + 0j
    for _ in range(iters):
        zs0, zs1 = steady_modes(mc, v1, v2)
        z[0], z[1], z[2], z[3] = zs0.real, zs0.imag, zs1.real, zs1.imag
        new = sbar_v2(lc, tab, d_short, phasors(mc, z, v1, v2)[1], vc_v)[0]
        if abs(new - v2) <= 1e-13 * (1.0 + abs(v2)):
            return new
        v2 = new
    return v2


@njit(cache=True)
def run_duties(lc, mc, tab, d_short, control_period_s, substeps, v1, vc_v, lm_h):
    """:meth:`wpt_receiver.modal.ModalEnvelope.run` compiled: duties held one per control period,
    V2 updated every ``control_period_s / substeps``, from the steady state of the first duty.
    Returns ``(i1, i2, v2, peak, energies)``: phasors per period end (plus the start), the
    instantaneous peak there [A], and ``[source, coil, rect, W_end - W_start, jumps]`` [J] (``jumps``:
    the stored energy of the feedthrough when V2 changes between steps; the balance is
    ``source = dW + coil + rect - jumps``)."""
    n = len(d_short)
    h = control_period_s / substeps
    zc = np.empty(N_ZOH_C, dtype=np.complex128)
    zoh(mc, h, zc)
    z = np.zeros(4)
    v2 = steady_state(lc, mc, tab, d_short[0], v1, vc_v, z)
    i1o, i2o, v2o = np.empty(n + 1, np.complex128), np.empty(n + 1, np.complex128), np.empty(n + 1, np.complex128)
    pk, en, out = np.empty(n + 1), np.zeros(5), np.empty(9)
    i1o[0], i2o[0] = phasors(mc, z, v1, v2)
    v2o[0], pk[0] = v2, inst_peak(lc, tab, d_short[0], i2o[0], vc_v)
    w_start = stored_energy_j(lc, mc, z, v1, v2, lm_h)
    for k in range(n):
        dk = d_short[k]
        for _ in range(substeps):
            new = sbar_v2(lc, tab, dk, phasors(mc, z, v1, v2)[1], vc_v)[0]
            en[4] += stored_energy_j(lc, mc, z, v1, new, lm_h) - stored_energy_j(lc, mc, z, v1, v2, lm_h)
            v2 = new
            step(lc, mc, zc, h, z, v1, v2, out)
            en[0] += out[6]
            en[1] += out[7]
            en[2] += out[8]
        i1o[k + 1], i2o[k + 1] = phasors(mc, z, v1, v2)
        v2o[k + 1], pk[k + 1] = v2, inst_peak(lc, tab, dk, i2o[k + 1], vc_v)
    en[3] = stored_energy_j(lc, mc, z, v1, v2, lm_h) - w_start
    return i1o, i2o, v2o, pk, en



@njit(cache=True)
def held_peak(lc, mc, tab, zc, z, v2, d_short, substeps, v1, vc_v, k_tail, tail_vinv, tail_x, tail_w, tail_cap,
              i2_ref=1.0, above=math.inf):
    """The instantaneous peak [A] of a run of held duties without its energies: :func:`run_duties`' steps (V2
    from i2's phase at each step's start, :func:`sbar_v2`; the state part of :func:`step`, :func:`advance_z`;
    :func:`inst_peak` at each step's end) from the mode state ``z`` (4 reals, advanced in place) under the
    V2 ``v2`` [V] held before it, each duty of ``d_short`` held ``substeps`` steps of ``zc``. Returns ``(max
    peak over every step's end, the last V2)``: the same arithmetic as :func:`run_duties` with ``substeps=1``
    on the duties repeated, so the same peaks bit for bit (``tests/test_budget_modal.py``); NaN when a peak is
    NaN (as numpy's ``max``). Fused: :func:`sbar_v2`'s and :func:`inst_peak`'s pieces, i2's polar form and table
    cell computed once per sub-step end for the peak there and the next edge, the duty's window sine, short
    weight and duty cell once per duty (the edge's phase clip is left out: it does not move the cell).

    **Stopping early without changing the max.** From the duty ``k_tail`` on every duty is 1 (short mode; pass
    ``len(d_short)`` for none): V2 is then the shorted switches' ``ws I2`` (plus ``Vc (4/pi) cos(pi/2)``,
    ~1e-15 V) and the step is affine in ``x = (z0, z1, V2)``, ``x+ - x* = M (x - x*)``, with ``M = V diag(lam)
    V^-1`` (``|lam| < 1``). After a step of that tail, ``|I2| <= |I2*| + sum_i tail_w_i |(V^-1 (x - x*))_i|``
    at every later step (``tail_w_i = |(C V)_i| |lam_i|``, ``C`` I2's readout of ``x``; ``tail_vinv`` = V^-1,
    ``tail_x`` = x*) and the peak exceeds ``|I2|`` by at most the table's largest excess at duty 1: with
    ``tail_cap`` = ``|I2*|`` + ``Vc`` times that excess + a margin for the rounding, no later peak can reach
    the max once ``tail_cap + sum_i ...`` is below it, and the run returns then (the max unchanged; the V2
    returned is then the last one computed). Built by :func:`policies.budget_modal._tail_bound`.

    **Stopping once above.** With ``above`` finite the run also returns as soon as the max so far, as the
    overshoot ``pmax / i2_ref - 1`` (the same arithmetic as the caller's), exceeds ``above``: the returned max is
    then a lower bound of the run's (the whole run's overshoot is above ``above`` too)."""
    pmax = -math.inf
    i2 = phasors(mc, z, v1, v2)[1]
    # the fused sub-step: i2's fold, polar form and table cell at a sub-step's end serve both its peak and the
    # next sub-step's edge; the duty's window, sine, short weight and duty cell once per duty. The pieces of
    # sbar_v2 / inst_peak, so their arithmetic (the edge's phase clip leaves the cell unchanged: a phase beyond
    # +-pi/2 has |u| = 1 either way, and the folded phase is within it)
    sgn, ih = _fold(i2)
    amp, rho, phi = _polar(ih, vc_v)
    m, kk, fz, fy = _phase_rho_coords(lc, tab, phi, rho)
    for k in range(len(d_short)):
        dk = d_short[k]
        wd = _window(dk)
        sin_wd = math.sin(wd)
        ws = lc[LC_DR_SHORT] * short_weight(dk)
        j, fx = _duty_coords(lc, tab, dk)
        for _ in range(substeps):
            e = _commutation(_shift(lc, _trilinear(tab, 0, m, j, kk, fz, fx, fy), rho), phi, wd)
            v2 = _v2_of(vc_v, _clamp_f(sin_wd, e, sgn), ws, i2)
            advance_z(mc, zc, z, v1, v2)
            i2 = phasors(mc, z, v1, v2)[1]
            sgn, ih = _fold(i2)
            amp, rho, phi = _polar(ih, vc_v)
            m, kk, fz, fy = _phase_rho_coords(lc, tab, phi, rho)
            p = _peak_of(amp, vc_v, _trilinear(tab, 1, m, j, kk, fz, fx, fy))
            if math.isnan(p):
                return math.nan, v2
            if p > pmax:
                pmax = p
                if pmax / i2_ref - 1.0 > above:
                    return pmax, v2
            if k >= k_tail:
                dx0, dx1, dx2 = complex(z[0], z[1]) - tail_x[0], complex(z[2], z[3]) - tail_x[1], v2 - tail_x[2]
                bound = tail_cap
                for i in range(3):
                    bound += tail_w[i] * abs(tail_vinv[i, 0] * dx0 + tail_vinv[i, 1] * dx1 + tail_vinv[i, 2] * dx2)
                if bound < pmax:
                    return pmax, v2
    return pmax, v2


def simulate(params: LinkParams, d_short, control_period_s: float | None = None, devices: DeviceSet = IDEAL,
             substeps: int = 2, table: np.ndarray | None = None) -> dict:
    """:func:`wpt_receiver.modal.simulate_modal` on the compiled step (same keys: ``t_s``, ``i1``,
    ``i2``, ``v2``, ``d_short``, ``peak_i2_a``; plus ``energy_j``, see :func:`run_duties`).
    ``table`` defaults to :func:`modal_table` of ``params`` and ``devices``."""
    cp = params.rectifier_period_s if control_period_s is None else float(control_period_s)
    d = np.ascontiguousarray(check_duty_run(d_short, cp, substeps))
    lc = link_constants(params, devices)
    mc = np.empty(N_MODES_C, dtype=np.complex128)
    modes(lc, params.lm_h, mc)
    tab = modal_table(params, devices) if table is None else np.ascontiguousarray(table, dtype=float)
    vc = params.vl_v + devices.rect_vf_v
    i1, i2, v2, pk, en = run_duties(lc, mc, tab, d, cp, int(substeps), -1j * params.v1_amp_v, vc, params.lm_h)
    return {"t_s": np.arange(len(d) + 1) * cp, "i1": i1, "i2": i2, "v2": v2, "d_short": np.r_[d[0], d],
            "peak_i2_a": pk, "energy_j": en}
