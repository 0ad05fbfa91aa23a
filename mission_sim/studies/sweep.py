"""Parameter sweeps: run many cases on Dask (or serially) into a resumable Parquet store.

The engine knows nothing about missions: it runs a *case runner* ``run_case(params: dict) -> dict``
(flat metrics) on every :class:`~mission_sim.studies.study.Case` and stores one row per case. The mission
runner is :class:`MissionCaseRunner`; tests and other studies can pass any picklable callable.

Store (``OUT/cases/``)
    A directory of Parquet files; each file holds the rows of the cases finished together (one
    ``as_completed`` batch). A file is written to a temporary name and renamed into place
    (``os.replace``, atomic), so a file is either complete or absent: *the part file is the
    bookkeeping*. A killed sweep loses only cases still running; a resumed sweep reads the case_ids
    present and submits the rest, so no case is written twice. At the end of a run the parts are
    compacted into one file that names the files it absorbs (Parquet metadata); absorbed files are
    ignored by readers and deleted, so a kill during compaction cannot duplicate rows either.
    Only one sweep may write a store at a time (an ``flock`` on ``OUT/.sweep.lock``).

Row = ``case_id, status ("ok" | "error"), error, traceback, case_wall_s, worker, params_json``, the
parameters (one column per key, dotted names as in the study) and the runner's metrics (a metric
whose name clashes with a parameter or a bookkeeping column is stored as ``metric.<name>``).

Dependency direction: this module imports nothing from ``envs`` or ``policies``. The caller (the
CLI) passes the policy factory (``policies.make``) into :class:`MissionCaseRunner`; it is pickled
by reference and imported on the workers.
"""

from __future__ import annotations

import contextlib
import fcntl
import importlib
import json
import logging
import math
import os
import socket
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from .study import POLICY_KEY, Case, Study, canonical_json, expand_cases

__all__ = ["CaseStore", "SweepResult", "MissionCaseRunner", "run_sweep", "run_case_safe", "dask_client",
           "prepare_study", "read_results", "BOOKKEEPING_COLUMNS"]

RunCase = Callable[[dict], Mapping]
BOOKKEEPING_COLUMNS = ("case_id", "status", "error", "traceback", "case_wall_s", "worker", "params_json")
_ABSORBS_KEY = b"dronewpt.absorbs"


# ----------------------------------------------------------------------------- store
class CaseStore:
    """Parquet part files under ``out_dir/cases`` (see the module docstring)."""

    def __init__(self, out_dir):
        self.out_dir = Path(out_dir)
        self.dir = self.out_dir / "cases"

    # -- files
    def _all_files(self) -> list[Path]:
        if not self.dir.is_dir():
            return []
        return sorted(p for p in self.dir.iterdir() if p.suffix == ".parquet" and not p.name.startswith("."))

    def _absorbed(self, files: Iterable[Path]) -> set[str]:
        gone = set()
        for p in files:
            if p.name.startswith("compact-"):
                meta = pq.read_schema(p).metadata or {}
                gone.update(json.loads(meta.get(_ABSORBS_KEY, b"[]")))
        return gone

    def files(self) -> list[Path]:
        """The live part files (absorbed files and temporaries excluded)."""
        files = self._all_files()
        gone = self._absorbed(files)
        return [p for p in files if p.name not in gone]

    # -- read
    def done_ids(self) -> set[str]:
        """case_ids present in the store (finished cases, ``ok`` or ``error``)."""
        ids = set()
        for p in self.files():
            ids.update(pq.read_table(p, columns=["case_id"]).column("case_id").to_pylist())
        return ids

    def read(self) -> pd.DataFrame:
        """All rows, one per case_id (duplicates, which the writer never makes, are dropped: first kept)."""
        frames = [pq.read_table(p).to_pandas() for p in self.files()]
        frames = [f for f in frames if len(f)]
        if not frames:
            return pd.DataFrame(columns=list(BOOKKEEPING_COLUMNS))
        df = pd.concat(frames, ignore_index=True, sort=False)
        return df.drop_duplicates("case_id", keep="first").reset_index(drop=True)

    # -- write
    def _write_table(self, table: pa.Table, name: str) -> Path:
        self.dir.mkdir(parents=True, exist_ok=True)
        final = self.dir / name
        tmp = self.dir / f".{name}.{os.getpid()}.tmp"
        pq.write_table(table, tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, final)
        return final

    def write(self, rows: Sequence[dict]) -> Path | None:
        """Write finished cases as one new part file (atomically). Returns its path."""
        if not rows:
            return None
        table = _rows_to_table(rows)
        name = f"part-{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet"
        return self._write_table(table, name)

    def compact(self) -> Path | None:
        """Merge all live files into one; absorbed files are then deleted (safe to kill at any point)."""
        every = self._all_files()
        live = self.files()
        tmps = [p for p in self.dir.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")] \
            if self.dir.is_dir() else []
        for p in tmps:  # leftovers of a killed writer: never renamed, so never counted
            p.unlink(missing_ok=True)
        if len(live) <= 1 and len(every) == len(live):
            return None
        out = None
        if len(live) > 1:
            table = _frame_to_table(self.read())
            table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                                   _ABSORBS_KEY: json.dumps([p.name for p in every]).encode()})
            out = self._write_table(table, f"compact-{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet")
            live = [out]
        for p in every:
            if p not in live:
                p.unlink(missing_ok=True)
        return out

    @contextlib.contextmanager
    def lock(self):
        """Exclusive writer lock for this store (released when the process ends, even if killed)."""
        self.out_dir.mkdir(parents=True, exist_ok=True)
        fh = open(self.out_dir / ".sweep.lock", "a+")
        try:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise ValueError(f"another sweep is writing to {str(self.out_dir)!r}; "
                                 "wait for it or use another --out") from None
            yield self
        finally:
            fh.close()


