"""The shipped learned seeds were trained on the env as it is today but for its link, and behave within physical
bounds on the plant they were trained on.

Every shipped seed group (``compare``'s default learned rows) records the env config it was trained on;
it must be today's default (real devices, instantaneous peaks: the objective has no switch for the
latter, so the config and the retraining record are the version) but for the link, which is one per group:
the SB3 models were trained on eq. 4's envelope link, the envs' default until 2026-11-26 (issue 23 made the
exact-mode link the default), and the groups retrained since on the exact-mode link say ``link_model: modal``
(docs/rl.md, "Retrained on the exact-mode link"). So the behaviour tests below run each group on
:func:`_trained_on` (the plant its metadata says it was trained on), not on whatever the default is. The residual seeds must keep their
duty within ``scale`` of their budgeted model-based base, reach short mode and deliver less energy after
the stop than the paper's controller; the Lagrangian seeds must have trained against a budget in the
measured units (the ramp's measured cost) and stay physical (no swing of I2 above the step's peak); the
unconstrained PPO seeds (``rl``) must be plain PPO (no budget, no multiplier) run by the same retraining
script and stay physical the same way."""

import json
from pathlib import Path

import numpy as np
import pytest

from policies.compare import run_policies, shipped_seed_groups

pytest.importorskip("stable_baselines3")

WINDOWS, SEED = 8, 5000   # fixed nominal windows, disjoint from compare's 1000-1099 and the training ones


def _metas(kind):
    return [json.loads(Path(s.split(":", 1)[1]).with_suffix(".json").read_text()) for s in shipped_seed_groups()[kind]]


def _trained_on(kind):
    """The EnvConfig of the plant a seed group was trained on (one link per group, module notes)."""
    from envs.core import EnvConfig
    links = {m["env_config"]["link_model"] for m in _metas(kind)}
    assert len(links) == 1, (kind, links)
    return EnvConfig(link_model=links.pop())


def test_every_shipped_seed_group_was_trained_on_todays_env_config():
    from envs.core import EnvConfig
    from policies.train import config_dict
    for kind in shipped_seed_groups():
        link = _trained_on(kind).link_model
        today = json.loads(json.dumps(config_dict(EnvConfig(link_model=link))))
        assert today["devices"] != "ideal" and today["link_model"] == link
        for m in _metas(kind):
            assert m["env_config"] == today, (kind, m["seed"])
            # the command names the link it trained on (as --link or as the --env override of retrain_shipped)
            assert f" --link {link} " in m["reproduce"] or f" --env link_model={link} " in m["reproduce"]
            if link != "envelope":   # retrained on the exact-mode link: by the retraining script, with its record
                assert m["trained"]["returncode"] == 0 and f" --link {link} " in m["trained"]["command"]
    for kind in ("rl", "residual", "ppo_lagrangian"):
        for m in _metas(kind):
            t = m["trained"]
            assert len(t["commit"]) == 40 and t["returncode"] == 0 and t["command"].startswith("dronewpt train")
            assert f"--seed {m['seed']} " in t["command"] and f"--timesteps {m['timesteps']} " in t["command"]
            if kind == "rl":   # plain PPO from a feed-forward clone: no budget, no multiplier, no residual base
                assert "--budget" not in t["command"] and "--lagrangian" not in t["command"]
                assert m["budget"] is None and m["lagrangian"] is None and m["residual"] is None
                assert "--imitate model_based_budget:0.05 " in t["command"] and m["imitation"]["teacher"] == \
                    "model_based_budget:0.05" and {"i2_amp_a", "battery_current_a", "rect_current_a"} <= \
                    set(m["imitation"]["masked"])
                assert m["imitation"]["clone"] == "clone.zip" and m["policy_kwargs"]["log_std_init"] == -2.5
            else:
                assert f"--budget {m['budget']:g} " in t["command"]
    assert len({m["seed"] for m in _metas("rl")}) == len(_metas("rl")) >= 2


def test_shipped_budgets_are_in_measured_overshoot_units():
    """The residual's budget sits above its base's measured overshoot on the training scenario (so it can
    trade), the Lagrangian's is the ramp's measured mean cost there (the documented default)."""
    from policies.constrained import BUDGET_EPISODES, BUDGET_SEED
    base_name = "model_based_budget:0.01"
    on_res, on_lag = _trained_on("residual"), _trained_on("ppo_lagrangian")   # each group on its own plant
    runs = run_policies([base_name], "random", BUDGET_EPISODES, BUDGET_SEED, on_res)
    base = float(np.mean(np.maximum(runs[base_name].metrics["cost"], 0.0)))
    ramp = float(np.mean(run_policies(["ramp"], "random", BUDGET_EPISODES, BUDGET_SEED, on_lag)["ramp"].metrics["cost"]))
    assert 0.03 < base < 0.06   # the ripple term: ~3 points above the envelope's ~1.5 %
    for m in _metas("residual"):
        assert m["residual"]["base"] == base_name and base < m["budget"] < base + 0.02
    for m in _metas("ppo_lagrangian"):
        assert m["budget"] == pytest.approx(ramp, rel=1e-5)


