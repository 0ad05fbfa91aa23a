"""The env as composed parts (gym-electric-motor's shape): the plant, the objective and the observation
(the fourth part, the scenario draws and the reference, is :class:`envs.scenario.ScenarioPart`).

=====================  =======================================================================
part                   at a reset (windows ``idx`` start)       at a step
=====================  =======================================================================
``scenario``           the scenario of the options, the draws    (nothing: the command and the
                       (:data:`envs.scenario.DRAWS` and the      noise are read by the step)
                       scenario's ``parts``), the command, the
                       sensor noise -> :class:`~envs.scenario.Window`
``plant``              true Lm, link coefficients, battery row,  the one compiled step
                       initial state, detuned tank               (:mod:`envs.vector_kernel`): link,
                       (:func:`envs.core.build_plans`)           battery, reward, objective, observation
``objective``          short-mode current of the true link,      the episode's short-mode flag
                       the stop step, running maximum reset
``observation``        the first observation and info, the       the info dict by name, the sensing
                       sensing delay line, the frame stack       delay line, the frame stack
                       (``history=K``)
=====================  =======================================================================

Each env calls every part's ``reset`` once per ``reset`` and the plant's, objective's and
observation's ``step`` once per ``step`` (``tests/test_env_parts.py`` counts it), in that order; every array a part owns is indexed by the names of :mod:`envs.layout`
(``plant.state[STATE.vl]``, ``plant.bat[BAT.i_load]``). The arithmetic of a step stays one compiled
function (:mod:`envs.vector_kernel`); the plant's step is that call, with the arrays of the other
parts, and the objective's and observation's steps read what it wrote.

The vector env's parts own arrays over its ``n`` windows (:class:`PlantPart`, :class:`ObjectivePart`,
:class:`ObservationPart`); the single env's (:class:`SinglePlant`, :class:`SingleObjective`,
:class:`SingleObservation`) make the same plans and keep them in the single kernel's rows
(:data:`envs.layout.SINGLE`, :data:`envs.layout.SLOW`: one row holding every part's slots).
"""

from __future__ import annotations

import math

import numpy as np

from mission_sim.contract import OBS_DIM
from wpt_receiver.sbar import rectifier_current, rectifier_v2_folded

from .core import (N_BAT, N_COEF, OBS_OFFSET, OBS_SCALE, EnvConfig, build_plans, kernel_from_ref, kernel_function,
                   kernel_ref)
from .layout import BAT, CCOEF_N, COEF, INFO, PAR, SINGLE, SINGLE_PAR, SLOW, STATE, XC
from .objective import short_mode_i2_a, stop_step
from .peaks import LOOKUP_SCALARS

__all__ = ["PlantPart", "ObjectivePart", "ObservationPart", "SinglePlant", "SingleObjective", "SingleObservation",
           "alias_parts"]

#: the single kernel's short-mode flag, written after the info values (``out[SM_FLAG]``)
SM_FLAG = len(INFO)
#: the keys of the single env's step info: the INFO values, then the short-mode flag
_SINGLE_KEYS = INFO._fields + ("reached_short_mode",)


