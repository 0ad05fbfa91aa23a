"""What an RL researcher new to dronewpt found using it from Python (docs/robustness.md, "An RL researcher's
pass over the Python API"; every case tried is in that session's notes, kept outside the repository). Each test fails on
the code before its fix: a bad input gave a silent wrong number, numpy's message or an AttributeError deep
inside; now one line naming the value and what is valid, or the convenience the user reached for works."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import policies
from envs import ENV_ID, EnvConfig, RewardWeights, Scenario, SbarChargingEnv, SbarChargingVectorEnv
from envs.charging import SbarChargingDiscreteEnv
from envs.vector import SbarChargingDiscreteVectorEnv
from mission_sim.contract import OBS_INDEX, denormalise_obs

ENVELOPE = EnvConfig(link_model="envelope", n_steps=40)   # cheap windows; the checks are before the step


def _rollout(env, actions, seed=5, options=None):
    obs, _ = env.reset(seed=seed, options=options)
    out = [obs]
    rewards = []
    for a in actions:
        obs, r, _, _, _ = env.step(a)
        out.append(obs)
        rewards.append(r)
    return np.array(out), np.array(rewards)


# ------------------------------------------------------------------ actions of a single env
@pytest.mark.parametrize("action, shown", [
    (np.array([0.1, 0.5]), "action=array of shape (2,), dtype float64"),   # was: 0.1 used, 0.5 dropped silently
    (np.zeros((2, 1)), "action=array of shape (2, 1), dtype float64"),    # (the repr spans lines)
    (np.zeros(100), "action=array of shape (100,), dtype float64"),
    (np.zeros(0), "array([]"),                      # was: IndexError
    (None, "action=None"),                          # was: "action=nan is invalid"
    ("0.5", "action='0.5'"),                        # was: taken as 0.5
    (np.array(["0.5"]), "action=array(['0.5'], dtype='<U3')"),   # was: taken as 0.5 (float() of .item())
    (np.str_("0.5"), "action=np.str_('0.5')"),                   # idem
    (np.array(["0.5"], dtype=object), "action=array(['0.5'], dtype=object)"),   # idem
    (np.array([0.3 + 1j]), "0.3+1.j"),              # was: ComplexWarning, imaginary part dropped
])
def test_single_env_refuses_an_action_that_is_not_one_number(action, shown):
    env = SbarChargingEnv(config=ENVELOPE)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="one number in \\[-1, 1\\], shape \\(1,\\)") as err:
        env.step(action)
    assert shown in str(err.value)
    assert "\n" not in str(err.value)


def test_single_env_takes_one_number_in_any_container_alike():
    acts = [0.25, np.float32(0.25), np.array([0.25]), [0.25], np.array([[0.25]], np.float32)]   # 0.25: exact in float32
    ref = _rollout(SbarChargingEnv(config=ENVELOPE), [np.array([0.25], np.float32)] * 5)
    for a in acts:
        got = _rollout(SbarChargingEnv(config=ENVELOPE), [a] * 5)
        assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])


@pytest.mark.parametrize("action", [0.5, float("nan"), 2, -1, np.array([0, 1]), None, "1", np.zeros((2, 1)),
                                    np.zeros(100)])
def test_discrete_env_refuses_anything_but_0_or_1(action):
    env = SbarChargingDiscreteEnv(config=ENVELOPE)   # was: 0.5 taken as 0 (int()), NaN numpy's message
    env.reset(seed=0)
    with pytest.raises(ValueError, match="valid values: 0 \\(RM\\), 1 \\(SM\\)") as err:
        env.step(action)
    assert "\n" not in str(err.value)


def test_discrete_env_takes_0_and_1_in_any_container_alike():
    ref = _rollout(SbarChargingDiscreteEnv(config=ENVELOPE), [1, 0, 1, 1])
    for one, zero in ((np.int64(1), np.int64(0)), (1.0, 0.0), (np.array(1), np.array(0)), (np.array([1]), [0]),
                      (True, False)):
        got = _rollout(SbarChargingDiscreteEnv(config=ENVELOPE), [one, zero, one, one])
        assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])


# ------------------------------------------------------------------ actions of a vector env
@pytest.mark.parametrize("cls", [SbarChargingVectorEnv, SbarChargingDiscreteVectorEnv])
@pytest.mark.parametrize("shape", [(2, 1), (3, 2), (6,), (), (1, 3), (3, 1, 1)])   # the last two: size 3, was taken
def test_vector_env_names_actions_of_the_wrong_shape(cls, shape):
    env = cls(3, config=ENVELOPE)   # was: "cannot reshape array of size 2 into shape (3,)"
    env.reset(seed=0)
    with pytest.raises(ValueError, match=f"actions of shape {shape!r}".replace("(", "\\(").replace(")", "\\)")
                       + " are invalid; valid: one per sub-environment, shape \\(3, 1\\) or \\(3,\\)"):
        env.step(np.zeros(shape))


def test_vector_env_names_actions_that_are_not_numbers():
    env = SbarChargingVectorEnv(2, config=ENVELOPE)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="actions=None are invalid; valid: real numbers"):
        env.step(None)   # was: "cannot reshape array of size 1 into shape (2,)"
    for cls in (SbarChargingVectorEnv, SbarChargingDiscreteVectorEnv):   # one line for an array of strings too
        env = cls(2, config=ENVELOPE)
        env.reset(seed=0)
        with pytest.raises(ValueError, match="actions=array of shape \\(2, 1\\), dtype <U3 are invalid") as err:
            env.step(np.array([["0.5"], ["0.1"]]))
        assert "\n" not in str(err.value)


# ------------------------------------------------------------------ reset options, scenarios
@pytest.mark.parametrize("make", [lambda: SbarChargingEnv(config=ENVELOPE),
                                  lambda: SbarChargingVectorEnv(2, config=ENVELOPE)])
def test_reset_options_that_are_not_a_dict(make):
    with pytest.raises(ValueError, match="options='windy' is invalid; valid: None or a dict"):
        make().reset(seed=0, options="windy")   # was: "reset option 'd' is invalid" (the string iterated)


def test_a_scenario_range_may_be_one_number():
    assert Scenario(soc=0.3) == Scenario(soc=(0.3, 0.3))   # was: TypeError 'float' object is not iterable
    a = _rollout(SbarChargingEnv(scenario={"soc": 0.3, "cmd_a": 4}, config=ENVELOPE), [np.zeros(1)] * 5)
    b = _rollout(SbarChargingEnv(scenario={"soc": (0.3, 0.3), "cmd_a": (4, 4)}, config=ENVELOPE), [np.zeros(1)] * 5)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert denormalise_obs(a[0][0])[OBS_INDEX["soc"]] == pytest.approx(0.3, abs=1e-6)


@pytest.mark.parametrize("value", [(0.1, 0.2, 0.3), "low", None])
def test_a_scenario_range_of_another_kind_is_named(value):
    with pytest.raises(ValueError, match="scenario soc=.* is invalid; valid: a number or a \\(low, high\\) pair"):
        Scenario(soc=value)


# ------------------------------------------------------------------ EnvConfig and the reward weights
@pytest.mark.parametrize("kw, text", [
    (dict(i_ref_a=0.0), "reward i_ref_a=0.0 is invalid; valid range: \\(0, inf\\) A"),   # was: ZeroDivisionError
    (dict(i_ref_a=-7.0), "reward i_ref_a=-7.0 is invalid"),                               # was: accepted
    (dict(tracking=float("nan")), "reward tracking=nan is invalid; valid range: \\[0, inf\\)"),  # was: NaN rewards
    (dict(overcurrent=-10.0), "reward overcurrent=-10.0 is invalid"),
    (dict(overcurrent="10"), "reward overcurrent='10' is invalid"),
])
def test_reward_weights_are_checked(kw, text):
    with pytest.raises(ValueError, match=text):
        RewardWeights(**kw)


def test_reward_weights_take_numpy_and_torch_scalars():
    """A 0-d array or a torch scalar is one real number (they worked before the weights were checked; a narrow
    isinstance list refused them): the same weights as the float, stored as it."""
    torch = pytest.importorskip("torch")
    ref = RewardWeights(overcurrent=20.0, i_ref_a=7.5)
    for oc, ir in ((np.array(20.0), np.float32(7.5)), (torch.tensor(20.0), torch.tensor(7.5, dtype=torch.float64)),
                   (np.int64(20), 7.5)):
        w = RewardWeights(overcurrent=oc, i_ref_a=ir)
        assert w == ref and type(w.overcurrent) is float and type(w.i_ref_a) is float
    with pytest.raises(ValueError, match="reward overcurrent=array of shape \\(2,\\), dtype float64 is invalid"):
        RewardWeights(overcurrent=np.array([20.0, 1.0]))
    with pytest.raises(ValueError, match="reward tracking=True is invalid; valid range: \\[0, inf\\)"):
        RewardWeights(tracking=True)


@pytest.mark.parametrize("kw, text", [
    (dict(soc=("0.1", "0.2")), "scenario soc=\\('0.1', '0.2'\\) is invalid; valid: a number or a \\(low, high\\) pair"),
    (dict(i2_noise_a="0.1"), "i2_noise_a='0.1' is invalid; valid range: \\[0, inf\\)"),   # was: numpy's TypeError
    (dict(hover_power_w=[1.0, 2.0]), "hover_power_w=\\[1.0, 2.0\\] is invalid; valid range: \\[0, inf\\)"),
])
def test_scenario_numbers_are_real_numbers(kw, text):
    """The scenario's numbers as the config's and the actions' (one test of a real number, not a string)."""
    with pytest.raises(ValueError, match=text):
        Scenario(**kw)
    assert Scenario(soc=np.array(0.3), cmd_a=(np.float32(4.0), 5)) == Scenario(soc=(0.3, 0.3), cmd_a=(4.0, 5.0))


