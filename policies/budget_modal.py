"""The budgeted model-based controller's after-stop plan predicted on the exact-mode link: what
:class:`policies.budgeted.BudgetedModelBasedPolicy` turns its budget into when its
:class:`~mission_sim.contract.PolicyContext` says the plant is the modal link (``link_model="modal"``).

**What the budget sets.** The controller (paper Fig. 5: ``Q G22^-1``, eq. 4's model, then ``f^-1``) is pure
feed-forward: from the stop on, its V2* sequence is fixed by its state at the stop and the reference it is
given, ``(1 + r) I2_sm``; so is the duty plan ``d_k(r) = f^-1(V2*_k(r), VL)``. With eq. 4's model (the
envelope path, unchanged) ``r`` is the budget ``b`` itself: the envelope overshoot the model promises. On the
modal link that promise is off twice: the SBAR's quadrature rings the exact modes near short mode, and the
measured overshoot is the instantaneous peak (the ripple on top), each window with its floor.

**Here** the plan is predicted with the exact-mode link (:func:`wpt_receiver.modal_kernel.run_duties`' steps: the
link's modes at the assumed Lm; the SBAR's *explicit* commutation :func:`~wpt_receiver.modal_kernel.sbar_v2`
with its quadrature, V2 set from i2's phase at the start of each rectifier sub-step, where the env and the
mission solve the commutation implicitly, :func:`~wpt_receiver.modal_kernel.sbar_implicit`; the phase-aware
instantaneous peak; the constants of :func:`policies.mpc_modal._link_modes`, the MPC's), from the periodic
steady state of the last duty before the stop, with the battery voltage measured at the stop held:

    P(r) = max_k peak_k(r) / I2_sm - 1          (the predicted measured overshoot of the plan)
    F    = min P(r) over the coarse grid        (the least this controller's plans reach: its floor)
    r*   = the largest fine-grid r whose running max  max_{r' <= r} P(r')  is <= F + b

**Why a running max on a fine grid.** ``P(r)`` is a saw-tooth at the 0.001 scale of ``r``: each tooth is
(apparently) one control period by which the plan's arrival at duty 1 moves, ``P`` jumps up at a tooth's left
edge and falls smoothly across it (window 1000's stop at b = 0.05, target 8.48 %: P = 9.91 / 8.41 / 6.56 / 9.86 %
at r = 0.03 / 0.031 / 0.0315 / 0.032; the closed loop on the env, with its implicit commutation, measured 9.96 /
8.46 / 6.61 / 9.92 %: the explicit prediction is within 0.2 point of it there). A bisection or a coarse grid
lands in a tooth's dip; the running max over a grid of step :data:`R_STEP` (finer than a tooth, ~9 points per
tooth near r = 0.03) does not. Between two grid points the running max may still be exceeded by up to the tooth's
slope times the step (up to ~0.4 point at a tooth's left edge). The fine scan runs from ``r = 0`` up to the first
grid point above the target (at most up to the coarse grid's first point above it), so its cost is ``r* /
R_STEP`` predictions.

**Cost, the same numbers.** A prediction is :func:`wpt_receiver.modal_kernel.held_peak`: ``run_duties``' steps
without its energies (two stored-energy evaluations and the step's integrals per sub-step), from the state after
``d_prev``'s control period computed once per stop; once a plan's remaining duties are all 1 (short mode, the link
affine) it stops as soon as a bound on every later peak (the modes' decay, :func:`_tail_bound`) is below the max
so far, so the max is unchanged. A stop's predictions are kept per ``r`` (:func:`_stop_plans`, the last 64 stops
keyed on their exact inputs): ``r = 0`` is on both grids, and stacked budgets at one stop share them; a plan stops
as soon as it is above the threshold it is asked about (the target in the fine scan; the least exact ``P`` so far
plus b on the coarse grid, which leaves the floor and every flag as they are), kept as a lower bound. ``P(r)`` is
bit-identical to ``run_duties``' (``tests/test_budget_modal.py``) and so ``r*``: the same on all 100 stops of
nominal windows 1000-1099 at b = 0.01, 0.02, 0.05, 0.1 (``benchmarks/bench_budget_modal.py``). Per stop
(in-process CPU, medians over those stops, load 3.6-4.1 on 2 cores, 2026-11-26): 17 / 27 / 46 / 104 ms at b =
0.01 / 0.02 / 0.05 / 0.1, against 97 / 161 / 327 / 1070 ms with ``run_duties`` (5.6x / 5.9x / 7.1x / 10.3x;
docs/budget_search_cost.md). The coarse pass and the fine scan run compiled over blocks of plans
(:mod:`policies.budget_scan`, one call per block instead of one per plan; a stop keeps what it knows of each
``P`` as an interval), and ``B`` is computed once per controller (:func:`_v2_step`): ~1.1-1.3x less CPU per stop,
the same ``r*`` on all 1,500 stops of the modal ``compare --episodes 100`` (2026-11-26, branch ``budgetspeed``).
What remains is the non-linear SBAR step itself (~0.2 us per sub-step, 17 sub-steps per control period, up to 200
periods while a plan has not reached duty 1), needed whole for every fine point below ``r*``.

The budget is then *the measured overshoot above F*, the floor of the controller's own plans as the prediction
sees it: in practice its r = 0 plan's prediction (the paper's controller; every stop of nominal windows 1000-1019),
within 0.2 point of ``model_based``'s measured overshoot (a window's oracle floor is lower: docs/modal_policies.md,
section "`model_based_budget:b` on the modal link"). ``b = 0`` stays the paper's controller (``r = 0``, no
prediction), as on eq. 4. Bad inputs (a non-finite or non-positive battery voltage, a last duty outside [0, 1], a non-finite controller state or
budget) raise :class:`ValueError` naming the value and its valid range; a non-finite prediction counts as
above the target (the scan stops there).
"""

