"""A short history of observations (frame stack, ``history = K``) for learned policies (issue 21).

The contract (:mod:`mission_sim.contract`, :func:`~mission_sim.contract.history_obs_dim`) declares
the stacked observation: the last ``K`` observations of a window, oldest first, flattened to
``K * OBS_DIM``; a window starts with ``K`` copies of its first observation (the link sat in the
steady state before it, as in :mod:`envs.sensing`). One frame does not show where in the 4 kHz
ringing the link is, nor how old a delayed current measurement is; a few frames do.

* :class:`ObsHistory` - the buffer, for ``n`` rows (used by the wrapper, by the envs' observation part
  with ``history=K`` (:mod:`envs.parts`) and by the policies at inference, so training and running see
  the same numbers);
* :class:`HistoryVecEnv` - a stable-baselines3 ``VecEnvWrapper`` over the batched adapter
  (:class:`envs.sb3_vec.SbarSB3VecEnv`): stacked observations, ``terminal_observation`` stacked too,
  a window that autoresets starts its stack afresh. (SB3's ``VecFrameStack`` pads with zeros, i.e.
  mid-range values of every field, which is no state the link was ever in; hence this one.)
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import OBS_DIM, history_obs_dim

__all__ = ["ObsHistory", "HistoryVecEnv"]


class ObsHistory:
    """The last ``k`` observation rows of ``n`` windows; :attr:`stacked` is (n, k * dim), oldest first."""

    def __init__(self, k: int, dim: int = OBS_DIM):
        history_obs_dim(k)   # validates k
        self.k, self.dim = int(k), int(dim)
        self.buf = None

    def reset(self, obs) -> np.ndarray:
        """Start every row with ``k`` copies of ``obs`` (n, dim); returns the stacked observation.
        (``dim`` follows the rows given: a residual policy's rows carry the base duty too.)"""
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float32))
        self.dim = obs.shape[1]
        self.buf = np.repeat(obs[:, None, :], self.k, axis=1)
        return self.stacked

    def push(self, obs, starts=None) -> np.ndarray:
        """Append ``obs`` (n, dim); rows where ``starts`` is True begin a new window with it."""
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float32))
        if self.buf is None or self.buf.shape[0] != obs.shape[0] or self.buf.shape[2] != obs.shape[1]:
            return self.reset(obs)
        self.buf = np.concatenate([self.buf[:, 1:], obs[:, None, :]], axis=1)
        if starts is not None and np.any(starts):
            self.buf[np.asarray(starts, dtype=bool)] = obs[np.asarray(starts, dtype=bool)][:, None, :]
        return self.stacked

    def start(self, idx, obs_rows) -> np.ndarray:
        """Rows ``idx`` begin a new window with their first observations ``obs_rows`` (len(idx), dim): ``k``
        copies each (all rows when nothing is stacked yet); returns the stacked observation of every row."""
        obs_rows = np.atleast_2d(np.asarray(obs_rows, dtype=np.float32))
        if self.buf is None or self.buf.shape[2] != obs_rows.shape[1]:
            return self.reset(obs_rows)
        self.buf[idx] = obs_rows[:, None, :]
        return self.stacked

    @property
    def stacked(self) -> np.ndarray:
        return self.buf.reshape(len(self.buf), self.k * self.dim).copy()


def _make_history_vec_env():
    """:class:`HistoryVecEnv`, built on first use (stable-baselines3 imported only then: the envs'
    ``history`` option and the policies' inference use :class:`ObsHistory` without it)."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class HistoryVecEnv(VecEnvWrapper):
        """Frame stack of ``k`` observations over an SB3 ``VecEnv`` of contract observations (see module notes)."""

        def __init__(self, venv, k: int):
            from gymnasium import spaces

            width = history_obs_dim(k) // OBS_DIM * venv.observation_space.shape[0]
            super().__init__(venv, observation_space=spaces.Box(-1.0, 1.0, (width,), np.float32))
            self.k = int(k)
            self.hist = ObsHistory(self.k, venv.observation_space.shape[0])

        def reset(self):
            return self.hist.reset(self.venv.reset())

        def step_wait(self):
            obs, reward, done, infos = self.venv.step_wait()
            if done.any():
                for i in np.flatnonzero(done).tolist():
                    if "terminal_observation" in infos[i]:   # the last frame of the window, stacked on its past
                        last = np.concatenate([self.hist.buf[i, 1:], infos[i]["terminal_observation"][None]], axis=0)
                        infos[i]["terminal_observation"] = last.reshape(-1).astype(np.float32)
            return self.hist.push(obs, starts=done), reward, done, infos

    return HistoryVecEnv


def __getattr__(name):
    if name == "HistoryVecEnv":   # module attribute on first access (PEP 562)
        cls = globals()["HistoryVecEnv"] = _make_history_vec_env()
        cls.__module__, cls.__qualname__ = __name__, "HistoryVecEnv"
        return cls
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
