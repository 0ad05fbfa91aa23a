"""The batched vector versions of the charging environments.

Sub-environment ``i`` owns its own generator (seeded ``seed + i`` like
:class:`gymnasium.vector.SyncVectorEnv`), so the batched env reproduces ``num_envs`` single
environments seeded the same way. Autoreset: ``NEXT_STEP`` (the step after an episode ended resets
that sub-environment, returns its first observation, reward 0, and ignores its action).

The step is one compiled call (:func:`envs.vector_kernel.env_step`, the one implementation of the
env step, shared with the single env); this module keeps the orchestration: episodes drawn with
two generator calls per restarted sub-environment (:func:`envs.scenario.draw_episodes`) and planned
on arrays (:func:`envs.core.build_plans`), autoresets, the sensing delay, the info dict.

Threads: ``num_threads`` (default: numba's, all cores) sets how many threads step the sub-environments
(``numba.set_num_threads`` before each parallel step); below :attr:`SbarChargingVectorEnv.PARALLEL_MIN_ENVS`
sub-environments, or with ``num_threads=1``, the step runs on the calling thread (waking a thread pool
costs more than it saves there). The results do not depend on the threads (each sub-environment's
arithmetic is the same in any chunk): parallel == serial to the bit.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from mission_sim.contract import OBS_DIM, PolicyContext

from wpt_receiver.sbar import rectifier_current, rectifier_v2_folded

from .core import N_BAT, N_COEF, OBS_OFFSET, OBS_SCALE, EnvConfig, build_plans, kernel_function
from .layout import BAT, CCOEF_N, INFO, PAR, STATE, XC
from .objective import short_mode_i2_a, stop_step
from .peaks import LOOKUP_SCALARS, PeakLookup
from .scenario import draw_episodes, get_scenario, scenario_from_options

__all__ = ["SbarChargingVectorEnv", "SbarChargingDiscreteVectorEnv"]


class SbarChargingVectorEnv(VectorEnv):
    """``num_envs`` charging windows stepped at once; see :class:`envs.charging.SbarChargingEnv` for
    the spaces, reward and episode definition. ``info`` holds arrays of shape (num_envs,).

    ``compiled=False`` runs the compiled step's own source uncompiled (``py_func``: slow, for tests);
    ``num_threads``: threads of the parallel step (1..numba's thread count; default all)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    #: fewer sub-environments than this step on the calling thread
    PARALLEL_MIN_ENVS = 2048
    #: chunks per thread of the parallel step (smaller chunks even out a busy core)
    CHUNKS_PER_THREAD = 4

    def __init__(self, num_envs: int = 1, scenario="nominal", config: EnvConfig | None = None,
                 render_mode: str | None = None, compiled: bool | None = None, num_threads: int | None = None):
        if int(num_envs) != num_envs or num_envs < 1:
            raise ValueError(f"num_envs={num_envs!r} is invalid; valid range: integer >= 1")
        if render_mode is not None:
            raise ValueError(f"render_mode={render_mode!r} is invalid for the vector env; valid values: None "
                             "(render a single env instead)")
        self.num_envs = int(num_envs)
        self.render_mode = None
        self.scenario = get_scenario(scenario)
        self.config = c = config or EnvConfig()
        self.single_observation_space = spaces.Box(-1.0, 1.0, (OBS_DIM,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.single_action_space = self._make_action_space()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.num_threads = _num_threads(num_threads)
        self._compiled = compiled is None or bool(compiled)
        self._kernel = kernel_function("env_step", self._compiled)   # also: numba imported here
        self._alloc(c)

    def _alloc(self, c: EnvConfig):
        """The arrays of the episodes and the step (named slots: :mod:`envs.layout`)."""
        n, T, S = self.num_envs, c.n_steps, c.n_slow
        self._T, self._M, self._dt = T, c.slow_every, c.dt_s
        self._n_sub = c.n_sub
        self._devices, self._dev = c.device_set(), c.device_terms
        self._peak = PeakLookup(c.link, self._devices)
        w = c.reward
        vals = dict(n_steps=T, dt=self._dt, inv_rated=1.0 / c.rated_i2_a, w_track=w.tracking, w_over=w.overcurrent,
                    i_ref=w.i_ref_a, vf=self._dev[0], dr=self._dev[1], vlc=LOOKUP_SCALARS[0],
                    inv_imax=LOOKUP_SCALARS[1])
        self._par = np.array([vals[f] for f in PAR._fields], dtype=float)
        self._ar = np.arange(n)
        # per-step data stored step-major (T, n): a step reads one contiguous row across the envs
        self._cmd = np.zeros((T + 1, n))
        self._noise = np.zeros((T, n))
        self._coef_all = np.zeros((n, S, N_COEF))
        self._coef_cur = np.zeros((n, N_COEF))   # the current slow segment's coefficients (updated by the step)
        self._lm_all = np.zeros((S, n))
        self._bat = np.zeros((N_BAT, n))
        self._t_stop = np.zeros(n)
        self._delay = np.zeros(n, dtype=np.int64)   # sensing delay [steps] (envs.sensing), None line when never used
        self._line = None
        # detuned windows (envs.detuned): flag, complex state, coefficients; empty until one is drawn
        self._detuned = np.zeros(0, np.bool_)
        self._xc, self._ccoef, self._c_rel = np.zeros((0, len(XC))), np.zeros((0, 0, CCOEF_N)), None
        self._i2sm_all = np.ones((n, S))   # objective (envs.objective): short-mode I2 of the true link
        self._stop_k = np.zeros(n, dtype=np.int64)
        self._run_max = np.full(n, -np.inf)
        self._sm_ok = np.ones(n, dtype=bool)
        self._sm_checked = np.zeros(n, dtype=bool)
        self._j = np.zeros(n, dtype=np.int64)
        self._k = np.zeros(n, dtype=np.int64)
        self._state = np.zeros((len(STATE), n))
        self._prev_done = np.zeros(n, dtype=bool)
        self._rngs = [None] * n
        self._cur_scenario = self.scenario
        self._started = False
        self._obs_scale = OBS_SCALE[:, None]
        self._obs_offset = OBS_OFFSET[:, None]
        serial = n < self.PARALLEL_MIN_ENVS or self.num_threads == 1
        self._n_chunks = 1 if serial else min(self.num_threads * self.CHUNKS_PER_THREAD, max(1, n // 256))

    def _make_action_space(self):
        return spaces.Box(-1.0, 1.0, (1,), np.float32)

    def _duty(self, actions) -> np.ndarray:
        a = actions if isinstance(actions, np.ndarray) and actions.dtype.kind == "f" else np.asarray(actions, float)
        d = np.empty(self.num_envs)
        k = kernel_function("duty_kernel", self._compiled)(a.reshape(self.num_envs), d)
        if k >= 0:   # NaN would poison the link state and every reward after it
            raise ValueError(f"actions[{k}]={float(a.reshape(-1)[k])!r} is invalid; valid range: [-1, 1] (finite)")
        return d

    @property
    def policy_context(self) -> PolicyContext:
        return PolicyContext(link=self.config.link, control_period_s=self._dt, rated_i2_a=self.config.rated_i2_a)

    # ------------------------------------------------------------------ episodes
    def _start(self, idx: np.ndarray):
        """(Re)start the sub-environments ``idx``: draw with their generators, build plans batched.
        The scenario is the one given to the last ``reset`` (``options["scenario"]``) or the env's."""
        c, scn = self.config, self._cur_scenario
        rngs = self._rngs if len(idx) == self.num_envs else [self._rngs[i] for i in idx]
        full = len(idx) == self.num_envs
        # all at once (the usual autoreset): command, noise and coefficients written in place, plain slices
        out = (self._cmd, self._noise, self._coef_all) if full else None
        p = build_plans(draw_episodes(rngs, scn, c.n_steps), scn, c, out=out)
        if full:
            idx = slice(None)
        else:
            self._cmd[:, idx] = p.cmd_a.T
            self._noise[:, idx] = p.noise_a.T
            self._coef_all[idx] = p.coef
        self._lm_all[:, idx] = p.lm_h.T
        self._bat[:, idx] = p.battery.T
        self._t_stop[idx] = p.t_stop_s
        self._delay[idx] = p.delay_steps
        if self._line is None and self._delay.any():
            from .sensing import DelayLine
            self._line = DelayLine(self.num_envs)
        self._i2sm_all[idx] = short_mode_i2_a(c.link, p.lm_h, self._devices)
        self._stop_k[idx] = stop_step(p.t_stop_s, c.dt_s, c.n_steps)
        self._run_max[idx] = -np.inf
        self._sm_ok[idx] = True
        self._sm_checked[idx] = False
        self._coef_cur[idx] = p.coef[:, 0]
        self._j[idx] = 0
        self._k[idx] = 0
        st = self._state
        st[STATE.i1, idx], st[STATE.i2, idx] = p.x0[:, 0], p.x0[:, 1]
        st[STATE.vl, idx], st[STATE.soc, idx] = p.vl0, p.battery[:, BAT.soc0]
        st[STATE.vrc, idx], st[STATE.d, idx] = p.vrc0, p.d0
        self._start_detuned(idx, p)

    def _start_detuned(self, idx, p):
        """Detuned windows (:mod:`envs.detuned`, ``p.cplx``): their flag, complex-envelope coefficients
        and state (the step runs them on the complex envelope); other windows are unflagged."""
        cplx = p.cplx
        if cplx is None:
            if len(self._detuned):
                self._detuned[idx] = False
            return
        if not len(self._detuned):
            n = self.num_envs
            self._detuned = np.zeros(n, np.bool_)
            self._ccoef = np.zeros((n, self.config.n_slow, CCOEF_N))
            self._xc = np.zeros((n, len(XC)))
            self._c_rel = np.zeros((2, n))
        self._detuned[idx] = True
        self._ccoef[idx], self._xc[idx] = cplx[0], cplx[1]
        from .detuned import detuned_start
        i2sm, i1, i2, self._c_rel[:, idx] = detuned_start(self.config, self._devices, p)
        self._i2sm_all[idx] = i2sm
        self._state[STATE.i1, idx], self._state[STATE.i2, idx] = i1, i2

    def _initial_obs_info(self):
        """Observation and info of the windows' first state (steady state at the first duty)."""
        st = self._state
        i1, i2, vl, soc, d = st[STATE.i1], st[STATE.i2], st[STATE.vl], st[STATE.soc], st[STATE.d]
        il = rectifier_current(d, np.abs(i2))
        ib = il - self._bat[BAT.i_load]
        cmd = self._cmd[self._k, self._ar]
        t_since = np.where(self._k >= self._stop_k, np.maximum(self._k * self._dt - self._t_stop, 0.0), 0.0)
        obs = np.empty((self.num_envs, OBS_DIM), np.float32)
        kernel_function("obs_rows", self._compiled)(np.stack([i2, vl, ib, il, soc, cmd, d, t_since]), OBS_SCALE,
                                                     OBS_OFFSET, obs)
        info = {"t_s": self._k * self._dt, "i2_a": i2.copy(), "i2_peak_a": self._peak.array(np.abs(i2), d, vl),
                "i1_a": i1.copy(), "d_short": d.copy(), "v2_v": rectifier_v2_folded(d, vl, i2, self._devices),
                "rect_current_a": il, "battery_v": vl.copy(), "battery_current_a": ib, "soc": soc.copy(),
                "charge_cmd_a": cmd, "lm_h": self._lm_all[self._j, self._ar], "energy_j": np.zeros(self.num_envs),
                "cost": np.zeros(self.num_envs), "overcurrent": np.zeros(self.num_envs),
                "overshoot": self._run_max.copy(), "episode_cost": np.maximum(self._run_max, 0.0),
                "reached_short_mode": self._sm_ok & self._sm_checked, "t_stop_s": self._t_stop.copy(),
                "i2_peak_envelope_a": np.abs(i2)}
        return obs, info

    def restart(self, idx) -> np.ndarray:
        """Start new episodes in the sub-environments ``idx`` now (same-step autoreset, as
        stable-baselines3 wants it); returns their first observations, shape (len(idx), OBS_DIM)."""
        idx = np.asarray(idx, dtype=np.int64)
        self._start(idx)
        self._prev_done[idx] = False
        obs, _ = self._initial_obs_info()
        if self._line is not None:
            self._line.start(idx, obs[idx], self._delay[idx])
        return obs[idx]

    def reset(self, *, seed=None, options: dict | None = None):
        super().reset(seed=seed if seed is None or np.ndim(seed) == 0 else int(seed[0]))
        n = self.num_envs
        if seed is None:
            seeds = [None] * n
        elif np.ndim(seed) == 0:
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = [int(s) for s in seed]
            if len(seeds) != n:
                raise ValueError(f"seed has {len(seeds)} entries; valid: one int or num_envs={n} ints")
        if seed is not None or not self._started:
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        self._cur_scenario = scenario_from_options(options, self.scenario)
        self._start(self._ar)
        self._prev_done[:] = False
        self._started = True
        obs, info = self._initial_obs_info()
        if self._line is not None:
            self._line.start(self._ar, obs, self._delay)
        return obs, info

    def step(self, actions):
        if not self._started:
            raise RuntimeError("step() called before reset(); call reset()")
        d = self._duty(actions)
        done = self._prev_done
        any_done = bool(done.any())
        if any_done:
            self._k[done] = 0   # these rows are stepped for nothing and restarted below
        obs, reward, truncated, info = self._step_kernel(d)
        terminated = np.zeros(self.num_envs, dtype=bool)
        if self._line is not None:
            self._line.push(obs)
        if any_done:
            idx = np.flatnonzero(done)
            self._start(idx)
            obs0, info0 = self._initial_obs_info()
            obs[idx] = obs0[idx]
            if self._line is not None:
                self._line.start(idx, obs0[idx], self._delay[idx])
            reward[idx] = 0.0
            truncated[idx] = False
            for key, v in info.items():
                v[idx] = info0[key][idx]
        self._prev_done = truncated.copy()
        return obs, reward, terminated, truncated, info

    def _step_kernel(self, d):
        """One step of every sub-environment in one call of :func:`envs.vector_kernel.env_step` (the
        objective and the detuned windows included)."""
        n = self.num_envs
        obs = np.empty((n, OBS_DIM), np.float32)
        reward = np.empty(n)
        truncated = np.empty(n, dtype=bool)
        block = np.empty((n, len(INFO)))
        ep = (self._i2sm_all, self._stop_k, self._t_stop, self._run_max, self._sm_ok, self._sm_checked)
        cx = (self._detuned, self._xc, self._ccoef, self.config.link.v1_amp_v)
        if self._n_chunks > 1:
            _set_threads(self.num_threads)
        kern = self._kernel if self._compiled else kernel_function("env_step", False)
        kern(d, self._state, self._k, self._j, self._coef_all, self._coef_cur, self._bat, self._cmd, self._noise,
             self._lm_all, ep, self._M, self._n_sub, self._par, OBS_SCALE, OBS_OFFSET, self._peak.kernel_table, obs,
             reward, truncated, block, cx, self._n_chunks)
        info = dict(zip(INFO._fields, block.T))   # (n,) views, one per key
        info["reached_short_mode"] = self._sm_ok & self._sm_checked
        info["i2_peak_envelope_a"] = info.pop("i2_peak_envelope_a")   # last, as in the single env
        return obs, reward, truncated, info


def _num_threads(num_threads) -> int:
    """``num_threads`` checked against numba's pool (default: all its threads)."""
    import numba
    top = numba.config.NUMBA_NUM_THREADS
    if num_threads is None:
        return top
    if int(num_threads) != num_threads or not 1 <= num_threads <= top:
        raise ValueError(f"num_threads={num_threads!r} is invalid; valid range: integer 1..{top} (numba's threads)")
    return int(num_threads)


def _set_threads(k: int) -> None:
    import numba
    if numba.get_num_threads() != k:
        numba.set_num_threads(k)


class SbarChargingDiscreteVectorEnv(SbarChargingVectorEnv):
    """Batched :class:`envs.charging.SbarChargingDiscreteEnv`: actions in {0: RM, 1: SM}."""

    def _make_action_space(self):
        return spaces.Discrete(2)

    def _duty(self, actions) -> np.ndarray:
        a = np.asarray(actions).reshape(self.num_envs)
        if np.any((a != 0) & (a != 1)):
            raise ValueError(f"actions={a[(a != 0) & (a != 1)][0]!r} is invalid; valid values: 0 (RM), 1 (SM)")
        return a.astype(float)