def test_shipped_residual_keeps_its_duty_within_scale_of_its_base():
    from mission_sim.contract import PolicyContext
    from policies.budgeted import BudgetedModelBasedPolicy
    from policies.residual import ResidualPolicy
    rng = np.random.default_rng(4)
    obs = rng.uniform(-1.0, 1.0, (60, 16, 8)).astype(np.float32)
    for spec in shipped_seed_groups()["residual"]:
        pol = ResidualPolicy(PolicyContext(), path=spec.split(":", 1)[1])
        base = BudgetedModelBasedPolicy(PolicyContext(), budget=pol.base_budget)
        pol.reset(16)
        base.reset(16)
        diff = np.array([pol.act(o) - np.asarray(base.act(o), dtype=float).reshape(-1) for o in obs])
        assert np.all(np.abs(diff) <= pol.scale + 1e-9)
        assert np.abs(diff).max() > 1e-3   # learned: not its base


def test_shipped_residual_reaches_short_mode_and_delivers_less_than_the_paper_after_the_stop():
    specs = shipped_seed_groups()["residual"]
    runs = run_policies(["model_based", "step", *specs], "nominal", WINDOWS, SEED, _trained_on("residual"))
    mb, step = runs["model_based"].metrics, runs["step"].metrics
    for sp in specs:
        m = runs[sp].metrics
        assert np.all(m["reached_short_mode"])
        assert np.mean(m["energy_after_stop_j"]) < np.mean(mb["energy_after_stop_j"])
        assert np.all(m["overshoot_pct"] < step["overshoot_pct"])


def test_shipped_lagrangian_stays_physical():
    specs = shipped_seed_groups()["ppo_lagrangian"]
    runs = run_policies(["step", *specs], "nominal", WINDOWS, SEED, _trained_on("ppo_lagrangian"))
    step = runs["step"].metrics
    for sp in specs:
        m = runs[sp].metrics
        assert np.all(m["peak_i2_a"] < step["peak_i2_a"])


def test_shipped_rl_stays_physical_and_is_the_default_rl_policy():
    """Each unconstrained seed's peak |I2| stays below the step's (the hardest RM -> SM switch) in every
    window (``random`` and ``hysteresis`` peak at ~51-53 A and fail it) and, started from the clone of a
    teacher that does (docs/rl.md), every seed reaches short mode (I_L < 0.5 A from 14 ms after the stop)
    in every window; ``--policy rl`` (policies.rl.PRETRAINED) is seed 0 of the group."""
    from policies.rl import PRETRAINED
    specs = shipped_seed_groups()["rl"]
    assert specs[0] == f"rl:{PRETRAINED}"
    runs = run_policies(["step", *specs], "nominal", WINDOWS, SEED, _trained_on("rl"))
    step = runs["step"].metrics
    for sp in specs:
        assert np.all(runs[sp].metrics["peak_i2_a"] < step["peak_i2_a"])
        assert np.all(runs[sp].metrics["reached_short_mode"] == 1.0), sp


@pytest.mark.parametrize("args, bad", [(["--kind", "rl", "--budget", "0.05"], "--budget is not valid with --kind rl"),
                                       (["--kind", "residual"], "--budget is required with --kind residual"),
                                       (["--kind", "rl", "--timesteps", "0"], "--timesteps 0 is invalid")])
def test_retrain_script_refuses_a_budget_for_rl_and_needs_one_for_the_constrained_kinds(tmp_path, args, bad):
    """One line on stderr naming the option, exit 2, nothing trained (no output folder)."""
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, str(root / "benchmarks" / "retrain_shipped.py"), "--timesteps", "1000",
           "--out", str(tmp_path / "retrain"), *args]
    r = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and bad in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "retrain").exists()


def test_retrain_script_rl_bc_is_the_cloned_start_and_installs_as_rl(tmp_path, monkeypatch):
    """``--kind rl_bc``: its command is a valid ``dronewpt train`` that clones model_based_budget:0.05 with the
    current fields hidden, without a budget; ``install`` writes ``rl_s<k>`` (not ``rl_bc_s<k>``) with the
    ``trained`` record, the final model copied byte for byte."""
    from mission_sim.cli import build_parser
    rs = _retrain_script()
    cmd = rs.KINDS["rl_bc"].format(timesteps=800000, seed=2, budget="")
    a = build_parser().parse_args(cmd.split()[1:] + ["--out", str(tmp_path / "x")])
    assert a.imitate == "model_based_budget:0.05" and a.timesteps == 800000 and a.seed == 2 and a.budget is None
    assert set(a.imitation_mask.split(",")) == {"last_d_short", "i2_amp_a", "battery_current_a", "rect_current_a"}
    assert not rs.constrained("rl_bc")
    src = tmp_path / "out" / "rl_bc_s2"
    src.mkdir(parents=True)
    (src / "ppo_sbar.zip").write_bytes(b"model bytes")
    (src / "ppo_sbar.json").write_text(json.dumps({"seed": 2}))
    (src / "clone.zip").write_bytes(b"clone bytes")
    (tmp_path / "policies" / "pretrained").mkdir(parents=True)
    monkeypatch.setattr(rs, "ROOT", tmp_path)
    rs.install("rl_bc", 2, tmp_path / "out", {"command": cmd})
    dst = tmp_path / "policies" / "pretrained"
    assert sorted(p.name for p in dst.iterdir()) == ["rl_s2.json", "rl_s2.zip"]
    assert (dst / "rl_s2.zip").read_bytes() == b"model bytes"
    assert json.loads((dst / "rl_s2.json").read_text()) == {"seed": 2, "trained": {"command": cmd}}


