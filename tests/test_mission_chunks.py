"""Long missions in bounded memory (issue 22): the trajectory planned in blocks, the loop's per-sample
arrays in chunks, and a run's peak Python-allocated memory that does not grow with its length.

* :class:`~mission_sim.world.trajectory.PlannedTrajectory` in blocks of 257 samples gives
  :func:`plan_mission`'s numbers to the bit (the wind's gust streams and both filters carried across
  blocks; a wrong carry changes every later sample);
* :class:`~mission_sim.world.samples.MissionSamples` chunks give the numbers of the whole series
  (propulsion power through ``numpy.gradient``, Lm from the table), also on a non-uniform grid;
* a mission run through chunks of 300 samples (the default pads 3 times: ~3,400 samples, 12 chunks)
  gives the summary and the stored rows of one chunk larger than the mission: counts, flags and
  the rows exactly, float summary values to 1e-12 relative (the exact sums are carried block by
  block, ``math.fsum`` of the previous sum and the block, and the chunks move the block edges);
* tracemalloc's peak of a streamed compiled run at 8x the length is within 1.25x of the short
  run's (no wall-clock asserts; unchunked it doubles);
* the writer's thinned copy for figures is bounded and keeps the peak transient.
"""

import dataclasses
import math
import tracemalloc

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("numba")

from mission_sim.config import load_config, policy_context  # noqa: E402
from mission_sim.world import samples as samples_mod  # noqa: E402
from mission_sim.world import trajectory as traj_mod  # noqa: E402
from mission_sim.world.runner import _lm_along, run_mission  # noqa: E402
from mission_sim.world.samples import MissionSamples, gradient_rows, uniform_spacing  # noqa: E402
from mission_sim.world.stream import SeriesWriter  # noqa: E402
from mission_sim.world.trajectory import PlannedTrajectory, Trajectory, plan_mission  # noqa: E402

_FIELDS = ("t_s", "pos_m", "tilt_rad", "phase", "tilt_axis_rad", "wind_m_s")


def _cfg(repeats: int):
    cfg = load_config()
    return dataclasses.replace(cfg, pads=cfg.pads * repeats)


def _policy(cfg):
    import policies
    return policies.make("model_based", policy_context(cfg))


def test_planned_trajectory_in_blocks_is_the_plan(monkeypatch):
    cfg = _cfg(2)
    whole = plan_mission(cfg)
    monkeypatch.setattr(traj_mod, "PLAN_BLOCK", 257)
    plan = PlannedTrajectory(cfg)
    assert len(plan) == len(whole) > 4 * 257 and plan.t_end_s == whole.t_s[-1]
    for a, b in [(0, 10), (250, 1300), (1299, 1800), (3, 9), (len(whole) - 5, len(whole))]:  # (3, 9): back to the start
        part = plan.chunk(a, b)
        for f in _FIELDS:
            assert np.array_equal(getattr(part, f), getattr(whole, f)[a:b]), (f, a, b)
    assert not np.array_equal(whole.wind_m_s[:257], whole.wind_m_s[257:514])   # the gusts are not repeated per block
    # the generator passed in is left where plan_mission always left it (3 gust streams drawn)
    r1, r2 = np.random.default_rng(4), np.random.default_rng(4)
    PlannedTrajectory(cfg, r1)
    r2.standard_normal(3 * len(whole))
    assert r1.standard_normal() == r2.standard_normal()


def test_gradient_rows_is_numpy_gradient_uniform_and_not():
    rng = np.random.default_rng(1)
    f = rng.normal(size=(400, 3))
    for t in (np.arange(400) * 0.25, np.cumsum(rng.uniform(0.05, 0.3, 400))):
        u = uniform_spacing(t)
        assert np.array_equal(gradient_rows(f, t, u), np.gradient(f, t, axis=0))
        # a window's interior rows are the whole series' rows
        assert np.array_equal(gradient_rows(f[99:201], t[99:201], u)[1:-1], np.gradient(f, t, axis=0)[100:200])
    assert uniform_spacing(np.arange(5) * 0.25) and not uniform_spacing([0.0, 1.0, 2.5])


@pytest.mark.parametrize("replay", [False, True], ids=["planned", "replayed, non-uniform"])
def test_sample_chunks_are_the_whole_series(replay):
    cfg = _cfg(1)
    whole = plan_mission(cfg)
    if replay:   # a logged track: jittered sample times
        t = whole.t_s + np.random.default_rng(2).uniform(-0.02, 0.02, len(whole)) * (np.arange(len(whole)) > 0)
        whole = Trajectory(t, whole.pos_m, whole.tilt_rad, whole.phase, whole.tilt_axis_rad, whole.wind_m_s)
    traj = whole if replay else PlannedTrajectory(cfg)
    smp = MissionSamples(cfg, traj, True)
    p_want = whole.propulsion_w(cfg.drone)
    lm_want = _lm_along(cfg, cfg.coupling.model(), whole)[0]
    n, step = len(whole), 173
    got = [smp.chunk(a, a + step) for a in range(0, n, step)]
    assert np.array_equal(np.concatenate([c.p_w for c in got]), p_want)
    assert np.array_equal(np.concatenate([c.lm_h for c in got]), lm_want) and lm_want.max() > 0
    elig = np.concatenate([c.elig for c in got])
    assert np.array_equal(elig != 0, np.isin(whole.phase, ("charge", "hover"))) and elig.any()
    pos, phase = smp.pose(np.arange(n - 10, n))
    assert np.array_equal(pos, whole.pos_m[n - 10:]) and np.array_equal(phase, whole.phase[n - 10:])