from __future__ import annotations

from collections import OrderedDict
from functools import lru_cache

import numpy as np

__all__ = ["relaxation", "plan", "predicted_overshoot", "R_MAX", "R_STEP", "HORIZON_S"]

#: the largest relaxation of the reference searched (fraction of I2_sm)
R_MAX = 0.5
#: the prediction's horizon after the stop [s] (V2* reaches 0 within ~10 ms at the smallest budgets searched)
HORIZON_S = 0.02
#: the fine grid's step of the relaxation (a tooth of P(r) is ~0.0015 wide near r = 0.03: module docstring)
R_STEP = 0.0002
_N_GRID = 21


@lru_cache(maxsize=4)
def _plant(link, devices: str):
    """``(lc, tab, mc, v1, I2_sm, Vf)`` of the exact-mode link (the MPC's constants, :mod:`policies.mpc_modal`):
    the short-mode |I2| [A] of the modes (steady state at duty 1) and the rectifier's forward drop [V]."""
    from wpt_receiver import modal_kernel as mk

    from .mpc_modal import _link_modes
    lc, tab, mc, dev = _link_modes(link, devices)
    v1 = -1j * link.v1_amp_v
    z = np.zeros(4)
    vc = link.vl_v + dev.rect_vf_v
    v2 = mk.steady_state(lc, mc, tab, 1.0, v1, vc, z)
    return lc, tab, mc, v1, float(abs(mk.phasors(mc, z, v1, v2)[1])), dev.rect_vf_v


def _v2_plans(ctl_ss, x0, u0, du, n):
    """``(A (n,), B (n,))``: the controller's V2* [V] over ``n`` steps from the state ``x0`` under the constant
    input ``u0 + r du`` is ``A + r B`` (``ctl_ss`` = ``(Ad, Bd, Cd, Dd)`` of the inverse controller). ``B``, the
    response to ``du`` from rest, does not depend on the stop: computed once per controller (:func:`_v2_step`)."""
    ad, bd, cd, dd = ctl_ss
    a = np.empty(n)
    x = np.asarray(x0, dtype=float).copy()
    du_a, bu_a = dd * u0, bd * u0   # the constant terms, once (the same numbers)
    for k in range(n):
        a[k] = cd @ x + du_a
        x = ad @ x + bu_a
    return a, _v2_step(*((np.asarray(m, dtype=float).shape, np.asarray(m, dtype=float).tobytes()) for m in ctl_ss),
                       float(du), int(n))


