"""Model-predictive control of the SBAR: a receding-horizon QP in V2 on the nominal envelope model.

Model (what the controller assumes, like every model-based policy: Table I from the
:class:`~mission_sim.contract.PolicyContext`, nominal Lm, perfect resonance): the envelope link of
paper eq. 4 with the known semiconductors' constant resistances folded in (R1 + 2 Ron, R2 + Rd,
:func:`wpt_receiver.devices.envelope_params`), discretised at the control period with the exact ZOH
(:func:`wpt_receiver.zoh_discretise`; half-step too, for the mid-step samples the env's peak takes),
state ``x = [I1, I2]``, input the fundamental ``V2`` (linear: eq. 9's duty comes after, from
``f^-1``, :func:`wpt_receiver.duty_from_v2_clipped` at the measured clamp voltage ``VL + Vf``), plus an
input disturbance ``w`` on V2 (offset-free MPC: it absorbs the forward drop, the short window's
resistance and a wrong Lm in the steady state).

**Estimation** (:class:`_DelayBank`): steady-state Kalman filters of ``z = [I1, I2, w]`` (the modal model's
``[s (4), w]``; ``nz`` 3 or 5 below) from the measured
(noisy) I2 envelope and the V2 the previous duties applied, one per hypothesis of the sensing delay
(:data:`DELAYS`, 0-5 control periods: filter ``D`` reads the measurement as the state ``D`` steps ago);
each receiver follows the hypothesis with the least weighted squared innovation, carried forward over
its delay with the V2 applied since (a Smith predictor). Without a delay it is the plain filter.

Every control period, over a prediction horizon of :data:`N_PRED` steps (15 ms, beyond the 4.4 ms
slow pole), V2 piecewise linear between the knots :data:`BLOCKS` (fine near now, coarse later):

* charging (command > 0): track ``I2ref``, the steady I2 of the model *with the estimated w* at the V2
  that delivers the command (power balance ``V2 I2 / 2 = (VL + Vf) I_L``; ``w = 0`` gives the paper's
  reference): ``min sum (I2_k - I2ref)^2 + lam sum dV2^2``, ``0 <= V2 <= (4/pi)(VL + Vf)``, in closed
  form (batched over receivers) when the box is inactive;
* after the stop (command 0): minimise the energy after the stop, linear in V2 at the short-mode
  current (``sum V2_k``, ~ ``sum V2 I2 / 2 dt``), ``+ lam sum dV2^2``, subject to the measured
  overshoot budget on every predicted sample (mid-step and end): ``I2_k + e_k <= (1 + b) I2_sm``
  (``I2_sm`` the model's own short-mode current with the estimated ``w``),
  ``e_k`` the SBAR's ripple excess at the short-mode current (:mod:`envs.peaks`' table, the same the
  env scores with; at a fixed current it is piecewise linear in the duty) linearised along a plan (at
  the stop a ramp to 0, then the previous plan shifted; iterated 3 times in the first 3 steps: SCP),
  the same box on V2, V2 = 0 from 11 ms after the stop on (:data:`_SM_DEADLINE`, at the next knot: a
  shrinking horizon, so short mode is reached even while the bound holds V2 up). The I2 constraints are soft (one slack with an
  exact penalty, 1e6 per A, above the energy term's multiplier): when the state at the stop allows no
  plan within the budget, the bound is raised by the least violation found in the first 3 steps after
  the stop, so the MPC holds the window's floor (:func:`policies.oracle.oracle_floor` from its own
  state at the stop) instead of giving up. A plan still feasible from the new state is followed for
  up to :data:`_REPLAN_EVERY` steps before it is re-solved; once settled in short mode nothing is solved.
A receiver whose command turns positive after its stop starts a new window afresh.

So the budget ``b`` is in the metric's units: the allowed measured (instantaneous-peak) overshoot over
the short-mode current (or the window's floor, if that is higher), not a reference relaxation
(:mod:`policies.budgeted`). Checked by ``tests/test_oracle_mpc.py``: budget 0 measures the floor within
0.5 points on fixed windows, ``mpc:b`` at most ``max(floor, b) + 0.5`` points.

**On the exact-mode link** (the context's ``link_model="modal"``, as the env with
``EnvConfig(link_model="modal")`` gives it) the model is :mod:`policies.mpc_modal`'s instead: the link's
two modes (4 real states, I2's frame) with the SBAR's V2 residual in that frame (its quadrature) linearised
along the plan, the same ``w``, bound, QPs and filters (``z = [s (4), w]``); and the last :data:`_TAIL_V`
of V2 after the stop go linearly in the duty over :data:`_TAIL_STEPS` steps, fewer with a budget
(:meth:`MPCPolicy._duty_tail`, :meth:`MPCPolicy._tail_steps`).
Its constraint back-off is :data:`_MARGIN_MODAL`. With a budget (and ``|w| <=`` :data:`_TAIL_W_MAX`) the after-stop
QP also predicts with the rectifier's phase lock (:mod:`policies.mpc_lock`: V2 turned onto I2's phase every sub-step):
after the unlocked solve, which sets the window's floor, :data:`_LOCK_ITERS` sequential convex iterations on the
locked rows linearised along the previous iterate, each knot within :data:`_LOCK_TRUST` of it, back-off
:data:`_MARGIN_LOCK`; after the stop the estimator steps the locked model open loop. Nominal, 20 windows: ``mpc:0.1``'s
gap to the oracle from its own state at the stop 6.2 -> 3.1 % at 0.42 points less overshoot (docs/rl.md, "The
rectifier's phase lock in the modal MPC's prediction"); budget 0 and eq. 4's MPC bit-identical. Nominal, 100 windows (``compare --link modal``): overshoot
6.39 % -> 2.57 %, energy after the stop 0.832 -> 0.806 J (eq. 4's MPC on eq. 4's plant: 2.54 %, 0.844 J);
eq. 4's path is unchanged to the bit. It costs about twice eq. 4's MPC on that plant (in process, 100 windows
batched: 25-31 ms of CPU per window against 13 ms; end to end 1.4-1.9x; docs/rl.md).

Solver: DAQP (``pip install daqp``; a dual active-set solver for small dense QPs in C, exact), one
QP of 21 variables and 300 constraints per receiver and re-plan, warm-started from the receiver's last
multipliers (~7 active-set iterations instead of ~70, ~0.1 ms); the decisions, the excess
linearisation and the QP data are batched over the receivers, and ``act`` runs with one BLAS thread
(:mod:`policies.threads`); the constraint rows' fixed part stays in one buffer and only the entries the
excess slope changes are rewritten per QP (daqp only reads it). ~14 ms of CPU per nominal window at load ~7
(``benchmarks/bench_mpc.py``; 52 ms before the batching and warm starts, 23 ms before the one buffer, the
same results). Without daqp the policy raises a one-line ``ValueError`` naming the package. (OSQP, used before, stopped at its iteration
limit on most after-stop QPs of this problem and returned unconverged plans.)
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from mission_sim.contract import OBS_INDEX, PolicyContext, denormalise_obs

__all__ = ["MPCPolicy", "N_PRED", "BLOCKS"]

N_PRED = 150
#: knots of the V2 plan [steps from now] (linear in between, held after the last)
BLOCKS = (0, 1, 2, 3, 4, 5, 6, 8, 10, 13, 16, 20, 25, 31, 38, 46, 56, 68, 82, 100, 120)
_LAMBDA = 0.1        # move penalty [A^2/V^2] of the tracking QP (smooth V2: no ringing of the 4 kHz resonance)
_SLACK_W = 1e6      # slack penalty [1/A] of the after-stop QP (exact: above the energy term's multiplier ~1.3e4)
_SLACK_Q = 1e3      # its quadratic part [1/A^2] (strictly convex)
_LAMBDA_STOP = 2e-4  # move penalty [1/V] of the after-stop QP (energy term in V per step)
_RHO_Q = 0.01      # quadratic share of the after-stop energy term [1/V] (keeps the QP strongly convex)
_RELAX_STEPS = 3    # after-stop steps in which the bound may be raised to the floor
_REPLAN_EVERY = 5   # after-stop steps a still-feasible plan is followed before it is re-solved
_SCP_ITERS = 3      # linearisations of the ripple excess per solve in those steps
_MARGIN = 0.002      # constraint back-off, fraction of I2_sm (model error)
_MARGIN_MODAL = 0.006   # the same on the modal model (policies.mpc_modal: its end-of-descent error; on 100 nominal windows mpc:0.05 measures 5.01 %, 5.22 % with 0.4 %, docs/rl.md)
#: hypotheses of the sensing delay [control periods] the estimator tells apart (:class:`_DelayBank`)
DELAYS = (0, 1, 2, 3, 4, 5)
_DELAY_MEMORY = 50.0  # memory of the innovation scores [control periods]
_VLC = 31.0         # the battery voltage of the excess fold [V] (envs.peaks.VL_GRID_V[1], checked in __init__)
_SM_DEADLINE = 110  # steps after the stop from which V2 = 0 (at the next knot; short mode is scored from 14 ms)
_BIG = 1e30         # an absent bound for daqp
#: (modal model) below this V2 [V] after the stop the duty goes to 1 linearly over _TAIL_STEPS (policies.mpc_modal)
_TAIL_V = 2.0
_TAIL_STEPS = 30
#: (modal model) with a budget the tail may be shorter: a tail of n steps rings the link by ~_TAIL_RING / n of the
#: short-mode current (20 nominal windows: 2.9 % at n = 10, 5.5 % at 5, 13 % at 2), so it takes the fewest steps
#: (at least _TAIL_MIN) whose ring stays _TAIL_RESERVE below the budget; 30 steps at budgets up to ~1.9 %
_TAIL_RING = 0.28
_TAIL_RESERVE = 0.01
_TAIL_MIN = 4
#: ... only where the model is right: |w| at the tail's start within this [V] (nominal windows 0.1-1.1 V; detuned tanks
#: 3-970 V, where the 0.28 ring was exceeded: mpc:0.05 3.79 -> 6.35 % on detuned, 20 windows; Lm drift 10-33 V)
_TAIL_W_MAX = 5.0
#: (modal model, budget > 0) the after-stop QP's prediction with the rectifier's phase lock (policies.mpc_lock): after
#: the unlocked solve (whose slack sets the floor), _LOCK_ITERS sequential convex iterations on the locked rows
#: linearised along the previous iterate, each knot within _LOCK_TRUST [V] of it (a trust region); only where the
#: model is right (|w| <= _TAIL_W_MAX, as the tail)
_LOCK = True
_LOCK_ITERS = 2
_LOCK_TRUST = 3.0
#: (the estimator of a locked receiver after its stop steps the locked model open loop, no correction: with the
#: filter's correction the 1-step prediction lost the modes' ring, and correcting w alone rang; docs/rl.md)
_MARGIN_LOCK = 0.004   # the constraint back-off of the locked rows, fraction of I2_sm (20 nominal windows: 0.3 % overshot mpc:0.05 by 0.06 points)
_F = {k: OBS_INDEX[k] for k in ("i2_amp_a", "battery_v", "charge_cmd_a", "last_d_short")}


def _require_daqp():
    import importlib.util
    if importlib.util.find_spec("daqp") is None:
        raise ValueError("policy 'mpc' needs the QP solver daqp: pip install 'dronewpt[mpc]' (or daqp)")


def _block_basis(n: int = None, blocks=None) -> np.ndarray:
    """``M`` (n, knots): V2 over the ``n`` (default :data:`N_PRED`) steps of the horizon piecewise linear between
    the knots ``blocks`` (default :data:`BLOCKS`) (a staircase of held moves would ring the 4 kHz resonance at
    every step of it), held after the last knot. The basis of both prediction models."""
    n = N_PRED if n is None else n
    blocks = BLOCKS if blocks is None else blocks
    return np.stack([np.interp(np.arange(n), blocks, np.eye(len(blocks))[i]) for i in range(len(blocks))], axis=1)


def _kalman_gain(ad, b_w, c, d_w, meas_sd_a=0.1, q_i=1e-3, q_w=0.05) -> np.ndarray:
    """Steady-state gain (nx + 1, 1) of the filter on ``z = [x, w]`` (``x`` the model's nx states, one step
    ``ad``; ``w`` a random walk on V2 entering as ``b_w``) from the measured I2 ``c x + d_w w`` (sd
    ``meas_sd_a`` [A]); process noise sd ``q_i`` per state, ``q_w`` [V] on ``w``. Both models' filter (eq. 4's
    ``c = [0, 1]``, ``d_w = 0``), solved through :func:`_steady_kalman_gain`'s disk cache."""
    nx = len(ad)
    A = np.zeros((nx + 1, nx + 1))
    A[:nx, :nx], A[:nx, nx], A[nx, nx] = ad, b_w, 1.0
    C = np.concatenate([np.asarray(c, dtype=float), [float(d_w)]])[None, :]
    Q = np.diag([q_i ** 2] * nx + [q_w ** 2])
    return _steady_kalman_gain(A, C, Q, np.array([[meas_sd_a ** 2]]))


