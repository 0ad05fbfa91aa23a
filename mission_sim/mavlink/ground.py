"""The height above the take-off spot below which a flight log's vehicle is on the ground: one source.

:data:`GROUND_M` is read by the replay (airborne samples of the power comparison, and the refusal of a ground log
whose armed state is unknown: :mod:`~mission_sim.mavlink.takeoff`), ``calibrate`` (its airborne samples), the
re-flight (``replay --pads``: its detours leave from airborne samples) and the flown route (``mission --plan LOG``:
its points below it are landings). Until 2026-11-28 these were four constants of 1.0 m, two of them said to be
copies of the replay's.

No imports on purpose: :mod:`mission_sim.plans.items` imports it at module level, and ``dronewpt mission`` starts
without pandas (tests/test_startup.py); :mod:`~mission_sim.mavlink.takeoff` imports the log tables (pandas).
The users read ``ground.GROUND_M`` when they run, so that it is one value however it is set.
"""

from __future__ import annotations

__all__ = ["GROUND_M"]

#: [m] height above the take-off spot (the pad, the flown route's home) below which the vehicle is on the ground:
#: GPS height noise is ~1 m, so a track that never rises this high is GPS drift on the ground
GROUND_M = 1.0
