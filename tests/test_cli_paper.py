import json

from mission_sim.cli import main


def test_paper_json(capsys, tmp_path):
    assert main(["paper", "--format", "json", "--out", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == "envelope"
    rows = {r["trajectory"]: r for r in out["rows"]}
    assert set(rows) == {"step", "ramp", "proposed"}
    for key in ("rm_current_a", "final_current_a", "max_current_a", "overshoot_pct", "settling_time_s"):
        assert all(isinstance(r[key], float) for r in rows.values())
    assert rows["step"]["max_current_a"] > rows["ramp"]["max_current_a"] > rows["proposed"]["max_current_a"]
    assert (tmp_path / "fig6_envelope.png").stat().st_size > 10_000


def test_paper_bad_model_is_one_line_error(capsys):
    assert main(["paper", "--model", "nope", "--no-plot"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope" in err[0] and "envelope" in err[0]
