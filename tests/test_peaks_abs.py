"""``SwitchingResult.peaks_abs``: the exact maximum of |i| over a window, from a coarse scan and a vectorised
golden-section refinement (the switching model's peaks in ``benchmarks/bench_switching.py``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

import _spice
from wpt_receiver import TABLE_I
from wpt_receiver.switching import SwitchingConfig, SwitchingLink
from wpt_receiver.switching.circuit import I1, I2

T_STEP_S, T_END_S = 4e-3, 8e-3


@pytest.fixture(scope="module")
def step_run():
    """Table I's RM -> SM step (ideal devices) from the closed-form RM state: the overshoot rings for ms."""
    link = SwitchingLink(TABLE_I, SwitchingConfig(), compiled=True)
    x0 = np.zeros(link.cir.m)
    x0[:4] = _spice.initial_state(TABLE_I, link.cfg.devices)
    x0[-1] = 1.0
    return _spice._run_step(link, x0, t_step_s=T_STEP_S, t_end_s=T_END_S)


def _windows(res):
    T = res.circuit.T
    return [(I2, T_STEP_S - 4 * T, T_STEP_S), (I2, T_STEP_S, res.t_end), (I1, T_STEP_S - 4 * T, T_STEP_S),
            (I1, res.t_end - 4 * T, res.t_end)]


def _dense_reference(res, col, a, b):
    """The largest of 64 samples per period, each local maximum within 1 % of it refined by scipy's bounded
    Brent search on the exact solution (what the benchmark did before)."""
    ts = np.linspace(a, b, int(math.ceil((b - a) / (res.circuit.T / 64))) + 1)
    y = np.abs(res.states(ts, cols=[col])[0][:, 0])
    best = float(y.max())
    for k in np.flatnonzero((y >= 0.99 * best) & (y >= np.r_[y[1:], 0]) & (y >= np.r_[0, y[:-1]])):
        f = lambda t: -abs(float(res.states(np.array([t]), cols=[col])[0][0, 0]))  # noqa: E731
        r = minimize_scalar(f, bounds=(ts[max(k - 1, 0)], ts[min(k + 1, len(ts) - 1)]), method="bounded",
                            options={"xatol": 1e-13})
        best = max(best, -r.fun)
    return best


def test_peaks_equal_a_dense_brent_search_and_bound_every_sample(step_run):
    """Each window's peak (the RM peaks, the step's overshoot, the SM primary current) equals a dense
    64-per-period scan refined by Brent's method to 1e-9 relative, whatever the coarse scan (4 or 8 per period),
    and no sample of a 256-per-period scan is above it."""
    res = step_run
    wins = _windows(res)
    for per in (4, 8):
        got = res.peaks_abs(wins, per_period=per)
        for (col, a, b), (t, v) in zip(wins, got):
            assert a <= t <= b
            assert v == pytest.approx(_dense_reference(res, col, a, b), rel=1e-9), (per, col, a)
            ts = np.linspace(a, b, int(math.ceil((b - a) / (res.circuit.T / 256))) + 1)
            assert np.abs(res.states(ts, cols=[col])[0][:, 0]).max() <= v * (1 + 1e-12)
    step = got[1][1]
    assert 3.5 < step / got[0][1] < 5.0     # the RM -> SM overshoot: ~4.5x the RM peak with ideal devices


def test_a_peak_on_the_window_edge_and_bad_windows(step_run):
    """A window that ends on a rising flank peaks at its end (the search keeps the ends); a window outside the
    run or reversed, and fewer than 4 samples per period, are refused with the valid range."""
    res = step_run
    T = res.circuit.T
    t_end = T_STEP_S + 0.1 * T
    ts = np.linspace(T_STEP_S, t_end, 200)
    y = np.abs(res.states(ts, cols=[I2])[0][:, 0])
    t, v = res.peak_abs(I2, T_STEP_S, t_end)
    assert v == pytest.approx(y.max(), rel=1e-6) and v >= y.max()
    with pytest.raises(ValueError, match="valid range"):
        res.peak_abs(I2, res.t_end, res.t_end + T)
    with pytest.raises(ValueError, match="valid range"):
        res.peak_abs(I2, T_STEP_S, T_STEP_S - T)
    with pytest.raises(ValueError, match="per_period=2 is invalid"):
        res.peak_abs(I2, T_STEP_S, t_end, per_period=2)
