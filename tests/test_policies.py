"""Policies through the environment's closed loop: the paper's result, the online Lm estimator, ON-OFF, RL wrapper."""

import numpy as np
import pytest

from envs import EnvConfig, SbarChargingEnv
from mission_sim.contract import OBS_DIM, Policy, PolicyContext, duty_to_action
from policies import available, make
from policies.compare import run_policy
from policies.online import lm_from_steady_state
from _ripple import ripple_bound_pts
from wpt_receiver import TABLE_I, steady_state


def test_registry_and_protocol():
    assert {"step", "ramp", "model_based", "model_based_online", "hysteresis", "random", "rl"} <= set(available())
    for name in ("step", "ramp", "model_based", "model_based_online", "hysteresis", "random"):
        pol = make(name, PolicyContext(control_period_s=1e-4))
        assert isinstance(pol, Policy)
        pol.reset(3)
        d = pol.act(np.zeros((3, OBS_DIM)))
        assert d.shape == (3,) and np.all((d >= 0) & (d <= 1))


@pytest.mark.parametrize("devices", ["ideal", "schottky"])
def test_model_based_in_env_reproduces_no_overshoot(devices):
    """The core result in the env's closed loop (100 us control period, Lm from the coupling model,
    battery voltage from the ECM): the step overshoots by ~200 %, the ramp by ~6 %, the model-based
    controller's envelope (the paper's fundamental) by < 1 % (0.5 % is inter-sample ripple of V2
    held for 100 us, seen at mid-step), with the paper's ideal devices and with real ones. Its
    instantaneous peak (the env's objective) adds the SBAR's harmonic ripple at the duty of the
    crest: at most the largest excess over duties at 11.5 A and VL 33 V (tests/_ripple.py: 5.0 / 5.3
    points ideal / schottky, near d = 0.15). Eq. 4's link (pinned since the envs' default became the exact-mode
    link, 2026-11-26: the bounds here are eq. 4's, its envelope and its ripple table; on the modal link, whose
    peak is 2.85 % higher on the paper's ramp, the ramp overshoots 10.1 % with ideal devices; docs/rl.md has
    the modal link's numbers)."""
    cfg = EnvConfig(devices=devices, link_model="envelope")
    res = {p: run_policy(p, "nominal", 6, 100, cfg).metrics for p in ("step", "ramp", "model_based")}
    os_ = {p: float(np.mean(m["overshoot_pct"])) for p, m in res.items()}
    assert os_["step"] > 150.0
    assert 2.0 < os_["ramp"] < 10.0
    mb = res["model_based"]
    assert np.all(mb["envelope_overshoot_pct"] < 1.0)
    assert np.all(mb["envelope_overshoot_pct"] < mb["overshoot_pct"])
    assert np.all(mb["overshoot_pct"] < mb["envelope_overshoot_pct"] + ripple_bound_pts(devices))
    assert np.all(mb["time_above_rated_s"] == 0.0)
    assert np.all(mb["peak_i2_a"] < 1.055 * steady_state(TABLE_I, 0.0)[1])
    assert np.mean(res["step"]["peak_i2_a"]) > np.mean(res["ramp"]["peak_i2_a"]) > np.mean(res["model_based"]["peak_i2_a"])


def test_lm_inversion_is_exact():
    for lm in (4.8e-6, 6.25e-6, 8.1e-6):
        for v2 in (0.0, 20.0, 38.0):
            i2 = steady_state(TABLE_I, v2, lm_h=lm)[1]
            assert float(lm_from_steady_state(TABLE_I, i2, v2)) == pytest.approx(lm, rel=1e-9)


def test_online_estimator_converges_under_mismatch_and_rediscretises_rarely():
    env = SbarChargingEnv(scenario="lm_mismatch", config=EnvConfig(n_steps=300))
    pol = make("model_based_online", env.policy_context)
    errs = []
    for seed in range(4):
        obs, info = env.reset(seed=seed)
        pol.reset(1)
        pol.rebuilds = 0
        t_stop = info["t_stop_s"]
        while info["t_s"] < t_stop - 1e-3:
            d = pol.act(obs[None])[0]
            obs, _, _, _, info = env.step(np.array([duty_to_action(d)], np.float32))
        errs.append(abs(pol.lm_estimate_h[0] / info["lm_h"] - 1.0))
        assert pol.rebuilds < 20 and pol.rebuilds < 0.2 * info["t_s"] / env.config.dt_s   # on > 1 % moves only
    assert max(errs) < 0.03               # true Lm is 0.8 .. 1.25 x the assumed Table I value
    # and it is no worse than the fixed-model controller on the same windows (peak I2)
    fixed = run_policy("model_based", "lm_mismatch", 8, 7).metrics["peak_i2_a"]
    online = run_policy("model_based_online", "lm_mismatch", 8, 7).metrics["peak_i2_a"]
    assert np.mean(online) <= np.mean(fixed) + 0.05


