"""A demanding newcomer's afternoon (2026-11-27): an RL researcher (README, docs/rl.md, docs/envs.md) and a MAVLink
integrator (docs/mavlink.md); docs/robustness.md, "A newcomer's afternoon (2026-11-27)". 51 of the first 53 tests fail
on ``main`` (875a414); the other 2 guard what worked. The review's mend (the last section) added 18: 11 failed on the
branch before it (a port '--5' / '²' / '٣', calibrate's mass range from Python and --mass 0, compare's one table of
episodes and seeds), 7 guard (numpy integers, --follow-time's value, a negative port).

Probes fixed here:

* ``compare --policies rl:M.zip`` whose ``M.json`` is broken JSON (json's message without the file), a JSON list
  (``AttributeError`` traceback), has ``control_period_s`` -1 / "x" / missing (an inverted message, "could not
  convert string to float", ``KeyError``), or says another algorithm than the zip's (SB3's ``AttributeError``).
* ``compare --policies oracle_imitation:nothere.npz`` ("RL model file ... does not exist"), ``rl:FIFO`` ("does not
  exist").
* ``policies.compare.run_policy(name, scenario, 0, seed)`` ("num_envs=0 is invalid"), episodes 1.5 and seed 1.5
  (truncated, silently), seed -1 (gymnasium's error); ``compare(policies="step")`` / ``scenarios="nominal"``
  (iterated letter by letter: "policy='s' is invalid").
* ``policies.train.train(..., seed=1.5)`` (seed 1), ``eval_episodes=0`` ("num_envs=0"), ``eval_every=0``,
  ``checkpoint_every=-1``, ``lambda_lr=0`` (trained, where ``dronewpt train`` refuses each).
* ``train --algo dqn --action-filter 0.5``: trained, wrote part of its outputs, then failed on the env's message.
* ``compare --no-plot --out DIR`` (nothing written, nothing said); ``compare --policies step --no-frontier``
  (matplotlib's "No artists with labels found to put in legend" on stderr).
* ``compare --train-seeds x=residual:M.zip,residual:./M.zip``: one model as "2 seeds", a zero-width interval.
* ``train --hyperparams hp.yml`` with ``learning_rate: 1e-4`` ("valid type: number": PyYAML reads a string).
* ``register_scenario(Scenario("nominal", soc=(0.1, 0.2)))``: the built-in "nominal" replaced for the process.
* ``SbarSB3VecEnv(reset_seed=1.5)`` (seed 1, silently), ``reset_seed=-1`` (gymnasium's error at the first reset).
* ``SbarChargingVectorEnv.restart([1.5])`` (restarted window 1, silently), ``restart([True, False, True])`` (a mask
  read as indices 1, 0, 1: "indices [1] are invalid"); ``SbarChargingVectorEnv(num_threads="a")`` (int()'s message).
* ``telemetry --follow-time`` / ``--follow-idle`` without ``--follow`` (no effect, exit 0), ``--duration`` /
  ``--speed`` with ``--follow`` (ignored); ``--connect udpout:127.0.0.1:99999`` (port 0, 70000: "valid format ..."
  naming no port range).
* ``calibrate LOG --mass 5000``: fitted, and wrote a ``[drone]`` TOML that ``mission --drone`` refuses.
* ``replay`` / ``calibrate`` of an empty file, a text file, a ULog cut before its first record: "0 usable position
  sample(s), need at least 2" / "the log has no battery data", nothing said of what the file was.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from _cli_helpers import fake_follow
from _cli_helpers import one_error_line as _one_error_line
from mission_sim.cli import main

ROOT = Path(__file__).resolve().parents[1]
LOGS = ROOT / "tests" / "data" / "flightlogs"


# ------------------------------------------------------------------ an RL model's metadata JSON
@pytest.fixture
def model_zip(tmp_path):
    """A copy of the shipped PPO ``rl_s0.zip`` without its JSON (each test writes its own)."""
    z = tmp_path / "mine.zip"
    from policies.shipped import default_model
    shutil.copy(default_model("rl"), z)
    return z


@pytest.mark.parametrize("meta, text", [
    ("{", "RL model metadata '{json}' is not valid JSON (Expecting property name enclosed in double quotes: line 1 "
          "column 2 (char 1)); valid: a JSON object such as {\"algo\": \"ppo\", \"control_period_s\": 0.0001}"),
    ("[]", "RL model metadata '{json}' holds a JSON list; valid: a JSON object"),
    ('{"algo": "ppo", "control_period_s": -1}',
     "control_period_s=-1 in {json} is invalid; valid range: [1e-07, 0.01] s (the control period it was trained at"),
    ('{"algo": "ppo", "control_period_s": "x"}', "control_period_s='x' in {json} is invalid; valid range: [1e-07, 0.01] s"),
    ('{"algo": "ppo"}', "control_period_s=None in {json} is invalid; valid range: [1e-07, 0.01] s"),
    ('{"algo": "dqn", "control_period_s": 0.0001}',
     "RL model '{zip}' cannot be loaded as algo='dqn' (what mine.json says: AttributeError"),
])
def test_rl_model_metadata_is_checked(capsys, model_zip, meta, text):
    meta_path = model_zip.with_suffix(".json")
    meta_path.write_text(meta)
    line = _one_error_line(capsys, ["compare", "--policies", f"rl:{model_zip}", "--episodes", "1",
                                    "--scenarios", "nominal", "--no-plot", "--no-frontier"])
    assert text.replace("{json}", str(meta_path)).replace("{zip}", str(model_zip)) in line, line


@pytest.mark.parametrize("kind, what", [("oracle_imitation", "oracle imitation model file"),
                                        ("oracle_imitation_filtered", "oracle imitation model file"),
                                        ("rl", "RL model file")])
def test_a_policy_file_is_named_by_its_kind_and_a_fifo_is_not_a_missing_file(capsys, tmp_path, kind, what):
    """``oracle_imitation:nothere.npz`` said "RL model file 'nothere.npz' does not exist"; a FIFO said it does not
    exist either (it does: not a regular file)."""
    import os
    missing = tmp_path / "nothere.npz"
    argv = ["compare", "--episodes", "1", "--scenarios", "nominal", "--no-plot", "--no-frontier", "--policies"]
    assert _one_error_line(capsys, argv + [f"{kind}:{missing}"]) == (
        f"dronewpt compare: error: {what} '{missing}' does not exist")
    fifo = tmp_path / "pipe.zip"
    os.mkfifo(fifo)
    assert _one_error_line(capsys, argv + [f"{kind}:{fifo}"]).startswith(
        f"dronewpt compare: error: {what} '{fifo}' is a FIFO (named pipe); valid: a model ")


def test_rl_model_with_good_metadata_still_runs(model_zip):
    """The same zip with the JSON docs/rl.md asks for acts as the shipped model on its normalisation-free input."""
    import policies
    model_zip.with_suffix(".json").write_text('{"algo": "ppo", "control_period_s": 0.0001}')
    pol = policies.make(f"rl:{model_zip}")
    pol.reset(1)
    d = pol.act(np.zeros((1, 8), np.float32))
    assert d.shape == (1,) and 0.0 <= d[0] <= 1.0


# ------------------------------------------------------------------ run_policy / compare from Python
@pytest.mark.parametrize("episodes, seed, text", [
    (0, 1000, "episodes=0 is invalid; valid range: integer 1..100000"),
    (1.5, 1000, "episodes=1.5 is invalid; valid range: integer 1..100000"),
    (2, 1.5, "seed=1.5 is invalid; valid range: integer 0..4294967294 (episode seeds go up to seed + episodes - 1, "
             "episodes=2)"),
    (2, -1, "seed=-1 is invalid; valid range: integer 0..4294967294 (episode seeds go up to seed + episodes - 1, "
            "episodes=2)"),
    (1, 2**32, "seed=4294967296 is invalid; valid range: integer 0..4294967295"),
])
def test_run_policy_checks_episodes_and_seed(episodes, seed, text):
    from policies.compare import run_policy
    with pytest.raises(ValueError) as exc:
        run_policy("step", "nominal", episodes, seed)
    assert str(exc.value) == text


def test_compare_takes_a_comma_separated_string_as_the_cli_does():
    from policies.compare import compare, run_policies
    rows, _ = compare(policies="step,ramp", scenarios="nominal", episodes=2, progress=False)
    listed, _ = compare(policies=["step", "ramp"], scenarios=["nominal"], episodes=2, progress=False)
    assert [(r["scenario"], r["policy"]) for r in rows] == [("nominal", "step"), ("nominal", "ramp")]
    assert [r["return"] for r in rows] == [r["return"] for r in listed]
    assert list(run_policies("step", "nominal", 1, 1000)) == ["step"]
    with pytest.raises(ValueError, match=r"^policies=5 is invalid; valid: a list of names, or one comma-separated"):
        compare(policies=5, scenarios="nominal", episodes=1)


@pytest.mark.parametrize("kw, text", [
    ({"seed": 1.5}, "seed=1.5 is invalid; valid range: integer 0..4294967295"),   # ran seed 1
    ({"seed": -1}, "seed=-1 is invalid; valid range: integer 0..4294967295"),    # numpy's "Seed must be between ..."
    ({"eval_episodes": 0}, "eval_episodes=0 is invalid; valid range: integer >= 1"),   # "num_envs=0 is invalid"
    ({"eval_every": 0}, "eval_every=0 is invalid; valid range: integer >= 1"),         # trained, exit 0
    ({"checkpoint_every": -1}, "checkpoint_every=-1 is invalid; valid range: integer >= 1"),
    ({"lagrangian": True, "budget": 0.1, "lambda_lr": 0.0}, "lambda_lr=0.0 is invalid; valid range: (0, inf)"),
])
def test_train_from_python_checks_as_the_cli_does(tmp_path, kw, text):
    """``policies.train.train`` refuses what ``dronewpt train`` refuses, before anything is written."""
    from policies.train import train
    with pytest.raises(ValueError) as exc:
        train("ppo", 64, tmp_path / "run", progress=False, n_envs=4, env={"link_model": "envelope"}, **kw)
    assert str(exc.value) == text
    assert not (tmp_path / "run").exists()


def test_dqn_with_an_action_filter_is_refused_before_training(capsys, tmp_path):
    """``train --algo dqn --action-filter 0.5`` built the run, wrote checkpoints/, eval/ and the monitor CSV, then
    stopped at the env's "actions=0.13... is invalid; valid values: 0 (RM), 1 (SM)" (naming no option)."""
    out = tmp_path / "run"
    line = _one_error_line(capsys, ["train", "--algo", "dqn", "--action-filter", "0.5", "--timesteps", "256",
                                    "--n-envs", "4", "--link", "envelope", "--no-progress", "--out", str(out)])
    assert line == ("dronewpt train: error: --algo dqn is invalid with --action-filter 0.5; valid: --algo ppo, sac or "
                    "td3 (a low-passed duty is not 0 or 1), or drop --action-filter")
    assert not out.exists()   # (the review: an empty --out folder was left, and the message said algo='dqn')
    from policies.train import train   # Python callers: the library's own check, the same rule
    with pytest.raises(ValueError) as exc:
        train("dqn", 64, tmp_path / "py", progress=False, n_envs=4, env={"link_model": "envelope"}, action_filter=0.5)
    assert str(exc.value) == ("algo='dqn' is invalid with action_filter=0.5; valid values: ppo, sac, td3 (a low-passed "
                              "duty is not 0 or 1)")
    assert not (tmp_path / "py").exists()


