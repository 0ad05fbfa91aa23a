"""One compiled mission loop (issues 14, 22): the compiled-policy path against the Python-policy path.

Every physics formula of a mission step exists once, in :mod:`mission_sim.world.loop_kernel`. A policy
with the ``kernel()`` hook is called inside the kernel; ``compiled=False`` (or a policy without the
hook) calls its Python ``act`` whenever the kernel asks for a duty: the same compiled physics, only
the duty computed elsewhere. The policies' kernels do ``act``'s floating-point operations (numpy's
SIMD ``arcsin`` and BLAS dot products may round the last bit differently), so: summaries and time
series agree to 1e-9 relative (each float column to 1e-9 of its largest magnitude; the two
energy-balance residuals, rounding noise of ~1e-16 themselves, to 1e-13 absolute), counts and flags
exactly. And a change to one constant or one equation of the kernel moves both paths alike.
No timings are asserted.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config  # noqa: E402
from mission_sim.contract import OBS_DIM, PolicyContext, normalise_obs  # noqa: E402
from mission_sim.world import fastpath, loop_kernel  # noqa: E402
from mission_sim.world.loop import _COLUMNS  # noqa: E402
from mission_sim.world.runner import run_mission  # noqa: E402
from policies import make  # noqa: E402

RTOL = 1e-9
_RESIDUALS = ("energy_balance_error_rel", "link_balance_error_rel")
_TIMING = ("wall_s", "realtime_factor")
ROOT = Path(__file__).resolve().parents[1]


class _Counting:
    """A policy wrapper counting its Python ``act`` calls (``kernel`` passed on only when asked)."""

    def __init__(self, pol, hook=True):
        self.pol, self.calls, self.name, self.obs_i2 = pol, 0, pol.name, []
        if hook:
            self.kernel = pol.kernel

    def reset(self, n):
        self.pol.reset(n)

    def act(self, obs):
        self.calls += 1
        self.obs_i2.append(float(obs[0, 0]))
        return self.pol.act(obs)


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


def _both(cfg, name, **kw):
    """The default run (the policy's kernel inside the compiled loop) and the Python-policy run."""
    fast, py = _Counting(_policy(cfg, name)), _Counting(_policy(cfg, name))
    res = run_mission(cfg, fast, **kw), run_mission(cfg, py, compiled=False, **kw)
    assert fast.calls == 0 and py.calls > 500     # who computed the duty: the kernel / Python
    return res


@pytest.mark.parametrize("name", ["model_based", "step", "ramp"])
def test_compiled_policy_matches_the_python_policy_on_the_default_mission(name):
    cfg = load_config()
    fast, py = _both(cfg, name)
    assert_summaries_agree(fast.summary, py.summary)
    assert_timeseries_agree(fast.timeseries, py.timeseries)
    assert fast.summary["fine_steps"] > 500 and fast.summary["energy_balance_error_rel"] < 1e-14


@pytest.mark.parametrize("overrides", [{"pads.1.x_m": 10_000.0}, {"link.devices": "ideal", "pads.1.hover_time_s": 20.0},
                                       {"sim.i2_noise_a": 0.3}],
                         ids=["depleted on the way", "ideal devices", "sensor noise"])
def test_compiled_policy_matches_the_python_policy_on_depletion_devices_and_noise(overrides):
    cfg = _cfg(overrides)
    fast, py = _both(cfg, "model_based")
    assert_summaries_agree(fast.summary, py.summary)
    assert_timeseries_agree(fast.timeseries, py.timeseries)
    assert fast.summary["battery_depleted"] == ("pads.1.x_m" in overrides)


def test_sensor_noise_reaches_the_observation_in_the_generators_order():
    """Noise drawn in blocks by the driver: observation i2 = |I2| + sigma n_j with n_j the loop generator's
    j-th standard normal, one per policy call (model_based ignores i2, so the run itself is the quiet one)."""
    sigma = 0.3
    clean, noisy = _Counting(_policy(load_config(), "model_based"), hook=False), \
        _Counting(_policy(load_config(), "model_based"), hook=False)
    run_mission(load_config(), clean)
    cfg = _cfg({"sim.i2_noise_a": sigma})
    run_mission(cfg, noisy)
    a, b = np.array(clean.obs_i2), np.array(noisy.obs_i2)
    assert len(a) == len(b) > 500
    n = np.random.default_rng([cfg.seed, 1]).standard_normal(len(b))
    free = (a > -1.0) & (b > -1.0) & (b < 1.0)          # not clipped
    assert free.sum() > 100
    np.testing.assert_allclose((b - a)[free], (2.0 * sigma / 60.0) * n[free], rtol=1e-9, atol=1e-14)


def test_small_row_buffer_and_progress_chunks_give_the_same_run(monkeypatch):
    """Many short kernel calls (chunks of samples) and a row buffer handed over every ~50 rows give the same run."""
    cfg = load_config()
    ref = run_mission(cfg, _policy(cfg, "model_based"))
    monkeypatch.setattr(fastpath, "_CHUNK", 3)
    monkeypatch.setattr(fastpath, "BLOCK_ROWS", 50)
    blocks = []
    res = run_mission(cfg, _policy(cfg, "model_based"), sink=lambda lp, arr: blocks.append(len(arr)), progress=True)
    # the buffer holds at least twice the row margin (a fine step's rectifier-period sub-steps, each refined into
    # up to 2^REFINE_LEVELS pieces in a large transient: 17 x 8 + 3 rows), so a block is 140 rows here, not 50
    from wpt_receiver.modal_kernel import REFINE_LEVELS
    margin = 17 * 2 ** REFINE_LEVELS + 3
    assert len(blocks) > len(ref.timeseries) // (margin + 1) - 2 and max(blocks) <= max(50, 2 * margin) \
        and sum(blocks) == len(ref.timeseries) and len(blocks) > 20
    assert_summaries_agree(res.summary, ref.summary)
    assert_timeseries_agree(res.timeseries, ref.timeseries)


def test_policies_without_the_hook_run_in_python_and_compiled_true_needs_it():
    cfg = load_config()
    pol = make("model_based_budget", PolicyContext(control_period_s=cfg.sim.control_period_s))
    pol.reset(1)
    assert pol.kernel() is None        # a subclass that changes act() gets no kernel
    hyst = _Counting(_policy(cfg, "hysteresis"), hook=False)
    res = run_mission(cfg, hyst)
    assert hyst.calls > 500 and res.summary["energy_balance_error_rel"] < 1e-12
    with pytest.raises(ValueError, match="compiled=True needs a policy with the kernel hook"):
        run_mission(cfg, _policy(cfg, "hysteresis"), compiled=True)


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


def test_records_name_every_slot():
    """The row layout is the loop's columns; every constant is packed from the config; the state starts at rest."""
    from mission_sim.world.loop import MissionLoop
    from mission_sim.world.runner import _lm_along
    from mission_sim.world.trajectory import plan_mission
    assert fastpath.N_COLUMNS == len(_COLUMNS)
    cfg = load_config()
    traj = plan_mission(cfg)
    lp = MissionLoop(cfg, _policy(cfg, "step"), traj, True, _lm_along(cfg, cfg.coupling.model(), traj)[0])
    c, s = fastpath.pack_constants(lp).view(np.recarray)[0], fastpath.initial_state(lp).view(np.recarray)[0]
    assert c.n_cells == cfg.battery.n_series and c.capacity_c == 3600.0 * cfg.battery.capacity_ah
    assert c.l1 == lp.l1 and c.b0 == 1.0 / (2 * lp.l1)
    assert s.soc == cfg.battery.initial_soc and s.x0 == s.x1 == s.v1 == 0.0 and not s.tx_on and s.d == 1.0
    assert np.isnan(s.depleted_at) and s.depleted_k == -1


def test_a_kernel_constant_moves_both_paths_alike(monkeypatch):
    """Battery R0 1.5x in the packed constants (the one place the kernel reads it): both paths move, alike."""
    cfg = load_config()
    base = run_mission(cfg, _policy(cfg, "model_based"))
    pack = fastpath.pack_constants

    def patched(loop):
        c = pack(loop)
        c["r0"] *= 1.5
        return c
    monkeypatch.setattr(fastpath, "pack_constants", patched)
    fast, py = _both(cfg, "model_based")
    assert_summaries_agree(fast.summary, py.summary)
    assert fast.summary["battery_losses_j"] > 1.05 * base.summary["battery_losses_j"]   # R0 is ~2/3 of R0 + R1
    assert fast.summary["energy_balance_error_rel"] < 1e-12     # still closes: the losses follow the constant


_EQUATION_PROBE = """
import json, sys
import mission_sim.world.loop_kernel as K
from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, load_config
from mission_sim.contract import PolicyContext
from mission_sim.world.runner import run_mission
from policies import make
d = apply_overrides(config_to_dict(load_config()), {"mission.start_x_m": -1.0, "mission.cruise_altitude_m": 1.0,
    "mission.land_x_m": 1.0, "pads.0.hover_time_s": 0.1, "sim.traj_dt_s": 0.05})
d["pads"] = d["pads"][:1]
cfg = config_from_dict(d)
if sys.argv[1] == "patched":
    ocv = K._ocv_cell
    K._ocv_cell = lambda soc: ocv(soc) + 0.02      # +20 mV per cell in the one OCV equation
out = {}
for path in (None, False):
    pol = make("model_based", PolicyContext(control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a))
    s = run_mission(cfg, pol, compiled=path, frame=False).summary
    out[str(path)] = {k: v for k, v in s.items() if isinstance(v, (int, float)) and k not in ("wall_s", "realtime_factor")}
print(json.dumps(out))
"""


def test_a_kernel_equation_moves_both_paths_alike():
    """The kernel interpreted (NUMBA_DISABLE_JIT=1) with its OCV equation changed: the compiled-policy and
    the Python-policy paths both move, alike (no second copy of the equation on either path)."""
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1", "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    got = {}
    for which in ("plain", "patched"):
        out = subprocess.run([sys.executable, "-c", _EQUATION_PROBE, which], capture_output=True, text=True, env=env,
                             cwd=ROOT, timeout=600, check=True)
        got[which] = json.loads(out.stdout.strip().splitlines()[-1])
    for which in got:
        assert_summaries_agree(got[which]["None"], got[which]["False"])
    plain, patched = got["plain"]["None"], got["patched"]["None"]
    assert plain["fine_steps"] > 100
    # the rest voltage is 8 x 20 mV (~0.5 %) higher: the same propulsion power draws ~0.5 % less charge
    used = {name: run["initial_soc"] - run["final_soc"] for name, run in (("plain", plain), ("patched", patched))}
    assert 0.990 < used["patched"] / used["plain"] < 0.998


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


def test_kernel_runs_over_chunks_of_the_samples():
    """The kernel fed the trajectory in chunks (sample offset ``k0`` in the state; each chunk reaching one
    quiet-flight merge beyond where the call stops) writes exactly the rows of one call over all samples:
    the interface a bounded-memory run feeds."""
    import math
    from mission_sim.world.loop import MissionLoop
    from mission_sim.world.runner import _lm_along
    from mission_sim.world.trajectory import plan_mission
    cfg = load_config()
    traj = plan_mission(cfg)
    lm = _lm_along(cfg, cfg.coupling.model(), traj)[0]

    def run(chunk):
        lp = MissionLoop(cfg, _policy(cfg, "step"), traj, True, lm)
        lp.policy.reset(1)
        fn, params, pstate = lp.policy.kernel()
        c, s, n = fastpath.pack_constants(lp), fastpath.initial_state(lp), lp.samples.n
        rows, none = np.empty((100_000, len(_COLUMNS))), np.empty(0)
        link = fastpath.link_arrays(lp)
        ahead = math.ceil(cfg.sim.flight_dt_s / float(np.min(np.diff(traj.t_s)))) + 2
        a, calls = 0, 0
        while True:
            b = min(n, a + chunk)
            s[0]["k0"] = a
            status = loop_kernel.advance(b - ahead if b < n else n, s, c, fastpath.samples(lp, a, b), rows, none,
                                         np.empty(OBS_DIM), fn, params, pstate, *link)
            calls += 1
            if status == loop_kernel.DONE:
                return rows[:s[0]["n_rows"]].copy(), calls
            assert status == loop_kernel.PAUSED
            a = int(s[0]["k"])

    whole, one = run(10**9)
    parts, many = run(100)
    assert one == 1 and many > 8 and len(whole) > 1000
    np.testing.assert_array_equal(parts, whole)