class PlantPart:
    """The physical system of ``n`` windows: link state (:data:`STATE`, ``state_names``), slow-segment
    index ``j``, ZOH coefficients, true Lm, battery rows, detuned tanks; its step is the compiled step."""

    state_names = STATE._fields
    #: the slots of the compiled step's constants (``constants`` by these names)
    PAR = PAR

    def __getstate__(self):   # (every plant part's: its compiled step by name, envs.core.kernel_ref)
        return {**self.__dict__, "kernel": kernel_ref(self.kernel)}

    def __setstate__(self, state):
        self.__dict__.update(state, kernel=kernel_from_ref(state["kernel"]))

    def __init__(self, cfg: EnvConfig, n: int, compiled: bool = True):
        S = cfg.n_slow
        self.cfg, self.compiled, self.n_sub = cfg, compiled, cfg.n_sub
        self.kernel = kernel_function("env_step", compiled)   # also: numba imported here
        self.state = np.zeros((len(STATE), n))
        self.j = np.zeros(n, dtype=np.int64)
        # ZOH coefficients: one row per distinct Lm (rows [0, tab_used) live), row of window e's slow
        # segment j at coef_ix[j, e] (step-major: a step reads one contiguous row of indices)
        self.coef_tab = np.zeros((1, N_COEF))
        self.coef_ix = np.zeros((S, n), dtype=np.int64)
        self.tab_used = 0
        self.lm_all = np.zeros((S, n))
        self.bat = np.zeros((N_BAT, n))
        # detuned windows (envs.detuned): flag, complex state, coefficients; empty until one is drawn
        self.detuned = np.zeros(0, np.bool_)
        self.xc, self.ccoef, self.c_rel = np.zeros((0, len(XC))), np.zeros((0, 0, CCOEF_N)), None

    def constants(self, peak) -> dict:
        """The plant's constants of the compiled step by the names of :data:`envs.layout.PAR` /
        :data:`envs.layout.SINGLE_PAR`: window length, step, the devices' ``(Vf, dR)``, the sub-steps,
        V1 (the detuned tank's source) and the instantaneous-peak table's scalars and shape (``peak``: the
        :class:`envs.peaks.PeakLookup`)."""
        c, tab = self.cfg, peak.kernel_table
        (vf, dr), (vlc, inv_imax) = c.device_terms, LOOKUP_SCALARS
        return dict(n_steps=c.n_steps, dt=c.dt_s, slow_every=c.slow_every, n_sub=c.n_sub, vf=vf, dr=dr, vlc=vlc,
                    inv_imax=inv_imax, v1=c.link.v1_amp_v, nd=tab.shape[0], ni=tab.shape[1], nq=tab.shape[2])

    def reset(self, idx, win):
        """Plans of the windows ``idx`` (a slice for all: the coefficients written in place) from the
        scenario's window ``win``; returns the :class:`envs.core.Plans`."""
        p = build_plans(win, self.cfg, table=True)
        self._put_table(idx, p.zoh, p.coef_ix)
        self.lm_all[:, idx] = p.lm_h.T
        self.bat[:, idx] = p.battery.T
        self.j[idx] = 0
        self.state[:, idx] = p.state0.T   # the columns of state0 are the STATE slots
        self._reset_detuned(idx, p.detuned)
        return p

    def _put_table(self, idx, zoh, ix):
        """The windows ``idx`` read the coefficient rows ``zoh`` (U, N_COEF) by ``ix`` (len(idx), S): all windows
        (a slice) replace the table; some append to it, the rows no window reads dropped when it is full."""
        if isinstance(idx, slice):
            self.coef_tab, self.tab_used = zoh, len(zoh)
            self.coef_ix[:, idx] = ix.T
            return
        self.coef_ix[:, idx] = -1   # these windows' old rows are no longer read
        if self.tab_used + len(zoh) > len(self.coef_tab):
            live = np.unique(self.coef_ix)
            live = live[live >= 0]
            tab = np.empty((2 * (len(live) + len(zoh)), N_COEF))
            tab[:len(live)] = self.coef_tab[live]
            keep = self.coef_ix >= 0
            self.coef_ix[keep] = np.searchsorted(live, self.coef_ix[keep])
            self.coef_tab, self.tab_used = tab, len(live)
        self.coef_tab[self.tab_used:self.tab_used + len(zoh)] = zoh
        self.coef_ix[:, idx] = ix.T + self.tab_used
        self.tab_used += len(zoh)

    def _reset_detuned(self, idx, det):
        if det is None:
            if len(self.detuned):
                self.detuned[idx] = False
            return
        from .detuned import relative_errors
        if not len(self.detuned):
            n = self.state.shape[1]
            self.detuned, self.c_rel = np.zeros(n, np.bool_), np.zeros((2, n))
            self._alloc_complex(n)
        self.detuned[idx] = True
        self._set_complex(idx, det)
        self.c_rel[:, idx] = relative_errors(self.cfg, det.c1_f, det.c2_f)

    def _alloc_complex(self, n):
        """Room for ``n`` windows' complex envelope (eq. 4's detuned step): coefficients and state."""
        self.ccoef = np.zeros((n, self.cfg.n_slow, CCOEF_N))
        self.xc = np.zeros((n, len(XC)))

    def _set_complex(self, idx, det):
        """The detuned windows ``idx``'s complex-envelope coefficients and start state from their plan ``det``."""
        self.ccoef[idx], self.xc[idx] = det.coef, det.xc0

    def start_values(self, peak):
        """``(I_L, instantaneous peak, V2)`` at the windows' start state: the SBAR's rules on it (eq. 9,
        :func:`wpt_receiver.sbar.rectifier_current`) and ``peak``'s table (:class:`envs.peaks.PeakLookup`)."""
        st = self.state
        d, i2, vl = st[STATE.d], st[STATE.i2], st[STATE.vl]
        return (rectifier_current(d, np.abs(i2)), peak.array(np.abs(i2), d, vl),
                rectifier_v2_folded(d, vl, i2, self.cfg.device_set()))

    def step(self, d, k, scenario, objective, par, ptab, obs, reward, truncated, block, chunks):
        """One step of every window: the compiled :func:`envs.vector_kernel.env_step` (link, battery,
        reward, objective, observation, info rows into ``obs``, ``reward``, ``truncated``, ``block``)."""
        c = self.cfg
        kern = self.kernel if self.compiled else kernel_function("env_step", False)
        cx = (self.detuned, self.xc, self.ccoef, c.link.v1_amp_v)
        kern(d, self.state, k, self.j, self.coef_tab, self.coef_ix, self.bat, scenario.cmd, scenario.noise,
             self.lm_all, objective.ep, c.slow_every, self.n_sub, par, OBS_SCALE, OBS_OFFSET, ptab, obs, reward,
             truncated, block, cx, chunks)


