"""Sensing delay of the observation (scenario ``sense_delay``): the current measurements reach the
policy ``delay`` control periods late.

The fields delayed are the currents a receiver measures with a sensor and a filter (the I2
envelope, the battery current, the SBAR output current: :data:`SENSED`); the battery voltage, SoC,
the command, the last duty and the time since the stop are not (a voltage is sampled directly, the
rest is known to the controller). The observation of step ``k`` then carries the currents of step
``k - delay``; before the window the link sat in the steady state of its first observation, so the
first ``delay`` observations repeat it. ``delay = 0`` is the plain observation, bit for bit
(``tests/test_scenarios_wrong.py``).
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import OBS_INDEX

__all__ = ["SENSED", "MAX_DELAY", "DelayLine"]

SENSED = np.array([OBS_INDEX[k] for k in ("i2_amp_a", "battery_current_a", "rect_current_a")])
MAX_DELAY = 20


class DelayLine:
    """Ring buffer of the sensed fields of ``n`` observation rows (normalised, as the env returns them)."""

    def __init__(self, n: int):
        self.buf = np.zeros((MAX_DELAY + 1, n, len(SENSED)), np.float32)
        self.delay = np.zeros(n, dtype=np.int64)
        self.w = np.zeros(n, dtype=np.int64)
        self._ar = np.arange(n)

    def start(self, idx, obs_rows, delay) -> None:
        """Rows ``idx`` start a window: their history is the first observation ``obs_rows`` (len(idx), OBS_DIM)."""
        self.buf[:, idx] = np.asarray(obs_rows)[:, SENSED][None]
        self.delay[idx] = delay
        self.w[idx] = 1

    def push(self, obs) -> np.ndarray:
        """Store the sensed fields of the new observations ``obs`` (n, OBS_DIM) and replace them, in
        place, by those of ``delay`` steps ago; returns ``obs``."""
        L = self.buf.shape[0]
        self.buf[self.w % L, self._ar] = obs[:, SENSED]
        obs[:, SENSED] = self.buf[(self.w - self.delay) % L, self._ar][:, :]
        self.w += 1
        return obs
