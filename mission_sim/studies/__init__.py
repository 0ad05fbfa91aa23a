"""Parameter studies: many missions, on Dask or serially.

=================  ===========================================================================
``study``          study files (TOML): base mission, grid and Monte Carlo parameters, lazy case
                   space, size check, case identity
``prepare``        a study made ready to run: size, runner, keys and every case's values checked
``mission_cases``  the mission case runner and the fast check of a case's values
``replay_cases``   the replay case runner of ``[replay]`` studies: your flight logs, re-flown per case
``sweep``          the engine: lazy cases in chunks with back-pressure, results into the store
``store``          the Parquet store: parts by count or age, incremental merges, compaction
``cluster``        a Dask client that starts and stops quietly and fast
                   (``_forkserver_env``: the workers get the driver's PYTHONPATH back)
``status``         the sweep's manifest and ``--status`` (done, failed, pending)
``report``         summary and error tables, trade-off plots of a sweep's results
``worst_cases``    per policy the stored case with the largest peak, rebuilt for re-running (sizing)
``tolerance``      component-tolerance Monte Carlo: draws as cases, the runner, yields
=================  ===========================================================================
"""

DEFAULT_MAX_CASES = 1_000_000  # a study larger than this is refused unless --max-cases says otherwise