class ObjectivePart:
    """The domain's objective (:mod:`envs.objective`) of ``n`` windows: the short-mode current of the
    true link per slow segment, the stop step and time, the running overshoot and the short-mode flags
    (the reward's and cost's arithmetic is the compiled step's)."""

    def __init__(self, cfg: EnvConfig, n: int):
        self.cfg = cfg
        self.i2sm_all = np.ones((cfg.n_slow, n))   # step-major: a step reads one contiguous row
        self.stop_k = np.zeros(n, dtype=np.int64)
        self.t_stop = np.zeros(n)
        self.run_max = np.full(n, -np.inf)
        self.sm_ok = np.ones(n, dtype=bool)
        self.sm_checked = np.zeros(n, dtype=bool)

    def constants(self) -> dict:
        """The reward's and cost's constants of the compiled step (:class:`envs.core.RewardWeights`, the
        rated I2) by the names of :data:`envs.layout.PAR`."""
        c, w = self.cfg, self.cfg.reward
        return dict(inv_rated=1.0 / c.rated_i2_a, w_track=w.tracking, w_over=w.overcurrent, i_ref=w.i_ref_a)

    @property
    def ep(self) -> tuple:
        """The objective's arrays as the compiled step takes them."""
        return self.i2sm_all, self.stop_k, self.t_stop, self.run_max, self.sm_ok, self.sm_checked

    def plan(self, win, plan):
        """``(i2_sm (n, S), stop_k (n,), t_stop (n,))`` of the windows of ``win`` on the plant's ``plan``."""
        c = self.cfg
        t_stop = np.asarray(win.draw.t_stop_s, dtype=float)
        det, lm = plan.detuned, plan.lm_h
        if det is None:
            flat = lm.reshape(-1)
            one = flat.size > 0 and bool(np.all(flat == flat[0]))   # one Lm for all (no wind, no drift): once
            i2_sm = short_mode_i2_a(c.link, flat[:1] if one else lm, c.device_set())   # (elementwise: same numbers)
            if one:
                i2_sm = np.broadcast_to(i2_sm, lm.shape)
        else:   # the detuned link's short-mode current
            from .detuned import short_mode_i2
            i2_sm = short_mode_i2(c, c.device_set(), lm, det.c1_f, det.c2_f)
        return i2_sm, stop_step(t_stop, c.dt_s, c.n_steps), t_stop

    def reset(self, idx, win, plan):
        i2sm, self.stop_k[idx], self.t_stop[idx] = self.plan(win, plan)
        self.i2sm_all[:, idx] = i2sm.T
        self.run_max[idx] = -np.inf
        self.sm_ok[idx] = True
        self.sm_checked[idx] = False

    def reached(self) -> np.ndarray:
        """Reached short mode (:mod:`envs.objective`), per window."""
        return self.sm_ok & self.sm_checked

    def step(self) -> np.ndarray:
        return self.reached()