def test_config_may_be_a_dict_of_its_fields():
    """``gymnasium.make(ENV_ID, config={...})`` as a YAML file of env kwargs gives it (was: AttributeError
    'dict' object has no attribute 'n_steps'); the same env as with the EnvConfig."""
    cfg = {"link_model": "envelope", "n_steps": 40, "reward": {"overcurrent": 20.0}}
    env = gym.make(ENV_ID, config=cfg)
    assert env.unwrapped.config == EnvConfig(link_model="envelope", n_steps=40, reward=RewardWeights(overcurrent=20.0))
    acts = [np.array([a], np.float32) for a in np.linspace(-1, 1, 40)]
    ref = _rollout(SbarChargingEnv(config=EnvConfig(link_model="envelope", n_steps=40,
                                                    reward=RewardWeights(overcurrent=20.0))), acts)
    got = _rollout(env, acts)
    assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])
    venv = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", config=cfg)
    assert venv.config == env.unwrapped.config


@pytest.mark.parametrize("config, text", [
    ({"link_modle": "envelope"}, "config key 'link_modle' is invalid; valid keys: link, dt_s"),
    ({"reward": {"overcurent": 1}}, "reward key 'overcurent' is invalid; valid keys: tracking, overcurrent, i_ref_a"),
    ("envelope", "config='envelope' is invalid; valid: an envs.EnvConfig, a dict of its fields or None"),
    ({"link": None}, "link=None is invalid; valid: a wpt_receiver.LinkParams"),   # was: AttributeError
    ({"reward": 7.0}, "reward=7.0 is invalid; valid: an envs.RewardWeights or a dict"),
])
def test_a_bad_config_is_named(config, text):
    with pytest.raises(ValueError, match=text):
        SbarChargingEnv(config=config)


