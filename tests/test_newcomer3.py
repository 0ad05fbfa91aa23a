"""A demanding newcomer's third pass (2026-11-28): sweep, sizing, tolerance, netlist, export-controller, coupling,
paper, warmup, the flags of compare and train, and the Python API from a notebook. Each test fails on the tree
before its fix (docs/robustness.md, "A demanding newcomer's third pass")."""

import json
import signal
import threading

import numpy as np
import pytest

SMALL = dict(n_steps=32, batch_size=256, n_epochs=2, policy_kwargs=dict(net_arch=[16, 16], log_std_init=-2.0))


# --------------------------------------------------------------------------- train: Ctrl-C keeps the model so far
@pytest.fixture
def sigint_raises():
    """SIGINT raising KeyboardInterrupt (Python's default) for the test, whatever pytest started with: a background
    job, nohup or a CI wrapper starts Python with SIGINT ignored, which ``interrupts_requested`` leaves alone."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers can only be set in the main thread")
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_an_interrupted_training_keeps_its_model_usable_and_resumable(tmp_path, monkeypatch, capfd, sigint_raises):
    """Ctrl-C (or SIGTERM) 9 env steps into ``train`` ended the run with nothing but the checkpoints and an
    ``eval/best_model.zip`` without its metadata (neither usable as ``rl:``): the steps since the last checkpoint
    (up to --checkpoint-every, 100,000 by default) were lost. Now the first signal stops SB3 at the next step (one
    line on stderr says so) and the model so far is saved beside the final one's name, with its metadata
    (``interrupted``) and statistics: a ``rl:`` policy, and ``resume=`` goes on from it to the total. A second Ctrl-C
    while saving no longer cuts the saving short (it is raised after, with the note naming the model), and the
    resume moves the first run's learning-curve files aside instead of starting them afresh over them."""
    pytest.importorskip("stable_baselines3")
    import stable_baselines3 as sb3

    import policies
    from policies import callbacks, train as train_mod
    from policies.train import train

    step = callbacks.ProgressCallback._on_step
    best_meta = train_mod._write_best_meta

    def ctrl_c_at_call_9(self):
        if self.n_calls == 9:
            signal.raise_signal(signal.SIGINT)
        return step(self)

    def ctrl_c_again_while_saving(*a):   # the second Ctrl-C, half-way through the saving
        signal.raise_signal(signal.SIGINT)
        return best_meta(*a)
    monkeypatch.setattr(callbacks.ProgressCallback, "_on_step", ctrl_c_at_call_9)
    monkeypatch.setattr(train_mod, "_write_best_meta", ctrl_c_again_while_saving)
    kw = dict(seed=1, n_envs=16, scenario="nominal", progress=False, hyperparams=SMALL, eval_episodes=4,
              checkpoint_every=10**6)
    with pytest.raises(KeyboardInterrupt) as e:
        train("ppo", 4096, tmp_path, eval_every=128, **kw)   # one evaluation, at call 8
    assert "SIGINT: stopping at the next step to save the model so far" in capfd.readouterr().err
    # SB3 stops at the step that saw the request: 9 steps of 16 windows
    model = tmp_path / "ppo_sbar_interrupted.zip"
    assert model.is_file() and not (tmp_path / "ppo_sbar.zip").exists()
    meta = json.loads(model.with_suffix(".json").read_text())
    assert meta["interrupted"] == {"signal": "SIGINT", "timesteps": 144, "of": 4096}
    assert sb3.PPO.load(str(model), device="cpu").num_timesteps == 144
    assert "144 of 4,096 steps" in e.value.__notes__[0] and f"--resume {model}" in e.value.__notes__[0]
    assert f"rl:{model}" in e.value.__notes__[0]
    # the best evaluated model so far has its metadata too (written only at the end of a whole run before; the
    # second Ctrl-C cut the saving there), without the interrupted model's `interrupted`
    best = json.loads((tmp_path / "eval" / "best_model.json").read_text())
    assert "interrupted" not in best and best["selected_at"]["timesteps"] == 128
    assert (tmp_path / "learning_curve.png").is_file()
    first_curve = (tmp_path / "eval" / "eval_curve.json").read_text()
    first_monitor = (tmp_path / "monitor.monitor.csv").read_text()
    # usable as a policy: one window's duties in [0, 1]
    from envs import SbarChargingEnv
    env = SbarChargingEnv("nominal")
    pol = policies.make(f"rl:{model}")
    obs, _ = env.reset(seed=3)
    pol.reset()
    d = [float(np.asarray(pol.act(obs)).ravel()[0])]
    assert 0.0 <= d[0] <= 1.0
    # and resumable to the total (the signal no longer sent; no evaluation due)
    monkeypatch.setattr(callbacks.ProgressCallback, "_on_step", step)
    monkeypatch.setattr(train_mod, "_write_best_meta", best_meta)
    res = train("ppo", 512, tmp_path, resume=model, eval_every=10**9, **kw)
    # on from 144: one PPO rollout (32 steps x 16 windows) reaches the 512
    assert sb3.PPO.load(str(res["model"]), device="cpu").num_timesteps == 144 + 512
    assert "interrupted" not in json.loads(res["meta"].read_text())
    # the first run's learning curve kept beside, not overwritten by the resumed run's
    assert [p.read_text() for p in (tmp_path / "eval").glob("eval_curve.prev-*.json")] == [first_curve]
    assert [p.read_text() for p in tmp_path.glob("monitor.monitor.prev-*.csv")] == [first_monitor]
    assert "eval_curve.prev-" in res["earlier_curves"]
    assert (tmp_path / "monitor.monitor.csv").read_text() != first_monitor