def test_hysteresis_is_bang_bang_and_follows_the_command():
    tr = run_policy("hysteresis", "nominal", 6, 3)
    assert set(np.unique(tr.d_short)) <= {0.0, 1.0}
    charging = tr.charge_cmd_a > 0
    mean_il = np.array([tr.rect_current_a[charging[:, e], e].mean() for e in range(6)])
    mean_cmd = np.array([tr.charge_cmd_a[charging[:, e], e].mean() for e in range(6)])
    assert np.all(np.abs(mean_il - mean_cmd) < 0.4 * mean_cmd)       # biased low by the ringing, but follows
    assert np.corrcoef(mean_il, mean_cmd)[0, 1] > 0.8                # more command -> more current
    assert np.all(tr.d_short[~charging] == 1.0)                      # stop -> short mode
    assert np.mean(tr.metrics["overshoot_pct"]) > 100.0              # every RM -> SM switch rings


def test_rl_wrapper_on_the_shipped_policy():
    from policies.rl import PRETRAINED, RLPolicy, load_meta
    meta = load_meta(PRETRAINED)
    assert PRETRAINED.stat().st_size < 1_000_000
    assert meta["algo"] in ("ppo", "sac", "dqn") and meta["timesteps"] > 0 and "seed" in meta
    env = SbarChargingEnv()
    pol = make("rl", env.policy_context)
    obs, _ = env.reset(seed=0)
    pol.reset(2)
    d = pol.act(np.stack([obs, obs]))
    assert d.shape == (2,) and np.all((d >= 0) & (d <= 1)) and d[0] == pytest.approx(d[1], abs=1e-6)
    with pytest.raises(ValueError, match="control_period_s"):
        RLPolicy(PolicyContext(control_period_s=5e-5))
    with pytest.raises(FileNotFoundError, match="not found"):
        RLPolicy(env.policy_context, path="/nonexistent/model.zip")


def test_online_lm_policy_batched_equals_one_receiver_at_a_time():
    """The online-Lm policy steps all receivers' controllers at once (stacked state spaces); it must
    give exactly what independent single-receiver instances give, rebuilds included."""
    from mission_sim.contract import PolicyContext, normalise_obs
    from policies.online import OnlineLmModelBasedPolicy
    from wpt_receiver import TABLE_I, EnvelopeLink, v2_from_duty

    ctx = PolicyContext()
    lms = np.array([5e-6, 6.25e-6, 8e-6])
    n = len(lms)

    def run(pols):
        link = EnvelopeLink(TABLE_I, n)
        link.set_steady_state(TABLE_I.v2_rm_amp_v, lm_h=lms)
        d, outs = np.zeros(n), []
        for k in range(300):
            cmd = np.full(n, 6.0 if k < 120 else 0.0)
            i2 = link.i2
            il = 2 / np.pi * i2 * (1 - np.sin(np.pi / 2 * d))
            obs = normalise_obs(np.column_stack([i2, np.full(n, 30.0), il, il, np.full(n, 0.5), cmd, d, np.full(n, max(k - 120, 0) * 1e-4)]))
            d = np.concatenate([p.act(obs[j::len(pols)] if len(pols) > 1 else obs) for j, p in enumerate(pols)])
            outs.append(d)
            link.step(v2_from_duty(d, 30.0), ctx.control_period_s, lm_h=lms)
        return np.array(outs)

    batched = OnlineLmModelBasedPolicy(ctx)
    singles = [OnlineLmModelBasedPolicy(ctx) for _ in range(n)]
    np.testing.assert_allclose(run([batched]), run(singles), atol=1e-12)
    assert batched.rebuilds == sum(p.rebuilds for p in singles) > n  # Lm off nominal: estimates moved


def test_online_lm_policy_frozen_after_the_stop_reaches_short_mode_on_detuned_tanks():
    """Detuned tanks (C1, C2 off resonance): the steady-state inversion explains the collapsed RM current
    with an Lm several times nominal. After the stop the estimate and controller are frozen (no rebuild:
    a bumpless rebuild restarts the decay of V2), so V2 decays from the stop on and every window reaches
    short mode (window 1000 did not while rebuilds went on after the stop)."""
    from envs import SbarChargingVectorEnv
    from mission_sim.contract import OBS_INDEX, denormalise_obs
    from policies.online import OnlineLmModelBasedPolicy

    venv = SbarChargingVectorEnv(num_envs=2, scenario="detuned")
    pol = OnlineLmModelBasedPolicy(venv.policy_context)
    obs, _ = venv.reset(seed=1000)
    at_stop = None
    for _ in range(venv.config.n_steps):
        if at_stop is None and np.all(denormalise_obs(obs)[:, OBS_INDEX["charge_cmd_a"]] <= 0.0):
            at_stop = (pol.rebuilds, pol.lm_estimate_h)
        d = np.asarray(pol.act(obs), dtype=float)
        obs, _, _, _, info = venv.step((2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32))
    assert at_stop is not None
    assert np.all(info["reached_short_mode"])
    assert pol.rebuilds == at_stop[0]
    np.testing.assert_array_equal(pol.lm_estimate_h, at_stop[1])
    assert np.any(at_stop[1] > 1.5 * venv.policy_context.link.lm_h)   # the estimate ran off (the model is wrong)
