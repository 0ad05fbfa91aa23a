"""A cheap deterministic case runner for the sweep-engine tests (no mission physics).

Used where the point of the test is the engine (kill-and-resume, error capture, store), via
``[study] runner = "sweep_toy:factory"`` (the tests put this folder on PYTHONPATH).

Metrics are closed forms of the parameters, so a case's result is known exactly:
``flight_time_gain_s = hover_time_s * 8 / (1 + spacing_m / 50)``, ``peak_i2_a`` by policy.
Parameters: ``mission.hover_time_s``, ``pads.1.x_m``, ``policy``, ``seed``, ``delay_s`` (sleep,
to make cases take time), ``fail`` (raise ``ValueError`` when true). Environment variable
``SWEEP_TOY_FAIL_ABOVE``: cases with a larger hover time raise (a flaky setup, fixed by unsetting it).
"""

from __future__ import annotations

import os
import time

import numpy as np

VALID_KEYS = ("mission.hover_time_s", "pads.1.x_m", "seed", "delay_s", "fail", "wind.speed_m_s")
PEAK_I2_A = {"step": 50.5, "ramp": 11.8, "model_based": 11.44}


def toy_case(params: dict) -> dict:
    time.sleep(float(params.get("delay_s", 0.0)))
    if params.get("fail"):
        raise ValueError(f"fail={params['fail']!r}: this case is meant to fail")
    hover = float(params.get("mission.hover_time_s", 10.0))
    if hover > float(os.environ.get("SWEEP_TOY_FAIL_ABOVE", "inf")):  # a flaky environment, for --retry-errors
        raise RuntimeError(f"hover {hover} > SWEEP_TOY_FAIL_ABOVE")
    spacing = float(params.get("pads.1.x_m", 50.0))
    rng = np.random.default_rng(int(params.get("seed", 0)))
    noise = float(rng.normal(0.0, 0.01))
    return {"flight_time_gain_s": hover * 8.0 / (1.0 + spacing / 50.0) + noise,
            "peak_i2_a": PEAK_I2_A[params.get("policy", "model_based")] + noise,
            "time_above_rated_s": 0.0,
            "wind_seen_m_s": float(params.get("wind.speed_m_s", 0.0)),
            "worker_pid": os.getpid()}


class ToyRunner:
    """Picklable runner object with the same ``validate_keys`` hook as the mission runner."""

    def __call__(self, params: dict) -> dict:
        return toy_case(params)

    def check_params(self, params):
        """Like the mission runner's check: a message naming the key and value, or None."""
        hover = params.get("mission.hover_time_s", 10.0)
        if isinstance(hover, bool) or not isinstance(hover, (int, float)) or not hover >= 0:
            return f"mission.hover_time_s={hover!r} is invalid; valid range: [0, inf)"
        return None

    def validate_keys(self, keys, example):
        for k in keys:
            if k not in VALID_KEYS:
                raise ValueError(f"override key {k!r} is unknown; valid keys: {', '.join(VALID_KEYS)}")


def factory(study):
    return ToyRunner()
