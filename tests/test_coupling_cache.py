"""The coupling lookup table's disk cache: built once, reused, rebuilt when stale or corrupt."""

import numpy as np
import pytest

from wpt_receiver import diskcache
from wpt_receiver.coupling import CouplingModel, default_rx_coil, default_tx_coil

GRID = dict(grid_step_m=0.02, rho_max_m=0.6, z_min_m=0.05, z_max_m=0.5)   # small: builds in ms


def _model():
    return CouplingModel(default_tx_coil(), default_rx_coil(), **GRID)


def _table(model):
    model._build_table()
    return model._table[0]


def _forbid_build(monkeypatch):
    """A table build fails the test. (Its field is ``_a_exact`` on the grid, spline-filtered: the filter is the build's
    own step; ``_a_exact`` is not, since ``lm_h`` also takes the exact field for a pose near the pad, 8 grid steps above
    the table's edge: 16 cm on this test's coarse grid.)"""
    from scipy import ndimage

    def fail(*args, **kwargs):
        raise AssertionError("table rebuilt although a valid cache entry exists")
    monkeypatch.setattr(ndimage, "spline_filter", fail)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(diskcache.ENV_VAR, str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_first_use_builds_and_stores_then_reuses_bit_identical(cache, monkeypatch):
    built = _table(_model())
    assert len(list(cache.glob("coupling-*.npy"))) == 1
    _forbid_build(monkeypatch)
    assert np.array_equal(_table(_model()), built)


def test_cached_table_gives_the_same_lm_as_a_fresh_build(cache, monkeypatch):
    monkeypatch.setenv(diskcache.ENV_VAR, "")        # cache off: a fresh build
    fresh = _model().lm_h(0.03, -0.02, 0.17, 0.05)
    monkeypatch.setenv(diskcache.ENV_VAR, str(cache))
    _model().lm_h(0.0, 0.0, 0.17)                     # fills the cache
    _forbid_build(monkeypatch)
    assert _model().lm_h(0.03, -0.02, 0.17, 0.05) == fresh
    assert 0 < fresh < 1e-5


def test_stale_key_rebuilds(cache, monkeypatch):
    _table(_model())
    # a code or library change gives another key: not found, rebuilt under the new key
    monkeypatch.setattr(CouplingModel, "table_key", lambda self: "coupling-table v0 (older code)")
    calls = []
    orig = CouplingModel._a_exact
    monkeypatch.setattr(CouplingModel, "_a_exact", lambda self, r, z: calls.append(1) or orig(self, r, z))
    _table(_model())
    assert calls and len(list(cache.glob("coupling-*.npy"))) == 2


def test_key_text_mismatch_rebuilds(cache, monkeypatch):
    model = _model()
    built = _table(model)
    (key_file,) = cache.glob("coupling-*.key")
    key_file.write_text("something else", "utf-8")       # same file name, other content: stale
    calls = []
    orig = CouplingModel._a_exact
    monkeypatch.setattr(CouplingModel, "_a_exact", lambda self, r, z: calls.append(1) or orig(self, r, z))
    assert np.array_equal(_table(_model()), built)
    assert calls and key_file.read_text("utf-8") == model.table_key()


@pytest.mark.parametrize("damage", ["garbage", "truncated", "nan"])
def test_corrupt_file_rebuilds_and_repairs(cache, monkeypatch, damage):
    built = _table(_model())
    (npy,) = cache.glob("coupling-*.npy")
    if damage == "garbage":
        npy.write_bytes(b"not a numpy file at all")
    elif damage == "truncated":
        npy.write_bytes(npy.read_bytes()[:1000])
    else:
        bad = built.copy()
        bad[3, 4] = np.nan
        np.save(npy, bad)
    assert np.array_equal(_table(_model()), built)     # rebuilt, not the damaged copy
    _forbid_build(monkeypatch)
    assert np.array_equal(_table(_model()), built)     # and the entry was repaired


def test_key_names_geometry_grid_and_code(cache):
    a, b = _model(), CouplingModel(default_tx_coil(), default_rx_coil(), **{**GRID, "grid_step_m": 0.025})
    assert a.table_key() != b.table_key()
    assert "src=" in a.table_key() and "scipy=" in a.table_key()


def test_unwritable_cache_dir_still_works(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv(diskcache.ENV_VAR, str(blocker / "sub"))   # parent is a file: cannot mkdir
    assert _model().lm_h(0.0, 0.0, 0.17) > 0


def test_lm_of_known_poses_comes_from_the_cache_bit_identical_and_old_entries_are_pruned(cache, monkeypatch):
    from wpt_receiver import coupling
    dx = np.linspace(-0.1, 0.1, 7)
    fresh = _model().lm_h(dx, 0.01, 0.17, 0.02)           # computed, stored under the poses' key
    assert len(list(cache.glob("lm_poses-*.npy"))) == 1
    monkeypatch.setattr(CouplingModel, "_lm_poses", lambda self, rot, org: pytest.fail("recomputed"))
    assert np.array_equal(_model().lm_h(dx, 0.01, 0.17, 0.02), fresh)
    monkeypatch.undo()
    monkeypatch.setenv(diskcache.ENV_VAR, str(cache))
    monkeypatch.setattr(coupling, "MEMO_ENTRIES", 3)
    for i in range(5):
        _model().lm_h(0.01 * i, 0.0, 0.17)
    assert len(list(cache.glob("lm_poses-*.npy"))) == 3 and len(list(cache.glob("lm_poses-*.key"))) == 3
    assert not np.array_equal(_model().lm_h(dx + 1e-3, 0.01, 0.17, 0.02), fresh)   # other poses: other key
