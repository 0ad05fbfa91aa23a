"""``model_based_budget:b`` on the exact-mode link (policies.budget_modal): its after-stop plan predicted with
the modal link, the budget in the measured overshoot's units above the floor (ordering and tolerance on fixed
windows, against eq. 4's relaxation on the same plant), one relaxation per receiver and stop, the stacked
batch equal to each policy alone; eq. 4's path untouched."""

import numpy as np
import pytest

from envs import EnvConfig
from mission_sim.contract import PolicyContext
from policies import budget_modal as bm
from policies.budgeted import BudgetedModelBasedPolicy
from policies.classical import ModelBasedPolicy
from policies.compare import run_policies

MODAL = EnvConfig(link_model="modal")
SEEDS = (1000, 4)
BUDGETS = (0.0, 0.01, 0.02, 0.05)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Measured overshoot above each window's oracle floor (the modal env's) and energy after the stop of the
    modal plan and of eq. 4's relaxation, windows ``SEEDS[0] ..`` (``SEEDS[1]`` windows)."""
    import os

    import policies
    from policies.oracle import oracle_floor
    old = os.environ.get("DRONEWPT_CACHE_DIR")
    os.environ["DRONEWPT_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))
    make = policies.make

    def patched(name, ctx=None, **kw):
        base, _, arg = name.partition(":")
        if base == "eq4":   # the relaxation r = b on the modal plant (the policy before its modal plan)
            return BudgetedModelBasedPolicy(ctx, budget=float(arg), eq4_relaxation=True)
        return make(name, ctx, **kw)

    policies.make = patched
    try:
        names = [f"model_based_budget:{b:g}" for b in BUDGETS] + [f"eq4:{b:g}" for b in BUDGETS[1:]]
        tr = run_policies(names, "nominal", SEEDS[1], SEEDS[0], MODAL)
        floor = np.array([100.0 * oracle_floor("nominal", SEEDS[0] + i, MODAL).overshoot for i in range(SEEDS[1])])
    finally:
        policies.make = make
        if old is None:
            os.environ.pop("DRONEWPT_CACHE_DIR", None)
        else:
            os.environ["DRONEWPT_CACHE_DIR"] = old
    return {n: (t.metrics["overshoot_pct"] - floor, t.metrics["energy_after_stop_j"], t.metrics["reached_short_mode"])
            for n, t in tr.items()}


def test_budget_is_measured_overshoot_above_the_floor(runs):
    """Mean over the windows of (measured overshoot - floor) at b = 0.01, 0.02 between b - 1.2 points and b plus
    the paper controller's own distance to the floor (b = 0) + 0.3 points: the plan's target is b above the least
    overshoot of its own family of plans (r >= 0, whose r = 0 is the paper's controller), which lies between the
    oracle's floor and the paper controller's overshoot (0.3: the prediction's error). Below b at 0.05 by at most
    2.5 points; eq. 4's relaxation on the same plant is further from b (by more than a point at 0.02 and 0.05):
    the modal plan is the better calibrated one. Every window in short mode. (Until the oracle's floor search
    on this link used a finer difference step, 2026-11-26, the floor sat ~0.9 points higher and the band was
    +-1.2 points about b; against the corrected floor the paper's controller is 1.7 points above it, as on eq. 4.)"""
    above0 = runs["model_based_budget:0"][0].mean()
    for b in (0.01, 0.02):
        assert -1.2 < runs[f"model_based_budget:{b:g}"][0].mean() - 100 * b < above0 + 0.3, (b, above0)
    assert -2.5 < runs["model_based_budget:0.05"][0].mean() - 5.0 < 1.2
    for b in (0.02, 0.05):
        modal, eq4 = runs[f"model_based_budget:{b:g}"][0].mean(), runs[f"eq4:{b:g}"][0].mean()
        assert abs(eq4 - 100 * b) > abs(modal - 100 * b) + 1.0, (b, modal, eq4)
    assert all(np.all(v[2]) for v in runs.values())


#: windows and budgets of the documented-meaning test; the band of (measured overshoot - predicted floor F) in points:
#: at most b + BAND_ABOVE_PTS (the running max's tooth slope between its grid points, up to ~0.4 point, plus the
#: prediction's error against the closed loop, up to ~0.2 point: policies/budget_modal.py's docstring), above
#: BAND_BELOW_FRAC x b in every window and at least BAND_MEAN_FRAC x b on average over the windows (the search stops
#: below the first plan that predicts more than F + b, which on a saw-tooth P(r) can lie well below the target; with
#: r forced to 0, the paper's controller, overshoot - F is -0.2..+0.01 points and both lower clauses fail). Measured
#: on windows 1000-1019 (2026-11-28): 0.31-1.00 / 0.46-1.85 / 2.48-3.74 / 5.77-10.31 points at b = 0.01 / 0.02 /
#: 0.05 / 0.1 (means 0.68 / 1.38 / 2.94 / 9.07: 68 / 69 / 59 / 91 % of b; the least window 0.23 b, window 1008 at
#: b = 0.02); eq. 4's r = b on the same plant and stops: above the band.
MEANING_WINDOWS, MEANING_BUDGETS = 6, (0.01, 0.02, 0.05, 0.1)
BAND_ABOVE_PTS, BAND_BELOW_FRAC, BAND_MEAN_FRAC = 0.6, 0.1, 0.5


def test_budget_means_measured_overshoot_above_its_predicted_floor():
    """What ``model_based_budget:b`` documents on the exact-mode link (policies.make, compare --help, the class
    docstring): b is the measured overshoot allowed above the floor F the controller predicts for its own after-stop
    plans at the stop (``predicted_floor``). On nominal windows 1000-1005, for every b: measured overshoot - F <= b +
    BAND_ABOVE_PTS points and > BAND_BELOW_FRAC x b in every window, and its mean over the windows >= BAND_MEAN_FRAC x
    b; every window in short mode; F is the same at every b (a property of the stop, not of the budget). Eq. 4's
    relaxation r = b on the same plant and windows (the budget read as eq. 4's reference relaxation) leaves the band
    at b = 0.02 in most windows."""
    from envs import SbarChargingVectorEnv
    from policies.compare import _rollout

    def run(b, eq4=False):
        venv = SbarChargingVectorEnv(num_envs=MEANING_WINDOWS, scenario="nominal", config=MODAL)
        pol = BudgetedModelBasedPolicy(venv.policy_context, budget=b, eq4_relaxation=eq4)
        pol.reset(MEANING_WINDOWS)
        _, _, _, last = _rollout(pol, venv, [1000 + i for i in range(MEANING_WINDOWS)])
        assert np.all(last["reached_short_mode"])
        return 100.0 * last["overshoot"], pol.predicted_floor

    floors = []
    for b in MEANING_BUDGETS:
        over, f = run(b)
        assert np.all(np.isfinite(f)) and np.all(f > 0.0)
        above = over - 100.0 * f
        assert np.all(above <= 100.0 * b + BAND_ABOVE_PTS), (b, above)
        assert np.all(above > BAND_BELOW_FRAC * 100.0 * b), (b, above)
        assert np.mean(above) >= BAND_MEAN_FRAC * 100.0 * b, (b, above)
        floors.append(f)
    assert np.all(np.array(floors) == floors[0])
    over4, f4 = run(0.02, eq4=True)
    assert f4 is None   # eq. 4's path predicts nothing
    assert np.mean(over4 - 100.0 * floors[0] > 2.0 + BAND_ABOVE_PTS) > 0.5


@pytest.mark.parametrize("link,says", [("modal", "allowed above F, the overshoot the controller predicts at the stop"),
                                        ("envelope", "relaxation of the controller's reference")])
def test_compare_says_what_the_budget_is(capsys, link, says):
    """`dronewpt compare` with a model_based_budget row (or the budgeted sweep) prints what b is on its link (the
    meaning tested above on the exact-mode link; eq. 4's relaxation on --link envelope); without one it does not;
    `compare --help`'s policy list says both."""
    import argparse

    from mission_sim.cli.common import policy_names
    from mission_sim.cli.learning import _print_compare
    row = {"scenario": "nominal", "train_seeds": 1, "reached_short_mode": 1.0, "peak_i2_a": 12.5,
           "energy_before_stop_j": 1.4, "tracking_rmse_a": 0.7}
    for k in ("overshoot_pct", "energy_after_stop_j", "return"):
        row[k], row[k + "_lo"], row[k + "_hi"] = 1.0, 0.5, 1.5
    ns = argparse.Namespace(episodes=5, seed=1000, link=link, oracle_windows=0)
    _print_compare([{**row, "policy": "model_based_budget:0.02"}], [], ns)
    assert says in capsys.readouterr().out
    _print_compare([{**row, "policy": "model_based"}], [], ns)
    assert "model_based_budget:b" not in capsys.readouterr().out
    help_text = " ".join(policy_names())
    assert "allowed above F, the overshoot the controller predicts at the stop" in help_text
    assert "relaxation" in help_text and "100 B + 3.3 %" in help_text


def test_budget_orders_overshoot_and_energy(runs):
    """A larger budget: more overshoot and less energy after the stop (means over the windows); b = 0 is the
    paper's controller (no relaxation: the prediction's floor is r = 0 or below the budget's)."""
    o = [runs[f"model_based_budget:{b:g}"][0].mean() for b in BUDGETS]
    e = [runs[f"model_based_budget:{b:g}"][1].mean() for b in BUDGETS]
    assert np.all(np.diff(o) > 0.0) and np.all(np.diff(e) < 0.0), (o, e)


def test_constant_plan_predicts_the_steady_peak():
    """A plan that holds the last duty predicts the periodic steady state's instantaneous peak over the modal
    short-mode current (closed form of the modes' steady state and the peak table), whatever r (B = 0)."""
    from wpt_receiver import modal_kernel as mk
    from wpt_receiver import v2_from_duty
    ctx = PolicyContext(link_model="modal")
    link = ctx.link
    lc, tab, mc, v1, i2_sm, vf = bm._plant(link, "schottky")
    d0, vl = 0.3, link.vl_v
    z = np.zeros(4)
    v2 = mk.steady_state(lc, mc, tab, d0, v1, vl + vf, z)
    want = mk.inst_peak(lc, tab, d0, mk.phasors(mc, z, v1, v2)[1], vl + vf) / i2_sm - 1.0
    a = np.full(50, float(v2_from_duty(d0, vl)))
    for r in (0.0, 0.3):
        got = bm.predicted_overshoot(link, "schottky", ctx.control_period_s, d0, vl, a, np.zeros(50), r)
        assert got == pytest.approx(want, abs=2e-4)


def test_relaxation_meets_its_prediction():
    """From the controller's steady state at a charge command: r* in [0, R_MAX], its predicted overshoot within
    b of the least over the grid, a larger budget no smaller r*, and b = 0.05 relaxes (r* > 0)."""
    from wpt_receiver import InverseModelController, duty_from_v2_clipped
    ctx = PolicyContext(link_model="modal")
    pol = BudgetedModelBasedPolicy(ctx, budget=0.0)
    link, dt = ctx.link, ctx.control_period_s
    ctl = InverseModelController(link, dt, pol.lpf, n=1)
    ref = float(pol.i2_ref(np.array([1.0]), np.array([link.vl_v]))[0])
    ctl.reset(ref)
    x0, d_prev = ctl.x[0].copy(), float(duty_from_v2_clipped(ctl.v2_cmd_v[0], link.vl_v))
    u0 = pol._i2_sm - ctl.i2_sm_a
    a, b = bm._v2_plans(ctl.discrete_ss, x0, u0, pol._i2_sm, int(round(bm.HORIZON_S / dt)))
    floor = min(bm.predicted_overshoot(link, "schottky", dt, d_prev, link.vl_v, a, b, r)
                for r in np.linspace(0.0, bm.R_MAX, bm._N_GRID))
    rs = []
    for budget in (0.01, 0.05):
        r = bm.relaxation(budget, link, "schottky", dt, ctl.discrete_ss, x0, u0, pol._i2_sm, d_prev, link.vl_v)
        assert 0.0 <= r <= bm.R_MAX
        assert bm.predicted_overshoot(link, "schottky", dt, d_prev, link.vl_v, a, b, r) <= floor + budget + 1e-12
        rs.append(r)
    assert rs[1] >= rs[0] and rs[1] > 0.0


def test_stacked_equals_alone_on_modal():
    """compare's stacked model-based batch (one controller, a budget per row) gives each budget's rows as
    the policy alone on the modal plant (the relaxation is chosen per row from the row's own budget)."""
    names = ["model_based_budget:0.01", "model_based_budget:0.05"]
    both = run_policies(names, "nominal", 2, 1010, MODAL)
    for n in names:
        alone = run_policies([n], "nominal", 2, 1010, MODAL)[n]
        assert np.array_equal(both[n].d_short, alone.d_short)


def test_each_stop_of_a_mission_chooses_its_relaxation():
    """One receiver (the mission's scalar path): every stop after charging computes a relaxation from the state
    at that stop (two stops, two calls; none while charging or while staying stopped); the eq. 4 context never
    predicts."""
    from mission_sim.contract import OBS_DIM, OBS_INDEX, normalise_obs
    calls = []
    orig = bm.plan

    def spy(*a):
        calls.append(a[8])   # the last duty before the stop
        return orig(*a)

    for link_model, want in (("modal", 2), ("envelope", 0)):
        calls.clear()
        pol = BudgetedModelBasedPolicy(PolicyContext(link_model=link_model), budget=0.02)
        pol.reset(1)
        phys = np.zeros(OBS_DIM)
        phys[OBS_INDEX["battery_v"]] = 30.0
        bm.plan = spy
        try:
            for cmd in [2.0] * 30 + [0.0] * 30 + [3.0] * 30 + [0.0] * 5:
                phys[OBS_INDEX["charge_cmd_a"]] = cmd
                pol.act(normalise_obs(phys[None, :]))
        finally:
            bm.plan = orig
        assert len(calls) == want, link_model
    assert calls == [] and pol._relax is None


@pytest.fixture(scope="module")
def stop_1000():
    """The arguments of :func:`policies.budget_modal.relaxation` at nominal window 1000's real stop on the modal
    env (``model_based_budget:0.05``), captured in the closed loop."""
    caps = _captured_stops("model_based_budget:0.05", 1, 1000)
    assert len(caps) == 1
    return caps[0]


def _captured_stops(spec: str, episodes: int, seed: int) -> list:
    """The arguments (after the first) of every :func:`policies.budget_modal.plan` call (the policy's one entry:
    relaxation and floor) while ``spec`` runs ``episodes`` nominal windows from ``seed`` on the modal env."""
    caps = []
    orig = bm.plan

    def spy(*a):
        caps.append(a[1:])
        return orig(*a)
    bm.plan = spy
    try:
        run_policies([spec], "nominal", episodes, seed, MODAL)
    finally:
        bm.plan = orig
    return caps


@pytest.mark.parametrize("budget", [0.02, 0.05])
def test_every_smaller_relaxation_meets_the_target(stop_1000, budget):
    """At a real stop, every r' <= r* on a 0.0005 grid (independent of the search's own step) predicts P <= F + b,
    F the least over the coarse grid, and the search's next grid point above r* does not (r* is the largest).
    P(r) is a saw-tooth here: a search that lands in a tooth's dip (r* = 0.0315 at b = 0.05, with r' = 0.03
    predicting 9.91 % against the target 8.48 %) fails this."""
    link, devices, dt, ss, x0, u0, du, d_prev, vl = stop_1000
    a, b = bm._v2_plans(ss, x0, u0, du, int(round(bm.HORIZON_S / dt)))

    def pred(r):
        return bm.predicted_overshoot(link, devices, dt, d_prev, vl, a, b, r)
    target = min(pred(r) for r in np.linspace(0.0, bm.R_MAX, bm._N_GRID)) + budget
    r_star = bm.relaxation(budget, *stop_1000)
    assert 0.0 < r_star < bm.R_MAX
    worst = max(pred(r) for r in np.arange(0.0, r_star + 1e-12, 0.0005))
    assert worst <= target, (r_star, worst, target)
    assert pred(r_star + bm.R_STEP) > target


@pytest.mark.parametrize("field,value", [("vl_v", float("nan")), ("vl_v", -30.0), ("vl_v", 0.0),
                                         ("d_prev", float("nan")), ("d_prev", 1.5), ("x0", float("nan")),
                                         ("budget", float("nan"))])
def test_bad_stop_state_raises(stop_1000, field, value):
    """A NaN or out-of-range battery voltage, last duty, controller state or budget raises ValueError naming the
    value (a NaN made every P NaN, so that no P exceeded the target and r = R_MAX was returned silently)."""
    link, devices, dt, ss, x0, u0, du, d_prev, vl = stop_1000
    kw = {"budget": 0.05, "vl_v": vl, "d_prev": d_prev, "x0": x0}
    kw[field] = np.full_like(x0, value) if field == "x0" else value
    with pytest.raises(ValueError, match=field):
        bm.relaxation(kw["budget"], link, devices, dt, ss, kw["x0"], u0, du, kw["d_prev"], kw["vl_v"])


def test_bad_battery_voltage_at_a_stop_raises():
    """The policy's one-receiver path: a stop observed with a NaN battery voltage raises ValueError naming it
    (it chose r = R_MAX silently; a measured voltage below 20 V is clamped by the policy's sensing)."""
    from mission_sim.contract import OBS_DIM, OBS_INDEX, normalise_obs
    pol = BudgetedModelBasedPolicy(PolicyContext(link_model="modal"), budget=0.02)
    pol.reset(1)
    phys = np.zeros(OBS_DIM)
    phys[OBS_INDEX["battery_v"]] = 30.0
    phys[OBS_INDEX["charge_cmd_a"]] = 2.0
    for _ in range(20):
        pol.act(normalise_obs(phys[None, :]))
    phys[OBS_INDEX["battery_v"]], phys[OBS_INDEX["charge_cmd_a"]] = np.nan, 0.0
    with pytest.raises(ValueError, match="vl"):
        pol.act(normalise_obs(phys[None, :]))


def test_eq4_relaxation_option():
    """``eq4_relaxation=True`` on the modal context: the reference after the stop is relaxed by the budget itself
    (eq. 4's ``(1 + b) I2_sm``, as on the envelope context), no prediction is made, and it is not stacked with
    the modal policies (its rows would get the modal plan)."""
    from policies.batched import stackable
    calls = []
    orig = bm.plan
    bm.plan = lambda *a: calls.append(a) or orig(*a)
    try:
        env4 = BudgetedModelBasedPolicy(PolicyContext(link_model="envelope"), budget=0.05)
        opt = BudgetedModelBasedPolicy(PolicyContext(link_model="modal"), budget=0.05, eq4_relaxation=True)
        cmd, vl = np.array([2.0, 0.0]), np.array([30.0, 30.0])
        got = opt.i2_ref(cmd, vl)
        assert np.allclose(got, env4.i2_ref(cmd, vl))
        assert got[1] == pytest.approx(ModelBasedPolicy(opt.ctx).i2_ref(cmd, vl)[1] + 0.05 * opt._i2_sm)
    finally:
        bm.plan = orig
    assert calls == [] and opt.name == "model_based_budget_eq4:0.05"
    assert stackable(opt) is None and stackable(BudgetedModelBasedPolicy(opt.ctx, budget=0.05)) is not None


def test_a_recycled_row_starts_its_window_afresh():
    """Two receivers on the modal context: both charge, both stop (each chooses its r from its state); row 0 is
    recycled (``restart``) into a window that opens stopped. Its r is then the budget, as for a window that starts
    stopped, not the previous window's r; row 1 keeps its own. After charging again, row 0's next stop chooses afresh."""
    from mission_sim.contract import OBS_DIM, OBS_INDEX, normalise_obs
    pol = BudgetedModelBasedPolicy(PolicyContext(link_model="modal"), budget=0.05)
    pol.reset(2)
    phys = np.zeros((2, OBS_DIM))
    phys[:, OBS_INDEX["battery_v"]] = 30.0

    def step(cmds, restart=None):
        phys[:, OBS_INDEX["charge_cmd_a"]] = cmds
        pol.act(normalise_obs(phys), restart)
    for _ in range(20):
        step([2.0, 3.0])
    step([0.0, 0.0])
    r_first = pol._relax.copy()
    assert np.all(r_first > 0.0) and np.all(r_first != 0.05), r_first
    step([0.0, 0.0], restart=np.array([0]))
    assert pol._relax[0] == 0.05 and pol._relax[1] == r_first[1]
    for _ in range(20):
        step([2.0, 0.0])
    step([0.0, 0.0])
    assert pol._relax[0] != 0.05 and pol._relax[1] == r_first[1]


def _run_duties_overshoot(link, devices, dt, d_prev, vl, a, b, r):
    """``P(r)`` as the search predicted it before :func:`wpt_receiver.modal_kernel.held_peak` (the reference):
    :func:`wpt_receiver.modal_kernel.run_duties` (with energies) on ``[d_prev, plan]``, each duty repeated over
    the rectifier sub-steps, the max over the plan's sub-step ends."""
    from wpt_receiver import duty_from_v2_clipped
    from wpt_receiver import modal_kernel as mk
    lc, tab, mc, v1, i2_sm, vf = bm._plant(link, devices)
    d = np.r_[d_prev, duty_from_v2_clipped(a + r * b, vl)]
    sub = max(1, int(round(dt / link.rectifier_period_s)))
    pk = mk.run_duties(lc, mc, tab, np.repeat(d, sub), dt / sub, 1, v1, vl + vf, link.lm_h)[3]
    return float(pk[sub + 1:].max() / i2_sm - 1.0)


def test_plan_peak_is_run_duties_bit_for_bit(stop_1000):
    """The search's P(r) (held_peak without energies, the d_prev prefix once per stop, the short-mode tail stopped
    early by its bound) is exactly run_duties' on the same duties, for plans that never reach duty 1 (r = 0), reach it
    late or early (r up to R_MAX): the search's answer cannot move."""
    from wpt_receiver import duty_from_v2_clipped
    link, devices, dt, ss, x0, u0, du, d_prev, vl = stop_1000
    a, b = bm._v2_plans(ss, x0, u0, du, int(round(bm.HORIZON_S / dt)))
    tails = set()
    for r in (0.0, 0.0002, 0.003, 0.0316, 0.1, 0.5):
        d = duty_from_v2_clipped(a + r * b, vl)
        tails.add(bool(d[-1] == 1.0))
        assert bm.predicted_overshoot(link, devices, dt, d_prev, vl, a, b, r) == \
            _run_duties_overshoot(link, devices, dt, d_prev, vl, a, b, r), r
    assert tails == {False, True}


def test_short_mode_tail_bound_holds(stop_1000):
    """The bound held_peak stops on: at every sub-step of a plan's short-mode tail, every later sub-step's
    instantaneous peak is at most ``cap + sum_i w_i |(V^-1 (x - x*))_i|`` (stepped one sub-step at a time with the
    kernel, the bound evaluated in numpy), and the bound falls below the plan's max before the horizon ends (the
    early stop does save steps); x* is the steady state of duty 1 (modal_kernel.steady_state)."""
    from wpt_receiver import duty_from_v2_clipped
    from wpt_receiver import modal_kernel as mk
    link, devices, dt, ss, x0, u0, du, d_prev, vl = stop_1000
    lc, tab, mc, v1, i2_sm, vf = bm._plant(link, devices)
    a, b = bm._v2_plans(ss, x0, u0, du, int(round(bm.HORIZON_S / dt)))
    z, v2, sub, zc, vc, tail = bm._start(link, devices, dt, d_prev, vl)
    vinv, xs, w, cap = tail
    zs = np.zeros(4)
    v2s = mk.steady_state(lc, mc, tab, 1.0, v1, vc, zs)
    assert np.allclose(xs, [complex(zs[0], zs[1]), complex(zs[2], zs[3]), v2s], rtol=1e-9, atol=1e-9)
    d = duty_from_v2_clipped(a + 0.05 * b, vl)
    k_tail = int(np.flatnonzero(d != 1.0)[-1]) + 1
    peaks, bounds = [], []
    for k, dk in enumerate(d):
        for _ in range(sub):
            p, v2 = bm._held_peak(lc, mc, tab, zc, z, v2, np.array([dk]), 1, v1, vc)
            peaks.append(p)
            x = np.array([complex(z[0], z[1]), complex(z[2], z[3]), v2])
            bounds.append(cap + w @ np.abs(vinv @ (x - xs)) if k >= k_tail else np.inf)
    peaks, bounds = np.array(peaks), np.array(bounds)
    later = np.maximum.accumulate(peaks[::-1])[::-1]   # the max over each sub-step and every later one
    assert np.all(later[1:] <= bounds[:-1])
    hit = np.flatnonzero(bounds < np.maximum.accumulate(peaks))
    assert len(hit) and hit[0] < len(peaks) - 10 * sub, (len(hit), len(peaks))


def _reference_search(stop, budget, predict=_run_duties_overshoot):
    """``r*`` by the module docstring's rule, plainly: every coarse point's whole plan (the floor), then every fine
    point's whole plan from ``r = 0`` up to the first above the target (at most up to the coarse grid's first point
    above it), one prediction per point, no cache, no early stop."""
    link, devices, dt, ss, x0, u0, du, d_prev, vl = stop
    a, b = bm._v2_plans(ss, x0, u0, du, int(round(bm.HORIZON_S / dt)))
    coarse = np.linspace(0.0, bm.R_MAX, bm._N_GRID)
    pc = np.array([predict(link, devices, dt, d_prev, vl, a, b, r) for r in coarse])
    target = np.nanmin(pc) + budget
    above = ~(pc <= target)
    n_fine = int(round((coarse[int(np.argmax(above))] if above.any() else bm.R_MAX) / bm.R_STEP))
    k = 0
    while k <= n_fine and predict(link, devices, dt, d_prev, vl, a, b, k * bm.R_STEP) <= target:
        k += 1
    return round(max(0, k - 1) * bm.R_STEP, 12)


@pytest.mark.parametrize("budget", [0.02, 0.05])
def test_search_equals_the_reference_search(stop_1000, budget):
    """r* is the plain reference search's on run_duties' predictions (the same coarse floor and running max on the
    R_STEP grid); asked again at the same stop nothing is predicted again (the stop's intervals are unchanged), and
    a second budget at the same stop (as compare's stacked rows) that reuses the stop's plans gets the r* it gets
    alone."""
    bm._STOPS.clear()
    assert bm.relaxation(budget, *stop_1000) == _reference_search(stop_1000, budget)
    stop = next(iter(bm._STOPS.values()))
    known = [x.copy() for x in (stop.c_lo, stop.c_hi, stop.f_lo, stop.f_hi)]
    r_again = bm.relaxation(budget, *stop_1000)
    assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(known, (stop.c_lo, stop.c_hi, stop.f_lo, stop.f_hi)))
    r_shared = bm.relaxation(0.01, *stop_1000)
    bm._STOPS.clear()
    assert bm.relaxation(0.01, *stop_1000) == r_shared and r_again == bm.relaxation(budget, *stop_1000)


