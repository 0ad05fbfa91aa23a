"""The compiled mission fast path (numba) against the pure-Python reference loop (issue 14).

The fast path (:mod:`mission_sim.world.loop_kernel`, the policies' ``kernel()`` hook, the compiled
Lm table) does the reference's floating-point operations; only numpy's SIMD ``exp``/``arcsin`` and
BLAS dot products may round the last bit differently. So: summaries and time series agree to
1e-9 relative (each float column to 1e-9 of its largest magnitude; the two energy-balance
residuals, rounding noise of ~1e-16 themselves, to 1e-13 absolute), counts and flags exactly.
No timings are asserted.
"""

import numpy as np
import pytest

pytest.importorskip("numba")

from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config  # noqa: E402
from mission_sim.contract import OBS_DIM, PolicyContext, normalise_obs  # noqa: E402
from mission_sim.world import fastpath  # noqa: E402
from mission_sim.world.loop import _COLUMNS, MissionLoop  # noqa: E402
from mission_sim.world.runner import _lm_along, run_mission  # noqa: E402
from mission_sim.world.trajectory import plan_mission  # noqa: E402
from policies import make  # noqa: E402

RTOL = 1e-9
_RESIDUALS = ("energy_balance_error_rel", "link_balance_error_rel")
_TIMING = ("wall_s", "realtime_factor")


def _policy(cfg, name):
    return make(name, PolicyContext(control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a))


def _cfg(overrides=None):
    return config_from_dict(apply_overrides(config_to_dict(load_config()), overrides or {}))


def assert_summaries_agree(fast: dict, ref: dict):
    assert fast.keys() == ref.keys()
    for key, want in ref.items():
        got = fast[key]
        if key in _TIMING:
            continue
        if key in _RESIDUALS:
            assert abs(got - want) <= 1e-13 and got < 1e-12, key
        elif isinstance(want, float) and not isinstance(want, bool):
            assert got == pytest.approx(want, rel=RTOL, abs=0.0), key
        else:
            assert got == want, key


def assert_timeseries_agree(fast, ref):
    assert list(fast.columns) == list(ref.columns) and len(fast) == len(ref)
    for col in ref.columns:
        a, b = fast[col].to_numpy(), ref[col].to_numpy()
        if b.dtype.kind == "f":
            scale = max(float(np.max(np.abs(b))), 1e-300)
            assert np.max(np.abs(a - b)) <= RTOL * scale, col
        else:
            assert (a == b).all(), col


def _loop(cfg, name, charge=True, compiled=None):
    traj = plan_mission(cfg)
    return MissionLoop(cfg, _policy(cfg, name), traj, charge, _lm_along(cfg, cfg.coupling.model(), traj)[0], compiled)


@pytest.mark.parametrize("name", ["model_based", "step", "ramp"])
def test_fast_path_matches_the_reference_on_the_default_mission(name):
    cfg = load_config()
    fast = _loop(cfg, name)
    assert fastpath.usable(fast) and fastpath.run_compiled(fast)   # the compiled kernel ran (no fallback)
    fast_res = fast.result()
    ref_res = _loop(cfg, name, compiled=False).run()
    assert_summaries_agree(fast_res.summary, ref_res.summary)
    assert_timeseries_agree(fast_res.timeseries, ref_res.timeseries)
    assert fast_res.summary["fine_steps"] > 500 and fast_res.summary["energy_balance_error_rel"] < 1e-14
    # and through run_mission (charged + uncharged runs, flight-time gain), default = compiled
    fast_m, ref_m = run_mission(cfg, _policy(cfg, name)), run_mission(cfg, _policy(cfg, name), compiled=False)
    assert_summaries_agree(fast_m.summary, ref_m.summary)
    assert_timeseries_agree(fast_m.timeseries, ref_m.timeseries)


@pytest.mark.parametrize("overrides", [{"pads.1.x_m": 10_000.0}, {"link.devices": "ideal", "pads.1.hover_time_s": 20.0}],
                         ids=["depleted on the way", "ideal devices"])
