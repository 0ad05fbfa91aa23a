"""Envelope model on the exact coupled modes, with the SBAR's v2 from the harmonic balance.

Eq. 4 puts the two coupled modes symmetrically at ``w (1 -+ k/2)``; the circuit of eq. 1 (series
tanks resonant at w) has them at ``w / sqrt(1 -+ k)``, and the difference shows in the beats
after a fast duty change (second and third beat of the RM -> SM step off by -5 % / +4 %).

Here the envelope is taken mode by mode. Eq. 1 as a linear system ``dx/dt = M x + b1 v1 + b2 v2``
on ``x = [i1, vC1, i2, vC2]``::

    L1 di1/dt - Lm di2/dt = v1 - R1 i1 - vC1,   L2 di2/dt - Lm di1/dt = -v2 - R2 i2 - vC2,
    C1 dvC1/dt = i1,   C2 dvC2/dt = i2

(the sign of Lm that gives eq. 4). With the eigenpairs ``(lam_i, v_i)`` of M of positive
frequency, ``x = 2 Re(sum_i z_i v_i)``; writing ``z_i = y_i e^{j w t}`` and averaging the input
over a period (only the co-rotating part of ``v = Re(V e^{j w t})`` drives ``y``)::

    dy_i/dt = (lam_i - j w) y_i + (1/2) u_i^T (b1 V1 + b2 V2),     X = 2 sum_i v_i y_i

is exact in the modal frequencies and damping; the only approximations left are the averaging
and the quasi-static harmonics. ``V2`` is the complex fundamental of the SBAR's v2 from
:class:`wpt_receiver.peak.SbarHarmonics` at the current i2 phasor and duty (so its quadrature
part, which eq. 9 lacks, drives the link too), and the instantaneous peak is that module's
fundamental-plus-ripple estimate. Phasors use ``x = Re(X e^{j w t})``.
"""

from __future__ import annotations

import numpy as np

from .devices import IDEAL, DeviceSet
from .params import LinkParams
from .peak import SbarHarmonics
from .sbar import check_duty_run

__all__ = ["ModalEnvelope", "simulate_modal"]


def link_matrices(p: LinkParams, devices: DeviceSet = IDEAL, c1_f=None, c2_f=None):
    """``(M, b1, b2)`` of eq. 1 on ``[i1, vC1, i2, vC2]`` with the devices' resistances folded in."""
    w = p.omega_rad_s
    c1 = 1 / (w * w * p.l1_h) if c1_f is None else c1_f
    c2 = 1 / (w * w * p.l2_h) if c2_f is None else c2_f
    r1, r2 = p.r1_ohm + devices.inv_r_ohm, p.r2_ohm + devices.rect_rd_ohm
    linv = np.linalg.inv(np.array([[p.l1_h, -p.lm_h], [-p.lm_h, p.l2_h]]))
    # rows of the inductor equations: [i1, vC1, i2, vC2] -> voltage
    volt = np.array([[-r1, -1.0, 0.0, 0.0], [0.0, 0.0, -r2, -1.0]])
    m = np.zeros((4, 4))
    m[[0, 2]] = linv @ volt
    m[1, 0], m[3, 2] = 1 / c1, 1 / c2
    b = np.zeros((4, 2))
    b[[0, 2]] = linv @ np.array([[1.0, 0.0], [0.0, -1.0]])
    return m, b[:, 0], b[:, 1]