@lru_cache(maxsize=4)
def _modal_model(link, devices: str, dt_s: float):
    """The exact-mode link's prediction model (:class:`policies.mpc_modal.ModalModel`) of a link, device preset
    and control period over the horizon, on this module's basis and with its filter (shared by the instances)."""
    from .mpc_modal import ModalModel
    m = ModalModel(link, devices, dt_s, N_PRED, _block_basis())
    m.kalman = _kalman_gain(m.ad, m.bu, m.c, m.du)
    return m


@lru_cache(maxsize=4)
def _locked_model(link, devices: str, dt_s: float):
    """The locked-phase model's constants (:class:`policies.mpc_lock.LockedModel`, shared by the instances)."""
    from .mpc_lock import LockedModel
    return LockedModel(link, devices, dt_s)


@lru_cache(maxsize=8)
def _model(link, dt_s: float):
    """The prediction model of a link and control period (:class:`_Model`, shared by the MPC instances)."""
    return _Model(link, dt_s)


class _Model:
    """Condensed predictions of the nominal model over the horizon: the I2 samples (mid-step and end
    of every step, 2 N_PRED rows) = ``F z + G v + h`` with ``z = [I1, I2, w]``, ``v`` the blocked moves."""

    modal = False   # (policies.mpc_modal.ModalModel: True)

    def __init__(self, link, dt_s):
        from wpt_receiver import state_matrices, zoh_discretise
        a, b = state_matrices(link)
        ad, bd = zoh_discretise(a, b, dt_s)
        am, bm = zoh_discretise(a, b, 0.5 * dt_s)
        v1 = link.v1_amp_v
        n = N_PRED
        self.ad, self.b2, self.e = ad, bd[:, 1], bd[:, 0] * v1
        M = _block_basis()
        # state response: x_k = Phi_k x0 + sum_j Psi_{k-1-j} (u_j + w) + c_k; rows 2k (mid-step of step k, from
        # x_k) and 2k + 1 (end of step k: x_{k+1})
        F = np.zeros((2 * n, 3))
        h = np.zeros(2 * n)
        Phi, c = np.eye(2), np.zeros(2)
        imp = np.zeros((2, n))   # I2 response of the mid / end sample of a step to the input i steps earlier
        x = self.b2.copy()
        for k in range(n):
            for r, (A_, E_) in enumerate(((am, bm[:, 0] * v1), (ad, bd[:, 0] * v1))):
                F[2 * k + r, :2] = (A_ @ Phi)[1]
                h[2 * k + r] = (A_ @ c + E_)[1]
            if k:
                imp[:, k] = (am @ x)[1], (ad @ x)[1]
                x = ad @ x
            Phi, c = ad @ Phi, ad @ c + self.e
        imp[:, 0] = bm[1, 1], bd[1, 1]
        lag = np.arange(n)[:, None] - np.arange(n)[None, :]   # k - j
        Gu = np.where(lag >= 0, imp[:, np.maximum(lag, 0)], 0.0).transpose(1, 0, 2).reshape(2 * n, n)
        F[:, 2] = Gu.sum(axis=1)   # the disturbance acts on every step like an input
        self.F, self.G, self.h, self.M, self.Gu = F, Gu @ M, h, M, Gu
        self.ends = np.arange(1, 2 * n, 2)
        self.kalman = _kalman_gain(ad, bd[:, 1], (0.0, 1.0), 0.0)   # on z = [I1, I2, w] from I2 (3, 1)

    def step(self, z, u, vc=None):
        """One step of the estimates ``z`` (..., 3) under the V2 ``u`` (...) [V] (``vc``: the modal model's)."""
        out = np.empty_like(z)
        out[..., :2] = z[..., :2] @ self.ad.T + (u + z[..., 2])[..., None] * self.b2 + self.e
        out[..., 2] = z[..., 2]
        return out

    def step_measure(self, z, u, vc=None):
        """:meth:`step` and the I2 [A] the sensor reads after it (the state's I2)."""
        x = self.step(z, u)
        return x, x[..., 1]


