"""Parameter sweeps: run many cases on Dask (or serially) into a resumable Parquet store.

The engine knows nothing about missions: it runs a *case runner* ``run_case(params: dict) -> dict``
(flat metrics) on every :class:`~mission_sim.studies.study.Case` and stores one row per case
(:mod:`mission_sim.studies.store`). The mission runner is :class:`MissionCaseRunner`; tests and
other studies can pass any picklable callable.

Scale (10^5 cases and more)
    Cases come from a lazy iterator (:class:`~mission_sim.studies.study.CaseSpace`) and are
    submitted in *chunks* (several cases per Dask task, sized from the cases' measured busy time on
    the workers so a task lasts about ``chunk_target_s`` and at least ``TASK_OVERHEAD_S / 2 %``:
    the per-task overhead stays under 2 % of the work; busy = wall minus the time spent waiting for
    a core, so a loaded machine does not shrink the chunks) with a bounded number of tasks in
    flight: a new chunk is submitted only when one has come back (back-pressure), and each future
    is dropped as soon as its rows are buffered, so the scheduler never holds stored results and
    a lost worker never makes it recompute them. A runner with a ``warm()`` method (the mission
    runner: imports, numba cache, coupling table) is warmed once on every worker before the first
    chunk (``client.run``), and mission cases run summary-only. Results go to a :class:`~.store.PartWriter`
    (a part every 1,000 rows or 2 s, merged incrementally), and the end of a run compacts a
    handful of files.

Before anything runs, :func:`prepare_study` refuses a study larger than ``max_cases`` (from its
axis lengths, nothing generated) and checks every case's parameters against the runner
(``validate_params``: the mission config's own validation), reporting all bad values at once.

Dependency direction: this module imports nothing from ``envs`` or ``policies``. The caller (the
CLI) passes the policy factory (``policies.make``) into :class:`MissionCaseRunner`; it is pickled
by reference and imported on the workers.
"""

from __future__ import annotations

import itertools
import math
import os
import socket
import time
import traceback
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from .cluster import dask_client
from .mission_cases import MissionCaseRunner
from .prepare import check_cases, prepare_study
from .status import SweepStatus, sweep_status, write_manifest
from .store import BOOKKEEPING_COLUMNS, CaseStore, PartWriter, StoreState, _to_scalar, read_results
from .study import Case, CaseSpace

__all__ = ["CaseStore", "SweepResult", "MissionCaseRunner", "run_sweep", "run_case_safe", "run_chunk",
           "dask_client", "prepare_study", "check_cases", "read_results", "sweep_status", "SweepStatus",
           "write_manifest", "BOOKKEEPING_COLUMNS"]

RunCase = Callable[[dict], Mapping]
_MAX_CHUNK = 4096
#: CPU cost of one Dask task on a local cluster (scheduling, (de)serialising a chunk and its rows, the
#: driver's bookkeeping): measured 8.6 ms in the driver + 6.5 ms in the worker per one-case task of a
#: no-op runner (2 cores, load ~10, benchmarks/bench_sweep_missions.py --overhead); a task computes at
#: least 50x this, so the overhead stays < 2 %
TASK_OVERHEAD_S = 0.015
_OVERHEAD_SHARE = 0.02
#: tasks in flight per worker thread: one running, one waiting on the worker (no idle round trip)
_IN_FLIGHT_PER_THREAD = 2


# ----------------------------------------------------------------------------- one case
def run_case_safe(run_case: RunCase, case_id: str, params: dict) -> dict:
    """Run one case on a worker; any exception becomes an ``error`` result instead of propagating."""
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        metrics = run_case(dict(params))
        if not isinstance(metrics, Mapping):
            raise TypeError(f"case runner returned {type(metrics).__name__}; valid: a dict of metrics")
        metrics = {str(k): v if type(v) in _PLAIN else _to_scalar(v) for k, v in metrics.items()}
        status, error, tb = "ok", None, None
    except Exception as exc:  # noqa: BLE001 - recorded with the case, the sweep goes on
        metrics, status = {}, "error"
        error = f"{type(exc).__name__}: {exc}".splitlines()[0] if str(exc) else type(exc).__name__
        tb = traceback.format_exc()
    return {"case_id": case_id, "status": status, "error": error, "traceback": tb,
            "case_wall_s": time.perf_counter() - t0, "case_cpu_s": time.thread_time() - c0, "worker": _worker_name(),
            "metrics": metrics}


_PLAIN = (float, int, str, bool, type(None))


_WORKER_NAME = [0, ""]  # (pid, "host:pid"): computed once per process (a forked child recomputes it)


def _worker_name() -> str:
    pid = os.getpid()
    if _WORKER_NAME[0] != pid:
        _WORKER_NAME[:] = [pid, f"{socket.gethostname()}:{pid}"]
    return _WORKER_NAME[1]


