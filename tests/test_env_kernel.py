"""Eq. 4's env step exists once (``envs/vector_kernel.py``, compiled; ``EnvConfig(link_model="envelope")``): the single
and the vector env both
call it, so a change to one constant or equation there changes both alike; the compiled kernel is
its own source run by the interpreter (every numba function swapped for its ``py_func``)."""

import numpy as np
import pytest

from envs import EnvConfig, SbarChargingEnv, SbarChargingVectorEnv
from envs import vector_kernel as vk

SHORT = EnvConfig(n_steps=40, link_model="envelope")   # pinned: this module is eq. 4's step (envs/vector_kernel.py),
#   the envs' default link is the exact-mode one since 2026-11-26 (its versions: tests/test_env_modal.py)


def _use_py_funcs(monkeypatch):
    """Every numba function of :mod:`envs.vector_kernel` replaced by its ``py_func`` (module globals:
    compiled functions freeze their globals, the interpreted source reads them at each call)."""
    for name in dir(vk):
        f = getattr(vk, name)
        if hasattr(f, "py_func"):
            monkeypatch.setattr(vk, name, f.py_func)


def _run(scenario, compiled=True, steps=50, seed=3, cfg=SHORT):
    """Single env and row 0 of a 2-env vector env on ``cfg``, seeded alike, the same random actions (through
    an autoreset of the vector env): arrays of (reward, I2, I_L, peak, VL) and the observations."""
    single = SbarChargingEnv(scenario=scenario, config=cfg, compiled=compiled)
    vec = SbarChargingVectorEnv(2, scenario, cfg, compiled=compiled)
    o1, _ = single.reset(seed=seed)
    ov, _ = vec.reset(seed=seed)
    rng = np.random.default_rng(0)
    rs, rv, obs = [], [], [(o1, ov[0])]
    for k in range(steps):
        a = rng.uniform(-1.0, 1.0, (2, 1)).astype(np.float32)
        if k == cfg.n_steps:
            o1, _ = single.reset()   # the vector env autoresets row 0 on this step
            s1 = (o1, 0.0, False, False, None)
        else:
            s1 = single.step(a[0])
        sv = vec.step(a)
        obs.append((s1[0], sv[0][0]))
        if s1[4] is not None:
            keys = ("i2_a", "rect_current_a", "i2_peak_a", "battery_v")
            rs.append([s1[1]] + [s1[4][key] for key in keys])
            rv.append([sv[1][0]] + [sv[4][key][0] for key in keys])
    return np.array(rs), np.array(rv), np.array(obs)


@pytest.mark.parametrize("scenario", ["random", "detuned"])
def test_interpreted_source_equals_compiled(monkeypatch, scenario):
    fs, fv, fo = _run(scenario)
    _use_py_funcs(monkeypatch)
    rs, rv, ro = _run(scenario, compiled=False)
    if scenario == "random":
        assert np.array_equal(fs, rs) and np.array_equal(fv, rv) and np.array_equal(fo, ro)
    else:   # |J| by math.hypot: Python's own algorithm interpreted, libm's compiled (last bits differ)
        np.testing.assert_allclose(rs, fs, rtol=1e-11, atol=1e-11)
        np.testing.assert_allclose(rv, fv, rtol=1e-11, atol=1e-11)
        np.testing.assert_allclose(ro, fo, atol=1e-6)   # float32 observations: one float32 ulp
    assert np.array_equal(fs, fv) and np.array_equal(fo[:, 0], fo[:, 1])   # single == vector row 0


@pytest.mark.parametrize("scenario,name,value", [
    ("random", "_FOUR_OVER_PI", 1.2),                   # the SBAR's clamp (eq. 9)
    ("random", "SHORT_MODE_IL_A", 1e9),                 # the objective's short-mode threshold (no effect here)
    ("detuned", "_FOUR_OVER_PI", 1.2),                  # the same constant in the detuned tank's step
])
def test_one_change_moves_single_and_vector_alike(monkeypatch, scenario, name, value):
    """A constant of the step changed once (in the kernel's source) changes the single env's and the
    vector env's trajectories alike: equal to each other before and after, different from before."""
    _use_py_funcs(monkeypatch)
    s0, v0, _ = _run(scenario, compiled=False)
    monkeypatch.setattr(vk, name, value)
    s1, v1, _ = _run(scenario, compiled=False)
    assert np.array_equal(s0, v0) and np.array_equal(s1, v1)
    if name == "_FOUR_OVER_PI":
        # a weaker clamp (1.2 < 4/pi) draws more current in RM: I_L and I2 move in both envs alike
        assert np.abs(s1 - s0)[:, 1:3].max() > 0.1
    else:
        assert np.array_equal(s1, s0)


def test_one_equation_change_moves_both(monkeypatch):
    """An equation swapped once (the battery's: its bus capacitor removed) moves both envs alike."""
    _use_py_funcs(monkeypatch)
    s0, v0, _ = _run("random", compiled=False, steps=30)
    orig = vk._battery

    def no_bus(il, soc, vrc, vl, b):
        ib, soc, vrc, _ = orig(il, soc, vrc, vl, b)
        return ib, soc, vrc, b[vk.BAT.ocv0] + b[vk.BAT.docv] * (soc - b[vk.BAT.soc0]) + b[vk.BAT.r0] * ib + vrc

    monkeypatch.setattr(vk, "_battery", no_bus)
    s1, v1, _ = _run("random", compiled=False, steps=30)
    assert np.array_equal(s1, v1) and not np.array_equal(s1, s0)
    assert np.abs(s1[:, 4] - s0[:, 4]).max() > 1e-4   # VL jumps to its target at once