@pytest.mark.parametrize("config, text", [
    ({"dt_s": "1e-4"}, "dt_s='1e-4' is invalid; valid range: \\[1e-07, 0.01\\] s; a number, not a string \\(YAML"),
    ({"rated_i2_a": "15"}, "rated_i2_a='15' is invalid; valid range: \\(0, inf\\) A; a number"),
    ({"bus_c_f": None}, "bus_c_f=None is invalid; valid range: \\(0, inf\\) F"),
    ({"n_steps": 40.5}, "n_steps=40.5 is invalid; valid range: integer 2..1000000"),
    ({"slow_every": True}, "slow_every=True is invalid; valid range: integer >= 1"),
    ({"hold_tol_a": np.array([1e-3, 2e-3])}, "hold_tol_a=array of shape \\(2,\\), dtype float64 is invalid"),
])
def test_a_config_value_that_is_not_a_number_is_named(config, text):
    """As PyYAML gives a YAML file of env kwargs (``dt_s: 1e-4`` is the string "1e-4"); was numpy's TypeError from
    ``np.isfinite`` naming neither the key nor the range."""
    with pytest.raises(ValueError, match=text) as err:
        SbarChargingEnv(config=config)
    assert "\n" not in str(err.value)


def test_whole_number_config_fields_become_ints():
    """``n_steps: 40.0`` (YAML, JSON) passed the check and crashed the env's build; now the same env as 40."""
    cfg = EnvConfig(link_model="envelope", n_steps=40.0, slow_every=np.int64(10), v2_updates=0.0,
                    v2_refine_levels=np.float64(3), rated_i2_a=np.float32(15.0))
    assert cfg == EnvConfig(link_model="envelope", n_steps=40) and repr(cfg) == repr(EnvConfig(link_model="envelope",
                                                                                               n_steps=40))
    assert [type(getattr(cfg, k)) for k in ("n_steps", "slow_every", "v2_updates", "v2_refine_levels", "rated_i2_a")] \
        == [int, int, int, int, float]
    acts = [np.array([a], np.float32) for a in np.linspace(-1, 1, 40)]
    got = _rollout(SbarChargingEnv(config={"link_model": "envelope", "n_steps": 40.0}), acts)
    ref = _rollout(SbarChargingEnv(config=ENVELOPE), acts)
    assert np.array_equal(got[0], ref[0]) and np.array_equal(got[1], ref[1])


