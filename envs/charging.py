"""Single gymnasium environments of a drone's charging window: continuous and discrete (ON-OFF)."""

from __future__ import annotations

import math

import numpy as np
import gymnasium as gym
from gymnasium import spaces

from mission_sim.contract import OBS_DIM, PolicyContext

from wpt_receiver.sbar import rectifier_current, rectifier_v2_folded

from .core import (OBS_OFFSET, OBS_SCALE, SCALAR_OPS, EnvConfig, advance, build_plans, reward_cost)
from .objective import SHORT_MODE_IL_A, SHORT_MODE_WITHIN_S, short_mode_i2_a, stop_step
from .peaks import LOOKUP_SCALARS, PeakLookup
from .render import draw_envelope
from .scenario import draw_episodes, get_scenario, scenario_from_options

__all__ = ["SbarChargingEnv", "SbarChargingDiscreteEnv"]

_SC = OBS_SCALE.tolist()
_OF = OBS_OFFSET.tolist()
_S0, _S1, _S2, _S3, _S4, _S5, _S6, _S7 = _SC
_O0, _O1, _O2, _O3, _O4, _O5, _O6, _O7 = _OF


def _n(v, i):
    x = v * _SC[i] + _OF[i]
    return -1.0 if x < -1.0 else (1.0 if x > 1.0 else x)


