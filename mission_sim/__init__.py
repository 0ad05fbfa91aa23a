"""mission_sim: the world around the link. Subpackages by concern, in the order data flows:

==================  ============================================================================
``contract``        the observation/action contract and the :class:`Policy` protocol, shared by
                    the mission loop, the envs and every policy
``validation``      one-line checks of physical parameters
``files``           atomic output files (temporary name, then rename; storage errors name the
                    file) and the writer lock of an output folder
``signals``         SIGTERM handled like Ctrl-C (:class:`Interrupted`, exit 130 / 143)
``config``          the mission configuration (TOML, ``default_mission.toml``), ``--set`` overrides
``train_options``   ``policies.train``'s options that act only with another (``ONLY_WITH``), numpy-free: ``dronewpt
                    train`` refuses a misuse before importing ``policies``
``setup_warnings``  what a mission's setup gets likely wrong, one line each (a link outside the exact-mode
                    model's checked range, a pad the route never comes near, a policy for another link)
``world/``          the physical world: trajectory, wind, drone power, battery, the link step,
                    the mission loop and its results
``mavlink/``        MAVLink: reading flight logs, replaying them, live telemetry, follow mode,
                    geodesy
``plans/``          a user's own mission and pads: QGC .plan / .waypoints / flight-log missions
                    into the route, pads files, what-if re-flights of a log with pads
``studies/``        parameter studies: study files, the Dask sweep, its report
``figures/``        every figure (matplotlib); imported only by the CLI
``cli/``            the ``dronewpt`` command line: parse, call, print
==================  ============================================================================

Dependencies point one way: ``wpt_receiver`` <- ``mission_sim`` <- ``envs`` <- ``policies``;
only the CLI reaches ``envs`` and ``policies``, lazily.
"""