@pytest.mark.parametrize("argv, line, kw, text", [
    (["--algo", "dqn", "--residual"], "--algo dqn is invalid with --residual; valid: --algo ppo, sac or td3 (a continuous "
     "correction), or drop --residual", {"residual": True},
     "algo='dqn' is invalid with residual=True; valid values: ppo, sac, td3 (a continuous correction)"),
    (["--algo", "sac", "--imitate", "mpc"], "--algo sac is invalid with --imitate mpc; valid: --algo ppo (the student is "
     "a PPO actor), or drop --imitate", {"imitate": "mpc"},
     "algo='sac' is invalid with imitate='mpc'; valid values: ppo (the student is a PPO actor)")])
def test_an_option_its_algorithm_does_not_take_is_refused_before_out_is_made(capsys, tmp_path, argv, line, kw, text):
    """``--algo dqn --residual`` and ``--algo sac --imitate mpc`` were refused by ``train()`` only, after ``--out`` was
    made (an empty folder left), in Python's words; one table now (``mission_sim.train_options.ALGO_ONLY``) for the CLI
    (before ``--out``) and ``train()``. ``--residual`` with td3 trains (the old message said "ppo, sac")."""
    out = tmp_path / "run"
    got = _one_error_line(capsys, ["train", *argv, "--timesteps", "256", "--n-envs", "4", "--link", "envelope",
                                   "--no-progress", "--out", str(out)])
    assert got == "dronewpt train: error: " + line
    assert not out.exists()
    from policies.train import train
    with pytest.raises(ValueError) as exc:
        train(argv[1], 64, tmp_path / "py", progress=False, n_envs=4, env={"link_model": "envelope"}, **kw)
    assert str(exc.value) == text
    assert not (tmp_path / "py").exists()