def _retrain_script():
    import importlib.util
    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("retrain_shipped", root / "benchmarks" / "retrain_shipped.py")
    rs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rs)
    return rs


@pytest.mark.parametrize("kind, timesteps, budget", [("slow_budget", 307200, "0.1"), ("imitation", 0, "")])
def test_retrain_script_slow_budget_and_imitation_are_the_shipped_commands(kind, timesteps, budget):
    """The script's command of each kind parses to the options of the shipped seed 0's own ``reproduce``
    (link and output aside): the retraining runs what was shipped, on the link it is told."""
    from mission_sim.cli import build_parser
    from mission_sim.cli.learning import _only_with
    from mission_sim.train_options import ONLY_WITH
    from policies.train import _only_with_values

    def parsed(argv):   # the options the run uses: the dependent ones' defaults filled in, the CLI's then train()'s
        a = build_parser().parse_args(argv)
        _only_with(a)
        v = vars(a)
        keys = set(ONLY_WITH) | set(ONLY_WITH.values())
        v.update(_only_with_values({k: v[k] for k in keys if k in v}))
        return v
    rs = _retrain_script()
    assert rs.constrained(kind) == bool(budget)
    ours = parsed(rs.KINDS[kind].format(timesteps=timesteps, seed=0, budget=budget).split()[1:] + ["--out", "x"])
    shipped = json.loads((Path(__file__).resolve().parents[1] / "policies" / "pretrained" / f"{kind}_s0.json").read_text())
    theirs = parsed(shipped["reproduce"].replace(" --out DIR", " --out x").split()[1:])
    skip = {"link", "env", "eval_every", "checkpoint_every"}   # the link is the run's; evaluation cadence is not the model
    assert {k: v for k, v in ours.items() if k not in skip} == {k: v for k, v in theirs.items() if k not in skip}


def test_retrain_script_refuses_ppo_steps_for_the_clone_and_installs_only_finished_runs(tmp_path):
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[1]
    script = [sys.executable, str(root / "benchmarks" / "retrain_shipped.py")]
    r = subprocess.run([*script, "--kind", "imitation", "--timesteps", "1000", "--out", str(tmp_path / "r")],
                       cwd=root, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--timesteps 1000 is invalid with --kind imitation" in r.stderr
    assert not (tmp_path / "r").exists()
    (tmp_path / "recs").write_text(json.dumps({"kind": "imitation", "seed": 0, "returncode": 0}) + "\n")
    r = subprocess.run([*script, "--kind", "imitation", "--timesteps", "0", "--seeds", "0-1", "--out", str(tmp_path / "r"),
                        "--install-from", str(tmp_path / "recs")], cwd=root, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "seeds [0, 1] of --kind imitation have no finished run" in r.stderr


@pytest.mark.parametrize("links", ["envelope", "modal,modal", "envelope,exact"])
def test_bench_train_refuses_bad_links(links):
    """``bench_train.py --links``: two or more distinct link names, else one line naming the value, exit 2."""
    import subprocess
    import sys
    root = Path(__file__).resolve().parents[1]
    r = subprocess.run([sys.executable, str(root / "benchmarks" / "bench_train.py"), "--links", links],
                       cwd=root, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and f"--links {links!r} is invalid" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_retrain_script_moves_an_earlier_seed_folder_aside(tmp_path, monkeypatch, capsys):
    """A rerun of the script trained into out/retrain/<kind>_s<k> again, which ``dronewpt train`` refuses as an
    earlier run (the reason only in the seed's log, exit 1). Now the earlier folder is moved aside first, said on
    stderr, and the command gets a fresh folder."""
    import subprocess
    rs = _retrain_script()
    earlier = tmp_path / "rl_s3"
    earlier.mkdir()
    (earlier / "ppo_sbar.zip").write_bytes(b"the first run's model")
    seen = []

    def run(cmd, **kw):   # the training command: what it would find in its --out
        seen.append(earlier.exists())
        return subprocess.CompletedProcess(cmd, 0)
    monkeypatch.setattr(rs.subprocess, "run", run)
    monkeypatch.setattr(rs, "_commit", lambda: "x")
    assert rs.train_seed("rl", 3, 1000, None, tmp_path)["returncode"] == 0
    assert seen == [False]
    [moved] = tmp_path.glob("rl_s3.prev-*")
    assert (moved / "ppo_sbar.zip").read_bytes() == b"the first run's model"
    assert f"aside to {moved.name}" in capsys.readouterr().err
