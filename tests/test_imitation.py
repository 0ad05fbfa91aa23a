"""Issue 21: frame stack, privileged observation, smoothed actions, imitation of a teacher."""

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from mission_sim.contract import OBS_DIM, OBS_INDEX, history_obs_dim  # noqa: E402


def _cfg(n_steps=40, **kw):
    from policies.train import env_config
    return env_config({"n_steps": n_steps, **kw})


def _eq4():
    """Eq. 4's link, pinned where a test's tolerance is eq. 4's (the envs' default is the exact-mode link since
    2026-11-26)."""
    from envs import EnvConfig
    return EnvConfig(link_model="envelope")


def test_history_obs_dim_and_bad_values():
    assert history_obs_dim(1) == OBS_DIM and history_obs_dim(4) == 4 * OBS_DIM
    for bad in (0, 33, 2.5):
        with pytest.raises(ValueError, match="history"):
            history_obs_dim(bad)


def test_frame_stack_equals_last_k_single_observations_across_autoreset():
    """The stacked observation is the last K observations of the same window, oldest first (K copies
    of the first one at a window's start), terminal observations included."""
    from envs.history import HistoryVecEnv
    from envs.sb3_vec import SbarSB3VecEnv

    k, n, T = 3, 4, 12
    plain = SbarSB3VecEnv(n, "random", _cfg(T))
    stacked = HistoryVecEnv(SbarSB3VecEnv(n, "random", _cfg(T)), k)
    plain.seed(5)
    stacked.venv.seed(5)
    window = [[o] for o in plain.reset()]
    s = stacked.reset()
    rng = np.random.default_rng(0)
    n_done = 0
    for _ in range(2 * T + 3):
        past = [np.stack(([w[0]] * k + w)[-k:]) for w in window]
        assert np.array_equal(s, np.stack([p.reshape(-1) for p in past]))
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        o, _, done, infos = plain.step(a)
        s, _, done2, infos2 = stacked.step(a)
        assert np.array_equal(done, done2)
        for i in range(n):
            if done[i]:
                n_done += 1
                term = np.stack(([window[i][0]] * k + window[i] + [infos[i]["terminal_observation"]])[-k:])
                assert np.array_equal(infos2[i]["terminal_observation"], term.reshape(-1))
                window[i] = [o[i]]
            else:
                window[i].append(o[i])
    assert n_done == 2 * n   # two autoresets of every window were checked
    assert s.shape == (n, k * OBS_DIM)


def test_privileged_observation_is_the_undelayed_one():
    """With a sensing delay of D periods the privileged current fields at step k equal the observed
    ones at step k + D (the observation's noise aside: I2 is compared within the sensor noise)."""
    from envs import SbarChargingVectorEnv
    from policies.imitation import privileged_obs

    delay = 2
    venv = SbarChargingVectorEnv(num_envs=3, scenario={"name": "d", "sense_delay_steps": (delay, delay)})
    obs, info = venv.reset(seed=3)
    priv, seen = [], []
    for _ in range(30):
        priv.append(privileged_obs(obs, info))
        seen.append(obs.copy())
        obs, _, _, _, info = venv.step(np.full((3, 1), -0.6, np.float32))
    for f in ("battery_current_a", "rect_current_a"):
        j = OBS_INDEX[f]
        for k in range(5, 25):
            np.testing.assert_allclose(priv[k][:, j], seen[k + delay][:, j], atol=2e-6)
            assert not np.allclose(priv[k][:, j], seen[k][:, j]) or np.allclose(priv[k][:, j], priv[k - delay][:, j])
    j = OBS_INDEX["i2_amp_a"]   # noise-free in the privileged view: within the sensor noise (0.1 A ~ 0.004 normalised)
    assert np.max(np.abs(np.array(priv[5:25])[:, :, j] - np.array(seen[5 + delay:25 + delay])[:, :, j])) < 0.05


