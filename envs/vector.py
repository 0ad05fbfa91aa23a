"""The batched vector versions of the charging environments.

Sub-environment ``i`` owns its own generator (seeded ``seed + i`` like
:class:`gymnasium.vector.SyncVectorEnv`), so the batched env reproduces ``num_envs`` single
environments seeded the same way. Autoreset: ``NEXT_STEP`` (the step after an episode ended resets
that sub-environment, returns its first observation, reward 0, and ignores its action) in the env's scenario:
``reset(options={"scenario": ...})`` sets the scenario of the windows that reset starts only, as
``SyncVectorEnv``'s autoreset calls its single envs' ``reset()`` without options.

The step is one compiled call (:func:`envs.vector_kernel.env_step`, the one implementation of the
env step, shared with the single env); this module keeps the orchestration: the parts
(:attr:`SbarChargingVectorEnv.parts`: scenario draws with two generator calls per restarted
sub-environment, plant, objective, observation; :mod:`envs.parts`), each entered once per reset and
step, the autoresets and the threads.

Threads: ``num_threads=k`` steps the sub-environments on ``k`` threads (``numba.set_num_threads``
before each parallel step, chunks handed out dynamically); ``num_threads=1`` on the calling thread;
the default (``None``) chooses between one thread and all of numba's by measured step times
(:class:`_AutoThreads`: on a machine whose cores are busy with other work, a parallel step waits for
descheduled threads). Below :attr:`SbarChargingVectorEnv.PARALLEL_MIN_ENVS` sub-environments the step
always runs on the calling thread (waking a thread pool costs more than it saves there). The
results do not depend on the threads (each sub-environment's arithmetic is the same in any chunk):
parallel == serial to the bit. An autoreset's generator draws (one generator per sub-environment,
:mod:`envs.draw_kernel`) and command profile (:mod:`envs.command_kernel`) run compiled on the step's threads when the
step runs parallel; its plans (numpy) on the calling thread.
"""

from __future__ import annotations

import math
import time
from collections import namedtuple
from collections.abc import Mapping

import numpy as np
from gymnasium import logger, spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from mission_sim.contract import OBS_DIM, PolicyContext, check_history, history_obs_dim
from mission_sim.validation import SEED_RANGE, Range, check_first_seed, check_number, real_array, shown

from .core import (OBS_OFFSET, OBS_SCALE, EnvConfig, as_config, kernel_from_ref, kernel_function, kernel_ref,
                   refuse_unknown_kwargs)
from .layout import INFO
from .modal_plant import vector_plant
from .parts import ObjectivePart, ObservationPart, alias_parts
from .peaks import PeakLookup
from .scenario import ENV_SCENARIO, ScenarioPart, get_scenario

__all__ = ["SbarChargingVectorEnv", "SbarChargingDiscreteVectorEnv", "Parts"]

#: an env's parts, in the order a reset and a step call them (:mod:`envs.parts`)
Parts = namedtuple("Parts", "scenario plant objective observation")


#: memory of one sub-environment per step of its window, bytes, by link model (the step-major per-step arrays, the
#: per-segment plans and a reset's draws and temporaries; ~36 kB / ~19 kB a sub-environment at n_steps = 300). Measured
#: (2026-11-27 midday, tests/test_python_api_newcomer.py checks it): tracemalloc's peak over construction and the first
#: reset (the peak of a whole episode is the reset's), after a warm-up, per env and step (n_steps + 1), N = 64-8192:
#: envelope 92-94 B (scenario random), 89-96 B (detuned_wide), 25-30 B (nominal: no per-segment coupling plans);
#: modal 44-49 B (random, nominal), 47-53 B (detuned_wide). Held after the reset: envelope 22-53 B, modal 32-36 B. The
#: process's resident memory (RSS, which also counts numba's allocations) grew by 23-26 B (envelope) and 34-46 B (modal)
#: over a whole episode of 2,000 and 8,000 envs, a review's figures 102-117 B and 19-46 B. So: an upper estimate of
#: the traced peak with ~25 % room (the envelope link's worst RSS figure covered), lenient for the nominal scenario
#: (was one 96 B for both links: 2x the modal link's peak)
BYTES_PER_ENV_STEP = {"envelope": 120, "modal": 64}


