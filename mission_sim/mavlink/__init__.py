"""MAVLink: flight logs in, telemetry out (pymavlink).

=============  ==============================================================================
``logs``       read .tlog and DataFlash .bin logs into pandas tables (never raises on content)
``ulog``       read PX4 ULog (.ulg) files into the same tables (pyulog)
``flightlog``  the :class:`FlightLog` tables shared by both readers
``clock``      one time base per .tlog: the boot clock fitted to the receive clock, reboot segments
``calibrate``  the drone power model fitted to a log's battery power (``dronewpt calibrate``)
``armed``      armed periods: from armed-state records, else inferred from motor outputs / throttle
``gpsclean``   rejection of implausible GPS fixes (quality, altitude, jumps), counted
``geodesy``    geodetic <-> local ENU about a pad, the ``--pad`` text format
``takeoff``    a log's take-off spot: the replay's default pad, the flown route's home
``ground``     the height above the take-off spot below which the vehicle is on the ground (one constant)
``replay``     a real flight log through the mission world: track about a pad, logged vs model
``telemetry``  live MAVLink 2 telemetry of a simulated mission, .tlog writer
``follow``     drive the mission world from a live vehicle's positions (``--follow``)
=============  ==============================================================================
"""