def test_fast_path_matches_the_reference_on_depletion_and_ideal_devices(overrides):
    cfg = _cfg(overrides)
    fast, ref = run_mission(cfg, _policy(cfg, "model_based"), compiled=True), \
        run_mission(cfg, _policy(cfg, "model_based"), compiled=False)
    assert_summaries_agree(fast.summary, ref.summary)
    assert_timeseries_agree(fast.timeseries, ref.timeseries)
    assert fast.summary["battery_depleted"] == ("pads.1.x_m" in overrides)


def test_rows_buffer_grows_and_progress_chunks_resume():
    """Many short calls (chunks of samples) and a row buffer that has to grow give the same run."""
    cfg = load_config()
    ref = _loop(cfg, "model_based", compiled=False).run()
    old = fastpath._CHUNK
    try:
        fastpath._CHUNK = 3
        loop = _loop(cfg, "model_based")
        assert fastpath.run_compiled(loop)
    finally:
        fastpath._CHUNK = old
    res = loop.result()
    assert_summaries_agree(res.summary, ref.summary)
    assert_timeseries_agree(res.timeseries, ref.timeseries)


def test_policies_without_the_hook_run_the_reference_and_compiled_true_needs_it():
    cfg = load_config()
    pol = make("model_based_budget", PolicyContext(control_period_s=cfg.sim.control_period_s))
    pol.reset(1)
    assert pol.kernel() is None        # a subclass that changes act() gets no kernel
    assert not fastpath.usable(_loop(cfg, "hysteresis"))
    with pytest.raises(ValueError, match="compiled=True needs numba, a policy with the kernel hook"):
        run_mission(cfg, _policy(cfg, "hysteresis"), compiled=True)
    noisy = _cfg({"sim.i2_noise_a": 0.1})
    assert not fastpath.usable(_loop(noisy, "model_based"))


@pytest.mark.parametrize("name", ["model_based", "step", "ramp"])
def test_policy_kernel_reproduces_act(name):
    """The kernel alone, on a random walk of observations, against the policy's act (one receiver)."""
    pol = make(name, PolicyContext())
    pol.reset(1)
    fn, params, state = pol.kernel()
    rng = np.random.default_rng(3)
    phys = np.array([8.0, 30.0, 1.0, 2.0, 0.6, 3.0, 0.5, 0.0])
    for _ in range(300):
        phys = phys + rng.normal(0, [0.5, 0.2, 0.3, 0.2, 0.0, 0.8, 0.05, 0.0])
        obs = normalise_obs(phys[None, :])
        want = float(np.asarray(pol.act(obs)).reshape(-1)[0])
        got = fn(np.ascontiguousarray(obs[0]), params, state)
        assert got == pytest.approx(want, rel=1e-12, abs=1e-12)
    assert obs.shape == (1, OBS_DIM)


def test_kernel_row_layout_matches_the_columns():
    assert fastpath.N_COLUMNS == len(_COLUMNS)
    from mission_sim.world.loop_kernel import S_NAMES
    loop = _loop(load_config(), "step")
    assert set(fastpath._state_values(loop)) == set(S_NAMES)


def test_partial_peak_table_has_the_full_tables_values():
    from wpt_receiver.peak import PeakTable, SbarHarmonics
    cfg = load_config()
    model = cfg.coupling.model()
    harm = SbarHarmonics(cfg.link.link_params(model.l1_h, model.l2_h, 6.25e-6), cfg.link.device_set())
    full = PeakTable(harm, i2_max_a=14.0, n_d=11, n_i=9)
    part = PeakTable(harm, i2_max_a=14.0, n_d=11, n_i=9, i2_min_a=9.0)
    done = ~np.isnan(part.excess[0])
    assert 2 <= done.sum() < 9 and np.array_equal(part.excess[:, done], full.excess[:, done])
    d, i2 = np.linspace(0, 1, 7), np.linspace(9.0, 14.0, 7)
    assert np.array_equal(part(d, i2), full(d, i2))