def test_action_filter_and_smoothness_penalty_are_exact():
    from envs.sb3_vec import SbarSB3VecEnv
    from policies.smoothing import SmoothActionVecEnv, filtered_duty

    alpha, w, n = 0.6, 3.0, 4
    # eq. 4's link (pinned): the wrapper's arithmetic does not depend on the link, but the filtered duty reaches the
    # env through a float32 action, and on the modal link that last-bit difference moves a step's reward by up to
    # 3.5e-5 (its sub-steps' refinement is a threshold on |dI2|), beyond this exactness test's 1e-5
    base = SbarSB3VecEnv(n, "nominal", _cfg(link_model="envelope"))
    raw = SbarSB3VecEnv(n, "nominal", _cfg(link_model="envelope"))
    env = SmoothActionVecEnv(base, alpha, w)
    base.seed(1)
    raw.seed(1)
    obs, obs_raw = env.reset(), raw.reset()
    rng = np.random.default_rng(2)
    for _ in range(20):
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        last = (obs[:, OBS_INDEX["last_d_short"]] + 1.0) / 2.0
        d = alpha * last + (1 - alpha) * (a[:, 0] + 1.0) / 2.0
        np.testing.assert_allclose(filtered_duty(obs, (a[:, 0] + 1) / 2, alpha), d, atol=1e-7)
        obs, r, _, _ = env.step(a)
        obs_raw, r_raw, _, _ = raw.step((2 * d - 1)[:, None].astype(np.float32))
        np.testing.assert_allclose(obs[:, OBS_INDEX["last_d_short"]], obs_raw[:, OBS_INDEX["last_d_short"]], atol=1e-6)
        np.testing.assert_allclose(r, r_raw - w * (d - last) ** 2, rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="action_filter"):
        SmoothActionVecEnv(base, 1.0)


FEEDFORWARD = ("last_d_short", "i2_amp_a", "battery_current_a", "rect_current_a")


@pytest.fixture(scope="module")
def clone(tmp_path_factory):
    """BC (16 windows, seeds 10000+) of model_based_budget:0.02 as a residual on model_based_budget:0.01, on eq. 4's
    link (pinned: the tolerances of the test below were set on eq. 4's teacher; on the exact-mode link, the envs'
    default since 2026-11-26, the teacher is the modal plan (policies.budget_modal) and the teacher-forced RMS was
    0.0059, over this test's 0.005)."""
    from policies.imitation import ImitationSpec, imitate

    spec = ImitationSpec(teacher="model_based_budget:0.02", scenario="nominal", episodes=16, epochs=60,
                         batch_size=256, residual_scale=0.1, residual_base_budget=0.01, masked=FEEDFORWARD)
    out = tmp_path_factory.mktemp("clone")
    return spec, imitate(spec, out, progress=False, config=_eq4())


def test_imitation_reproduces_its_teacher(clone):
    """Teacher-forced: the student's duty is within 0.005 RMS of the teacher's on 4 unseen windows;
    closed loop on 16 unseen windows (seeds 1000+): every window in short mode, overshoot within 1.5
    points of the teacher's, and energy after the stop closer to the teacher's than its base is (at
    least halfway from the base to the teacher)."""
    from dataclasses import replace

    from policies.compare import run_policy
    from policies.imitation import collect
    from policies import make

    spec, res = clone
    pol = make(f"residual:{res['model']}")
    X, Y = collect(replace(spec, episodes=4), 5000, config=_eq4())   # teacher's own windows, not trained on
    rows = X.reshape(300, 4, -1)
    pol.rl.reset(4)
    a = np.concatenate([2.0 * pol.rl.act(r) - 1.0 for r in rows])
    duty_rms = spec.residual_scale * np.sqrt(np.mean((np.clip(a, -1, 1) - Y) ** 2))
    assert duty_rms < 0.005
    m = {p: run_policy(p, "nominal", 16, 1000, _eq4()).metrics for p in
         (f"residual:{res['model']}", "model_based_budget:0.02", "model_based_budget:0.01")}
    s, t, b = (m[k] for k in m)
    assert s["reached_short_mode"].min() == 1.0
    assert abs(s["overshoot_pct"].mean() - t["overshoot_pct"].mean()) < 1.5
    e_s, e_t, e_b = (x["energy_after_stop_j"].mean() for x in (s, t, b))
    assert abs(e_s - e_t) < 0.5 * abs(e_b - e_t)


def test_clone_metadata_and_sb3_load(clone):
    """The clone is a plain SB3 PPO zip + VecNormalize: ``PPO.load`` gives the same actions as the policy."""
    import json

    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import VecNormalize

    from envs.sb3_vec import SbarSB3VecEnv
    from policies.constrained import ResidualVecEnv

    spec, res = clone
    meta = json.loads(res["meta"].read_text())
    assert meta["residual"]["scale"] == 0.1 and meta["imitation"]["teacher"] == "model_based_budget:0.02"
    assert meta["obs_dim"] == 9 and meta["history"] == 1
    venv = VecNormalize.load(str(res["vecnormalize"]), ResidualVecEnv(SbarSB3VecEnv(2, "nominal"), 0.1, 0.01))
    venv.training = False
    model = sb3.PPO.load(str(res["model"]), device="cpu")
    obs = venv.reset()
    a_sb3 = model.predict(obs, deterministic=True)[0][:, 0]
    from policies.rl import RLPolicy
    rl = RLPolicy(path=res["model"], residual=True)
    rl.reset(2)
    np.testing.assert_allclose(2 * rl.act(venv.unnormalize_obs(obs)) - 1, np.clip(a_sb3, -1, 1), atol=1e-5)


