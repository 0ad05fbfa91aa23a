"""The envs used as any third-party gymnasium / stable-baselines3 env is, from Python, outside the CLI (a power user's
pass, 2026-11-27 evening; docs/envs.md, "Used as any gymnasium env"). Each fix's test fails on the tree before it
(main); the others guard what already worked."""

from __future__ import annotations

import copy
import pickle
import re
import warnings

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs import EnvConfig, SbarChargingEnv, SbarChargingVectorEnv

#: short windows: a copy taken mid-window, its end, and two more windows (the fault was in the windows after the copy)
SHORT = {"envelope": EnvConfig(link_model="envelope", n_steps=12), "modal": EnvConfig(link_model="modal", n_steps=12)}


def _actions(n, shape=(1,), seed=0):
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n,) + shape).astype(np.float32)


def _windows(env, acts, windows=3):
    """Every observation, reward, flag and info value of the current window's rest and ``windows - 1`` more."""
    out = []
    for w in range(windows):
        if w:
            obs, info = env.reset()
            out.append((obs, sorted(info.items(), key=str)))
        for a in acts:
            obs, r, term, trunc, info = env.step(a)
            out.append((obs, r, term, trunc, sorted(info.items())))
            if term or trunc:
                break
    return out


def _same(a, b) -> bool:
    return len(a) == len(b) and all(pickle.dumps(x) == pickle.dumps(y) for x, y in zip(a, b))


@pytest.mark.parametrize("link", ["envelope", "modal"])
@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
@pytest.mark.parametrize("env_id,kw", [(envs.ENV_ID, {"scenario": "random"}),
                                       (envs.DISCRETE_ENV_ID, {"scenario": "sense_delay", "history": 2})])
def test_a_copied_or_unpickled_env_continues_as_the_original(link, how, env_id, kw):
    """``copy.deepcopy(env)`` / a pickle round trip mid-window go on bit for bit, in the next windows too. Was: the
    copy's scenario part wrote each new window's command and I2 noise into arrays of its own (numpy views do not
    survive a copy), while its step read the copied rows of the window it was copied in: from the next reset on the
    copy was stepped on a stale command and noise, silently (first observation's field 0 and 5 differed)."""
    env = gym.make(env_id, config=SHORT[link], **kw)
    env.reset(seed=5)
    env.action_space.seed(1)
    acts = [env.action_space.sample() for _ in range(SHORT[link].n_steps)]
    for a in acts[:5]:
        env.step(a)
    twin = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    assert _same(_windows(env, acts), _windows(twin, acts))


def test_vector_env_seed_list_with_none_entries_as_sync_vector_env():
    """``reset(seed=[7, None, 9])`` (SyncVectorEnv's form: that sub-env's generator goes on) was
    ``TypeError: int() argument must be ... not 'NoneType'``; now the windows of gymnasium's SyncVectorEnv."""
    cfg = SHORT["envelope"]
    venv = SbarChargingVectorEnv(3, "random", cfg)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(envs.ENV_ID, scenario="random", config=cfg)] * 3)
    acts = _actions(2 * cfg.n_steps + 3, (3, 1))
    for seed in ([4, 5, 6], [7, None, 9], [None, None, None]):
        a, b = venv.reset(seed=seed)[0], sync.reset(seed=seed)[0]
        np.testing.assert_array_equal(a, b)
        for x in acts:   # through two autoresets
            np.testing.assert_array_equal(venv.step(x)[0], sync.step(x)[0])


@pytest.mark.parametrize("seed,text", [([1.5, 2, 3], r"seed\[0\]=1\.5 is invalid; valid range: integer 0\.\.4294967295"),
                                       ([1, -2, 3], r"seed\[1\]=-2 is invalid"),
                                       ([1, 2, True], r"seed\[2\]=True is invalid"),
                                       ([1, 2], r"seed has 2 entries; valid: one int or num_envs=3 ints")])
def test_vector_env_names_a_seed_list_entry_that_is_not_a_seed(seed, text):
    """A seed list's 1.5 was seed 1 and True seed 1, silently (gymnasium's own reset refuses both); -2 numpy's error."""
    venv = SbarChargingVectorEnv(3, config=SHORT["envelope"])
    with pytest.raises(ValueError, match=text):
        venv.reset(seed=seed)


