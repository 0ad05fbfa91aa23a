"""Batched (numpy) vector versions of the charging environments.

Every operation of a step runs on arrays of shape (num_envs,); sub-environment ``i`` owns its own
generator (seeded ``seed + i`` like :class:`gymnasium.vector.SyncVectorEnv`), so the batched env
reproduces ``num_envs`` single environments seeded the same way. Autoreset: ``NEXT_STEP`` (the
step after an episode ended resets that sub-environment, returns its first observation, reward 0,
and ignores its action).

Speed: the step runs in one compiled loop over the sub-environments (:mod:`envs.vector_kernel`,
numba, the default when numba is installed; ``compiled=False`` keeps the numpy path of
:func:`envs.core.advance`, the reference); episodes are drawn with two generator calls per
restarted sub-environment (:func:`envs.scenario.draw_episodes`) and planned on arrays.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from mission_sim.contract import OBS_DIM, PolicyContext

from wpt_receiver.sbar import rectifier_current, rectifier_v2_folded

from .core import (N_BAT, N_COEF, NUMPY_OPS, OBS_OFFSET, OBS_SCALE, EnvConfig, advance, build_plans, reward_cost)
from .objective import overshoot_update, short_mode_i2_a, short_mode_update, stop_step, t_since_stop_s
from .peaks import LOOKUP_SCALARS, PeakLookup
from .scenario import draw_episodes, get_scenario, scenario_from_options

__all__ = ["SbarChargingVectorEnv", "SbarChargingDiscreteVectorEnv"]


class SbarChargingVectorEnv(VectorEnv):
    """``num_envs`` charging windows stepped at once; see :class:`envs.charging.SbarChargingEnv` for
    the spaces, reward and episode definition. ``info`` holds arrays of shape (num_envs,)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, scenario="nominal", config: EnvConfig | None = None,
                 render_mode: str | None = None, compiled: bool | None = None):
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
        n, T, S = self.num_envs, c.n_steps, c.n_slow
        self._T, self._M, self._dt, self._inv_rated = T, c.slow_every, c.dt_s, 1.0 / c.rated_i2_a
        self._n_sub = c.n_sub
        self._devices, self._dev = c.device_set(), c.device_terms
        self._peak = PeakLookup(c.link, self._devices)
        w = c.reward   # the kernel's constants (envs.vector_kernel._finish_pass), one float array: a cheap dispatch
        self._par = np.array([T, self._dt, self._inv_rated, w.tracking, w.overcurrent, w.i_ref_a, *self._dev,
                              *LOOKUP_SCALARS], dtype=float)
        self._ar = np.arange(n)
        # per-step data stored step-major (T, n): a step reads one contiguous row across the envs
        self._cmd = np.zeros((T + 1, n))
        self._noise = np.zeros((T, n))
        self._coef_all = np.zeros((n, S, N_COEF))
        self._lm_all = np.zeros((S, n))
        self._bat = np.zeros((N_BAT, n))
        self._t_stop = np.zeros(n)
        self._delay = np.zeros(n, dtype=np.int64)   # sensing delay [steps] (envs.sensing), None line when never used
        self._line = None
        self._ccoef = None   # complex-envelope coefficients when a window is detuned (envs.detuned)
        self._i2sm_all = np.ones((n, S))   # objective (envs.objective): short-mode I2 of the true link
        self._stop_k = np.zeros(n, dtype=np.int64)
        self._run_max = np.full(n, -np.inf)
        self._sm_ok = np.ones(n, dtype=bool)
        self._sm_checked = np.zeros(n, dtype=bool)
        self._coef = np.zeros((N_COEF, n))     # numpy path: the current coefficients, one row per coefficient
        self._coef_cur = np.zeros((n, N_COEF))  # compiled path: the same, one row per env (updated in place)
        self._j = np.zeros(n, dtype=np.int64)
        self._k = np.zeros(n, dtype=np.int64)
        self._state = np.zeros((6, n))   # i1, i2, vl, soc, vrc, d
        self._prev_done = np.zeros(n, dtype=bool)
        self._rngs = [None] * n
        self._cur_scenario = self.scenario
        self._started = False
        self._obs_scale = OBS_SCALE[:, None]
        self._obs_offset = OBS_OFFSET[:, None]
        self._kernel = _load_kernel() if compiled is None or compiled else None
        if compiled and self._kernel is None:
            raise ValueError("compiled=True needs numba; install it or pass compiled=None/False")

    def _make_action_space(self):
        return spaces.Box(-1.0, 1.0, (1,), np.float32)

    def _duty(self, actions) -> np.ndarray:
        if self._kernel is not None and isinstance(actions, np.ndarray) and actions.dtype.kind == "f":
            d = np.empty(self.num_envs)
            k = self._kernel[2](actions.reshape(self.num_envs), d)   # compiled: the same arithmetic
            if k < 0:
                return d
        a = np.asarray(actions, dtype=float).reshape(self.num_envs)
        if not np.all(np.isfinite(a)):  # NaN would poison the link state and every reward after it
            k = int(np.flatnonzero(~np.isfinite(a))[0])
            raise ValueError(f"actions[{k}]={float(a[k])!r} is invalid; valid range: [-1, 1] (finite)")
        return np.clip((a + 1.0) * 0.5, 0.0, 1.0)

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
        self._coef[:, idx] = p.coef[:, 0].T
        self._coef_cur[idx] = p.coef[:, 0]
        self._j[idx] = 0
        self._k[idx] = 0
        st = self._state
        st[0, idx], st[1, idx] = p.x0[:, 0], p.x0[:, 1]
        st[2, idx], st[3, idx], st[4, idx], st[5, idx] = p.vl0, p.battery[:, 2], p.vrc0, p.d0
        self._start_detuned(idx, p, full)

    def _start_detuned(self, idx, p, full):
        """Detuned windows (:mod:`envs.detuned`): their complex-envelope coefficients and state; a batch
        with any of them steps every window on the complex envelope (the tuned ones with zero detuning)."""
        cplx = p.cplx
        if cplx is None and (full or self._ccoef is None):
            self._ccoef = None
            return
        if cplx is None:
            from .core import _detuned_plans
            z = np.zeros(len(p.d0))
            cplx = _detuned_plans(self.config.link_folded, p.lm_h, z, z, p.vl0, p.d0, self.config)
        if self._ccoef is None:
            self._ccoef = np.zeros((self.num_envs, self.config.n_slow, 32))
            self._xc = np.zeros((self.num_envs, 4))
            self._c_rel = np.zeros((2, self.num_envs))
        self._ccoef[idx], self._xc[idx] = cplx[0], cplx[1]
        w, lk = self.config.link.omega_rad_s, self.config.link_folded
        self._c_rel[0, idx] = cplx[2] * w * w * lk.l1_h - 1.0   # relative C errors (tests, info)
        self._c_rel[1, idx] = cplx[3] * w * w * lk.l2_h - 1.0
        # the objective's short-mode current is the detuned link's (V2 = 0, the short mode's resistances)
        from .detuned import complex_steady
        dev, base = self._devices, self.config.link
        sm = base.with_(r1_ohm=base.r1_ohm + dev.inv_r_ohm, r2_ohm=base.r2_ohm + dev.short_r_ohm)
        S = p.lm_h.shape[1]
        _, j2 = complex_steady(sm, p.lm_h.ravel(), np.repeat(cplx[2], S), np.repeat(cplx[3], S), 0.0)
        self._i2sm_all[idx] = np.abs(j2).reshape(-1, S)
        self._state[0, idx] = np.hypot(cplx[1][:, 0], cplx[1][:, 2])
        self._state[1, idx] = np.hypot(cplx[1][:, 1], cplx[1][:, 3])

    def _initial_obs_info(self):
        i1, i2, vl, soc, vrc, d = self._state
        il = rectifier_current(d, np.abs(i2))
        ib = il - self._bat[7]
        cmd = self._cmd[self._k, self._ar]
        obs = self._obs(i2, vl, ib, il, soc, cmd, d, self._t_since(self._k))
        info = {"t_s": self._k * self._dt, "i2_a": i2.copy(), "i2_peak_a": self._peak.array(np.abs(i2), d, vl),
                "i1_a": i1.copy(), "d_short": d.copy(), "v2_v": rectifier_v2_folded(d, vl, i2, self._devices),
                "rect_current_a": il, "battery_v": vl.copy(), "battery_current_a": ib, "soc": soc.copy(),
                "charge_cmd_a": cmd, "lm_h": self._lm_all[self._j, self._ar], "energy_j": np.zeros(self.num_envs),
                "cost": np.zeros(self.num_envs), "overcurrent": np.zeros(self.num_envs),
                "overshoot": self._run_max.copy(), "episode_cost": np.maximum(self._run_max, 0.0),
                "reached_short_mode": self._sm_ok & self._sm_checked, "t_stop_s": self._t_stop.copy(),
                "i2_peak_envelope_a": np.abs(i2)}
        return obs, info

    def _t_since(self, k):
        return np.where(k >= self._stop_k, t_since_stop_s(k, self._t_stop, self._dt), 0.0)

    def _objective(self, k, peak, il):
        """Running overshoot, short-mode flag and the step cost after step ``k`` (:mod:`envs.objective`)."""
        after = k >= self._stop_k
        self._run_max, cost = overshoot_update(self._run_max, peak, self._i2sm_all[self._ar, k // self._M], after)
        self._sm_ok, self._sm_checked = short_mode_update(self._sm_ok, self._sm_checked, il, k + 1, self._stop_k,
                                                          self._dt)
        return cost

    def _objective_info(self, info: dict, k_prev) -> dict:
        """Add the objective to a step's ``info`` (``info["cost"]`` is the episode-cost increment;
        the old peak-over-rated penalty is ``info["overcurrent"]``)."""
        info["cost"] = self._objective(k_prev, info["i2_peak_a"], info["rect_current_a"])
        info["overshoot"] = self._run_max.copy()
        info["episode_cost"] = np.maximum(self._run_max, 0.0)
        info["reached_short_mode"] = self._sm_ok & self._sm_checked
        return info

    def _obs(self, i2m, vl, ib, il, soc, cmd, d, t_since):
        o = np.stack([i2m, vl, ib, il, soc, cmd, d, t_since])
        o *= self._obs_scale
        o += self._obs_offset
        np.clip(o, -1.0, 1.0, out=o)
        return o.T.astype(np.float32)

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
        if self._ccoef is not None:
            obs, reward, truncated, info = self._step_detuned(d)
        elif self._kernel is not None:
            obs, reward, truncated, info = self._step_compiled(d)
        else:
            obs, reward, truncated, info = self._step_numpy(d)
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

    def _step_compiled(self, d):
        """One step of every sub-environment in the compiled loop (:func:`envs.vector_kernel.step_kernel`),
        the objective included."""
        kern, rows, _ = self._kernel
        n = self.num_envs
        obs = np.empty((n, OBS_DIM), np.float32)
        reward = np.empty(n)
        truncated = np.empty(n, dtype=bool)
        block = np.empty((n, len(rows)))
        ep = (self._i2sm_all, self._stop_k, self._t_stop, self._run_max, self._sm_ok, self._sm_checked)
        kern(d, self._state, self._k, self._j, self._coef_all, self._coef_cur, self._bat, self._cmd, self._noise,
             self._lm_all, ep, self._M, self._n_sub, self._par, OBS_SCALE, OBS_OFFSET, self._peak.kernel_table, obs,
             reward, truncated, block)
        info = dict(zip(rows, block.T))   # (n,) views, one per key
        info["reached_short_mode"] = self._sm_ok & self._sm_checked
        info["i2_peak_envelope_a"] = info.pop("i2_peak_envelope_a")   # last, as in the single env
        return obs, reward, truncated, info

    def _step_numpy(self, d):
        """The same step on numpy arrays (:func:`envs.core.advance` with ``NUMPY_OPS``): the reference."""
        k = self._k
        j = k // self._M
        moved = j != self._j
        if moved.any():
            self._coef[:, moved] = self._coef_all[self._ar[moved], j[moved]].T
            self._j = j
        i1, i2, vl_old, soc, vrc, _ = self._state
        out = advance(i1, i2, vl_old, soc, vrc, d, self._coef, self._bat, NUMPY_OPS, self._n_sub, self._dev)
        return self._finish_numpy(k, d, vl_old, out)

    def _finish_numpy(self, k, d, vl_old, out):
        """The rest of a numpy step from the link and battery's ``out`` = (i1, i2, peak envelope, I_L,
        I_batt, soc, vrc, VL, V2): peak, reward, state, observation, info (the tuned and the detuned
        step alike)."""
        i1, i2, pk_env, il, ib, soc, vrc, vl, v2 = out
        peak = self._peak.array(pk_env, d, vl_old)
        cmd = self._cmd[k, self._ar]
        reward, overcurrent = reward_cost(il, cmd, peak, self._inv_rated, self.config.reward, NUMPY_OPS)
        energy = vl_old * il * self._dt
        st = self._state
        st[0], st[1], st[2], st[3], st[4], st[5] = i1, i2, vl, soc, vrc, d
        k += 1
        obs = self._obs(i2 + self._noise[k - 1, self._ar], vl, ib, il, soc, self._cmd[k, self._ar], d, self._t_since(k))
        info = {"t_s": k * self._dt, "i2_a": i2, "i2_peak_a": peak, "i1_a": i1, "d_short": d, "v2_v": v2,
                "rect_current_a": il, "battery_v": vl, "battery_current_a": ib, "soc": soc, "charge_cmd_a": cmd,
                "lm_h": self._lm_all[self._j, self._ar], "energy_j": energy, "overcurrent": overcurrent}
        info = self._objective_info(info, k - 1)
        info["i2_peak_envelope_a"] = pk_env
        return obs, reward, k >= self._T, info


def _step_detuned(self, d):
    """The step on the complex envelope (:func:`envs.detuned.advance_complex`): as :meth:`_step_numpy`
    with ``|J1|``, ``|J2|`` for I1, I2 and ``|V2|`` for V2."""
    from .detuned import advance_complex
    k = self._k
    j = k // self._M
    _, _, vl_old, soc, vrc, _ = self._state
    self._xc, *out = advance_complex(self._xc, vl_old, soc, vrc, d, self._ccoef[self._ar, j], self._bat, self._dev,
                                     self.config.link.v1_amp_v, self._n_sub)
    self._j = j
    return self._finish_numpy(k, d, vl_old, out)


SbarChargingVectorEnv._step_detuned = _step_detuned


def _load_kernel():
    """``(step_kernel, INFO_ROWS, duty_kernel)`` of :mod:`envs.vector_kernel`, or None without numba (imported
    here, when a vector env is built, so ``import envs`` does not load numba)."""
    import importlib.util
    if importlib.util.find_spec("numba") is None:
        return None
    from .vector_kernel import INFO_ROWS, duty_kernel, step_kernel
    return step_kernel, INFO_ROWS, duty_kernel


class SbarChargingDiscreteVectorEnv(SbarChargingVectorEnv):
    """Batched :class:`envs.charging.SbarChargingDiscreteEnv`: actions in {0: RM, 1: SM}."""

    def _make_action_space(self):
        return spaces.Discrete(2)

    def _duty(self, actions) -> np.ndarray:
        a = np.asarray(actions).reshape(self.num_envs)
        if np.any((a != 0) & (a != 1)):
            raise ValueError(f"actions={a[(a != 0) & (a != 1)][0]!r} is invalid; valid values: 0 (RM), 1 (SM)")
        return a.astype(float)