@lru_cache(maxsize=8)
def _v2_step(ad, bd, cd, dd, du, n):
    """``B`` of :func:`_v2_plans` for the controller ``(Ad, Bd, Cd, Dd)`` (each ``(shape, bytes)``, so it can be a
    cache key): its V2* [V] over ``n`` steps from rest under the input ``du`` (read-only)."""
    ad, bd, cd, dd = (np.frombuffer(m[1]).reshape(m[0]) for m in (ad, bd, cd, dd))
    b = np.empty(n)
    xb = np.zeros(len(bd))
    du_b, bu_b = dd * du, bd * du
    for k in range(n):
        b[k] = cd @ xb + du_b
        xb = ad @ xb + bu_b
    b.flags.writeable = False
    return b


@lru_cache(maxsize=4)
def _tail_bound(link, devices: str, dt_s: float):
    """``(V^-1 (3, 3), x* (3,), w (3,), |I2*| [A], excess [A/V])`` of the short-mode tail for
    :func:`wpt_receiver.modal_kernel.held_peak` (its docstring): the step at duty 1 is affine in ``x = (z0, z1,
    V2)``; its linear part ``M`` and I2's readout ``C`` are taken from the kernel's own step
    (:func:`~wpt_receiver.modal_kernel.held_peak` over one sub-step, :func:`~wpt_receiver.modal_kernel.phasors`)
    on the unit vectors with ``V1 = 0`` and ``Vc = 0`` (then exactly linear), ``x*`` its fixed point under
    ``V1``, ``M = V diag(lam) V^-1``, ``w_i = |(C V)_i| |lam_i| (1 + 1e-9)``; ``excess`` the peak table's largest
    excess at duty 1 (the lookup there interpolates in phase and |I2| only). ``None`` when a mode does not decay (``|lam| >= 1``) or ``V`` is ill-conditioned: no
    early stop then."""
    from wpt_receiver import modal_kernel as mk
    lc, tab, mc, v1, i2_sm, vf = _plant(link, devices)
    sub, zc = _substeps(link, dt_s, mc)
    one = np.ones(1)
    no_vinv, no_x, no_w = np.zeros((3, 3), np.complex128), np.zeros(3, np.complex128), np.zeros(3)

    def step(x, v1x):
        z = np.array([x[0].real, x[0].imag, x[1].real, x[1].imag])
        v2 = mk.held_peak(lc, mc, tab, zc, z, x[2], one, 1, v1x, 0.0, 1, no_vinv, no_x, no_w, 0.0)[1]
        return np.array([complex(z[0], z[1]), complex(z[2], z[3]), v2])

    def i2(x, v1x):
        return mk.phasors(mc, np.array([x[0].real, x[0].imag, x[1].real, x[1].imag]), v1x, x[2])[1]
    eye = np.eye(3, dtype=np.complex128)
    m = np.column_stack([step(e, 0j) for e in eye])
    c = np.array([i2(e, 0j) for e in eye])
    xs = np.linalg.solve(eye - m, step(np.zeros(3, np.complex128), v1))
    lam, vec = np.linalg.eig(m)
    if not (np.all(np.abs(lam) < 1.0) and np.linalg.cond(vec) < 1e6):
        return None
    w = np.abs(c @ vec) * np.abs(lam) * (1.0 + 1e-9)
    excess = float(tab[1, :, -1, :].max())   # duty 1 is the table's last row: the lookup's weight on it is 1
    return np.linalg.inv(vec), xs, w, abs(i2(xs, v1)), excess


def _substeps(link, dt_s, mc):
    """``(sub, zc)``: the rectifier sub-steps per control period and the sub-step's ZOH coefficients."""
    from wpt_receiver import modal_kernel as mk
    # V2 follows i2's phase once per rectifier period (as the env's sub-steps; held longer, it pumps the link),
    # and the peak is taken at every sub-step's end as the env's (each duty repeated over its sub-steps)
    sub = max(1, int(round(dt_s / link.rectifier_period_s)))
    zc = np.empty(mk.N_ZOH_C, dtype=np.complex128)
    mk.zoh(mc, dt_s / sub, zc)
    return sub, zc