@pytest.mark.parametrize("seed,text", [(True, "seed=True"), (1.5, r"seed=1\.5"), (-1, "seed=-1"), (2**32, "seed=4294967296"),
                                       (2**32 - 2, "seed=4294967294")])
def test_vector_env_checks_a_scalar_seed_as_a_seed_list(seed, text):
    """A scalar seed had none of the list form's checks: True was seed 1, 2**32 passed (its list form refused), 2**32 - 2
    gave sub-environment seeds above SEED_RANGE; now its seeds ``seed .. seed + num_envs - 1`` must all be seeds."""
    venv = SbarChargingVectorEnv(3, config=SHORT["envelope"])
    with pytest.raises(ValueError, match=text + r" is invalid; valid range: integer 0\.\.4294967293 \(sub-environment seeds "
                                                r"go up to seed \+ num_envs - 1, num_envs=3\)"):
        venv.reset(seed=seed)
    top = 2**32 - 3   # the last seed of three: the list form's seeds
    np.testing.assert_array_equal(venv.reset(seed=top)[0], venv.reset(seed=[top, top + 1, top + 2])[0])


def test_vector_env_takes_a_numpy_integer_seed():
    """``reset(seed=np.int64(3))`` raised gymnasium's 'Seed must be a python integer'; now seed 3."""
    venv = SbarChargingVectorEnv(3, config=SHORT["envelope"])
    want = venv.reset(seed=3)[0]
    np.testing.assert_array_equal(venv.reset(seed=np.int64(3))[0], want)
    np.testing.assert_array_equal(venv.reset(seed=np.uint32(3))[0], want)


@pytest.mark.parametrize("make", [lambda h: SbarChargingEnv(history=h), lambda h: SbarChargingVectorEnv(2, history=h)])
def test_history_true_is_refused(make):
    """``history=True`` was one frame, silently (as a bool is refused everywhere a number is asked for)."""
    with pytest.raises(ValueError, match=r"history=True is invalid; valid range: integer 1\.\.32"):
        make(True)
    assert make(np.int64(2)).observation_space.shape[-1] == 16   # numpy integers stay numbers


def test_the_docstring_names_the_info_key_of_the_overcurrent_term():
    """The Rewards section said ``info["cost"]`` carries the overcurrent term; ``cost`` is the overshoot's rise (it
    sums to ``episode_cost``), the overcurrent term is ``info["overcurrent"]``."""
    key = re.search(r'``info\["(\w+)"\]`` carries the overcurrent term', SbarChargingEnv.__doc__).group(1)
    env = SbarChargingEnv(scenario="random", config=EnvConfig(link_model="envelope"))
    env.reset(seed=7)
    rows = []
    for k in range(env.config.n_steps):   # bang-bang duties: the link rings above its rating
        info = env.step(np.array([1.0 if k % 7 < 3 else -1.0], np.float32))[4]
        rows.append((info[key], info["i2_peak_a"], info["cost"]))
    got, peak, cost = np.array(rows).T
    assert got.max() > 0.5
    np.testing.assert_allclose(got, np.maximum(0.0, peak / env.config.rated_i2_a - 1.0), rtol=0, atol=1e-12)
    assert cost.sum() == pytest.approx(info["episode_cost"], abs=1e-12)


# ----------------------------------------------------------------------------------------------- guards (pass on main)
@pytest.mark.parametrize("env_id", [envs.ENV_ID, envs.DISCRETE_ENV_ID])
def test_checkers_pass_on_eq4s_link_and_with_a_frame_stack(env_id):
    """tests/test_envs.py runs both checkers on the default link; here eq. 4's link and ``history=4``."""
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env
    for kw in ({"config": EnvConfig(link_model="envelope")}, {"history": 4}):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(gym.make(env_id, render_mode="rgb_array", **kw).unwrapped, skip_render_check=False)
            sb3_check_env(gym.make(env_id, **kw).unwrapped, warn=True)