def _steady_kalman_gain(A, C, Q, R) -> np.ndarray:
    """``P C^T (C P C^T + R)^-1`` with ``P`` the solution of the filter's discrete Riccati equation
    (``scipy.linalg.solve_discrete_are(A.T, C.T, Q, R)``), through the disk cache
    (:mod:`wpt_receiver.diskcache`, keyed by the exact bits of the four matrices and the scipy and numpy
    versions): ``import scipy.linalg`` is 0.3-1 s of CPU, most of the MPC's set-up (``compare`` pays it in
    its forked MPC child, on the critical path) for one 3 x 3 equation whose answer never changes. A cached
    gain is the array computed here before (the same bits)."""
    import scipy  # the top-level package only (cheap): its version is part of the key

    from wpt_receiver.diskcache import load, store

    key = (f"kalman v1 A{A.shape}={A.tobytes().hex()} C{C.shape}={C.tobytes().hex()} Q{Q.shape}={Q.tobytes().hex()} "
           f"R{R.shape}={R.tobytes().hex()} scipy={scipy.__version__} numpy={np.__version__}")
    gain = load("kalman", key, (A.shape[0], C.shape[0]))
    if gain is None:
        from scipy.linalg import solve_discrete_are
        P = solve_discrete_are(A.T, C.T, Q, R)
        gain = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
        store("kalman", key, gain)
    return gain


class _DelayBank:
    """Steady-state Kalman filters of ``z`` (n, nz) (``[I1, I2, w]``, the modal model's ``[s (4), w]``), one
    per hypothesis ``D`` of the sensing delay [control periods] (multiple-model estimation): filter ``D`` reads the measured I2 as the state ``D``
    steps ago and is stepped with the V2 applied then (kept in a history); each receiver follows the
    hypothesis with the least exponentially weighted squared innovation (memory :data:`_DELAY_MEMORY`
    steps), whose estimate is carried forward over its delay with the V2 applied since (a Smith
    predictor: the plan starts from the state now, not from the state the sensor shows)."""

    def __init__(self, model, z0, u0, delays):
        self.m, self.delays, self.n = model, tuple(int(d) for d in delays), len(z0)
        self.z = np.repeat(np.asarray(z0, dtype=float)[None], len(self.delays), axis=0)   # (H, n, nz)
        self.u = np.repeat(np.asarray(u0, dtype=float)[None], max(self.delays) + 1, axis=0)   # u[j] = V2 of step k-1-j
        self.score = np.zeros((len(self.delays), self.n))
        self.best = np.zeros(self.n, dtype=int)
        self._lag = np.asarray(self.delays)   # u's rows of the hypotheses (an index array, built once)
        self._prefer = (1.0 + 0.1 * np.arange(len(self.delays)))[:, None]   # a shorter delay preferred
        self.vc = None   # the receivers' clamp voltages [V] (the modal model's residual of V2 needs them)
        #: (modal model) receivers stepped with the phase lock (bool (n,)) and the locked step
        #: (:func:`policies.mpc_lock.locked_step`'s ``(z, u, vc) -> (z, I2)``); None: none
        self.lock, self.lock_step = None, None

    def update(self, y, u_last, vc=None):
        """Filter the measured I2 ``y`` (n,) [A] given the V2 of the last step ``u_last`` (n,) [V] (and, for the
        modal model, the clamp voltages ``vc`` (n,) [V]): ``z`` now."""
        self.u[1:] = self.u[:-1]   # shifted by one step in place (np.roll's values, without a new array)
        self.u[0] = u_last
        self.vc = vc
        uh = self.u[self._lag]
        x, y_model = self.m.step_measure(self.z, uh, vc)   # every hypothesis at once (H, n, nz)
        c = None if self.lock is None else np.flatnonzero(self.lock)
        if c is not None and len(c):
            x[:, c], y_model[:, c] = self.lock_step(self.z[:, c], uh[:, c], vc[c])
        innov = y[None, :] - y_model
        self.z = x + innov[..., None] * self.m.kalman[:, 0]
        if c is not None and len(c):
            self.z[:, c] = x[:, c]   # locked after the stop: open loop (the innovation still scores the delays)
        self.score += (1.0 / _DELAY_MEMORY) * (innov * innov - self.score)
        # a shorter delay is preferred unless a longer one explains the measurements clearly better
        self.best = np.argmin(self.score * self._prefer, axis=0)
        return self.now()

    def now(self):
        """The chosen hypothesis' estimate carried forward over its delay (n, nz)."""
        cols = np.arange(self.n)
        z = self.z[self.best, cols]
        d = self._lag[self.best]
        for j in range(int(d.max(initial=0)) - 1, -1, -1):
            go = np.flatnonzero(d > j)
            c = go[self.lock[go]] if self.lock is not None else go[:0]
            zc = self.lock_step(z[c], self.u[j, c], self.vc[c])[0] if len(c) else None
            z[go] = self.m.step(z[go], self.u[j, go], None if self.vc is None else self.vc[go])
            if len(c):
                z[c] = zc
        return z