# ------------------------------------------------------------------ one's own policy through compare's loop
@pytest.fixture
def registered():
    names = []

    def register(name, factory):
        policies.register(name, factory)
        names.append(name)
    yield register
    for n in names:
        policies._REGISTRY.pop(n, None)


class _Returns:
    """A policy whose act returns ``value(n)`` for n observation rows."""

    def __init__(self, value, name):
        self.value, self.name = value, name

    def reset(self, n=1):
        pass

    def act(self, obs):
        return self.value(len(obs))


@pytest.mark.parametrize("value, text", [
    (lambda n: np.zeros(n + 1), "policy 'wrong_shape': act\\(\\) returned shape \\(3,\\); valid: \\(2,\\)"),
    (lambda n: 1.0, "policy 'wrong_shape': act\\(\\) returned shape \\(\\); valid: \\(2,\\)"),
    (lambda n: np.full(n, np.nan), "policy 'wrong_shape': act\\(\\) returned a duty nan; valid: finite duties"),
])
def test_run_policy_names_a_policy_whose_act_is_wrong(registered, value, text):
    from policies.compare import run_policy
    registered("wrong_shape", lambda ctx, **kw: _Returns(value, "wrong_shape"))
    with pytest.raises(ValueError, match=text):   # was: numpy's reshape message / the env's "actions[0]=nan"
        run_policy("wrong_shape", "nominal", 2, 1000, ENVELOPE)


def test_compare_names_a_policy_object_given_for_a_name():
    from policies.compare import compare, run_policies
    pol = _Returns(lambda n: np.zeros(n), "mine")
    for call in (lambda: compare(policies=[pol], scenarios=["nominal"], episodes=2, config=ENVELOPE),
                 lambda: run_policies([pol], "nominal", 2, 1000, ENVELOPE)):
        with pytest.raises(ValueError, match="valid: a policies.make name .* policies.register\\(NAME, factory\\)"):
            call()   # was: AttributeError 'Mine' object has no attribute 'partition'