def test_gymnasium_wrappers_and_vectorisers_give_the_envs_numbers():
    """The usual wrappers stack on the env; SyncVectorEnv, make_vec's three modes and the env's own vector env step
    the same windows (NEXT_STEP autoreset in each)."""
    from gymnasium.wrappers import (ClipAction, FlattenObservation, FrameStackObservation, NormalizeObservation,
                                    RecordEpisodeStatistics, RescaleAction, TimeLimit)
    cfg = SHORT["envelope"]
    env = RecordEpisodeStatistics(TimeLimit(NormalizeObservation(FlattenObservation(FrameStackObservation(
        ClipAction(RescaleAction(gym.make(envs.ENV_ID, config=cfg), np.float32(0), np.float32(1))), 3))), 5))
    env.reset(seed=0)
    for _ in range(5):
        obs, _, _, trunc, info = env.step(np.array([0.5], np.float32))
    assert obs.shape == (24,) and trunc and info["episode"]["l"] == 5
    acts = _actions(cfg.n_steps + 3, (2, 1))
    runs = []
    for mode in ("sync", "vector_entry_point"):
        venv = gym.make_vec(envs.ENV_ID, num_envs=2, vectorization_mode=mode, config=cfg)
        assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
        runs.append([venv.reset(seed=3)[0]] + [venv.step(a)[0] for a in acts])
        venv.close()
        venv.close()   # twice: nothing to close
    np.testing.assert_array_equal(np.array(runs[0]), np.array(runs[1]))


def test_a_reset_options_scenario_holds_for_the_windows_that_reset_starts_as_sync_vector_env():
    """``reset(options={"scenario": "battery"})`` on the vector env kept "battery" for every autoreset after it, where
    gymnasium's SyncVectorEnv over the single envs (and SB3's DummyVecEnv after ``set_options``) start the env's own
    scenario again (the single env's docstring: "for that episode only"); the two diverged at the first autoreset."""
    from stable_baselines3.common.env_util import make_vec_env

    from envs.sb3_vec import SbarSB3VecEnv
    cfg = SHORT["envelope"]
    venv = SbarChargingVectorEnv(2, "nominal", cfg)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(envs.ENV_ID, scenario="nominal", config=cfg)] * 2)
    acts = _actions(2 * cfg.n_steps + 3, (2, 1))
    np.testing.assert_array_equal(venv.reset(seed=1, options={"scenario": "battery"})[0],
                                  sync.reset(seed=1, options={"scenario": "battery"})[0])
    for x in acts:
        got, want = venv.step(x), sync.step(x)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[4]["soc"], want[4]["soc"])
    ours, dummy = SbarSB3VecEnv(2, "nominal", cfg), make_vec_env(envs.ENV_ID, 2, env_kwargs={"config": cfg})
    for vec in (ours, dummy):
        vec.seed(3)
        vec.set_options({"scenario": "battery"})
    np.testing.assert_array_equal(ours.reset(), dummy.reset())
    for x in acts:
        np.testing.assert_array_equal(ours.step(x)[0], dummy.step(x)[0])


def test_an_assigned_scenario_is_the_one_later_resets_and_autoresets_start():
    """``env.scenario = ...`` (SB3's ``set_attr``, a curriculum) was stored and ignored: the windows went on with the
    constructor's scenario. Now it sets the scenario part's default: resets without options, autoresets and
    ``restart`` start it, as an env built with it; a bad name is the constructor's message."""
    from envs.sb3_vec import SbarSB3VecEnv
    cfg = SHORT["envelope"]
    acts = _actions(2 * cfg.n_steps + 3, (3, 1))
    got, want = SbarChargingVectorEnv(3, "nominal", cfg), SbarChargingVectorEnv(3, "battery", cfg)
    got.reset(seed=1)
    got.scenario = "battery"
    assert got.scenario is want.scenario
    for a, b in zip(got.reset(seed=2), want.reset(seed=2)):
        assert _same(a, b)
    for x in acts:   # through two autoresets
        assert _same(got.step(x), want.step(x))
    np.testing.assert_array_equal(got.restart([1]), want.restart([1]))
    with pytest.raises(ValueError, match=r"^scenario='bogus' is invalid; valid values: nominal, "):
        got.scenario = "bogus"
    assert got.scenario is want.scenario
    ours, theirs = SbarSB3VecEnv(3, "nominal", cfg), SbarSB3VecEnv(3, "battery", cfg)   # SB3's set_attr forwards it
    ours.set_attr("scenario", "battery")
    ours.seed(5), theirs.seed(5)
    np.testing.assert_array_equal(ours.reset(), theirs.reset())
    for x in acts:
        assert _same(ours.step(x), theirs.step(x))
    single = SbarChargingEnv("nominal", config=cfg)   # the single env's too (gymnasium's set_attr)
    single.scenario = {"base": "battery"}
    assert _same(single.reset(seed=3), SbarChargingEnv("battery", config=cfg).reset(seed=3))