def _start(link, devices, dt_s, d_prev, vl_v):
    """``(z, v2, sub, zc, vc, tail)`` at the plan's start: the mode state (4 reals) and V2 [V] after the duty
    ``d_prev`` held for one control period from its periodic steady state, the rectifier sub-steps per control
    period, the sub-step's ZOH, the clamp ``VL + Vf`` [V] and the short-mode tail's bound (:func:`_tail_bound`,
    its cap with this clamp; ``None``: none); the same for every ``r`` (computed once per stop)."""
    from wpt_receiver import modal_kernel as mk
    lc, tab, mc, v1, i2_sm, vf = _plant(link, devices)
    sub, zc = _substeps(link, dt_s, mc)
    vc = vl_v + vf
    z = np.zeros(4)
    v2 = mk.steady_state(lc, mc, tab, d_prev, v1, vc, z)
    tail = _tail_bound(link, devices, dt_s)
    if tail is not None:
        vinv, xs, w, i2s, excess = tail
        # the margin (1e-6 A) is ~1e6 times the rounding and the ~1e-15 V of V2's clamp part in short mode
        tail = (vinv, xs, w, i2s + vc * excess + 1e-6)
    v2 = _held_peak(lc, mc, tab, zc, z, v2, np.array([float(d_prev)]), sub, v1, vc)[1]
    return z, v2, sub, zc, vc, tail


def _held_peak(lc, mc, tab, zc, z, v2, d, sub, v1, vc, tail=None, i2_ref=1.0, above=np.inf):
    """:func:`wpt_receiver.modal_kernel.held_peak`, with the short-mode tail's early stop when ``tail`` is
    given (``(V^-1, x*, w, cap)``) and ``d`` ends in duties 1, and the stop once ``pmax / i2_ref - 1 > above``."""
    from wpt_receiver import modal_kernel as mk
    if tail is None:
        return mk.held_peak(lc, mc, tab, zc, z, v2, d, sub, v1, vc, len(d), np.zeros((3, 3), np.complex128),
                            np.zeros(3, np.complex128), np.zeros(3), 0.0, i2_ref, above)
    not_one = np.flatnonzero(d != 1.0)
    k_tail = int(not_one[-1]) + 1 if len(not_one) else 0
    return mk.held_peak(lc, mc, tab, zc, z, v2, d, sub, v1, vc, k_tail, *tail, i2_ref, above)


def _plan_overshoot(link, devices, start, vl_v, a, b, r, above=np.inf):
    """``P(r)`` from the plan's ``start`` (:func:`_start`): the peak of the duties ``f^-1(a + r b, vl_v)``; with
    ``above`` finite, a lower bound of ``P(r)`` above ``above`` as soon as the plan's peak so far shows one."""
    from wpt_receiver import duty_from_v2_clipped
    lc, tab, mc, v1, i2_sm, vf = _plant(link, devices)
    z, v2, sub, zc, vc, tail = start
    d = np.ascontiguousarray(duty_from_v2_clipped(a + r * b, vl_v), dtype=float)
    above = float(above) if above == above else np.inf   # a NaN threshold: no stop
    return float(_held_peak(lc, mc, tab, zc, z.copy(), v2, d, sub, v1, vc, tail, i2_sm, above)[0] / i2_sm - 1.0)


def predicted_overshoot(link, devices, dt_s, d_prev, vl_v, a, b, r):
    """``P(r)`` (module docstring): the exact-mode link's predicted overshoot (fraction) of the plan
    ``f^-1(a + r b, vl_v)`` after the duty ``d_prev`` held before it (the peak over the plan's sub-steps,
    :func:`wpt_receiver.modal_kernel.held_peak`; the same numbers as :func:`~wpt_receiver.modal_kernel.run_duties`
    on ``[d_prev, plan]`` each repeated over the sub-steps)."""
    return _plan_overshoot(link, devices, _start(link, devices, dt_s, d_prev, vl_v), vl_v, a, b, r)