class ObservationPart:
    """What the agent and the caller see of ``n`` windows: the observation (the contract's fields,
    normalised), the info dict by the names of :data:`INFO`, the sensing delay line (:mod:`envs.sensing`)
    and, with ``history=K > 1``, the last K observations stacked, oldest first (:mod:`envs.history`)."""

    def __init__(self, cfg: EnvConfig, n: int, peak, compiled: bool = True, history: int = 1):
        self.cfg, self.peak, self.compiled = cfg, peak, compiled
        self.n = n
        self.delay = np.zeros(n, dtype=np.int64)   # sensing delay [steps]; the line exists once one is drawn
        self.line = None
        self.hist = _history(history)

    def reset(self, idx, win, k, scenario, plant, objective):
        """Observation and info of every window's current state (the windows ``idx`` just started in the
        steady state at their first duty); the delay line of ``idx`` started with it."""
        self.delay[idx] = np.asarray(win.draw.sense_delay).astype(np.int64)
        if self.line is None and self.delay.any():
            from .sensing import DelayLine
            self.line = DelayLine(self.n)
        obs, info = self._first(k, scenario, plant, objective)
        if self.line is not None:
            self.line.start(idx, obs[idx], self.delay[idx])
        if self.hist is not None:   # a frame stack: the windows that start hold k copies of their first frame
            obs = self.hist.start(idx, obs[idx])
        return obs, info

    def _first(self, k, scenario, plant, objective):
        st, bat, n, dt = plant.state, plant.bat, self.n, self.cfg.dt_s
        ar = np.arange(n)
        i1, i2, vl, soc, d = st[STATE.i1], st[STATE.i2], st[STATE.vl], st[STATE.soc], st[STATE.d]
        il, pk0, v2 = plant.start_values(self.peak)
        ib = il - bat[BAT.i_load]
        cmd = scenario.cmd[k, ar]
        t_stop, run_max = objective.t_stop, objective.run_max
        t_since = np.where(k >= objective.stop_k, np.maximum(k * dt - t_stop, 0.0), 0.0)
        obs = np.empty((n, OBS_DIM), np.float32)
        kernel_function("obs_rows", self.compiled)(np.stack([i2, vl, ib, il, soc, cmd, d, t_since]), OBS_SCALE,
                                                    OBS_OFFSET, obs)
        info = {"t_s": k * dt, "i2_a": i2.copy(), "i2_peak_a": pk0,
                "i1_a": i1.copy(), "d_short": d.copy(), "v2_v": v2,
                "rect_current_a": il, "battery_v": vl.copy(), "battery_current_a": ib, "soc": soc.copy(),
                "charge_cmd_a": cmd, "lm_h": plant.lm_all[plant.j, ar], "energy_j": np.zeros(n),
                "cost": np.zeros(n), "overcurrent": np.zeros(n),
                "overshoot": run_max.copy(), "episode_cost": np.maximum(run_max, 0.0),
                "reached_short_mode": objective.reached(), "t_stop_s": t_stop.copy(),
                "i2_peak_envelope_a": np.abs(i2)}
        return obs, info

    def step(self, obs, block, reached):
        """The step's observation (delayed fields replaced, in place) and info (views of ``block`` by name)."""
        if self.line is not None:
            self.line.push(obs)
        if self.hist is not None:
            obs = self.hist.push(obs)
        info = dict(zip(INFO._fields, block.T))   # (n,) views, one per key
        info["reached_short_mode"] = reached
        info["i2_peak_envelope_a"] = info.pop("i2_peak_envelope_a")   # last, as in the single env
        return obs, info


