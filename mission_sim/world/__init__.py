"""The physical world of a mission, in the order one loop step uses it:

===============  ==============================================================================
``trajectory``   waypoint missions (planned in blocks on demand), speed profiles, hover phases, replayed tracks
``wind``         seeded wind (Dryden-type gusts), drag, position-hold error, thrust tilt
``power``        electrical propulsion power from momentum theory
``battery``      equivalent-circuit battery (OCV, R0, R1-C1) and CC-CV charger: parameters, OCV curve
``budget``       the size of a run (samples, memory, output bytes) estimated before it starts
``runner``       ``run_mission``: Lm along the trajectory, charged + uncharged runs, flight-time gain
``samples``      the loop's per-sample arrays (Lm, k, propulsion, gating) in chunks as the loop advances
``loop``         ``MissionLoop``: orchestration (constants, per-sample arrays, Python policy calls, result)
``fastpath``     the driver: records packed, the kernel run in chunks, Python policies / noise / errors served
``loop_kernel``  every formula of a mission step, once, compiled (numba; link, battery, BMS, gating, windows)
``loop_records`` the loop's record dtypes, status codes and work-array layout, without numba
``aot``          the loop built ahead of time by ``dronewpt warmup`` (``mission`` then runs without numba)
``results``      :class:`MissionResult`: time series, summary, files
``stream``       rows in blocks: the summary on the fly, the time series to Parquet row groups (CSV on request)
===============  ==============================================================================
"""
