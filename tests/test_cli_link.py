"""``--link {envelope,modal}`` on ``compare`` and ``train``: the envs' plant (``envs.EnvConfig.link_model``).
A bad value is one line on stderr naming it and the valid choices, exit 2, nothing run; ``--link modal``
reaches the batched env of every policy (the same numbers as the env built with the modal config)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mission_sim.cli import main


def _cli(*args):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run([sys.executable, "-m", "mission_sim.cli", *args], capture_output=True, text=True, env=env,
                          timeout=600)


@pytest.mark.parametrize("cmd", [["compare", "--episodes", "2", "--no-plot"],
                                 ["train", "--algo", "ppo", "--timesteps", "1", "--out", "never_made"]])
def test_invalid_link_is_one_line_exit_2(cmd, tmp_path):
    out = _cli(*cmd, "--link", "exact")
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr
    assert "--link" in lines[0] and "'exact'" in lines[0] and "'envelope'" in lines[0] and "'modal'" in lines[0]
    assert out.stdout == "" and not (tmp_path / "never_made").exists() and not os.path.exists("never_made")


def test_train_env_link_model_bad_value_is_one_line_before_anything_is_written(tmp_path):
    out = _cli("train", "--algo", "ppo", "--timesteps", "1", "--out", str(tmp_path / "run"), "--env", "link_model=x")
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip().splitlines() == [
        "dronewpt train: error: --env: link_model='x' is invalid; valid values: envelope, modal"]
    assert not (tmp_path / "run").exists()


def test_train_env_key_selects_the_link():
    """``train --env link_model=modal`` (the config key) builds the same EnvConfig as ``--link modal``."""
    from policies.train import env_config
    assert env_config({"link_model": "modal"}).link_model == "modal"
    assert env_config({"link_model": "envelope"}).link_model == "envelope"
    assert env_config({}).link_model == "modal"   # the envs' default since 2026-11-26 (issue 23)
    with pytest.raises(ValueError, match="link_model='x' is invalid; valid values: envelope, modal"):
        env_config({"link_model": "x"})


def _compare_json(capsys, link):
    argv = ["compare", "--episodes", "2", "--policies", "model_based,step", "--scenarios", "nominal", "--no-plot",
            "--no-frontier", "--format", "json"] + (["--link", link] if link else [])
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_link_modal_reaches_every_policys_env(capsys):
    """``compare --link X`` scores the policies on X's plant: its rows are those of ``run_policies`` on
    ``EnvConfig(link_model=X)`` to the bit; without ``--link`` the default's, the exact-mode link's since
    2026-11-26 (issue 23), and ``--link envelope`` is eq. 4's (other numbers), named so in the JSON."""
    from envs import EnvConfig
    from policies.compare import run_policies
    modal = _compare_json(capsys, "modal")
    default, envelope = _compare_json(capsys, None), _compare_json(capsys, "envelope")
    assert default["link"] == modal["link"] == "modal" and envelope["link"] == "envelope"
    assert default["rows"] == modal["rows"]
    for link, out in (("modal", modal), ("envelope", envelope)):
        ref = run_policies(["model_based", "step"], "nominal", 2, 1000, EnvConfig(link_model=link))
        for row in out["rows"]:
            m = ref[row["policy"]].metrics
            assert row["peak_i2_a"] == pytest.approx(float(np.mean(m["peak_i2_a"])), rel=1e-12)
            assert row["energy_after_stop_j"] == pytest.approx(float(np.mean(m["energy_after_stop_j"])), rel=1e-12)
    assert modal["rows"][0]["peak_i2_a"] != envelope["rows"][0]["peak_i2_a"]


def test_config_dict_states_the_link_always_and_the_modal_step_options_only_off_their_defaults():
    """The trained models' metadata follows ``EnvConfig.__repr__``'s rule (one rule,
    ``EnvConfig.stated_fields``): ``link_model`` always, whatever the default (it changed on 2026-11-26: an
    eq. 4-trained model's record must not read as modal, nor a modal one's as eq. 4, and the oracle's cache keys
    of the two links never meet); hold_tol_a / v2_updates only where they differ from their defaults."""
    from envs import EnvConfig
    from policies.train import config_dict
    opt = {"hold_tol_a", "v2_updates"}
    assert config_dict(EnvConfig())["link_model"] == EnvConfig.link_model == "modal"
    assert config_dict(EnvConfig(link_model="envelope"))["link_model"] == "envelope"
    assert repr(EnvConfig(link_model="envelope")) != repr(EnvConfig()) == repr(EnvConfig(link_model="modal"))
    for cfg in (EnvConfig(), EnvConfig(link_model="envelope")):
        assert f"link_model={cfg.link_model!r}" in repr(cfg) and not opt & set(config_dict(cfg))
    d = config_dict(EnvConfig(link_model="modal", v2_updates=34))
    assert d["link_model"] == "modal" and d["v2_updates"] == 34 and "hold_tol_a" not in d
    assert config_dict(EnvConfig(hold_tol_a=2e-3))["hold_tol_a"] == 2e-3
    for cfg in (EnvConfig(), EnvConfig(link_model="envelope", hold_tol_a=5e-3)):
        named = {k for k, _ in cfg.stated_fields()} & opt
        assert named == {k for k in opt if k in repr(cfg)} == set(config_dict(cfg)) & opt