def test_a_stop_is_shared_only_by_the_exact_same_state(stop_1000):
    """The stop memo (``_STOPS``, keyed on the bytes of the stop's inputs) gives a repeated stop exactly the fresh
    search's r* without a new entry; a state one ulp away (in the controller's state or the battery voltage: the
    residual's and imitation's seeds stop within ~4e-5 of each other, never at the same state) is a new stop,
    searched afresh, with the r* of its own fresh search."""
    link, devices, dt, ss, x0, u0, du, d_prev, vl = stop_1000
    bm._STOPS.clear()
    fresh = bm.relaxation(0.01, *stop_1000)
    assert len(bm._STOPS) == 1 and bm.relaxation(0.01, *stop_1000) == fresh and len(bm._STOPS) == 1
    x1 = np.array(x0, dtype=float)
    x1[0] = np.nextafter(x1[0], np.inf)
    for moved in ((link, devices, dt, ss, x1, u0, du, d_prev, vl),
                  (link, devices, dt, ss, x0, u0, du, d_prev, float(np.nextafter(vl, 0.0)))):
        bm._STOPS.clear()
        assert bm.relaxation(0.01, *stop_1000) == fresh and len(bm._STOPS) == 1   # the original stop in the memo
        got = bm.relaxation(0.01, *moved)
        assert len(bm._STOPS) == 2       # a miss beside it, not the original's entry
        bm._STOPS.clear()
        assert bm.relaxation(0.01, *moved) == got
    bm._STOPS.clear()


