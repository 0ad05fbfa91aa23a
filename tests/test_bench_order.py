"""``benchmarks/bench_startup.py`` times each ``--link``'s compare commands in rounds of their own: interleaved, each
tree's eq. 4 compare ran right after its own modal one (whose forked child keeps both cores busy to its end), and the
other sessions' jobs held back meanwhile took their turn in the eq. 4 run (docs/performance.md, "seventh pass")."""

from pathlib import Path

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
