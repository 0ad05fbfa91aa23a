"""How long the README's quickstart commands take end to end on this machine (for README.md).

Runs the main job, ``dronewpt mission`` (the built-in default mission with its five figures), as a
fresh process ``--repeat`` times, and beside it in the same run ``dronewpt mission --no-plot`` and
``dronewpt --version`` (the baseline: interpreter and CLI start-up only). With ``--tests`` it also
times ``python -m pytest -q`` once (the quickstart's test command after the install; the pip step
is not timed: it depends on the network and pip's cache). Reports medians with the range and the
load average (``os.getloadavg()``) before and after, since other work on the machine slows it.

    PYTHONPATH=$PWD python benchmarks/bench_quickstart.py [--repeat 5] [--tests]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _time_once(argv: list[str], cwd: Path, check: bool = True) -> tuple[float, str]:
    """Wall time [s] of one fresh process and the last line of its output; raises if it fails and ``check``."""
    t0 = time.perf_counter()
    r = subprocess.run(argv, cwd=cwd, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if check and r.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({r.returncode}): {r.stderr.strip()[-500:]}")
    return dt, (r.stdout.strip().splitlines() or [""])[-1]


def _row(name: str, times: list[float], base: float | None) -> str:
    med = statistics.median(times)
    ratio = f", {med / base:.0f}x the start-up" if base else ""
    return f"{name:<34} median {med:6.2f} s  (range {min(times):.2f}-{max(times):.2f} s, n={len(times)}{ratio})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--tests", action="store_true", help="also time the whole test suite once")
    args = ap.parse_args()
    cli = [sys.executable, "-m", "mission_sim.cli"]
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        runs = {"dronewpt --version": [*cli, "--version"],
                "dronewpt mission --no-plot": [*cli, "mission", "--no-plot", "--no-progress", "--out", f"{tmp}/m"],
                "dronewpt mission (main job)": [*cli, "mission", "--no-progress", "--out", f"{tmp}/m"]}
        times = {name: [] for name in runs}
        for _ in range(args.repeat):  # interleaved, so a change of load hits all three alike
            for name, argv in runs.items():
                times[name].append(_time_once(argv, Path(tmp))[0])
    base = statistics.median(times["dronewpt --version"])
    for name, ts in times.items():
        print(_row(name, ts, None if name.endswith("--version") else base))
    if args.tests:
        t, last = _time_once([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"], ROOT, check=False)
        print(f"{'python -m pytest -q (whole suite)':<34} {t:6.1f} s (once: {last})")
    load1 = os.getloadavg()
    print(f"load average (1, 5, 15 min) before {load0[0]:.1f}, {load0[1]:.1f}, {load0[2]:.1f}; after "
          f"{load1[0]:.1f}, {load1[1]:.1f}, {load1[2]:.1f}; {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