def _run_queue_wait_s() -> float:
    """Seconds this thread has spent runnable but waiting for a core (Linux ``schedstat``; 0 elsewhere).
    A chunk's wall time minus this is what it would take on an idle machine: its CPU time plus its
    own waits (I/O, sleeps), so a loaded machine does not make the chunks smaller."""
    try:
        with open("/proc/thread-self/schedstat", "rb") as f:
            return int(f.read().split()[1]) * 1e-9
    except (OSError, ValueError, IndexError):
        return 0.0


class Chunk:
    """The ``(case_id, params)`` pairs of one Dask task, in a box: Dask walks lists, tuples and dicts
    given to ``submit`` looking for other tasks (~50 us a case), but not other objects."""

    __slots__ = ("items",)

    def __init__(self, items: list):
        self.items = items

    def __getstate__(self):
        return self.items

    def __setstate__(self, items):
        self.items = items


def run_chunk(run_case: RunCase, chunk: Chunk) -> list[dict]:
    """One Dask task: several ``(case_id, params)`` run one after the other (:func:`run_case_safe`);
    each result also gets ``case_busy_s``, its wall time less its share of the chunk's wait for a core."""
    t0, q0 = time.perf_counter(), _run_queue_wait_s()
    out = [run_case_safe(run_case, cid, params) for cid, params in chunk.items]
    wall, wait = time.perf_counter() - t0, _run_queue_wait_s() - q0
    busy_share = max(0.0, 1.0 - wait / wall) if wall > 0 else 1.0
    for r in out:
        r["case_busy_s"] = r["case_wall_s"] * busy_share
    return out


def _row(case: Case, result: dict, attempt: int = 1) -> dict:
    row = {k: result.get(k) for k in BOOKKEEPING_COLUMNS if k not in ("params_json", "attempt")}
    row["case_id"] = case.case_id
    row["attempt"] = int(attempt)
    row["params_json"] = case.canonical_params
    row.update(case.params)
    for k, v in result.get("metrics", {}).items():
        row[f"metric.{k}" if k in row else k] = v
    return row


def _infrastructure_error(case: Case, exc: BaseException) -> dict:
    """A case whose task failed outside the runner (worker died, task cancelled)."""
    return {"case_id": case.case_id, "status": "error",
            "error": f"{type(exc).__name__}: {exc}".splitlines()[0], "traceback": None,
            "case_wall_s": math.nan, "worker": None, "metrics": {}}


# ----------------------------------------------------------------------------- pending cases
class _Pending:
    """The study's cases not yet stored (or stored as errors, with ``retry_errors``), lazily, as
    ``(case, attempt)``; counts the cases it skips (ok / error). Case ids are remembered only for a
    one-shot iterator (to check they are unique and to find this study's rows afterwards)."""

    def __init__(self, cases: Iterable[Case], state: StoreState, retry_errors: bool, bar=None):
        self.cases, self.state, self.retry, self.bar = cases, state, retry_errors, bar
        self.ids: set[str] | None = None if isinstance(cases, (CaseSpace, list, tuple)) else set()
        self.n_skipped = self.n_skipped_error = self.n_seen = 0
        if isinstance(cases, (list, tuple)) and len({c.case_id for c in cases}) != len(cases):
            raise ValueError("duplicate case_ids in the case list; use case_space()")

    def _skip(self, case: Case) -> bool:
        if case.case_id not in self.state.done:
            return False
        is_error = case.case_id in self.state.errors
        if is_error and self.retry:
            return False
        self.n_skipped += 1
        self.n_skipped_error += is_error
        return True

    def __iter__(self):
        skipped_since = 0
        for c in self.cases:
            if self.ids is not None:
                if c.case_id in self.ids:
                    raise ValueError(f"duplicate case_id {c.case_id} in the case list; use case_space()")
                self.ids.add(c.case_id)
            self.n_seen += 1
            if self._skip(c):
                skipped_since += 1
                if skipped_since >= 1000:
                    self.bar.update(skipped_since)
                    skipped_since = 0
                continue
            if skipped_since:
                self.bar.update(skipped_since)
                skipped_since = 0
            yield c, self.state.errors.get(c.case_id, 0) + 1
        self.bar.update(skipped_since)

    def case_ids(self) -> frozenset:
        """The ids of the study's cases (recomputed from a re-iterable case collection)."""
        return frozenset(self.ids if self.ids is not None else (c.case_id for c in self.cases))


