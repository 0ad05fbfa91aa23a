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


@pytest.mark.parametrize("content", [b"not a zip", "cut", "no members"])
def test_a_corrupt_rl_model_zip_is_one_line_for_mission_compare_and_sweep(tmp_path, capsys, monkeypatch, content):
    """2026-11-27: `policy = ["rl:bad.zip"]` (a valid bad.json beside a file that is not a zip) gave
    zipfile.BadZipFile with a traceback, exit 1, in sweep, mission --policy and compare alike."""
    import shutil
    import zipfile
    import policies
    from policies.shipped import default_model
    shipped = default_model("rl")
    bad = tmp_path / "bad.zip"
    if content == "cut":
        bad.write_bytes(shipped.read_bytes()[:3000])
    elif content == "no members":
        with zipfile.ZipFile(bad, "w") as z:
            z.writestr("x", "y")
    else:
        bad.write_bytes(content)
    shutil.copy(shipped.with_suffix(".json"), tmp_path / "bad.json")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text('[grid]\npolicy = ["rl:bad.zip"]\n')
    for argv in (["sweep", "s.toml", "--out", "o"], ["mission", "--policy", "rl:bad.zip", "--out", "o"],
                 ["compare", "--policies", "rl:bad.zip", "--episodes", "1", "--scenarios", "nominal", "--no-plot",
                  "--no-frontier", "--no-progress"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "RL model 'bad.zip' is not a readable stable-baselines3 model zip" in err[0], err
    assert not (tmp_path / "o").exists()
    with pytest.raises(ValueError, match="is not a readable stable-baselines3 model zip"):
        policies.make(f"rl:{bad}")


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_an_unreadable_rl_model_zip_is_said_once_not_nested(tmp_path, algo):
    """2026-11-27 mend: a bad zip whose JSON says sac went through the model property (which words the error)
    and then __init__'s except, which worded it again: "is not a readable ... zip (RL model ... is not a
    readable ... zip (...); valid ...); valid ..."."""
    import json

    from policies.rl import RLPolicy
    bad = tmp_path / "bad.zip"
    bad.write_bytes(b"not a zip")
    (tmp_path / "bad.json").write_text(json.dumps({"algo": algo, "control_period_s": 0.0001}))
    with pytest.raises(ValueError) as exc:
        RLPolicy(path=bad)
    msg = str(exc.value)
    assert msg.count("is not a readable") == 1 and msg.count("valid: a model zip") == 1, msg
    assert msg.startswith(f"RL model {str(bad)!r} is not a readable stable-baselines3 model zip ("), msg


def test_a_study_case_with_a_parameterised_policy_flies_what_mission_policy_flies(tmp_path, capsys):
    """A study's `policy = ["model_based_budget:0.02"]` (e6d2280) runs the same mission as
    `dronewpt mission --policy model_based_budget:0.02` and run_mission with policies.make of the spec: the same
    summary numbers, bit for bit; model_based's differ (the budget is not dropped on the way)."""
    import json

    import policies
    from mission_sim.config import apply_overrides, config_from_dict, load_config_dict, policy_context
    from mission_sim.studies.store import read_results
    from mission_sim.world.runner import run_mission

    sets = {"pads.0.hover_time_s": 5.0, "pads.1.hover_time_s": 5.0, "pads.1.x_m": 20.0}   # ~56 s of flight
    fixed = "".join(f'"{k}" = {v}\n' for k, v in sets.items())
    (tmp_path / "s.toml").write_text(f'[fixed]\n{fixed}[grid]\npolicy = ["model_based_budget:0.02", "model_based"]\n')
    assert main(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "o"), "--workers", "0"]) == 0
    rows = read_results(tmp_path / "o").set_index("policy")
    capsys.readouterr()
    assert main(["mission", "--policy", "model_based_budget:0.02", "--no-plot", "--format", "json", "--no-progress",
                 "--out", str(tmp_path / "m"), *[x for k, v in sets.items() for x in ("--set", f"{k}={v}")]]) == 0
    cli = json.loads(capsys.readouterr().out)
    cfg = config_from_dict(apply_overrides(load_config_dict(), sets))
    api = run_mission(cfg, policies.make("model_based_budget:0.02", policy_context(cfg)), frame=False).summary
    for key in ("final_soc", "battery_charge_in_j", "energy_from_source_j", "peak_i2_a"):
        assert rows.loc["model_based_budget:0.02", key] == cli[key] == api[key], key
    assert rows.loc["model_based", "battery_charge_in_j"] != cli["battery_charge_in_j"]
