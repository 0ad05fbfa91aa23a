"""The fast paths of the batched env against their references: compiled step vs numpy step,
batched episode draws vs one-at-a-time draws, vectorised Lm windows vs ``np.interp``."""

import numpy as np
import pytest
from gymnasium.utils import seeding

from envs import EnvConfig, SbarChargingVectorEnv
from envs.plant import RECORD_DT_S, _valid_starts, lm_record, lm_window_h
from envs.scenario import SCENARIOS, command_profile, draw_episode, draw_episodes, stack_draws

SHORT = EnvConfig(n_steps=40)


@pytest.mark.parametrize("scenario", ["nominal", "random"])
def test_draw_episodes_equals_draw_episode(scenario):
    scn = SCENARIOS[scenario]
    a = [seeding.np_random(s)[0] for s in range(5)]
    b = [seeding.np_random(s)[0] for s in range(5)]
    for _ in range(2):  # twice: the generators are left in the same state
        batch = draw_episodes(a, scn, 30)
        ref = stack_draws([draw_episode(r, scn, 30, 3) for r in b])
        for name in ("soc0", "lm_scale", "wind_speed_m_s", "record_u", "cmd0_a", "cmd1_a", "t_change_s", "t_stop_s",
                     "noise"):
            np.testing.assert_array_equal(getattr(batch, name), getattr(ref, name), err_msg=name)
    cmd = command_profile(batch, 30, 1e-3)
    assert cmd.shape == (5, 31) and np.all(cmd[:, -1] == 0.0)  # stopped before 30 ms
    np.testing.assert_array_equal(cmd[:, 0], batch.cmd0_a)


def test_lm_windows_equal_np_interp():
    rng = np.random.default_rng(1)
    wind = np.r_[0.5, 1.5, 2.5, 3.5, rng.uniform(0, 4, 60)]
    u = rng.uniform(size=len(wind))
    t = np.arange(30) * 1e-3
    got = lm_window_h(wind, u, t)
    n_span = int(np.ceil(t[-1] / RECORD_DT_S)) + 1
    for i, (w, ui) in enumerate(zip(wind, u)):
        level = int(round(w))
        starts = _valid_starts(level, n_span)
        i0 = starts[min(int(ui * len(starts)), len(starts) - 1)]
        seg = lm_record(level)[0][i0:i0 + n_span + 1]
        np.testing.assert_array_equal(got[i], np.interp(t, np.arange(len(seg)) * RECORD_DT_S, seg))


@pytest.mark.parametrize("link", ["modal", "envelope"])   # the default (modal since 2026-11-26) and eq. 4's step
@pytest.mark.parametrize("discrete", [False, True])
def test_compiled_step_equals_numpy_step_through_autoresets(discrete, link):
    pytest.importorskip("numba")
    from envs.vector import SbarChargingDiscreteVectorEnv
    cls = SbarChargingDiscreteVectorEnv if discrete else SbarChargingVectorEnv
    n = 16
    cfg = EnvConfig(n_steps=SHORT.n_steps, link_model=link)
    fast, ref = cls(n, "random", cfg, compiled=True), cls(n, "random", cfg, compiled=False)
    of, _ = fast.reset(seed=3)
    orf, _ = ref.reset(seed=3)
    np.testing.assert_array_equal(of, orf)
    rng = np.random.default_rng(0)
    for _ in range(2 * cfg.n_steps + 7):
        act = rng.integers(0, 2, n) if discrete else rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        f, r = fast.step(act), ref.step(act)
        np.testing.assert_allclose(f[0], r[0], atol=1e-6)
        np.testing.assert_allclose(f[1], r[1], rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(f[3], r[3])
        assert set(f[4]) == set(r[4])
        for key in r[4]:
            np.testing.assert_allclose(f[4][key], r[4][key], rtol=1e-9, atol=1e-12, err_msg=key)


@pytest.mark.parametrize("compiled", [True, False])
def test_non_finite_action_is_refused_by_its_index(compiled):
    """The duty map's finiteness check (or-ed over the actions, the index looked up after) names the first
    NaN or infinite action, and the step does not run."""
    pytest.importorskip("numba")
    n = 300
    env = SbarChargingVectorEnv(n, config=EnvConfig(n_steps=SHORT.n_steps, link_model="envelope"), compiled=compiled)
    env.reset(seed=1)
    a = np.zeros((n, 1), np.float32)
    env.step(a)
    before = env._state.copy()
    for bad in ({7: np.nan}, {250: np.inf, 260: np.nan}, {0: -np.inf}, {299: np.nan}):
        b = a.copy()
        for i, v in bad.items():
            b[i] = v
        first = min(bad)
        with pytest.raises(ValueError, match=rf"actions\[{first}\]={float(bad[first])!r} is invalid; valid range"):
            env.step(b)
        np.testing.assert_array_equal(env._state, before)
    np.testing.assert_array_equal(env._duty(np.linspace(-1.5, 1.5, n, dtype=np.float32)),
                                  np.clip((np.linspace(-1.5, 1.5, n, dtype=np.float32).astype(float) + 1.0) * 0.5, 0, 1))