def test_hyperparams_yaml_number_read_as_a_string_says_why(capsys, tmp_path):
    """``learning_rate: 1e-4`` in a YAML file (PyYAML reads it as the string "1e-4") said "valid type: number" to
    someone who wrote a number; now with the YAML hint the env config's message has (one text)."""
    from mission_sim.validation import YAML_NUMBER_NOTE
    hp = tmp_path / "hp.yml"
    hp.write_text("learning_rate: 1e-4\n")
    line = _one_error_line(capsys, ["train", "--algo", "ppo", "--timesteps", "64", "--out", str(tmp_path / "o"),
                                    "--hyperparams", str(hp), "--no-progress"])
    assert line == (f"dronewpt train: error: hyperparams file '{hp}': learning_rate='1e-4' is invalid; valid type: "
                    "number; a number, not a string (YAML 1.1 reads 1e-4 as a string: write 1.0e-4)")
    assert YAML_NUMBER_NOTE in line
    hp.write_text("ent_coef: abc\n")   # not a number at all: no hint
    assert _one_error_line(capsys, ["train", "--algo", "ppo", "--timesteps", "64", "--out", str(tmp_path / "o"),
                                    "--hyperparams", str(hp), "--no-progress"]).endswith(
        "ent_coef='abc' is invalid; valid type: number")