def _check(budget, d_prev, vl_v, x0) -> None:
    """:class:`ValueError` naming the bad value and its valid range (a NaN would make every ``P`` NaN and the
    search return ``R_MAX`` silently)."""
    if not (np.isfinite(budget) and 0.0 <= budget <= 1.0):
        raise ValueError(f"budget={budget!r} is invalid; valid range: [0, 1] (an overshoot fraction)")
    if not (np.isfinite(vl_v) and vl_v > 0.0):
        raise ValueError(f"vl_v={vl_v!r} is invalid; valid range: a finite battery voltage > 0 V")
    if not (np.isfinite(d_prev) and 0.0 <= d_prev <= 1.0):
        raise ValueError(f"d_prev={d_prev!r} is invalid; valid range: [0, 1] (the last short-mode duty)")
    if not np.all(np.isfinite(x0)):
        raise ValueError(f"x0={np.asarray(x0)!r} is invalid; valid range: a finite controller state")


def _stop_key(link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v):
    """The exact inputs of a stop's plans (bytes of every array, with its shape): equal keys, equal plans."""
    def arr(x):
        x = np.asarray(x, dtype=float)
        return x.shape, x.tobytes()
    return (link, devices, float(dt_s), tuple(arr(m) for m in ctl_ss), arr(x0), float(u0), float(du), float(d_prev),
            float(vl_v))


#: the last stops' plans: key (:func:`_stop_key`) -> :class:`_Stop`, least recent first
_STOPS: OrderedDict = OrderedDict()
_N_STOPS = 64
#: fine-grid plans predicted per compiled call (:func:`policies.budget_scan.fine_scan`); their duties cost ~1 us each
_BLOCK = 48


class _Stop:
    """One stop's plans (:func:`_stop_plans`): the controller's V2* ``A + r B`` (:func:`_v2_plans`), the plans'
    start (:func:`_start`), the coarse grid's duties, and what is known of every ``P`` on the coarse and the fine
    grid (intervals ``lo <= P <= hi``, :mod:`policies.budget_scan`). ``P`` does not depend on the budget."""

    __slots__ = ("link", "devices", "vl_v", "a", "b", "start", "args", "tail", "coarse", "c_lo", "c_hi", "c_tails",
                 "f_lo", "f_hi")

    def __init__(self, link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v):
        from .budget_scan import k_tails
        self.link, self.devices, self.vl_v = link, devices, float(vl_v)
        self.a, self.b = _v2_plans(ctl_ss, x0, u0, du, int(round(HORIZON_S / dt_s)))
        lc, tab, mc, v1, i2_sm, vf = _plant(link, devices)
        self.start = z, v2, sub, zc, vc, tail = _start(link, devices, dt_s, d_prev, vl_v)
        self.tail = tail is not None
        if tail is None:
            tail = (np.zeros((3, 3), np.complex128), np.zeros(3, np.complex128), np.zeros(3), 0.0)
        self.args = (lc, mc, tab, zc, z, v2), (sub, v1, vc), (*tail, i2_sm)
        self.coarse = self.duties(np.linspace(0.0, R_MAX, _N_GRID))
        self.c_tails = k_tails(self.coarse, self.tail)
        self.c_lo, self.c_hi = np.full(_N_GRID, -np.inf), np.full(_N_GRID, np.inf)
        n = int(round(R_MAX / R_STEP)) + 1
        self.f_lo, self.f_hi = np.full(n, -np.inf), np.full(n, np.inf)

    def duties(self, r):
        """The plans' duties ``f^-1(A + r B, VL)`` (len(r), n) for the relaxations ``r`` (each row the same numbers
        as :func:`_plan_overshoot`'s)."""
        from wpt_receiver import duty_from_v2_clipped
        r = np.asarray(r, dtype=float)
        return np.ascontiguousarray(duty_from_v2_clipped(self.a[None, :] + r[:, None] * self.b[None, :], self.vl_v),
                                    dtype=float)

    def floor_pass(self, budget):
        """The coarse grid's ``P`` (exact, or a lower bound above the least so far + ``budget``: module docstring)."""
        from .budget_scan import coarse_pass
        pc = np.empty(_N_GRID)
        (lc, mc, tab, zc, z, v2), (sub, v1, vc), (*tail, i2_sm) = self.args
        coarse_pass(lc, mc, tab, zc, z, v2, self.coarse, sub, v1, vc, self.c_tails, *tail, i2_sm, float(budget),
                    self.c_lo, self.c_hi, pc)
        if self.c_lo[0] == self.c_hi[0] and self.f_lo[0] != self.f_hi[0]:   # r = 0 is on both grids
            self.f_lo[0] = self.f_hi[0] = self.c_lo[0]
        return pc

    def first_above(self, target, n_fine):
        """The least ``k`` in ``0 .. n_fine`` whose ``P(k R_STEP)`` is not ``<= target``, ``n_fine + 1`` if none."""
        from .budget_scan import fine_scan, k_tails
        (lc, mc, tab, zc, z, v2), (sub, v1, vc), (*tail, i2_sm) = self.args
        k = 0
        while k <= n_fine:
            m = min(_BLOCK, n_fine + 1 - k)
            lo, hi = self.f_lo[k:k + m], self.f_hi[k:k + m]
            below = hi <= target
            if below.all():   # known from earlier questions at this stop: no duties, no plan
                k += m
                continue
            j = int(np.argmin(below))
            if np.isnan(lo[j]) or lo[j] > target:
                return k + j
            d = self.duties(np.arange(k, k + m) * R_STEP)
            j = fine_scan(lc, mc, tab, zc, z, v2, d, sub, v1, vc, k_tails(d, self.tail), *tail, i2_sm, float(target),
                          lo, hi)
            if j < m:
                return k + j
            k += m
        return n_fine + 1


