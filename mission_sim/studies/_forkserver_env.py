"""Preloaded last by the sweep's forkserver (:data:`mission_sim.studies.cluster.FORKSERVER_PRELOAD`): puts back the
driver's ``PYTHONSAFEPATH`` and ``PYTHONPATH``, which :func:`mission_sim.studies.cluster._driver_path_environ` set only
so that the forkserver imports on the driver's ``sys.path``. Without this every Dask worker inherited them: a study
runner's ``subprocess.run([sys.executable, "helper/script.py"])`` could not ``import`` the script's sibling modules
(safe path) and other Pythons a worker starts got this interpreter's site-packages. The forkserver's own ``sys.path``
was computed at its start and is kept."""

from __future__ import annotations

import json
import os

RESTORE_VAR = "DRONEWPT_FORKSERVER_RESTORE"


def restore_environ() -> None:
    """Pop :data:`RESTORE_VAR` and set the variables it names back to its values (unset where ``null``)."""
    saved = os.environ.pop(RESTORE_VAR, None)
    if saved is None:
        return
    for key, value in json.loads(saved).items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


restore_environ()