def test_ones_own_registered_policy_runs_the_loop_a_single_env_runs(registered):
    """``policies.register`` + ``run_policy`` (compare's closed loop) == the same policy by hand on a single env."""
    from policies.compare import run_policy

    class AfterStopShort:
        name = "after_stop_short"

        def __init__(self, ctx=None, **kw):
            pass

        def reset(self, n=1):
            pass

        def act(self, obs):
            return np.where(np.asarray(obs)[:, 7] > -1.0, 1.0, 0.3)

    registered("after_stop_short", AfterStopShort)
    tr = run_policy("after_stop_short", "nominal", 2, 1000, ENVELOPE)
    for w in range(2):
        env = SbarChargingEnv(config=ENVELOPE)
        obs, _ = env.reset(seed=1000 + w)
        pol = AfterStopShort()
        pol.reset(1)
        total = 0.0
        for _ in range(ENVELOPE.n_steps):
            d = pol.act(obs[None, :])
            obs, r, _, _, _ = env.step(np.array([2.0 * d[0] - 1.0], np.float32))
            total += r
        assert tr.metrics["return"][w] == pytest.approx(total, rel=1e-12, abs=1e-12)


def test_a_shipped_models_env_config_makes_its_env():
    """A trained model's metadata ``env_config`` (``policies.train.config_dict``) is a dict of EnvConfig fields:
    ``gymnasium.make(ENV_ID, config=meta["env_config"])`` is the env it was trained on (was: AttributeError)."""
    import json
    from pathlib import Path

    from policies.train import config_dict

    files = sorted((Path(policies.__file__).parent / "pretrained").glob("*.json"))
    assert len(files) >= 20
    for f in files:
        ec = json.loads(f.read_text())["env_config"]
        env = gym.make(ENV_ID, config=ec)
        assert config_dict(env.unwrapped.config) == ec
        assert env.unwrapped.config.link_model == "envelope"   # every shipped SB3 model: trained on eq. 4 (docs/rl.md)


@pytest.mark.parametrize("doc, after, first", [("docs/envs.md", None, None), ("docs/rl.md", None, 1),
                                               ("docs/rl.md", "### From Python", 1)])
def test_the_docs_python_snippets_run_as_written(doc, after, first, monkeypatch):
    """Every ```python block of docs/envs.md, the first of docs/rl.md and its "From Python" one run in a fresh
    namespace as pasted (two of docs/envs.md used ``gymnasium`` without importing it: NameError)."""
    import re
    from pathlib import Path

    from envs.scenario import SCENARIOS
    monkeypatch.setattr("envs.scenario.SCENARIOS", dict(SCENARIOS))   # a snippet registers a scenario
    monkeypatch.setattr(policies, "_REGISTRY", dict(policies._REGISTRY))   # one registers a policy
    text = (Path(__file__).resolve().parents[1] / doc).read_text()
    if after:
        text = text[text.index(after):]
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)[:first]
    assert blocks
    for code in blocks:
        exec(compile(code, doc, "exec"), {"__name__": "snippet"})


def _train_env(monkeypatch, env):
    """The ``env`` overrides ``policies.train.train(..., env=env)`` hands on (stopped before training)."""
    from policies import train as tr

    seen = {}

    def spec(algo, timesteps, opts):
        seen.update(opts)
        raise RuntimeError("stop before training")
    monkeypatch.setattr(tr, "_spec", spec)
    with pytest.raises(RuntimeError, match="stop before training"):
        tr.train("ppo", 1000, "unused", env=env, progress=False)
    return seen["env"]


