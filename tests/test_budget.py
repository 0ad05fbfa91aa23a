"""The run-size estimate (mission_sim.world.budget) against real runs: rows, Parquet bytes, peak RSS.

Each real run is ``dronewpt mission --every 0 --no-plot`` in a fresh process, after one unmeasured run
(numba's cache and the disk cache warm: a cold cache compiles, which is not the run's memory). Its peak
RSS is the process's own high-water mark (``VmHWM``), read by the process at its end: ``ru_maxrss``
from ``wait4`` would not do here, as Linux carries the spawning process's maximum (this test process,
after other tests' missions) across ``execve`` into the child's."""

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

_RUN = r"""
import dataclasses, io, sys, contextlib
from mission_sim.config import load_config
import mission_sim.cli.mission as cm
from mission_sim.cli import main
cfg = load_config()
cfg = dataclasses.replace(cfg, pads=cfg.pads * int(sys.argv[1]))
cm.mission_config = lambda args: cfg       # the repeated pads (the config file allows 100 pads)
with contextlib.redirect_stdout(io.StringIO()):
    rc = main(["mission", "--out", sys.argv[2], "--every", "0", "--no-plot", "--no-progress"])
with open("/proc/self/status") as f:
    print(rc, next(line.split()[1] for line in f if line.startswith("VmHWM:")))   # kB
"""


def _run(n: int, out: Path) -> int:
    """Peak RSS [B] of one run of the default pads repeated ``n`` times (a fresh process)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    p = subprocess.run([sys.executable, "-c", _RUN, str(n), str(out)], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    rc, hwm_kb = p.stdout.split()
    assert rc == "0", p.stderr
    return int(hwm_kb) * 1024


@pytest.mark.parametrize("n", [1, 5])
def test_estimate_bounds_a_real_runs_rows_bytes_and_memory(tmp_path, n):
    import pyarrow.parquet as pq

    from mission_sim.config import load_config
    from mission_sim.world.budget import estimate_run

    cfg = load_config()
    est = estimate_run(dataclasses.replace(cfg, pads=cfg.pads * n))
    _run(n, tmp_path / "warm")
    rss = _run(n, tmp_path / "m")
    path = tmp_path / "m" / "timeseries.parquet"
    rows, size = pq.ParquetFile(path).metadata.num_rows, path.stat().st_size
    # rows: one per control period in fine windows (sub-steps merged), per sample charging, per
    # flight_dt in flight; the estimate errs high (a limit), by less than 1.5x
    assert rows <= est.rows < 1.5 * rows, (est.rows, rows)
    assert 0.7 * size < est.output_bytes < 1.6 * size, (est.output_bytes, size)
    # memory is bounded, not per row: the estimate is the real peak within 15 % either way
    assert 0.85 * rss < est.memory_bytes < 1.15 * rss, (est.memory_bytes, rss)


def test_streamed_memory_is_bounded_in_the_missions_length():
    """A streamed run holds a planned block and a chunk of samples, not the trajectory: the estimate
    stops growing with the mission's length (a DataFrame of the rows does not)."""
    from mission_sim.config import load_config
    from mission_sim.world.budget import FIXED_BYTES, HELD_SAMPLES, SAMPLE_BYTES, estimate_run

    cfg = load_config()
    est = {n: estimate_run(dataclasses.replace(cfg, pads=cfg.pads * n)) for n in (1, 100, 1000)}
    assert est[1].memory_bytes < est[100].memory_bytes == est[1000].memory_bytes \
        == FIXED_BYTES + SAMPLE_BYTES * HELD_SAMPLES
    assert est[1000].rows > 9 * est[100].rows
    framed = {n: estimate_run(dataclasses.replace(cfg, pads=cfg.pads * n), frame=True) for n in (100, 1000)}
    assert framed[1000].memory_bytes > 9 * (framed[100].memory_bytes - FIXED_BYTES)
