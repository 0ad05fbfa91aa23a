"""Single gymnasium environments of a drone's charging window: continuous and discrete (ON-OFF)."""

from __future__ import annotations

import math

import numpy as np
import gymnasium as gym
from gymnasium import spaces

from mission_sim.contract import OBS_DIM, PolicyContext, check_history, history_obs_dim
from mission_sim.validation import real_array, shown

from .core import OBS_OFFSET, OBS_SCALE, EnvConfig, as_config, refuse_unknown_kwargs
from .layout import INFO
from .modal_plant import single_plant
from .parts import SingleObjective, SingleObservation, alias_parts
from .peaks import PeakLookup
from .render import draw_envelope
from .scenario import ENV_SCENARIO, ScenarioPart, get_scenario
from .vector import Parts

__all__ = ["SbarChargingEnv", "SbarChargingDiscreteEnv"]


class SbarChargingEnv(gym.Env):
    """A drone hovers over a charging pad; its SBAR receiver must follow a charge command and, when
    the command drops to zero (battery full or departure), go from rectification mode (RM) to
    short mode (SM) without a secondary coil current overshoot.

    ## Description
    The series-series link of the paper (Table I) is stepped every control period (100 us = 17
    rectifier periods): by default the mission's exact-mode link (``EnvConfig(link_model="modal")``,
    :mod:`envs.modal_step`: eq. 1's coupled modes, V2 updated every rectifier period), or eq. 4's
    envelope with exact ZOH (``EnvConfig(link_model="envelope")``, :mod:`envs.vector_kernel`; split into
    rectifier periods when the I2 envelope changes sign within a step). Wind moves the drone around its hover pose, so
    the true mutual inductance Lm follows the pose error (updated every 1 ms). The agent sets the
    short duty ``d_short`` of the SBAR (eq. 9) for the next control period; the SBAR's V2 takes the
    sign of the I2 envelope (the diodes conduct with the instantaneous i2), so it always absorbs
    power and its output current ``I_L = (2/pi) (1 - sin(pi/2 d)) |I2| >= 0``. The SBAR output feeds
    the battery (equivalent circuit), which also supplies the hover power. The semiconductors are
    real parts (``EnvConfig.devices``, default ``"schottky"`` as the mission; ``"ideal"`` = the
    paper's circuit): the inverter's and the rectifier's on-resistances in R1 / R2, the diodes'
    forward drop on the clamp ``VL + Vf`` and the shorted channels' excess in V2
    (``envs.vector_kernel._link_step``).

    ## Action Space
    ``Box(-1, 1, (1,), float32)`` (``SbarCharging-v0``) or ``Discrete(2)`` (``SbarChargingDiscrete-v0``,
    the classic unsynchronised ON-OFF method), applied for the next control period:

    | Env                      | Action | Range     | Meaning                                                       |
    |--------------------------|--------|-----------|---------------------------------------------------------------|
    | ``SbarCharging-v0``      | a      | -1 .. 1   | ``d_short = (a + 1) / 2`` (:func:`mission_sim.contract.action_to_duty`): -1 = RM, +1 = SM |
    | ``SbarChargingDiscrete-v0`` | 0 / 1 | {0, 1} | 0 = rectification mode (d = 0), 1 = short mode (d = 1)       |

    A continuous action outside [-1, 1] is clipped (the duty stays in [0, 1]); NaN or inf, more or fewer
    than one number, or anything that is not a real number is a ``ValueError`` naming it (the discrete env:
    anything but 0 or 1, e.g. 0.5). A vector env takes shape ``(num_envs, 1)`` or ``(num_envs,)``.

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

    Field 0 is the I2 envelope as the step ends (signed: on eq. 4's link the envelope, on the exact-mode link
    ``|I2|`` with the sign of the phasor's real part) plus the noise, so a negative value reads 0 A after
    the clipping (a policy ringing the link, e.g. random duties: ~8 % of steps, up to ~27 A unseen; the
    mission observes ``|I2|``; docs/robustness.md, "An RL researcher's pass over the Python API").
    Field 5 is the command of the *next* step; ``info["charge_cmd_a"]`` is the one the step just taken
    was scored against (the previous observation's field 5).

    With ``history=K`` (2..the contract's MAX_HISTORY) the observation is the last K of these rows,
    oldest first, ``Box(-1, 1, (8 K,))`` (a window starts with K copies of its first row: the observation
    part's frame stack, :mod:`envs.history`). Physical values (true I2, the step's instantaneous and
    envelope peaks, I1, V2, Lm, energy, ...) are in ``info``.

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

    ``info["overcurrent"]`` carries the overcurrent term unweighted, rated I2 = 15 A by default;
    ``info["cost"]`` (safety-gymnasium style) is the domain's constraint, the rise of the running overshoot after
    the stop (:mod:`envs.objective`; the Info table), not the overcurrent term.

    ## Info
    Floats (``reached_short_mode`` a bool), the same keys after ``reset`` (at t = 0, with ``scenario`` and
    ``t_stop_s`` besides) and after every ``step`` (the step's end); a vector env's are arrays (num_envs,), its
    ``reset`` info with ``t_stop_s`` besides (no ``scenario``: the scenario of the windows it started is
    ``env.parts.scenario.current``). After a partial reset (``options={"reset_mask": m}``) only the info rows where
    ``m`` is True are meaningful (a fresh reset's); the others are not (neither gymnasium ``SyncVectorEnv``'s zeros
    with a ``_key`` mask nor the last step's values):

    | Key                  | Unit | Meaning                                                                        |
    |----------------------|------|--------------------------------------------------------------------------------|
    | t_s                  | s    | time at the end of the step                                                    |
    | i2_a, i1_a           | A    | true I2 / I1 amplitude, no noise (I2 signed as obs field 0; I1: eq. 4 signed, exact-mode link ``abs(I1)``) |
    | i2_peak_a            | A    | the step's instantaneous peak ``abs(i2)`` (what the reward, cost and overshoot use) |
    | i2_peak_envelope_a   | A    | the step's envelope (fundamental) peak, without the ripple                      |
    | d_short              | -    | the duty applied in this step                                                  |
    | v2_v                 | V    | the SBAR's V2 (fundamental; eq. 4 signed with I2, exact-mode: its component in phase with I2) |
    | rect_current_a       | A    | SBAR output current I_L, mean over the step                                    |
    | battery_v, battery_current_a, soc | V, A, - | battery terminal voltage, current (+ = charging), state of charge |
    | charge_cmd_a         | A    | the command this step was scored against                                       |
    | lm_h                 | H    | the true mutual inductance of the step                                         |
    | energy_j             | J    | ``VL I_L dt`` delivered to the battery node in the step                         |
    | overcurrent          | -    | ``max(0, i2_peak_a / rated - 1)``, the reward's overcurrent term unweighted     |
    | cost                 | -    | the rise of the running overshoot in this step (sums to ``episode_cost``)      |
    | overshoot            | -    | running overshoot since the stop (:mod:`envs.objective`); ``-inf`` before the stop, and all window long if the stop falls after ``n_steps`` |
    | episode_cost         | -    | ``max(0, overshoot)`` so far                                                   |
    | reached_short_mode   | bool | the window has reached short mode (decided 14 ms after the stop; False until then) |

    ## Starting State
    Drawn with the environment's ``np_random`` by the scenario part (:class:`envs.scenario.ScenarioPart`,
    the scenario's :class:`~envs.scenario.Draw` parts in order), at the nominal scenario:

    | Quantity              | Start                                                                 |
    |-----------------------|-----------------------------------------------------------------------|
    | I1, I2, V_L, d        | steady state of the link delivering the first command                  |
    | charge command        | 2..7 A, one change at 3..8 ms to another 2..7 A, 0 from the stop at 10..16 ms |
    | true Lm               | the coupling model's at the nominal hover pose, constant (no wind)     |
    | SoC                   | 0.5 (battery equivalent circuit at that SoC)                           |
    | I2 sensor noise       | 0.1 A standard deviation per step                                      |

    ## Episode End
    | Condition  | When                                                        |
    |------------|-------------------------------------------------------------|
    | terminated | never (there is no terminal state in a charging window)      |
    | truncated  | after ``n_steps`` steps (300 = 30 ms: covers the stop and the ringing) |

    ## Arguments
    ``gymnasium.make("dronewpt/SbarCharging-v0", scenario="nominal", render_mode=None, config=None)``;
    ``scenario`` is a name of :data:`envs.scenario.SCENARIOS` (nominal, lm_mismatch, windy, battery,
    random and the model-is-wrong ones, or one added with :func:`envs.scenario.register_scenario`), a
    :class:`~envs.scenario.Scenario` or a dict of its fields (a range may be one number: ``{"soc": 0.3}``);
    ``reset(options={"scenario": ...})`` overrides it for that episode only (a ``reset()`` without options
    returns to ``scenario``). ``config`` is an :class:`~envs.core.EnvConfig` or a dict of its fields
    (``config={"link_model": "envelope", "reward": {"overcurrent": 20}}``). ``history=K``: the frame stack
    above. ``compiled``: the step is one numba-compiled call (``single_step`` of :mod:`envs.modal_step`, or of
    :mod:`envs.vector_kernel` on eq. 4's link: the helpers of the vector env's step on one window); ``False``
    runs the same source uncompiled (``py_func``: slow, for tests). Detuned windows (scenario ``detuned``) step
    their complex envelope on eq. 4's link, their C1, C2 in the link constants on the exact-mode link.
    ``terminated`` is always False and the env truncates itself after ``n_steps``, so the registration has no
    ``max_episode_steps`` (``env.spec.max_episode_steps`` is None; ``gymnasium.make(..., max_episode_steps=N)``
    adds a ``TimeLimit`` that cuts windows shorter; the vector env, ``gymnasium.make_vec(..., max_episode_steps=N)``,
    cuts its windows after ``min(N, n_steps)`` steps alike).

    ## Parts
    ``env.parts`` = (scenario, plant, objective, observation) (:mod:`envs.parts`, docs/envs.md): ``reset``
    calls each part's ``reset`` once, ``step`` the plant's (the compiled step), the objective's and the
    observation's once; state by name (``env.state_names``, :mod:`envs.layout`).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}
    scenario = ENV_SCENARIO

    def __init__(self, scenario="nominal", render_mode: str | None = None, config: EnvConfig | dict | None = None,
                 compiled: bool | None = None, history: int = 1, **unknown):
        refuse_unknown_kwargs(type(self).__name__, unknown,   # (Python's bare "unexpected keyword argument 'n_steps'")
                              ("scenario", "render_mode", "config", "compiled", "history"))
        scenario = get_scenario(scenario)
        self.config = as_config(config)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode={render_mode!r} is invalid; valid values: None, 'rgb_array'")
        self.render_mode = render_mode
        self.history = history = check_history(history)   # (2.0 was stored as a float)
        self.observation_space = spaces.Box(-1.0, 1.0, (history_obs_dim(history),), np.float32)
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
        self._compiled = compiled is None or bool(compiled)
        self._out = np.empty(len(INFO) + 1)
        # the per-step row of the single kernel (command, I2 sensor noise): the scenario part's stores
        self._steps = np.zeros((self._T + 1, 2))
        plant = single_plant(c, self._compiled)
        observation = SingleObservation(c, self._peak, self._compiled, self.history)
        self.parts = Parts(ScenarioPart(scenario, self._T, self._dt, None, None, compiled=self._compiled),
                           plant, SingleObjective(c, plant), observation)
        self._share_steps()
        # the compiled step's constants, each part's by name, then the observation map and the peak table
        vals = {**plant.constants(self._peak), **self.parts.objective.constants()}
        self._par = np.concatenate([[vals[f] for f in plant.PAR._fields], OBS_SCALE, OBS_OFFSET,
                                    self._peak.kernel_table.ravel()]).astype(float)

    def _share_steps(self) -> None:
        """The scenario part's stores, command (T + 1, 1) and I2 sensor noise (T, 1), as views of the step rows the
        compiled step reads (``_steps``). When built, and again after ``copy.deepcopy`` or an unpickling: a copy gives
        each view an array of its own, and the copy's next windows were stepped on the command and noise of the
        window it was copied in (only the vector env's parts own their stores)."""
        self._cmd = self._steps[:, 0]   # the command per step [A] (a view)
        scenario = self.parts.scenario
        scenario.cmd, scenario.noise = self._steps[:, :1], self._steps[:-1, 1:]

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._share_steps()

    # ------------------------------------------------------------------ interface
    def _make_action_space(self):
        return spaces.Box(-1.0, 1.0, (1,), np.float32)

    def _duty(self, action) -> float:
        try:   # the usual case (a float array of one value, a numpy float or a torch scalar): no array conversion
            a = action.item()
        except (AttributeError, ValueError, RuntimeError):   # no .item() (a list); two values (numpy's, torch's)
            a = None
        if type(a) is not float:   # "0.5" of an array of strings was float()ed; ints, bools: one number of any kind,
            a = _one_number(action)   # or a one-line error naming it (no dtype check here: ~0.1 us of the step's ~5)
        if not math.isfinite(a):  # NaN would poison the link state and every reward after it
            raise ValueError(f"action={a!r} is invalid; valid range: [-1, 1] (finite)")
        d = (a + 1.0) * 0.5
        return 0.0 if d < 0.0 else (1.0 if d > 1.0 else d)

    @property
    def policy_context(self) -> PolicyContext:
        """What a policy may assume: Table I link (not the true Lm), the control period, the rating."""
        return PolicyContext(link=self.config.link, control_period_s=self._dt, rated_i2_a=self.config.rated_i2_a,
                             link_model=self.config.link_model)

    @property
    def state_names(self) -> tuple:
        """Names of the plant's link and battery state (:data:`envs.layout.STATE`)."""
        return self.parts.plant.state_names

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        scenario, plant, objective, observation = self.parts   # each part once, in order
        win = scenario.reset([self.np_random], slice(None), options)
        plan = plant.reset(slice(None), win)
        objective.reset(slice(None), win, plan)
        self._k = 0
        obs, info = observation.reset(win, plant, objective)
        if self.render_mode is not None:
            self._hist = [[0.0], [info["i2_a"]], [info["rect_current_a"]], [info["charge_cmd_a"]], [info["d_short"]]]
        return obs, info

    def step(self, action):
        k = self._k
        if k is None or k >= self._T:
            raise RuntimeError("step() called before reset() or after the episode was truncated; call reset()")
        d = self._duty(action)
        obs = np.empty(OBS_DIM, np.float32)
        _, plant, objective, observation = self.parts
        reward = plant.step(k, d, self._steps, self._par, obs, self._out)
        obs, info = observation.step(obs, self._out, d, objective.step(self._out))
        k += 1
        self._k = k
        if self._hist is not None:
            for lst, v in zip(self._hist, (info["t_s"], info["i2_a"], info["rect_current_a"],
                                           float(self._steps[k, 0]), d)):
                lst.append(v)
        return obs, float(reward), False, k >= self._T, info

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
        if type(action) is int or isinstance(action, np.integer):   # the usual case (SB3, action_space.sample())
            a = action
        else:   # one number of any kind (a 0-d or one-element array, a float that is whole); 0.5 is not 0
            try:
                a = _one_number(action)
            except ValueError:
                a = None
        if a != 0 and a != 1:
            raise ValueError(f"action={shown(action)} is invalid; valid values: 0 (RM), 1 (SM)")
        return float(a)


def _one_number(action) -> float:
    """The one real number of ``action`` (a Python number, a list or array of one element); a ``ValueError``
    naming it for anything else: two values (only the first was used), none, None, a string, a complex."""
    x = real_array(action)
    if x is None or x.size != 1:
        raise ValueError(f"action={shown(action)} is invalid; valid: one number in [-1, 1], shape (1,) as the "
                         "action_space (values outside are clipped)")
    return float(x.reshape(-1)[0])


alias_parts(SbarChargingEnv, {"_st": ("plant", "st"), "_slow": ("plant", "slow"), "_cc": ("plant", "cc"),
                              "_lc": ("plant", "lc"), "_cz": ("plant", "cz"), "_tab": ("plant", "tab"),
                              "_t_stop": ("objective", "t_stop"), "_stop_k": ("objective", "stop_k"),
                              "_line": ("observation", "line")})
