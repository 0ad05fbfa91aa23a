"""The RM steady state of the complex envelope model in closed form (:func:`rm_steady`): the tolerance draws'
RM operating point (:mod:`wpt_receiver.tolerance`, which re-exports it; the derivation is in its module docstring)
and the emf margin of the exact-mode model's checked range (:func:`wpt_receiver.paper.rm_emf_margin`). A module of
its own so that a mission's setup check (:mod:`mission_sim.setup_warnings`) does not import the tolerance study
(its dataclasses and transition set, ~1.5 ms) for one 2x2 solve: it needs only modules a mission has loaded."""

from __future__ import annotations

import math

import numpy as np

from .devices import IDEAL, DeviceSet
from .envelope import complex_envelope_matrices
from .params import LinkParams

__all__ = ["folded_link", "rm_steady"]


def folded_link(p: LinkParams, devices: DeviceSet) -> LinkParams:
    return p if devices.is_ideal else p.with_(r1_ohm=p.r1_ohm + devices.inv_r_ohm,
                                              r2_ohm=p.r2_ohm + devices.rect_rd_ohm)


def rm_steady(p: LinkParams, c1_f: float | None, c2_f: float | None, devices: DeviceSet = IDEAL) -> dict:
    """RM steady state in closed form (:mod:`wpt_receiver.tolerance`'s module docstring; ``c1_f`` / ``c2_f``
    None: tuned to ``p.f_hz``, as :func:`wpt_receiver.envelope.complex_envelope_matrices`): ``x`` = [J1, J2]
    (complex amplitudes), ``i2_a`` |J2|, ``p_batt_w``, ``p_in_w``, ``efficiency`` (0 when nothing conducts) and
    ``clamp_margin`` = ``|E| / (V2 |G22|)``, the induced emf over the clamp it must overcome: the
    rectifier conducts iff it exceeds 1 (when ``Im G22 = 0``), and near 1 it conducts only briefly
    each half period (discontinuous), where this first-harmonic estimate is not accurate
    (:data:`wpt_receiver.tolerance.TRUSTED_POWER_FRAC`)."""
    pf = folded_link(p, devices)
    a_m, b_m = complex_envelope_matrices(pf, c1_f, c2_f)
    g = -np.linalg.solve(a_m, b_m)
    v1, v2 = p.v1_amp_v, 4.0 / math.pi * (p.vl_v + devices.rect_vf_v)
    e = g[1, 0] * v1
    disc = abs(e) ** 2 - (v2 * g[1, 1].imag) ** 2
    amp = -v2 * g[1, 1].real + math.sqrt(disc) if disc > 0 else 0.0
    if amp > 0:
        ph = e / (amp + g[1, 1] * v2)
        ph /= abs(ph)
        x = g @ np.array([v1, -v2 * ph])
        x[1] = amp * ph
    else:   # blocked: the SBAR's v2 is the open-circuit voltage that keeps J2 = 0
        amp = 0.0
        x = g @ np.array([v1, -e / g[1, 1]])
        x[1] = 0.0
    p_batt = 2.0 / math.pi * p.vl_v * amp
    p_in = 0.5 * (v1 * np.conj(x[0])).real
    return {"x": x, "i2_a": amp, "p_batt_w": p_batt, "p_in_w": p_in,
            "efficiency": p_batt / p_in if p_in > 0 and amp > 0 else 0.0,
            "clamp_margin": abs(e) / (v2 * abs(g[1, 1]))}
