"""The cache keys a ``dronewpt mission`` computes at start-up (the ahead-of-time loop's,
:func:`mission_sim.world.aot.build_key`; the coupling table's, ``wpt_receiver.coupling._code_key``; a ZOH's,
``wpt_receiver.lti._zoh_key``) read the installed versions of numba, llvmlite, numpy and scipy from their ``.dist-info``
folders without importing ``importlib.metadata`` (~15 ms with the email parser) or scipy (~10 ms), which the mission
otherwise never loads (docs/performance.md, "`dronewpt mission` end to end, seventh pass"). They hold the same strings
as ``importlib.metadata`` and ``scipy.__version__`` gave for a distribution installed as one ``.dist-info`` folder in a
plain directory (checked for every installed distribution); where the folder names cannot tell it for sure (two
``.dist-info`` folders in one directory, an ``.egg-info`` folder, an earlier zip file, ``.egg`` folder or source tree
on the path) the keys fall back to what they did before (fake site folders on a patched ``sys.path`` below)."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from importlib import metadata
from pathlib import Path

import pytest

from mission_sim.world import aot
from wpt_receiver import diskcache

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("package", ["numba", "llvmlite", "numpy", "scipy", "stable-baselines3", "pytest_xdist"])
def test_the_version_is_importlib_metadatas(package):
    assert diskcache.installed_version(package) == metadata.version(package)


def test_every_installed_distribution_gets_importlib_metadatas_string_or_none():
    names = {d.metadata["Name"] for d in metadata.distributions()}
    assert len(names) > 20
    differ = {n: (diskcache.installed_version(n), metadata.version(n)) for n in names
              if diskcache.installed_version(n) not in (None, metadata.version(n))}
    assert differ == {}


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


def _dist(folder: Path, child: str, name: str, version: str) -> None:
    """A fake installed distribution: ``folder/child`` with the metadata file importlib.metadata reads."""
    (folder / child).mkdir(parents=True)
    meta = "PKG-INFO" if child.lower().endswith("egg-info") else "METADATA"
    (folder / child / meta).write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n\n")


@pytest.fixture
def fake_path(monkeypatch):
    """Sets ``sys.path`` to the given entries for the folder lookup and importlib.metadata alike."""
    def use(*entries):
        monkeypatch.setattr(sys, "path", [str(e) for e in entries])
        diskcache._dist_info_versions.cache_clear()
    yield use
    diskcache._dist_info_versions.cache_clear()


def _as_before(package: str) -> bytes:
    """The ahead-of-time key's version part as main computed it (importlib.metadata)."""
    return f"{package}=={metadata.version(package)}".encode()


def test_one_dist_info_folder_gives_its_version(fake_path, tmp_path):
    _dist(tmp_path, "Fake_Pkg-0.68.1.dist-info", "fake-pkg", "0.68.1")
    fake_path(tmp_path)
    assert diskcache.installed_version("fake-pkg") == "0.68.1" == metadata.version("fake-pkg")
    assert aot._version("fake-pkg") == _as_before("fake-pkg")


@pytest.mark.parametrize("old, new", [("0.60.0", "0.68.1"), ("1.9", "1.10")])
def test_two_dist_info_folders_in_one_folder_fall_back(fake_path, tmp_path, old, new):
    """``pip install --target T --upgrade`` leaves the old folder beside the new one (pypa/pip#13763)."""
    _dist(tmp_path, f"fakepkg-{old}.dist-info", "fakepkg", old)
    _dist(tmp_path, f"fakepkg-{new}.dist-info", "fakepkg", new)
    fake_path(tmp_path)
    assert diskcache.installed_version("fakepkg") is None
    assert aot._version("fakepkg") == _as_before("fakepkg")


@pytest.mark.parametrize("child", ["fakepkg.egg-info", "fakepkg-2.0-py3.11.egg-info", "FakePkg-2.0.EGG-INFO"])
def test_an_egg_info_folder_earlier_on_the_path_falls_back(fake_path, tmp_path, child):
    first, second = tmp_path / "a", tmp_path / "b"
    _dist(first, child, "fakepkg", "2.0")
    _dist(second, "fakepkg-1.0.dist-info", "fakepkg", "1.0")
    fake_path(first, second)
    assert diskcache.installed_version("fakepkg") is None
    assert aot._version("fakepkg") == _as_before("fakepkg") == b"fakepkg==2.0"


def test_an_egg_folder_or_zip_file_earlier_on_the_path_falls_back(fake_path, tmp_path):
    egg, later = tmp_path / "fakepkg-3.0-py3.11.egg", tmp_path / "site"
    _dist(egg, "EGG-INFO", "fakepkg", "3.0")
    _dist(later, "fakepkg-1.0.dist-info", "fakepkg", "1.0")
    _dist(later, "otherpkg-1.0.dist-info", "otherpkg", "1.0")
    fake_path(egg, later)
    assert diskcache.installed_version("fakepkg") is None
    assert diskcache.installed_version("otherpkg") is None
    assert aot._version("fakepkg") == _as_before("fakepkg")
    zipped = tmp_path / "dists.zip"
    with zipfile.ZipFile(zipped, "w") as zf:
        zf.writestr("fakepkg-5.0.dist-info/METADATA", "Metadata-Version: 2.1\nName: fakepkg\nVersion: 5.0\n\n")
    fake_path(zipped, later)
    assert diskcache.installed_version("fakepkg") is None
    assert aot._version("fakepkg") == _as_before("fakepkg") == b"fakepkg==5.0"


def test_a_source_tree_shadowing_an_installed_copy_falls_back_to_its_version(fake_path, tmp_path):
    """A source build of the package on ``PYTHONPATH`` (no metadata) ahead of an installed copy: the key takes the
    imported package's ``__version__``, as ``scipy.__version__`` did."""
    src, site = tmp_path / "src", tmp_path / "site"
    (src / "fakesci").mkdir(parents=True)
    (src / "fakesci" / "__init__.py").write_text('__version__ = "1.17.0.dev0+git"\n')
    _dist(site, "fakesci-1.14.1.dist-info", "fakesci", "1.14.1")
    fake_path(src, site)
    assert "fakesci" not in sys.modules
    try:
        assert diskcache.installed_version("fakesci") is None
        assert diskcache.package_version("fakesci") == "1.17.0.dev0+git"
    finally:
        sys.modules.pop("fakesci", None)


def test_an_imported_package_gives_its_own_version(fake_path, tmp_path, monkeypatch):
    _dist(tmp_path, "fakesci-1.14.1.dist-info", "fakesci", "1.14.1")
    fake_path(tmp_path)
    monkeypatch.setitem(sys.modules, "fakesci", type(sys)("fakesci"))
    sys.modules["fakesci"].__version__ = "1.15.0"
    assert diskcache.package_version("fakesci") == "1.15.0"
