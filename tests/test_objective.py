"""The objective of the domain (envs/objective.py): overshoot over the true link's short-mode I2,
the episode cost (per-step costs sum to it), and the reached-short-mode flag."""

import numpy as np
import pytest

from envs import EnvConfig, SbarChargingEnv, SbarChargingVectorEnv
from envs.objective import short_mode_i2_a
from mission_sim.contract import duty_to_action
from policies import make
from wpt_receiver import TABLE_I, steady_state
from wpt_receiver.devices import envelope_params, preset
from wpt_receiver.peak import SbarHarmonics

N, SEED = 16, 2024


def _run(policy, scenario="nominal", n=N, seed=SEED, devices="schottky"):
    """Run a policy (name, or callable obs -> duty) on ``n`` windows; returns per-step info arrays."""
    venv = SbarChargingVectorEnv(num_envs=n, scenario=scenario, config=EnvConfig(devices=devices))
    pol = make(policy, venv.policy_context) if isinstance(policy, str) else None
    if pol is not None:
        pol.reset(n)
    obs, info0 = venv.reset(seed=seed)
    rec = {k: [] for k in ("i2_peak_a", "i2_peak_envelope_a", "lm_h", "cost", "rect_current_a", "t_s")}
    for _ in range(venv.config.n_steps):
        d = pol.act(obs) if pol is not None else policy(obs)
        obs, _, _, _, info = venv.step(duty_to_action(d)[:, None].astype(np.float32))
        for k in rec:
            rec[k].append(info[k])
    out = {k: np.array(v) for k, v in rec.items()}
    out.update(t_stop_s=info0["t_stop_s"], final=info, dt=venv.config.dt_s, devices=venv.config.device_set())
    return out


def _overshoot_from_traces(r, key="i2_peak_a"):
    """Independent recomputation: steps whose start time is at or after the stop command; ``key`` the
    instantaneous peak (the env's objective) or ``"i2_peak_envelope_a"`` (the fundamental's)."""
    t_start = r["t_s"] - r["dt"]
    after = t_start >= r["t_stop_s"][None, :] - 1e-12
    ratio = np.abs(r[key]) / short_mode_i2_a(TABLE_I, r["lm_h"], r["devices"]) - 1.0
    return np.where(after, ratio, -np.inf).max(axis=0)


@pytest.mark.parametrize("name", ["step", "ramp", "model_based"])
def test_overshoot_is_peak_over_true_short_mode_current_and_costs_sum_to_it(name):
    r = _run(name, "lm_mismatch")
    ov = r["final"]["overshoot"]
    np.testing.assert_allclose(ov, _overshoot_from_traces(r), rtol=1e-12)
    np.testing.assert_allclose(r["cost"].sum(axis=0), np.maximum(ov, 0.0), atol=1e-12)
    np.testing.assert_allclose(r["final"]["episode_cost"], np.maximum(ov, 0.0), atol=1e-12)
    assert r["final"]["reached_short_mode"].all()   # all three end in SM within 14 ms


@pytest.mark.parametrize("devices", ["ideal", "schottky"])
def test_overshoot_orders_step_ramp_model_based(devices):
    """The paper's ordering: step rings to ~2x the SM current, the ramp a few %, the inverse ~0 on the
    envelope (the fundamental, the paper's claim). The instantaneous peak (the env's objective) adds
    the SBAR's harmonic ripple at the duty of the peak: up to 0.49 A at 11.5 A (4.3 %) at small
    duties, which the model-based transition passes through near its crest."""
    runs = {p: _run(p, devices=devices) for p in ("step", "ramp", "model_based")}
    inst = {p: float(np.mean(r["final"]["overshoot"])) for p, r in runs.items()}
    env = {p: float(np.mean(_overshoot_from_traces(r, "i2_peak_envelope_a"))) for p, r in runs.items()}
    assert inst["step"] > 0.8 > 0.02 < inst["ramp"] < 0.15
    assert env["step"] > 0.8 > 0.02 < env["ramp"] < 0.15
    assert abs(env["model_based"]) < 0.015
    assert env["model_based"] < inst["model_based"] < env["model_based"] + 0.045
    assert inst["model_based"] < inst["ramp"]


def test_a_policy_that_stays_in_rm_is_flagged_and_has_negative_overshoot():
    """Never reaching SM games the overshoot: in RM ``I2 = I2_sm (1 - R1 V2_rm / (w Lm V1))``, about
    3 % below the short-mode current with Table I, so the overshoot is negative and the cost 0; the
    flag catches it."""
    r = _run(lambda obs: np.zeros(len(obs)))
    assert not r["final"]["reached_short_mode"].any()
    p, dev = TABLE_I, r["devices"]
    # at Table I's VL: the RM envelope with the devices (clamp VL + Vf, R folded in), its instantaneous
    # peak (d = 0: + 0.1 A), over the short-mode current with the devices
    i2_rm = steady_state(envelope_params(p, dev), 4 / np.pi * (p.vl_v + dev.rect_vf_v))[1]
    expect = SbarHarmonics(p, dev).peak(0.0, i2_rm) / short_mode_i2_a(p, p.lm_h, dev) - 1.0
    np.testing.assert_allclose(r["final"]["overshoot"], expect, atol=0.002)   # VL is not exactly 30 V
    env_ratio = r["i2_peak_envelope_a"][-1] / short_mode_i2_a(p, r["lm_h"][-1], dev) - 1.0   # the fundamental
    np.testing.assert_allclose(env_ratio, i2_rm / short_mode_i2_a(p, p.lm_h, dev) - 1.0, atol=0.002)
    ideal = -p.r1_ohm * p.v2_rm_amp_v / (p.omega_rad_s * p.lm_h * p.v1_amp_v)   # the paper's circuit
    assert (env_ratio < ideal - 0.006).all()   # the drops and resistances lower RM's I2 by ~0.7 %
    assert (r["final"]["episode_cost"] == 0).all()


def test_dipping_below_the_threshold_now_and_then_is_not_short_mode():
    """SM must hold from t_stop + 14 ms on: toggling RM/SM every step fails although I_L dips to 0."""
    r = _run(lambda obs: (obs[:, 6] < 0).astype(float))   # alternate: d = 1 after a 0, 0 after a 1
    assert (r["rect_current_a"] < 0.5).any()
    assert not r["final"]["reached_short_mode"].any()


def test_single_env_reports_the_same_objective_as_the_vector_env():
    r = _run("model_based", "windy", n=3, seed=7)
    for i in range(3):
        env = SbarChargingEnv(scenario="windy")
        pol = make("model_based", env.policy_context)
        pol.reset(1)
        obs, _ = env.reset(seed=7 + i)
        costs = 0.0
        for _ in range(env.config.n_steps):
            obs, _, _, _, info = env.step(duty_to_action(pol.act(obs[None]))[:1].astype(np.float32))
            costs += info["cost"]
        assert info["overshoot"] == pytest.approx(r["final"]["overshoot"][i], rel=1e-9)
        assert info["reached_short_mode"] == bool(r["final"]["reached_short_mode"][i])
        assert costs == pytest.approx(max(info["overshoot"], 0.0), abs=1e-12)
