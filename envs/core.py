"""The batched physical system, reward and observation of the charging window (one implementation
for the single and the vector environment).

Composition (gym-electric-motor style):

* physical system: the envelope link (paper eq. 4) stepped by exact ZOH
  (:func:`wpt_receiver.zoh_discretise`, the closed form :class:`wpt_receiver.EnvelopeLink` uses)
  with a true Lm that follows the hover pose error (:mod:`envs.plant`), the SBAR (eq. 9 with the
  sign of the I2 envelope, :func:`wpt_receiver.sbar.rectifier_v2`: it always absorbs power), the
  semiconductor devices averaged as in the mission (:attr:`EnvConfig.devices`: on-resistances folded
  into R1 / R2, forward drop on the clamp, short-window excess in V2) and the battery equivalent
  circuit; the step's peak is turned into the instantaneous peak (harmonic ripple) by :mod:`envs.peaks`;
* reference generator: the seeded charge command (:mod:`envs.scenario`);
* reward and cost: :func:`reward_cost`;
* visualisation: :mod:`envs.render`.

Multi-rate: the link is stepped every control period ``dt_s`` (default 100 us = 17 rectifier
periods; a step in which the I2 envelope changes sign is split into rectifier-period sub-steps,
see :func:`advance`); the hover pose (hence Lm) is sampled every ``slow_every`` steps (default 1 ms) and held;
the battery is the equivalent circuit linearised around the episode's initial SoC (its open-circuit
voltage moves by < 1 mV over a 30 ms window, the RC branch is integrated exactly).

Everything exogenous (command, sensor noise, pose -> Lm -> ZOH coefficients) is computed once per
episode in :func:`build_plans` (batched over the episodes that start), so a step is only
arithmetic. The step functions :func:`advance` and :func:`reward_cost` are written once and run on
either numpy arrays (vector env, n rows) or Python floats (single env); they are the references of
the compiled steps of both envs (:mod:`envs.vector_kernel`, the default with numba, the same
expressions). ``tests/test_envs.py`` and ``tests/test_vector_fast.py`` check that all give the same
trajectories.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from mission_sim.contract import OBS_FIELDS
from wpt_receiver import TABLE_I, LinkParams, duty_from_v2_clipped, state_matrices, steady_state, zoh_discretise
from wpt_receiver.sbar import rectifier_current, short_weight

from .plant import battery_operating_point, lm_window_h
from .scenario import Scenario, command_profile, stack_draws

__all__ = ["EnvConfig", "RewardWeights", "Plans", "build_plans", "advance", "reward_cost", "OBS_SCALE",
           "OBS_OFFSET", "SCALAR_OPS", "NUMPY_OPS", "N_COEF"]

HALF_PI = 0.5 * math.pi
FOUR_OVER_PI = 4.0 / math.pi
N_COEF = 20
N_BAT = 9

#: affine map physical -> [-1, 1] of :data:`mission_sim.contract.OBS_FIELDS` (same as normalise_obs)
OBS_SCALE = np.array([2.0 / (f.hi - f.lo) for f in OBS_FIELDS])
OBS_OFFSET = np.array([-1.0 - f.lo * 2.0 / (f.hi - f.lo) for f in OBS_FIELDS])


@dataclass(frozen=True)
class RewardWeights:
    """reward = (min(I_L, I*) - tracking |I_L - I*|) / i_ref_a - overcurrent max(0, I2_peak/I2_rated - 1)

    i_ref_a : current scale [A] (about what RM delivers with Table I: (2/pi) 11.07 A = 7.05 A)
    """

    tracking: float = 1.0
    overcurrent: float = 10.0
    i_ref_a: float = 7.0


@dataclass(frozen=True)
class EnvConfig:
    """Fixed settings of an environment (episode randomness lives in the :class:`Scenario`).

    link : the link parameters (Table I); the true Lm replaces ``link.lm_h`` per pose
    dt_s : control period = env step [s] (default 17 rectifier periods = 100 us)
    n_steps : steps per episode (truncation), default 300 (30 ms)
    slow_every : pose / Lm update every this many steps
    rated_i2_a : rated secondary coil current amplitude [A] (cost above it)
    bus_c_f : smoothing capacitor on the SBAR's DC side [F] (assumption: 4.7 mF, tau = R0 C ~ 0.45 ms)
    devices : semiconductor preset of the link (``wpt_receiver/parts.toml``), the mission's default
        ``"schottky"``; ``"ideal"`` is the paper's circuit. Applied as in the mission
        (:class:`mission_sim.world.loop.MissionLoop`): the inverter's 2 Ron folded into R1, the
        rectifying path's Rd into R2, the forward drop added to the clamp ``VL + Vf``, the shorted
        channels' excess ``(2 Ron - Rd) w(d) I2`` added to V2 (see :func:`advance`).
    device_tj_c : junction temperature of the devices' conduction values [C] (0 = the table's, as
        the mission's ``link.device_tj_c``); ``device_terms`` keeps its ``(Vf, dR)`` interface.
    """

    link: LinkParams = TABLE_I
    dt_s: float = 17 * TABLE_I.rectifier_period_s
    n_steps: int = 300
    slow_every: int = 10
    rated_i2_a: float = 15.0
    bus_c_f: float = 4.7e-3
    reward: RewardWeights = RewardWeights()
    devices: str = "schottky"
    device_tj_c: float = 0.0

    def __post_init__(self):
        from wpt_receiver.devices import preset_names
        if not (self.device_tj_c == 0.0 or 25.0 <= self.device_tj_c <= 175.0):
            raise ValueError(f"device_tj_c={self.device_tj_c!r} is invalid; valid range: 0 (table values) or "
                             "[25, 175] C")
        if not isinstance(self.devices, str) or self.devices not in preset_names():
            raise ValueError(f"devices={self.devices!r} is invalid; valid values: {', '.join(preset_names())}")
        if not (np.isfinite(self.dt_s) and 1e-7 <= self.dt_s <= 1e-2):
            raise ValueError(f"dt_s={self.dt_s!r} is invalid; valid range: [1e-7, 1e-2] s")
        if int(self.n_steps) != self.n_steps or not 2 <= self.n_steps <= 10**6:
            raise ValueError(f"n_steps={self.n_steps!r} is invalid; valid range: integer 2..1e6")
        if int(self.slow_every) != self.slow_every or self.slow_every < 1:
            raise ValueError(f"slow_every={self.slow_every!r} is invalid; valid range: integer >= 1")
        if not (np.isfinite(self.bus_c_f) and self.bus_c_f > 0):
            raise ValueError(f"bus_c_f={self.bus_c_f!r} is invalid; valid range: (0, inf)")
        if not (np.isfinite(self.rated_i2_a) and self.rated_i2_a > 0):
            raise ValueError(f"rated_i2_a={self.rated_i2_a!r} is invalid; valid range: (0, inf)")

    def device_set(self):
        """The :class:`wpt_receiver.devices.DeviceSet` of ``devices``."""
        return self._derived[0]

    @property
    def link_folded(self) -> LinkParams:
        """The link with the devices' constant resistances folded in (R1 + 2 Ron, R2 + Rd): what the
        envelope is stepped with (:func:`wpt_receiver.devices.envelope_params`)."""
        return self._derived[1]

    @property
    def device_terms(self) -> tuple:
        """``(Vf, dR)`` of :func:`advance`: the rectifying path's forward drop [V] and the shorted
        channels' resistance minus the folded Rd [ohm] (both 0 for ``"ideal"``)."""
        return self._derived[2]

    @cached_property   # every episode start asks (the config is frozen)
    def _derived(self):
        from wpt_receiver.devices import envelope_params, preset
        dev = preset(self.devices, tj_c=self.device_tj_c or None)
        return dev, envelope_params(self.link, dev), (dev.rect_vf_v, dev.short_r_ohm - dev.rect_rd_ohm)

    @property
    def n_slow(self) -> int:
        return -(-self.n_steps // self.slow_every)

    @property
    def n_sub(self) -> int:
        """Rectifier-period sub-steps of a step in which I2 changes sign (17 at the default)."""
        return max(1, math.ceil(self.dt_s / self.link.rectifier_period_s - 1e-9))


@dataclass
class Plans:
    """Per-episode exogenous data and initial state for ``n`` episodes (all arrays lead with n)."""

    cmd_a: np.ndarray        # (n, T+1) charge command per step
    noise_a: np.ndarray      # (n, T) I2 sensor noise [A]
    coef: np.ndarray         # (n, S, 12) ZOH coefficients per slow segment (see advance)
    lm_h: np.ndarray         # (n, S) true Lm per slow segment
    battery: np.ndarray      # (n, 9) ocv0, docv_dsoc, soc0, r0, rc_decay, rc_gain, dsoc_per_a, i_load, bus_decay
    x0: np.ndarray           # (n, 2) initial I1, I2
    vl0: np.ndarray          # (n,) initial battery voltage
    vrc0: np.ndarray         # (n,) initial RC-branch voltage
    d0: np.ndarray           # (n,) initial duty (steady state for cmd0)
    t_stop_s: np.ndarray     # (n,) time of the stop command
    delay_steps: np.ndarray | None = None   # (n,) int: age of the current measurements [control periods]
    cplx: tuple | None = None   # detuned windows (envs.detuned): (coef (n, S, 32), x0 (n, 4), C1 (n,), C2 (n,) [F])


def _steady_v2(link: LinkParams, lm, il, vl):
    """V2 [V] that delivers DC current ``il`` at battery voltage ``vl`` in steady state (lossless
    rectifier: V2 I2 / 2 = VL I_L with I2 = (w Lm V1 - R1 V2)/det), saturated at RM."""
    x = link.omega_rad_s * lm
    det = link.r1_ohm * link.r2_ohm + x * x
    disc = np.maximum((x * link.v1_amp_v) ** 2 - 8.0 * link.r1_ohm * vl * il * det, 0.0)
    return np.minimum(np.maximum((x * link.v1_amp_v - np.sqrt(disc)) / (2.0 * link.r1_ohm), 0.0), FOUR_OVER_PI * vl)


def build_plans(draws, scenarios, cfg: EnvConfig, out=None) -> Plans:
    """Turn the episodes' random draws (a list of :class:`~envs.scenario.EpisodeDraw` or a batched
    one) into what the step needs, on arrays over the episodes. ``scenarios``: one per episode,
    or one :class:`Scenario` for all. The command and the sensor noise are built step-major, the Plans
    holding their transposed views; ``out``: None (new arrays) or float arrays ``(cmd (T + 1, n), noise
    (T, n), coef (n, S, 20))`` (C-contiguous) to write them and the coefficients into (the vector env's
    stores: no temporaries, no copies; the same numbers)."""
    if isinstance(draws, (list, tuple)):
        draws = stack_draws(draws)
    n, T, S, link = draws.n, cfg.n_steps, cfg.n_slow, cfg.link_folded
    if isinstance(scenarios, Scenario):
        load_w, noise_sd = np.full(n, scenarios.load_power_w), np.full(n, scenarios.i2_noise_a)
    else:
        load_w = np.array([s.load_power_w for s in scenarios])
        noise_sd = np.array([s.i2_noise_a for s in scenarios])
    t_slow = np.arange(S) * (cfg.slow_every * cfg.dt_s)
    lm = lm_window_h(draws.wind_speed_m_s, draws.record_u, t_slow)
    lm *= np.asarray(draws.lm_scale)[:, None]
    drift = np.asarray(draws.lm_drift, dtype=float)
    if np.any(drift != 0.0):   # Lm moving within the window (scenario lm_drift): linear in time
        lm *= 1.0 + drift[:, None] * (t_slow / (T * cfg.dt_s))[None, :]
    # windows without wind share one Lm: discretise each distinct value once (same numbers)
    lm_u, back = np.unique(lm.ravel(), return_inverse=True)
    zoh = _zoh_coefficients(link, lm_u, cfg)
    cmd, noise, coef = out if out is not None else (np.empty((T + 1, n)), np.empty((T, n)), np.empty((n, S, N_COEF)))
    np.take(zoh, back.ravel(), axis=0, out=coef.reshape(n * S, N_COEF), mode="clip")   # indices all valid
    noise = np.multiply(draws.noise.T, noise_sd, out=noise).T
    cmd = command_profile(draws, T, cfg.dt_s, out=cmd)
    battery, x0, vl0, vrc0, d0 = _initial_state(link, lm[:, 0], np.asarray(draws.soc0, dtype=float), load_w,
                                                cmd[:, 0], cfg)
    c1 = np.asarray(draws.c1_detune, dtype=float).reshape(n)
    c2 = np.asarray(draws.c2_detune, dtype=float).reshape(n)
    cplx = _detuned_plans(link, lm, c1, c2, vl0, d0, cfg) if np.any(c1 != 0.0) or np.any(c2 != 0.0) else None
    return Plans(cmd, noise, coef, lm, battery, x0, vl0, vrc0, d0,
                 np.asarray(draws.t_stop_s, dtype=float), np.asarray(draws.sense_delay).astype(np.int64).reshape(n),
                 cplx)


def _detuned_plans(link, lm, c1_rel, c2_rel, vl0, d0, cfg: EnvConfig):
    """ZOH coefficients of the complex envelope per window and slow segment and the steady state at
    the first duty (:mod:`envs.detuned`; ``c*_rel`` the relative capacitor errors)."""
    from .detuned import complex_steady, zoh_complex
    w = link.omega_rad_s
    c1 = (1.0 + c1_rel) / (w * w * link.l1_h)
    c2 = (1.0 + c2_rel) / (w * w * link.l2_h)
    n, S = lm.shape
    keys = np.stack([lm.ravel(), np.repeat(c1, S), np.repeat(c2, S)], axis=1)
    uk, back = np.unique(keys, axis=0, return_inverse=True)
    coef = zoh_complex(link, uk[:, 0], uk[:, 1], uk[:, 2], cfg.dt_s / cfg.n_sub)[back.ravel()].reshape(n, S, 32)
    vf, dr = cfg.device_terms
    v2 = FOUR_OVER_PI * (vl0 + vf) * (1.0 - np.sin(HALF_PI * d0))
    j1, j2 = complex_steady(link, lm[:, 0], c1, c2, v2, dr * short_weight(d0))
    return coef, np.stack([j1.real, j2.real, j1.imag, j2.imag], axis=1), c1, c2


def _zoh_coefficients(link: LinkParams, lm, cfg: EnvConfig) -> np.ndarray:
    """The 20 ZOH coefficients of :func:`advance` for every Lm in ``lm`` (flattened, (n*S, 20))."""
    a, b = state_matrices(link, lm.ravel())
    n = len(a)
    # the three step lengths (step, half step, sub-step) in one call: elementwise, the same numbers
    dt = np.repeat([cfg.dt_s, 0.5 * cfg.dt_s, cfg.dt_s / cfg.n_sub], n)
    ad3, bd3 = zoh_discretise(np.concatenate([a, a, a]), b, dt)
    ad, am, ah = ad3[:n], ad3[n:2 * n], ad3[2 * n:]
    bd, bm, bh = bd3[:n], bd3[n:2 * n], bd3[2 * n:]
    v1 = link.v1_amp_v
    # columns: Ad00 Ad01 Ad10 Ad11, Bd00 V1, Bd10 V1, Bd01, Bd11, Am10 Am11, Bm10 V1, Bm11, the same 8 for Ah, Bh
    return np.concatenate([ad.reshape(n, 4), bd[:, :, 0] * v1, bd[:, :, 1], am[:, 1, :], bm[:, 1, :1] * v1,
                           bm[:, 1, 1:], ah.reshape(n, 4), bh[:, :, 0] * v1, bh[:, :, 1]], axis=1)


def _initial_state(link: LinkParams, lm0, soc0, load_w, cmd0, cfg: EnvConfig):
    """Battery rows of :class:`Plans` and the steady state delivering the first command ``cmd0``
    (fixed point through the battery voltage): ``(battery, x0, vl0, vrc0, d0)``. ``link`` has the
    devices' resistances folded in; ``(vf, dr)`` = :attr:`EnvConfig.device_terms` as in :func:`advance`
    (the clamp is ``VL + vf``, the short-window excess ``dr w(d) I2`` acts as a resistance in series with R2)."""
    vf, dr = cfg.device_terms
    ocv, docv, r0, r1, tau1, cap = battery_operating_point(soc0)
    i_load = load_w / ocv   # hover draw, constant over 30 ms
    vl = ocv + (r0 + r1) * (cmd0 - i_load)
    for _ in range(2):
        v2 = _steady_v2(link, lm0, cmd0, vl + vf)
        i1, i2 = steady_state(link, v2, lm0)
        il = v2 * i2 / (2.0 * (vl + vf))
        vl = ocv + (r0 + r1) * (il - i_load)
    d0 = duty_from_v2_clipped(v2, vl + vf)
    v2 = FOUR_OVER_PI * (vl + vf) * (1.0 - np.sin(HALF_PI * d0))
    # steady state with V2 = v2 + dr w(d0) I2 (eq. 4; i2 > 0: V2 <= RM's, below w Lm V1 / R1)
    r2e = link.r2_ohm + dr * short_weight(d0)
    wlm = link.omega_rad_s * np.asarray(lm0, dtype=float)
    det = link.r1_ohm * r2e + wlm**2
    i2 = (wlm * link.v1_amp_v - link.r1_ohm * v2) / det
    i1 = (r2e * link.v1_amp_v + wlm * v2) / det
    ib0 = rectifier_current(d0, np.abs(i2)) - i_load
    vrc0 = r1 * ib0
    vl0 = ocv + r0 * ib0 + vrc0
    decay = np.exp(-cfg.dt_s / tau1)
    bus_decay = np.exp(-cfg.dt_s / (r0 * cfg.bus_c_f))
    battery = np.stack([ocv, docv, soc0, r0, decay, r1 * (1.0 - decay), cfg.dt_s / (3600.0 * cap), i_load,
                        bus_decay], axis=-1)
    return battery, np.stack([i1, i2], axis=-1), vl0, vrc0, d0


def _sign_float(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


class _ScalarOps:
    sin = staticmethod(math.sin)
    sqrt = staticmethod(math.sqrt)
    sign = staticmethod(_sign_float)
    minimum = staticmethod(min)
    maximum = staticmethod(max)


class _NumpyOps:
    sin = staticmethod(np.sin)
    sqrt = staticmethod(np.sqrt)
    sign = staticmethod(np.sign)
    minimum = staticmethod(np.minimum)
    maximum = staticmethod(np.maximum)


SCALAR_OPS = _ScalarOps()
NUMPY_OPS = _NumpyOps()


def advance(i1, i2, vl, soc, vrc, d, c, b, ops, n_sub: int = 1, dev=(0.0, 0.0)):
    """One control period with duty ``d`` held (floats, or arrays of shape (n,) with ``NUMPY_OPS``).

    ``c`` = (Ad00, Ad01, Ad10, Ad11, Bd00 V1, Bd10 V1, Bd01, Bd11, Ad10', Ad11', Bd10' V1, Bd11', and
    the same 8 as the first for the sub-step ``dt / n_sub``) with ' the half-step discretisation
    (of the link with the devices' resistances folded in, :attr:`EnvConfig.link_folded`);
    ``b`` = battery row of :class:`Plans`. ``vl`` is the battery voltage of the previous step. The
    SBAR applies ``V2 = (4/pi) (VL + Vf) (1 - sin(pi/2 d)) sign(I2) + dR w(d) I2`` with ``dev = (Vf,
    dR)`` (:attr:`EnvConfig.device_terms`, zero for ideal devices: eq. 9 with the sign of the
    envelope, :func:`wpt_receiver.sbar.rectifier_v2`; the diodes conduct with the instantaneous
    i2, so the rectifier always absorbs power) and ``w(d) = d + sin(pi d)/pi`` the short window's
    share of ``<i2^2>`` (:func:`wpt_receiver.sbar.rectifier_v2_folded`, as the mission). The sign
    and the ``I2`` of the excess term are those at the start of the step;
    if the envelope changes sign within the step (at mid-step or at its end, V2 held) the step is
    recomputed in ``n_sub`` sub-steps (the rectifier period ``T = 1/(2f)``, 17 at 100 us), each
    with the sign (and ``I2``) at its start: holding the sign over a step that is a sizeable part of the
    envelope's ~250 us ringing period would pump the ringing instead of damping it. The SBAR's DC
    bus is the battery terminal with its smoothing capacitor: VL follows ``OCV + R0 i_batt + v_rc``
    with the time constant R0 C_bus (without the capacitor the one-step VL -> V2 -> I2 -> I_L loop
    through R0 would be unstable at the link's ~4 kHz resonance, where |G22| ~ 24 A/V).

    Returns ``(i1, i2, i2_peak, i_l, i_batt, soc, vrc, vl, v2)``: ``i2_peak`` the largest |I2| of
    the envelope at mid-step and at the end (of every sub-step end when split; the envs turn it
    into the instantaneous peak with :mod:`envs.peaks` at the duty and the VL of the step), ``i_l = (2/pi)
    (1 - sin(pi/2 d)) |I2| >= 0`` the SBAR output current averaged over the step (the clamp's
    ``V2c I2 / (2 (VL + Vf))``; Simpson's rule on I2, the mean of |I2| on each sub-step when split),
    ``i_batt = i_l - i_load``, ``v2`` the V2 applied at the start of the step.
    """
    a00, a01, a10, a11, e0, e1, b01, b11, m10, m11, me1, mb11 = c[:12]
    ocv0, docv, soc0, r0, rc_decay, rc_gain, dsoc, i_load, bus_decay = b
    vf, dr = dev
    vc = vl + vf
    s = ops.sin(HALF_PI * d)
    v2c = FOUR_OVER_PI * vc * (1.0 - s) * ops.sign(i2)   # the clamp's part (rectifier_v2's arithmetic)
    rx = dr * (d + 2.0 * s * ops.sqrt(1.0 - s * s) / math.pi)   # sin(pi d) = 2 s cos(pi d/2), d in [0, 1]
    v2 = v2c + rx * i2
    i2m = m10 * i1 + m11 * i2 + me1 + mb11 * v2
    i1n = a00 * i1 + a01 * i2 + e0 + b01 * v2
    i2n = a10 * i1 + a11 * i2 + e1 + b11 * v2
    il = v2c * (i2 + 4.0 * i2m + i2n) / (12.0 * vc)
    pk = ops.maximum(abs(i2m), abs(i2n))
    if n_sub > 1:
        if ops is NUMPY_OPS:
            idx = np.flatnonzero((i2m * v2c < 0.0) | (i2n * v2c < 0.0))
            if len(idx):
                r = _substeps(i1[idx], i2[idx], np.abs(v2c[idx]), vc[idx], c[12:, idx], n_sub, ops, rx[idx])
                i1n[idx], i2n[idx], pk[idx], il[idx] = r
        elif i2m * v2c < 0.0 or i2n * v2c < 0.0:
            i1n, i2n, pk, il = _substeps_float(i1, i2, abs(v2c), vc, c[12:], n_sub, rx)
    ib = il - i_load
    soc = soc + dsoc * ib
    vrc = rc_decay * vrc + rc_gain * ib
    vl = bus_decay * vl + (1.0 - bus_decay) * (ocv0 + docv * (soc - soc0) + r0 * ib + vrc)
    return i1n, i2n, pk, il, ib, soc, vrc, vl, v2


def _substeps(i1, i2, v2_mag, vl, c, n_sub, ops, rx=0.0):
    """``n_sub`` rectifier-period sub-steps on arrays, V2 = |f(d)| sign(I2) + rx I2 re-evaluated at each
    (``vl`` the clamp voltage VL + Vf):
    returns ``(i1, i2, peak |I2|, mean I_L)`` (I_L from the mean |I2| of each sub-step, linear in
    it). Python floats: :func:`_substeps_float`."""
    h00, h01, h10, h11, f0, f1, g01, g11 = c
    sign = ops.sign
    path = [i2]
    for _ in range(n_sub):
        v2 = v2_mag * sign(i2) + rx * i2
        i1, i2 = h00 * i1 + h01 * i2 + f0 + g01 * v2, h10 * i1 + h11 * i2 + f1 + g11 * v2
        path.append(i2)
    p = np.abs(np.stack(path))
    pk = p[1:].max(axis=0)
    s = p[1:] + p[:-1]
    # mean |I2| on a linear sub-step: (|a| + |b|)/2, less |a||b|/(|a| + |b|) when it crosses zero
    cross = (np.stack(path[1:]) * np.stack(path[:-1])) < 0.0
    tot = 0.5 * s.sum(axis=0)
    if cross.any():
        tot -= np.where(cross, p[1:] * p[:-1] / np.where(cross, s, 1.0), 0.0).sum(axis=0)
    return i1, i2, pk, v2_mag * tot / (2.0 * n_sub * vl)


def _substeps_float(i1, i2, v2_mag, vl, c, n_sub, rx=0.0):
    """:func:`_substeps` on Python floats (the single env), one pass: the same sums in the same
    order (peak = first largest |I2|, mean |I2| summed from 0 over the sub-steps)."""
    h00, h01, h10, h11, f0, f1, g01, g11 = c
    pk, tot = -1.0, 0
    for _ in range(n_sub):
        a = i2
        v2 = (v2_mag if i2 > 0.0 else (-v2_mag if i2 < 0.0 else 0.0 * v2_mag)) + rx * i2
        i1, i2 = h00 * i1 + h01 * i2 + f0 + g01 * v2, h10 * i1 + h11 * i2 + f1 + g11 * v2
        m = abs(i2)
        if m > pk:
            pk = m
        if a * i2 >= 0.0:  # mean |x| on the linear sub-step from a to i2
            tot += 0.5 * abs(a + i2)
        else:
            tot += 0.5 * (a * a + i2 * i2) / (abs(a) + abs(i2))
    return i1, i2, pk, v2_mag * tot / (2.0 * n_sub * vl)


def reward_cost(il, cmd, i2_peak, inv_rated, w: RewardWeights, ops):
    """``(reward, cost)`` of one step; ``cost = max(0, |I2|_peak / I2_rated - 1)`` (relative excess of
    the step's peak coil current magnitude over the rated value, 0 when within rating: a negative
    envelope amplitude is a real current of that size). ``i2_peak`` is taken by magnitude."""
    cost = ops.maximum(abs(i2_peak) * inv_rated - 1.0, 0.0)
    r = (ops.minimum(il, cmd) - w.tracking * abs(il - cmd)) / w.i_ref_a - w.overcurrent * cost
    return r, cost
