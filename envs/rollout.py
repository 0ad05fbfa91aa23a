"""Replay fixed duty sequences on one seeded charging window, many candidates at once.

An episode is a pure function of (scenario, seed) and the duties (:mod:`envs.scenario`), so an
open-loop duty sequence can be scored without a policy: :class:`DutyRollout` resets a batched
vector env (:class:`envs.vector.SbarChargingVectorEnv`, the compiled step) with ``m`` copies of the
same seed and steps the ``m`` candidate sequences side by side. One batch of 64 candidates x 300
steps takes ~20 ms after numba's first compile; finite differences of a sequence's parameters or a
population method cost one batch each. Used by the per-window oracle (:mod:`policies.oracle`).

Both links replay compiled: eq. 4's envelope (``EnvConfig(link_model="envelope")``:
:func:`envs.vector_kernel.step_kernel`) and the exact-mode link (the default since 2026-11-26,
``EnvConfig(link_model="modal")``: :func:`envs.modal_step.step_kernel`, detuned windows
included, their C1, C2 being in the window's link constants); ``DutyRollout(..., compiled=False)`` steps the
env from Python instead (the reference the tests compare the replays with).

What a rollout returns (:class:`RolloutResult`, arrays (m, n_steps)): the step's energy into the
battery node ``VL I_L dt`` [J], the instantaneous peak |i2| [A] (the objective's, envelope + ripple,
:mod:`envs.peaks`), the short-mode I2 of the true link at each step [A] (:func:`envs.objective.short_mode_i2_a`),
the SBAR output current ``I_L`` [A], and the stop step; the objective's overshoot, the energy
after the stop and the short-mode flag follow from them exactly as the env computes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .core import EnvConfig, as_config
from .scenario import get_scenario

__all__ = ["RolloutResult", "DutyRollout"]


@dataclass
class RolloutResult:
    """Per-step traces of ``m`` duty sequences on one window (arrays (m, n_steps) unless stated)."""

    energy_j: np.ndarray
    i2_peak_a: np.ndarray
    i2_sm_a: np.ndarray          # (n_steps,) short-mode I2 of the true link (the overshoot's reference)
    rect_current_a: np.ndarray
    stop_k: int                  # first step scored against the stop (envs.objective.stop_step)
    overshoot: np.ndarray        # (m,) the env's episode overshoot (fraction)
    reached_short_mode: np.ndarray  # (m,) bool

    @property
    def energy_after_stop_j(self) -> np.ndarray:
        """(m,) energy delivered after the stop command [J] (compare's ``energy_after_stop_j``)."""
        return self.energy_j[:, self.stop_k:].sum(axis=1)

    @property
    def ratios(self) -> np.ndarray:
        """(m, n_steps - stop_k) ``peak / I2_sm - 1`` of every step after the stop (max = overshoot)."""
        return self.i2_peak_a[:, self.stop_k:] / self.i2_sm_a[self.stop_k:] - 1.0


class DutyRollout:
    """Fixed duty sequences (m, n_steps) on the window ``seed`` of ``scenario`` (one batched env per
    batch size, kept; duties clipped to [0, 1] as the env does)."""

    def __init__(self, scenario="nominal", seed: int = 0, config: EnvConfig | dict | None = None,
                 compiled: bool = True):
        self.scenario = get_scenario(scenario)
        self.seed = int(seed)
        self.config = as_config(config)
        self.compiled = bool(compiled)
        self._modal = self.config.link_model == "modal"
        self._envs, self._snap, self._prefix = {}, {}, {}
        self.n_steps = self.config.n_steps
        probe = self._env(1)
        probe.reset(seed=[self.seed])
        self.stop_k = int(probe._stop_k[0])
        # eq. 4's env with a detuned window: its replay step (vector_kernel.step_kernel) has no complex envelope,
        # so that window is stepped from Python; the exact-mode link's replay covers it (C1, C2 in the constants)
        self._detuned_envelope = not self._modal and bool(len(probe._detuned) and probe._detuned.any())
        self.i2_sm_a = probe._i2sm_all[np.arange(self.n_steps) // self.config.slow_every, 0].copy()

    def _env(self, m: int):
        from .vector import SbarChargingVectorEnv
        if m not in self._envs:
            self._envs[m] = SbarChargingVectorEnv(num_envs=m, scenario=self.scenario, config=self.config)
        return self._envs[m]

    def run(self, duties) -> RolloutResult:
        """Roll out every row of ``duties`` (m, n_steps) (or one sequence (n_steps,)): the env's
        compiled step (:func:`envs.vector_kernel.step_kernel`) called for every step inside one
        compiled loop (:func:`_replay`, no Python per step), the same numbers as ``env.step``
        (``tests/test_oracle_mpc.py``); on the exact-mode link (``config.link_model == "modal"``) the loop calls
        :func:`envs.modal_step.step_kernel` (``tests/test_rollout_modal.py``). Uncompiled (``compiled=False``),
        or eq. 4's env with a detuned window (its replay step is the tuned one), the env is stepped from
        Python (:meth:`_run_steps`: the same numbers, slower)."""
        d = np.atleast_2d(np.asarray(duties, dtype=float))
        m, T = d.shape
        if T != self.n_steps or not np.all(np.isfinite(d)):
            raise ValueError(f"duties shape {d.shape} is invalid; valid: (m, {self.n_steps}) finite values")
        env = self._env(m)
        if env._kernel is None or not self.compiled or self._detuned_envelope:
            env.reset(seed=[self.seed] * m)
            return self._run_steps(env, d)
        # the env's duty arithmetic: d = clip((a + 1)/2, 0, 1) of the float32 action
        acts = (2.0 * np.clip(d, 0.0, 1.0) - 1.0).astype(np.float32).astype(np.float64)
        duty = np.ascontiguousarray(np.clip((acts + 1.0) * 0.5, 0.0, 1.0).T)
        k0 = self.stop_k if np.all(duty[:self.stop_k] == duty[:self.stop_k, :1]) else 0
        out = np.zeros((3, T, m))
        self._restore(env, m, duty[:k0, 0])
        self._replay(env, duty[k0:], out[:, k0:])
        if k0:
            out[:, :k0] = self._prefix[duty[:k0, 0].tobytes()][1]
        return RolloutResult(out[0].T.copy(), out[1].T.copy(), self.i2_sm_a, out[2].T.copy(), self.stop_k,
                             env._run_max.copy(), env._sm_ok & env._sm_checked)

    _MUTABLE = ("_state", "_k", "_j", "_run_max", "_sm_ok", "_sm_checked")
    #: the exact-mode link's own state besides: mode amplitudes and V2 (MSTATE), the current segment's modes and ZOH
    _MUTABLE_MODAL = _MUTABLE + ("_mstate", "_coef_cur")

    def _mutable(self):
        return self._MUTABLE_MODAL if self._modal else self._MUTABLE

    def _restore(self, env, m, prefix):
        """Put env (m rows) at the window's start, or after the duty ``prefix`` shared by every row
        (kept per prefix: one env reset per batch size, the prefix stepped once with one row)."""
        if m not in self._snap:
            env.reset(seed=[self.seed] * m)
            self._snap[m] = {a: getattr(env, a).copy() for a in self._mutable()}
        for a, v in self._snap[m].items():
            getattr(env, a)[...] = v
        if len(prefix) == 0:
            return
        key = prefix.tobytes()
        if key not in self._prefix:
            one = self._env(1)
            self._restore(one, 1, prefix[:0])
            out = np.zeros((3, len(prefix), 1))
            self._replay(one, np.ascontiguousarray(prefix[:, None]), out)
            self._prefix[key] = ({a: getattr(one, a).copy() for a in self._mutable()}, out)
        for a, v in self._prefix[key][0].items():
            x = getattr(env, a)
            x[...] = v if x.ndim == 1 and len(v) == 1 else (v if x.shape == v.shape else np.broadcast_to(
                v, x.shape) if x.ndim == 1 else (np.repeat(v, x.shape[1], axis=1) if a in ("_state", "_mstate") else
                                                np.repeat(v, x.shape[0], axis=0)))

    def _replay(self, env, duty, out):
        """Step ``env`` with ``duty`` (T', m) in one compiled call; energy, peak and I_L into ``out`` (3, T', m)."""
        from .vector_kernel import INFO_ROWS
        ep = (env._i2sm_all, env._stop_k, env._t_stop, env._run_max, env._sm_ok, env._sm_checked)
        scale, offset = env._obs_scale[:, 0].copy(), env._obs_offset[:, 0].copy()
        if self._modal:
            info = _replay_modal()(duty, env._state, env._mstate, env._k, env._j, env._lc, env._coef_cur, env._bat,
                                   env._cmd, env._noise, env._lm_all, ep, env._M, env._n_sub, env._par, scale, offset,
                                   env._tab, len(INFO_ROWS))
        else:
            info = _replay()(duty, env._state, env._k, env._j, env._coef_tab, env._coef_ix, env._bat, env._cmd,
                             env._noise, env._lm_all, ep, env._M, env._n_sub, env._par, scale, offset,
                             env._peak.kernel_table, len(INFO_ROWS))
        cols = [INFO_ROWS.index(k) for k in ("energy_j", "i2_peak_a", "rect_current_a")]
        out[...] = info[:, :, cols].transpose(2, 0, 1)   # (T', m, 3) -> (3, T', m)
        env._started = False   # the env's own bookkeeping (autoreset flags) was bypassed: reset before reuse

    def _run_steps(self, env, d) -> RolloutResult:
        """:meth:`run` through ``env.step`` (without numba)."""
        m, T = d.shape
        acts = (2.0 * np.clip(d, 0.0, 1.0) - 1.0).astype(np.float32)
        e, pk, il = np.empty((m, T)), np.empty((m, T)), np.empty((m, T))
        for k in range(T):
            _, _, _, _, info = env.step(acts[:, k:k + 1])
            e[:, k], pk[:, k], il[:, k] = info["energy_j"], info["i2_peak_a"], info["rect_current_a"]
        return RolloutResult(e, pk, self.i2_sm_a, il, self.stop_k, info["overshoot"].copy(),
                             np.asarray(info["reached_short_mode"], dtype=bool).copy())


_REPLAY = []
_CHECKED = []


def _drop_stale():
    """Drop this module's numba cache when a step it compiles in changed (numba keys on this file alone). Both
    replays' sources in one stamp (one stamp per module: two sets would drop each other's cache), by path, so
    the envelope's replay does not import the modal step; checked once per process."""
    if _CHECKED:
        return
    from pathlib import Path

    from wpt_receiver.kernel_cache import drop_stale_cache
    from wpt_receiver.modal_link import SOURCES
    here = Path(__file__).parent
    deps = [here / f for f in ("vector_kernel.py", "layout.py", "objective.py", "modal_step.py", "duty_sine.py")]
    drop_stale_cache(_here, deps + list(SOURCES))
    _CHECKED.append(True)


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


def _replay():
    """The compiled replay loop (built on first use: numba is imported only then)."""
    if not _REPLAY:
        from numba import njit

        from .vector_kernel import step_kernel

        _drop_stale()

        @njit(cache=True)
        def replay(duty, state, k, j, coef_tab, coef_ix, bat, cmd_all, noise_all, lm_all, ep, slow_every, n_sub,
                   par, scale, offset, ptab, n_info):
            T, n = duty.shape
            obs, reward, trunc = np.empty((n, 8), np.float32), np.empty(n), np.empty(n, np.bool_)
            info = np.empty((T, n, n_info))   # every step's info block (DutyRollout._replay takes its columns)
            for s in range(T):
                step_kernel(duty[s], state, k, j, coef_tab, coef_ix, bat, cmd_all, noise_all, lm_all, ep,
                            slow_every, n_sub, par, scale, offset, ptab, obs, reward, trunc, info[s])
            return info

        _REPLAY.append(replay)
    return _REPLAY[0]


_REPLAY_MODAL = []


def _replay_modal():
    """The compiled replay loop of the exact-mode link (:func:`envs.modal_step.step_kernel`; built on first use)."""
    if not _REPLAY_MODAL:
        from numba import njit

        from .modal_step import step_kernel

        _drop_stale()

        @njit(cache=True)
        def replay_modal(duty, state, mstate, k, j, lc_all, cz_all, bat, cmd_all, noise_all, lm_all, ep, slow_every,
                         n_sub, par, scale, offset, tab, n_info):
            T, n = duty.shape
            obs, reward, trunc = np.empty((n, 8), np.float32), np.empty(n), np.empty(n, np.bool_)
            info = np.empty((T, n, n_info))   # as _replay's loop, on the modal step
            for s in range(T):
                step_kernel(duty[s], state, mstate, k, j, lc_all, cz_all, bat, cmd_all, noise_all, lm_all, ep,
                            slow_every, n_sub, par, scale, offset, tab, obs, reward, trunc, info[s])
            return info

        _REPLAY_MODAL.append(replay_modal)
    return _REPLAY_MODAL[0]