def _to_scalar(v):
    if isinstance(v, (np.generic,)):
        v = v.item()
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    return json.dumps(v, default=str)


def _frame_to_table(df: pd.DataFrame) -> pa.Table:
    """DataFrame -> Arrow table; a column mixing strings and other values is stored as JSON text."""
    df = df.copy()
    for col in df.columns:
        if df[col].dtype == object:
            kinds = {type(v) for v in df[col] if v is not None and not (isinstance(v, float) and math.isnan(v))}
            if len(kinds) > 1 and str in kinds:
                df[col] = [None if v is None or (isinstance(v, float) and math.isnan(v))
                           else (v if isinstance(v, str) else json.dumps(v)) for v in df[col]]
    return pa.Table.from_pandas(df, preserve_index=False)


def _rows_to_table(rows: Sequence[dict]) -> pa.Table:
    return _frame_to_table(pd.DataFrame([{k: _to_scalar(v) for k, v in r.items()} for r in rows]))


def read_results(out_dir) -> pd.DataFrame:
    """All rows of a sweep output folder, one per case (see :class:`CaseStore`)."""
    return CaseStore(out_dir).read()


# ----------------------------------------------------------------------------- one case
def run_case_safe(run_case: RunCase, case_id: str, params: dict) -> dict:
    """Run one case on a worker; any exception becomes an ``error`` result instead of propagating."""
    t0 = time.perf_counter()
    try:
        metrics = run_case(dict(params))
        if not isinstance(metrics, Mapping):
            raise TypeError(f"case runner returned {type(metrics).__name__}; valid: a dict of metrics")
        metrics = {str(k): _to_scalar(v) for k, v in metrics.items()}
        status, error, tb = "ok", None, None
    except Exception as exc:  # noqa: BLE001 - recorded with the case, the sweep goes on
        metrics, status = {}, "error"
        error = f"{type(exc).__name__}: {exc}".splitlines()[0] if str(exc) else type(exc).__name__
        tb = traceback.format_exc()
    return {"case_id": case_id, "status": status, "error": error, "traceback": tb,
            "case_wall_s": time.perf_counter() - t0, "worker": f"{socket.gethostname()}:{os.getpid()}",
            "metrics": metrics}


def _row(case: Case, result: dict) -> dict:
    row = {k: result.get(k) for k in BOOKKEEPING_COLUMNS if k != "params_json"}
    row["case_id"] = case.case_id
    row["params_json"] = canonical_json(case.params)
    row.update(case.params)
    for k, v in result.get("metrics", {}).items():
        row[f"metric.{k}" if k in row else k] = v
    return row


def _infrastructure_error(case: Case, exc: BaseException) -> dict:
    """A case whose task failed outside the runner (worker died, task cancelled)."""
    return {"case_id": case.case_id, "status": "error",
            "error": f"{type(exc).__name__}: {exc}".splitlines()[0], "traceback": None,
            "case_wall_s": math.nan, "worker": None, "metrics": {}}