# ----------------------------------------------------------------------------- engine
@dataclass
class SweepResult:
    """What a sweep did: counts, timing; ``results`` reads the rows of *this* study's cases (lazily)."""

    out_dir: Path
    n_cases: int
    n_skipped: int
    n_run: int
    n_ok: int
    n_error: int
    wall_s: float  # the whole call (includes the cluster start-up when ``client_factory`` is used)
    compact_s: float = math.nan  # the end-of-run compaction alone
    case_ids: Callable[[], frozenset] | None = field(default=None, repr=False)
    _results: pd.DataFrame | None = field(default=None, repr=False)

    @property
    def results(self) -> pd.DataFrame:
        """The stored rows of this study's cases (read on first use)."""
        if self._results is None:
            df = CaseStore(self.out_dir).read()
            ids = self.case_ids() if self.case_ids is not None else frozenset(df["case_id"])
            self._results = df[df["case_id"].isin(ids)].reset_index(drop=True)
        return self._results

    @property
    def cases_per_s(self) -> float:
        return self.n_run / self.wall_s if self.wall_s > 0 else math.nan

    @property
    def n_missing(self) -> int:
        """Cases of the study not in the store (interrupted, or their tasks were lost)."""
        return self.n_cases - self.n_ok - self.n_error


def run_sweep(cases: Iterable[Case], run_case: RunCase, out_dir, *, client=None, client_factory=None,
              progress: bool = True, progress_desc: str = "sweep", retry_errors: bool = False,
              part_rows: int = 1000, part_age_s: float = 2.0, chunk_target_s: float = 1.0,
              max_in_flight: int | None = None, before_run: Callable[[], object] | None = None) -> SweepResult:
    """Run the cases not yet in ``out_dir`` and store one row per case.

    cases : the study's cases (a lazy :class:`~.study.CaseSpace`, or any iterable of unique cases)
    client : a ``distributed.Client`` (tasks are submitted to its cluster), or None to run serially
        in this process (same store, same rows; the reference for the "equal to serial" tests).
    client_factory : instead of ``client``, a zero-argument callable returning a context manager that
        yields a client (e.g. ``lambda: dask_client(None, 2)``); called only if there is work left.
    retry_errors : also re-run the cases stored with ``status = "error"`` (their new row supersedes
        the old one: ``attempt`` + 1).
    part_rows, part_age_s : a part file every that many rows or seconds.
    chunk_target_s, max_in_flight : busy time aimed at per Dask task (at least 50 x ``TASK_OVERHEAD_S``);
        tasks in flight (default 2 per worker thread, at least 4).
    before_run : called once the store is locked, before anything runs (the CLI writes the manifest).

    A case whose runner raises is stored with ``status = "error"``; the others go on. Interrupting
    (KeyboardInterrupt) stores the rows already received and leaves the rest for a re-run.
    """
    from tqdm.auto import tqdm

    store, t0 = CaseStore(out_dir), time.perf_counter()
    n_total = len(cases) if hasattr(cases, "__len__") else None
    with store.lock():
        store.cleanup()  # leftovers of a killed run (absorbed files, temporaries)
        if before_run is not None:
            before_run()
        bar = tqdm(total=n_total, unit="case", desc=progress_desc, disable=not progress, dynamic_ncols=True)
        pending = _Pending(cases, store.state(), retry_errors, bar)
        writer = PartWriter(store, part_rows, part_age_s)
        try:
            n_run = _dispatch(pending, run_case, writer, bar, client, client_factory,
                              dict(chunk_target_s=chunk_target_s, max_in_flight=max_in_flight))
        finally:
            writer.flush()  # interrupted too: what came back is stored
            bar.close()
        t_c = time.perf_counter()
        store.compact(progress=progress)
        compact_s = time.perf_counter() - t_c
    n_error = pending.n_skipped_error + writer.n_error_rows
    return SweepResult(out_dir=Path(out_dir), n_cases=pending.n_seen, n_skipped=pending.n_skipped, n_run=n_run,
                       n_ok=pending.n_skipped + writer.n_rows - n_error, n_error=n_error,
                       wall_s=time.perf_counter() - t0, compact_s=compact_s, case_ids=pending.case_ids)


def _dispatch(pending: _Pending, run_case, writer: PartWriter, bar, client, client_factory, opts) -> int:
    """Serially, on ``client``, or on a client from ``client_factory`` (started only if work is left)."""
    it = iter(pending)
    first = next(it, None)
    if first is None:
        return 0
    it = itertools.chain([first], it)
    if client is not None:
        return _run_dask(client, it, run_case, writer, bar, **opts)
    if client_factory is not None:
        with client_factory() as c:
            return _run_dask(c, it, run_case, writer, bar, **opts)
    n = 0
    for case, attempt in it:
        writer.add([_row(case, run_case_safe(run_case, case.case_id, case.params), attempt)])
        n += 1
        bar.update(1)
    return n


