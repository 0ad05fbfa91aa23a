"""A check every test gets: no mission run in the test's process leaves SoC in [0, 1] (issue #16).

Every in-process mission (the CLI, replay, telemetry, studies run in-process, the tests' own calls)
ends in ``MissionLoop.result``; wrapped here, it fails the test if any row of the time series has
SoC outside [0, 1]. Missions run in other processes (CLI subprocesses, Dask workers) are not seen.

And the flight-log tests (``_flightlogs.LOG_TESTS``) read logs from the repository only (issue 16): while
one of their modules runs, opening a file named like a flight log outside the repository (and outside
the temporary folder; never in a ``../shared`` beside it) fails (``_flightlogs.log_guard``, an audit hook
inert at other times).

``dronewpt mission`` run by the tests (in process or in a child) stays on numba's JIT and never builds the
loop ahead of time (``DRONEWPT_AOT=0`` unless set: a build is ~30-60 s of CPU, and tests that change the
loop's code in process must run it); ``tests/test_mission_aot.py`` builds and checks that path.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from _flightlogs import LOG_TESTS, log_guard

_ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("DRONEWPT_AOT", "0")   # mission_sim.world.aot (module notes above)
_GUARDED = [False]
sys.addaudithook(log_guard(_ROOT, _ROOT.parent / "shared", lambda: _GUARDED[0]))


@pytest.fixture(autouse=True, scope="module")
def _flight_logs_from_the_repository_only(request):
    """The guard on for a whole module of ``LOG_TESTS`` (its module fixtures too), off after it."""
    _GUARDED[0] = request.path.name in LOG_TESTS
    yield
    _GUARDED[0] = False


@pytest.fixture(autouse=True)
def _soc_stays_in_0_1(monkeypatch):
    from mission_sim.world import loop

    result = loop.MissionLoop.result

    def checked(self):
        res = result(self)
        if res.timeseries is not None:
            soc = res.timeseries["soc"].to_numpy()
        else:   # no DataFrame (summary-only runs, streamed output): the extremes kept over every row
            soc = np.array([self.stats.min_soc, self.stats.max_soc]) if self.stats.n_rows else np.empty(0)
        if len(soc):
            assert 0.0 <= soc.min() and soc.max() <= 1.0, \
                f"SoC left [0, 1] in a mission run: min {soc.min()!r}, max {soc.max()!r}"
        return res

    monkeypatch.setattr(loop.MissionLoop, "result", checked)