@pytest.fixture(scope="module")
def stops_1001():
    """The arguments of :func:`policies.budget_modal.relaxation` at the real stops of nominal windows 1001-1003 on
    the modal env (``model_based_budget:0.01``), captured in the closed loop."""
    caps = _captured_stops("model_based_budget:0.01", 3, 1001)
    assert len(caps) == 3
    return caps


def test_compiled_search_equals_a_plain_search_on_real_stops(stops_1001):
    """The compiled search (coarse pass and fine scan over blocks of plans in one call each, a plan stopped once above
    its threshold, a stop's intervals shared by its budgets) gives the plain reference search's r* (whole plans of
    held_peak, no cache) on three real stops at four budgets, each stop's cache fresh and shared by the budgets in a
    mixed order (a larger budget's lower bounds, then a smaller budget's question); every r* positive and below R_MAX
    (the scan, not an end of the grid, decides it). What the stop keeps about each P it was asked (lo <= P <= hi)
    holds the whole plan's P."""
    def plain(link, devices, dt, d_prev, vl, a, b, r):
        return bm.predicted_overshoot(link, devices, dt, d_prev, vl, a, b, r)
    for stop in stops_1001:
        want = {b: _reference_search(stop, b, plain) for b in (0.005, 0.01, 0.02, 0.05)}
        assert all(0.0 < r < bm.R_MAX for r in want.values()), want
        for b in want:
            bm._STOPS.clear()
            assert bm.relaxation(b, *stop) == want[b], (b, want)
        bm._STOPS.clear()
        for b in (0.02, 0.005, 0.05, 0.01):
            assert bm.relaxation(b, *stop) == want[b], (b, want)
        # what the stop keeps about each P it asked (an interval: exact, or a lower bound) holds the whole plan's P
        link, devices, dt, ss, x0, u0, du, d_prev, vl = stop
        kept = next(iter(bm._STOPS.values()))
        a, b = kept.a, kept.b
        asked = np.flatnonzero(np.isfinite(kept.f_lo) | np.isfinite(kept.f_hi))
        assert len(asked) > 10 and np.any(kept.f_lo[asked] < kept.f_hi[asked])   # exact ones and lower bounds
        for k in asked:
            p = plain(link, devices, dt, d_prev, vl, a, b, k * bm.R_STEP)
            assert kept.f_lo[k] <= p <= kept.f_hi[k], (k, kept.f_lo[k], p, kept.f_hi[k])
        for i, r in enumerate(np.linspace(0.0, bm.R_MAX, bm._N_GRID)):
            p = plain(link, devices, dt, d_prev, vl, a, b, r)
            assert kept.c_lo[i] <= p <= kept.c_hi[i], (r, kept.c_lo[i], p, kept.c_hi[i])


def test_plan_stopped_above_a_threshold_is_a_lower_bound(stop_1000):
    """A plan stopped once its overshoot so far exceeds a threshold returns a value above the threshold and at most
    the whole plan's P (so "above the target" is decided as on the whole plan); a threshold above P changes
    nothing (the whole plan's P, bit for bit)."""
    link, devices, dt, ss, x0, u0, du, d_prev, vl = stop_1000
    a, b = bm._v2_plans(ss, x0, u0, du, int(round(bm.HORIZON_S / dt)))
    start = bm._start(link, devices, dt, d_prev, vl)
    for r in (0.0, 0.0316, 0.1):
        p = bm._plan_overshoot(link, devices, start, vl, a, b, r)
        assert bm._plan_overshoot(link, devices, start, vl, a, b, r, p + 1e-3) == p
        for below in (0.005, 0.02):
            q = bm._plan_overshoot(link, devices, start, vl, a, b, r, p - below)
            assert p - below < q <= p, (r, below, q, p)