class MPCPolicy:
    """Receding-horizon QP controller (see the module docstring); ``budget`` the measured overshoot
    allowed after the stop (fraction), ``link`` the model (default the context's, i.e. Table I),
    ``devices`` the semiconductor preset it knows (the env's default ``schottky``), ``delays`` the sensing
    delays [control periods] its estimator tells apart (``(0,)``: a plain Kalman filter)."""

    name = "mpc"
    uses_link_model = True   # predicts with the context's link_model (mission_sim.setup_warnings)

    def __init__(self, ctx: PolicyContext = PolicyContext(), budget: float = 0.0, link=None,
                 devices: str = "schottky", delays=DELAYS):
        _require_daqp()
        self.delays = tuple(int(d) for d in delays)
        if not self.delays or min(self.delays) < 0 or max(self.delays) > 20:
            raise ValueError(f"delays={delays!r} is invalid; valid: a non-empty set of integers 0..20 [control periods]")
        budget = float(budget)
        if not (np.isfinite(budget) and 0.0 <= budget <= 1.0):
            raise ValueError(f"budget={budget!r} is invalid; valid range: [0, 1] (a measured overshoot fraction)")
        from envs.objective import short_mode_i2_a
        from envs.peaks import fold_vl, peak_table
        from wpt_receiver.devices import envelope_params, preset
        self.ctx, self.budget = ctx, budget
        self.name = "mpc" if budget == 0.0 else f"mpc:{budget:g}"
        base = ctx.link if link is None else link
        dev = preset(devices)
        self._vf = dev.rect_vf_v
        self._link = envelope_params(base, dev)
        # the plant's link (the context's link_model): eq. 4's envelope, or the exact modes (policies.mpc_modal)
        self._modal = ctx.link_model == "modal"
        self._tail_on = self._modal   # the duty-linear approach to short mode (:meth:`_duty_tail`)
        self._margin = _MARGIN_MODAL if self._modal else _MARGIN
        if self._modal:
            self._model = _modal_model(base, devices, float(ctx.control_period_s))
            self._lm_args = (base, devices, float(ctx.control_period_s))
        else:
            self._model = _model(self._link, float(ctx.control_period_s))
        self._i2_sm = float(short_mode_i2_a(base, base.lm_h, dev))
        self._peak_table = fold_vl(peak_table(base, dev))
        from .classical import ModelBasedPolicy
        self._ref = ModelBasedPolicy(PolicyContext(link=self._link, control_period_s=ctx.control_period_s))
        self._setup_qp()
        self.reset(0)
        self._ex0 = float(self._excess_at(np.zeros(1), _VLC)[0])

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self._bank = None
        self._plan = np.zeros((self.n, N_PRED))
        self._relax = np.zeros(self.n)   # [A] the bound raised to what the window allows (its floor)
        self._n_stop = np.zeros(self.n, dtype=int)   # after-stop solves so far
        self._k_stop = np.zeros(self.n, dtype=int)   # steps since the stop
        self._age = np.zeros(self.n, dtype=int)      # steps since the plan was solved
        self._lam = np.zeros((self.n, len(self._sense)))   # the last after-stop QP's multipliers (warm start)
        self._lam_k = np.full(self.n, -1)            # the step after the stop they are from (-1: none, solve cold)
        self._tail = np.full((3, self.n), -1.0)      # (modal) the duty at the tail's start, its steps so far, its length
        self._lock_mask = None                       # (modal, budget) receivers whose estimator steps with the lock

    def _v2_of(self, d, vl):
        return 4.0 / np.pi * (vl + self._vf) * (1.0 - np.sin(0.5 * np.pi * d))

    def _estimate(self, i2m, vl, d_last, new=None):
        """The state ``z`` now (n, nz): from the delay bank (:class:`_DelayBank`), started in the
        steady state the first measured I2 implies (``w`` explains the offset); the rows ``new`` (a new
        window in a batched env that resets its windows) are started afresh the same way."""
        u_last = self._v2_of(d_last, vl)
        vc = vl + self._vf if self._modal else None
        if self._bank is None or self._bank.n != len(i2m):
            self._bank = _DelayBank(self._model, self._steady_z(i2m, u_last, vc), u_last, self.delays)
            self._bank.vc = vc
            return self._bank.now()
        out = self._bank.update(i2m, u_last, vc)
        if new is not None and len(new):
            z0 = self._steady_z(i2m, u_last, vc)
            b = self._bank
            b.z[:, new], b.u[:, new], b.score[:, new], b.best[new] = z0[new], u_last[new], 0.0, 0
            out[new] = z0[new]
        return out

    def _steady_z(self, i2m, u_last, vc=None):
        """The steady state ``z = [I1, I2, w]`` (n, 3) of eq. 4's model the measured I2 ``i2m`` implies under the
        V2 ``u_last`` (``w`` explains the offset): a filter's start (made only when one starts). The modal
        model's (``vc`` the clamp voltages): ``z = [s (4), w]`` (n, 5), the same way."""
        if self._modal:
            m = self._model
            i0 = m.steady(u_last, 0.0, vc)[1]
            w = (i2m - i0) / self._ss_i2[1]
            return np.concatenate([m.steady(u_last, w, vc)[0], w[:, None]], axis=1)
        lk = self._link
        x = lk.omega_rad_s * lk.lm_h
        det = lk.r1_ohm * lk.r2_ohm + x * x
        w = (x * lk.v1_amp_v - det * i2m) / lk.r1_ohm - u_last
        return np.stack([(lk.r2_ohm * lk.v1_amp_v + x * (u_last + w)) / det, i2m, w], axis=1)

    def act(self, obs):
        from .threads import single_blas_thread
        with single_blas_thread():   # small batched products: BLAS threads cost more than they give
            return self._act(obs)

    def _act(self, obs):
        from wpt_receiver import duty_from_v2_clipped
        o = denormalise_obs(np.atleast_2d(obs))
        i2m, vl, cmd, d_last = (o[:, _F[k]] for k in ("i2_amp_a", "battery_v", "charge_cmd_a", "last_d_short"))
        if len(self._plan) != len(i2m):
            self.reset(len(i2m))
        # a receiver charging again after its stop is in a new window (a batched env resetting its windows)
        new = np.flatnonzero((cmd > 0.0) & (self._k_stop > 0))
        if len(new):
            self._relax[new], self._n_stop[new], self._k_stop[new], self._age[new] = 0.0, 0, 0, 0
            self._lam_k[new] = -1
            self._tail[:, new] = -1.0
        if self._lock_mask is not None:   # (modal, budget) the steps since the stop predicted with the phase lock
            self._lock_mask[new] = False
            self._bank_lock(self._lock_mask)
        z = self._estimate(i2m, vl, d_last, new)
        u_prev = self._v2_of(d_last, vl)
        stop = cmd <= 0.0
        if _LOCK and self._modal:
            self._lock_mask = stop & self._locked(np.arange(len(z)), z)
        v2 = np.empty(len(i2m))
        track = np.flatnonzero(~stop)
        if len(track):
            ref = self._i2_ref(cmd[track], vl[track] + self._vf, z[track, -1])
            v2[track] = self._track(track, z[track], vl[track], ref, u_prev[track])
        stopped = np.flatnonzero(stop)
        if len(stopped):
            plan = stopped
            if self._tail_on:   # a receiver on its tail past the relaxing steps: no plan (the tail decides)
                done = (self._tail[0, stopped] >= 0.0) & (self._n_stop[stopped] >= _RELAX_STEPS)
                plan, v2[stopped[done]] = stopped[~done], 0.0
                self._k_stop[stopped[done]] += 1
            if len(plan):
                v2[plan] = self._after_stop(plan, z[plan], vl[plan], u_prev[plan])
            if self._tail_on:
                v2[stopped] = self._duty_tail(stopped, v2[stopped], vl[stopped], d_last[stopped], z[stopped, -1])
        return duty_from_v2_clipped(v2, vl + self._vf)

    def _setup_qp(self):
        """The fixed Hessians of the two QPs (daqp's ``H``): the
        tracking QP in the ``nb`` knots; the after-stop QP in the ``nb - 1`` free knots (the last is 0:
        short mode) and the slack."""
        m = self._model
        nb = m.M.shape[1]
        D = np.eye(nb) - np.eye(nb, k=-1)
        Ge = m.G[m.ends]
        P = 2.0 * (Ge.T @ Ge + _LAMBDA * D.T @ D) + 1e-9 * np.eye(nb)
        self._track_P = P
        self._track_inv = np.linalg.inv(P)
        f = nb - 1
        Ps = np.zeros((f + 1, f + 1))
        Ps[:f, :f] = 2.0 * (_LAMBDA_STOP * D.T @ D + _RHO_Q * np.diag(m.M.sum(axis=0)))[:f, :f]
        Ps[f, f] = 2.0 * _SLACK_Q
        self._stop_P = Ps
        self._M2 = m.M.repeat(2, axis=0)[:, :f]
        self._energy_w = m.M.sum(axis=0)[:f]
        self._q_stop = np.concatenate([self._energy_w, [_SLACK_W]])
        self._Gf = np.ascontiguousarray(m.G[:, :f])
        self._m2_r, self._m2_c = np.nonzero(self._M2)
        self._m2_v = self._M2[self._m2_r, self._m2_c]
        self._A_stop = np.empty((len(m.G), f + 1))   # the after-stop QP's rows without the excess' slope
        self._A_stop[:, :f], self._A_stop[:, f] = self._Gf, -1.0
        self._m2_flat = np.ravel_multi_index((self._m2_r, self._m2_c), self._A_stop.shape)
        self._A_m2 = self._A_stop.flat[self._m2_flat].copy()   # G's entries where the excess slope is added
        self._A_stop_flat = self._A_stop.reshape(-1)   # a view: per QP only the slope's entries are written
        self._knots = np.asarray(BLOCKS[:f])
        self._bl_stop = np.concatenate([np.zeros(f + 1), np.full(len(m.G), -_BIG)])
        self._sense = np.zeros(f + 1 + len(m.G), dtype=np.int32)
        if self._modal:   # steady I2 [A] at V2 = 0 (clamp at 31 V) and per volt of w
            vc0 = np.array(_VLC + self._vf)
            i0 = float(m.steady(np.zeros(()), 0.0, vc0)[1])
            self._ss_i2 = (i0, float(m.steady(np.zeros(()), 1.0, vc0)[1]) - i0)
        else:
            ss = np.linalg.solve(np.eye(2) - m.ad, np.stack([m.e, m.b2], axis=1))   # steady [I1, I2] of (1, w)
            self._ss_i2 = (float(ss[1, 0]), float(ss[1, 1]))
        self._excess_curve()

    def _solve_stop(self, e, z, vl, u_prev):
        """V2 plans [V] (the knots, (n, nb)) after the stop of the receivers ``e`` (n,) (``z`` (n, nz), ``vl``,
        ``u_prev`` (n,)): min energy + move penalty + slack penalty s.t. the predicted peak (envelope + ripple
        excess linearised along a plan) within the bound + slack, V2 in the box; one QP per receiver. The
        excess is linearised along the previous plan shifted by a step (at the stop: a ramp from the V2 now
        to 0 at the last knot; the plan before the stop holds V2 and would put the rectification mode's
        ripple on the short-mode current); in the first :data:`_RELAX_STEPS` steps the linearisation is
        iterated :data:`_SCP_ITERS` times along the new plan (sequential convex programming), since the
        window's floor is read from these solves."""
        m = self._model
        start = np.flatnonzero(self._n_stop[e] == 0)
        if len(start):
            self._plan[e[start]] = np.interp(np.arange(N_PRED) + 1.0, [0.0, BLOCKS[-2]], [0.0, 1.0])[None, :] * (
                0.0 - u_prev[start, None]) + u_prev[start, None]
        plan = self._plan[e]
        v_bar = np.concatenate([plan[:, 1:], plan[:, -1:]], axis=1)
        first = self._n_stop[e] < _RELAX_STEPS
        v, slack = np.zeros((len(e), m.M.shape[1])), np.zeros(len(e))
        lock = self._locked(e, z)
        rows = np.flatnonzero(first | ~lock)   # the unlocked solves (a locked plan past the floor's steps: none)
        for it in range(_SCP_ITERS):
            if it:
                rows = np.flatnonzero(first)
                if not len(rows):
                    break
            if len(rows):
                v[rows], slack[rows] = self._qp_stop(e[rows], z[rows], vl[rows], u_prev[rows], v_bar[rows])
                v_bar[rows] = np.maximum(v[rows] @ m.M.T, 0.0)
        rows = np.flatnonzero(lock)
        for it in range(_LOCK_ITERS if len(rows) else 0):   # the locked rows' SCP (its slack does not raise the floor)
            v[rows] = self._qp_stop(e[rows], z[rows], vl[rows], u_prev[rows], v_bar[rows], locked=True)[0]
            v_bar[rows] = np.maximum(v[rows] @ m.M.T, 0.0)
        self._n_stop[e] += 1
        # below the window's floor (the state at the stop allows no less): the bound is raised by the least
        # violation for the rest of the window, so the energy term drives the descent again; only in the first
        # steps after the stop (the floor is set there; later violations are model error and must not
        # accumulate into the bound)
        raise_ = first & (slack > 1e-4)
        self._relax[e[raise_]] += slack[raise_]
        return v

    def _bank_lock(self, mask):
        """The estimator's next step with the phase lock on the receivers ``mask`` (bool (n,))."""
        if self._bank is None or self._bank.n != len(mask):
            return
        if not mask.any() and self._bank.lock_step is None:   # nothing locked yet (budget 0: never): no model built
            self._bank.lock = mask.copy()
            return
        if self._bank.lock_step is None:
            from .mpc_lock import locked_step
            lm, m = _locked_model(*self._lm_args), self._model
            self._bank.lock_step = lambda z, u, vc: locked_step(lm, m, z, u, vc)
        self._bank.lock = mask.copy()

    def _locked(self, e, z):
        """Per receiver ``e`` (n,): its after-stop plan is predicted with the phase lock (:data:`_LOCK`; the modal
        model, a budget, ``|w| <=`` :data:`_TAIL_W_MAX` in the estimates ``z`` (n, nz))."""
        if not (_LOCK and self._modal):
            return np.zeros(len(e), dtype=bool)
        b = np.broadcast_to(np.asarray(self._budget_of(e), dtype=float), np.shape(e))
        return (b > 0.0) & (np.abs(z[:, -1]) <= _TAIL_W_MAX)

    def _locked_rows(self, z, v_bar, vl, grad=True):
        """The locked model's I2 rows (n, 2 N_PRED) [A] along ``v_bar`` and (``grad``) their derivatives in the free
        knots and along ``v_bar`` (:func:`policies.mpc_lock.locked_rows`)."""
        from .mpc_lock import locked_rows
        return locked_rows(_locked_model(*self._lm_args), self._model, z, v_bar, vl + self._vf, self._model.M[:, :-1], grad=grad)

    def _qp_stop(self, e, z, vl, u_prev, v_bar, locked=False):
        """One after-stop QP per receiver ``e`` (n,) with the excess linearised along ``v_bar`` (n, N_PRED)
        [V]: ``(knots (n, nb), slack (n,) [A])``. The QP data are built for all receivers at once; daqp
        solves them one by one (:meth:`_daqp`). ``locked``: the I2 rows are the locked model's linearised along
        ``v_bar`` (:meth:`_locked_rows`) and every knot stays within :data:`_LOCK_TRUST` of ``v_bar``."""
        m = self._model
        f = m.M.shape[1] - 1
        vmax = 4.0 / np.pi * (vl + self._vf)
        ex, slope = self._excess(v_bar, vl)
        extra = None
        if locked:   # rows(v) ~ rows(v_bar) + J (M v - v_bar)
            rows, J, Jv = self._locked_rows(z, v_bar, vl)
            free = rows - Jv
            extra = np.zeros((len(e), 2 * N_PRED, f + 1))
            extra[:, :, :f] = J - self._Gf
        else:
            free = z @ m.F.T + m.h
        if self._modal and not locked:   # the residual of V2 linearised along v_bar: a constant and a term in the knots
            free, extra = self._residual_lin(free, v_bar, vl, f)
        margin = _MARGIN_LOCK if locked else self._margin
        ub = (((1.0 + self._budget_of(e) - margin) * self._bound_sm(z) + self._relax[e])[:, None]
              - (ex - slope * v_bar).repeat(2, axis=1) - free)
        # x = [v (f knots), s]: 0 <= v <= vmax, s >= 0 (simple bounds), (G + slope M) v - s <= ub; M's rows have
        # at most two non-zeros (V2 linear between knots), so the slope term is added where they are
        # the entries the slope changes, for every receiver at once (n, nnz): the same sums as one at a time;
        # the other entries of A are fixed (self._A_stop, which daqp only reads)
        A, vals = self._A_stop, self._A_m2 + slope[:, self._m2_r // 2] * self._m2_v
        A_flat, m2_flat = self._A_stop_flat, self._m2_flat
        # V2 = 0 from a fixed time after the stop on (a shrinking horizon: a receding terminal could be
        # put off forever while the bound holds V2 up), at the first knot at or after it
        bu = np.empty((len(e), f + 1 + ub.shape[1]))
        bu[:, :f] = np.where(self._knots[None, :] >= (_SM_DEADLINE - self._k_stop[e])[:, None], 0.0, vmax[:, None])
        bu[:, f], bu[:, f + 1:] = _BIG, ub
        q = np.repeat(self._q_stop[None], len(e), axis=0)
        q[:, 0] -= 2.0 * _LAMBDA_STOP * u_prev
        v, slack = np.zeros((len(e), f + 1)), np.zeros(len(e))
        knots = np.asarray(BLOCKS[:-1])
        bl = np.repeat(self._bl_stop[None], len(e), axis=0) if locked else None
        if locked:   # the trust region about v_bar's knots
            vk = v_bar[:, knots]
            bu[:, :f] = np.minimum(bu[:, :f], vk + _LOCK_TRUST)
            bl[:, :f] = np.minimum(np.maximum(vk - _LOCK_TRUST, 0.0), bu[:, :f])
        for r in range(len(e)):
            A_flat[m2_flat] = vals[r]   # into A through its flat view (A.flat's iterator costs ~5x)
            x, flag = self._daqp(e[r], q[r], A if extra is None else A + extra[r], bu[r],
                                 self._bl_stop if bl is None else bl[r])
            if flag < 1:
                v[r, :f] = np.minimum(v_bar[r, knots], vmax[r])   # keep the plan
            else:
                v[r, :f], slack[r] = x[:f], x[f]
        return v, slack

    def _duty_tail(self, idx, v2, vl, d_last, w):
        """(modal model) V2 [V] of the receivers ``idx`` after their stop: the plan's ``v2`` until it falls below
        :data:`_TAIL_V`, then the duty from the last one ``d_last`` to 1 linearly over :data:`_TAIL_STEPS` steps.
        Near short mode the SBAR's V2 quadrature grows like sqrt(V2) (:mod:`policies.mpc_modal`): a plan linear
        in V2 ends in a steep duty step that rings the exact-mode link (5.6 % on a 10 ms V2 ramp, against 0.6 %
        with its last 2 V linear in the duty) where the linearised residual is least accurate."""
        t = self._tail[:, idx]
        start = (t[0] < 0.0) & (v2 < _TAIL_V)
        t[0, start], t[1, start] = d_last[start], 0.0
        t[2, start] = self._tail_steps(idx[start], w[start])
        on = t[0] >= 0.0
        t[1, on] += 1.0
        d = t[0, on] + (1.0 - t[0, on]) * np.minimum(t[1, on] / t[2, on], 1.0)
        out = v2.copy()
        out[on] = self._v2_of(d, vl[on])
        self._tail[:, idx] = t
        self._plan[idx[on]] = 0.0
        return out

    def _tail_steps(self, e, w):
        """(modal model) Length [control periods] of the duty tail of receivers ``e`` (n,) starting now with the
        estimated disturbances ``w`` (n,) [V]: :data:`_TAIL_STEPS` at budget 0; with a budget, where the model is
        right (``|w| <=`` :data:`_TAIL_W_MAX`), the fewest steps (at least :data:`_TAIL_MIN`) whose ring,
        ~:data:`_TAIL_RING` / n of the short-mode current, stays :data:`_TAIL_RESERVE` below it: the shorter tail
        delivers less after the stop (20 nominal windows, budget 0.1: 0.130 J with 30 steps, 0.117 J with 4, the
        same overshoot)."""
        room = np.broadcast_to(np.asarray(self._budget_of(e), dtype=float), np.shape(e)) - _TAIL_RESERVE
        n = np.where((room > 0.0) & (np.abs(w) <= _TAIL_W_MAX), np.ceil(_TAIL_RING / np.maximum(room, 1e-9)), _TAIL_STEPS)
        return np.clip(n, _TAIL_MIN, _TAIL_STEPS)

    def _rterm(self, plan, vl):
        """(modal model) The I2 samples' part (n, 2 N_PRED) [A] of the residual of V2 in I2's frame along the
        V2 plans ``plan`` (n, N_PRED) [V] at the battery voltages ``vl`` (n,) (:mod:`policies.mpc_modal`)."""
        m = self._model
        rr, ri = m.residual(plan, (vl + self._vf)[:, None])
        return np.concatenate([rr, ri], axis=1) @ m.Gr.T

    def _residual_lin(self, free, v_bar, vl, f):
        """(modal model) The residual of V2 linearised along the plans ``v_bar`` (n, N_PRED) [V]: ``free`` (n, 2
        N_PRED) with its constant part added, and its part in the ``f`` free knots (n, 2 N_PRED, f + 1) (the
        slack's column 0), added to the after-stop QP's constraint rows."""
        m = self._model
        n = N_PRED
        (rr, ri), (sr, si) = m.residual_slope(v_bar, (vl + self._vf)[:, None])
        free = free + np.concatenate([rr - sr * v_bar, ri - si * v_bar], axis=1) @ m.Gr.T
        mf = m.M[None, :, :f]
        extra = np.zeros((len(v_bar), 2 * n, f + 1))
        # Gr_re diag(slope_re) M + Gr_im diag(slope_im) M, batched BLAS products (einsum's loop cost 30x)
        extra[:, :, :f] = m.Gr[:, :n] @ (sr[:, :, None] * mf) + m.Gr[:, n:] @ (si[:, :, None] * mf)
        return free, extra

    def _daqp(self, e, q, A, bu, bl):
        """Solve receiver ``e``'s after-stop QP with daqp, warm-started from its last solve's multipliers
        (the same rows: the knots, and so where the bound binds, keep their offsets from now; ~7 active-set
        iterations instead of ~70 cold, and instead of ~50 from multipliers shifted to the same instants).
        A warm start changes only the path to the optimum (the QP is strictly convex); a failed one is
        retried cold. Returns ``(x, exit flag)``."""
        import daqp
        warm = self._lam_k[e] >= 0
        x, _, flag, info = daqp.solve(self._stop_P, q, A, bu, bl, self._sense.copy(),
                                      dual_start=self._lam[e] if warm else None)
        if flag < 1 and warm:
            x, _, flag, info = daqp.solve(self._stop_P, q, A, bu, bl, self._sense.copy())
        if flag >= 1:
            self._lam[e], self._lam_k[e] = info["lam"], self._k_stop[e]
        return x, flag

    def _i2_ref(self, cmd, vc, w):
        """I2 reference [A] of the charging receivers: the steady I2 of the model *with the estimated
        disturbance* ``w`` [V] at the V2 that delivers the command ``cmd`` [A] at the clamp voltage ``vc``
        [V] (power balance ``V2 I2 / 2 = vc I_L``, the smaller root of ``R1 V2^2 - (X V1 - R1 w) V2 +
        2 vc I_L det = 0``, clipped into ``[0, (4/pi) vc]``; ``w = 0`` is the model-based reference). So the
        tracking is offset-free in the charging current, not in I2: a link that cannot carry the nominal I2
        (detuned tanks, a drifting Lm; ``w`` explains its I2) is driven to the V2 that delivers the command,
        or to the most rectification mode gives, not to short mode."""
        lk = self._link
        x = lk.omega_rad_s * lk.lm_h
        det = lk.r1_ohm * lk.r2_ohm + x * x
        xv = x * lk.v1_amp_v - lk.r1_ohm * w
        disc = np.maximum(xv * xv - 8.0 * lk.r1_ohm * vc * np.maximum(cmd, 0.0) * det, 0.0)
        v2 = np.clip((xv - np.sqrt(disc)) / (2.0 * lk.r1_ohm), 0.0, 4.0 / np.pi * vc)
        return (xv - lk.r1_ohm * v2) / det

    def _track(self, idx, z, vl, ref, u_prev):
        """V2 now [V] of the charging receivers ``idx`` (tracking QP; closed form, batched, where the box is
        inactive, else daqp per receiver)."""
        import daqp
        m = self._model
        nb = m.M.shape[1]
        vmax = 4.0 / np.pi * (vl + self._vf)
        Ge = m.G[m.ends]
        free = z @ m.F[m.ends].T + m.h[m.ends]
        if self._modal:   # the residual of V2 along the previous plan, shifted by a step
            prev = np.concatenate([self._plan[idx, 1:], self._plan[idx, -1:]], axis=1)
            free += self._rterm(prev, vl)[:, m.ends]
        q = 2.0 * (free - ref[:, None]) @ Ge
        q[:, 0] -= 2.0 * _LAMBDA * u_prev
        v = -q @ self._track_inv.T   # the unconstrained optimum: the QP's solution when the box is inactive
        for i in np.flatnonzero(np.any(v < 0.0, axis=1) | np.any(v > vmax[:, None], axis=1)):
            x, _, flag, _ = daqp.solve(self._track_P, q[i], np.zeros((0, nb)), np.full(nb, vmax[i]), np.zeros(nb),
                                       np.zeros(nb, dtype=np.int32))
            v[i] = x if flag >= 1 else np.clip(v[i], 0.0, vmax[i])
        self._plan[idx] = np.clip(v @ m.M.T, 0.0, vmax[:, None])
        self._age[idx] = 0
        return self._plan[idx, 0]

    def _after_stop(self, idx, z, vl, u_prev):
        """V2 now [V] of the receivers ``idx`` after their stop (batched; ``z`` (n, nz), ``vl``, ``u_prev`` (n,)):
        0 once settled in short mode; the previous plan's next move while that plan, shifted by a step, still
        keeps the predicted peak within the bound from the state now (at most :data:`_REPLAN_EVERY` steps: the
        plan's tail is the optimum's continuation when the model holds); else the first move of a new
        after-stop QP (:meth:`_solve_stop`, one per receiver). Each receiver's decision is its own."""
        vmax = 4.0 / np.pi * (vl + self._vf)
        self._k_stop[idx] += 1
        out = np.zeros(len(idx))
        plan = self._plan[idx]
        quiet = plan[:, :BLOCKS[-1]].max(axis=1) < 0.05
        quiet[quiet] = self._settled(z[quiet], self._relax[idx[quiet]], idx[quiet])
        self._plan[idx[quiet]] = 0.0   # in short mode with the free response inside the bound: nothing to plan
        busy = np.flatnonzero(~quiet)
        shifted = np.concatenate([plan[busy, 1:], plan[busy, -1:]], axis=1)
        e = idx[busy]
        follow = (self._n_stop[e] >= _RELAX_STEPS) & (self._age[e] < _REPLAN_EVERY)
        follow[follow] = self._feasible(z[busy[follow]], vl[busy[follow]], shifted[follow], e[follow])
        self._plan[e[follow]] = shifted[follow]
        self._age[e[follow]] += 1
        out[busy[follow]] = shifted[follow, 0]
        j = busy[~follow]
        if len(j):
            v = self._solve_stop(idx[j], z[j], vl[j], u_prev[j])
            self._plan[idx[j]] = np.minimum(np.maximum(v @ self._model.M.T, 0.0), vmax[j, None])
            self._age[idx[j]] = 0
            out[j] = self._plan[idx[j], 0]
        return out

    def _feasible(self, z, vl, plan, e):
        """Per row: the predicted peak (envelope + ripple excess at the plan's duties) of the V2 ``plan``
        (n, N_PRED) from ``z`` (n, nz) within the bound of receiver ``e`` (n,) (bool (n,))."""
        rows, margin = self.predicted_rows(z, vl, plan, self._locked(e, z) if self._modal else None)
        bound = (1.0 + self._budget_of(e) - 0.5 * margin) * self._bound_sm(z) + self._relax[e]
        return np.all(rows <= bound[:, None], axis=1)

    def predicted_rows(self, z, vl, plan, locked=None):
        """The predicted peak samples (n, 2 N_PRED) [A] of the V2 ``plan`` (n, N_PRED) [V] from the estimates ``z``
        (n, nz) at the battery voltages ``vl`` (n,): the model's I2 at mid-step and end of every step (on the modal
        model with the residual of V2, and the rows ``locked`` (bool (n,)) with the phase lock,
        :func:`policies.mpc_lock.locked_rows`) plus the ripple excess at the plan's duties; and the constraint
        back-off of each row's model (fraction of I2_sm; (n,) on the modal model). What :meth:`_feasible` bounds and
        :class:`policies.oracle_imitation_filter.OracleImitationFilteredPolicy` filters with."""
        m = self._model
        i2 = z @ m.F.T + m.h + plan @ m.Gu.T
        if self._modal:
            i2 += self._rterm(plan, vl)
            locked = np.zeros(len(z), dtype=bool) if locked is None else locked
            lock = np.flatnonzero(locked)
            if len(lock):
                i2[lock] = self._locked_rows(z[lock], plan[lock], vl[lock], grad=False)[0]
            margin = np.where(locked, _MARGIN_LOCK, self._margin)
        else:
            margin = self._margin
        ex = self._excess_at(plan, vl[:, None])
        return i2 + ex.repeat(2, axis=1), margin

    def _budget_of(self, e):
        """The measured-overshoot budget of receivers ``e`` (n,): the policy's one ``budget`` (a subclass may
        give each receiver its own, :class:`policies.slow_budget.BudgetScheduledMPC`)."""
        return self.budget

    def _bound_sm(self, z):
        """The short-mode current of the bound [A]: the model's own, its steady state with V2 = 0 and the
        estimated disturbance ``w`` (on nominal windows within ~0.1 % of the nominal one; a link whose I2
        the disturbance explains - detuned tanks - has its own: with the nominal one as the bound the MPC
        overshot the detuned link's short-mode current by 35 % on 5 windows, with this 8.6 %)."""
        return self._ss_i2[0] + self._ss_i2[1] * z[..., -1]

    def _settled(self, z, relax, e):
        """Per row of ``z`` (n, nz): the free response (V2 = 0) stays within the budget's bound with the
        short-mode ripple (:meth:`_excess` at V2 = 0), ``relax`` (n,) [A] the raised bounds, ``e`` (n,) the
        receivers (bool (n,))."""
        m = self._model
        free = z @ m.F.T + m.h
        if self._modal:
            free = free + self._rterm(np.zeros((len(z), N_PRED)), np.full(len(z), _VLC))
        sm = self._bound_sm(z)
        return np.all(free + self._ex0 <= ((1.0 + self._budget_of(e) - self._margin) * sm + relax)[:, None], axis=1)

    def _excess_at(self, v2, vl):
        """Ripple excess [A] at V2 ``v2`` (any shape) [V], the short-mode current and battery voltage ``vl``:
        the env's lookup (:mod:`envs.peaks`) at that current is piecewise linear in the duty between the
        table's duty grid points (:meth:`_excess_curve`), so one ``np.interp`` gives it exactly."""
        from wpt_receiver import duty_from_v2_clipped
        d = duty_from_v2_clipped(v2, vl + self._vf)
        a, b = self._ex_curve
        if np.ndim(vl) == 0:
            return np.interp(d, self._ex_grid, a + b * (vl - _VLC))
        return np.interp(d, self._ex_grid, a) + (vl - _VLC) * np.interp(d, self._ex_grid, b)   # vl per row

    def _excess_curve(self):
        """The lookup's excess at the short-mode current on the duty grid: ``(A, B)`` [A], [A/V] with
        excess = A + B (VL - 31 V) (:func:`envs.peaks.fold_vl`), bilinear in sqrt(I2) as the env."""
        from envs.peaks import I2_MAX_A, LOOKUP_SCALARS
        assert LOOKUP_SCALARS[0] == _VLC
        tab = self._peak_table
        nd, ni, _ = tab.shape
        y = np.sqrt(min(self._i2_sm / I2_MAX_A, 1.0)) * (ni - 1)
        k = min(int(y), ni - 2)
        fy = y - k
        c = tab[:, k] * (1.0 - fy) + tab[:, k + 1] * fy
        self._ex_grid = np.linspace(0.0, 1.0, nd)
        self._ex_curve = (c[:, 0], c[:, 1])

    def _excess(self, v2, vl):
        """Ripple excess [A] at V2 ``v2`` (n, N) [V] and its slope dexcess/dV2 [A/V] (central difference,
        0.5 V) at the short-mode current and the battery voltages ``vl`` (n,) (:mod:`envs.peaks`)."""
        h = 0.5
        vmax = (4.0 / np.pi * (vl + self._vf))[:, None]
        hi, lo = np.minimum(v2 + h, vmax), np.maximum(v2 - h, 0.0)
        ex = self._excess_at(np.stack([v2, hi, lo]), vl[:, None])
        slope = (ex[1] - ex[2]) / np.maximum(hi - lo, 1e-9)
        return ex[0], np.maximum(slope, 0.0)