class SbarChargingEnv(gym.Env):
    """A drone hovers over a charging pad; its SBAR receiver must follow a charge command and, when
    the command drops to zero (battery full or departure), go from rectification mode (RM) to
    short mode (SM) without a secondary coil current overshoot.

    ## Description
    The series-series link of the paper (Table I, envelope model eq. 4, exact ZOH) is stepped every
    control period (100 us = 17 rectifier periods; split into rectifier periods when the I2
    envelope changes sign within it). Wind moves the drone around its hover pose, so
    the true mutual inductance Lm follows the pose error (updated every 1 ms). The agent sets the
    short duty ``d_short`` of the SBAR (eq. 9) for the next control period; the SBAR's V2 takes the
    sign of the I2 envelope (the diodes conduct with the instantaneous i2), so it always absorbs
    power and its output current ``I_L = (2/pi) (1 - sin(pi/2 d)) |I2| >= 0``. The SBAR output feeds
    the battery (equivalent circuit), which also supplies the hover power. The semiconductors are
    real parts (``EnvConfig.devices``, default ``"schottky"`` as the mission; ``"ideal"`` = the
    paper's circuit): the inverter's and the rectifier's on-resistances in R1 / R2, the diodes'
    forward drop on the clamp ``VL + Vf`` and the shorted channels' excess in V2
    (:func:`envs.core.advance`).

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: ``d_short = (a + 1) / 2`` (:func:`mission_sim.contract.action_to_duty`);
    -1 = rectification mode, +1 = short mode. The discrete variant (``SbarChargingDiscrete-v0``)
    takes ``Discrete(2)``: 0 = RM, 1 = SM (the classic unsynchronised ON-OFF method).

    ## Observation Space
    ``Box(-1, 1, (8,), float32)``, the contract of :mod:`mission_sim.contract`, each field mapped
    linearly from its physical range to [-1, 1] and clipped:

    | Num | Observation         | Physical range | Unit | Meaning                                        |
    |-----|---------------------|----------------|------|------------------------------------------------|
    | 0   | i2_amp_a            | 0 .. 60        | A    | secondary current envelope (sensor noise added) |
    | 1   | battery_v           | 20 .. 36       | V    | battery terminal voltage                        |
    | 2   | battery_current_a   | -60 .. 30      | A    | battery current, + = charging                   |
    | 3   | rect_current_a      | 0 .. 20        | A    | SBAR output current I_L (mean over the step)    |
    | 4   | soc                 | 0 .. 1         | -    | state of charge                                 |
    | 5   | charge_cmd_a        | 0 .. 20        | A    | command for the next step; 0 = stop charging    |
    | 6   | last_d_short        | 0 .. 1         | -    | duty applied in the previous step               |
    | 7   | t_since_stop_s      | 0 .. 0.01      | s    | time since the stop command (0 before it)       |

    Physical values (true I2, the step's instantaneous and envelope peaks, I1, V2, Lm, energy, ...)
    are in ``info``.

    ## Rewards
    Per step, with ``I_L`` the SBAR output current, ``I*`` the command, ``I2_pk`` the instantaneous
    peak |i2| of the step (``info["i2_peak_a"]``): the largest magnitude |I2| of the envelope at
    mid-step and at the end of the step (of every rectifier-period sub-step when the envelope changes
    sign within the step; a negative amplitude is a real current of that size;
    ``info["i2_peak_envelope_a"]``) plus the SBAR's harmonic ripple at the step's duty
    (:mod:`envs.peaks`):

    | Term        | Value                                              | Default weight |
    |-------------|----------------------------------------------------|----------------|
    | energy      | ``+ min(I_L, I*) / 7 A`` (energy wanted by the BMS) | 1              |
    | tracking    | ``- abs(I_L - I*) / 7 A``                           | 1              |
    | overcurrent | ``- max(0, I2_pk / I2_rated - 1)``                  | 10             |

    ``info["cost"]`` carries the overcurrent term unweighted (safety-gymnasium style), rated
    I2 = 15 A by default.

    ## Starting State
    Steady state of the link delivering the first command (2..7 A at the nominal scenario), drawn
    with the environment's ``np_random`` together with the pose-error path, the command profile
    (one change at 3..8 ms, stop at 10..16 ms) and the sensor noise.

    ## Episode End
    | Condition  | When                                                        |
    |------------|-------------------------------------------------------------|
    | terminated | never (there is no terminal state in a charging window)      |
    | truncated  | after ``n_steps`` steps (300 = 30 ms: covers the stop and the ringing) |

    ## Arguments
    ``gymnasium.make("dronewpt/SbarCharging-v0", scenario="nominal", render_mode=None, config=None)``;
    ``scenario`` is a name of :data:`envs.scenario.SCENARIOS` (nominal, lm_mismatch, windy, battery,
    random), a :class:`~envs.scenario.Scenario` or a dict of its fields; ``reset(options={"scenario":
    ...})`` overrides it for one episode. ``config`` is an :class:`~envs.core.EnvConfig`.
    ``compiled``: step in one numba-compiled call (:func:`envs.vector_kernel.single_step`, the
    default when numba is installed) or on Python floats (``False``: the reference, same numbers).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, scenario="nominal", render_mode: str | None = None, config: EnvConfig | None = None,
                 compiled: bool | None = None):
        self.scenario = get_scenario(scenario)
        self.config = config or EnvConfig()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode={render_mode!r} is invalid; valid values: None, 'rgb_array'")
        self.render_mode = render_mode
        self.observation_space = spaces.Box(-1.0, 1.0, (OBS_DIM,), np.float32)
        self.action_space = self._make_action_space()
        c = self.config
        self._T, self._M, self._dt = c.n_steps, c.slow_every, c.dt_s
        self._inv_rated = 1.0 / c.rated_i2_a
        self._n_sub = c.n_sub
        self._w = c.reward
        self._devices, self._dev = c.device_set(), c.device_terms
        self._peak = PeakLookup(c.link, self._devices)
        self._k = None
        self._hist = None
        self._line = None
        self._kern = _load_single_kernel() if compiled is None or compiled else None
        if compiled and self._kern is None:
            raise ValueError("compiled=True needs numba; install it or pass compiled=None/False")
        if self._kern is not None:
            w = self._w
            self._par = np.concatenate([[self._T, self._dt, self._inv_rated, w.tracking, w.overcurrent, w.i_ref_a,
                                         self._M, self._n_sub], OBS_SCALE, OBS_OFFSET, self._dev,
                                        LOOKUP_SCALARS, self._peak.kernel_table.shape,
                                        self._peak.kernel_table.ravel()]).astype(float)
            self._out = np.empty(19)

    # ------------------------------------------------------------------ interface
    def _make_action_space(self):
        return spaces.Box(-1.0, 1.0, (1,), np.float32)

    def _duty(self, action) -> float:
        try:   # the usual case (an array of one value or a numpy scalar), without array conversions
            a = float(action.item())
        except (AttributeError, ValueError, TypeError):
            a = float(np.asarray(action, dtype=float).reshape(-1)[0])
        if not math.isfinite(a):  # NaN would poison the link state and every reward after it
            raise ValueError(f"action={a!r} is invalid; valid range: [-1, 1] (finite)")
        d = (a + 1.0) * 0.5
        return 0.0 if d < 0.0 else (1.0 if d > 1.0 else d)

    @property
    def policy_context(self) -> PolicyContext:
        """What a policy may assume: Table I link (not the true Lm), the control period, the rating."""
        return PolicyContext(link=self.config.link, control_period_s=self._dt, rated_i2_a=self.config.rated_i2_a)

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        scn = scenario_from_options(options, self.scenario)
        p = build_plans(draw_episodes([self.np_random], scn, self._T), scn, self.config)
        if p.cplx is not None:
            raise ValueError(f"scenario {scn.name!r} (detuned tanks, complex envelope) runs in the vector env only: "
                             "envs.SbarChargingVectorEnv (or gymnasium.make_vec); valid here: c_detune=(0, 0)")
        self._plan = p
        self._t_stop = float(p.t_stop_s[0])
        self._stop_k = int(stop_step(p.t_stop_s, self._dt, self._T)[0])
        i2_sm = short_mode_i2_a(self.config.link, p.lm_h[0], self._devices)
        if self._kern is None:
            self._start_float(p, i2_sm)
        else:
            self._start_compiled(p, i2_sm)
        self._k = 0
        i1, i2 = (float(v) for v in p.x0[0])
        vl, d, soc, cmd0 = float(p.vl0[0]), float(p.d0[0]), float(p.battery[0, 2]), float(p.cmd_a[0, 0])
        il = float(rectifier_current(d, abs(i2)))
        ib = il - float(p.battery[0, 7])
        v2 = rectifier_v2_folded(d, vl, i2, self._devices, sin=math.sin, sign=SCALAR_OPS.sign)
        info = {"t_s": 0.0, "i2_a": i2, "i2_peak_a": self._peak.scalar(abs(i2), d, vl), "i1_a": i1, "d_short": d,
                "v2_v": v2, "rect_current_a": il, "battery_v": vl, "battery_current_a": ib, "soc": soc,
                "charge_cmd_a": cmd0, "lm_h": float(p.lm_h[0, 0]), "energy_j": 0.0, "cost": 0.0, "overcurrent": 0.0,
                "overshoot": -np.inf, "episode_cost": 0.0, "reached_short_mode": False, "scenario": scn.name,
                "t_stop_s": self._t_stop, "i2_peak_envelope_a": abs(i2)}
        if self.render_mode is not None:
            self._hist = [[0.0], [i2], [il], [cmd0], [d]]
        obs = np.array([_n(i2, 0), _n(vl, 1), _n(ib, 2), _n(il, 3), _n(soc, 4),
                        _n(cmd0, 5), _n(d, 6), _n(self._t_since(0), 7)], dtype=np.float32)
        self._line = None
        if p.delay_steps[0] > 0:   # sensing delay (envs.sensing)
            from .sensing import DelayLine
            self._line = DelayLine(1)
            self._line.start([0], obs[None], p.delay_steps[:1])
        return obs, info

    def _start_float(self, p, i2_sm):
        """The episode's plan as Python floats for :meth:`_step_float`."""
        self._cmd = p.cmd_a[0].tolist()
        self._noise = p.noise_a[0].tolist()
        self._coef = [tuple(r) for r in p.coef[0].tolist()]
        self._lm = p.lm_h[0].tolist()
        self._b = tuple(p.battery[0].tolist())
        self._i1, self._i2 = (float(v) for v in p.x0[0])
        self._vl, self._vrc, self._d = float(p.vl0[0]), float(p.vrc0[0]), float(p.d0[0])
        self._soc = self._b[2]
        self._i2_sm = i2_sm.tolist()
        self._run_max, self._sm_ok, self._sm_checked = -np.inf, True, False

    def _start_compiled(self, p, i2_sm):
        """The episode's plan as the arrays of :func:`envs.vector_kernel.single_step`."""
        T = self._T
        st = np.empty(20)
        st[0:2] = p.x0[0]
        st[2], st[3], st[4], st[5] = p.vl0[0], p.battery[0, 2], p.vrc0[0], p.d0[0]
        st[6], st[7], st[8], st[9], st[10] = -np.inf, 1.0, 0.0, self._stop_k, self._t_stop
        st[11:] = p.battery[0]
        steps = np.zeros((T + 1, 2))
        steps[:, 0] = p.cmd_a[0]
        steps[:T, 1] = p.noise_a[0]
        slow = np.empty((p.coef.shape[1], 22))
        slow[:, :20] = p.coef[0]
        slow[:, 20] = p.lm_h[0]
        slow[:, 21] = i2_sm
        self._st, self._steps, self._slow = st, steps, slow
        self._cmd = steps[:, 0]

    def step(self, action):
        out = self._step(action)
        if self._line is not None:
            self._line.push(out[0][None])
        return out

    def _step(self, action):
        k = self._k
        if k is None or k >= self._T:
            raise RuntimeError("step() called before reset() or after the episode was truncated; call reset()")
        d = self._duty(action)
        if self._kern is None:
            return self._step_float(k, d)
        obs = np.empty(OBS_DIM, np.float32)
        reward = self._kern(k, d, self._st, self._steps, self._slow, self._par, obs, self._out)
        t, i2, pk, i1, _, v2, il, vl, ib, soc, cmd, lm, energy, over, cost, rm, ec, pk_env, sm = self._out.tolist()
        k += 1
        self._k = k
        info = {"t_s": t, "i2_a": i2, "i2_peak_a": pk, "i1_a": i1, "d_short": d, "v2_v": v2, "rect_current_a": il,
                "battery_v": vl, "battery_current_a": ib, "soc": soc, "charge_cmd_a": cmd, "lm_h": lm,
                "energy_j": energy, "cost": cost, "overcurrent": over, "overshoot": rm, "episode_cost": ec,
                "reached_short_mode": sm != 0.0, "i2_peak_envelope_a": pk_env}
        if self._hist is not None:
            for lst, v in zip(self._hist, (t, i2, il, float(self._steps[k, 0]), d)):
                lst.append(v)
        return obs, reward, False, k >= self._T, info

    def _step_float(self, k: int, d: float):
        """:meth:`step` on Python floats (:func:`envs.core.advance` with ``SCALAR_OPS``): the reference."""
        vl_old = self._vl
        i1, i2, pk_env, il, ib, soc, vrc, vl, v2 = advance(self._i1, self._i2, vl_old, self._soc, self._vrc, d,
                                                           self._coef[k // self._M], self._b, SCALAR_OPS, self._n_sub,
                                                           self._dev)
        peak = self._peak.scalar(pk_env, d, vl_old)
        cmd = self._cmd[k]
        reward, overcurrent = reward_cost(il, cmd, peak, self._inv_rated, self._w, SCALAR_OPS)
        cost = self._objective(k, peak, il)
        energy = vl_old * il * self._dt
        self._i1, self._i2, self._soc, self._vrc, self._vl, self._d = i1, i2, soc, vrc, vl, d
        k += 1
        self._k = k
        cmd_next = self._cmd[k]
        # normalise (same affine map and clipping as mission_sim.contract.normalise_obs)
        o0 = (i2 + self._noise[k - 1]) * _S0 + _O0
        o1 = vl * _S1 + _O1
        o2 = ib * _S2 + _O2
        o3 = il * _S3 + _O3
        o4 = soc * _S4 + _O4
        obs = np.array([-1.0 if o0 < -1.0 else (1.0 if o0 > 1.0 else o0),
                        -1.0 if o1 < -1.0 else (1.0 if o1 > 1.0 else o1),
                        -1.0 if o2 < -1.0 else (1.0 if o2 > 1.0 else o2),
                        -1.0 if o3 < -1.0 else (1.0 if o3 > 1.0 else o3),
                        -1.0 if o4 < -1.0 else (1.0 if o4 > 1.0 else o4),
                        cmd_next * _S5 + _O5, d * _S6 + _O6, _n(self._t_since(k), 7)], dtype=np.float32)
        info = {"t_s": k * self._dt, "i2_a": i2, "i2_peak_a": peak, "i1_a": i1, "d_short": d, "v2_v": v2,
                "rect_current_a": il, "battery_v": vl, "battery_current_a": ib, "soc": soc,
                "charge_cmd_a": cmd, "lm_h": self._lm[(k - 1) // self._M], "energy_j": energy, "cost": cost,
                "overcurrent": overcurrent, "overshoot": self._run_max, "episode_cost": max(self._run_max, 0.0),
                "reached_short_mode": self._sm_ok and self._sm_checked, "i2_peak_envelope_a": pk_env}
        if self._hist is not None:
            for lst, v in zip(self._hist, (k * self._dt, i2, il, cmd_next, d)):
                lst.append(v)
        return obs, reward, False, k >= self._T, info

    def _t_since(self, k: int) -> float:
        t = k * self._dt - self._t_stop
        return t if (k >= self._stop_k and t > 0.0) else 0.0

    def _objective(self, k: int, peak: float, il: float) -> float:
        """Update the running overshoot and the short-mode flag after step ``k`` (:mod:`envs.objective`);
        returns the step's cost (the rise of max(0, running overshoot))."""
        if k < self._stop_k:
            return 0.0
        old = self._run_max
        ratio = (peak if peak >= 0.0 else -peak) / self._i2_sm[k // self._M] - 1.0
        if ratio > old:
            self._run_max = ratio
        if (k + 1 - self._stop_k) * self._dt >= SHORT_MODE_WITHIN_S - 1e-12:
            self._sm_checked = True
            if il >= SHORT_MODE_IL_A:
                self._sm_ok = False
        return max(self._run_max, 0.0) - max(old, 0.0)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; make the env with render_mode='rgb_array'")
            return None
        if self._hist is None:
            raise RuntimeError("render() called before reset()")
        t, i2, il, cmd, d = self._hist
        return draw_envelope(t, i2, il, cmd, d, self.config.rated_i2_a, self._T * self._dt)


def _load_single_kernel():
    """:func:`envs.vector_kernel.single_step`, or None without numba (imported here, when an env is
    built, so ``import envs`` does not load numba)."""
    import importlib.util
    if importlib.util.find_spec("numba") is None:
        return None
    from .vector_kernel import single_step
    return single_step


class SbarChargingDiscreteEnv(SbarChargingEnv):
    """:class:`SbarChargingEnv` with ``Discrete(2)`` actions: 0 = rectification mode (d_short = 0),
    1 = short mode (d_short = 1), chosen every control period (unsynchronised ON-OFF)."""

    def _make_action_space(self):
        return spaces.Discrete(2)

    def _duty(self, action) -> float:
        a = int(action)
        if a != 0 and a != 1:
            raise ValueError(f"action={action!r} is invalid; valid values: 0 (RM), 1 (SM)")
        return float(a)