@pytest.mark.parametrize("history", [1, 3])
def test_a_partial_reset_with_reset_mask_is_sync_vector_envs(history):
    """gymnasium 1.x's partial reset, ``reset(options={"reset_mask": m})`` (SyncVectorEnv, AsyncVectorEnv and the
    vector wrappers take it): was ``reset option 'reset_mask' is invalid``; now the windows where ``m`` is True start
    (with their seeds, the options' scenario), the others go on, as SyncVectorEnv over the single envs."""
    cfg = SHORT["envelope"]
    venv = SbarChargingVectorEnv(3, "sense_delay", cfg, history=history)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make(envs.ENV_ID, scenario="sense_delay", config=cfg,
                                                      history=history)] * 3)
    np.testing.assert_array_equal(venv.reset(seed=1)[0], sync.reset(seed=1)[0])
    resets = {4: (None, {"scenario": "windy"}, [True, False, False]), 9: ([5, 6, 7], {}, [True, False, True]),
              15: (9, {}, [False, True, True])}
    for k, x in enumerate(_actions(2 * cfg.n_steps + 3, (3, 1))):
        got, want = venv.step(x), sync.step(x)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        if k in resets:
            seed, opts, m = resets[k]
            m = np.array(m)
            (obs, info), (obs_s, info_s) = (env.reset(seed=seed, options={"reset_mask": m, **opts})
                                            for env in (venv, sync))
            np.testing.assert_array_equal(obs, obs_s)
            np.testing.assert_array_equal(info["soc"][m], info_s["soc"][m])


def test_a_partial_reset_keeps_the_others_observations_and_gives_a_fresh_resets_info_where_the_mask_is_true():
    """What docs/envs.md ("Options") and the Info docstring promise of a partial reset: the windows outside the mask keep
    their last observation, and the info rows inside it are a fresh reset's (the rows outside are documented as not
    meaningful)."""
    cfg = SHORT["envelope"]
    doc = " ".join(SbarChargingEnv.__doc__.split())
    assert "only the info rows where ``m`` is True are meaningful" in doc
    venv, fresh = SbarChargingVectorEnv(3, "random", cfg), SbarChargingVectorEnv(3, "random", cfg)
    venv.reset(seed=1)
    for x in _actions(5, (3, 1)):
        last = venv.step(x)[0].copy()
    m = np.array([False, True, False])
    obs, info = venv.reset(seed=[None, 8, None], options={"reset_mask": m, "scenario": "windy"})
    obs0, info0 = fresh.reset(seed=[7, 8, 9], options={"scenario": "windy"})
    np.testing.assert_array_equal(obs[~m], last[~m])
    np.testing.assert_array_equal(obs[m], obs0[m])
    assert sorted(info) == sorted(info0)
    for key in info:
        np.testing.assert_array_equal(info[key][m], info0[key][m], err_msg=key)


@pytest.mark.parametrize("mask,text", [(np.array([1, 0, 1]), "dtype int64"), ([True, False, True], r"\[True, False, True\]"),
                                       (np.zeros(3, bool), "dtype bool"), (np.ones(2, bool), r"shape \(2,\)")])
