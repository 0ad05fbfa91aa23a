"""An installed (not editable) copy keeps numba's cache out of ``site-packages``
(:func:`wpt_receiver.kernel_cache.place_numba_cache`).

Before, ``pip install .`` then ``dronewpt mission`` wrote numba's cache files into the installed package folders; a
later ``pip install -e .`` in the same venv (the README's second quickstart line) removed only the files pip had
installed, and the folders left with the caches alone shadowed the editable install as namespace packages: every
command ended in ``ImportError: ... (unknown location)``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

import wpt_receiver

_PROBE = '''
from numba import njit


@njit(cache=True)
def twice(x):
    return 2.0 * x
'''


def _installed_copy(tmp_path: Path, folder: str = "site-packages") -> Path:
    """A copy of wpt_receiver in ``tmp_path/<folder>`` (as pip installs it) with a tiny cached kernel."""
    site = tmp_path / folder
    shutil.copytree(Path(wpt_receiver.__file__).parent, site / "wpt_receiver",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (site / "wpt_receiver" / "_probe.py").write_text(_PROBE)
    return site


def _run(site: Path, code: str, **env) -> str:
    full = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    full.update(PYTHONPATH=str(site), **env)
    out = subprocess.run([sys.executable, "-c", code], env=full, cwd=site.parent, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def _cache_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.suffix in (".nbi", ".nbc"))


@pytest.mark.parametrize("folder", ["site-packages", "dist-packages"])
def test_installed_copy_caches_in_dronewpt_cache(tmp_path, folder):
    site = _installed_copy(tmp_path, folder)
    cache = tmp_path / "cache"
    code = ("import wpt_receiver, os; from wpt_receiver._probe import twice; assert twice(2.0) == 4.0; "
            "print(os.environ['NUMBA_CACHE_DIR'])")
    assert _run(site, code, DRONEWPT_CACHE_DIR=str(cache)) == str(cache / "numba")
    assert _cache_files(site) == []                       # nothing of numba's beside the installed sources
    files = _cache_files(cache / "numba")
    assert any(f.name.startswith("_probe.twice") for f in files), files
    # a second process loads it from there (no second index)
    assert _run(site, code, DRONEWPT_CACHE_DIR=str(cache)) == str(cache / "numba")
    assert _cache_files(cache / "numba") == files


def test_numba_imported_first_follows_too(tmp_path):
    site = _installed_copy(tmp_path)
    cache = tmp_path / "cache"
    code = ("import numba; from numba.core import config; import wpt_receiver; "
            "from wpt_receiver._probe import twice; twice(1.0); print(config.CACHE_DIR)")
    assert _run(site, code, DRONEWPT_CACHE_DIR=str(cache)) == str(cache / "numba")
    assert _cache_files(site) == []


def test_users_numba_cache_dir_and_checkouts_are_left_alone(tmp_path):
    site = _installed_copy(tmp_path)
    mine = tmp_path / "mine"
    code = "import wpt_receiver, os; print(os.environ.get('NUMBA_CACHE_DIR', '-'))"
    assert _run(site, code, NUMBA_CACHE_DIR=str(mine), DRONEWPT_CACHE_DIR=str(tmp_path / "c")) == str(mine)
    assert _run(site, code, DRONEWPT_CACHE_DIR="") == "-"          # the disk cache off: numba as it is
    checkout = _installed_copy(tmp_path / "repo", "dronewpt")       # a checkout / editable tree: in-tree caches
    probe = code + "; from wpt_receiver._probe import twice; twice(1.0)"
    assert _run(checkout, probe, DRONEWPT_CACHE_DIR=str(tmp_path / "c")) == "-"
    assert any(f.name.startswith("_probe.twice") for f in _cache_files(checkout / "wpt_receiver" / "__pycache__"))


def test_unusable_or_relative_cache_folder_never_falls_back_into_site_packages(tmp_path):
    """A cache folder numba cannot write (here under a file) would make numba fall back to ``__pycache__`` beside
    the installed sources: a private temporary folder is used instead; a relative one is made absolute (workers
    started in another folder, as the ahead-of-time build's child, find the same cache)."""
    site = _installed_copy(tmp_path)
    (tmp_path / "afile").write_text("")
    code = ("import wpt_receiver, os; from wpt_receiver._probe import twice; twice(1.0); "
            "print(os.environ['NUMBA_CACHE_DIR'])")
    got = Path(_run(site, code, DRONEWPT_CACHE_DIR=str(tmp_path / "afile" / "cache")))
    assert got.is_absolute() and "dronewpt-numba-" in got.name and got.parent == Path(tempfile.gettempdir())
    assert _cache_files(site) == []
    assert _run(site, code, DRONEWPT_CACHE_DIR="relcache") == str(tmp_path / "relcache" / "numba")
    assert _cache_files(site) == []


def test_private_temporary_folder_is_never_one_others_can_write(tmp_path, monkeypatch):
    """numba's cache files hold pickles: the shared temporary fallback is used only when it is this user's alone
    (not group/world-writable, not a symlink); otherwise a fresh folder of this process's."""
    from wpt_receiver import kernel_cache

    monkeypatch.setattr(tempfile, "gettempdir", lambda: str(tmp_path))
    shared = tmp_path / f"dronewpt-numba-{os.getuid()}"
    assert kernel_cache._private_temporary() == shared and oct(shared.stat().st_mode & 0o777) == oct(0o700)
    shared.chmod(0o777)                                   # as if another user had made it writable for all
    other = kernel_cache._private_temporary()
    assert other is not None and other != shared and other.parent == tmp_path and other.name.startswith("dronewpt-numba-")
    shared.chmod(0o700)
    shared.rmdir()
    shared.symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    (tmp_path / "elsewhere").mkdir()
    assert kernel_cache._private_temporary() not in (shared, tmp_path / "elsewhere")
