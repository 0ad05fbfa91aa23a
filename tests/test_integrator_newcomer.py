"""A drone integrator's pass (2026-11-27): what replaying real logs, flying one's own mission files and
streaming telemetry to a ground station found, each case a test that failed before its fix
(docs/robustness.md, "A drone integrator's pass")."""

from __future__ import annotations

import numpy as np
import pytest

from _flightlogs import log_path
from mission_sim.config import load_config


def test_replay_disarmed_draws_avionics_only():
    """A replayed log's disarmed samples ("ground": motors off) draw the avionics alone. The per-sample
    arrays moved into chunks (world/samples.py) had dropped the replay's override, so a disarmed ROV
    sitting on the bench for 247 s drew hover power (98.8 W): 26.0 kJ of 'propulsion' instead of 3.6 kJ."""
    import policies
    from mission_sim.mavlink.replay import replay_log

    cfg = load_config(None)
    res = replay_log(log_path("ardusub_log_tools_small_rov.tlog"), cfg, policies.make("model_based"))
    ts = res.mission.timeseries
    ground = (ts["phase"] == "ground").to_numpy()
    assert ground.sum() > 100 and (~ground).sum() > 100
    np.testing.assert_allclose(ts.loc[ground, "propulsion_w"].to_numpy(), cfg.drone.avionics_w, rtol=1e-12)
    assert ts.loc[~ground, "propulsion_w"].median() > 10 * cfg.drone.avionics_w    # armed: momentum theory
    # the summary's propulsion energy is the rows' (the step-mean power times dt, to rounding)
    e = float(np.sum(ts["propulsion_w"].to_numpy() * ts["dt_s"].to_numpy()))
    assert res.summary["propulsion_energy_j"] == pytest.approx(e, rel=1e-6)
    assert res.summary["propulsion_energy_j"] < 5000.0           # 26,024 J before the fix