@pytest.mark.parametrize("kv, valid", [("v2_updates=20.5", "integer 0..1000"), ("n_steps=300.5", "integer 2..1000000"),
                                       ("slow_every=1.5", "integer >= 1")])   # mission_sim.validation.Range's text
def test_train_env_non_integer_count_is_refused_not_truncated(kv, valid, tmp_path):
    """``--env v2_updates=20.5`` is refused by EnvConfig's check (one line, exit 2), not trained with int()'s 20."""
    out = _cli("train", "--algo", "ppo", "--timesteps", "1", "--out", str(tmp_path / "run"), "--env", kv)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{kv} is invalid" in lines[0] and valid in lines[0]
    assert not (tmp_path / "run").exists()
    from policies.train import env_config
    key, value = kv.split("=")
    assert getattr(env_config({key: float(value.split(".")[0])}), key) == int(value.split(".")[0])  # whole: taken


def test_train_env_fewer_v2_updates_than_rectifier_periods_is_one_line_exit_2(tmp_path):
    """``--env v2_updates=4`` (1 .. 16 at the default dt_s: V2 held while i2 turns, the energy off by 0.5-450 %
    under random duties) is refused by EnvConfig's cross-field check: one line naming the value and the valid set,
    exit 2, nothing written."""
    out = _cli("train", "--algo", "ppo", "--timesteps", "1", "--out", str(tmp_path / "run"), "--env", "v2_updates=4")
    assert out.returncode == 2 and "Traceback" not in out.stderr and out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "v2_updates=4 is invalid" in lines[0] and "17..1000 at dt_s=0.0001 s" in lines[0]
    assert not (tmp_path / "run").exists()


def test_train_link_and_env_link_model_conflict_is_one_line_exit_2(tmp_path):
    """``--link modal --env link_model=envelope``: neither silently wins; one line naming both, nothing written.
    The same value twice is no conflict (refused here only by the bad v2_updates, checked after the link)."""
    out = _cli("train", "--algo", "ppo", "--timesteps", "1", "--out", str(tmp_path / "run"), "--link", "modal",
               "--env", "link_model=envelope")
    assert out.returncode == 2 and "Traceback" not in out.stderr and out.stdout == ""
    assert out.stderr.strip().splitlines() == [
        "dronewpt train: error: --link modal conflicts with --env link_model=envelope; valid: one of them, or both "
        "with the same value"]
    assert not (tmp_path / "run").exists()
    same = _cli("train", "--algo", "ppo", "--timesteps", "1", "--out", str(tmp_path / "run"), "--link", "modal",
                "--env", "link_model=modal", "--env", "v2_updates=2.5")
    assert same.returncode == 2 and "conflicts" not in same.stderr and "v2_updates=2.5 is invalid" in same.stderr


def test_train_reproduce_command_always_names_the_link():
    """A trained model's ``reproduce`` command names its link whether or not ``--link`` was given (the envs' default
    changed once: a command without it would retrain on another plant)."""
    from envs import EnvConfig
    from policies.train import _reproduce
    spec = dict(algo="ppo", timesteps=1000, seed=0, n_envs=4, scenario="nominal", cost="overshoot", lagrangian=False,
                residual=False, history=1, slow_budget=None, action_filter=0.0, smooth_penalty=0.0, imitate=None,
                env_overrides={}, hyperparams_file=None)
    assert " --link modal " in _reproduce({**spec, "config": EnvConfig()})
    assert " --link envelope " in _reproduce({**spec, "config": EnvConfig(link_model="envelope")})


def test_compare_help_names_the_real_defaults(capsys):
    """``compare --help`` lists the default policies and scenarios that ``compare`` actually runs."""
    import pytest

    from mission_sim.cli import main
    from policies.compare import DEFAULT_POLICIES, DEFAULT_SCENARIOS
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    text = "".join(capsys.readouterr().out.split())   # argparse wraps inside words
    assert "(default:" + ",".join(DEFAULT_POLICIES) + ";" in text
    assert "(default:" + ",".join(DEFAULT_SCENARIOS) + ";" in text
