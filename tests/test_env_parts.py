"""The env as composed parts (issue 21): every part is entered once per reset and once per step, the
state is read by name, and a new scenario is one new part (a Draw) registered without editing the env."""

import numpy as np
import pytest

from envs import EnvConfig, SbarChargingEnv, SbarChargingVectorEnv
from envs.layout import BAT, STATE
from envs.plant import battery_operating_point
from envs.scenario import DRAWS, SCENARIOS, Draw, Scenario, register_scenario

SHORT = EnvConfig(n_steps=40, slow_every=10)
PARTS = ("scenario", "plant", "objective", "observation")


def _count(env, monkeypatch):
    """Wrap every part's reset and step and every built-in Draw's apply with a counter."""
    calls = {}
    for name in PARTS:
        part = getattr(env.parts, name)
        for meth in ("reset", "step"):
            if not hasattr(part, meth):
                continue
            key, inner = f"{name}.{meth}", getattr(part, meth)

            def wrapped(*a, _key=key, _inner=inner, **kw):
                calls[_key] = calls.get(_key, 0) + 1
                return _inner(*a, **kw)
            monkeypatch.setattr(part, meth, wrapped)
    for i, draw in enumerate(DRAWS):
        key, inner = f"draw{i}", draw.apply

        def counted(*a, _key=key, _inner=inner):
            calls[_key] = calls.get(_key, 0) + 1
            return _inner(*a)
        monkeypatch.setattr(draw, "apply", counted)
    return calls


@pytest.mark.parametrize("make", [lambda: SbarChargingEnv(config=SHORT), lambda: SbarChargingVectorEnv(3, config=SHORT)],
                         ids=["single", "vector"])
@pytest.mark.parametrize("scenario", ["nominal", "sense_delay", "detuned"])
def test_each_part_entered_once_per_reset_and_step(make, scenario, monkeypatch):
    env = make()
    calls = _count(env, monkeypatch)
    env.reset(seed=2, options={"scenario": scenario})
    resets = {f"{p}.reset": 1 for p in PARTS} | {f"draw{i}": 1 for i in range(len(DRAWS))}
    assert calls == resets
    calls.clear()
    act = env.action_space.sample()
    for _ in range(3):   # steps inside the window: no autoreset
        env.step(act)
    steps = {f"{p}.step": 3 for p in ("plant", "objective", "observation")}
    assert calls == steps   # the scenario part is not entered at a step (the step reads its command)


def test_vector_autoreset_resets_each_part_once():
    env = SbarChargingVectorEnv(2, config=EnvConfig(n_steps=3, slow_every=1))
    env.reset(seed=0)
    counts = {}
    for name in PARTS:
        part = getattr(env.parts, name)
        inner = part.reset

        def wrapped(*a, _n=name, _inner=inner, **kw):
            counts[_n] = counts.get(_n, 0) + 1
            return _inner(*a, **kw)
        part.reset = wrapped
    for _ in range(4):   # the 4th step restarts both windows
        env.step(np.zeros((2, 1), np.float32))
    assert counts == {p: 1 for p in PARTS}


def test_state_by_name_is_what_the_info_reports():
    v = SbarChargingVectorEnv(4, scenario="battery", config=SHORT)
    _, info = v.reset(seed=4)
    assert v.state_names == STATE._fields == SbarChargingEnv(config=SHORT).state_names
    st = v.parts.plant.state
    np.testing.assert_array_equal(st[STATE.vl], info["battery_v"])
    np.testing.assert_array_equal(st[STATE.soc], v.parts.plant.bat[BAT.soc0])
    np.testing.assert_array_equal(st[STATE.d], info["d_short"])
    # the OCV of the drawn SoC, read by name from the battery rows
    soc = v.parts.plant.bat[BAT.soc0]
    np.testing.assert_allclose(v.parts.plant.bat[BAT.ocv0], battery_operating_point(soc)[0], rtol=1e-15)


class BatteryVoltage(Draw):
    """A scenario part written for this test: the pack's open-circuit voltage drawn uniformly in
    ``volts`` [V]; the window starts at the SoC of that OCV (the inverse of the pack's OCV curve)."""

    def __init__(self, volts):
        self.volts = tuple(float(v) for v in volts)

    def ranges(self, scn):
        return (self.volts,)

    def apply(self, scn, cols, win):
        grid = np.linspace(0.0, 1.0, 20001)
        ocv = battery_operating_point(grid)[0]   # increasing in SoC
        win["soc0"] = np.interp(cols[0], ocv, grid)