# ----------------------------------------------------------------------------- engine
@dataclass
class SweepResult:
    """What a sweep did: counts, timing, and the rows of *this* study's cases."""

    out_dir: Path
    n_cases: int
    n_skipped: int
    n_run: int
    n_ok: int
    n_error: int
    wall_s: float  # the whole call (includes the cluster start-up when ``client_factory`` is used)
    results: pd.DataFrame = field(repr=False)

    @property
    def cases_per_s(self) -> float:
        return self.n_run / self.wall_s if self.wall_s > 0 else math.nan

    @property
    def n_missing(self) -> int:
        """Cases of the study not in the store (interrupted, or their tasks were lost)."""
        return self.n_cases - self.n_ok - self.n_error


def run_sweep(cases: Sequence[Case], run_case: RunCase, out_dir, *, client=None, client_factory=None,
              progress: bool = True, progress_desc: str = "sweep") -> SweepResult:
    """Run the cases not yet in ``out_dir`` and store one row per case.

    client : a ``distributed.Client`` (tasks are submitted to its cluster), or None to run serially
        in this process (same store, same rows; the reference for the "equal to serial" tests).
    client_factory : instead of ``client``, a zero-argument callable returning a context manager that
        yields a client (e.g. ``lambda: dask_client(None, 2)``); called only if there is work left.
    progress : tqdm progress bar on stderr.

    Cases already present (by case_id) are skipped. A case whose runner raises is stored with
    ``status = "error"`` and its error; the others go on. Interrupting (KeyboardInterrupt, SIGTERM
    turned into one by the CLI) cancels the pending cases; finished ones are already on disk.
    """
    from tqdm.auto import tqdm

    store = CaseStore(out_dir)
    by_id = {c.case_id: c for c in cases}
    if len(by_id) != len(cases):
        raise ValueError("duplicate case_ids in the case list; expand the study with expand_cases()")
    t0 = time.perf_counter()
    with store.lock():
        store.compact()  # clean leftovers of a killed run (absorbed files, temporaries)
        done = store.done_ids() & set(by_id)
        todo = [c for c in cases if c.case_id not in done]
        n_run = 0
        bar = tqdm(total=len(cases), initial=len(done), unit="case", desc=progress_desc, disable=not progress,
                   dynamic_ncols=True)
        try:
            if client is None and client_factory is not None and todo:
                with client_factory() as c:
                    n_run = _run_dask(c, todo, run_case, store, bar)
            elif client is None:
                for c in todo:
                    store.write([_row(c, run_case_safe(run_case, c.case_id, c.params))])
                    n_run += 1
                    bar.update(1)
            else:
                n_run = _run_dask(client, todo, run_case, store, bar)
        finally:
            bar.close()
            store.compact()
        df = store.read()
    df = df[df["case_id"].isin(by_id)].reset_index(drop=True)
    n_err = int((df["status"] == "error").sum()) if len(df) else 0
    return SweepResult(out_dir=Path(out_dir), n_cases=len(cases), n_skipped=len(done), n_run=n_run,
                       n_ok=len(df) - n_err, n_error=n_err, wall_s=time.perf_counter() - t0, results=df)