def test_train_seeds_refuse_the_same_model_twice(capsys):
    """``--train-seeds x=residual:M.zip,residual:./M.zip`` (or a glob and one of its files) made a row over "2 seeds"
    of one model: an interval of width 0 (3.47 [3.47, 3.47]); the default groups (five files each) still pass."""
    from policies.compare import check_row_labels, shipped_seed_groups
    spec, again = (f"residual:{ROOT}/policies/pretrained/residual_s0.zip",
                   f"residual:{ROOT}/policies/./pretrained/residual_s0.zip")
    line = _one_error_line(capsys, ["compare", "--policies", "step", "--train-seeds", f"x={spec},{again}",
                                    "--episodes", "1", "--scenarios", "nominal", "--no-plot", "--no-frontier"])
    assert line == (f"dronewpt compare: error: --train-seeds: train_seeds 'x' lists the model '{again}' twice (also "
                    f"as '{spec}'); valid: each model file once (a row over N seeds needs N models)")
    check_row_labels(["step"], shipped_seed_groups())


def test_compare_out_with_no_plot_is_refused(capsys, tmp_path):
    """``compare --no-plot --out DIR``: --out is the figures' folder; it wrote nothing and said nothing."""
    line = _one_error_line(capsys, ["compare", "--policies", "step", "--episodes", "1", "--scenarios", "nominal",
                                    "--no-plot", "--no-frontier", "--out", str(tmp_path / "figs")])
    assert line == (f"dronewpt compare: error: --out '{tmp_path / 'figs'}' is only used for the figures; valid: drop "
                    "--no-plot, or drop --out")