def test_a_reset_mask_that_is_not_one_bool_per_window_is_named(mask, text):
    venv = SbarChargingVectorEnv(3, config=SHORT["envelope"])
    with pytest.raises(ValueError, match="before the first reset"):
        venv.reset(options={"reset_mask": np.ones(3, bool)})
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=rf"options\['reset_mask'\]=.*{text}.* is invalid; valid: a numpy bool array of "
                                         r"shape \(3,\) with at least one True"):
        venv.reset(options={"reset_mask": mask})


def test_restart_before_the_first_reset_is_named_as_a_partial_reset():
    """``restart([0])`` before any reset raised ``AttributeError: 'NoneType' object ...``; now the partial reset's line."""
    venv = SbarChargingVectorEnv(3, config=SHORT["envelope"])
    with pytest.raises(ValueError, match=r"^restart is invalid before the first reset; valid: a reset of every window first$"):
        venv.restart([0])
    venv.reset(seed=0)
    assert venv.restart([0]).shape == (1, venv.single_observation_space.shape[0])


@pytest.mark.parametrize("dtype", [np.float16, ">f8", np.longdouble])
def test_vector_env_takes_float_actions_of_any_precision(dtype):
    """float16, big-endian or long-double actions (a policy's half-precision output, an array read from a file) went
    to the compiled duty map as they were: numba's ``NotImplementedError: float16`` / ``TypingError: non-precise type
    pyobject``, after a compile notice; the single env took them. Now the float64 of the same values."""
    acts = np.array([[-1.0], [0.5], [0.25]])
    rewards = []
    for a in (acts, acts.astype(dtype)):
        venv = SbarChargingVectorEnv(3, config=SHORT["envelope"])
        venv.reset(seed=0)
        rewards.append(venv.step(a)[1])
    np.testing.assert_array_equal(rewards[0], rewards[1])


def test_an_env_remade_from_its_spec_json_is_the_same_env():
    """``EnvSpec.from_json(env.spec.to_json())`` (gymnasium writes an EnvConfig's dataclass fields as dicts) made no
    env: ``link={...} is invalid; valid: a wpt_receiver.LinkParams``; a config's ``link`` may now be a dict of its
    fields (Table I's for the others), as ``reward`` a dict of RewardWeights fields."""
    from gymnasium.envs.registration import EnvSpec

    from wpt_receiver import TABLE_I
    cfg = EnvConfig(link=TABLE_I.with_(lm_h=5e-6), link_model="envelope", n_steps=12, reward={"overcurrent": 20.0})
    env = gym.make(envs.ENV_ID, config=cfg, scenario="random")
    twin = gym.make(EnvSpec.from_json(env.spec.to_json()))
    assert twin.unwrapped.config == cfg
    acts = _actions(cfg.n_steps)
    env.reset(seed=2)
    twin.reset(seed=2)
    assert _same(_windows(env, acts, 2), _windows(twin, acts, 2))
    assert EnvConfig(link={"lm_h": 5e-6}).link == TABLE_I.with_(lm_h=5e-6)
    with pytest.raises(ValueError, match="'lm' is not a LinkParams field; valid: l1_h, l2_h, lm_h"):
        EnvConfig(link={"lm": 5e-6})


_UNPICKLE = """
import pickle, sys
import envs.modal_step, envs.vector_kernel
env = pickle.load(sys.stdin.buffer)
step = env.unwrapped.parts.plant.kernel
module = envs.modal_step if env.unwrapped.config.link_model == "modal" else envs.vector_kernel
duty = getattr(env.unwrapped, "_duty_kernel", envs.vector_kernel.duty_kernel)
print(step is getattr(module, step.__name__), duty is envs.vector_kernel.duty_kernel)
"""


@pytest.mark.parametrize("make", [lambda: gym.make(envs.ENV_ID, config=SHORT["envelope"]),
                                  lambda: SbarChargingVectorEnv(2, config=SHORT["modal"])], ids=["single", "vector"])
