"""The physical world of a mission, in the order one loop step uses it:

===============  ==============================================================================
``trajectory``   waypoint missions (planned in blocks on demand), speed profiles, hover phases, replayed tracks
``wind``         seeded wind (Dryden-type gusts), drag, position-hold error, thrust tilt
``power``        electrical propulsion power from momentum theory
``battery``      equivalent-circuit battery (OCV, R0, R1-C1) and the CC-CV charge manager
``linkstep``     one exact ZOH step of the envelope link with its energy integrals
``budget``       the size of a run (samples, memory, output bytes) estimated before it starts
``runner``       ``run_mission``: Lm along the trajectory, charged + uncharged runs, flight-time gain
``samples``      the loop's per-sample arrays (Lm, k, propulsion, gating) in chunks as the loop advances
``loop``         ``MissionLoop``: the loop (pose -> Lm -> pad gating -> BMS -> policy -> link -> battery)
``fastpath``     when and how the loop runs compiled (policies with a ``kernel()``), packing the state
``loop_kernel``  the loop compiled with numba (imported on the first compiled run; ``loop`` is the reference)
``results``      :class:`MissionResult`: time series, summary, files
``stream``       rows in blocks: the summary on the fly, the time series to Parquet row groups (CSV on request)
===============  ==============================================================================
"""
