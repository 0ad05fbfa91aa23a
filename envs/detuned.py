"""Detuned series capacitors in the env (scenario ``detuned``): the complex envelope of the link.

With C1 or C2 off resonance the coil currents develop a quadrature component and eq. 4 (two real
states) no longer holds. The step uses the complex envelope of
:func:`wpt_receiver.envelope.complex_envelope_matrices` (``X = [J1, J2]``, ``Xk = w Lk - 1/(w Ck)``
in ``R_k + j X_k``; ``cross=False``: without the ``Lm D`` terms, so at zero detuning it is eq. 4
exactly) as four real states ``[Re J1, Re J2, Im J1, Im J2]`` with the exact ZOH over rectifier
periods (17 per step), the SBAR's V2 in phase with J2 re-evaluated every rectifier period
(``V2c = -|V2| J2 / |J2|``, as :func:`wpt_receiver.envelope.simulate_complex` per step), the I2 envelope
``|J2|`` (peak: every sub-step end), ``I_L = (2/pi)(1 - sin(pi d/2)) |J2|`` (mean of |J2|), the devices as in
the two-state step. This module makes the plans (coefficients :func:`zoh_complex`, steady state
:func:`complex_steady`); the step is the env's compiled one (``envs.vector_kernel._complex_step``, one
function beside the two-state ``_link_step``; the rest of the step is shared), in the single and the
vector env.

The steady state (:func:`complex_steady`) has a closed form: with ``Z_k = R_k + j X_k``,
``X = w Lm`` and ``Zeff = Z2 + X^2 / Z1 = a + j b``, the RM / any-duty steady ``|J2| = r`` solves
``(a r + |V2|)^2 + (b r)^2 = (X V1 / |Z1|)^2``; when ``X V1 / |Z1|`` (the induced emf with J2 = 0)
is at most ``|V2|`` it has no root r > 0 (``a > 0``) and the rectifier blocks: ``J2 = 0``, ``J1 = V1 / Z1``
(a C1 off by more than ~3 % at Table I in RM; the switching model settles there from any start).
"""

from __future__ import annotations

import math

import numpy as np

from .layout import XC

__all__ = ["real_matrices", "zoh_complex", "complex_steady", "short_mode_i2", "magnitudes", "relative_errors"]


def real_matrices(link, lm_h: float, c1_f: float, c2_f: float):
    """``(A, B)`` real 4x4 of the complex envelope (cross=False) for one Lm [H] and C1, C2 [F]."""
    w = link.omega_rad_s
    x1 = w * link.l1_h - 1.0 / (w * c1_f)
    x2 = w * link.l2_h - 1.0 / (w * c2_f)
    xm = w * lm_h
    m = np.diag([link.l1_h + 1.0 / (w * w * c1_f), link.l2_h + 1.0 / (w * w * c2_f)])
    z = np.array([[link.r1_ohm + 1j * x1, -1j * xm], [-1j * xm, link.r2_ohm + 1j * x2]])
    minv = np.linalg.inv(m)
    a, b = -minv @ z, minv.astype(complex)
    return _real(a), _real(b)


def _real(c):
    return np.block([[c.real, -c.imag], [c.imag, c.real]])


def zoh_complex(link, lm_h, c1_f, c2_f, dt_s: float) -> np.ndarray:
    """Per row (lm, c1, c2): ``[Ad (16), Bd (16)]`` flattened, (n, 32), of one sub-step ``dt_s``."""
    from scipy.linalg import expm
    out = np.empty((len(lm_h), 32))
    for i, (lm, c1, c2) in enumerate(zip(lm_h, c1_f, c2_f)):
        a, b = real_matrices(link, lm, c1, c2)
        ad = expm(a * dt_s)
        out[i, :16] = ad.ravel()
        out[i, 16:] = np.linalg.solve(a, (ad - np.eye(4)) @ b).ravel()
    return out


def complex_steady(link, lm_h, c1_f, c2_f, v2_mag_v, r2_add_ohm=0.0):
    """Steady ``(J1, J2)`` complex [A] for a V2 magnitude in phase with J2 (arrays (n,)); ``r2_add_ohm``
    a resistance in series with R2 (the short window's excess ``dR w(d)`` of the devices)."""
    w = link.omega_rad_s
    z1 = link.r1_ohm + 1j * (w * link.l1_h - 1.0 / (w * np.asarray(c1_f)))
    z2 = link.r2_ohm + r2_add_ohm + 1j * (w * link.l2_h - 1.0 / (w * np.asarray(c2_f)))
    x = w * np.asarray(lm_h, dtype=float)
    v2 = np.asarray(v2_mag_v, dtype=float)
    zeff = z2 + x * x / z1
    a, b = zeff.real, zeff.imag
    k = x * link.v1_amp_v / np.abs(z1)
    r = (-a * v2 + np.sqrt(np.maximum(a * a * v2 * v2 - (a * a + b * b) * (v2 * v2 - k * k), 0.0))) / (a * a + b * b)
    blocks = k <= v2   # the emf with J2 = 0 is within the clamp: the rectifier blocks, J2 = 0
    with np.errstate(divide="ignore", invalid="ignore"):
        j2 = np.where(blocks, 0j, 1j * x * link.v1_amp_v / z1 / (zeff + v2 / np.where(blocks, 1.0, r)))
    j1 = (link.v1_amp_v + 1j * x * j2) / z1
    return j1, j2


def short_mode_i2(cfg, devices, lm_h, c1_f, c2_f) -> np.ndarray:
    """The objective's short-mode current [A] of a detuned link, (n, S): V2 = 0, the short mode's
    resistances (the driven inverter channels in R1, the shorted SBAR channels in R2), per slow
    segment's true Lm ``lm_h`` (n, S) and the windows' C1, C2 [F] (n,)."""
    base = cfg.link
    sm = base.with_(r1_ohm=base.r1_ohm + devices.inv_r_ohm, r2_ohm=base.r2_ohm + devices.short_r_ohm)
    S = lm_h.shape[1]
    _, j2 = complex_steady(sm, lm_h.ravel(), np.repeat(c1_f, S), np.repeat(c2_f, S), 0.0)
    return np.abs(j2).reshape(-1, S)


def magnitudes(xc):
    """``(|J1|, |J2|)`` [A] of complex states ``xc`` (n, 4) (slots :data:`envs.layout.XC`)."""
    return np.hypot(xc[:, XC.re_j1], xc[:, XC.im_j1]), np.hypot(xc[:, XC.re_j2], xc[:, XC.im_j2])


def relative_errors(cfg, c1_f, c2_f) -> np.ndarray:
    """The relative C1, C2 errors (2, n) against resonance with the link's L1, L2 (what ``c_detune`` drew)."""
    w, lk = cfg.link.omega_rad_s, cfg.link_folded
    return np.stack([c1_f * w * w * lk.l1_h - 1.0, c2_f * w * w * lk.l2_h - 1.0])
