"""Detuned series capacitors in the env (scenario ``detuned``): the complex envelope of the link.

With C1 or C2 off resonance the coil currents develop a quadrature component and eq. 4 (two real
states) no longer holds. The step uses the complex envelope of
:func:`wpt_receiver.envelope.complex_envelope_matrices` (``X = [J1, J2]``, ``Xk = w Lk - 1/(w Ck)``
in ``R_k + j X_k``; ``cross=False``: without the ``Lm D`` terms, so at zero detuning it is eq. 4
exactly) as four real states ``[Re J1, Re J2, Im J1, Im J2]`` with the exact ZOH over rectifier
periods (17 per step), the SBAR's V2 in phase with J2 re-evaluated every rectifier period
(``V2c = -|V2| J2 / |J2|``, as :func:`wpt_receiver.envelope.simulate_complex` per step), the I2 envelope
``|J2|`` (peak: every sub-step end), ``I_L = (2/pi)(1 - sin(pi d/2)) |J2|`` (mean of |J2|), the devices as in
:func:`envs.core.advance`. The windows of a batch go through this numpy path when any of them is
detuned (:class:`envs.vector.SbarChargingVectorEnv`; the compiled kernel is the two-state one).

The steady state (:func:`complex_steady`) has a closed form: with ``Z_k = R_k + j X_k``,
``X = w Lm`` and ``Zeff = Z2 + X^2 / Z1 = a + j b``, the RM / any-duty steady ``|J2| = r`` solves
``(a r + |V2|)^2 + (b r)^2 = (X V1 / |Z1|)^2``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["real_matrices", "zoh_complex", "complex_steady", "advance_complex"]


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
    j2 = 1j * x * link.v1_amp_v / z1 / (zeff + v2 / r)
    j1 = (link.v1_amp_v + 1j * x * j2) / z1
    return j1, j2


def advance_complex(xc, vl, soc, vrc, d, coef, b, dev, v1, n_sub: int):
    """One control period on the complex envelope for arrays (n,): ``xc`` (n, 4) ``[Re J1, Re J2, Im J1,
    Im J2]``, ``coef`` (n, 32) of :func:`zoh_complex` for the rectifier period ``dt / n_sub``, ``b`` the
    battery rows (9, n), ``dev`` = (Vf, dR). The SBAR's V2 follows the phase of J2 every rectifier period
    (held over a 100 us step, while a detuned link's phasors turn by up to ~1 rad, it would pump the
    link). Returns ``(xc, |J1|, |J2|, peak |J2| over the sub-step ends, I_L, i_batt, soc, vrc, vl, |V2|)``."""
    vf, dr = dev
    vc = vl + vf
    s = np.sin(0.5 * math.pi * d)
    v2c = 4.0 / math.pi * vc * (1.0 - s)
    wd = dr * (d + np.sin(math.pi * d) / math.pi)
    ad, bd = coef[:, :16].reshape(-1, 4, 4), coef[:, 16:32].reshape(-1, 4, 4)
    r = np.hypot(xc[:, 1], xc[:, 3])
    v2_0 = v2c + wd * r
    pk, tot = np.full(len(d), -1.0), np.zeros(len(d))
    for _ in range(n_sub):
        ok = r > 0.0
        safe = np.where(ok, r, 1.0)
        ph_re, ph_im = np.where(ok, xc[:, 1] / safe, 0.0), np.where(ok, xc[:, 3] / safe, 1.0)
        v2 = v2c + wd * r
        u = np.stack([np.full_like(d, v1), -v2 * ph_re, np.zeros_like(d), -v2 * ph_im], axis=1)
        xc = np.einsum("nij,nj->ni", ad, xc) + np.einsum("nij,nj->ni", bd, u)
        rn = np.hypot(xc[:, 1], xc[:, 3])
        pk = np.maximum(pk, rn)
        tot += 0.5 * (r + rn)
        r = rn
    il = v2c * tot / (2.0 * n_sub * vc)   # V2c I2 / (2 VC) with the mean of |J2|
    ocv0, docv, soc0, rb0, rc_decay, rc_gain, dsoc, i_load, bus_decay = b
    ib = il - i_load
    soc = soc + dsoc * ib
    vrc = rc_decay * vrc + rc_gain * ib
    vl = bus_decay * vl + (1.0 - bus_decay) * (ocv0 + docv * (soc - soc0) + rb0 * ib + vrc)
    return xc, np.hypot(xc[:, 0], xc[:, 2]), r, pk, il, ib, soc, vrc, vl, v2_0
