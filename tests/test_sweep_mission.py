"""``dronewpt sweep`` with the mission runner: bad studies fail before anything runs (one line).
(The end-to-end run of real missions on two Dask workers is in test_sweep_dask.py.)"""

import pytest

from mission_sim.cli import main


@pytest.mark.parametrize("line, words", [
    ('"mission.hover_tme_s" = [1.0]', ["mission.hover_tme_s", "hover_time_s"]),
    ('policy = ["step", "bang_bang"]', ["bang_bang", "model_based"]),
])
def test_cli_bad_study_for_the_mission_runner_is_one_line_error(tmp_path, capsys, line, words):
    (tmp_path / "s.toml").write_text(f"[grid]\n{line}\n")
    assert main(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert not (tmp_path / "o").exists()