def _streamed(cfg, tmp_path, name):
    w = SeriesWriter(tmp_path / name)
    res = run_mission(cfg, _policy(cfg), compiled=True, frame=False, sink=w)
    w.close()
    return res.summary, pd.read_parquet(tmp_path / name / "timeseries.parquet")


def test_mission_in_chunks_gives_the_summary_and_rows_of_one_chunk(tmp_path, monkeypatch):
    cfg = _cfg(3)
    one_summary, one_rows = _streamed(cfg, tmp_path, "one")
    sizes = []
    real_chunk = MissionSamples.chunk

    def spy(self, k0, k1):
        c = real_chunk(self, k0, k1)
        sizes.append(len(c))
        return c
    monkeypatch.setattr(samples_mod, "SAMPLE_CHUNK", 300)
    monkeypatch.setattr(MissionSamples, "chunk", spy)
    many_summary, many_rows = _streamed(cfg, tmp_path, "many")
    n = len(PlannedTrajectory(cfg))
    assert n > 10 * 300 and len(sizes) >= 2 * n // 300 - 2     # both runs (charged and baseline) went in chunks
    assert max(sizes) <= 300 + 64                               # a chunk and the quiet-flight look-ahead
    assert many_summary.keys() == one_summary.keys()
    for key, want in one_summary.items():
        got = many_summary[key]
        if key in ("wall_s", "realtime_factor"):
            continue
        if isinstance(want, float) and not isinstance(want, bool):
            assert got == pytest.approx(want, rel=1e-12, abs=1e-15 if "error" in key else 0.0), key
        else:
            assert got == want, key
    assert one_summary["fine_steps"] > 1000 and not one_summary["battery_depleted"]
    pd.testing.assert_frame_equal(many_rows, one_rows, check_exact=True)


def _peak_bytes(repeats: int, tmp_path) -> tuple[int, int]:
    cfg = _cfg(repeats)
    pol = _policy(cfg)
    w = SeriesWriter(tmp_path / f"r{repeats}", every_s=1.0)
    tracemalloc.start()
    try:
        res = run_mission(cfg, pol, compiled=True, frame=False, sink=w)
        w.close()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return peak, math.ceil(res.summary["sim_time_s"] / cfg.sim.traj_dt_s)


def test_peak_python_memory_does_not_grow_with_the_mission(tmp_path, monkeypatch):
    """Chunks of 1,024 samples and planning blocks of 512: the default pads 2 times (~2,200 samples)
    and 16 times (~17,000). Planning and holding all samples at once costs ~300 B a sample at the
    planning peak (RSS by phases, docs/streaming.md): with one chunk and one block larger than the
    mission the traced peak doubles from the short run to the long one (6.7 -> 13.5 MB measured),
    the peak being ~7 MB (the kernel's row buffer for a chunk, numpy's ``np.empty`` counted whole);
    chunked, the peak grows by less than 25 % for 8x the length (the instantaneous peak is tracked
    in the kernel: no per-row candidates are kept)."""
    monkeypatch.setattr(samples_mod, "SAMPLE_CHUNK", 1024)
    monkeypatch.setattr(traj_mod, "PLAN_BLOCK", 512)
    _peak_bytes(1, tmp_path)   # warm: imports, numba, the coupling table, caches
    short, n_short = _peak_bytes(2, tmp_path)
    long_, n_long = _peak_bytes(16, tmp_path)
    assert n_long > 7 * n_short
    assert long_ < 1.25 * short, (short, long_)


def test_thinned_copy_for_figures_is_bounded_and_keeps_the_peak_transient(tmp_path):
    """The writer's :class:`ThinnedSeries` (what ``dronewpt mission`` draws its figures from): rows of the
    stored file unchanged, between ``max_points`` and twice that many plus the peak window, in time
    order, and the 2,000 stored rows either side of the largest |I2| all there."""
    from mission_sim.world.stream import FIGURE_COLUMNS
    cfg = _cfg(3)
    w = SeriesWriter(tmp_path / "t", figure_points=500)
    run_mission(cfg, _policy(cfg), compiled=True, frame=False, sink=w)
    w.close()
    stored = pd.read_parquet(tmp_path / "t" / "timeseries.parquet", columns=list(FIGURE_COLUMNS))
    thin = w.thinned.frame()
    assert len(stored) > 8 * 500 and 500 <= len(thin) <= 2 * 500 + 4001 and w.thinned.stride >= 4
    assert np.all(np.diff(thin["t_s"].to_numpy()) > 0)
    merged = thin.merge(stored, on="t_s", suffixes=("", "_file"))
    assert len(merged) == len(thin)                       # every kept row is a stored row ...
    for c in FIGURE_COLUMNS[1:]:
        assert np.array_equal(merged[c].to_numpy(), merged[c + "_file"].to_numpy()), c   # ... unchanged
    j = int(np.argmax(np.abs(stored["i2_amp_a"].to_numpy())))
    window = stored["t_s"].to_numpy()[max(j - 2000, 0):j + 2000]
    assert np.isin(window, thin["t_s"].to_numpy()).all()