def test_an_env_unpickled_in_another_process_steps_with_the_cached_kernels(make):
    """A pickled env (to a worker, a checkpoint) carried its numba dispatchers, which another process rebuilt from their
    source without numba's disk cache: its first step compiled them again (6.7-8.8 s for the single env, against 0.7 s
    from the cache, load 4.8). Now the env's kernels are the worker's module functions (``envs.core.kernel_ref``)."""
    import subprocess
    import sys
    env = make()
    env.reset(seed=0)
    out = subprocess.run([sys.executable, "-c", _UNPICKLE], input=pickle.dumps(env), capture_output=True, check=True)
    assert out.stdout.split() == [b"True", b"True"]
    twin = pickle.loads(pickle.dumps(env))   # compiled=False: the uncompiled source, by reference too
    assert twin.unwrapped.parts.plant.kernel is env.unwrapped.parts.plant.kernel


def test_history_is_stored_as_the_checked_int_and_its_range_exported():
    """``history=2.0`` passed and was stored as a float; ``HISTORY_RANGE`` was not in the contract's ``__all__``."""
    import mission_sim.contract as contract
    assert {"HISTORY_RANGE", "check_history"} <= set(contract.__all__)
    for env in (SbarChargingEnv(config=SHORT["envelope"], history=2.0),
                SbarChargingVectorEnv(2, config=SHORT["envelope"], history=np.int64(2))):
        assert type(env.history) is int and env.history == 2


def test_sb3_adapter_passes_none_seed_entries_on_as_dummy_vec_env():
    """The SB3 adapter's reset made a None seed entry seed 0; DummyVecEnv resets that sub-env with ``seed=None`` (its
    generator goes on), and so does the vector env now."""
    from stable_baselines3.common.env_util import make_vec_env

    from envs.sb3_vec import SbarSB3VecEnv
    cfg = SHORT["envelope"]
    ours, dummy = SbarSB3VecEnv(3, "random", cfg), make_vec_env(envs.ENV_ID, 3, env_kwargs={"config": cfg,
                                                                                           "scenario": "random"})
    acts = _actions(cfg.n_steps + 3, (3, 1))
    for vec in (ours, dummy):
        vec.seed(3)
    np.testing.assert_array_equal(ours.reset(), dummy.reset())
    for vec in (ours, dummy):
        vec._seeds = [11, None, 13]   # (VecEnv.seed sets every entry; a user's or a subclass's list may hold None)
    np.testing.assert_array_equal(ours.reset(), dummy.reset())
    for x in acts:
        np.testing.assert_array_equal(ours.step(x)[0], dummy.step(x)[0])


def test_the_docstring_names_the_keys_a_reset_info_has_besides_a_steps():
    """The Info section said every reset info has ``scenario`` and ``t_stop_s`` besides the step's keys; the vector
    env's has ``t_stop_s`` only."""
    doc = " ".join(SbarChargingEnv.__doc__.split())
    single = re.search(r"after ``reset`` \(at t = 0, with ``(\w+)`` and ``(\w+)`` besides\)", doc).groups()
    vector = re.findall(r"``(\w+)``", re.search(r"its ``reset`` info with (.*?) besides", doc).group(1))
    for env, said in ((SbarChargingEnv(config=SHORT["envelope"]), single),
                      (SbarChargingVectorEnv(2, config=SHORT["envelope"]), vector)):
        info0 = env.reset(seed=0)[1]
        info1 = env.step(env.action_space.sample())[4]
        assert set(info1) <= set(info0) and sorted(set(info0) - set(info1)) == sorted(said)


def test_sb3_set_attr_on_part_of_the_windows_is_refused():
    """``SbarSB3VecEnv.set_attr(name, value, indices=[0])`` switched every window (the batched env's attributes are
    shared): refused with one line; None or every window sets it."""
    from envs.sb3_vec import SbarSB3VecEnv
    v = SbarSB3VecEnv(3, "nominal", EnvConfig(link_model="envelope"))
    with pytest.raises(ValueError, match=r"^set_attr\('scenario', indices=\[0\]\) is invalid; valid: indices=None or "
                                         r"every window 0\.\.2 "):
        v.set_attr("scenario", "battery", indices=[0])
    assert v.get_attr("scenario")[0].name == "nominal"
    v.set_attr("scenario", "battery", indices=[2, 0, 1])
    assert v.get_attr("scenario")[0].name == "battery"
    v.close()