def test_compare_figures_of_unplotted_rows_print_no_matplotlib_warning(capsys, tmp_path):
    """``compare --policies step --no-frontier``: the frontier figure has no labelled point (step, random and
    hysteresis are left out of it); matplotlib's "No artists with labels found to put in legend" went to stderr."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)   # (pytest would only collect it)
        rc = main(["compare", "--policies", "step", "--episodes", "1", "--scenarios", "nominal", "--no-frontier",
                   "--out", str(tmp_path / "figs"), "--no-progress"])
    cap = capsys.readouterr()
    assert rc == 0 and cap.err == "", cap.err
    assert sorted(p.name for p in (tmp_path / "figs").iterdir()) == ["frontier_nominal.png", "transitions_nominal.png"]


def test_register_scenario_does_not_replace_a_built_in_one():
    """``register_scenario(Scenario("nominal", soc=(0.1, 0.2)))`` replaced the built-in "nominal" for the whole process
    (``compare``'s nominal rows, the docs' windows 1000-1099), silently; a name of one's own is re-registered as
    before (a notebook cell run twice), and the built-in itself unchanged is accepted."""
    from envs.scenario import BUILT_IN, SCENARIOS, Scenario, register_scenario
    nominal = SCENARIOS["nominal"]
    with pytest.raises(ValueError) as exc:
        register_scenario(Scenario("nominal", soc=(0.1, 0.2)))
    assert str(exc.value) == ("scenario name 'nominal' is a built-in scenario's; valid: a name of your own (the "
                              f"built-in ones: {', '.join(BUILT_IN)})")
    with pytest.raises(ValueError, match="^scenario name 'windy' is a built-in"):   # as a held-out variant: neither
        register_scenario(Scenario("afternoon_a"), held_out=Scenario("windy", soc=(0.2, 0.3)))
    assert SCENARIOS["nominal"] is nominal and "afternoon_a" not in SCENARIOS
    register_scenario(Scenario("afternoon_b"))
    assert register_scenario(Scenario("afternoon_b", soc=(0.1, 0.2))).soc == SCENARIOS["afternoon_b"].soc == (0.1, 0.2)
    assert register_scenario(Scenario("nominal")) == nominal
    for name in ("afternoon_b",):
        del SCENARIOS[name]


# ------------------------------------------------------------------ the vector env's restart and threads
@pytest.fixture(scope="module")
def venv3():
    from envs import SbarChargingVectorEnv
    v = SbarChargingVectorEnv(3, "nominal", config={"link_model": "envelope"})
    v.reset(seed=1)
    yield v
    v.close()


@pytest.mark.parametrize("idx, named", [([1.5], "[1.5]"), ([True, False, True], "[True, False, True]"),
                                        ("1", "'1'"), (None, "None")])
def test_restart_refuses_what_is_not_integer_indices(venv3, idx, named):
    before = venv3.parts.plant.state.copy()
    with pytest.raises(ValueError) as exc:
        venv3.restart(idx)
    assert str(exc.value) == (f"restart indices {named} are invalid; valid: distinct integers 0..2 (for a mask m: "
                              "np.flatnonzero(m))")
    assert np.array_equal(venv3.parts.plant.state, before)   # nothing restarted


def test_restart_takes_integer_indices_as_before(venv3):
    assert venv3.restart(np.array([2], np.uint8)).shape == (1, 8)
    assert venv3.restart([]).shape == (0, 8)


@pytest.mark.parametrize("seed", [1.5, -1, "a", 2**32])
def test_sb3_adapter_reset_seed_checked(seed):
    """``SbarSB3VecEnv(reset_seed=1.5)`` re-seeded with 1 (int()), -1 failed at the first reset in gymnasium."""
    from envs.sb3_vec import SbarSB3VecEnv
    with pytest.raises(ValueError) as exc:
        SbarSB3VecEnv(2, reset_seed=seed)
    assert str(exc.value) == f"reset_seed={seed!r} is invalid; valid range: integer 0..4294967295"
    assert SbarSB3VecEnv(2, reset_seed=3.0).reset_seed == 3


def test_vector_env_num_threads_named():
    from envs import SbarChargingVectorEnv
    with pytest.raises(ValueError, match=r"^num_threads='a' is invalid; valid range: integer 1\.\.\d+ \(numba's "):
        SbarChargingVectorEnv(2, num_threads="a")


# ------------------------------------------------------------------ telemetry: options of the other mode, ports
@pytest.mark.parametrize("extra, text", [
    (["--follow-time", "5"], "--follow-time 5 is only used with --follow; valid: add --follow udpin:HOST:PORT, or drop "
                             "--follow-time"),
    (["--follow-idle", "2.5"], "--follow-idle 2.5 is only used with --follow"),
    (["--follow", "udpin:127.0.0.1:14561", "--duration", "3"],
     "--duration 3 is not used with --follow (the live vehicle sets the pace and the length); valid: drop --duration"),
    (["--follow", "udpin:127.0.0.1:14561", "--speed", "inf"], "--speed inf is not used with --follow"),
    (["--connect", "udpout:127.0.0.1:99999"], "--connect 'udpout:127.0.0.1:99999' is invalid: port 99999; valid "
                                              "range: 1..65535"),
    (["--connect", "udpout:127.0.0.1:0"], "--connect 'udpout:127.0.0.1:0' is invalid: port 0; valid range: 1..65535"),
    (["--follow", "tcp:127.0.0.1:70000"], "--follow 'tcp:127.0.0.1:70000' is invalid: port 70000; valid range: "
                                          "1..65535"),
])
def test_telemetry_refuses_options_of_the_other_mode_and_names_the_port_range(capsys, tmp_path, extra, text):
    argv = ["telemetry", "--no-progress", "--tlog", str(tmp_path / "x.tlog")]
    if "--connect" not in extra:
        argv += ["--connect", "none"]
    line = _one_error_line(capsys, argv + extra)
    assert line.startswith("dronewpt telemetry: error: ") and text in line, line
    assert not (tmp_path / "x.tlog").exists()


def test_telemetry_mode_defaults_unchanged(monkeypatch, tmp_path, capsys):
    """Not given, the options keep their defaults: --follow gets 60 s / 10 s, a stream speed 1 and no duration."""
    seen = fake_follow(monkeypatch)
    assert main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--connect", "none",
                 "--tlog", str(tmp_path / "f.tlog")]) == 0
    assert (seen["max_wall_s"], seen["idle_timeout_s"]) == (60.0, 10.0)
    from mission_sim.cli import mavlink as cli_mavlink
    assert [(d, v) for d, v, _ in cli_mavlink._MODE_OPTIONS] == [("follow_time", 60.0), ("follow_idle", 10.0),
                                                                 ("duration", None), ("speed", 1.0)]


# ------------------------------------------------------------------ a file that is not a flight log
@pytest.mark.parametrize("command", ["replay", "calibrate"])
@pytest.mark.parametrize("name, data, what", [
    ("empty.tlog", b"", "the file is empty (0 bytes)"),
    ("notes.txt", b"hi\n", "no readable record in its 3 bytes: cut short before its first record, or not a flight "
                           "log"),
    ("head.ulg", None, "no readable record in its 2000 bytes: cut short before its first record, or not a flight log"),
])
def test_a_file_that_is_not_a_flight_log_is_named_as_such(capsys, tmp_path, command, name, data, what):
    """It said "0 usable position sample(s), need at least 2" (replay) or "the log has no battery data" (calibrate)."""
    p = tmp_path / name
    p.write_bytes(data if data is not None else (LOGS / "pyulog_sample_log_small.ulg").read_bytes()[:2000])
    out = ["--out", str(tmp_path / "o" / "d.toml")] if command == "calibrate" else ["--out", str(tmp_path / "o")]
    line = _one_error_line(capsys, [command, str(p), "--no-plot"] + out)
    assert line == (f"dronewpt {command}: error: {name}: no usable position (GPS fix >= 3): {what}; valid: a MAVLink "
                    ".tlog, a DataFlash .bin or a PX4 .ulg")


def test_calibrate_log_from_python_names_a_file_that_is_not_a_flight_log(tmp_path):
    """2026-11-27 mend: check_decoded ran in the CLI only; calibrate_log from Python still said "the log has no
    battery data" for an empty file."""
    from mission_sim.mavlink.calibrate import calibrate_log
    from mission_sim.world.power import DroneParams
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import NoPositionError
    p = tmp_path / "empty.tlog"
    p.write_bytes(b"")
    with pytest.raises(NoPositionError) as exc:
        calibrate_log(read_log(p), DroneParams())
    assert str(exc.value) == ("empty.tlog: no usable position (GPS fix >= 3): the file is empty (0 bytes); valid: a "
                              "MAVLink .tlog, a DataFlash .bin or a PX4 .ulg")


