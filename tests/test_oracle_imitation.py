"""The amortised imitation of the oracle (policies/oracle_imitation.py): the clone reproduces its
teacher on its training windows, the policy's closed loop is the open-loop replay of its sequence, it
is causal, and the training script refuses bad options."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "pretrained" / "oracle_imitation_s0.npz"


def _shipped_config():
    """The env config of the shipped model's plant (its meta's ``link``; a model without it was fitted on eq. 4's
    envelope link, the envs' default until 2026-11-26)."""
    import json

    from envs import EnvConfig
    return EnvConfig(link_model=json.loads(str(np.load(SHIPPED)["meta"])).get("link", "envelope"))


def _clone(slow=None):
    from policies.oracle_imitation import load_model
    m = load_model(SHIPPED)
    m.pop("meta")
    if slow is not None:
        m["slow"] = np.array(float(slow))
    return m


def test_clone_reproduces_its_teacher_on_training_windows():
    """Windows 0 and 1 of nominal are training windows of the shipped seeds: the teacher is the oracle at
    the budget (floor + delta) picked by lam = 0.4 J / point. The clone (its sequence as learned, not
    slowed) lands within 1 point of the teacher's measured overshoot and 0.25 J of its energy after the
    stop in each (measured over all 80 training windows: mean +0.10..+0.23 points, -0.02..+0.01 J over the
    five seeds, worst window +0.95 points, 0.23 J), and every window reaches short mode. Teacher and clone on
    the plant the shipped model was fitted on (its meta's link)."""
    import json

    from policies.oracle_imitation import choose_targets
    from policies.oracle_imitation_train import SearchWindows, oracle_targets
    meta = json.loads(str(np.load(SHIPPED)["meta"]))
    cfg = _shipped_config()
    tg = oracle_targets("nominal", [0, 1], meta["deltas"], config=cfg)
    pick = choose_targets(tg["energy_j"], tg["overshoot"], meta["lam"])
    t_ov = 100.0 * tg["overshoot"][[0, 1], pick]
    t_e = tg["energy_j"][[0, 1], pick]
    e, ov, il = SearchWindows("nominal", "nominal", [0, 1], config=cfg).run([_clone(slow=1.0)])
    assert np.all(np.abs(100.0 * ov[:, 0] - t_ov) < 1.0), (100.0 * ov[:, 0], t_ov)
    assert np.all(np.abs(e[:, 0] - t_e) < 0.25), (e[:, 0], t_e)
    assert np.all(il[:, 0] < 0.5)
    # the teacher itself is within its budget above the window's floor
    assert np.all(tg["overshoot"][[0, 1], pick] <= tg["floor"] + np.asarray(meta["deltas"])[pick] + 1e-12)


def test_closed_loop_equals_the_replay_of_its_sequence_and_ignores_the_sensing_delay():
    """In closed loop (compare's loop, sense_delay windows 1000-1003) the policy is the paper's controller
    before the stop and its latched sequence after it: the open-loop replay of that sequence on the
    same windows without the delay gives the same overshoot and energy (the duty goes through float32
    actions in the loop: to 1e-3 points and 1e-5 J), and so does the closed loop on nominal."""
    from policies.compare import run_policy
    from policies.oracle_imitation_train import SearchWindows
    name = f"oracle_imitation:{SHIPPED}"
    loop = run_policy(name, "sense_delay", 4, 1000).metrics
    nom = run_policy(name, "nominal", 4, 1000).metrics
    e, ov, _ = SearchWindows("sense_delay", "nominal", range(1000, 1004)).run([_clone()])
    np.testing.assert_allclose(loop["overshoot_pct"], 100.0 * ov[:, 0], atol=1e-3)
    np.testing.assert_allclose(loop["energy_after_stop_j"], e[:, 0], atol=1e-5)
    np.testing.assert_allclose(loop["overshoot_pct"], nom["overshoot_pct"], atol=1e-9)
    assert np.all(loop["reached_short_mode"])