def test_a_deferred_section_leaves_an_ignored_sigint_ignored():
    """``interrupts_deferred`` (now over train's saving) turned a SIGINT that the process ignores (nohup, a
    background job) into an ``Interrupted`` on leaving; an ignored signal stays ignored, a handled one is raised."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signal handlers can only be set in the main thread")
    from mission_sim.signals import Interrupted, interrupts_deferred
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        try:
            with interrupts_deferred():
                signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:   # (not let through: pytest would end the session)
            pytest.fail("an ignored SIGINT was raised on leaving interrupts_deferred")
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        signal.signal(signal.SIGINT, signal.default_int_handler)
        with pytest.raises(Interrupted):
            with interrupts_deferred():
                signal.raise_signal(signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, old)


def test_an_interrupt_note_names_the_policy_prefix_of_the_trained_kind():
    """The interrupt note said ``rl:PATH`` for every model, also a --slow-budget one (``slow_budget:PATH``)."""
    from policies.train import _policy_prefix
    assert [_policy_prefix(s) for s in ({"residual": False, "slow_budget": None}, {"residual": True},
                                        {"residual": False, "slow_budget": (0.0, 2.0)})] == \
        ["rl", "residual", "slow_budget"]


# --------------------------------------------------------------------------- train: --out of an earlier run
def _earlier_run(folder):
    folder.mkdir()
    for name, data in (("ppo_sbar.zip", b"an earlier run's model"), ("monitor.monitor.csv", b"#{}\nr,l,t\n")):
        (folder / name).write_bytes(data)
    return {p.name: p.read_bytes() for p in folder.iterdir()}


def test_train_refuses_an_out_folder_holding_an_earlier_run(tmp_path, capsys):
    """``dronewpt train --out t2`` a second time replaced the first run's ``ppo_sbar.zip`` (150,000 steps of
    training) and its monitor log with the new run's, exit 0, no word. Now refused (the command line before anything
    is built, ``train()`` alike), unless it resumes; a folder without a model or monitor log is still taken."""
    pytest.importorskip("stable_baselines3")
    from _cli_helpers import one_error_line

    from policies.train import train
    before = _earlier_run(tmp_path / "t2")
    line = one_error_line(capsys, ["train", "--algo", "ppo", "--timesteps", "10", "--out", str(tmp_path / "t2"),
                                   "--no-progress"])
    assert "holds an earlier training run (ppo_sbar.zip, monitor.monitor.csv)" in line and "--resume" in line
    with pytest.raises(ValueError, match="holds an earlier training run"):
        train("ppo", 10, tmp_path / "t2", progress=False)
    assert {p.name: p.read_bytes() for p in (tmp_path / "t2").iterdir()} == before
    # only what this run would replace counts: notes.zip or another model's name does not, eval/ with files does
    from policies.train import earlier_run
    other = tmp_path / "t3"
    other.mkdir()
    (other / "notes.zip").write_bytes(b"PK")
    (other / "sac_sbar.zip").write_bytes(b"PK")
    (other / "eval").mkdir()
    assert earlier_run(other, "ppo_sbar") is None
    (other / "eval" / "best_model.zip").write_bytes(b"PK")
    assert earlier_run(other, "ppo_sbar") == "eval/"


# --------------------------------------------------------------------------- sweep: a policy's model retrained
def test_a_sweep_over_a_model_file_refuses_to_resume_once_the_model_changed(tmp_path, monkeypatch):
    """A study with ``policy = ["rl:PATH"]`` resumed after PATH was retrained (another model at the same path)
    printed ``2 cases, 2 already done, 0 run``: the old model's rows as the new model's numbers (a case's id holds
    the spec, not the model). Now the model and its metadata are recorded in sweep.json (sha256, as a replay study's
    log) and the resume is refused naming the file; the model as it was resumes."""
    pytest.importorskip("stable_baselines3")
    import shutil

    import policies
    from mission_sim.studies.prepare import prepare_study
    from mission_sim.studies.status import check_same_study, write_manifest
    from mission_sim.studies.study import parse_study

    pre = policies.__file__.rsplit("/", 1)[0] + "/pretrained/"
    for ext in ("zip", "json"):
        shutil.copy(pre + f"rl_s0.{ext}", tmp_path / f"mine.{ext}")
    doc = {"study": {"name": "mine"}, "grid": {"policy": ["step", f"rl:{tmp_path / 'mine.zip'}"]}}
    out = tmp_path / "sweep"

    def prepared():
        st = parse_study(doc)
        runner, cases, fp = prepare_study(st, policies.make, policies.available(), warn=False)
        return st, runner, cases, fp
    st, runner, cases, fp = prepared()
    assert set(runner.input_files) == {f"policy rl:{tmp_path / 'mine.zip'}", f"policy rl:{tmp_path / 'mine.zip'} metadata"}
    write_manifest(out, st, fp, len(cases), runner.input_files)
    shutil.copy(pre + "rl_s1.zip", tmp_path / "mine.zip")   # retrained into the same path
    st, runner, cases, fp = prepared()
    with pytest.raises(ValueError, match=r"over another file: policy rl:.*mine.zip' changed since it ran"):
        check_same_study(out, st, fp, len(cases), runner.input_files)
    shutil.copy(pre + "rl_s0.zip", tmp_path / "mine.zip")   # as it was: resumes
    st, runner, cases, fp = prepared()
    check_same_study(out, st, fp, len(cases), runner.input_files)


# --------------------------------------------------------------------------- sweep: missions that ran dry
def test_a_sweep_counts_the_missions_that_ended_with_the_battery_depleted(tmp_path, capsys):
    """``dronewpt mission`` ends a depleted mission with exit 3; a sweep of 4 missions, 3 of them depleted (a pad
    10 km away, an empty start), said ``4 ok, 0 failed`` and averaged them into the table with no word. Now the line
    and the table (``battery depleted``, also in summary.csv and --format json) count them."""
    from mission_sim.cli import main
    study = tmp_path / "f1.toml"
    study.write_text('[study]\nname = "f1"\n[grid]\n"pads.1.x_m" = [40.0, 10000.0]\n'
                     '"battery.initial_soc" = [0.5, 0.0]\n')
    assert main(["sweep", str(study), "--out", str(tmp_path / "o"), "--workers", "0", "--no-plot",
                 "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "4 ok (3 with the battery depleted: battery_depleted in the rows), 0 failed" in out
    import pandas as pd
    table = pd.read_csv(tmp_path / "o" / "summary.csv", index_col=0)
    assert table.loc["all", "battery depleted"] == 3


# --------------------------------------------------------------------------- Python API from a notebook
@pytest.mark.parametrize("kw, where", [
    ({"n_steps": 100}, "n_steps is an EnvConfig field: config={'n_steps': 100}"),
    ({"link_model": "envelope"}, "link_model is an EnvConfig field: config={'link_model': 'envelope'}"),
    ({"overcurrent": 20}, "overcurrent is a reward weight: config={'reward': {'overcurrent': 20}}"),
    ({"bogus": 1}, "valid keywords: scenario, render_mode, config, compiled, history")])
def test_gymnasium_make_with_an_env_config_field_says_where_it_goes(kw, where):
    """``gymnasium.make(ENV_ID, n_steps=100)`` (the EnvConfig fields as keywords, as many envs take them) said
    ``SbarChargingEnv.__init__() got an unexpected keyword argument 'n_steps'``, no word of ``config=``; now the
    valid keywords and, for a config field or reward weight, the ``config={...}`` it belongs in (the vector env too)."""
    import gymnasium as gym

    import envs
    with pytest.raises(TypeError, match=r"keyword argument '\w+' is unknown; valid keywords: ") as e:
        gym.make(envs.ENV_ID, **kw)
    assert where in str(e.value)
    with pytest.raises(TypeError) as e:
        gym.make_vec(envs.ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", **kw)
    assert "SbarChargingVectorEnv: keyword argument" in str(e.value) and "valid keywords: num_envs," in str(e.value)
    assert "config={" not in where or where in str(e.value)


def test_run_paper_takes_one_trajectory_by_name():
    """``run_paper(trajectories="step")`` iterated the string: ``trajectory='s' is invalid``; now one trajectory:
    the step's envelope peak, Table II's 50.51 A (eq. 4's model, run_paper's default)."""
    from wpt_receiver.paper import run_paper
    runs = run_paper(trajectories="step")
    assert [r.trajectory for r in runs] == ["step"]
    assert runs[0].metrics.max_current_a == pytest.approx(50.51, abs=0.01)


# --------------------------------------------------------------------------- a list split by the shell
@pytest.mark.parametrize("argv, shown", [
    (["compare", "--policies", "step,", "ramp", "--no-plot"], "(a space after the comma in 'step,'? a list is one "
                                                             "argument: step,ramp, or quote it)"),
    (["sizing", "--policies", "step,", "ramp", "--no-plot"], "argument: step,ramp"),
    (["compare", "--scenarios", "nominal,", "windy", "--no-plot"], "argument: nominal,windy"),
    (["compare", "--policies", "step,", "ramp,", "mpc", "--no-plot"], "argument: step,ramp,mpc, or quote")])
def test_a_list_split_at_a_space_after_its_comma_says_so(argv, shown, capsys):
    """``compare --policies step, ramp`` said ``unrecognized argument 'ramp'`` alone; a newcomer reads the list as
    given. Now the line points at the space after the comma."""
    from _cli_helpers import one_error_line
    line = one_error_line(capsys, argv)
    assert f"unrecognized argument '{argv[3]}' (a space after the comma in '{argv[2]}'?" in line and shown in line


# --------------------------------------------------------------------------- a study's value spec misspelt
@pytest.mark.parametrize("section, text, shown", [
    ("grid", '"pads.1.hover_time_s" = {range = [30, 60, 10]}',
     "[grid] 'pads.1.hover_time_s' = {range = ...} is invalid; valid: a list of values, or {linspace = [start, stop, "
     "num]}"),
    ("grid", 'pads.1.hover_time_s = {arange = [30, 60, 10]}', "[grid] 'pads.1.hover_time_s' = {arange = ...}"),
    ("grid", '"pads.1.hover_time_s" = {linspace = [30, 60], num = 3}',
     "[grid] 'pads.1.hover_time_s' = {linspace = ..., num = ...} is invalid"),
    ("monte_carlo.params", '"wind.speed_m_s" = {randint = [0, 6]}',
     "[monte_carlo.params] 'wind.speed_m_s' = {randint = ...} is invalid; valid: one of {uniform = [...]}")])
def test_a_study_value_spec_that_is_not_one_is_named_as_a_spec(section, text, shown):
    """``"pads.1.hover_time_s" = {range = [30, 60, 10]}`` (numpy's / Python's word for a grid) was flattened into a key:
    ``override key 'pads.1.hover_time_s.range' is invalid; valid form: pads.<index>.<key>``, about a key the user
    never wrote; now the value is named with the specs the section takes. A nested table of real keys
    (``link = {devices = [...]}``) is still a dotted key."""
    from mission_sim.studies.study import parse_study
    import tomllib
    doc = tomllib.loads(f"[{section}]\n{text}\n" + ("[monte_carlo]\nn = 2\n" if "monte" in section else ""))
    with pytest.raises(ValueError) as e:
        parse_study(doc)
    assert shown in str(e.value)
    assert parse_study({"grid": {"link": {"devices": ["ideal", "sic"]}}}).grid == {"link.devices": ["ideal", "sic"]}


def test_a_resume_from_a_model_without_its_statistics_leaves_the_earlier_curves_in_place(tmp_path):
    """``train(resume=...)`` checks the model's VecNormalize statistics before it moves the folder's learning-curve
    files aside: a wrong resume (no statistics beside it) had moved monitor.monitor.csv and eval/eval_curve.json to
    *.prev-* and then failed, so the rerun resumed without them (a re-read of 2026-11-28)."""
    from policies.train import train
    (tmp_path / "monitor.monitor.csv").write_text("#\n")
    (tmp_path / "eval").mkdir()
    (tmp_path / "eval" / "eval_curve.json").write_text("[]")
    (tmp_path / "wrong.zip").write_bytes(b"PK")
    with pytest.raises(FileNotFoundError, match="no VecNormalize statistics"):
        train("ppo", 100, tmp_path, resume=str(tmp_path / "wrong.zip"), progress=False)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["eval", "eval_curve.json", "monitor.monitor.csv", "wrong.zip"]


def test_a_budget_after_the_colon_is_not_taken_for_a_model_file(tmp_path, monkeypatch):
    """``mpc:0.05`` names a budget: a file called ``0.05`` in the working folder is not recorded (hashed) as the
    policy's model; ``rl:PATH`` is (a re-read of 2026-11-28)."""
    from mission_sim.studies.prepare import policy_files
    from mission_sim.studies.study import parse_study
    monkeypatch.chdir(tmp_path)
    (tmp_path / "0.05").write_text("not a model")
    (tmp_path / "m.zip").write_bytes(b"PK")
    st = parse_study({"study": {"name": "b"}, "grid": {"policy": ["mpc:0.05", "rl:m.zip"]}})
    assert set(policy_files(st)) == {"policy rl:m.zip"}
