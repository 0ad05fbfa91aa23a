"""Instantaneous peak of i2 from the envelope model: fundamental plus the harmonic ripple.

The envelope model (eq. 4) carries only the fundamentals ``i1 = I1 sin(wt)``, ``i2 = I2 cos(wt)``.
The real i2 also carries the odd harmonics that the square-wave voltages drive through the
coupled coils: the SBAR's v2 (clamped to ``+-(VL + Vf0)`` outside the short window of width
``d pi`` centred on the i2 peak) and the inverter's ``v1 = Vdc sign(sin wt)``. Their Fourier
series (odd n)::

    v2 = sum (4 (VL + Vf0) / (n pi)) (sin(n pi/2) - sin(n pi d/2)) cos(n wt)      (n = 1: eq. 9)
    v1 = sum (4 Vdc / (n pi)) sin(n wt)

and at ``n w`` the link is the phasor system ``Z1n I1n - j n w Lm I2n = V1n``,
``-j n w Lm I1n + Z2n I2n = -V2n`` with ``Zkn = Rk + j (n w Lk - 1/(n w Ck))``. The harmonics
are far from resonance, so they follow the duty quasi-statically: the ripple ``r(theta; d)`` of
n >= 3 is tabulated once on a duty grid, and the instantaneous peak is
``max_theta |I2 cos(theta) + r(theta; d)|``.
"""

from __future__ import annotations

import numpy as np

from .devices import IDEAL, DeviceSet
from .params import LinkParams

__all__ = ["HarmonicRipple"]


class HarmonicRipple:
    """Ripple table of i2 (harmonics 3..``n_max``) over the short duty, and the peak estimate.

    Parameters: ``params`` (Table I), ``devices`` (forward drops add to the clamp, resistances to
    R1 / R2), ``n_max`` highest odd harmonic, ``n_duty`` duty grid points, ``n_theta`` phase
    points per period, ``c1_f``/``c2_f`` the series capacitors (None = resonant).
    """

    def __init__(self, params: LinkParams, devices: DeviceSet = IDEAL, n_max: int = 63, n_duty: int = 201,
                 n_theta: int = 512, c1_f=None, c2_f=None):
        p = params
        w = p.omega_rad_s
        c1 = 1 / (w * w * p.l1_h) if c1_f is None else c1_f
        c2 = 1 / (w * w * p.l2_h) if c2_f is None else c2_f
        self.d = np.linspace(0.0, 1.0, n_duty)
        self.theta = np.linspace(-np.pi, np.pi, n_theta, endpoint=False)
        n = np.arange(3, n_max + 1, 2)
        nw = n * w
        z1 = p.r1_ohm + devices.inv_r_ohm + 1j * (nw * p.l1_h - 1 / (nw * c1))
        z2 = p.r2_ohm + devices.rect_rd_ohm + 1j * (nw * p.l2_h - 1 / (nw * c2))
        zm = 1j * nw * p.lm_h
        det = z1 * z2 - zm * zm
        v1n = -1j * 4 * p.vdc_v / (n * np.pi)                     # sin(n theta) = Re(-j e^{j n theta})
        clamp = p.vl_v + devices.rect_vf_v
        v2n = 4 * clamp / (n * np.pi) * (np.sin(n * np.pi / 2) - np.sin(np.outer(self.d, n) * np.pi / 2))
        i2n = (zm * v1n - z1 * v2n) / det                        # (n_duty, n_h)
        e = np.exp(1j * np.outer(n, self.theta))                  # (n_h, n_theta)
        self.ripple = (i2n @ e).real                              # (n_duty, n_theta) [A]
        self._cos = np.cos(self.theta)

    def waveform(self, d_short, i2_amp_a) -> np.ndarray:
        """i2 over one period (``theta`` grid) for a duty and a fundamental amplitude [A]."""
        r = self._rows(np.atleast_1d(d_short))
        return np.atleast_1d(i2_amp_a)[:, None] * self._cos[None, :] + r

    def _rows(self, d):
        """Ripple rows linearly interpolated on the duty grid, shape (len(d), n_theta)."""
        x = np.clip(np.asarray(d, dtype=float), 0.0, 1.0) * (len(self.d) - 1)
        j = np.minimum(x.astype(int), len(self.d) - 2)
        f = (x - j)[:, None]
        return self.ripple[j] * (1 - f) + self.ripple[j + 1] * f

    def peak(self, d_short, i2_amp_a):
        """Instantaneous peak |i2| [A] for duties and fundamental amplitudes (broadcast, any
        shape): ``max_theta |I2 cos(theta) + r(theta; d)|`` (|I2|: the ripple follows the sign)."""
        d, i2 = np.broadcast_arrays(np.asarray(d_short, dtype=float), np.abs(np.asarray(i2_amp_a, dtype=float)))
        out = np.empty(d.shape)
        flat_d, flat_i = d.ravel(), i2.ravel()
        res = out.ravel()
        for a in range(0, len(flat_d), 4096):  # chunks bound the (chunk, n_theta) temporaries
            sl = slice(a, a + 4096)
            wave = flat_i[sl, None] * self._cos[None, :] + self._rows(flat_d[sl])
            res[sl] = np.max(np.abs(wave), axis=1)
        out = res.reshape(d.shape)
        return out if out.ndim else float(out)