def test_policy_is_causal_and_releases_a_new_window():
    """Two receivers see the same observations up to step k, different ones after: their duties agree up
    to k. A receiver whose command turns positive after its stop gets the base controller again, and one
    that starts with command 0 (a mission before its first pad) has the base's duty (no stop yet)."""
    from envs import SbarChargingVectorEnv
    from policies import make
    venv = SbarChargingVectorEnv(num_envs=1, scenario="nominal")
    obs, _ = venv.reset(seed=1000)
    pol0 = make("model_based", venv.policy_context)
    pol0.reset(1)
    seq = []
    for _ in range(venv.config.n_steps):
        seq.append(obs[0].astype(float))
        d = pol0.act(obs)
        obs, *_ = venv.step((2.0 * np.clip(np.asarray(d, dtype=float), 0, 1) - 1.0).reshape(1, 1).astype(np.float32))
    seq = np.array(seq)
    k_stop = int(venv._stop_k[0])
    rng = np.random.default_rng(0)
    for k in (k_stop - 3, k_stop, k_stop + 5):
        other = seq.copy()
        other[k + 1:] = np.clip(other[k + 1:] + rng.normal(0.0, 0.3, other[k + 1:].shape), -1.0, 1.0)
        pol = make(f"oracle_imitation:{SHIPPED}")
        pol.reset(2)
        acts = np.array([pol.act(np.vstack([a, b])) for a, b in zip(seq, other)])
        np.testing.assert_array_equal(acts[:k + 1, 0], acts[:k + 1, 1])
        assert not np.array_equal(acts[:, 0], acts[:, 1])
    # a new window after the stop: the base controller's duty again (not the latched sequence)
    pol = make("oracle_imitation")
    pol.reset(1)
    for row in seq[:k_stop + 10]:
        pol.act(row[None, :])
    assert pol._j[0] > 0
    pol.act(seq[5][None, :])
    assert pol._j[0] == -1
    idle = seq[k_stop + 20].copy()
    pol, base = make("oracle_imitation"), make("model_based")
    pol.reset(1)
    base.reset(1)
    for row in [idle] * 5 + list(seq[:40]):
        assert float(np.asarray(pol.act(row[None, :])).ravel()[0]) == float(np.asarray(base.act(row[None, :])).ravel()[0])


@pytest.mark.parametrize("args, names", [
    (["--windows", "990:1010"], ["--windows", "990:1010", "1000-1099"]), (["--lam", "0"], ["--lam", "> 0"]),
    (["--lam", "abc"], ["--lam", "abc", "> 0"]), (["--slow", "x"], ["--slow", "'x'", "[1, 3]"]),
    (["--slow", "0.5"], ["--slow", "0.5", "[1, 3]"]), (["--features", "d_pre,zzz"], ["--features", "zzz", "cmd_before_a"]),
    (["--features", "bogus"], ["--features", "bogus", "d_pre"]), (["--deltas", "0.5"], ["--deltas", "0.5", "(0, 0.2]"]),
    (["--scenarios", "nowhere"], ["--scenarios", "nowhere", "nominal"]),
    (["--train-seeds", "-1"], ["--train-seeds", "-1", "0..2^32-1"]), (["--train-seeds", "0,x"], ["--train-seeds", "0,x"]),
    (["--out", "FILE/m"], ["--out", "FILE"]), (["--base", "pid"], ["--base", "'pid'", "model_based, mpc"]),
    (["--link", "exact"], ["--link", "'exact'", "envelope", "modal"])])
def test_train_script_bad_options_exit_2_with_one_line(args, names, tmp_path):
    """Each bad option: exit 2, one line naming the option, the value and what is valid, before any oracle
    solve (the oracle's disk cache stays empty) and with nothing written."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "FILE").write_text("a file where --out needs a folder\n")
    args = [str(work / x) if x.startswith("FILE") else x for x in args]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "DRONEWPT_CACHE_DIR": str(tmp_path / "cache")}
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "train_oracle_imitation.py"),
                        "--out", str(work / "m"), *args], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    assert "usage:" not in r.stderr and all(n in r.stderr for n in names), r.stderr
    assert [f.name for f in work.iterdir()] == ["FILE"] and not (tmp_path / "cache").exists()


def test_train_script_defaults_are_the_shipped_models_command(tmp_path, monkeypatch):
    """The defaults are the shipped models' training options (their meta's command) but for --out, which
    is under out/ (never the shipped files; the shipped modal-teacher models were written under out/ and copied to
    policies/pretrained/, 2026-11-26); the command names its link, the envs' default."""
    import json
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    monkeypatch.chdir(tmp_path)
    from train_oracle_imitation import parse
    meta = json.loads(str(np.load(SHIPPED)["meta"]))
    cmd = meta["command"].split()[2:]
    out_at = cmd.index("--out")
    assert Path(cmd[out_at + 1]).parent in (Path("policies/pretrained"), Path("out/oracle_imitation_modal"))
    assert "--link" in cmd and meta["link"] == cmd[cmd.index("--link") + 1] == "modal"
    shipped = vars(parse(cmd[:out_at] + cmd[out_at + 2:]))
    default = vars(parse([]))
    assert shipped == default
    assert default["seeds"] == list(range(*meta["windows"])) and default["lam"] == meta["lam"]
    assert default["slow"] == meta["slow"] and default["deltas"] == meta["deltas"]
    assert Path(default["out"]).parts[0] == "out" and "pretrained" not in default["out"]


