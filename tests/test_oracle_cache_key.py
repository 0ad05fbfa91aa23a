"""The oracle's disk-cache key covers the env's physics: a bound computed by other env / link sources
(the detuned windows' blocking fix changed ``envs/vector_kernel.py`` and ``envs/detuned.py``) is computed
again, never read back stale (``policies.oracle._source_hash``)."""

import shutil

import numpy as np

from policies import oracle


def test_the_key_covers_the_sources_of_the_rollouts_step():
    names = {(f.parent.name, f.name) for f in oracle._rollout_files()}
    for need in [("envs", "vector_kernel.py"), ("envs", "duty_sine.py"), ("envs", "detuned.py"), ("envs", "modal_step.py"), ("envs", "core.py"),
                 ("envs", "layout.py"), ("envs", "rollout.py"), ("wpt_receiver", "modal_kernel.py"),
                 ("wpt_receiver", "sbar.py"), ("wpt_receiver", "inverse_controller.py"), ("wpt_receiver", "parts.toml")]:
        assert need in names
    assert all(f.is_file() for f in oracle._rollout_files())


def test_changing_one_env_source_changes_the_key(tmp_path, monkeypatch):
    copies = []
    for f in oracle._rollout_files():
        (tmp_path / f.parent.name).mkdir(exist_ok=True)
        copies.append(tmp_path / f.parent.name / f.name)
        shutil.copy(f, copies[-1])
    before = oracle._source_hash()
    monkeypatch.setattr(oracle, "_rollout_files", lambda: copies)
    assert oracle._source_hash() == before          # the same bytes: the same key
    detuned = tmp_path / "envs" / "detuned.py"
    detuned.write_text(detuned.read_text() + "\n# another blocking rule\n")
    assert oracle._source_hash() != before


def test_a_cached_bound_is_recomputed_when_the_env_sources_change(tmp_path, monkeypatch):
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path / "cache"))
    calls = []

    def compute():
        calls.append(1)
        return oracle.OracleResult(1.5, 0.01, True, True, np.linspace(0.0, 1.0, 300))

    args = ("floor", "nominal", 1000, 0.01, oracle.DEFAULT_STARTS, None, compute)
    r1, r2 = oracle._cached(*args), oracle._cached(*args)
    assert len(calls) == 1 and r1.energy_after_stop_j == r2.energy_after_stop_j == 1.5   # the second from disk
    src = tmp_path / "vector_kernel.py"
    src.write_text("# other physics\n")
    monkeypatch.setattr(oracle, "_rollout_files", lambda: [src])
    oracle._cached(*args)
    assert len(calls) == 2
    np.testing.assert_array_equal(r2.duties, np.linspace(0.0, 1.0, 300))


def test_the_key_covers_the_base_policys_sources(tmp_path, monkeypatch):
    """A floor's base policy sets the state at the stop: its modules are in the key (the MPC's: mpc.py and the
    modal model's mpc_modal.py), and a change of one changes the key of a base-"mpc" bound only."""
    names = {f.name for f in oracle._policy_files(("mpc",))}
    assert {"mpc.py", "mpc_modal.py", "classical.py"} <= names
    assert "budgeted.py" in {f.name for f in oracle._policy_files(oracle.DEFAULT_STARTS)}
    copies = []
    for f in oracle._policy_files(("mpc",)):
        copies.append(tmp_path / f.name)
        shutil.copy(f, copies[-1])
    before, other = oracle._source_hash(("mpc",)), oracle._source_hash(("model_based",))
    real = oracle._policy_files
    monkeypatch.setattr(oracle, "_policy_files", lambda names: tuple(copies) if names == ("mpc",) else real(names))
    assert oracle._source_hash(("mpc",)) == before
    (tmp_path / "mpc_modal.py").write_text((tmp_path / "mpc_modal.py").read_text() + "\n# another model\n")
    assert oracle._source_hash(("mpc",)) != before
    assert oracle._source_hash(("model_based",)) == other


def test_the_two_links_bounds_never_mix_whichever_is_the_default(tmp_path, monkeypatch):
    """The key holds ``repr(config)``, which always names ``link_model`` (issue 23 swapped the envs' default from
    eq. 4's envelope to the exact-mode link on 2026-11-26: a key that left the default out would have read an eq. 4
    bound cached under the old default as a modal one). A bound cached on one link is computed again on the other;
    the default config (None) and the explicit modal config share theirs."""
    from envs import EnvConfig
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(tmp_path / "cache"))
    calls = []

    def compute(value):
        def run():
            calls.append(value)
            return oracle.OracleResult(value, 0.01, True, True, np.full(300, value))
        return run

    eq4, modal = EnvConfig(link_model="envelope"), EnvConfig(link_model="modal")
    assert "link_model='envelope'" in repr(eq4) and "link_model='modal'" in repr(modal) == repr(EnvConfig())

    def cached(cfg, value):
        return oracle._cached("floor", "nominal", 1000, 0.0, ("model_based",), cfg, compute(value))

    assert cached(eq4, 1.0).energy_after_stop_j == 1.0
    assert cached(modal, 2.0).energy_after_stop_j == 2.0     # not eq. 4's bound
    assert cached(None, 3.0).energy_after_stop_j == 2.0      # the default is the modal link: its bound, from disk
    assert cached(eq4, 4.0).energy_after_stop_j == 1.0       # eq. 4's, from disk
    assert calls == [1.0, 2.0]