# ------------------------------------------------------------------ review of this branch (newbie2's mend)
@pytest.mark.parametrize("port", ["--5", "²", "٣", "+5", " 5"])
def test_telemetry_port_not_an_integer_is_the_format_message(capsys, tmp_path, port):
    """``--connect udpout:127.0.0.1:--5`` said "invalid literal for int() with base 10: '--5'" (``lstrip('-')``
    let it through), ``²`` passed ``str.isdigit``; both are the format's one line, as on main."""
    from mission_sim.mavlink.telemetry import CONNECT_FORMAT
    spec = f"udpout:127.0.0.1:{port}"
    line = _one_error_line(capsys, ["telemetry", "--no-progress", "--tlog", str(tmp_path / "x.tlog"),
                                    "--connect", spec])
    assert line == f"dronewpt telemetry: error: --connect {spec!r} is invalid; valid format: {CONNECT_FORMAT}"
    assert not (tmp_path / "x.tlog").exists()


def test_telemetry_negative_port_names_the_range(capsys, tmp_path):
    line = _one_error_line(capsys, ["telemetry", "--no-progress", "--tlog", str(tmp_path / "x.tlog"),
                                    "--connect", "udpout:127.0.0.1:-5"])
    assert line == "dronewpt telemetry: error: --connect 'udpout:127.0.0.1:-5' is invalid: port -5; valid range: 1..65535"