def test_a_new_scenario_is_one_part(monkeypatch):
    """A scenario the env has never seen (battery voltage drawn directly), added as one Draw and one
    registered Scenario, runs in the single and the vector env by name; the rest of the window is the
    nominal one (its draws come after the built-in ones)."""
    monkeypatch.setattr("envs.scenario.SCENARIOS", dict(SCENARIOS))   # leave the registry as it was
    import envs.scenario as sc
    register_scenario(Scenario("pack_24v", parts=(BatteryVoltage((23.5, 24.5)),)))
    assert "pack_24v" in sc.SCENARIOS
    v = SbarChargingVectorEnv(6, scenario="pack_24v", config=SHORT)
    _, info = v.reset(seed=11)
    ocv = v.parts.plant.bat[BAT.ocv0]
    assert np.all((ocv > 23.5 - 1e-3) & (ocv < 24.5 + 1e-3)) and np.ptp(ocv) > 0.2   # drawn, not one value
    assert np.all(np.abs(info["battery_v"] - ocv) < 1.5)   # terminal = OCV + the IR rise of the charge current
    nominal = SbarChargingVectorEnv(6, scenario="nominal", config=SHORT)
    nominal.reset(seed=11)
    np.testing.assert_array_equal(v.parts.scenario.cmd, nominal.parts.scenario.cmd)   # same reference
    assert np.all(v.parts.plant.bat[BAT.soc0] < 0.1)
    # the single env draws the same window as the vector env's row 0; reset(options=...) finds it by name
    s = SbarChargingEnv(config=SHORT)
    obs, info1 = s.reset(seed=11, options={"scenario": "pack_24v"})
    assert info1["battery_v"] == info["battery_v"][0] and info1["scenario"] == "pack_24v"
    # a point range draws nothing: the window's other draws stay those of the nominal scenario
    fixed = SbarChargingVectorEnv(6, scenario=Scenario("pack_25v", parts=(BatteryVoltage((25.0, 25.0)),)),
                                  config=SHORT)
    fixed.reset(seed=11)
    np.testing.assert_allclose(fixed.parts.plant.bat[BAT.ocv0], 25.0, atol=1e-3)
    np.testing.assert_array_equal(fixed.parts.scenario.noise, nominal.parts.scenario.noise)


def test_bad_scenario_part_is_refused():
    with pytest.raises(ValueError, match="scenario part"):
        Scenario("bad", parts=("not a draw",))


def test_history_is_the_observation_part_frame_stack():
    """history=K: each observation is the last K plain observations, oldest first; a window (and a
    window restarted by the autoreset) starts with K copies of its first; single env = vector row 0."""
    from envs.history import ObsHistory
    cfg, K, n = EnvConfig(n_steps=6, slow_every=2), 3, 2
    plain, stacked = (SbarChargingVectorEnv(n, scenario="sense_delay", config=cfg, history=h) for h in (1, K))
    assert stacked.single_observation_space.shape == (8 * K,)
    o1, _ = plain.reset(seed=7)
    oK, _ = stacked.reset(seed=7)
    frames = [o1] * K
    np.testing.assert_array_equal(oK, np.concatenate(frames[-K:], axis=1))
    single = SbarChargingEnv(scenario="sense_delay", config=cfg, history=K)
    np.testing.assert_array_equal(single.reset(seed=7)[0], oK[0])
    ref = ObsHistory(K)
    ref.reset(o1)
    rng = np.random.default_rng(3)
    for t in range(9):   # the 7th step restarts both windows (NEXT_STEP autoreset)
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        o1, _, _, tr1, _ = plain.step(a)
        oK, _, _, trK, _ = stacked.step(a)
        restarted = t == cfg.n_steps
        want = ref.push(o1, starts=np.full(n, restarted))
        np.testing.assert_array_equal(oK, want)
        np.testing.assert_array_equal(oK[:, -8:], o1)   # the newest frame is the plain observation
        if restarted:
            np.testing.assert_array_equal(oK, np.tile(o1, K))
        elif t < cfg.n_steps:
            np.testing.assert_array_equal(single.step(a[0])[0], oK[0])
    with pytest.raises(ValueError, match="history"):
        SbarChargingVectorEnv(2, history=0)


def test_the_scenario_part_hands_its_fill_the_resets_chunks():
    """2026-11-27 midday: ScenarioPart.reset built a lambda per reset (the draws' fill with the reset's chunks); a
    method reads them now. The fill gets the chunks of its reset (2, then 3) and the draws are the generators' when it
    declines (False), as before (benchmarks/env_bits.py cases 0-5: the same fingerprints as main). (How reset is
    written, no function built in it, is not asserted: a review, it is not what reset does.)"""
    from envs.scenario import ScenarioPart
    n, T, seen, chunks = 3, 10, [], iter([2, 3])

    def fill(rngs, u, noise, scale, k):
        seen.append(k)
        return False

    part = ScenarioPart("random", T, 1e-4, np.zeros((T + 1, n)), np.zeros((T, n)), fill, lambda: next(chunks))
    plain = ScenarioPart("random", T, 1e-4, np.zeros((T + 1, n)), np.zeros((T, n)))
    for _ in range(2):
        a = part.reset([np.random.default_rng(s) for s in range(n)], slice(None))
        b = plain.reset([np.random.default_rng(s) for s in range(n)], slice(None))
        np.testing.assert_array_equal(a.noise_a, b.noise_a)
        np.testing.assert_array_equal(a.cmd_a, b.cmd_a)
    assert seen == [2, 3]