class _Submitter:
    """Chunks of pending cases submitted to Dask, at most ``window`` tasks in flight; chunk size
    adapted to the measured per-case time so a task lasts about ``target_s``."""

    def __init__(self, client, pending, run_case, target_s: float, window: int):
        self.client, self.pending, self.run_case = client, pending, run_case
        self.target_s, self.window = max(target_s, TASK_OVERHEAD_S / _OVERHEAD_SHARE), window
        self.in_flight: dict[str, list] = {}
        self.requeued: deque = deque()  # cases of a chunk that killed a worker: re-run one by one
        self.chunk = 1
        self.mean_case_s: float | None = None
        self.n_lost = 0

    def fill(self, ac) -> None:
        while len(self.in_flight) < self.window:
            if self.requeued:
                items = [self.requeued.popleft()]
            else:
                items = list(itertools.islice(self.pending, self.chunk))
            if not items:
                return
            key = f"cases-{items[0][0].case_id}-{len(items)}-{uuid.uuid4().hex[:6]}"
            fut = self.client.submit(run_chunk, self.run_case, Chunk([(c.case_id, c.params) for c, _ in items]),
                                     key=key, pure=False, retries=0)
            self.in_flight[key] = items
            ac.add(fut)

    def learn(self, results: list[dict]) -> None:
        """Chunk size from the cases' busy time on the worker (wall minus time spent waiting for a core)."""
        busy = [r.get("case_busy_s", r["case_wall_s"]) for r in results if r.get("case_wall_s") is not None]
        if not busy:
            return
        m = sum(busy) / len(busy)
        self.mean_case_s = m if self.mean_case_s is None else 0.7 * self.mean_case_s + 0.3 * m
        self.chunk = int(min(max(self.target_s / max(self.mean_case_s, 1e-6), 1), _MAX_CHUNK))

    def collect(self, fut, res) -> list[dict]:
        """Rows of a finished task; a task that killed its worker is split, other failures are left out."""
        from distributed import KilledWorker

        items = self.in_flight.pop(fut.key)
        if fut.status == "finished" and isinstance(res, list):
            self.learn(res)
            return [_row(c, r, a) for (c, a), r in zip(items, res)]
        exc = res if isinstance(res, BaseException) else None
        if exc is None:
            try:
                exc = fut.exception(timeout=10)
            except Exception as e:  # noqa: BLE001 - cancelled / lost
                exc = e
        if isinstance(exc, KilledWorker) and len(items) > 1:
            self.requeued.extend(items)  # find the culprit: its chunk-mates run alone
            return []
        if isinstance(exc, KilledWorker):
            (case, attempt), = items
            return [_row(case, _infrastructure_error(case, exc), attempt)]
        self.n_lost += len(items)  # not the cases' fault: left out of the store, retried on re-run
        return []


def _run_dask(client, pending, run_case: RunCase, writer: PartWriter, bar, *, chunk_target_s: float = 1.0,
              max_in_flight: int | None = None) -> int:
    """Submit chunks with back-pressure, buffer rows as tasks complete, drop each future once stored."""
    from distributed import as_completed

    window = max_in_flight or max(4, _IN_FLIGHT_PER_THREAD * sum(client.nthreads().values()))
    _warm_workers(client, run_case)
    sub = _Submitter(client, pending, run_case, chunk_target_s, window)
    # loop=client.loop: as_completed would otherwise use the *default* client's loop, which a
    # failed Client(...) elsewhere in the process can leave pointing at a dead loop (hang)
    ac = as_completed([], loop=client.loop, with_results=True, raise_errors=False)
    try:
        return _drain(ac, sub, writer, bar)
    finally:
        ac.clear()  # interrupted: the futures still in flight are released (the scheduler forgets them)


def _warm_workers(client, run_case) -> None:
    """``run_case.warm()`` once on every worker (if the runner has one); a failure is only a missed warm-up."""
    warm = getattr(run_case, "warm", None)
    if not callable(warm):
        return
    try:
        client.run(_call, warm)
    except Exception:  # noqa: BLE001 - the cases warm their worker themselves then
        pass


def _call(fn):
    fn()


def _drain(ac, sub: _Submitter, writer: PartWriter, bar) -> int:
    """Keep ``sub``'s window full and store what comes back until nothing is pending or in flight."""
    sub.fill(ac)
    n = n_err = 0
    while not ac.is_empty():
        if writer.rows and not ac.has_ready():
            time.sleep(0.1)  # rows waiting: flush them on time even if no task comes back for a while
            writer.maybe_flush()
            continue
        rows = [r for fut, res in ac.next_batch(block=True) for r in sub.collect(fut, res)]
        writer.add(rows)  # the batch's futures are gone now: the scheduler may forget their results
        n += len(rows)
        n_err += sum(r["status"] == "error" for r in rows)
        if n_err:
            bar.set_postfix(errors=n_err, refresh=False)
        bar.update(len(rows))
        sub.fill(ac)
    return n
