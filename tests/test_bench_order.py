"""``benchmarks/bench_startup.py`` times each ``--link``'s compare commands in rounds of their own: interleaved, each
tree's eq. 4 compare ran right after its own modal one (whose forked child keeps both cores busy to its end), and the
other sessions' jobs held back meanwhile took their turn in the eq. 4 run (docs/performance.md, "seventh pass")."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_each_link_is_timed_in_its_own_rounds_and_every_tree_alternates(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_startup

    order = []

    def fake_run(argv, env):
        link = argv[argv.index("--link") + 1] if "--link" in argv else "-"
        order.append((link, env["PYTHONPATH"]))
        return 1.0, 1.0, "same"

    monkeypatch.setattr(bench_startup, "_run", fake_run)
    r = bench_startup.end_to_end(repeat=3, compare="default", before=tmp_path, links=("modal", "envelope"),
                                 compare_only=True)
    timed = order[5:]   # after the warm-up round (python -c pass, and the two links' compare on both trees)
    links = [link for link, _ in timed if link != "-"]
    assert links == ["modal"] * 6 + ["envelope"] * 6            # no eq. 4 run right after a modal one
    trees = [tree for link, tree in timed if link == "envelope"]
    assert trees == [str(ROOT), str(tmp_path.resolve())] * 3      # the two trees alternate within a link's rounds
    assert r["dronewpt compare (default, --link envelope)"]["n"] == 3
    assert r["dronewpt compare (default, --link envelope)"]["same_table_as_before"] is True


def test_the_before_tree_has_its_own_cache_folder_and_both_trees_are_warmed_before_timing(monkeypatch, tmp_path):
    """``dronewpt warmup`` removes other sources' ahead-of-time mission modules from its cache folder: two trees
    sharing one would not both run without numba. Each tree gets its own ``DRONEWPT_CACHE_DIR`` and its warmup (with
    that folder and its own ``PYTHONPATH``) runs before the first timed command."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_startup

    events = []

    def fake_run(argv, env):
        events.append(("run", env["PYTHONPATH"], env.get("DRONEWPT_CACHE_DIR")))
        return 1.0, 1.0, "same"

    def fake_warm(env):
        events.append(("warmup", env["PYTHONPATH"], env.get("DRONEWPT_CACHE_DIR")))
        return 2.0

    monkeypatch.setattr(bench_startup, "_run", fake_run)
    monkeypatch.setattr(bench_startup, "_warm", fake_warm)
    own = tmp_path / "own-cache"
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", str(own))
    peer = tmp_path / "peer"
    peer.mkdir()
    r = bench_startup.end_to_end(repeat=2, compare="none", before=peer, mission_only=True, warm=True)
    assert [e[0] for e in events[:2]] == ["warmup", "warmup"] and all(e[0] == "run" for e in events[2:])
    caches = {tree: cache for _, tree, cache in events}
    assert caches == {str(ROOT): str(own), str(peer.resolve()): str(bench_startup.tree_cache_dir(peer))}
    assert len(set(caches.values())) == 2
    assert {(tree, cache) for _, tree, cache in events[2:]} == {(t, c) for _, t, c in events[:2]}  # runs as warmed
    assert r["caches"] == caches and set(r["warmed"]) == set(caches)
    # a --before-cache equal to the measured tree's folder is refused
    import pytest
    with pytest.raises(SystemExit, match="--before-cache"):
        bench_startup.end_to_end(repeat=1, compare="none", before=peer, mission_only=True, before_cache=own)


def test_without_a_cache_variable_the_measured_tree_gets_its_own_folder_too(monkeypatch, tmp_path):
    """No ``DRONEWPT_CACHE_DIR``: the measured tree's warmup does not go to the user's shared default folder (where it
    would remove other trees' ahead-of-time modules) but to a folder of its own, as the ``--before`` tree's."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_startup

    seen = {}
    monkeypatch.setattr(bench_startup, "_run", lambda argv, env: (1.0, 1.0, "same"))
    monkeypatch.setattr(bench_startup, "_warm",
                        lambda env: seen.setdefault(env["PYTHONPATH"], env["DRONEWPT_CACHE_DIR"]) and 0.0)
    monkeypatch.delenv("DRONEWPT_CACHE_DIR", raising=False)
    peer = tmp_path / "peer"
    peer.mkdir()
    bench_startup.end_to_end(repeat=1, compare="none", before=peer, mission_only=True, warm=True)
    assert seen == {str(ROOT): str(bench_startup.tree_cache_dir(ROOT)),
                    str(peer.resolve()): str(bench_startup.tree_cache_dir(peer))}
    assert seen[str(ROOT)] != seen[str(peer.resolve())]


class _Reached(Exception):
    pass


def test_the_no_mpc_compare_command_is_accepted_with_one_row_per_label(monkeypatch, tmp_path):
    """The default ``--compare no-mpc`` command listed ``rl`` in ``--policies`` and as ``--train-seeds rl=...``:
    two ``rl`` rows before, exit 2 since compare refuses a seed-group label that is also a listed policy."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_startup
    import policies.compare as pc
    from mission_sim.cli import main
    from policies.compare import shipped_seed_groups

    argv = bench_startup._commands(str(tmp_path), "no-mpc")["dronewpt compare (no-mpc)"]
    seen = {}

    def fake_compare(pols, scns, *a, train_seeds=None, **k):   # reached only when the options were accepted
        seen.update(pols=tuple(pols), groups=dict(train_seeds or {}))
        raise _Reached

    monkeypatch.setattr(pc, "compare", fake_compare)
    with pytest.raises(_Reached):
        main(argv[argv.index("compare"):])
    labels = list(seen["pols"]) + list(seen["groups"])
    assert len(labels) == len(set(labels))
    assert set(seen["groups"]) == set(shipped_seed_groups())
    assert set(seen["pols"]) == set(bench_startup.NO_MPC.split(",")) - set(shipped_seed_groups())


def test_with_the_cache_off_both_trees_run_without_it(monkeypatch, tmp_path):
    """``DRONEWPT_CACHE_DIR=`` (empty: the cache off) holds for the ``--before`` tree too: neither tree gets a cache
    folder or warms one; a ``--before-cache`` then is refused with one line."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import bench_startup
    import pytest

    seen = []
    def note(kind, env):
        seen.append((kind, env["PYTHONPATH"], env["DRONEWPT_CACHE_DIR"]))

    monkeypatch.setattr(bench_startup, "_run", lambda argv, env: note("run", env) or (1.0, 1.0, "s"))
    monkeypatch.setattr(bench_startup, "_warm", lambda env: note("warmup", env) or 0.0)
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", "")
    peer = tmp_path / "peer"
    peer.mkdir()
    r = bench_startup.end_to_end(repeat=1, compare="none", before=peer, mission_only=True, warm=True)
    assert {tree for _, tree, _ in seen} == {str(ROOT), str(peer.resolve())}
    assert {cache for _, _, cache in seen} == {""}
    assert r["caches"] == {str(ROOT): "", str(peer.resolve()): ""}
    with pytest.raises(SystemExit, match="--before-cache .* empty"):
        bench_startup.end_to_end(repeat=1, compare="none", before=peer, mission_only=True,
                                 before_cache=tmp_path / "c")