@pytest.mark.parametrize("mass", [5000, 0.0, -1.0, float("nan")])
def test_calibrate_mass_range_is_the_librarys(mass):
    """``calibrate_log(log, DroneParams(), mass_kg=5000)`` fitted (the range lived only in the CLI)."""
    from mission_sim.mavlink.calibrate import calibrate_log, fit_drone
    from mission_sim.mavlink.logs import read_log
    from mission_sim.world.power import DroneParams
    text = f"mass_kg={mass!r} is invalid; valid range: [0.01, 1000] kg (the config's drone.mass_kg)"
    with pytest.raises(ValueError) as exc:
        calibrate_log(read_log(LOGS / "dronekit-la-testdata_log171.bin"), DroneParams(), mass_kg=mass)
    assert str(exc.value) == text
    with pytest.raises(ValueError) as exc:
        fit_drone(None, DroneParams(), mass_kg=mass)   # refused before the samples are looked at
    assert str(exc.value) == text


@pytest.mark.parametrize("mass", ["0", "5000", "0.005"])
def test_calibrate_cli_mass_zero_has_the_same_range(capsys, tmp_path, mass):
    """``--mass 5000`` was fitted and written as a [drone] TOML that ``mission --drone`` then refused; ``--mass 0``
    said argparse's "(0, inf)": now the library's one range, before the log is read."""
    out = tmp_path / "cal" / "drone.toml"
    line = _one_error_line(capsys, ["calibrate", str(LOGS / "dronekit-la-testdata_log171.bin"), "--no-plot",
                                    "--out", str(out), "--mass", mass])
    assert line == (f"dronewpt calibrate: error: --mass={float(mass)!r} is invalid; valid range: [0.01, 1000] kg "
                    "(the config's drone.mass_kg)")
    assert not out.parent.exists()