def test_train_script_link_reaches_the_teacher_and_the_meta(tmp_path, monkeypatch):
    """``--link L``: the stop observations and the oracle solves run on ``EnvConfig(link_model=L)`` (the oracle's
    cache key holds the config) and the models' meta says ``link``; the default is the envs' default (modal since
    2026-11-26), passed as an explicit config too, so a model's teacher never depends on which link is the
    default."""
    import json

    import policies.oracle_imitation_train as oit
    from envs.core import EnvConfig
    from policies.oracle_imitation import HORIZON
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import train_oracle_imitation as tr
    seen, n, T = [], 6, EnvConfig().n_steps

    def stop_obs(scenario, seed, episodes, config=None, base="model_based"):
        seen.append(("obs", config, base))
        from mission_sim.contract import OBS_DIM
        from policies.oracle_imitation import HISTORY
        return np.random.default_rng(seed).normal(size=(episodes, HISTORY, OBS_DIM)), np.full(episodes, 10)

    def targets(scenario, seeds, deltas, config=None, progress=False, base="model_based"):
        seen.append(("oracle", config, base))
        m, d = len(seeds), len(deltas)
        return {"floor": np.full(m, 0.01), "overshoot": np.full((m, d), 0.02), "energy_j": np.ones((m, d)),
                "feasible": np.ones((m, d), bool), "duties": np.full((m, d, T), 0.5)}
    monkeypatch.setattr(oit, "collect_stop_observations", stop_obs)
    monkeypatch.setattr(oit, "oracle_targets", targets)
    for link, want, base in (("modal", "modal", None), ("envelope", "envelope", None), (None, EnvConfig.link_model, None),
                             ("modal", "modal", "mpc"), ("envelope", "envelope", "mpc")):   # --link with --base mpc
        seen.clear()
        out = tmp_path / f"{link}{base}" / "m"
        tr.main(["--windows", f"0:{n}", "--train-seeds", "0", "--out", str(out)] + (["--link", link] if link else [])
                + (["--base", base] if base else []))
        b = base or "model_based"
        assert seen == [("obs", EnvConfig(link_model=want), b), ("oracle", EnvConfig(link_model=want), b)]
        assert all(type(c) is EnvConfig for _, c, _ in seen)
        meta = json.loads(str(np.load(f"{out}_s0.npz")["meta"]))
        assert meta["link"] == want and meta["base"] == b and np.load(f"{out}_s0.npz")["W"].shape[1] == HORIZON


def _mission_cli(args, capsys):
    """``dronewpt mission`` in process: (exit status, stderr)."""
    from mission_sim.cli import main
    try:
        code = main(["mission", *args])
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