def _physical_memory() -> int | None:
    """The machine's physical memory (bytes), None where the system does not say."""
    import os
    try:
        have = int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return None
    return have if have > 0 else None   # (sysconf's -1: unknown; it refused every num_envs)


def _no_cut(max_episode_steps) -> bool:
    """Whether ``max_episode_steps`` is gymnasium's ``-1`` ("no TimeLimit"; a bool is not a number of steps)."""
    return not isinstance(max_episode_steps, bool) and isinstance(max_episode_steps, int | float | np.number) \
        and max_episode_steps == -1


def _check_memory(num_envs: int, n_steps: int, link_model: str) -> None:
    """``ValueError`` before anything is allocated when ``num_envs`` windows of ``n_steps`` would need more memory
    than the machine has (``SbarChargingVectorEnv(10**7)`` ended in numpy's ``MemoryError`` after seconds of
    allocating), naming the memory needed and the largest ``num_envs`` that fits; no check where the memory is
    unknown."""
    per = BYTES_PER_ENV_STEP[link_model] * (n_steps + 1)
    have = _physical_memory()
    if have is not None and num_envs * per > have:
        raise ValueError(f"num_envs={num_envs:,} is invalid: it would need ~{num_envs * per / 2**30:.3g} GiB of memory "
                         f"(~{per / 1e3:.0f} kB a sub-environment at n_steps={n_steps}), more than this machine's "
                         f"{have / 2**30:.3g} GiB; valid range: 1..{have // per:,}")