def test_compare_cli_reads_the_librarys_episodes_and_seed_ranges(capsys, monkeypatch):
    """``--episodes`` / ``--seed`` were checked by the CLI's own copy of ``policies.compare.check_episodes``' ranges
    (1..100000, seed + episodes - 1 <= 2^32 - 1): now the one table (changed here, both follow; same messages)."""
    import policies.compare as pc
    from mission_sim.validation import Range
    monkeypatch.setattr(pc, "EPISODES", Range(1, 5, integer=True))
    import mission_sim.validation as mv   # (seed_range's home since 2026-11-27 evening: the envs use it too)
    monkeypatch.setattr(mv, "seed_range", lambda n: Range(0, 10 - n, integer=True))
    base = ["compare", "--policies", "step", "--scenarios", "nominal", "--no-plot", "--no-frontier"]
    assert _one_error_line(capsys, base + ["--episodes", "6"]) == ("dronewpt compare: error: --episodes 6 is invalid; "
                                                                   "valid range: integer 1..5")
    assert _one_error_line(capsys, base + ["--episodes", "2", "--seed", "9"]) == (
        "dronewpt compare: error: --seed 9 is invalid with --episodes 2; valid range: integer 0..8 (episode seeds go up to "
        "seed + episodes - 1)")
    with pytest.raises(ValueError, match=r"^episodes=6 is invalid; valid range: integer 1\.\.5$"):
        pc.check_episodes(6, 0)
    with pytest.raises(ValueError, match=r"^seed=9 is invalid; valid range: integer 0\.\.8 "):
        pc.check_episodes(2, 9)


def test_telemetry_follow_time_and_idle_values_reach_follow(monkeypatch, tmp_path):
    """Given with --follow, --follow-time / --follow-idle reach ``follow()`` (not only their defaults)."""
    seen = fake_follow(monkeypatch)
    assert main(["telemetry", "--follow", "udpin:127.0.0.1:14999", "--connect", "none", "--follow-time", "7",
                 "--follow-idle", "2.5", "--tlog", str(tmp_path / "f.tlog")]) == 0
    assert (seen["max_wall_s"], seen["idle_timeout_s"]) == (7.0, 2.5)


@pytest.mark.parametrize("idx", [[np.int64(0), np.int64(2)], np.array([0, 2], np.int64)])
def test_restart_takes_numpy_integers_as_plain_ints(idx):
    """A list of np.int64 and an int64 array restart the same windows, with the same observations, as [0, 2]."""
    from envs import SbarChargingVectorEnv
    got = []
    for i in ([0, 2], idx):
        v = SbarChargingVectorEnv(3, "nominal", config={"link_model": "envelope"})
        v.reset(seed=1)
        v.step(np.full(3, 0.5, np.float32))
        got.append((v.restart(i), v.parts.plant.state.copy()))
        v.close()
    assert got[0][0].shape == (2, 8)
    assert np.array_equal(got[0][0], got[1][0]) and np.array_equal(got[0][1], got[1][1])


def test_sb3_adapter_reset_seed_numpy_integer():
    """``SbarSB3VecEnv(reset_seed=np.int64(3))``: seed 3, a Python int, and the same first observations as 3."""
    from envs.sb3_vec import SbarSB3VecEnv
    a, b = SbarSB3VecEnv(2, reset_seed=np.int64(3)), SbarSB3VecEnv(2, reset_seed=3)
    assert a.reset_seed == 3 and type(a.reset_seed) is int
    assert np.array_equal(a.reset(), b.reset())
    a.close()
    b.close()