def _history(k: int):
    """The frame stack of ``k`` observations (None for one frame: the plain observation)."""
    from mission_sim.contract import history_obs_dim
    history_obs_dim(k)   # validates k
    if int(k) == 1:
        return None
    from .history import ObsHistory
    return ObsHistory(int(k))


def alias_parts(cls, names: dict) -> None:
    """Properties ``cls.<alias>`` -> ``self.parts.<part>.<attr>`` (``names``: alias -> (part, attr)), read
    and write: the env's former attribute names (``_state``, ``_bat``, ``_line``...) for code that reads them."""
    for alias, (part, attr) in names.items():
        def get(self, part=part, attr=attr):
            return getattr(getattr(self.parts, part), attr)

        def put(self, value, part=part, attr=attr):
            setattr(getattr(self.parts, part), attr, value)
        setattr(cls, alias, property(get, put))


# ---------------------------------------------------------------------------------------------- single env
def _sign(x: float) -> float:
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


class SinglePlant(PlantPart):
    """The plant of the single env: the same plans, kept in the single kernel's rows (``st``: the
    :data:`SINGLE` slots then a detuned window's :data:`XC` state; ``slow``: :data:`SLOW` per slow
    segment; ``cc``: the detuned coefficients); its step is :func:`envs.vector_kernel.single_step`."""

    PAR = SINGLE_PAR

    def __init__(self, cfg: EnvConfig, compiled: bool = True):
        self.cfg, self.compiled = cfg, compiled
        self.kernel = kernel_function("single_step", compiled)   # also: numba imported here
        self.st = self.slow = None
        self.cc = np.zeros((0, CCOEF_N))

    def reset(self, idx, win):
        p = build_plans(win, self.cfg)
        det = p.detuned
        st = np.empty(len(SINGLE) + (len(XC) if det is not None else 0))
        for f in STATE._fields:
            st[getattr(SINGLE, f)] = p.state0[0, getattr(STATE, f)]
        for f in BAT._fields:
            st[getattr(SINGLE, f)] = p.battery[0, getattr(BAT, f)]
        self.cc = np.zeros((0, CCOEF_N))
        if det is not None:
            st[len(SINGLE):] = det.xc0[0]
            self.cc = np.ascontiguousarray(det.coef[0])
        slow = np.empty((p.coef.shape[1], len(SLOW)))
        slow[:, :len(COEF)] = p.coef[0]   # the first SLOW slots are the COEF ones
        slow[:, SLOW.lm_h] = p.lm_h[0]
        self.st, self.slow = st, slow
        return p

    def start_values(self, peak):
        """``(I_L, instantaneous peak, V2)`` at the window's start state (floats; as :meth:`PlantPart.start_values`)."""
        st, devices = self.st, self.cfg.device_set()
        i2, vl, d = (float(st[f]) for f in (SINGLE.i2, SINGLE.vl, SINGLE.d))
        return (float(rectifier_current(d, abs(i2))), peak.scalar(abs(i2), d, vl),
                rectifier_v2_folded(d, vl, i2, devices, sin=math.sin, sign=_sign))

    def step(self, k, d, steps, par, obs, out):
        """The single window's step; returns the reward."""
        kern = self.kernel if self.compiled else kernel_function("single_step", False)
        return kern(k, d, self.st, steps, self.slow, par, obs, out, self.cc)


