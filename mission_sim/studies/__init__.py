"""Parameter studies: many missions, on Dask or serially.

==========  ==================================================================================
``study``   study files (TOML): base mission, grid and Monte Carlo parameters, case identity
``sweep``   the resumable sweep engine (Parquet store, Dask client) and the mission case runner
``report``  summary and error tables, trade-off plots of a sweep's results
==========  ==================================================================================
"""