class ModalEnvelope:
    """One link on its two positive-frequency modes (module docstring), stepped by exact ZOH.

    ``short_r_ohm`` excess of the shorted SBAR over the folded ``Rd`` enters V2 as in
    :func:`wpt_receiver.sbar.rectifier_v2_folded`."""

    def __init__(self, params: LinkParams, devices: DeviceSet = IDEAL, c1_f=None, c2_f=None, n_max: int = 63):
        self.params, self.devices = params, devices
        m, b1, b2 = link_matrices(params, devices, c1_f, c2_f)
        lam, vec = np.linalg.eig(m)
        keep = np.argsort(-lam.imag)[:2]                      # the two positive-frequency modes
        left = np.linalg.inv(vec)
        self.lam = lam[keep] - 1j * params.omega_rad_s        # in the frame rotating at w [1/s]
        self.v_i2 = 2 * vec[2, keep]                          # X_i2 = v_i2 . y
        self.v_i1 = 2 * vec[0, keep]
        self.g1 = 0.5 * left[keep] @ b1
        self.g2 = 0.5 * left[keep] @ b2
        # quasi-static response of the two negative-frequency modes to the co-rotating input
        neg = np.argsort(-lam.imag)[2:]
        feed = vec[:, neg] @ np.diag(1 / (1j * params.omega_rad_s - lam[neg])) @ left[neg]
        self.d_i2 = feed[2] @ np.column_stack([b1, b2])       # X_i2 += d_i2 . [V1, V2]
        self.d_i1 = feed[0] @ np.column_stack([b1, b2])
        self.v1 = -1j * params.v1_amp_v                       # v1 = (4/pi) Vdc sin(wt)
        self.harm = SbarHarmonics(params, devices, n_max, c1_f, c2_f)
        self._edge = None                                     # last commutation angle (warm start)

    def i2(self, y, v2=0.0) -> complex:
        """i2 phasor [A] of the modal state ``y`` and the input (feedthrough of the other modes)."""
        return complex(self.v_i2 @ y + self.d_i2[0] * self.v1 + self.d_i2[1] * v2)

    def v2(self, d_short: float, i2_phasor) -> complex:
        """SBAR fundamental [V] at a duty and i2 phasor (harmonic balance + short-window excess)."""
        warm = self._edge is not None and abs(i2_phasor) > 1e-3
        v, _, e = self.harm.balance(d_short, i2_phasor, *((2, self._edge) if warm else ()))
        self._edge = e if abs(i2_phasor) > 1e-3 else None
        v = complex(v[0])
        dv = self.devices
        w = d_short + np.sin(np.pi * d_short) / np.pi
        return v + (dv.short_r_ohm - dv.rect_rd_ohm) * w * complex(i2_phasor)

    def steady_state(self, d_short: float, iters: int = 30):
        """``(y, v2)``: modal state and SBAR fundamental [V] of the periodic steady state at a
        constant duty (fixed point on V2)."""
        y = np.zeros(2, dtype=complex)
        v2 = 4 / np.pi * self.harm.clamp_v * (1 - np.sin(0.5 * np.pi * d_short)) + 0j
        for _ in range(iters):
            y_new = -(self.g1 * self.v1 + self.g2 * v2) / self.lam
            v2 = self.v2(d_short, self.i2(y_new, v2))
            if np.allclose(y_new, y, rtol=1e-13, atol=1e-13):
                break
            y = y_new
        return y_new, v2

    def steady_peak(self, d_short: float) -> tuple[complex, float]:
        """``(i2 phasor [A], instantaneous peak |i2| [A])`` in periodic steady state at a duty."""
        y, v2 = self.steady_state(d_short)
        i2 = self.i2(y, v2)
        return i2, float(self.harm.peak(d_short, i2))

    def run(self, d_short, control_period_s: float, substeps: int = 2, y0=None) -> dict:
        """Duties held one per control period; V2 updated every ``control_period_s / substeps``.

        Returns a dict of arrays per control period end (plus the start): ``t_s``, ``i2`` and
        ``i1`` phasors [A], ``v2`` phasor [V], ``d_short``, and ``peak_i2_a`` (instantaneous)."""
        d = check_duty_run(d_short, control_period_s, substeps)
        h = control_period_s / substeps
        ed = np.exp(self.lam * h)
        phi = (ed - 1) / self.lam
        if y0 is None:
            y, v2 = self.steady_state(float(d[0]))
        else:
            y = np.asarray(y0, dtype=complex)
            v2 = self.v2(float(d[0]), self.i2(y))
        out_y = np.empty((len(d) + 1, 2), dtype=complex)
        out_v = np.empty(len(d) + 1, dtype=complex)
        out_y[0], out_v[0] = y, v2
        for k, dk in enumerate(d):
            for _ in range(substeps):
                v2 = self.v2(dk, self.i2(y, v2))
                y = ed * y + phi * (self.g1 * self.v1 + self.g2 * v2)
            out_y[k + 1], out_v[k + 1] = y, v2
        dd = np.r_[d[0], d]
        i2 = out_y @ self.v_i2 + self.d_i2[0] * self.v1 + self.d_i2[1] * out_v
        i1 = out_y @ self.v_i1 + self.d_i1[0] * self.v1 + self.d_i1[1] * out_v
        return {"t_s": np.arange(len(d) + 1) * control_period_s, "i2": i2, "i1": i1, "v2": out_v,
                "d_short": dd, "peak_i2_a": self.harm.peak(dd, i2)}


def simulate_modal(params: LinkParams, d_short, control_period_s: float | None = None,
                   devices: DeviceSet = IDEAL, c1_f=None, c2_f=None, substeps: int = 2) -> dict:
    """:meth:`ModalEnvelope.run` from the steady state of the first duty (see there)."""
    cp = params.rectifier_period_s if control_period_s is None else float(control_period_s)
    return ModalEnvelope(params, devices, c1_f, c2_f).run(d_short, cp, substeps)