class SbarChargingVectorEnv(VectorEnv):
    """``num_envs`` charging windows stepped at once; see :class:`envs.charging.SbarChargingEnv` for
    the spaces, reward and episode definition. ``info`` holds arrays of shape (num_envs,).

    ``compiled=False`` runs the compiled step's own source uncompiled (``py_func``: slow, for tests);
    ``num_threads``: threads of the parallel step (1..numba's thread count; default: one or all,
    chosen by measured step times); ``history=K``: the observation is the last K frames stacked, oldest
    first (K * 8 values; the observation part's frame stack, :mod:`envs.history`).

    Episode length, as the single env's: each window truncates itself after ``EnvConfig.n_steps`` steps, so the
    id registers no ``max_episode_steps``; ``max_episode_steps=N`` (``gymnasium.make_vec(ID, ..., max_episode_steps=N)``
    passes it here) truncates each window after ``min(N, n_steps)`` steps, as ``gymnasium.make(ID,
    max_episode_steps=N)``'s ``TimeLimit`` cuts a single env's (the window itself is drawn for ``n_steps``); None and
    ``-1`` cut nothing (``gymnasium.make``'s ``-1``: no ``TimeLimit``).
    ``render()`` returns None with gymnasium's warning (the vector env has no render mode): render a single env."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    #: fewer sub-environments than this step on the calling thread
    PARALLEL_MIN_ENVS = 2048
    #: chunks per thread of the parallel step (smaller chunks even out a busy core)
    CHUNKS_PER_THREAD = 4

    def __init__(self, num_envs: int = 1, scenario="nominal", config: EnvConfig | dict | None = None,
                 render_mode: str | None = None, compiled: bool | None = None, num_threads: int | None = None,
                 history: int = 1, max_episode_steps: int | None = None, **unknown):
        refuse_unknown_kwargs(type(self).__name__, unknown, ("num_envs", "scenario", "config", "render_mode", "compiled",
                                                             "num_threads", "history", "max_episode_steps"))
        try:   # (True made one env)
            whole = not isinstance(num_envs, bool) and int(num_envs) == num_envs >= 1
        except (TypeError, ValueError, OverflowError):
            whole = False
        if not whole:
            raise ValueError(f"num_envs={num_envs!r} is invalid; valid range: integer >= 1")
        if render_mode is not None:
            raise ValueError(f"render_mode={render_mode!r} is invalid for the vector env; valid values: None "
                             "(render a single env instead)")
        self.num_envs = int(num_envs)
        self._action_shapes = ((self.num_envs, 1), (self.num_envs,))   # what step takes (_duty)
        self.render_mode = None
        scenario = get_scenario(scenario)
        self.config = c = as_config(config)
        _check_memory(self.num_envs, c.n_steps, c.link_model)
        #: steps a window runs before it is truncated: n_steps, or fewer with max_episode_steps (a TimeLimit's cut)
        # (None and -1: no cut, as gymnasium.make's "max_episode_steps=-1 will not apply the wrapper")
        self.max_episode_steps = None if max_episode_steps is None or _no_cut(max_episode_steps) else check_number(
            "max_episode_steps", max_episode_steps, Range(1, math.inf, integer=True), " (or None / -1: n_steps)")
        self.history = history = check_history(history)   # (2.0 was stored as a float)
        self.single_observation_space = spaces.Box(-1.0, 1.0, (history_obs_dim(history),), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.single_action_space = self._make_action_space()
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.num_threads = _num_threads(num_threads)
        self._threads_auto = num_threads is None
        self._compiled = compiled is None or bool(compiled)
        self._alloc(c, scenario)

    scenario = ENV_SCENARIO

    def _alloc(self, c: EnvConfig, scenario):
        """The parts (:mod:`envs.parts`) and the step's constants (named slots: :mod:`envs.layout`)."""
        n, T = self.num_envs, c.n_steps
        self._T, self._M, self._dt = T, c.slow_every, c.dt_s
        self._n_sub = c.modal_n_sub if c.link_model == "modal" else c.n_sub
        self._devices, self._dev = c.device_set(), c.device_terms
        self._peak = PeakLookup(c.link, self._devices)
        self._ar = np.arange(n)
        # the compiled duty map looked up once (not per step); uncompiled: per call (tests swap the source)
        self._duty_kernel = kernel_function("duty_kernel") if self._compiled else None
        # per-step data stored step-major (T, n): a step reads one contiguous row across the envs
        self.parts = Parts(ScenarioPart(scenario, T, c.dt_s, np.zeros((T + 1, n)), np.zeros((T, n)),
                                        self._fill if self._compiled else None,
                                        self._reset_chunks if self._compiled else None, self._compiled),
                           vector_plant(c, n, self._compiled), ObjectivePart(c, n),
                           ObservationPart(c, n, self._peak, self._compiled, self.history))
        # the compiled step's constants, each part's by name
        vals = {**self.parts.plant.constants(self._peak), **self.parts.objective.constants()}
        if self.max_episode_steps is not None:   # (the kernel's n_steps is its truncation step alone)
            vals["n_steps"] = min(self.max_episode_steps, T)
        self._par = np.array([vals[f] for f in self.parts.plant.PAR._fields], dtype=float)
        self._k = np.zeros(n, dtype=np.int64)
        self._prev_done = np.zeros(n, dtype=bool)
        self._rngs = [None] * n
        self._draws = None   # the compiled draws (envs.draw_kernel.Draws), made at the first reset
        self._started = False
        self._last_obs = None   # the last observation returned
        self._obs_scale = OBS_SCALE[:, None]
        self._obs_offset = OBS_OFFSET[:, None]
        serial = n < self.PARALLEL_MIN_ENVS or self.num_threads == 1
        self._n_chunks = 1 if serial else min(self.num_threads * self.CHUNKS_PER_THREAD, max(1, n // 256))
        # auto (num_threads=None, parallel possible): the step times decide between one thread and all
        self._auto = _AutoThreads() if self._threads_auto and self._n_chunks > 1 else None

    def __getstate__(self):   # the compiled duty map by name (envs.core.kernel_ref; the plant's step: its part's)
        return {**self.__dict__, "_duty_kernel": kernel_ref(self._duty_kernel)}

    def __setstate__(self, state):
        self.__dict__.update(state, _duty_kernel=kernel_from_ref(state["_duty_kernel"]))

    def _reset_chunks(self) -> int:
        """The chunks of an autoreset's compiled parallel parts (draws, command profile): the step's, as the auto
        threads' probes chose (one until they have); numba's threads set when more than one."""
        chunks = self._n_chunks
        if self._auto is not None:
            chunks = min(chunks, self._auto.best or 1)
        if chunks > 1:
            _set_threads(self.num_threads)
        return chunks

    def _fill(self, rngs, u, noise, scale, chunks) -> bool:
        """The scenario's draws (:func:`envs.scenario.draw_episodes`'s ``fill``) compiled, in the autoreset's
        ``chunks`` (:meth:`_reset_chunks`, taken once per reset by the scenario part: on the step's threads when it
        runs parallel; :mod:`envs.draw_kernel`: the generators' own numbers and end states)."""
        if self._draws is None:
            try:   # numba's private random-number modules: a numba without them draws with numpy's calls
                from .draw_kernel import Draws
                self._draws = Draws()
            except (ImportError, AttributeError):
                self._draws = False
        if self._draws is False:
            return False
        return self._draws(rngs, u, noise, min(chunks, len(rngs)), scale)

    @property
    def state_names(self) -> tuple:
        """Names of the rows of the plant's state (:data:`envs.layout.STATE`)."""
        return self.parts.plant.state_names

    def _make_action_space(self):
        return spaces.Box(-1.0, 1.0, (1,), np.float32)

    def _duty(self, actions) -> np.ndarray:
        # float64 / float32 arrays straight to the compiled duty map; any other (float16, big-endian, long double: numba
        # has no kernel for them, its TypingError named neither) as float64
        a = actions if isinstance(actions, np.ndarray) and actions.dtype in _KERNEL_FLOATS else _numbers(actions)
        if a.shape not in self._action_shapes:   # (n, 1) or (n,)
            raise _shape_error(actions, self.num_envs)
        d = np.empty(self.num_envs)
        k = (self._duty_kernel or kernel_function("duty_kernel", False))(a.reshape(self.num_envs), d)
        if k >= 0:   # NaN would poison the link state and every reward after it
            raise ValueError(f"actions[{k}]={float(a.reshape(-1)[k])!r} is invalid; valid range: [-1, 1] (finite)")
        return d

    def render(self):
        """None, with gymnasium's warning, as a vector env made with ``render_mode=None`` does (gymnasium's own
        ``CartPoleVectorEnv``); gymnasium's ``VectorEnv.render`` raised ``NotImplementedError``. This env has no
        render mode: a single env made with ``render_mode="rgb_array"`` draws a window."""
        logger.warn("render() called on the vector env, which has no render mode (render_mode=None); render a single "
                    "env: gymnasium.make(\"dronewpt/SbarCharging-v0\", render_mode=\"rgb_array\")")
        return None

    @property
    def policy_context(self) -> PolicyContext:
        return PolicyContext(link=self.config.link, control_period_s=self._dt, rated_i2_a=self.config.rated_i2_a,
                             link_model=self.config.link_model)

    # ------------------------------------------------------------------ episodes
    def _start(self, idx, options=None):
        """(Re)start the sub-environments ``idx``: each part reset once, in order (scenario draws with their
        generators, plant, objective, observation); returns the observation and info of every row. The
        scenario is the one of ``options`` (a ``reset``), else the env's: an autoreset or a ``restart`` starts the
        env's scenario, as gymnasium's ``SyncVectorEnv`` autoresets its single envs without options (until
        2026-11-27 the windows kept the last ``reset``'s scenario)."""
        sel = self._rows(idx)
        rngs = self._rngs if isinstance(sel, slice) else [self._rngs[i] for i in idx]
        scenario, plant, objective, observation = self.parts
        win = scenario.reset(rngs, sel, options)
        plan = plant.reset(sel, win)
        objective.reset(sel, win, plan)
        self._k[sel] = 0
        return observation.reset(sel, win, self._k, scenario, plant, objective)

    def _rows(self, idx):
        """The rows of the distinct windows ``idx``: ``slice(None)`` when they are all of them (the usual autoreset:
        written in place, plain copies), else ``idx``."""
        return slice(None) if len(idx) == self.num_envs else idx

    def restart(self, idx) -> np.ndarray:
        """Start new episodes in the sub-environments ``idx`` now (same-step autoreset, as
        stable-baselines3 wants it); returns their first observations, shape (len(idx), OBS_DIM). ``idx``:
        distinct indices 0..N-1 (ValueError otherwise); empty, nothing is restarted."""
        given = real_array(idx)   # a float 1.5 was window 1, a bool mask windows 1, 0, 1: silently
        if given is None or (given.size and given.dtype.kind not in "iu"):
            raise ValueError(f"restart indices {shown(idx)} are invalid; valid: distinct integers 0..{self.num_envs - 1} "
                             "(for a mask m: np.flatnonzero(m))")
        idx = np.asarray(given, dtype=np.int64).reshape(-1)
        if not self._started:   # (no generators yet: an AttributeError on NoneType)
            raise _before_reset("restart")
        if idx.size == 0:   # nothing to start (the plans of no window are not built)
            return np.empty((0,) + self.single_observation_space.shape, np.float32)
        n = self.num_envs
        seen, count = np.unique(idx, return_counts=True)
        if seen[0] < 0 or seen[-1] >= n or count.max() > 1:   # repeated: len(idx) == n would pass for all windows
            bad = seen[(seen < 0) | (seen >= n) | (count > 1)]
            raise ValueError(f"restart indices {bad.tolist()} are invalid; valid range: distinct integers 0..{n - 1}")
        obs, _ = self._start(idx)
        self._prev_done[idx] = False
        if self._last_obs is not None:   # (a copy: the array a step returned is the caller's)
            self._last_obs = self._last_obs.copy()
            self._last_obs[idx] = obs[idx]
        return obs[idx]

    def reset(self, *, seed=None, options: dict | None = None):
        n = self.num_envs
        if seed is None or np.ndim(seed) == 0:   # seed .. seed + n - 1, all seeds (a numpy int passed on as an int)
            if seed is not None:
                seed = check_first_seed(seed, n, "sub-environment", "num_envs")
            super().reset(seed=seed)
            seeds = [None] * n if seed is None else [seed + i for i in range(n)]
        else:   # one per sub-environment; None: that one's generator goes on (as SyncVectorEnv's env.reset(seed=None))
            seeds = [None if s is None else check_number(f"seed[{i}]", s, SEED_RANGE) for i, s in enumerate(seed)]
            if len(seeds) != n:
                raise ValueError(f"seed has {len(seeds)} entries; valid: one int or num_envs={n} ints (or None)")
            super().reset(seed=seeds[0])
        options, mask = self._reset_mask(options)
        # a sub-environment without a seed keeps its generator (a new one from the OS's entropy at the first reset), as
        # does one outside the reset mask
        self._rngs = [r if (s is None and r is not None) or not m else seeding.np_random(s)[0]
                      for s, r, m in zip(seeds, self._rngs, np.ones(n, bool) if mask is None else mask)]
        rows = self._ar if mask is None else np.flatnonzero(mask)
        obs, info = self._start(rows, options)
        if mask is not None:   # the other windows go on: their last observation
            obs = np.where(mask[:, None], obs, self._last_obs)
        self._prev_done[rows] = False
        self._started = True
        self._last_obs = obs
        return obs, info

    def _reset_mask(self, options):
        """``options`` without gymnasium's ``reset_mask`` (a partial reset: the windows where it is True start, the
        others go on; as ``SyncVectorEnv``) and the mask, None for a reset of every window; a ``ValueError`` naming a
        mask that is not a bool array of one value per window with one True at least, or one given before the first
        reset."""
        if not isinstance(options, Mapping) or "reset_mask" not in options:
            return options, None
        options = dict(options)
        mask, n = options.pop("reset_mask"), self.num_envs
        if not (isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.shape == (n,) and mask.any()):
            raise ValueError(f"options['reset_mask']={shown(mask)} is invalid; valid: a numpy bool array of shape "
                             f"({n},) with at least one True")
        if not self._started:
            raise _before_reset("options['reset_mask']")
        return options or None, mask

    def step(self, actions):
        if not self._started:
            raise RuntimeError("step() called before reset(); call reset()")
        d = self._duty(actions)
        done = self._prev_done
        any_done = bool(done.any())
        if any_done:
            self._k[done] = 0   # these rows are stepped for nothing and restarted below
        obs, reward, truncated, info = self._step_parts(d)
        terminated = np.zeros(self.num_envs, dtype=bool)
        if any_done:
            idx = np.flatnonzero(done)
            obs0, info0 = self._start(idx)
            sel = self._rows(idx)
            obs[sel] = obs0[sel]
            reward[sel] = 0.0
            truncated[sel] = False
            for key, v in info.items():
                v[sel] = info0[key][sel]
        self._prev_done = truncated.copy()
        self._last_obs = obs   # (a reset with a reset_mask returns it for the windows that go on)
        return obs, reward, terminated, truncated, info

    def _step_parts(self, d):
        """One step of every sub-environment: the plant's (one call of :func:`envs.vector_kernel.env_step`,
        the objective and the detuned windows included), then the objective's and the observation's."""
        n = self.num_envs
        obs = np.empty((n, OBS_DIM), np.float32)
        reward = np.empty(n)
        truncated = np.empty(n, dtype=bool)
        block = np.empty((n, len(INFO)))
        chunks = self._n_chunks if self._auto is None else self._auto.chunks(self._n_chunks)
        if chunks > 1:
            _set_threads(self.num_threads)
        scenario, plant, objective, observation = self.parts
        probing = self._auto is not None and self._auto.probing()
        t0 = time.perf_counter() if probing else 0.0   # (the clock only in the auto threads' probe steps)
        plant.step(d, self._k, scenario, objective, self._par, self._peak.kernel_table, obs, reward, truncated, block,
                   chunks)
        if self._auto is not None:
            self._auto.record(chunks, time.perf_counter() - t0 if probing else 0.0)
        obs, info = observation.step(obs, block, objective.step())
        return obs, reward, truncated, info


class _AutoThreads:
    """Chooses between the serial and the parallel step by their measured times: every
    :attr:`PERIOD` steps, :attr:`PROBE` steps alternate the two, then the faster (least time of its
    probes) runs until the next probe. On an idle machine the parallel step wins from ~2k sub-envs;
    on a machine whose cores are busy with other work a parallel step waits for a descheduled
    thread (measured 5-10x slower than serial at a load of 9 on 2 cores). The results are the same
    either way (bit-identical steps), only the time differs."""

    PERIOD, PROBE = 2000, 16

    def __init__(self):
        self.step, self.best, self.t = 0, None, {}

    def chunks(self, par: int) -> int:
        s = self.step % self.PERIOD
        if s < self.PROBE:
            return 1 if s % 2 == 0 else par
        return self.best

    def probing(self) -> bool:
        """True in the steps whose times :meth:`record` keeps (the probes)."""
        return self.step % self.PERIOD < self.PROBE

    def record(self, chunks: int, dt: float) -> None:
        s = self.step % self.PERIOD
        if s < self.PROBE:
            if s == 0:
                self.t = {}
            self.t[chunks] = min(self.t.get(chunks, dt), dt)
            if s == self.PROBE - 1:
                self.best = min(self.t, key=self.t.get)
        self.step += 1


def _num_threads(num_threads) -> int:
    """``num_threads`` checked against numba's pool (default: all its threads)."""
    import numba
    top = numba.config.NUMBA_NUM_THREADS
    if num_threads is None:
        return top
    return check_number("num_threads", num_threads, Range(1, top, integer=True), " (numba's threads)")


def _set_threads(k: int) -> None:
    """``k`` threads for the parallel step, its chunks handed out one at a time (dynamic schedule:
    a thread the OS holds back leaves its chunks to the others instead of stalling the step). Once numba's
    pool runs, its thread-local getters are read without ``numba.get_num_threads``'s launch lock (the call 1.3-2.0
    us instead of 6.3-8.3, ``benchmarks/set_threads.py``; numba's private names, the public calls when they are
    missing)."""
    import numba
    get_n, get_c = _GETTERS or _getters()
    if get_n() != k:
        numba.set_num_threads(k)
    if get_c() != 1:
        numba.set_parallel_chunksize(1)


_GETTERS: list = []


def _getters():
    """numba's getters of the calling thread's thread count and chunk size: the pool's own once it is launched
    (numba's private names; its public calls where they are missing), kept in :data:`_GETTERS`; the public calls,
    not kept, until the pool runs (they launch it: looked up again next time)."""
    import numba
    getters, keep = (numba.get_num_threads, numba.get_parallel_chunksize), True
    try:
        from numba.np.ufunc import parallel
        keep = parallel._is_initialized
        if keep:
            getters = (parallel._get_num_threads, parallel._get_parallel_chunksize)
    except (ImportError, AttributeError):
        pass
    if keep:
        _GETTERS[:] = getters
    return getters


#: the action dtypes the compiled duty map takes as they are (native byte order)
_KERNEL_FLOATS = (np.dtype(np.float64), np.dtype(np.float32))


def _before_reset(what: str) -> ValueError:
    """The one error of what needs a reset of every window first (a partial reset, ``restart``)."""
    return ValueError(f"{what} is invalid before the first reset; valid: a reset of every window first")


def _numbers(actions) -> np.ndarray:
    """``actions`` as a float array; a ``ValueError`` naming them when they are not real numbers (None, strings,
    complex values: numpy's own message named neither the argument nor what is valid)."""
    a = real_array(actions)
    if a is None:
        raise _numbers_error(actions)
    return a.astype(float, copy=False)


def _numbers_error(actions) -> ValueError:
    return ValueError(f"actions={shown(actions)} are invalid; valid: real numbers, one per sub-environment")


def _shape_error(actions, n: int) -> ValueError:
    return ValueError(f"actions of shape {np.shape(actions)} are invalid; valid: one per sub-environment, shape "
                      f"({n}, 1) or ({n},)")


class SbarChargingDiscreteVectorEnv(SbarChargingVectorEnv):
    """Batched :class:`envs.charging.SbarChargingDiscreteEnv`: actions in {0: RM, 1: SM}."""

    def _make_action_space(self):
        return spaces.Discrete(2)

    def _duty(self, actions) -> np.ndarray:
        a = real_array(actions)   # as given (ints from SB3): one copy to float below
        if a is None:
            raise _numbers_error(actions)
        if a.shape not in self._action_shapes:   # (n, 1) or (n,)
            raise _shape_error(actions, self.num_envs)
        a = a.reshape(self.num_envs)
        if np.any((a != 0) & (a != 1)):
            raise ValueError(f"actions={a[(a != 0) & (a != 1)][0].item()!r} is invalid; valid values: 0 (RM), 1 (SM)")
        return a.astype(float)


alias_parts(SbarChargingVectorEnv, {
    "_cmd": ("scenario", "cmd"), "_noise": ("scenario", "noise"), "_cur_scenario": ("scenario", "current"),
    "_kernel": ("plant", "kernel"), "_state": ("plant", "state"), "_j": ("plant", "j"),
    "_coef_tab": ("plant", "coef_tab"), "_coef_ix": ("plant", "coef_ix"), "_lm_all": ("plant", "lm_all"),
    "_bat": ("plant", "bat"), "_detuned": ("plant", "detuned"), "_xc": ("plant", "xc"), "_ccoef": ("plant", "ccoef"),
    "_c_rel": ("plant", "c_rel"), "_mstate": ("plant", "mstate"), "_lc": ("plant", "lc"), "_tab": ("plant", "tab"),
    "_coef_cur": ("plant", "coef_cur"), "_start0": ("plant", "start0"), "_i2sm_all": ("objective", "i2sm_all"), "_stop_k": ("objective", "stop_k"),
    "_t_stop": ("objective", "t_stop"), "_run_max": ("objective", "run_max"), "_sm_ok": ("objective", "sm_ok"),
    "_sm_checked": ("objective", "sm_checked"), "_delay": ("observation", "delay"), "_line": ("observation", "line")})