class SingleObjective(ObjectivePart):
    """The objective of the single env: its slots in the plant's row (:data:`SINGLE` run_max .. t_stop,
    :data:`SLOW` i2_sm_a); the short-mode flag is the kernel's ``out[SM_FLAG]``."""

    def __init__(self, cfg: EnvConfig, plant: SinglePlant):
        self.cfg, self.plant = cfg, plant
        self.t_stop, self.stop_k = 0.0, 0

    def reset(self, idx, win, plan):
        i2_sm, stop_k, t_stop = self.plan(win, plan)
        self.t_stop, self.stop_k = float(t_stop[0]), int(stop_k[0])
        st = self.plant.st
        st[SINGLE.run_max], st[SINGLE.sm_ok], st[SINGLE.sm_checked] = -np.inf, 1.0, 0.0
        st[SINGLE.stop_k], st[SINGLE.t_stop] = self.stop_k, self.t_stop
        self.plant.slow[:, SLOW.i2_sm_a] = i2_sm[0]

    def step(self, out) -> bool:
        return out[SM_FLAG] != 0.0


class SingleObservation:
    """The single env's observation and info (scalars), the delay line of a delayed window, the frame
    stack with ``history=K > 1``."""

    def __init__(self, cfg: EnvConfig, peak, compiled: bool = True, history: int = 1):
        self.cfg, self.peak, self.compiled = cfg, peak, compiled
        self.line = None
        self.hist = _history(history)

    def reset(self, win, plant, objective):
        st = plant.st
        i1, i2, vl, d, soc = (float(st[f]) for f in (SINGLE.i1, SINGLE.i2, SINGLE.vl, SINGLE.d, SINGLE.soc))
        cmd0 = float(win.cmd_a[0, 0])
        il, pk0, v2 = plant.start_values(self.peak)
        ib = il - float(st[SINGLE.i_load])
        info = {"t_s": 0.0, "i2_a": i2, "i2_peak_a": pk0, "i1_a": i1, "d_short": d,
                "v2_v": v2, "rect_current_a": il, "battery_v": vl, "battery_current_a": ib, "soc": soc,
                "charge_cmd_a": cmd0, "lm_h": float(plant.slow[0, SLOW.lm_h]), "energy_j": 0.0, "cost": 0.0,
                "overcurrent": 0.0, "overshoot": -np.inf, "episode_cost": 0.0, "reached_short_mode": False,
                "scenario": win.scenario.name, "t_stop_s": objective.t_stop, "i2_peak_envelope_a": abs(i2)}
        t = 0.0 * self.cfg.dt_s - objective.t_stop   # the time since the stop at step 0 (0 before it)
        t_since = t if (0 >= objective.stop_k and t > 0.0) else 0.0
        obs = np.empty((1, OBS_DIM), np.float32)
        vals = np.array([[i2], [vl], [ib], [il], [soc], [cmd0], [d], [t_since]])
        kernel_function("obs_rows", self.compiled)(vals, OBS_SCALE, OBS_OFFSET, obs)
        self.line = None
        delay = np.asarray(win.draw.sense_delay).astype(np.int64).reshape(1)
        if delay[0] > 0:   # sensing delay (envs.sensing)
            from .sensing import DelayLine
            self.line = DelayLine(1)
            self.line.start([0], obs, delay)
        if self.hist is not None:
            obs = self.hist.reset(obs)
        return obs[0], info

    def step(self, obs, out, d, reached):
        """The step's observation (delayed in place) and info by the names of :data:`INFO`."""
        info = dict(zip(_SINGLE_KEYS, out.tolist()))   # INFO's slots are 0, 1, ... in the order of its names
        info["d_short"] = d
        info["reached_short_mode"] = reached   # (the kernel's flag, out[SM_FLAG], as a bool)
        if self.line is not None:
            self.line.push(obs[None])
        if self.hist is not None:
            obs = self.hist.push(obs[None])[0]
        return obs, info
