"""The limit per window: the best open-loop duty sequence after the stop command, on the env's own
dynamics with the true parameters known (an oracle bound, not a realisable policy).

For a seeded window (scenario, seed) the duties before the stop are a base policy's (they set the
state at the stop; every policy of ``compare`` that is not learned shares them with
``model_based``), and the duties from the stop step on are optimised:

    minimise   E_after = sum_{k >= k_stop} VL_k I_L,k dt          (energy after the stop [J])
    subject to |i2|_pk,k / I2_sm,k - 1 <= b   for every k >= k_stop (the measured overshoot: the
               instantaneous peak, envelope + ripple, :mod:`envs.peaks`, as :mod:`envs.objective`)
               I_L,k <= 0.45 A from 14 ms after the stop on      (reaches short mode, with margin)

on :class:`envs.rollout.DutyRollout` (the compiled env replaying duty sequences, true Lm, devices,
battery). Parametrisation: ``d = clip(d_start + B x, 0, 1)`` after the stop, ``B`` a cubic B-spline
basis of :data:`N_BASIS` functions over the steps after the stop with knots dense near the stop
(where the transition happens) and ``d_start`` a start sequence; ``x = 0`` is the start itself. The
problem is solved with scipy's SLSQP (two passes, the budget backed off by 0.03 and 0.15 points, each
followed by a line search from the start to SLSQP's end point, whose last iterate may violate the
constraints by the solver's tolerance), gradients by forward differences evaluated in one batch of
``N_BASIS + 1`` rollouts (step 2e-3 in x on eq. 4's link, 1e-4 on the exact-mode link, whose per-step peaks
are kinked on the larger scale: :func:`_fd_step`), from several starts (the budgeted model-based controller's sequences at
b = 0.01 and 0.05, the floor's sequence on the frontier, and - for the gap of a policy - that
policy's own sequence). The result is the best *feasible*
sequence of every rollout evaluated (finite-difference points included), so it is never worse than
any feasible start: on its own windows the oracle beats or equals every fixed policy it was started
from (``tests/test_oracle.py``). A local optimum of a nonsmooth problem (max, table lookup, the
sub-steps of a sign change): an upper bound on the true optimum's energy, not the optimum.

The *floor* of a window (:func:`oracle_floor`): the smallest measured overshoot found by the same
search (min over x of the max step ratio); budgets below it are infeasible.

Results are cached on disk per (scenario, seed, budget, starts, env config) with
:mod:`wpt_receiver.diskcache` (``$DRONEWPT_CACHE_DIR``), keyed with the source hash of this module and
of the env's and the link's sources a rollout computes with and of the base / start policies' modules
(:func:`_source_hash`; each since 2026-11-26, which invalidated the bounds cached before once).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["OracleResult", "oracle_window", "oracle_floor", "oracle_frontier", "policy_duties", "N_BASIS",
           "DEFAULT_STARTS", "SM_MARGIN_A"]

N_BASIS = 14
#: start sequences of every solve (policies of :func:`policies.make`)
DEFAULT_STARTS = ("model_based_budget:0.01", "model_based_budget:0.05")
#: the short-mode constraint's current [A] (the objective's 0.5 A less a margin)
SM_MARGIN_A = 0.45
#: forward-difference step in the basis coefficients x (eq. 4's envelope link)
_FD_STEP = 2e-3
#: the same on the exact-mode link: its per-step peaks are kinked on the scale of ``_FD_STEP`` (the largest |I2|
#: over the rectifier-period sub-steps), so differences over 2e-3 mix slopes of both sides of the kinks and SLSQP
#: stalls at the start; 1e-4 resolves them (docs/rl.md, "Why the oracle stalled on the exact-mode link").
#: eq. 4 keeps 2e-3 so that its cached bounds stay the same to the bit.
_FD_STEP_MODAL = 1e-4
_MAXITER = 40
#: budget margins of the successive SLSQP passes (each warm-started from the last)
_MARGINS = (3e-4, 1.5e-3)


@dataclass(frozen=True)
class OracleResult:
    """Best feasible open-loop sequence found for one window and budget."""

    energy_after_stop_j: float
    overshoot: float             # measured (instantaneous-peak) overshoot, fraction
    reached_short_mode: bool
    feasible: bool               # False: no sequence within the budget was found (budget below the floor)
    duties: np.ndarray           # (n_steps,) the whole window's duties


def _basis(n_after: int) -> np.ndarray:
    """(n_after, N_BASIS) cubic B-spline design matrix over the steps after the stop, interior knots
    spaced quadratically (dense at the stop)."""
    from scipy.interpolate import BSpline
    k = 3
    n_int = N_BASIS - k - 1
    u = np.linspace(0.0, 1.0, n_int + 2) ** 2 * (n_after - 1)
    t = np.r_[[0.0] * k, u, [u[-1]] * k]
    return BSpline.design_matrix(np.arange(n_after, dtype=float), t, k).toarray()


@lru_cache(maxsize=256)
def _policy_traces(name: str, scenario, seed: int, episodes: int, config):
    """``(duties (episodes, n_steps), {"overshoot_pct", "energy_after_stop_j"})`` of a policy in closed loop
    on the windows ``seed + i`` (the loop of :func:`policies.compare.run_policy`, the same float32 actions)."""
    from envs import SbarChargingVectorEnv

    from . import make
    venv = SbarChargingVectorEnv(num_envs=episodes, scenario=scenario, config=config)
    pol = make(name, venv.policy_context)
    pol.reset(episodes)
    obs, _ = venv.reset(seed=seed)
    T = venv.config.n_steps
    duties, energy = np.empty((episodes, T)), np.empty((episodes, T))
    for k in range(T):
        d = np.asarray(pol.act(obs), dtype=float).reshape(episodes)
        obs, _, _, _, info = venv.step((2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32))
        duties[:, k], energy[:, k] = info["d_short"], info["energy_j"]
    k0 = venv._stop_k
    after = np.arange(T)[None, :] >= k0[:, None]
    return duties, {"overshoot_pct": 100.0 * info["overshoot"], "energy_after_stop_j": (energy * after).sum(axis=1)}


def policy_duties(name: str, scenario, seed: int, config=None, episodes: int = 1) -> np.ndarray:
    """The duty sequences (episodes, n_steps) a policy applies on the windows ``seed .. seed + episodes - 1``
    (closed loop; replayed open loop by :class:`envs.rollout.DutyRollout` they give the same window)."""
    from envs.core import given_config
    return _policy_traces(name, scenario, int(seed), int(episodes), given_config(config))[0]   # (lru-cached: hashable)


def _fd_step(config) -> float:
    """The forward-difference step in x on the link of ``config`` (:data:`_FD_STEP_MODAL` on the exact-mode
    link, ``link_model == "modal"``; else :data:`_FD_STEP`)."""
    return _FD_STEP_MODAL if getattr(config, "link_model", "envelope") == "modal" else _FD_STEP


class _Problem:
    """Energy, step ratios and late I_L of ``d_start + B x`` on one window, evaluated with forward
    differences (step :func:`_fd_step` of the window's link) in one batch; keeps the best feasible sequence
    of every rollout."""

    def __init__(self, roll, d_start, budget):
        self.roll, self.k0, self.budget = roll, roll.stop_k, budget
        self.fd = _fd_step(roll.config)
        self.d_start = np.asarray(d_start, dtype=float)
        self.B = _basis(roll.n_steps - self.k0)
        self.late = np.arange(roll.n_steps) >= self.k0 + int(round(14e-3 / roll.config.dt_s))
        self._memo = {}
        self.best = None

    def duties(self, xs):
        d = np.repeat(self.d_start[None, :], len(xs), axis=0)
        d[:, self.k0:] = np.clip(d[:, self.k0:] + xs @ self.B.T, 0.0, 1.0)
        return d

    def _eval(self, x, jac: bool = False):
        """``[(value, jacobian or None)]`` of (energy / 0.3 J, step ratios, late I_L) at ``x``; the
        jacobian (forward differences, one batch with the value) only when ``jac``."""
        key = x.tobytes()
        got = self._memo.get(key)
        if got is None or (jac and got[0][1] is None):
            xs = np.vstack([x, x + self.fd * np.eye(len(x))]) if jac else x[None, :]
            d = self.duties(xs)
            r = self.roll.run(d)
            e, rat, il = r.energy_after_stop_j, r.ratios, r.rect_current_a[:, self.late]
            self._keep(d, e, r.overshoot, r.reached_short_mode)
            vals = (e / 0.3, rat, il)
            got = [(v[0], (v[1:] - v[0]) / self.fd if jac else None) for v in vals]
            self._memo = {key: got}
        return got

    def _keep(self, d, e, over, sm):
        ok = (over <= self.budget + 1e-12) & sm
        if ok.any():
            i = int(np.flatnonzero(ok)[np.argmin(e[ok])])
            if self.best is None or e[i] < self.best.energy_after_stop_j:
                self.best = OracleResult(float(e[i]), float(over[i]), True, True, d[i].copy())

    def _segment(self, x):
        """Score the segment from the start (x = 0) to ``x`` in one batch (SLSQP's end point may
        violate the constraints by its tolerance; a point on the way is feasible)."""
        t = np.linspace(0.0, 1.0, 33)[1:]
        d = self.duties(t[:, None] * x[None, :])
        r = self.roll.run(d)
        self._keep(d, r.energy_after_stop_j, r.overshoot, r.reached_short_mode)

    def solve(self):
        from scipy.optimize import minimize
        x0 = np.zeros(N_BASIS)
        self._eval(x0)
        for margin in _MARGINS:
            b = self.budget - margin
            cons = [{"type": "ineq", "fun": lambda x: b - self._eval(x)[1][0],
                     "jac": lambda x: -self._eval(x, True)[1][1].T},
                    {"type": "ineq", "fun": lambda x: SM_MARGIN_A - self._eval(x)[2][0],
                     "jac": lambda x: -self._eval(x, True)[2][1].T}]
            res = minimize(lambda x: self._eval(x)[0][0], x0, jac=lambda x: self._eval(x, True)[0][1],
                           method="SLSQP", constraints=cons, options={"maxiter": _MAXITER, "ftol": 1e-7})
            self._segment(res.x)
            x0 = res.x
        return self.best


class _FloorProblem(_Problem):
    """min over x of the max step ratio (epigraph variable t): the window's floor."""

    def solve(self):
        from scipy.optimize import minimize
        n = N_BASIS

        def g(z, jac=False):
            v, dv = self._eval(z[:n], jac)[1]
            return z[n] - v, (np.hstack([-dv.T, np.ones((len(v), 1))]) if jac else None)

        def sm(z, jac=False):
            v, dv = self._eval(z[:n], jac)[2]
            return SM_MARGIN_A - v, (np.hstack([-dv.T, np.zeros((len(v), 1))]) if jac else None)

        t0 = float(self._eval(np.zeros(n))[1][0].max())
        res = minimize(lambda z: z[n], np.r_[np.zeros(n), t0], jac=lambda z: np.r_[np.zeros(n), 1.0],
                       method="SLSQP", options={"maxiter": _MAXITER, "ftol": 1e-9},
                       constraints=[{"type": "ineq", "fun": lambda z: g(z)[0], "jac": lambda z: g(z, True)[1]},
                                    {"type": "ineq", "fun": lambda z: sm(z)[0], "jac": lambda z: sm(z, True)[1]}])
        self._segment(res.x[:n])
        return self.best

    def _keep(self, d, e, over, sm):
        ok = sm
        if ok.any():
            i = int(np.flatnonzero(ok)[np.argmin(over[ok])])
            if self.best is None or over[i] < self.best.overshoot:
                self.best = OracleResult(float(e[i]), float(over[i]), True, True, d[i].copy())


#: the sources an oracle bound is computed with besides this file: the env's step and its replay
#: (:mod:`envs.rollout`'s compiled replay, the envelope / modal / detuned links, the scenarios, the objective)
#: and the link's physics in :mod:`wpt_receiver` (with the device presets' table; ``inverse_controller``: the
#: paper's controller, the base of the floor, and its ``discrete_ss`` that :mod:`policies.budget_modal` plans
#: with). The base and start policies' modules enter the key as well (:func:`_policy_files`): the base sets the
#: state at the stop, a start the local optimum the search finds.
_ROLLOUT_SOURCES = (
    ("envs", ("core.py", "detuned.py", "duty_sine.py", "layout.py", "modal_plant.py", "modal_step.py", "objective.py", "parts.py",
              "peaks.py", "plant.py", "rollout.py", "scenario.py", "sensing.py", "vector.py", "vector_kernel.py")),
    ("wpt_receiver", ("coupling.py", "devices.py", "envelope.py", "inverse_controller.py", "lti.py",
                      "modal_kernel.py", "params.py", "parts.toml", "sbar.py")),
)


def _rollout_files() -> list:
    """The files of :data:`_ROLLOUT_SOURCES` (paths of the imported packages)."""
    import envs
    import wpt_receiver
    roots = {"envs": Path(envs.__file__).parent, "wpt_receiver": Path(wpt_receiver.__file__).parent}
    return [roots[pkg] / name for pkg, names in _ROLLOUT_SOURCES for name in names]


def _relative_imports(text: str, root: Path) -> list:
    """The files under ``root`` (the policies package) that the source ``text`` imports relatively
    (``from .x import y``, ``from . import x``; inside functions too, where the lazy imports are)."""
    import ast
    out = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            names = [node.module] if node.module else [a.name for a in node.names]
            out += [root / f"{n.split('.')[0]}.py" for n in names if (root / f"{n.split('.')[0]}.py").is_file()]
    return out


@lru_cache(maxsize=16)
def _policy_files(names: tuple) -> tuple:
    """The policies modules the policies ``names`` (:func:`policies.make` names) run with: the module of each
    one's class or factory and, transitively, what it imports relatively (``mpc``: mpc.py, mpc_modal.py,
    classical.py, ...); sorted, this file and the package's ``__init__`` left out."""
    import inspect

    from . import _REGISTRY
    root = Path(__file__).parent
    todo = []
    for name in names:
        f = _REGISTRY.get(name.partition(":")[0])
        if f is None:
            continue
        if inspect.isclass(f):
            todo.append(Path(inspect.getsourcefile(f)))
        else:   # a factory in the package's __init__: the modules it imports
            todo += _relative_imports(inspect.getsource(f), root)
    seen = set()
    while todo:
        p = todo.pop()
        if p not in seen and p.name not in ("oracle.py", "__init__.py"):
            seen.add(p)
            todo += _relative_imports(p.read_text(), root)
    return tuple(sorted(seen))


def _source_hash(policies: tuple = ()) -> str:
    """16 hex digits of sha256 over this file, :func:`_rollout_files` and the modules of the base / start
    policies ``policies`` (:func:`_policy_files`) (:func:`wpt_receiver.kernel_cache.dependency_hash`): part
    of every disk-cache key, so a bound computed by other env physics (the detuned windows' blocking fix of
    2026-11-26, say) or from another base policy's state at the stop (the MPC on the modal link, 2026-11-26)
    is recomputed, not reused. Each widening of the key computes the bounds cached before again once (the
    old entries stay unused in the cache folder)."""
    from wpt_receiver.kernel_cache import dependency_hash
    return dependency_hash([Path(__file__), *_rollout_files(), *_policy_files(tuple(policies))])[:16]


def _cached(kind, scenario, seed, budget, starts, config, compute):
    from envs import get_scenario
    from envs.core import as_config
    from wpt_receiver import diskcache
    cfg = as_config(config)   # a dict of its fields too: the key holds the EnvConfig's repr either way
    src = _source_hash(tuple(s for s in starts if isinstance(s, str)))
    key = f"oracle {kind} {src} {get_scenario(scenario)!r} seed={seed} b={budget!r} {starts!r} {cfg!r}"
    shape = (4 + cfg.n_steps,)
    arr = diskcache.load("oracle", key, shape)
    if arr is None:
        r = compute()
        arr = np.r_[r.energy_after_stop_j, r.overshoot, float(r.reached_short_mode), float(r.feasible), r.duties]
        diskcache.store("oracle", key, arr)
    return OracleResult(float(arr[0]), float(arr[1]), bool(arr[2]), bool(arr[3]), arr[4:].copy())


def _start_sequences(scenario, seed, starts, config):
    return [policy_duties(s, scenario, seed, config)[0] for s in starts]


def oracle_window(scenario, seed: int, budget: float, starts=DEFAULT_STARTS, config=None, extra_starts=()):
    """The best open-loop sequence found for window ``seed`` within the measured overshoot ``budget``
    (a fraction), from the start sequences of the policies ``starts`` and the arrays ``extra_starts``
    (n_steps,) (cached; an extra start enters the key through its bytes). Infeasible (budget below
    what any search reached): ``feasible=False`` and the floor's sequence."""
    from envs.core import given_config
    from envs.rollout import DutyRollout
    config = given_config(config)
    extra = [np.asarray(s, dtype=float) for s in extra_starts]
    tag = tuple(starts) + tuple(hashlib.sha256(s.tobytes()).hexdigest()[:12] for s in extra)

    def compute():
        roll = DutyRollout(scenario, seed, config)
        best = None
        for d0 in _start_sequences(scenario, seed, starts, config) + extra:
            r = _Problem(roll, d0, float(budget)).solve()
            if r is not None and (best is None or r.energy_after_stop_j < best.energy_after_stop_j):
                best = r
        if best is None:
            f = oracle_floor(scenario, seed, config)
            return OracleResult(f.energy_after_stop_j, f.overshoot, f.reached_short_mode, False, f.duties)
        return best

    return _cached("window", scenario, int(seed), float(budget), tag, config, compute)


def oracle_floor(scenario, seed: int, config=None, base: str = "model_based") -> OracleResult:
    """The smallest measured overshoot found for window ``seed``, the duties before the stop being those of
    the policy ``base`` (a :func:`policies.make` name; the state at the stop, and so the floor, is that
    policy's: the paper's controller by default, every classical policy's own for its own floor)."""
    from envs.core import given_config
    from envs.rollout import DutyRollout
    config = given_config(config)

    def compute():
        roll = DutyRollout(scenario, seed, config)
        return _FloorProblem(roll, policy_duties(base, scenario, seed, config)[0], np.inf).solve()

    return _cached("floor", scenario, int(seed), 0.0, (base,), config, compute)


def oracle_frontier(scenario, seeds, budgets_above_floor=(0.0, 0.01, 0.03, 0.08), config=None,
                    progress: bool = False) -> list[dict]:
    """The oracle curve: for every window its floor ``f`` and the best energy at budgets ``f + db``;
    rows ``{"budget_above_floor", "overshoot_pct", "energy_after_stop_j"}`` with per-window arrays
    under ``"per_window"`` (means over the windows at the top level)."""
    from tqdm import tqdm
    seeds = [int(s) for s in seeds]
    floors = {s: oracle_floor(scenario, s, config) for s in tqdm(seeds, desc="oracle floor", disable=not progress)}
    rows = []
    for db in tqdm(budgets_above_floor, desc="oracle frontier", disable=not progress):
        res = [floors[s] if db == 0.0 else oracle_window(scenario, s, floors[s].overshoot + db, config=config,
                                                         extra_starts=(floors[s].duties,)) for s in seeds]
        e = np.array([r.energy_after_stop_j for r in res])
        o = np.array([100.0 * r.overshoot for r in res])
        rows.append({"budget_above_floor": float(db), "overshoot_pct": float(o.mean()),
                     "energy_after_stop_j": float(e.mean()), "per_window": {"seed": seeds, "overshoot_pct": o,
                                                                            "energy_after_stop_j": e}})
    return rows