def test_train_takes_an_env_config(monkeypatch):
    """``policies.train.train(..., env=EnvConfig(...))`` (was: TypeError 'EnvConfig' object is not iterable): the
    config becomes train's flat overrides, which rebuild the same EnvConfig."""
    from policies import train as tr

    cfg = EnvConfig(link_model="envelope", n_steps=200, devices="ideal", reward=RewardWeights(overcurrent=20.0))
    flat = tr.env_overrides(cfg)
    assert flat == {"n_steps": 200, "devices": "ideal", "link_model": "envelope", "overcurrent": 20.0}
    assert tr.env_config(flat) == cfg
    assert tr.env_overrides(EnvConfig()) == {} and tr.env_config({}) == EnvConfig()
    assert _train_env(monkeypatch, cfg) == flat
    with pytest.raises(ValueError, match="env='envelope' is invalid; valid: None, an envs.EnvConfig or a dict"):
        tr.train("ppo", 1000, "unused", env="envelope", progress=False)


def test_train_takes_a_models_metadata_env_config(monkeypatch):
    """``train(env=meta["env_config"])``, the nested form the envs, compare and the oracle take (was: "env config key
    'reward' is invalid"): the same flat overrides as the EnvConfig it makes."""
    import json
    from pathlib import Path

    from envs.core import as_config
    from policies import train as tr

    meta = json.loads((Path(policies.__file__).parent / "pretrained" / "ppo_lagrangian_s0.json").read_text())
    ec = dict(meta["env_config"], reward={**meta["env_config"]["reward"], "overcurrent": 20.0}, n_steps=200)
    assert tr.env_overrides(ec) == tr.env_overrides(as_config(ec)) == {"n_steps": 200, "link_model": "envelope",
                                                                      "overcurrent": 20.0}
    assert tr.env_config(tr.env_overrides(ec)) == as_config(ec)
    assert tr.env_config(_train_env(monkeypatch, meta["env_config"])) == as_config(meta["env_config"])
    with pytest.raises(ValueError, match="config key 'overcurrent' is invalid"):   # both forms at once: named
        tr.env_overrides({"reward": {}, "overcurrent": 20.0})


def test_a_learned_policy_refuses_a_stacked_observation():
    """An env made with ``history=4`` returns 32 values (four frames, oldest first); the shipped PPO given them
    read the first 8, the *oldest* frame, silently (``RLPolicy.normalise`` keeps the first ``obs_dim`` fields, for
    7-field models). Now one line; the classical policies already refused (numpy's broadcast error)."""
    pytest.importorskip("stable_baselines3")
    env = SbarChargingEnv(config=ENVELOPE, history=4)
    obs, _ = env.reset(seed=1000)
    pol = policies.make("rl", env.policy_context)
    pol.reset(1)
    with pytest.raises(ValueError, match="observations of shape \\(1, 32\\) are invalid; valid: \\(n, 8\\), one "
                       "contract frame per row, or \\(n, 9\\) for a residual's input"):   # (n, 9) is taken: say so
        pol.act(obs[None, :])
    frame = SbarChargingEnv(config=ENVELOPE)
    one, _ = frame.reset(seed=1000)
    np.testing.assert_array_equal(obs[-8:], one)   # the newest frame is the plain env's observation
    assert pol.act(one[None, :]).shape == (1,)


