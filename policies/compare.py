"""Head-to-head comparison: every policy through the same closed loop on the same seeded episodes,
with statistics.

Each scenario runs ``episodes`` charging windows at once in the batched vector env (sub-env ``i``
seeded ``seed + i``, the same windows for every policy), the policy acting on the whole batch of
contract observations every control period. Metrics per episode (the objective of
:mod:`envs.objective` and the physical values in ``info``):

====================  =====================================================================
overshoot_pct         100 x (peak |I2| after the stop / short-mode I2 of the true link - 1) [%]
                      (negative when the current never reaches the short-mode level)
reached_short_mode    1 if I_L < 0.5 A from 14 ms after the stop on, else 0 (mean = fraction)
peak_i2_a             largest |I2| envelope sample (mid- and end-of-step) in the window [A]
energy_before_stop_j  energy into the battery node before the stop command, sum VL I_L dt [J]
energy_after_stop_j   the energy delivered after the stop command (unwanted) [J]
tracking_rmse_a       RMS of (I_L - command) over the window [A]
cost                  the episode cost: max(0, overshoot) (a fraction)
return                sum of the env's reward
time_above_rated_s    time with the step's peak |I2| above the rated value [s]
====================  =====================================================================

Statistics (:mod:`policies.stats`): mean and 95 % bootstrap interval over the episodes, the paired
difference against ``model_based`` on the same episodes (``d_<metric>``), and for a policy trained
with several seeds (``train_seeds``) the mean over seeds with a t interval over the seed means.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np

from mission_sim.files import atomic_output
from mission_sim.validation import Range, check_first_seed, check_number

from .shipped import OTHER_PLAYERS, PRETRAINED_DIR, SHIPPED, model_of
from .stats import mean_ci, seed_ci
from .threads import single_blas_thread

__all__ = ["METRICS", "EpisodeTraces", "run_policy", "run_policies", "compare", "frontier", "oracle_gaps", "oracle_curve", "DEFAULT_POLICIES", "DEFAULT_SCENARIOS",
           "REFERENCE", "plot_transitions", "plot_frontier", "shipped_seed_groups", "OPT_IN_SEEDS",
           "frontier_specs"]

METRICS = ("overshoot_pct", "reached_short_mode", "peak_i2_a", "energy_before_stop_j", "energy_after_stop_j",
           "tracking_rmse_a", "cost", "return", "time_above_rated_s")
DEFAULT_POLICIES = ("step", "ramp", "hysteresis", "model_based", "model_based_online", "model_based_budget:0.01",
                    "model_based_budget:0.02", "mpc", "rl", "ppo_lagrangian", "residual", "random")
#: lm_high is held out: its Lm (1.3-1.5 x) is outside the training range of the random scenario (0.8-1.25 x);
#: the model-is-wrong scenarios each with its held-out variant (:data:`envs.scenario.HELD_OUT`)
DEFAULT_SCENARIOS = ("nominal", "lm_mismatch", "windy", "battery", "lm_high", "lm_drift", "lm_drift_fast",
                     "sense_delay", "sense_delay_long", "battery_low", "battery_empty", "detuned", "detuned_wide")
#: policies without an oracle gap (far from short mode without overshoot: the gap says nothing)
NO_GAP = ("step", "hysteresis", "random")
REFERENCE = "model_based"
DEFAULT_EPISODES = 100
#: learned kinds shipped with several training seeds (``policies/pretrained/<prefix><k>.zip``; :mod:`policies.shipped`)
SHIPPED_SEEDS = {kind: prefix for kind, (prefix, ext) in SHIPPED.items() if ext == ".zip"}
#: shipped kinds left out of compare's default rows (each seed is a full MPC run: ~5x the MPC's cost per
#: scenario); ``--train-seeds 'slow_budget=slow_budget:policies/pretrained/slow_budget_s*.zip'`` adds them
OPT_IN_SEEDS = ("slow_budget",)


def shipped_seed_groups() -> dict:
    """``{kind: ["kind:PATH_s0", ...]}`` for the learned kinds shipped with several training seeds
    (the rows ``compare`` aggregates over seeds by default); kinds with fewer than two files are left out."""
    folder = PRETRAINED_DIR
    out = {}
    import importlib.util
    for kind, prefix in SHIPPED_SEEDS.items():
        if kind == "slow_budget" and importlib.util.find_spec("daqp") is None:
            continue   # its base is the MPC (daqp); compare's mpc row is skipped with a note the same way
        files = sorted(folder.glob(f"{prefix}[0-9]*.zip"))
        if len(files) >= 2:
            out[kind] = [f"{kind}:{f}" for f in files]
    return out


@dataclass
class EpisodeTraces:
    """Time series (n_steps, episodes) of one policy on one scenario, and its per-episode metrics."""

    t_s: np.ndarray
    i2_peak_a: np.ndarray
    i2_a: np.ndarray
    d_short: np.ndarray
    rect_current_a: np.ndarray
    charge_cmd_a: np.ndarray
    t_stop_s: np.ndarray
    metrics: dict


def _rollout(pol, venv, seeds):
    obs, info = venv.reset(seed=seeds)
    T, n = venv.config.n_steps, venv.num_envs
    keys = ("i2_peak_a", "i2_a", "d_short", "rect_current_a", "charge_cmd_a", "energy_j", "i2_peak_envelope_a", "lm_h")
    rec = {k: np.empty((T, n)) for k in keys}
    rew = np.empty((T, n))
    for k in range(T):
        d = np.asarray(pol.act(obs), dtype=float).reshape(n)
        obs, r, term, trunc, last = venv.step((2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32))
        rew[k] = r
        for key in keys:
            rec[key][k] = last[key]
    return rec, rew, info["t_stop_s"], last


#: episodes per scenario of :func:`compare` / :func:`run_policy` and ``dronewpt compare --episodes`` (one table)
EPISODES = Range(1, 100_000, integer=True)


def check_episodes(episodes, seed) -> tuple[int, int]:
    """``(episodes, seed)`` as ints when ``episodes`` is a whole number 1..100000 and the episode seeds ``seed ..
    seed + episodes - 1`` are whole numbers in 0..2^32-1 (:func:`compare`'s and :func:`run_policies`'); else one
    ``ValueError`` naming the value and its range (``run_policy(..., 0, ...)`` said "num_envs=0", 1.5 ran 1)."""
    n = check_number("episodes", episodes, EPISODES)
    s = check_first_seed(seed, n, "episode", "episodes")
    return n, s


def _names(value, what: str) -> list:
    """A list of names; one string is a comma-separated list, as the CLI's ``--policies`` / ``--scenarios``
    (``compare(policies="step")`` ran the policies 's', 't', 'e', 'p': "policy='s' is invalid")."""
    if isinstance(value, str):
        return [v.strip() for v in value.split(",") if v.strip()]
    try:
        return list(value)
    except TypeError:
        raise ValueError(f"{what}={value!r} is invalid; valid: a list of names, or one comma-separated string") \
            from None


def _check_specs(specs) -> None:
    """Policies are given by name (a :func:`policies.make` spec); a policy object was an AttributeError deep inside."""
    for sp in specs:
        if not isinstance(sp, str):
            raise ValueError(f"policy {sp!r} is invalid; valid: a policies.make name such as 'model_based' or "
                             "'rl:PATH' (your own class: policies.register(NAME, factory), then NAME)")


def _model_file(spec):
    """The model ``spec`` loads, or None: the real path of its file (:func:`policies.shipped.model_of`), not its kind
    (``rl:policies/pretrained/ppo_lagrangian_s0.zip`` beside ``ppo_lagrangian`` ran two rows of one file), and the
    kind only where it plays the file otherwise (:data:`policies.shipped.OTHER_PLAYERS`)."""
    key = model_of(spec)
    if key is None:
        return None
    kind, path = key
    return path, kind if kind in OTHER_PLAYERS else None


def check_row_labels(policies, train_seeds=None) -> None:
    """Every row of :func:`compare` has its own label: a policy listed twice, or a ``train_seeds`` label that is also
    one of ``policies``, would share a row's slot (the table showed one row's numbers twice); ``ValueError`` naming it.
    A model is the same whatever its spelling (``rl`` and ``rl:policies/pretrained/rl_s0.zip``, another path to the file:
    :func:`policies.shipped.model_of`)."""
    seen = set()
    for p in policies:
        if p in seen:
            raise ValueError(f"policies lists {p!r} twice; valid: each policy once")
        seen.add(p)
    _each_model_once(policies, "policies lists the model {} twice (also as {}); valid: each policy once")
    for label, specs in (train_seeds or {}).items():
        if label in seen:
            raise ValueError(f"train_seeds label {label!r} is also one of the policies; valid: a label that names no "
                             f"listed policy (the policies: {', '.join(map(str, policies))})")
        # (the same model file twice made "2 seeds" with a zero-width interval)
        _each_model_once(specs, f"train_seeds {label!r} lists the model {{}} twice (also as {{}}); valid: each model "
                                "file once (a row over N seeds needs N models)")


def _each_model_once(specs, message: str) -> None:
    """``ValueError(message.format(spec, earlier))`` (both repr'd) at the first of ``specs`` that loads a model file an
    earlier one loads (:func:`_model_file`; a spec loading none, e.g. a classical policy, is not compared)."""
    models = {}
    for sp in specs:
        key = _model_file(sp)
        if key is not None and key in models:
            raise ValueError(message.format(repr(sp), repr(models[key])))
        models.setdefault(key, sp)


def run_policy(name: str, scenario: str, episodes: int, seed: int, config=None) -> EpisodeTraces:
    """Run policy ``name`` (a :func:`policies.make` name, e.g. ``rl:PATH`` or ``model_based_budget:0.02``)
    on ``episodes`` windows seeded ``seed + i``."""
    return run_policies([name], scenario, episodes, seed, config)[name]


def run_policies(names, scenario: str, episodes: int, seed: int, config=None, num_threads=None) -> dict:
    """:func:`run_policy` of every name in ``names`` (duplicates run once), side by side in one batched
    env of ``len(names) x episodes`` rows (:class:`policies.batched.BlockPolicy`: each policy on its own
    block of the same windows; a run of learned seeds as one stacked network); ``{name: EpisodeTraces}``,
    each equal to its separate run. ``num_threads``: the env's (:class:`envs.SbarChargingVectorEnv`; the
    same results whatever the threads)."""
    from envs import SbarChargingVectorEnv
    from envs.core import given_config

    from . import make
    from .batched import BlockPolicy

    names = _names(names, "names")
    _check_specs(names)
    n, seed = check_episodes(episodes, seed)
    config = given_config(config)   # a dict of EnvConfig fields too (as the envs take it)
    names = list(dict.fromkeys(names))
    venv = SbarChargingVectorEnv(num_envs=len(names) * n, scenario=scenario, config=config, num_threads=num_threads)
    try:
        pol = BlockPolicy([make(name, venv.policy_context) for name in names], n)
        pol.reset(venv.num_envs)
        rec, rew, t_stop, last = _rollout(pol, venv, [int(seed) + i for i in range(n)] * len(names))
        out = {name: _traces(venv, rec, rew, t_stop, last, slice(b * n, (b + 1) * n))
               for name, b in zip(names, pol.block)}
    finally:
        venv.close()
    return out


def _traces(venv, rec, rew, t_stop, last, rows) -> EpisodeTraces:
    """The traces and metrics of the block ``rows`` of a :func:`_rollout`."""
    from envs.objective import short_mode_i2_a

    rec = {k: v[:, rows] for k, v in rec.items()}
    rew, t_stop = rew[:, rows], t_stop[rows]
    last = {k: np.asarray(v)[rows] for k, v in last.items()}
    dt, T = venv.config.dt_s, venv.config.n_steps
    t = (np.arange(T) + 1) * dt
    after = (t - dt)[:, None] >= t_stop[None, :] - 1e-12   # steps scored against the stop (envs.objective)
    pk = np.abs(rec["i2_peak_a"])
    i2_sm = short_mode_i2_a(venv.config.link, rec["lm_h"], venv.config.device_set())
    m = {
        "overshoot_pct": 100.0 * last["overshoot"],
        "reached_short_mode": last["reached_short_mode"].astype(float),
        "peak_i2_a": pk.max(axis=0),
        "energy_before_stop_j": np.where(after, 0.0, rec["energy_j"]).sum(axis=0),
        "energy_after_stop_j": np.where(after, rec["energy_j"], 0.0).sum(axis=0),
        "tracking_rmse_a": np.sqrt(np.mean((rec["rect_current_a"] - rec["charge_cmd_a"]) ** 2, axis=0)),
        "cost": last["episode_cost"].copy(),
        "return": rew.sum(axis=0),
        "time_above_rated_s": (pk > venv.config.rated_i2_a).sum(axis=0) * dt,
        # not a table column: the overshoot of the envelope (the fundamental, the paper's quantity)
        "envelope_overshoot_pct": 100.0 * np.where(after, rec["i2_peak_envelope_a"] / i2_sm - 1.0, -np.inf).max(axis=0),
    }
    return EpisodeTraces(t, rec["i2_peak_a"], rec["i2_a"], rec["d_short"], rec["rect_current_a"],
                         rec["charge_cmd_a"], t_stop, m)


def _row_one(label, scenario, metrics, ref):
    """Row of one model: mean and bootstrap interval per metric, paired difference against ``ref``."""
    row = {"policy": label, "scenario": scenario, "episodes": len(metrics["return"]), "train_seeds": 1}
    for k in METRICS:
        row[k], row[f"{k}_lo"], row[f"{k}_hi"] = mean_ci(metrics[k])
        if ref is not None:
            row[f"d_{k}"], row[f"d_{k}_lo"], row[f"d_{k}_hi"] = mean_ci(metrics[k] - ref[k])
    return row


def _row_seeds(label, scenario, per_seed, ref):
    """Row of one kind trained with several seeds: t interval over the seed means."""
    row = {"policy": label, "scenario": scenario, "episodes": len(per_seed[0]["return"]), "train_seeds": len(per_seed)}
    for k in METRICS:
        row[k], row[f"{k}_lo"], row[f"{k}_hi"] = seed_ci([np.nanmean(m[k]) for m in per_seed])
        if ref is not None:
            row[f"d_{k}"], row[f"d_{k}_lo"], row[f"d_{k}_hi"] = seed_ci([np.nanmean(m[k] - ref[k]) for m in per_seed])
    return row


def compare(policies=DEFAULT_POLICIES, scenarios=DEFAULT_SCENARIOS, episodes: int = DEFAULT_EPISODES,
            seed: int = 1000, progress: bool = False, config=None, train_seeds: dict | None = None,
            reference: str = REFERENCE, fork: bool = True, extra=(), extra_traces: dict | None = None,
            on_extra=None):
    """Run every policy on every scenario (same seeds); returns ``(rows, traces)``; ``fork``: the MPC's runs
    in a forked process beside the others where possible (:mod:`policies.forked`; the same results).

    ``train_seeds`` maps a label to several model specs of one kind (e.g. ``rl:run_s0/ppo_sbar.zip``,
    ...): one row each, aggregated over the seeds. Rows hold ``<metric>``, ``<metric>_lo/_hi`` (95 %)
    and the paired differences ``d_<metric>...`` against ``reference`` (run even when not listed).
    ``extra``: more specs run on the first scenario in the same batched env, no rows; their traces go
    into ``extra_traces`` under ``(spec, scenario)`` (e.g. :func:`frontier_specs`, for :func:`frontier`'s
    ``traces``: one env and one rollout instead of two). ``on_extra``: called with those traces as soon as they
    are there, before waiting for the forked child (e.g. the frontier's rows, off the critical path)."""
    from envs.core import given_config

    policies, scenarios = _names(policies, "policies"), _names(scenarios, "scenarios")
    episodes, seed = check_episodes(episodes, seed)
    _check_specs(list(policies) + [sp for specs in (train_seeds or {}).values() for sp in specs])
    check_row_labels(policies, train_seeds)
    config = given_config(config)   # a dict of EnvConfig fields once here (the split, the child, run_policies)
    groups = [(p, [p]) for p in policies] + list((train_seeds or {}).items())
    rows, traces = [], {}
    jobs = [(s, g) for s in scenarios for g in groups]
    bar = _bar(progress, total=len(jobs), desc="compare", unit="run", dynamic_ncols=True)
    with single_blas_thread():   # batched small matrices (policies.threads)
        _compare_runs(scenarios, groups, reference, episodes, seed, config, rows, traces, bar, fork,
                      (tuple(extra), {} if extra_traces is None else extra_traces, on_extra))
    bar.close()
    return rows, traces


def frontier_specs(budgets=None) -> tuple:
    """The policy specs :func:`frontier` runs (``model_based_budget:b`` per budget; default the sweep's)."""
    from .budgeted import BUDGET_SWEEP
    return tuple(f"model_based_budget:{b:g}" for b in (BUDGET_SWEEP if budgets is None else budgets))


#: policies run in a forked process beside the others (:mod:`policies.forked`): the MPC's QPs are ~40 % of the CPU
FORKED = ("mpc",)
#: kinds whose runs may also go to the forked child to share the work between the two processes
#: (:func:`_split`): on the exact-mode link each residual or imitation seed runs ``model_based_budget``'s search under
#: it (~1.1 s each); the learned seeds of ``rl`` / ``ppo_lagrangian`` (~0.07 s each) are the finer steps that even out
#: what the ~1.1-s seeds leave. None of them shares work with a spec outside its own kind (a stacked seed's rows are
#: those of its own network: the same product per block, :mod:`policies.batched`), so moving one changes no result.
#: (``random``, ~0.5-0.7 s on the modal link, was tried as movable: the split moved it instead of the finer seeds and
#: the child became the longer side by a median 0.56 s of CPU, 4 runs of 4, docs/performance.md)
MOVABLE = ("residual", "imitation", "rl", "ppo_lagrangian")
#: CPU seconds of one spec's run per scenario of 100 windows, by link and policy kind (in process, nominal windows,
#: ``num_threads=1``, 2026-11-26, load ~5; a stacked group's shared work spread over its specs; the modal ``mpc``
#: 3.5 instead of its 2.8 alone: the child's CPU beside the moved seeds ran 1-2 s above the sum, in 4 runs of 4;
#: modal ``random`` and ``hysteresis``: 0.55 and 0.23 s at load ~8, scaled by the residual's and imitation's ratio
#: between the two loads, 0.86). At load ~2 the child's work costs the same in and out of the fork and the figures are
#: mpc 2.28, residual 1.10, imitation 1.34, rl 0.096, ppo_lagrangian 0.104, random 0.52: this table's split is the
#: better one by those too (11.60 s child, 11.91 s parent; theirs would move a third residual seed, 12.28 / 11.23).
#: Only used to share the runs between the parent and the forked child (:func:`_split`), so a wrong figure costs
#: balance, never a result
RUN_COST = {"modal": {"mpc": 3.5, "residual": 1.06, "imitation": 1.18, "model_based_budget": 1.1, "rl": 0.07,
                      "ppo_lagrangian": 0.07, "model_based": 0.2, "model_based_online": 0.3, "random": 0.47,
                      "hysteresis": 0.2},
            "envelope": {"mpc": 1.8, "residual": 0.04, "imitation": 0.04}}
_OTHER_COST = {"modal": 0.25, "envelope": 0.03}
#: least estimated work [s] worth a forked child of its own (no MPC among the specs)
_MIN_FORK_S = 1.0


def _forked_runs(specs, scenarios, episodes, seed, config) -> dict:
    """``{scenario: {spec: EpisodeTraces}}`` of ``specs`` (the forked child's work, on one core)."""
    with single_blas_thread(), _one_numba_thread():
        return {s: run_policies(specs, s, episodes, seed, config, num_threads=1) for s in scenarios}


@contextlib.contextmanager
def _one_numba_thread():
    """numba's parallel regions on the calling thread only while inside (the env step is a ``prange`` kernel:
    even its one-chunk steps wake numba's other thread, and the auto choice of the batched env can pick the
    parallel step): with a forked child on the other core, each process keeps to one. The same results
    (the parallel step is bit-identical to the serial one)."""
    import numba
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(old)


def _compare_runs(scenarios, groups, reference, episodes, seed, config, rows, traces, bar, fork=True,
                  extra=((), None, None)):
    """The runs of :func:`compare` (rows and traces filled in place); with ``fork`` the :data:`FORKED`
    policies and the share of the others :func:`_split` gives it run in a child process
    (:class:`policies.forked.Forked`) on the same windows meanwhile;
    ``extra``: ``(specs, traces, on_extra)``, specs run beside the first scenario's, their traces filled in
    place, then ``on_extra(traces)`` (if given) before the child's result is awaited."""
    from .forked import Forked, available

    n, seed = int(episodes), int(seed)
    specs = list(dict.fromkeys([reference] + [sp for _, sps in groups for sp in sps]))
    heavy = _split(specs, reference, [sp for sp in extra[0] if sp not in specs], len(scenarios), config) \
        if fork and len(specs) > 1 and available() else []
    job = None
    if heavy:   # numba's kernels loaded before the fork (the child inherits them), its thread pool not yet
        from envs import SbarChargingVectorEnv
        with _no_gc():   # set-up on the critical path: nothing for the cyclic collector to free
            SbarChargingVectorEnv(num_envs=1, scenario=scenarios[0], config=config).reset(seed=seed)
            _preimport("numba.np.arrayobj")   # the env step's cache entry imports it on loading: once, not in both
        job = Forked(_forked_runs, heavy, scenarios, n, seed, config)   # (the child: the collector as here)
    placed, mine = {}, {}
    try:
        with _one_numba_thread() if job else contextlib.nullcontext():   # the child has the other core
            for s in scenarios:
                first = s == scenarios[0]
                more = [sp for sp in extra[0] if sp not in specs] if first else []
                runs = run_policies([sp for sp in specs if sp not in heavy] + more, s, n, seed, config,
                                    num_threads=1 if job else None)
                extra[1].update({(sp, s): runs[sp] for sp in extra[0] if first and sp in runs})
                mine[s] = runs
                _add_rows(s, groups, reference, runs, placed, bar)
        if extra[0] and extra[2] is not None:
            extra[2](extra[1])
        for s, runs in (job.result() if job else {}).items():   # a group's seeds may be in both processes
            _add_rows(s, groups, reference, {**mine[s], **runs}, placed, bar)
    except BaseException:
        if job:
            job.cancel()
        raise
    for s in scenarios:   # rows and traces in the order of the scenarios and groups
        for label, _ in groups:
            rows.append(placed[(s, label)][0])
            traces[(label, s)] = placed[(s, label)][1]


def _split(specs, reference, extra, n_scenarios, config) -> list:
    """The specs the forked child runs, in the order of ``specs``: the :data:`FORKED` kinds', then specs of the
    :data:`MOVABLE` kinds, the costliest first (the last first among equal costs), each moved when moving it lowers
    the larger of the two processes' estimated work (:data:`RUN_COST`; the ``extra`` specs run in the parent on the
    first scenario only). Without a :data:`FORKED` spec, a child only for at least :data:`_MIN_FORK_S` of work.
    Which process runs a spec never changes its results (the rows are independent: :func:`run_policies`)."""
    from envs.core import as_config

    link = as_config(config).link_model
    table, other = RUN_COST.get(link, {}), _OTHER_COST.get(link, 0.05)

    def kind(sp):
        return sp.split(":", 1)[0]

    def cost(sp):
        return table.get(kind(sp), other)
    heavy = [sp for sp in specs if kind(sp) in FORKED and sp != reference]
    rest = [sp for sp in specs if sp not in heavy]
    child = sum(cost(sp) for sp in heavy)
    parent = sum(cost(sp) for sp in rest) + sum(cost(sp) for sp in extra) / n_scenarios
    moved = set()
    for sp in sorted(reversed([sp for sp in rest if kind(sp) in MOVABLE and sp != reference]), key=cost, reverse=True):
        if max(parent - cost(sp), child + cost(sp)) < max(parent, child):
            moved.add(sp)
            parent, child = parent - cost(sp), child + cost(sp)
    if not heavy and child < _MIN_FORK_S:
        return []
    return heavy + [sp for sp in rest if sp in moved]


@contextlib.contextmanager
def _no_gc():
    """Python's cyclic garbage collector paused inside (its previous state restored after): the set-up before the
    MPC's fork (a kernel cache load, ~10^4 new long-lived objects) triggers collections that free nothing."""
    import gc
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def _preimport(module: str) -> None:
    """Import ``module`` if it exists (a module a cached kernel's entry imports when it is loaded: numba's
    ``arrayobj``, ~0.1 s of CPU, imported before the fork instead of in both processes after it)."""
    import importlib
    try:
        importlib.import_module(module)
    except ImportError:
        pass


def _add_rows(s, groups, reference, runs, placed, bar):
    """The row and trace of each group of scenario ``s`` whose runs are all in ``runs`` (not yet placed)."""
    ref_tr = runs[reference]
    for label, specs in groups:
        if (s, label) in placed or not all(sp in runs for sp in specs):
            continue
        trs = [runs[sp] for sp in specs]
        ref = None if label == reference else ref_tr.metrics
        placed[(s, label)] = (_row_one(label, s, trs[0].metrics, ref) if len(trs) == 1
                              else _row_seeds(label, s, [t.metrics for t in trs], ref), trs[0])
        bar.update(1)


def frontier(scenario: str = "nominal", budgets=None, episodes: int = DEFAULT_EPISODES, seed: int = 1000, config=None,
             progress: bool = False, traces: dict | None = None):
    """The budgeted model-based curve: one row per overshoot budget (:mod:`policies.budgeted`);
    ``progress``: a tqdm bar over the budgets; ``traces``: :func:`compare`'s traces of the same episodes,
    seed and config, whose ``model_based_budget:b`` runs are reused instead of run again."""
    from .budgeted import BUDGET_SWEEP

    out = []
    budgets = BUDGET_SWEEP if budgets is None else budgets
    runs = {}
    for b in budgets:
        tr = (traces or {}).get((f"model_based_budget:{b:g}", scenario))
        if tr is not None and len(tr.metrics["return"]) == episodes:
            runs[f"model_based_budget:{b:g}"] = tr
    todo = [f"model_based_budget:{b:g}" for b in budgets if f"model_based_budget:{b:g}" not in runs]
    if todo:   # the budgets not in compare's traces, side by side in one batched env
        with single_blas_thread():
            runs.update(run_policies(todo, scenario, episodes, seed, config))
    bar = _bar(progress, total=len(budgets), desc="frontier", unit="budget", leave=False)
    for b in budgets:
        bar.update(1)
        tr = runs[f"model_based_budget:{b:g}"]
        out.append({"budget": float(b), **_row_one(f"model_based_budget:{b:g}", scenario, tr.metrics, None)})
    bar.close()
    return out


class _NoBar:
    """What :func:`_bar` gives without a progress bar."""

    def update(self, n=1):
        pass

    def close(self):
        pass


def _bar(progress: bool, **kw):
    """A tqdm bar when ``progress``, else a stand-in (tqdm's import, ~0.05-0.09 s with importlib.metadata, only
    when a bar is shown)."""
    if not progress:
        return _NoBar()
    from tqdm import tqdm
    return tqdm(**kw)


def oracle_gaps(rows, traces, scenario: str, windows: int, seed: int = 1000, config=None, progress: bool = False):
    """Add to the rows of ``scenario`` the gap to the oracle (:mod:`policies.oracle`) on its first ``windows``
    windows: per window the best open-loop sequence after the stop within *that policy's own measured
    overshoot* (started from the policy's own sequence and the budgeted controller's), and
    ``oracle_gap_pct`` = 100 (E_policy - E_oracle) / E_policy of the energy after the stop (mean and
    bootstrap interval over the windows that reached short mode), ``oracle_energy_after_stop_j``.
    Policies of :data:`NO_GAP` and windows not in short mode are left out. Returns the rows."""
    from tqdm import tqdm

    from .oracle import oracle_window
    todo = [r for r in rows if r["scenario"] == scenario and r["policy"] not in NO_GAP
            and (r["policy"], scenario) in traces]
    bar = tqdm(total=len(todo) * windows, desc="oracle gap", unit="window", disable=not progress)
    for r in todo:
        tr = traces[(r["policy"], scenario)]
        n = min(int(windows), tr.d_short.shape[1])
        m = tr.metrics
        gap, eo = [], []
        for i in range(n):
            bar.update(1)
            if not m["reached_short_mode"][i]:
                continue
            o = oracle_window(scenario, seed + i, max(m["overshoot_pct"][i], 0.0) / 100.0,
                              starts=("model_based_budget:0.01",), config=config, extra_starts=(tr.d_short[:, i],))
            e_pol = m["energy_after_stop_j"][i]
            gap.append(100.0 * (e_pol - o.energy_after_stop_j) / e_pol)
            eo.append(o.energy_after_stop_j)
        r["oracle_windows"] = len(gap)
        r["oracle_gap_pct"], r["oracle_gap_pct_lo"], r["oracle_gap_pct_hi"] = mean_ci(gap)
        r["oracle_energy_after_stop_j"] = float(np.mean(eo)) if eo else float("nan")
    bar.close()
    return rows


def oracle_curve(scenario: str = "nominal", windows: int = 20, seed: int = 1000, config=None, progress=False):
    """The oracle frontier (:func:`policies.oracle.oracle_frontier`) on the first ``windows`` windows."""
    from .oracle import oracle_frontier
    return oracle_frontier(scenario, range(seed, seed + int(windows)), config=config, progress=progress)


def plot_transitions(traces: dict, scenario: str, out_png, episode: int = 0, window_s=(-2e-3, 12e-3),
                     rated_i2_a: float = 15.0):
    """Figure of representative RM -> SM transitions: step peak |I2| and d_short of every policy
    (but ``random``, whose duty noise rings the link and would hide the rest) on one episode of
    ``scenario``, time relative to the stop command."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    items = [(p, tr) for (p, s), tr in traces.items() if s == scenario and p != "random"]   # random: noise
    if not items:
        raise ValueError(f"scenario={scenario!r} has no traces; valid: {sorted({s for _, s in traces})}")
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1])
    for p, tr in items:
        t = (tr.t_s - tr.t_stop_s[episode]) * 1e3
        sel = (t >= window_s[0] * 1e3) & (t <= window_s[1] * 1e3)
        a1.plot(t[sel], tr.i2_peak_a[sel, episode], lw=1.2, label=p)
        a2.plot(t[sel], tr.d_short[sel, episode], lw=1.0, label=p)
    a1.axhline(rated_i2_a, color="r", lw=0.8, ls="--", label="rated")
    a1.axvline(0, color="k", lw=0.8, ls=":")
    a1.set_ylabel("|I2| envelope, step peak [A]")
    a1.set_title(f"RM -> SM at the stop command ({scenario}, episode {episode})")
    a1.grid(alpha=0.3)
    a1.legend(fontsize=8, ncol=2)
    a2.set_ylabel("d_short")
    a2.set_xlabel("time after the stop command [ms]")
    a2.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_output(out_png) as tmp:  # removed on failure (a full disk: the file named)
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return out_png


def plot_frontier(rows, sweep, scenario: str, out_png, x: str = "overshoot_pct", oracle=None):
    """Return and energy after the stop against the overshoot on ``scenario``: one point per policy
    with its 95 % intervals, the Pareto front of the policies (higher return / less energy after the
    stop, less overshoot), the budgeted model-based curve and (``oracle``: rows of :func:`oracle_curve`)
    the oracle curve in the energy panel (means over its windows at each budget above the windows' floors)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .stats import pareto_front

    pts = [r for r in rows if r["scenario"] == scenario and r["policy"] not in ("random", "step", "hysteresis")]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    for ax, y, sign in ((axes[0], "return", 1.0), (axes[1], "energy_after_stop_j", -1.0)):
        for r in pts:
            ax.errorbar(r[x], r[y], xerr=[[r[x] - r[f"{x}_lo"]], [r[f"{x}_hi"] - r[x]]],
                        yerr=[[r[y] - r[f"{y}_lo"]], [r[f"{y}_hi"] - r[y]]], fmt="o", ms=4, capsize=2,
                        label=f"{r['policy']}" + (f" ({r['train_seeds']} seeds)" if r["train_seeds"] > 1 else ""))
        if pts:
            front = pareto_front([r[x] for r in pts], [sign * r[y] for r in pts])
            ax.plot([pts[i][x] for i in front], [pts[i][y] for i in front], "k--", lw=1, label="Pareto front")
        if sweep:
            ax.plot([r[x] for r in sweep], [r[y] for r in sweep], "-s", color="0.5", ms=3,
                    label="model_based with overshoot budget")
        if oracle and y == "energy_after_stop_j":
            n = len(oracle[0]["per_window"]["seed"])
            ax.plot([r["overshoot_pct"] for r in oracle], [r["energy_after_stop_j"] for r in oracle], "-^", color="C3",
                    ms=4, label=f"oracle: best open-loop sequence ({n} windows, from each window's floor)")
            ax.legend(fontsize=7)
        ax.set_xlabel("overshoot after the stop over the true short-mode I2 [%]")
        ax.set_ylabel({"return": "episode return", "energy_after_stop_j": "energy after the stop [J]"}[y])
        ax.grid(alpha=0.3)
    if axes[0].get_legend_handles_labels()[0]:   # (none: only step / random / hysteresis rows and no frontier, where
        axes[0].legend(fontsize=7)                # matplotlib warned "No artists with labels found" on stderr)
    fig.suptitle(f"{scenario}: means with 95 % intervals")
    fig.tight_layout()
    with atomic_output(out_png) as tmp:  # removed on failure (a full disk: the file named)
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return out_png
