"""Instantaneous circuit of the series-series link with an SBAR (paper eq. 1), per topology.

State (augmented with a constant 1 so every topology is a *linear* ODE ``dx/dt = M x``)::

    x = [i1, vC1, i2, vC2, (vout), 1]      currents [A], capacitor voltages [V]

Circuit (eq. 1 with the series capacitors written as states)::

    L1 di1/dt - Lm di2/dt = v1 - R1 i1 - vC1          dvC1/dt = i1 / C1
    -Lm di1/dt + L2 di2/dt = -v2 - R2 i2 - vC2        dvC2/dt = i2 / C2

``v1`` is the inverter output, ``v2`` the SBAR input voltage with ``i2`` flowing into the SBAR
(``v2 i2`` is the power into the rectifier). A topology is a pair ``(p, s)``:

* primary ``p``: ``+1`` / ``-1``: driven, v1 = p Vdc - 2 Ron i1; ``+2`` / ``-2``: freewheeling
  through the antiparallel (body) diodes during dead time, v1 = (p/2) (Vdc + 2 Vf0) - 2 Rd i1;
  ``0`` (``P_OPEN``): all four inverter devices off, i1 = 0.
* secondary ``s``: ``+1`` / ``-1``: a diode pair conducts (upper diode + lower body diode),
  v2 = s (vout + Vf0) + Rd i2 (i2 has the sign s); ``0`` (``S_SHORT``): lower switches on,
  v2 = 2 Ron i2; ``2`` (``S_OPEN``): diodes blocked, i2 = 0.

The devices (:class:`wpt_receiver.devices.DeviceSet`, ideal by default) are piecewise linear, so
every topology stays linear in the augmented state: a forward drop is a constant source term in
the column of the constant 1.

The battery is a DC voltage ``VL`` behind ``r_bat_ohm``. Without an output capacitor the diode
topologies see ``v2 = s VL + r_bat i2`` (stiff battery); with ``c_out_f`` the rectifier charges the
capacitor (state ``vout``) which feeds the battery through ``r_bat_ohm``.

Each topology is diagonalised once (``M = V diag(lam) V^-1``), so the exact solution over any
duration ``tau`` is ``x(tau) = Re(V (exp(lam tau) * V^-1 x0))``: exact stepping between events for
arbitrary event times, and a cheap exact dense output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..devices import IDEAL, DeviceSet
from ..params import LinkParams

__all__ = ["SwitchingConfig", "Circuit", "P_OPEN", "S_SHORT", "S_OPEN", "I1", "VC1", "I2", "VC2", "LOSS_GROUPS"]

P_OPEN = 0
S_SHORT = 0
S_OPEN = 2
I1, VC1, I2, VC2, VO = 0, 1, 2, 3, 4
PRIMARY = (1, -1, 2, -2, P_OPEN)
SECONDARY = (1, -1, S_SHORT, S_OPEN)
LOSS_GROUPS = ("inverter_switches", "inverter_diodes", "rectifier_diodes", "rectifier_switches")


@dataclass(frozen=True)
class SwitchingConfig:
    """Switching-level details that the envelope model does not need.

    Attributes
    ----------
    c1_f, c2_f : series capacitors [F]; ``None`` = resonant with L1 / L2 at ``f_hz``.
    dead_time_s : inverter dead time after each commutation [s], in [0, T/4].
    r_bat_ohm : battery series resistance [ohm] (>= 0; > 0 when ``c_out_f`` is given).
    c_out_f : smoothing capacitor [F]; ``None`` = stiff battery (v2 = +-VL while a diode conducts).
    gate_phase_rad : phase of the SBAR gate clock relative to the i2 peak, in radians of the
        85 kHz fundamental. 0 = short window centred on the peak of each i2 half-cycle (eq. 9
        assumption); pi/2 = centred on the i2 zero crossing (the paper's Fig. 10 case).
    samples_per_half_cycle : dense output samples per rectifier period T (even, >= 8).
    devices : the semiconductor devices (:data:`wpt_receiver.devices.IDEAL` = the paper's circuit).
    """

    c1_f: float | None = None
    c2_f: float | None = None
    dead_time_s: float = 0.0
    r_bat_ohm: float = 0.0
    c_out_f: float | None = None
    gate_phase_rad: float = 0.0
    samples_per_half_cycle: int = 16
    devices: DeviceSet = IDEAL

    def __post_init__(self):
        for name in ("c1_f", "c2_f", "c_out_f"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} is invalid; valid range: (0, inf) or None")
        if not (math.isfinite(self.r_bat_ohm) and self.r_bat_ohm >= 0):
            raise ValueError(f"r_bat_ohm={self.r_bat_ohm!r} is invalid; valid range: [0, inf)")
        if self.c_out_f is not None and self.r_bat_ohm <= 0:
            raise ValueError(f"r_bat_ohm={self.r_bat_ohm!r} is invalid with c_out_f set; valid range: (0, inf)")
        if not (math.isfinite(self.dead_time_s) and self.dead_time_s >= 0):
            raise ValueError(f"dead_time_s={self.dead_time_s!r} is invalid; valid range: [0, T/4]")
        if not math.isfinite(self.gate_phase_rad):
            raise ValueError(f"gate_phase_rad={self.gate_phase_rad!r} is invalid; valid range: finite")
        n = self.samples_per_half_cycle
        if int(n) != n or n < 8 or n % 2:
            raise ValueError(f"samples_per_half_cycle={n!r} is invalid; valid range: even integer >= 8")


class Circuit:
    """All topologies of one link: matrices, modal decompositions, guards and output rows.

    Attributes (per topology index ``k``, see :attr:`index` for ``(p, s) -> k``):
    ``lam[k]`` (m,), ``vec[k]`` (m, m), ``inv[k]`` (m, m) complex; ``mat[k]`` the real M.
    """

    def __init__(self, params: LinkParams, cfg: SwitchingConfig = SwitchingConfig()):
        self.p, self.cfg = params, cfg
        w = params.omega_rad_s
        self.c1_f = cfg.c1_f if cfg.c1_f is not None else 1.0 / (w * w * params.l1_h)
        self.c2_f = cfg.c2_f if cfg.c2_f is not None else 1.0 / (w * w * params.l2_h)
        self.T = params.rectifier_period_s
        if cfg.dead_time_s > self.T / 4:
            raise ValueError(f"dead_time_s={cfg.dead_time_s!r} is invalid; valid range: [0, {self.T / 4:.4g}] s (T/4)")
        self.has_cap = cfg.c_out_f is not None
        self.n = 5 if self.has_cap else 4
        self.m = self.n + 1
        self.keys = [(p, s) for p in PRIMARY for s in SECONDARY]
        self.index = {key: k for k, key in enumerate(self.keys)}
        self.mat, self.lam, self.vec, self.inv = [], [], [], []
        for key in self.keys:
            mm = self.matrix(*key)
            lam, vec = np.linalg.eig(mm)
            inv = np.linalg.inv(vec)
            err = np.max(np.abs((vec * lam) @ inv - mm)) / max(1.0, np.max(np.abs(mm)))
            if not err < 1e-8:  # pragma: no cover - would mean a defective (non-diagonalisable) topology
                raise ArithmeticError(f"topology {key} is not safely diagonalisable (error {err:.2e})")
            self.mat.append(mm)
            self.lam.append(lam)
            self.vec.append(vec)
            self.inv.append(inv)
        nk = len(self.keys)
        # modes kept for evaluation: one of each conjugate pair (weight 2), real modes (weight 1)
        self.half = []
        for lam in self.lam:
            keep = np.nonzero(lam.imag >= 0)[0]
            wgt = np.where(lam[keep].imag > 0, 2.0, 1.0)
            dyn = lam[keep] != 0
            self.half.append((keep, wgt, dyn))
        # modal change of basis between topologies: z_new = trans[k_old][k_new] @ z_old
        self.trans = [[self.inv[b] @ self.vec[a] for b in range(nk)] for a in range(nk)]
        self.rows = {k: self._output_rows(*key) for k, key in enumerate(self.keys)}

    # ------------------------------------------------------------------ equations
    def _emf(self, p: int, s: int):
        """Rows (over the augmented state) of e1 = v1 - R1 i1 - vC1 and e2 = -v2 - R2 i2 - vC2,
        devices included (forward drops in the constant column)."""
        m, P, cfg, dv = self.m, self.p, self.cfg, self.cfg.devices
        e1 = np.zeros(m)
        e1[I1], e1[VC1] = -P.r1_ohm, -1.0
        if p in (1, -1):
            e1[-1] = p * P.vdc_v
            e1[I1] -= dv.inv_r_ohm
        elif p in (2, -2):
            e1[-1] = 0.5 * p * (P.vdc_v + dv.fw_vf_v)
            e1[I1] -= dv.fw_rd_ohm
        e2 = np.zeros(m)
        e2[I2], e2[VC2] = -P.r2_ohm, -1.0
        if s in (1, -1):
            e2[I2] -= dv.rect_rd_ohm
            if self.has_cap:
                e2[VO] = -s
                e2[-1] = -s * dv.rect_vf_v
            else:
                e2[-1] = -s * (P.vl_v + dv.rect_vf_v)
                e2[I2] -= cfg.r_bat_ohm
        elif s == S_SHORT:
            e2[I2] -= dv.short_r_ohm
        return e1, e2

    def matrix(self, p: int, s: int) -> np.ndarray:
        """Augmented state matrix M (m x m) of topology ``(p, s)``: ``dx/dt = M x``."""
        P, m = self.p, self.m
        e1, e2 = self._emf(p, s)
        mm = np.zeros((m, m))
        po, so = p == P_OPEN, s == S_OPEN
        if not po and not so:
            det = P.l1_h * P.l2_h - P.lm_h**2
            mm[I1] = (P.l2_h * e1 + P.lm_h * e2) / det
            mm[I2] = (P.lm_h * e1 + P.l1_h * e2) / det
        elif not po:
            mm[I1] = e1 / P.l1_h
        elif not so:
            mm[I2] = e2 / P.l2_h
        mm[VC1, I1] = 1.0 / self.c1_f
        mm[VC2, I2] = 1.0 / self.c2_f
        if self.has_cap:
            c, rb = self.cfg.c_out_f, self.cfg.r_bat_ohm
            mm[VO, VO] = -1.0 / (rb * c)
            mm[VO, -1] = P.vl_v / (rb * c)
            if s in (1, -1):
                mm[VO, I2] = s / c
        if po:  # i1 is identically 0: its row and column vanish, vC1 frozen
            mm[I1] = 0.0
            mm[:, I1] = 0.0
            mm[VC1] = 0.0
        if so:
            mm[I2] = 0.0
            mm[:, I2] = 0.0
            mm[VC2] = 0.0
        return mm

    def vout_row(self) -> np.ndarray:
        """Row of the rectifier output voltage (battery side of the diodes)."""
        r = np.zeros(self.m)
        if self.has_cap:
            r[VO] = 1.0
        else:
            r[-1] = self.p.vl_v
        return r

    def rect_threshold_row(self) -> np.ndarray:
        """Row of the voltage the blocked SBAR input must exceed for a diode pair to conduct:
        the rectifier output plus the forward drops of the rectifying path."""
        return self.vout_row() + np.eye(self.m)[-1] * self.cfg.devices.rect_vf_v

    @property
    def inverter_threshold_v(self) -> float:
        """Voltage the blocked inverter output must exceed to freewheel: Vdc + 2 Vf0 [V]."""
        return self.p.vdc_v + self.cfg.devices.fw_vf_v

    def v2_open_row(self, p: int) -> np.ndarray:
        """Voltage across the blocked SBAR input (i2 = 0, di2/dt = 0): v2 = -vC2 + Lm di1/dt."""
        e1, _ = self._emf(p, S_OPEN)
        r = np.zeros(self.m)
        r[VC2] = -1.0
        if p != P_OPEN:
            r += self.p.lm_h / self.p.l1_h * e1
        return r

    def v1_open_row(self, s: int) -> np.ndarray:
        """Voltage across the blocked inverter (i1 = 0, di1/dt = 0): v1 = vC1 - Lm di2/dt."""
        _, e2 = self._emf(P_OPEN, s)
        r = np.zeros(self.m)
        r[VC1] = 1.0
        if s != S_OPEN:
            r -= self.p.lm_h / self.p.l2_h * e2
        return r

    def _output_rows(self, p: int, s: int) -> dict:
        """Rows for v1, v2, the battery current i_load and the DC source current i_src of
        topology (p, s) (dense output): v1 = e1 + R1 i1 + vC1, v2 = -(e2 + R2 i2 + vC2)."""
        m, P, cfg = self.m, self.p, self.cfg
        e = np.eye(m)
        e1, e2 = self._emf(p, s)
        v1 = self.v1_open_row(s) if p == P_OPEN else e1 + P.r1_ohm * e[I1] + e[VC1]
        v2 = self.v2_open_row(p) if s == S_OPEN else -(e2 + P.r2_ohm * e[I2] + e[VC2])
        il = np.zeros(m)
        if self.has_cap:
            il[VO], il[-1] = 1.0 / cfg.r_bat_ohm, -P.vl_v / cfg.r_bat_ohm
        elif s in (1, -1):
            il[I2] = s
        isrc = e[I1] * (p if p in (1, -1) else 0.5 * p)  # P_OPEN: 0
        return {"v1": v1, "v2": v2, "i_load": il, "i_src": isrc}

    def loss_forms(self, k: int) -> dict:
        """Conduction loss of each device group in topology ``k`` as a product of two rows:
        ``loss = (r . x)(q . x)`` [W] with ``r . x = |i|`` and ``q . x = n Vf0 + n Rd |i|``."""
        p, s = self.keys[k]
        dv, m = self.cfg.devices, self.m
        e, one = np.eye(m), np.eye(m)[-1]
        z = (np.zeros(m), np.zeros(m))
        out = dict.fromkeys(LOSS_GROUPS, z)
        if p in (1, -1):
            out["inverter_switches"] = (e[I1], dv.inv_r_ohm * e[I1])
        elif p in (2, -2):
            a = -0.5 * p * e[I1]  # |i1|: the current flows against the clamped polarity
            out["inverter_diodes"] = (a, dv.fw_vf_v * one + dv.fw_rd_ohm * a)
        if s in (1, -1):
            a = s * e[I2]
            out["rectifier_diodes"] = (a, dv.rect_diode.vf0_v * one + dv.rect_diode.rd_ohm * a)
            body = dv.rect_switch.body
            out["rectifier_switches"] = (a, body.vf0_v * one + body.rd_ohm * a)
        elif s == S_SHORT:
            out["rectifier_switches"] = (e[I2], dv.short_r_ohm * e[I2])
        return out

    # ------------------------------------------------------------------ energies
    def stored_energy(self, x: np.ndarray) -> np.ndarray:
        """Energy in the coils and capacitors [J] for states ``x`` (..., m)."""
        P = self.p
        i1, v1, i2, v2 = x[..., I1], x[..., VC1], x[..., I2], x[..., VC2]
        e = 0.5 * P.l1_h * i1**2 + 0.5 * P.l2_h * i2**2 - P.lm_h * i1 * i2 + 0.5 * self.c1_f * v1**2 + 0.5 * self.c2_f * v2**2
        if self.has_cap:
            e = e + 0.5 * self.cfg.c_out_f * x[..., VO] ** 2
        return e

    def phasor_state(self, i1_amp_a: float, i2_amp_a: float, t_s: float = 0.0) -> np.ndarray:
        """Augmented state of the fundamental-only solution i1 = I1 sin(wt), i2 = I2 cos(wt)."""
        w = self.p.omega_rad_s
        x = np.zeros(self.m)
        x[I1] = i1_amp_a * math.sin(w * t_s)
        x[VC1] = -i1_amp_a / (w * self.c1_f) * math.cos(w * t_s)
        x[I2] = i2_amp_a * math.cos(w * t_s)
        x[VC2] = i2_amp_a / (w * self.c2_f) * math.sin(w * t_s)
        if self.has_cap:
            x[VO] = self.p.vl_v
        x[-1] = 1.0
        return x
