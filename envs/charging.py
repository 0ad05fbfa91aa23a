"""Single gymnasium environments of a drone's charging window: continuous and discrete (ON-OFF)."""

from __future__ import annotations

import math

import numpy as np
import gymnasium as gym
from gymnasium import spaces

from mission_sim.contract import OBS_DIM, PolicyContext

from wpt_receiver.sbar import rectifier_current, rectifier_v2_folded

from .core import OBS_OFFSET, OBS_SCALE, EnvConfig, build_plans, kernel_function
from .layout import BAT, INFO, SINGLE, SINGLE_PAR, SLOW, XC
from .objective import short_mode_i2_a, stop_step
from .peaks import LOOKUP_SCALARS, PeakLookup
from .render import draw_envelope
from .scenario import draw_episodes, get_scenario, scenario_from_options

__all__ = ["SbarChargingEnv", "SbarChargingDiscreteEnv"]



def _sign(x: float) -> float:
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


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
    ``compiled``: the step is one numba-compiled call (:func:`envs.vector_kernel.single_step`, the
    helpers of the vector env's step on one window); ``False`` runs the same source uncompiled
    (``py_func``: slow, for tests). Detuned windows (scenario ``detuned``) step their complex envelope.
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
        self._compiled = compiled is None or bool(compiled)
        self._kern = kernel_function("single_step", self._compiled)   # also: numba imported here
        w, tab = self._w, self._peak.kernel_table
        vals = dict(n_steps=self._T, dt=self._dt, inv_rated=self._inv_rated, w_track=w.tracking,
                    w_over=w.overcurrent, i_ref=w.i_ref_a, slow_every=self._M, n_sub=self._n_sub, vf=self._dev[0],
                    dr=self._dev[1], vlc=LOOKUP_SCALARS[0], inv_imax=LOOKUP_SCALARS[1], v1=c.link.v1_amp_v,
                    nd=tab.shape[0], ni=tab.shape[1], nq=tab.shape[2])
        self._par = np.concatenate([[vals[f] for f in SINGLE_PAR._fields], OBS_SCALE, OBS_OFFSET,
                                    tab.ravel()]).astype(float)
        self._out = np.empty(len(INFO) + 1)

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
        self._plan = p
        self._t_stop = float(p.t_stop_s[0])
        self._stop_k = int(stop_step(p.t_stop_s, self._dt, self._T)[0])
        self._start(p)
        self._k = 0
        st = self._st
        i1, i2, vl, d, soc = (float(st[f]) for f in (SINGLE.i1, SINGLE.i2, SINGLE.vl, SINGLE.d, SINGLE.soc))
        cmd0 = float(p.cmd_a[0, 0])
        il = float(rectifier_current(d, abs(i2)))
        ib = il - float(p.battery[0, BAT.i_load])
        v2 = rectifier_v2_folded(d, vl, i2, self._devices, sin=math.sin, sign=_sign)
        info = {"t_s": 0.0, "i2_a": i2, "i2_peak_a": self._peak.scalar(abs(i2), d, vl), "i1_a": i1, "d_short": d,
                "v2_v": v2, "rect_current_a": il, "battery_v": vl, "battery_current_a": ib, "soc": soc,
                "charge_cmd_a": cmd0, "lm_h": float(p.lm_h[0, 0]), "energy_j": 0.0, "cost": 0.0, "overcurrent": 0.0,
                "overshoot": -np.inf, "episode_cost": 0.0, "reached_short_mode": False, "scenario": scn.name,
                "t_stop_s": self._t_stop, "i2_peak_envelope_a": abs(i2)}
        if self.render_mode is not None:
            self._hist = [[0.0], [i2], [il], [cmd0], [d]]
        obs = np.empty((1, OBS_DIM), np.float32)
        vals = np.array([[i2], [vl], [ib], [il], [soc], [cmd0], [d], [self._t_since(0)]])
        self._fn("obs_rows")(vals, OBS_SCALE, OBS_OFFSET, obs)
        self._line = None
        if p.delay_steps[0] > 0:   # sensing delay (envs.sensing)
            from .sensing import DelayLine
            self._line = DelayLine(1)
            self._line.start([0], obs, p.delay_steps[:1])
        return obs[0], info

    def _fn(self, name):
        return kernel_function(name, self._compiled)

    def _start(self, p):
        """The episode's plan as the arrays of :func:`envs.vector_kernel.single_step` (a detuned window:
        its complex state after :data:`SINGLE` and its coefficients in ``_cc``)."""
        T = self._T
        i2_sm = short_mode_i2_a(self.config.link, p.lm_h[0], self._devices)
        st = np.empty(len(SINGLE) + (len(XC) if p.cplx is not None else 0))
        st[SINGLE.i1], st[SINGLE.i2] = p.x0[0]
        st[SINGLE.vl], st[SINGLE.soc], st[SINGLE.vrc], st[SINGLE.d] = p.vl0[0], p.battery[0, BAT.soc0], p.vrc0[0], p.d0[0]
        st[SINGLE.run_max], st[SINGLE.sm_ok], st[SINGLE.sm_checked] = -np.inf, 1.0, 0.0
        st[SINGLE.stop_k], st[SINGLE.t_stop] = self._stop_k, self._t_stop
        st[SINGLE.ocv0:SINGLE.bus_decay + 1] = p.battery[0]
        self._cc = np.zeros((0, 32))
        if p.cplx is not None:
            from .detuned import detuned_start
            i2_sm, i1, i2, _ = detuned_start(self.config, self._devices, p)
            i2_sm = i2_sm[0]
            st[SINGLE.i1], st[SINGLE.i2] = i1[0], i2[0]
            st[len(SINGLE):] = p.cplx[1][0]
            self._cc = np.ascontiguousarray(p.cplx[0][0])
        steps = np.zeros((T + 1, 2))
        steps[:, 0] = p.cmd_a[0]
        steps[:T, 1] = p.noise_a[0]
        slow = np.empty((p.coef.shape[1], len(SLOW)))
        slow[:, :SLOW.lm_h] = p.coef[0]
        slow[:, SLOW.lm_h] = p.lm_h[0]
        slow[:, SLOW.i2_sm_a] = i2_sm
        self._st, self._steps, self._slow = st, steps, slow
        self._cmd = steps[:, 0]   # the command per step [A] (a view)

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
        obs = np.empty(OBS_DIM, np.float32)
        kern = self._kern if self._compiled else self._fn("single_step")
        reward = kern(k, d, self._st, self._steps, self._slow, self._par, obs, self._out, self._cc)
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
        return obs, float(reward), False, k >= self._T, info

    def _t_since(self, k: int) -> float:
        t = k * self._dt - self._t_stop
        return t if (k >= self._stop_k and t > 0.0) else 0.0

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode; make the env with render_mode='rgb_array'")
            return None
        if self._hist is None:
            raise RuntimeError("render() called before reset()")
        t, i2, il, cmd, d = self._hist
        return draw_envelope(t, i2, il, cmd, d, self.config.rated_i2_a, self._T * self._dt)


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
