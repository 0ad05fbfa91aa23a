"""The cache keys a ``dronewpt mission`` computes at start-up (the ahead-of-time loop's,
:func:`mission_sim.world.aot.build_key`; the coupling table's, ``wpt_receiver.coupling._code_key``; a ZOH's,
``wpt_receiver.lti._zoh_key``) read the installed versions of numba, llvmlite, numpy and scipy from their ``.dist-info``
folders: the same strings as ``importlib.metadata`` and ``scipy.__version__`` gave, without importing
``importlib.metadata`` (~15 ms with the email parser) or scipy (~10 ms), which the mission otherwise never loads
(docs/performance.md, "`dronewpt mission` end to end, seventh pass")."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

from mission_sim.world import aot
from wpt_receiver import diskcache

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("package", ["numba", "llvmlite", "numpy", "scipy", "stable-baselines3", "pytest_xdist"])
def test_the_version_is_importlib_metadatas(package):
    assert diskcache.installed_version(package) == metadata.version(package)


def test_the_keys_hold_the_same_version_strings_as_before():
    import scipy

    from wpt_receiver.coupling import _code_key
    for package in ("numba", "llvmlite", "numpy"):
        assert aot._version(package) == f"{package}=={metadata.version(package)}".encode()
    assert _code_key().endswith(f" scipy={scipy.__version__}")
    import numpy as np

    from wpt_receiver.lti import _zoh_key
    assert _zoh_key(np.eye(2), np.ones((2, 1)), 1e-3).endswith(f" scipy={scipy.__version__}")


def test_a_package_without_a_dist_info_folder_falls_back():
    assert diskcache.installed_version("no-such-distribution-dronewpt") is None
    assert aot._version("no-such-distribution-dronewpt") == b"no-such-distribution-dronewpt"


def test_the_first_path_entry_wins_and_names_are_normalised(monkeypatch, tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    (first / "Foo_Bar-1.2.dist-info").mkdir(parents=True)
    (second / "foo_bar-9.9.dist-info").mkdir(parents=True)
    (second / "other-3.0.dist-info").mkdir(parents=True)
    monkeypatch.setattr(sys, "path", [str(tmp_path / "missing"), str(first), str(second)])
    diskcache._dist_info_versions.cache_clear()
    try:
        assert diskcache.installed_version("foo-bar") == "1.2"
        assert diskcache.installed_version("Foo.Bar") == "1.2"
        assert diskcache.installed_version("other") == "3.0"
    finally:
        diskcache._dist_info_versions.cache_clear()


def test_the_keys_import_neither_importlib_metadata_nor_scipy():
    code = ("import sys\nimport numpy as np\nfrom mission_sim.world import aot\n"
            "from wpt_receiver.coupling import _code_key\nfrom wpt_receiver.lti import _zoh_key\n"
            "aot.build_key(); _code_key(); _zoh_key(np.eye(1), np.eye(1), 1.0)\n"
            "print('importlib.metadata' in sys.modules, 'scipy' in sys.modules)\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                          capture_output=True, text=True, timeout=120)
    assert proc.stdout.split() == ["False", "False"], (proc.stdout, proc.stderr)
