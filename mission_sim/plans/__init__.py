"""Missions and pads from files: a user's own mission instead of the built-in waypoint pattern.

==========  ==================================================================================
``items``   mission items from QGC ``.plan`` (JSON), ``.waypoints`` (QGC WPL 110), the mission a
            MAVLink log uploaded (MISSION_ITEM(_INT) in a .tlog, CMD in a DataFlash .bin) or the
            track it flew (decimated); one-line errors naming the file and the item
``fence``   a ``.plan``'s geofence zones and rally points; warnings where the route leaves an
            inclusion zone or enters an exclusion one (pure geometry; the route is flown as planned)
``pads``    charging pads from a CSV (lat, lon[, alt][, hover_time_s]) or GeoJSON Points file
``route``   items -> the config's ``[[waypoints]]`` in the pad frame (ENU about home, with
            :mod:`mission_sim.mavlink.geodesy`), pads -> ``[[pads]]``, loiters at a pad ->
            charging hovers, payload releases (DO_GRIPPER release; not DO_WINCH deliver) counted on the
            waypoint before them; :func:`~mission_sim.plans.route.apply_mission_files` (config loading)
``refly``   what-if re-flight of a logged flight with pads added (``replay LOG --pads FILE``)
==========  ==================================================================================

Nothing here imports :mod:`mission_sim.config`: the readers produce plain dicts that the config
validates (config -> plans, never back).
"""

#: the ``[mission]`` keys read together with the mission and pads files when a config is loaded (they decide what is
#: read: :func:`mission_sim.config.load_config_dict`'s ``mission_keys``, ``--set`` on the command line); laid over a
#: config already loaded, as a study's case values are, they change nothing
FILE_READ_KEYS = ("mission.file", "mission.pads_file", "mission.from_log", "mission.pad_radius_m")