def test_an_sb3_model_of_ones_own_runs_as_rl_path(tmp_path):
    """A PPO trained in one's own script (``model.save``) has no metadata JSON: ``policies.make("rl:PATH")`` said only
    "written by `dronewpt train`"; now it says what the JSON needs, and with that JSON (``obs_norm`` from
    ``policies.obs_mask.obs_norm_meta``) the policy acts as ``model.predict`` on the VecNormalize'd observation."""
    pytest.importorskip("stable_baselines3")
    import json

    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from envs.sb3_vec import SbarSB3VecEnv
    from policies.obs_mask import obs_norm_meta

    venv = VecNormalize(SbarSB3VecEnv(4, scenario="nominal", config=ENVELOPE))
    venv.reset()
    for _ in range(30):   # some statistics
        venv.step(np.random.default_rng(0).uniform(-1, 1, (4, 1)).astype(np.float32))
    model = PPO("MlpPolicy", venv, seed=0, device="cpu", n_steps=64, batch_size=64)
    path = tmp_path / "mine.zip"
    model.save(path)
    with pytest.raises(FileNotFoundError, match='for an SB3 model of your own, {"algo": "ppo", "control_period_s": '
                                                '0.0001} in that file, with "obs_norm"'):
        policies.make(f"rl:{path}")
    path.with_suffix(".json").write_text(json.dumps({"algo": "ppo", "control_period_s": 1e-4,
                                                     "obs_norm": obs_norm_meta(venv)}))
    pol = policies.make(f"rl:{path}")
    pol.reset(3)
    obs = np.random.default_rng(1).uniform(-1, 1, (3, 8)).astype(np.float32)
    a, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    np.testing.assert_allclose(pol.act(obs), np.clip((a[:, 0] + 1) / 2, 0, 1), rtol=0, atol=1e-6)   # numpy actor: 1 ulp


def test_compare_converts_a_dict_config_once_at_its_entry(monkeypatch):
    """compare() hands an EnvConfig to its runs (the split, the forked child, run_policies), not the dict given."""
    import policies.compare as pc

    seen = []
    monkeypatch.setattr(pc, "_compare_runs", lambda scenarios, groups, reference, episodes, seed, config, *a:
                        seen.append(config))
    pc.compare(policies=["ramp"], scenarios=["nominal"], episodes=2, config={"link_model": "envelope", "n_steps": 40},
               progress=False)
    assert seen == [ENVELOPE] and type(seen[0]) is EnvConfig


def test_compare_and_the_oracle_take_a_dict_config():
    """``compare(..., config={...})`` with the MPC among the policies (its forked-child split reads the link) and the
    oracle's duty replay (lru-cached on the config) took a dict as the envs do; they raised AttributeError
    ``'dict' object has no attribute 'link_model'`` / TypeError ``unhashable type: 'dict'``. Same rows as the EnvConfig."""
    pytest.importorskip("daqp")
    from policies.compare import compare
    from policies.oracle import policy_duties

    as_dict = {"link_model": "envelope", "n_steps": 160}
    cfg = EnvConfig(link_model="envelope", n_steps=160)
    rows_d, _ = compare(policies=["ramp", "mpc"], scenarios=["nominal"], episodes=2, config=as_dict)
    rows_c, _ = compare(policies=["ramp", "mpc"], scenarios=["nominal"], episodes=2, config=cfg)
    assert rows_d == rows_c
    np.testing.assert_array_equal(policy_duties("ramp", "nominal", 1000, as_dict), policy_duties("ramp", "nominal", 1000, cfg))


@pytest.mark.parametrize("n", [10**7, 10**12])
def test_a_vector_env_too_large_for_the_machine_is_refused_before_it_allocates(n, monkeypatch):
    """2026-11-27: ``SbarChargingVectorEnv(num_envs=10**7)`` allocated for seconds and ended in numpy's MemoryError;
    now one ValueError, before anything is allocated, naming the memory it would need and the largest num_envs that
    fits (the machine's memory set here: 16 GiB)."""
    from envs import vector
    monkeypatch.setattr(vector, "_physical_memory", lambda: 16 * 2**30)
    monkeypatch.setattr(vector.SbarChargingVectorEnv, "_alloc", lambda self, c, scenario: pytest.fail("allocated"))
    per = vector.BYTES_PER_ENV_STEP[EnvConfig().link_model] * (EnvConfig().n_steps + 1)
    with pytest.raises(ValueError) as e:
        SbarChargingVectorEnv(n, "random")
    assert str(e.value) == (f"num_envs={n:,} is invalid: it would need ~{n * per / 2**30:.3g} GiB of memory (~{per / 1e3:.0f} "
                            f"kB a sub-environment at n_steps={EnvConfig().n_steps}), more than this machine's 16 GiB; "
                            f"valid range: 1..{16 * 2**30 // per:,}")


