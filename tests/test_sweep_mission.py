"""``dronewpt sweep`` with the mission runner: bad studies fail before anything runs (one line).
(The end-to-end run of real missions on two Dask workers is in test_sweep_dask.py.)"""

import pytest

from mission_sim.cli import main


@pytest.mark.parametrize("line, words", [
    ('"mission.hover_tme_s" = [1.0]', ["mission.hover_tme_s", "hover_time_s"]),
    ('policy = ["step", "bang_bang"]', ["bang_bang", "model_based"]),
    # keys read with the base's mission and pads files: every case ran the same mission (a missing file too)
    ('"mission.pads_file" = ["/nonexistent.csv", "b.csv"]',
     ["study key 'mission.pads_file' is invalid", "valid: set it in the [study] base file"]),
    ('"mission.pad_radius_m" = [1.0, 5.0]', ["study key 'mission.pad_radius_m' is invalid"]),
    ('"mission.from_log" = ["auto", "flown"]', ["study key 'mission.from_log' is invalid"]),
    ('"mission.file" = ["a.plan"]', ["study key 'mission.file' is invalid"]),
    # a policy with a parameter: its own error, as --policy gives it
    ('policy = ["model_based_budget:abc"]', ["policy='model_based_budget:abc' is invalid; valid: model_based_budget:B"]),
    ('policy = ["rl:/nonexistent.zip"]', ["RL model file '/nonexistent.zip' does not exist"]),
])
def test_cli_bad_study_for_the_mission_runner_is_one_line_error(tmp_path, capsys, line, words):
    (tmp_path / "s.toml").write_text(f"[grid]\n{line}\n")
    assert main(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert not (tmp_path / "o").exists()


def test_the_documented_study_schema_and_the_example_study_are_valid_for_the_mission_runner(tmp_path):
    import inspect
    import textwrap
    import tomllib
    from pathlib import Path

    import policies
    from mission_sim.studies import study as study_mod
    from mission_sim.studies.study import load_study, parse_study
    from mission_sim.studies.sweep import prepare_study

    doc = inspect.getdoc(study_mod)
    block = textwrap.dedent(doc.split("::\n", 1)[1].split("\n\nKeys may be")[0])
    st = parse_study(tomllib.loads(block.replace('base = "mission.toml"', "")), name="doc")
    _, cases, _ = prepare_study(st, policies.make, policies.available())
    assert len(cases) == 3 * 3 * 2 * 8
    example = Path(__file__).resolve().parents[1] / "examples" / "study_small.toml"
    _, cases, _ = prepare_study(load_study(example), policies.make, policies.available())
    assert len(cases) == 48


def test_a_study_takes_the_policies_with_a_parameter_that_policy_takes():
    """2026-11-27: `policy = ["model_based_budget:0.02"]` was refused ("invalid; valid values: ..., model_based_budget,
    ...") though `--policy model_based_budget:0.02`, compare and the docs take it."""
    import policies
    from mission_sim.studies.study import parse_study
    from mission_sim.studies.sweep import prepare_study
    st = parse_study({"grid": {"policy": ["model_based_budget:0.02", "step"]}})
    _, cases, _ = prepare_study(st, policies.make, policies.available())
    assert sorted(p["policy"] for p in cases.params()) == ["model_based_budget:0.02", "step"]