def _stop_plans(link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v) -> _Stop:
    """The stop's :class:`_Stop`, kept for the last :data:`_N_STOPS` stops, so stacked controllers at the same stop
    (the budgets of compare's stacked batch; seeds of a learned policy over the same base whose stop states
    coincide) share their plans. The key is the exact inputs, so a shared plan is the same number."""
    key = _stop_key(link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v)
    stop = _STOPS.get(key)
    if stop is not None:
        _STOPS.move_to_end(key)
        return stop
    stop = _STOPS[key] = _Stop(link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v)
    if len(_STOPS) > _N_STOPS:
        _STOPS.popitem(last=False)
    return stop


def relaxation(budget, link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v) -> float:
    """``r*`` (module docstring) of one receiver at its stop: the controller's state ``x0``, its input ``u0 +
    r du`` after the stop (``du`` = I2_sm of the assumed model [A]), the last duty ``d_prev`` and the battery
    voltage ``vl_v`` [V]. ``r*`` is a multiple of :data:`R_STEP` in ``[0, R_MAX]``."""
    return plan(budget, link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v)[0]


def plan(budget, link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v) -> tuple[float, float]:
    """``(r*, F)`` of one receiver at its stop (arguments as :func:`relaxation`): the relaxation and the floor ``F``
    of the controller's own plans as the prediction sees it (a fraction: the least predicted measured overshoot on
    the coarse grid; NaN if no plan was finite). The budget is the measured overshoot allowed above ``F``."""
    _check(budget, d_prev, vl_v, x0)
    stop = _stop_plans(link, devices, dt_s, ctl_ss, x0, u0, du, d_prev, vl_v)
    coarse = np.linspace(0.0, R_MAX, _N_GRID)
    # a coarse point whose plan is above (the least exact P so far) + b is neither the floor nor below the target:
    # its plan stops there (a lower bound of P above that, which leaves the floor and the flags below as they are)
    pc = stop.floor_pass(budget)
    target = np.nanmin(pc) + budget if np.any(np.isfinite(pc)) else -np.inf
    above = ~(pc <= target)   # NaN counts as above
    # the running max's first crossing lies at or below the coarse grid's first point above the target
    r_end = coarse[int(np.argmax(above))] if above.any() else R_MAX
    n_fine = int(round(r_end / R_STEP))
    r_best = stop.first_above(target, n_fine) - 1
    return round(max(0, r_best) * R_STEP, 12), (float(np.nanmin(pc)) if np.any(np.isfinite(pc)) else float("nan"))
