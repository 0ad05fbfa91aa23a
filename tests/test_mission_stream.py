"""Streamed mission output (issue 22): rows handed over in blocks give the same summary as one block,
the Parquet file holds exactly the time series, CSV only on request, --every thins the stored series."""

import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from mission_sim.config import load_config
from mission_sim.contract import PolicyContext
from mission_sim.world import fastpath, stream
from mission_sim.world.runner import run_mission
from mission_sim.world.stream import SeriesWriter
from policies import make
from tests.test_mission_fast import assert_summaries_agree, assert_timeseries_agree


def _policy(cfg):
    return make("model_based", PolicyContext(control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a))


@pytest.fixture(scope="module")
def reference():
    cfg = load_config()
    return cfg, run_mission(cfg, _policy(cfg), compiled=False)


@pytest.mark.parametrize("compiled", [False, True], ids=["python", "compiled"])
def test_small_blocks_give_the_same_summary_and_series(reference, monkeypatch, compiled):
    """~3,600 rows in blocks of 257: sums, SoC extremes, peak candidates and the rows are those of one block."""
    if compiled:
        pytest.importorskip("numba")
    cfg, ref = reference
    monkeypatch.setattr(fastpath, "BLOCK_ROWS", 257)
    monkeypatch.setattr(fastpath, "_CHUNK", 16)   # the compiled path hands rows over between kernel calls
    blocks = []
    res = run_mission(cfg, _policy(cfg), compiled=compiled, sink=lambda lp, arr: blocks.append(len(arr)))
    assert len(blocks) > 10 and sum(blocks) == len(ref.timeseries)
    assert_summaries_agree(res.summary, ref.summary)
    assert_timeseries_agree(res.timeseries, ref.timeseries)


def test_summary_only_run_matches_the_framed_run(reference):
    cfg, ref = reference
    res = run_mission(cfg, _policy(cfg), compiled=False, frame=False)
    assert res.timeseries is None
    assert_summaries_agree(res.summary, ref.summary)
    # the summary's sums are the time series' sums (energies exact to rounding)
    ts = ref.timeseries
    assert res.summary["energy_from_source_j"] == pytest.approx(math.fsum(ts["e_source_j"]), rel=1e-15)
    assert res.summary["charge_time_s"] == pytest.approx(float(ts["dt_s"][ts["tx_on"]].sum()), rel=1e-12)


def test_parquet_holds_the_series_and_every_thins_it(reference, tmp_path, monkeypatch):
    cfg, ref = reference
    monkeypatch.setattr(fastpath, "BLOCK_ROWS", 500)
    w = SeriesWriter(tmp_path / "all", csv=True)
    run_mission(cfg, _policy(cfg), compiled=False, frame=False, sink=w)
    paths = w.close()
    assert [p.name for p in paths] == ["timeseries.parquet", "timeseries.csv"]
    got = pd.read_parquet(paths[0])
    want = ref.timeseries.copy()
    want["phase"] = want["phase"].astype(str)
    pd.testing.assert_frame_equal(got, want, check_exact=True)
    csv = pd.read_csv(paths[1])
    np.testing.assert_allclose(csv["i2_amp_a"], want["i2_amp_a"], rtol=1e-12)
    assert not [p for p in (tmp_path / "all").iterdir() if p.name.startswith(".")]  # no temporary left
    # --every 1 s: the first row of every simulated second and the last row, nothing else
    w = SeriesWriter(tmp_path / "thin", every_s=1.0)
    run_mission(cfg, _policy(cfg), compiled=False, frame=False, sink=w)
    thin = pd.read_parquet(w.close()[0])
    t = want["t_s"].to_numpy()
    first = np.r_[True, np.floor(t[1:]) > np.floor(t[:-1])]
    first[-1] = True
    np.testing.assert_array_equal(thin["t_s"].to_numpy(), t[first])
    assert len(thin) < 0.1 * len(want)


def test_abort_leaves_nothing(tmp_path):
    cfg = load_config()
    w = SeriesWriter(tmp_path, csv=True)

    def failing(lp, arr):
        w(lp, arr)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_mission(cfg, _policy(cfg), compiled=False, frame=False, sink=failing)
    w.abort()
    assert list(tmp_path.iterdir()) == []


def test_cli_mission_streams_parquet_csv_on_request(tmp_path):
    out = tmp_path / "m"
    cmd = [sys.executable, "-m", "mission_sim.cli", "mission", "--no-plot", "--format", "json", "--out", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == ["summary.json", "timeseries.parquet"]
    s = json.loads((out / "summary.json").read_text())
    ts = pd.read_parquet(out / "timeseries.parquet")
    assert math.isclose(ts["dt_s"].sum(), s["sim_time_s"], rel_tol=1e-9)
    r = subprocess.run(cmd + ["--csv", "--every", "-1"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "--every" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run(cmd + ["--csv", "--every", "0.5"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert len(pd.read_csv(out / "timeseries.csv")) == len(pd.read_parquet(out / "timeseries.parquet")) < len(ts)