def test_model_refuses_another_control_period(capsys):
    """The model's HORIZON steps are learned at the period in its meta (the shipped ones: 100 us): any
    other period is refused (one ValueError line; the CLI exits 2 with one line, nothing simulated);
    the period it was trained at is accepted."""
    import json

    from mission_sim.contract import PolicyContext
    from policies import make
    meta = json.loads(str(np.load(SHIPPED)["meta"]))
    assert meta["control_period_s"] == pytest.approx(1e-4, rel=1e-12)
    make("oracle_imitation", PolicyContext(control_period_s=1e-4))
    with pytest.raises(ValueError, match=r"control_period_s=0.0002 is invalid .*valid value: 0.0001"):
        make("oracle_imitation", PolicyContext(control_period_s=2e-4))
    code, err = _mission_cli(["--policy", "oracle_imitation", "--set", "sim.control_period_s=2e-4"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "control_period_s" in err, err


def _write(path, **arrays):
    np.savez(path, **arrays)
    return path


@pytest.mark.parametrize("case", ["no_W", "W_shape", "cols_range", "slow", "no_period", "bad_base", "text", "zip"])
def test_load_model_refuses_a_wrong_file_naming_it(case, tmp_path, capsys):
    """A file that is not such a model (keys, shapes, cols outside FEATURE_NAMES, slow < 1, no period in
    its meta, not an npz, a zip without arrays): one ValueError naming the file and what was expected;
    the CLI exits 2 with one line, no traceback."""
    import json
    import zipfile

    from policies.oracle_imitation import FEATURE_NAMES, HORIZON, load_model
    good = dict(np.load(SHIPPED))
    p = tmp_path / f"{case}.npz"
    if case == "text":
        p.write_text("not a model\n")
    elif case == "zip":
        with zipfile.ZipFile(p, "w") as z:
            z.writestr("notes.txt", "hello")
    else:
        bad = {"no_W": {k: v for k, v in good.items() if k != "W"},
               "W_shape": {**good, "W": np.zeros((3, HORIZON - 1))},
               "cols_range": {**good, "cols": np.array([0, len(FEATURE_NAMES)])},
               "slow": {**good, "slow": np.array(0.5)},
               "no_period": {**good, "meta": np.array(json.dumps({"seed": 0}))},
               "bad_base": {**good, "meta": np.array(json.dumps({"control_period_s": 1e-4, "base": "pid"}))}}[case]
        _write(p, **bad)
    with pytest.raises(ValueError, match=r"oracle imitation model .*" + case + r"\.npz.*valid: an oracle imitation model"):
        load_model(p)
    code, err = _mission_cli(["--policy", f"oracle_imitation:{p}"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and str(p) in err and "Traceback" not in err, err


def test_save_model_leaves_no_temporary_file_on_failure(tmp_path, monkeypatch):
    """A failed write leaves neither the model nor its temporary file; a good one leaves only the model."""
    from policies import oracle_imitation as oi
    model = {k: v for k, v in oi.load_model(SHIPPED).items() if k != "meta"}

    def broken(path, **kw):
        Path(path).write_bytes(b"partial")
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(oi.np, "savez", broken)
    with pytest.raises(OSError):
        oi.save_model(model, tmp_path / "m.npz", {"control_period_s": 1e-4})
    assert not list(tmp_path.iterdir())
    monkeypatch.undo()
    oi.save_model(model, tmp_path / "m.npz", {"control_period_s": 1e-4})
    assert [f.name for f in tmp_path.iterdir()] == ["m.npz"]
    np.testing.assert_array_equal(oi.load_model(tmp_path / "m.npz")["W"], model["W"])


def test_base_in_meta_runs_the_mpc_before_the_stop(tmp_path):
    """``meta["base"] = "mpc"``: before the stop the policy's duties are the MPC's (budget 0) in closed loop on
    the same windows (lm_drift 1000-1002, bit for bit: the same observations), after it the latched
    sequence (not the MPC's); a model without ``base`` keeps the paper's controller. A base that is not one
    of BASES: one-line ValueError naming it and the valid names (also from the teacher's functions)."""
    import json

    from envs import SbarChargingVectorEnv
    from policies.compare import run_policy
    from policies.oracle_imitation import BASES, check_base, load_model
    from policies.oracle_imitation_train import collect_stop_observations, oracle_targets
    good = dict(np.load(SHIPPED))
    assert json.loads(str(good["meta"])).get("base", "model_based") == "model_based"   # the shipped maps: the paper's
    bare = {k: v for k, v in json.loads(str(good["meta"])).items() if k != "base"}    # a model without ``base``
    p0 = _write(tmp_path / "bare.npz", **{**good, "meta": np.array(json.dumps(bare))})
    assert "base" not in load_model(p0)["meta"]
    r0, r1 = run_policy(f"oracle_imitation:{p0}", "lm_drift", 3, 1000), run_policy("model_based", "lm_drift", 3, 1000)
    venv = SbarChargingVectorEnv(num_envs=3, scenario="lm_drift")
    venv.reset(seed=1000)
    for i, k0 in enumerate(venv._stop_k):   # without ``base``: the paper's controller before the stop
        np.testing.assert_array_equal(r0.d_short[:k0, i], r1.d_short[:k0, i])
    p = _write(tmp_path / "drift.npz", **{**good, "meta": np.array(json.dumps({"control_period_s": 1e-4, "base": "mpc"}))})
    assert load_model(p)["meta"]["base"] == "mpc"
    pol = run_policy(f"oracle_imitation:{p}", "lm_drift", 3, 1000)
    mpc = run_policy("mpc", "lm_drift", 3, 1000)
    venv = SbarChargingVectorEnv(num_envs=3, scenario="lm_drift")
    venv.reset(seed=1000)
    for i, k0 in enumerate(venv._stop_k):
        np.testing.assert_array_equal(pol.d_short[:k0, i], mpc.d_short[:k0, i])
        assert np.abs(pol.d_short[k0:, i] - mpc.d_short[k0:, i]).max() > 1e-3
    for call in (lambda: check_base("pid"), lambda: collect_stop_observations("nominal", 0, 1, base="pid"),
                 lambda: oracle_targets("nominal", [0], [0.01], base="pid")):
        with pytest.raises(ValueError) as exc:
            call()
        assert str(exc.value) == f"base='pid' is invalid; valid values: {', '.join(BASES)}"


def test_playback_selection_rule_and_retimed_maps(tmp_path, monkeypatch):
    """benchmarks/select_oracle_imitation_playback.py (docs/rl.md, "Re-selecting the playback on the modal link"):
    the rule keeps the settings <= -margin points of overshoot against the reference on every scenario and picks the
    largest least return difference (within 0.1 of it: the larger least margin); none admissible gives None. A map
    re-timed to another ``slow`` differs from the shipped one in ``slow`` only (its unslowed prediction is the same
    and the slowed one is its interpolation at j / slow); windows that touch the training or evaluation seeds are
    refused (exit 2) before anything runs."""
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    from select_oracle_imitation_playback import choose, main, write_map

    from policies.oracle_imitation import HORIZON, load_model, predict
    t = {(0.4, 1.0): {"a": {"dov": -0.05, "dret": 5.0}, "b": {"dov": -0.2, "dret": 6.0}},
         (0.4, 1.1): {"a": {"dov": -0.12, "dret": 2.0}, "b": {"dov": -0.3, "dret": 1.0}},
         (0.4, 1.2): {"a": {"dov": -0.15, "dret": 1.5}, "b": {"dov": -0.4, "dret": 0.95}},
         (0.5, 1.0): {"a": {"dov": -0.11, "dret": 0.5}, "b": {"dov": -0.11, "dret": 3.0}}}
    assert choose(t, 0.10) == ((0.4, 1.2), [(0.4, 1.1), (0.4, 1.2), (0.5, 1.0)])   # 0.95 is within 0.1 of 1.0
    assert choose(t, 0.13)[0] == (0.4, 1.2) and choose(t, 0.5) == (None, [])
    # admit="upper": the pooled bootstrap's upper bound of the overshoot difference below -margin on every scenario
    up = {k: {s: {**v, "dov_pooled": (v["dov"], v["dov"] - 0.1, v["dov"] + 0.1)} for s, v in row.items()}
          for k, row in t.items()}
    assert choose(up, 0.0, "upper") == ((0.4, 1.2), [(0.4, 1.1), (0.4, 1.2), (0.5, 1.0)])   # -0.05 + 0.1 > 0
    assert choose(up, 0.03, "upper") == ((0.4, 1.2), [(0.4, 1.2)])   # -0.12 + 0.1 = -0.02 is not < -0.03
    with pytest.raises(ValueError, match="admit='max' is invalid; valid values: mean, upper"):
        choose(t, 0.0, "max")
    shipped = load_model(SHIPPED)
    m = {k: v for k, v in shipped.items() if k not in ("meta", "slow")}
    write_map(m, tmp_path / "m.npz", 0.4, 1.2, 0, "modal", shipped["meta"]["control_period_s"])
    re = load_model(tmp_path / "m.npz")
    assert float(re["slow"]) == 1.2 and re["meta"]["slow"] == 1.2
    assert all(np.array_equal(re[k], shipped[k]) for k in ("W", "cols", "feat_mean", "feat_std"))
    assert re["meta"]["base"] == "model_based"
    write_map(m, tmp_path / "b.npz", 0.4, 1.2, 0, "modal", shipped["meta"]["control_period_s"], "mpc", (0, 40))
    assert load_model(tmp_path / "b.npz")["meta"]["base"] == "mpc" and load_model(tmp_path / "b.npz")["meta"]["windows"] == [0, 40]
    f = np.array([[0.3, 2.0] + [0.0] * 7])
    base = predict({**re, "slow": np.array(1.0)}, f)[0]
    assert np.array_equal(predict(re, f)[0], np.interp(np.arange(HORIZON) / 1.2, np.arange(HORIZON), base))
    for seed in ("1000", "950", "2050", "40"):
        with pytest.raises(SystemExit) as e:
            main(["--seed", seed, "--episodes", "100", "--models", str(SHIPPED), "--work", str(tmp_path / "w")])
        assert e.value.code == 2
    assert not (tmp_path / "w").exists()


def _select_module(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    import select_oracle_imitation_playback as sel
    return sel


def _stub_run_policies(monkeypatch, calls=None):
    """``policies.compare.run_policies`` replaced by a stub: every name gets random metrics on ``episodes`` windows
    (no env is run); ``calls`` collects the names of each call."""
    from types import SimpleNamespace

    import policies.compare as pc

    def run(names, scenario, episodes, seed, config=None, num_threads=None):
        if calls is not None:
            calls.append(list(names))
        rng = np.random.default_rng(seed)
        return {n: SimpleNamespace(metrics={"overshoot_pct": rng.normal(2.5, 0.1, episodes),
                                            "return": rng.normal(40.0, 1.0, episodes),
                                            "energy_after_stop_j": rng.normal(0.7, 0.01, episodes),
                                            "reached_short_mode": np.ones(episodes, bool)}) for n in names}
    monkeypatch.setattr(pc, "run_policies", run)


def _write_source_maps(sel, folder, bases):
    """Maps as the training script writes them (the shipped model's arrays and meta), one per entry of ``bases``
    (the meta's ``base``), ``folder/src_s<k>.npz``."""
    from policies.oracle_imitation import load_model, save_model
    shipped = load_model(SHIPPED)
    arrays = {k: v for k, v in shipped.items() if k != "meta"}
    folder.mkdir(parents=True, exist_ok=True)
    for k, b in enumerate(bases):
        save_model(arrays, folder / f"src_s{k}.npz", {**shipped["meta"], "seed": k, "base": b,
                                                     "command": f"train command {k}"})
    return shipped["meta"]


def test_select_playback_retimes_mpc_base_maps_keeping_their_meta(tmp_path, monkeypatch, capsys):
    """``--models`` of maps whose base is the MPC: every re-timed map's meta is its source's (base ``mpc``, budgets,
    training windows, lam) with ``slow`` and a command naming the source's; the JSON records the maps' base and
    budgets (docs/rl.md, "The MPC before the stop on the exact-mode link")."""
    import json

    from policies.oracle_imitation import load_model
    sel = _select_module(monkeypatch)
    calls = []
    _stub_run_policies(monkeypatch, calls)
    src = _write_source_maps(sel, tmp_path / "src", ["mpc", "mpc"])
    work, out = tmp_path / "w", tmp_path / "s.json"
    sel.main(["--models", str(tmp_path / "src" / "src_s*.npz"), "--slows", "1.0,1.05", "--scenarios", "nominal",
              "--seed", "300", "--episodes", "4", "--work", str(work), "--json", str(out)])
    assert calls == [["mpc"] + [f"oracle_imitation:{work}/lam0.4_slow{s}_s{k}.npz" for s in ("1", "1.05") for k in (0, 1)]]
    for s in (1.0, 1.05):
        for k in (0, 1):
            meta = load_model(work / f"lam0.4_slow{s:g}_s{k}.npz")["meta"]
            assert meta == {**src, "seed": k, "base": "mpc", "slow": s,
                            "command": f"select_oracle_imitation_playback.py candidate lam=0.4 slow={s}, re-timed from: "
                                       f"train command {k}"}
    info = json.loads(out.read_text())["info"]
    assert info["base"] == "mpc" and info["deltas"] == src["deltas"] and info["windows"] == src["windows"]


def test_select_playback_base_mpc_reaches_the_teacher(tmp_path, monkeypatch):
    """Refitting: ``--base mpc --deltas --windows`` reach ``train_oracle_imitation.dataset`` (the teacher's solves)
    and every written map's meta; the validation windows are checked against the given training windows."""
    import train_oracle_imitation as tr

    import policies.oracle_imitation as oi
    from policies.oracle_imitation import load_model
    sel = _select_module(monkeypatch)
    _stub_run_policies(monkeypatch)
    seen = []
    shipped = load_model(SHIPPED)

    def dataset(scenarios, seeds, deltas, lam, base="model_based", config=None):
        seen.append((scenarios, list(seeds), list(deltas), lam, base, config.link_model))
        return np.zeros((3, 9)), np.zeros((3, 4)), {"overshoot": np.full(3, 0.02), "energy_j": np.ones(3)}
    monkeypatch.setattr(tr, "dataset", dataset)
    monkeypatch.setattr(oi, "fit", lambda X, Y, cols=(0, 1), seed=None: {k: v for k, v in shipped.items()
                                                                          if k not in ("meta", "slow")})
    work = tmp_path / "w"
    sel.main(["--base", "mpc", "--deltas", "0.001,0.002", "--windows", "0:40", "--lams", "0.7", "--slows", "1.05",
              "--scenarios", "nominal", "--seed", "40", "--episodes", "4", "--work", str(work)])
    assert seen == [(["nominal"], list(range(40)), [0.001, 0.002], 0.7, "mpc", "modal")]
    meta = load_model(work / "lam0.7_slow1.05_s4.npz")["meta"]
    assert (meta["base"], meta["deltas"], meta["windows"], meta["lam"], meta["slow"], meta["seed"]) == \
        ("mpc", [0.001, 0.002], [0, 40], 0.7, 1.05, 4)


@pytest.mark.parametrize("args, names", [
    (["--windows", "a:b"], ["--windows", "'a:b'", "LO:HI"]), (["--windows", "0"], ["--windows", "'0'", "LO:HI"]),
    (["--windows", "80:0"], ["--windows", "'80:0'", "0 <= LO < HI"]), (["--windows", "0:80:2"], ["--windows", "'0:80:2'"]),
    (["--deltas", "x"], ["--deltas", "'x'", "(0, 0.2]"]), (["--deltas", ","], ["--deltas", "','", "(0, 0.2]"]),
    (["--deltas", "-0.1"], ["--deltas", "'-0.1'", "(0, 0.2]"]), (["--slows", "x"], ["--slows", "'x'", "[1, 3]"]),
    (["--slows", "0.9"], ["--slows", "'0.9'", "[1, 3]"]), (["--lams", "1,y"], ["--lams", "'1,y'", "> 0"]),
    (["--windows", "0:400"], ["--seed 300", "300-399", "training (0-399)"]),   # the validation windows in the training's
    (["--models", "SHIPPED", "--base", "mpc"], ["--base mpc", "base model_based"]),
    (["--models", "SHIPPED", "--windows", "0:40"], ["--windows 0:40", "windows 0:80"]),
    (["--models", "SHIPPED", "--deltas", "0.003"], ["--deltas 0.003", "deltas 0.003,0.006,0.01,0.016"]),
    (["--models", "MIXED"], ["--models", "base differ", "src_s0.npz: mpc", "src_s1.npz: model_based"])])
def test_select_playback_bad_options_exit_2_with_one_line(args, names, tmp_path, monkeypatch, capsys):
    """Each bad option or set of maps: exit 2, one line naming the option, the value and what is valid, before
    anything is fitted, run or written (the teacher and the runs are stubs that fail the test if reached: a broken
    check fails here at once instead of solving the oracle)."""
    import train_oracle_imitation as tr

    import policies.compare as pc
    sel = _select_module(monkeypatch)

    def reached(*args, **kw):
        raise AssertionError("reached the teacher or the runs")
    monkeypatch.setattr(tr, "dataset", reached)
    monkeypatch.setattr(pc, "run_policies", reached)
    _write_source_maps(sel, tmp_path / "mixed", ["mpc", "model_based"])
    sub = {"SHIPPED": str(ROOT / "policies" / "pretrained" / "oracle_imitation_s*.npz"),
           "MIXED": str(tmp_path / "mixed" / "src_s*.npz")}
    with pytest.raises(SystemExit) as e:
        sel.main([sub.get(x, x) for x in args] + ["--work", str(tmp_path / "w")])
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and "usage:" not in err, err
    assert all(n in err for n in names), err
    assert not (tmp_path / "w").exists()