def _run_dask(client, todo: Sequence[Case], run_case: RunCase, store: CaseStore, bar) -> int:
    """Submit ``todo``, store results batch by batch as they complete; returns the number stored.

    A task that fails outside the runner is stored as an error only if it killed its workers
    (``KilledWorker``: the case itself is the likely cause). Other task failures (cancelled, lost
    scheduler) are not stored, so a re-run retries those cases.
    """
    from distributed import KilledWorker, as_completed

    if not todo:
        return 0
    futures = {}
    for c in todo:
        f = client.submit(run_case_safe, run_case, c.case_id, c.params, key=f"case-{c.case_id}-{uuid.uuid4().hex[:6]}",
                          pure=False, retries=0)
        futures[f.key] = (f, c)
    n = n_err = 0
    try:
        # loop=client.loop: as_completed would otherwise use the *default* client's loop, which a
        # failed Client(...) elsewhere in the process can leave pointing at a dead loop (hang)
        done_iter = as_completed([f for f, _ in futures.values()], loop=client.loop, with_results=True,
                                 raise_errors=False)
        for batch in done_iter.batches():
            rows = []
            for fut, res in batch:
                case = futures[fut.key][1]
                if fut.status != "finished" or not isinstance(res, dict):
                    exc = res if isinstance(res, BaseException) else None
                    if exc is None:
                        try:
                            exc = fut.exception(timeout=10)
                        except Exception as e:  # noqa: BLE001 - cancelled / lost
                            exc = e
                    if not isinstance(exc, KilledWorker):
                        continue  # not the case's fault: left out of the store, retried on re-run
                    res = _infrastructure_error(case, exc)
                rows.append(_row(case, res))
            store.write(rows)
            n += len(rows)
            n_err += sum(r["status"] == "error" for r in rows)
            if n_err:
                bar.set_postfix(errors=n_err, refresh=False)
            bar.update(len(rows))
    finally:
        client.cancel([f for f, _ in futures.values()])
    return n


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, *, connect_timeout_s: float = 10.0):
    """A ``distributed.Client``: to ``scheduler`` if given, else to a new local cluster of ``workers``
    single-threaded worker processes (default: one per CPU). Closed cleanly on exit."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=connect_timeout_s, set_as_default=False)
        except Exception as exc:  # noqa: BLE001 - address errors come as OSError, TimeoutError, ValueError, ...
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ValueError(f"--scheduler {scheduler!r}: cannot connect to a Dask scheduler ({msg})") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise ValueError(f"workers={n!r} is invalid; valid range: integer >= 1")
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR)
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


# ----------------------------------------------------------------------------- mission cases
class MissionCaseRunner:
    """``run_case`` for missions: overrides -> MissionConfig -> policy -> ``run_mission(...).summary``.

    base : the base mission as a plain dict (``config_to_dict``)
    make_policy : ``make_policy(name, PolicyContext) -> Policy`` (the CLI passes ``policies.make``;
        picklable by reference, so workers import ``policies`` themselves)
    """

    def __init__(self, base: dict, make_policy: Callable):
        self.base = base
        self.make_policy = make_policy

    def config(self, params: dict):
        from ..config import apply_overrides, config_from_dict

        overrides = {k: v for k, v in params.items() if k != POLICY_KEY}
        return config_from_dict(apply_overrides(self.base, overrides))

    def validate_keys(self, keys: Iterable[str], example: dict) -> None:
        """Unknown keys raise ``ValueError`` naming the key (apply_overrides' validation)."""
        from ..config import apply_overrides

        apply_overrides(self.base, {k: example[k] for k in keys if k != POLICY_KEY})

    def __call__(self, params: dict) -> dict:
        from ..config import policy_context
        from ..world.runner import run_mission

        cfg = self.config(params)
        policy = self.make_policy(params.get(POLICY_KEY, "model_based"), policy_context(cfg))
        return dict(run_mission(cfg, policy).summary)


def _import_factory(spec: str):
    mod, _, attr = spec.partition(":")
    try:
        obj = importlib.import_module(mod)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"[study] runner = {spec!r} cannot be imported ({exc})") from None
    return obj


def prepare_study(study: Study, make_policy: Callable | None = None, policy_names: Iterable[str] | None = None):
    """Runner, cases and base fingerprint of a study, validated before anything runs.

    The mission runner needs ``make_policy``; a study with ``[study] runner = "mod:factory"`` uses
    ``factory(study)`` instead (any picklable ``run_case``). Unknown parameter keys and unknown
    policy names raise ``ValueError`` naming the bad one and the valid ones.
    """
    import hashlib

    if study.runner:
        runner = _import_factory(study.runner)(study)
        base_text = study.base_path.read_text() if study.base_path else ""
        fingerprint = hashlib.sha256(f"{study.runner}\n{base_text}".encode()).hexdigest()[:16]
    else:
        from ..config import config_to_dict, load_config

        if make_policy is None:
            raise ValueError("the mission runner needs a policy factory (make_policy=policies.make)")
        base = config_to_dict(load_config(study.base_path))
        runner = MissionCaseRunner(base, make_policy)
        fingerprint = hashlib.sha256(canonical_json(base).encode()).hexdigest()[:16]
    cases = expand_cases(study, fingerprint)
    validate = getattr(runner, "validate_keys", None)
    if validate is not None and cases:
        validate(study.override_keys, cases[0].params)
    if policy_names is not None:
        valid = set(policy_names)
        bad = sorted({str(c.params.get(POLICY_KEY)) for c in cases} - valid)
        if bad:
            raise ValueError(f"policy={bad[0]!r} is invalid; valid values: {', '.join(sorted(valid))}")
    return runner, cases, fingerprint