def test_train_cli_imitation_dagger_history_then_compare_by_name(tmp_path):
    """``train --imitate ... --dagger 1 --history 2 --timesteps 0`` writes a model that ``compare`` runs as
    ``imitation:PATH`` (the frame stack kept by the policy); bad options exit 2 with one line."""
    import json
    import subprocess
    import sys

    out = tmp_path / "imit"
    cmd = [sys.executable, "-m", "mission_sim.cli", "train", "--algo", "ppo", "--timesteps", "0", "--imitate",
           "model_based", "--dagger", "1", "--history", "2", "--imitation-episodes", "2", "--imitation-epochs", "1",
           "--scenario", "nominal", "--no-progress", "--out", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    meta = json.loads((out / "ppo_sbar.json").read_text())
    assert meta["history"] == 2 and meta["obs_dim"] == 16 and len(meta["imitation"]["iterations"]) == 2
    r = subprocess.run([sys.executable, "-m", "mission_sim.cli", "compare", "--policies",
                        f"model_based,imitation:{out / 'ppo_sbar.zip'}", "--scenarios", "nominal", "--episodes", "2",
                        "--no-plot", "--no-frontier", "--format", "json", "--no-progress"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)["rows"]
    assert len(rows) == 2 and all(np.isfinite(row["return"]) for row in rows)
    for bad in (["--history", "0"], ["--imitate", "nonsense"], ["--action-filter", "1.5"]):
        r = subprocess.run(cmd[:-2] + bad + ["--out", str(tmp_path / "bad")], capture_output=True, text=True)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert not (tmp_path / "bad").exists()


def test_td3_with_filtered_actions_trains_and_runs_the_same_filter(tmp_path):
    """``train --algo td3 --action-filter 0.5``: the policy applies the filter at inference (its duty is
    0.5 last duty + 0.5 the network's), read from the metadata."""
    from policies.rl import RLPolicy
    from policies.train import train

    res = train("td3", 600, tmp_path, n_envs=8, scenario="nominal", progress=False, action_filter=0.5,
                smooth_penalty=5.0, eval_every=10**9, checkpoint_every=10**9,
                hyperparams={"learning_starts": 200, "gradient_steps": 1})
    pol = RLPolicy(path=res["model"])
    assert pol.action_filter == 0.5
    obs = np.zeros((3, OBS_DIM), np.float32)
    obs[:, OBS_INDEX["last_d_short"]] = [-1.0, 0.0, 1.0]   # last duty 0, 0.5, 1
    pol.reset(3)
    raw = RLPolicy(path=res["model"])
    raw.action_filter = 0.0
    raw.reset(3)
    np.testing.assert_allclose(pol.act(obs), 0.5 * np.array([0.0, 0.5, 1.0]) + 0.5 * raw.act(obs), atol=1e-6)


def _actor_state(zip_path):
    import stable_baselines3 as sb3
    pol = sb3.PPO.load(str(zip_path), device="cpu").policy
    return {k: v.detach().numpy().copy() for k, v in pol.state_dict().items()
            if k.startswith(("mlp_extractor.policy_net", "action_net", "log_std"))}


def test_train_imitate_then_ppo_keeps_the_clone_and_records_the_log_std_ppo_starts_from(tmp_path):
    """``train --imitate T --timesteps N > 0`` keeps the clone as ``clone.zip`` / ``clone.json`` /
    ``clone_vecnormalize.pkl`` (weights and normalisation identical to an imitation-only run of the same
    seed), writes the fine-tuned model to ``ppo_sbar.zip`` (moved away from the clone), and its metadata's
    ``log_std_init`` is the clone's ``log_std`` (-2.5), not the hyperparameters' -1.5 it never used."""
    import json
    import pickle

    from policies.train import train

    kw = dict(n_envs=8, scenario="nominal", progress=False, env={"n_steps": 40}, imitate="model_based_budget:0.05",
              imitation_episodes=2, imitation_epochs=2, imitation_mask=FEEDFORWARD, seed=3, eval_every=10**9,
              checkpoint_every=10**9, hyperparams={"n_steps": 64, "batch_size": 128,
                                                   "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -1.5}})
    only = train("ppo", 0, tmp_path / "only", **kw)
    res = train("ppo", 1024, tmp_path / "ft", **kw)
    ft = tmp_path / "ft"
    assert res["clone"] == ft / "clone.zip" and res["model"] == ft / "ppo_sbar.zip"
    clone, alone, tuned = (_actor_state(p) for p in (ft / "clone.zip", only["model"], ft / "ppo_sbar.zip"))
    for k in clone:
        np.testing.assert_array_equal(clone[k], alone[k])
    assert any(not np.array_equal(clone[k], tuned[k]) for k in clone)   # PPO did update the fine-tuned one
    c_meta, t_meta = (json.loads((ft / f"{n}.json").read_text()) for n in ("clone", "ppo_sbar"))
    assert c_meta["timesteps"] == 0 and t_meta["timesteps"] == 1024 and t_meta["imitation"]["clone"] == "clone.zip"
    start = float(clone["log_std"].mean())
    assert start == pytest.approx(-2.5)
    assert t_meta["policy_kwargs"]["log_std_init"] == pytest.approx(start)
    assert c_meta["policy_kwargs"]["log_std_init"] == pytest.approx(start)
    with open(ft / "clone_vecnormalize.pkl", "rb") as f1, open(only["vecnormalize"], "rb") as f2:
        np.testing.assert_array_equal(pickle.load(f1).obs_rms.mean, pickle.load(f2).obs_rms.mean)
    np.testing.assert_allclose(c_meta["obs_norm"]["mean"], json.loads(only["meta"].read_text())["obs_norm"]["mean"])


def test_masked_fields_stay_invisible_after_ppo_fine_tuning(tmp_path):
    """``--imitation-mask`` holds through PPO: after fine-tuning, the actions of the fine-tuned model do not
    depend on the masked fields at all (bit-identical when only they change, in ``RLPolicy``'s numpy actor,
    its SB3 ``predict`` path, the stacked seed rows of ``policies.batched`` and ``PPO.load`` +
    ``VecNormalize.load``), while they do depend on an unmasked field; the masked fields' statistics stay
    the clone's. (Before the mask was kept, PPO's running statistics let them back in, attenuated ~1/sqrt(var).)"""
    import json

    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import VecNormalize

    from envs.sb3_vec import SbarSB3VecEnv
    from policies.batched import StackedRL
    from policies.rl import RLPolicy
    from policies.train import train

    kw = dict(n_envs=8, scenario="nominal", progress=False, env={"n_steps": 40}, imitate="model_based_budget:0.05",
              imitation_episodes=2, imitation_epochs=2, imitation_mask=FEEDFORWARD, seed=4, eval_every=10**9,
              checkpoint_every=10**9, hyperparams={"n_steps": 64, "batch_size": 128, "n_epochs": 4})
    res = train("ppo", 2048, tmp_path / "ft", **kw)
    c_meta, t_meta = (json.loads((tmp_path / "ft" / f"{n}.json").read_text()) for n in ("clone", "ppo_sbar"))
    idx = [OBS_INDEX[f] for f in FEEDFORWARD]
    rng = np.random.default_rng(1)
    obs = rng.uniform(-1.0, 1.0, (16, OBS_DIM)).astype(np.float32)
    moved = obs.copy()
    moved[:, idx] += rng.uniform(-3.0, 3.0, (16, len(idx))).astype(np.float32)   # the hidden currents, far apart
    other = obs.copy()
    other[:, OBS_INDEX["charge_cmd_a"]] += 0.5
    for fast in (True, False):
        pol = RLPolicy(path=res["model"], fast=fast)
        d = pol.act(obs)
        np.testing.assert_array_equal(pol.act(moved), d)
        assert not np.array_equal(pol.act(other), d)   # the test can fail: a visible field does move the duty
    stacked = StackedRL([RLPolicy(path=res["model"]), RLPolicy(path=res["model"])])
    stacked.reset(16)
    both = stacked.act(np.concatenate([obs, obs]))   # (the stacked matmul may differ from one actor's by 1 ulp)
    np.testing.assert_array_equal(stacked.act(np.concatenate([moved, moved])), both)
    model = sb3.PPO.load(str(res["model"]), device="cpu")
    vn = VecNormalize.load(str(res["vecnormalize"]), SbarSB3VecEnv(1, "nominal", _cfg()))
    vn.training = False
    a, _ = model.predict(vn.normalize_obs(obs), deterministic=True)
    b, _ = model.predict(vn.normalize_obs(moved), deterministic=True)
    np.testing.assert_array_equal(a, b)
    assert t_meta["obs_norm"]["masked"] == sorted(idx)
    np.testing.assert_array_equal(np.take(t_meta["obs_norm"]["var"], idx), np.take(c_meta["obs_norm"]["var"], idx))