@pytest.mark.parametrize("link", ["envelope", "modal"])
def test_the_vector_env_memory_estimate_is_what_a_reset_allocates(link):
    """The memory check's bytes per env and step (envs.vector.BYTES_PER_ENV_STEP) against what construction and the
    first reset allocate (tracemalloc's peak: numpy's arrays, the plans and a reset's temporaries), at two N, for the
    training scenario and the widest: at least the peak, at most 1.6x it (it was 96 B for both links, ~2.2x the modal
    link's peak; a review measured more than it for the envelope link). The warm-up resets each measured scenario
    once: the first detuned reset imports ``envs.detuned`` (and scipy's ``expm`` in its ``zoh_complex``), one-off
    allocations that depend on what the process ran before (CI, 2026-11-28: 199 B for the envelope link after other
    test files on the same worker; it passed alone)."""
    import gc
    import tracemalloc

    from envs import vector
    cfg = EnvConfig(link_model=link)
    for scenario in ("random", "detuned_wide"):   # (warm-up: compiled kernels, cached tables, lazy imports)
        SbarChargingVectorEnv(4, scenario, config=cfg).reset(seed=0)
    was = tracemalloc.is_tracing()   # (PYTHONTRACEMALLOC=1: on already, for the whole process; left on)
    if not was:
        tracemalloc.start()
    try:
        for n in (256, 2048):
            for scenario in ("random", "detuned_wide"):
                gc.collect()   # (the previous env, if a cycle keeps it, is freed now, not during this one's build)
                tracemalloc.reset_peak()
                start = tracemalloc.get_traced_memory()[0]   # (what was traced before: not this env's)
                SbarChargingVectorEnv(n, scenario, config=cfg).reset(seed=1)
                peak = (tracemalloc.get_traced_memory()[1] - start) / (n * (cfg.n_steps + 1))
                assert peak <= vector.BYTES_PER_ENV_STEP[link] <= 1.6 * peak, (n, scenario, peak)
    finally:
        if not was:
            tracemalloc.stop()


def test_the_vector_env_memory_estimate_has_one_figure_per_link_model():
    """BYTES_PER_ENV_STEP is keyed by link model (2026-11-27 midday): a link model added to envs.core.LINK_MODELS
    without its measured figure would be a KeyError in the memory check, one without a model a stale figure."""
    from envs import vector
    from envs.core import LINK_MODELS
    assert set(vector.BYTES_PER_ENV_STEP) == set(LINK_MODELS)


class _Allocating(Exception):
    pass


@pytest.mark.parametrize("unknown", ["None", "-1 pages"])
def test_a_large_vector_env_is_not_refused_where_the_machine_memory_is_unknown(unknown, monkeypatch):
    """The memory check is skipped where the system does not say how much memory there is (``os.sysconf`` returns -1
    when it does not know: the product, negative, refused every num_envs, even 1); the allocation (stubbed here) is
    reached."""
    import os

    from envs import vector
    if unknown == "None":
        monkeypatch.setattr(vector, "_physical_memory", lambda: None)
    else:
        sysconf = os.sysconf
        monkeypatch.setattr(os, "sysconf", lambda k: -1 if k == "SC_PHYS_PAGES" else sysconf(k))
        assert vector._physical_memory() is None

    def alloc(self, c, scenario):
        raise _Allocating
    monkeypatch.setattr(vector.SbarChargingVectorEnv, "_alloc", alloc)
    for n in (1, 10**7):
        with pytest.raises(_Allocating):
            SbarChargingVectorEnv(n, "random")


@pytest.mark.parametrize("n", [True, None, "3", 2.5, float("nan")])
def test_a_vector_env_size_that_is_not_a_whole_number_is_refused(n):
    """``num_envs=True`` made one env (``None`` was a TypeError); a whole float (4.0) is 4 envs as before."""
    with pytest.raises(ValueError, match=r"^num_envs=.* is invalid; valid range: integer >= 1$"):
        SbarChargingVectorEnv(n)
    assert SbarChargingVectorEnv(4.0).num_envs == 4
