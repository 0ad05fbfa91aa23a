"""The sweep's result store: Parquet files under ``OUT/cases/``, written in parts, merged as it grows.

Parts
    :class:`PartWriter` buffers finished cases and writes them as one Parquet *part* every
    ``max_rows`` rows or ``max_age_s`` seconds (default 1,000 rows / 2 s), so a study of 10^5 cases
    makes ~100 parts, not 10^5. A file is written to a temporary name and renamed into place
    (``os.replace``, atomic): a file is either complete or absent, and *the files are the
    bookkeeping* (no separate index to get out of step). A killed sweep loses only the rows still
    in the buffer (at most ``max_age_s`` of work) and the cases running.

Merges (incremental compaction)
    Whenever :data:`FANOUT` files share a level, they are merged into one file of the next level
    (level 0 = parts), so the number of files stays logarithmic in the number of rows and every row
    is rewritten only ~log_FANOUT(n / max_rows) times. A merged file names the files it absorbs in
    its Parquet metadata; absorbed files are ignored by readers and deleted after the merge, so a
    kill at any point of a merge never duplicates or loses a row. :meth:`CaseStore.compact` (end of
    a run) merges the few remaining files into one.

Rows and retries
    One row per case: ``case_id, attempt, status ("ok" | "error"), error, traceback, case_wall_s,
    case_cpu_s`` (the case's CPU time on its worker thread), ``worker, params_json``, the
    parameters and the metrics. ``attempt`` counts runs of the case (``--retry-errors`` re-runs an
    error row with ``attempt + 1``); readers keep the row with the highest attempt per case_id,
    merges drop the superseded ones.

Only one sweep writes a store at a time (an ``flock`` on ``OUT/.sweep.lock``); readers
(``--status``) need no lock.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
import uuid
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from ..files import atomic_output, folder_lock

__all__ = ["CaseStore", "PartWriter", "StoreState", "read_results", "BOOKKEEPING_COLUMNS", "FANOUT", "BATCH_ROWS"]

BOOKKEEPING_COLUMNS = ("case_id", "attempt", "status", "error", "traceback", "case_wall_s", "case_cpu_s", "worker",
                       "params_json")
FANOUT = 8
BATCH_ROWS = 8192  # rows per batch of a streamed merge (its memory bound)
_ABSORBS_KEY = b"dronewpt.absorbs"
_TOP_LEVEL = 99


class StoreState:
    """What the store holds, per case (latest attempt): the done ids and the error ids with their attempt."""

    def __init__(self, ids: np.ndarray, attempts: np.ndarray, is_error: np.ndarray):
        self.done = set(ids.tolist())
        self.errors = dict(zip(ids[is_error].tolist(), attempts[is_error].tolist()))

    @property
    def n_done(self) -> int:
        return len(self.done)

    @property
    def n_error(self) -> int:
        return len(self.errors)


class CaseStore:
    """Parquet files under ``out_dir/cases`` (see the module docstring)."""

    def __init__(self, out_dir):
        self.out_dir = Path(out_dir)
        self.dir = self.out_dir / "cases"

    # -- files
    def _all_files(self) -> list[Path]:
        if not self.dir.is_dir():
            return []
        return sorted(p for p in self.dir.iterdir() if p.suffix == ".parquet" and not p.name.startswith("."))

    @staticmethod
    def _absorbed(files: Iterable[Path]) -> set[str]:
        gone = set()
        for p in files:
            if p.name.startswith("compact-"):
                with contextlib.suppress(FileNotFoundError):  # a concurrent merge deleted it
                    meta = pq.read_schema(p).metadata or {}
                    gone.update(json.loads(meta.get(_ABSORBS_KEY, b"[]")))
        return gone

    def files(self) -> list[Path]:
        """The live files (absorbed files and temporaries excluded)."""
        files = self._all_files()
        gone = self._absorbed(files)
        return [p for p in files if p.name not in gone]

    @staticmethod
    def level(path: Path) -> int:
        """0 for a part, the merge level for ``compact-L<level>-...``, top level for a full compaction."""
        name = path.name
        if name.startswith("compact-L") and name[9:11].isdigit():
            return int(name[9:11])
        return _TOP_LEVEL if name.startswith("compact-") else 0

    # -- read
    def _tables(self, columns=None) -> list[pa.Table]:
        for _ in range(5):  # a concurrent writer may merge (delete) a file between listing and reading
            try:
                out = []
                for p in self.files():
                    cols = None if columns is None else [c for c in columns if c in pq.read_schema(p).names]
                    out.append(pq.read_table(p, columns=cols))
                return out
            except FileNotFoundError:
                time.sleep(0.05)
        raise OSError(f"the store {str(self.dir)!r} kept changing while being read; try again")

    def state(self) -> StoreState:
        """Done and error case_ids (latest attempt per case) from three columns of every live file."""
        tables = [t for t in self._tables(["case_id", "attempt", "status"]) if t.num_rows]
        if not tables:
            return StoreState(np.array([], dtype=object), np.array([], dtype=np.int64), np.array([], dtype=bool))
        df = _latest(pd.concat([_with_attempt(t.to_pandas()) for t in tables], ignore_index=True))
        return StoreState(df["case_id"].to_numpy(object), df["attempt"].to_numpy(np.int64),
                          (df["status"] == "error").to_numpy())

    def done_ids(self) -> set[str]:
        """case_ids present in the store (finished cases, ``ok`` or ``error``)."""
        return self.state().done

    def read(self, columns=None) -> pd.DataFrame:
        """All rows, one per case_id (the latest attempt)."""
        tables = [t for t in self._tables(columns) if t.num_rows]
        if not tables:
            return pd.DataFrame(columns=list(columns or BOOKKEEPING_COLUMNS))
        return _latest(_with_attempt(_concat(tables).to_pandas()))

    # -- write
    def _publish(self, name: str, write: Callable[[Path], None]) -> Path:
        """``write(tmp)`` a file under a temporary name, fsync it, rename it to ``name`` (atomic)."""
        self.dir.mkdir(parents=True, exist_ok=True)
        final = self.dir / name
        with atomic_output(final, tmp_name=f".{name}.{os.getpid()}.tmp", fsync=True) as tmp:  # removed on failure
            write(tmp)
        return final

    def _write_table(self, table: pa.Table, name: str) -> Path:
        return self._publish(name, lambda tmp: pq.write_table(table, tmp))

    def write(self, rows: Sequence[dict]) -> Path | None:
        """Write finished cases as one new part file (atomically). Returns its path."""
        if not rows:
            return None
        return self._write_table(_rows_to_table(rows), f"part-{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet")

    def cleanup(self) -> None:
        """Delete what readers already ignore: absorbed files and temporaries of a killed writer."""
        every = self._all_files()
        gone = self._absorbed(every)
        for p in every:
            if p.name in gone:
                p.unlink(missing_ok=True)
        if self.dir.is_dir():
            for p in self.dir.iterdir():
                if p.name.startswith(".") and p.name.endswith(".tmp"):
                    p.unlink(missing_ok=True)

    def merge(self, inputs: Sequence[Path], level: int, on_read: Callable[[int], None] | None = None) -> Path:
        """Merge ``inputs`` into one file of ``level`` (superseded attempts dropped); inputs deleted after.

        Streamed batch by batch (memory bounded by :data:`BATCH_ROWS`, whatever the files' sizes); in
        memory only if the files' column types cannot be unified (text in one, numbers in another).
        ``on_read(n_rows)`` is called as rows are read (progress).
        """
        # the files the inputs absorbed are named too while they exist (a killed merge leaves them until
        # cleanup), so they cannot come back to life when their absorbing input is deleted
        names = sorted({p.name for p in inputs} | {n for n in self._absorbed(inputs) if (self.dir / n).exists()})
        meta = {_ABSORBS_KEY: json.dumps(names).encode()}
        tag = f"L{level:02d}-" if level < _TOP_LEVEL else ""
        name = f"compact-{tag}{time.time_ns():020d}-{uuid.uuid4().hex[:8]}.parquet"
        on_read = on_read or (lambda n: None)
        try:
            out = self._publish(name, lambda tmp: _stream_merge(inputs, tmp, meta, on_read))
        except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
            tables = [pq.read_table(p) for p in inputs]
            table = _dedupe(_concat(tables))
            out = self._write_table(table.replace_schema_metadata({**(table.schema.metadata or {}), **meta}), name)
        for n in names:
            (self.dir / n).unlink(missing_ok=True)
        return out

    def merge_levels(self) -> int:
        """Merge every level holding :data:`FANOUT` files or more; returns the number of merges."""
        n = 0
        while True:
            by_level: dict[int, list[Path]] = {}
            for p in self.files():
                by_level.setdefault(self.level(p), []).append(p)
            full = sorted(lv for lv, ps in by_level.items() if len(ps) >= FANOUT and lv < _TOP_LEVEL - 1)
            if not full:
                return n
            self.merge(by_level[full[0]], full[0] + 1)
            n += 1

    def compact(self, progress: bool = False) -> Path | None:
        """Merge all live files into one (safe to kill at any point); a tqdm bar over the rows read."""
        from tqdm.auto import tqdm

        self.cleanup()
        live = self.files()
        if len(live) <= 1:
            return live[0] if live else None
        total = sum(pq.ParquetFile(p).metadata.num_rows for p in live)
        with tqdm(total=total, unit="row", desc="compact", disable=not progress, dynamic_ncols=True,
                  leave=False) as bar:
            return self.merge(live, _TOP_LEVEL, on_read=bar.update)

    @contextlib.contextmanager
    def lock(self):
        """Exclusive writer lock for this store (released when the process ends, even if killed; the
        lock file ``.sweep.lock`` is removed when the sweep ends)."""
        with folder_lock(self.out_dir, ".sweep.lock", f"another sweep is writing to {str(self.out_dir)!r}; "
                         "wait for it or use another --out"):
            yield self


class PartWriter:
    """Buffer of finished rows, written as one part every ``max_rows`` rows or ``max_age_s`` seconds,
    with the store's merges run after each part (``flush()`` writes what is buffered now)."""

    def __init__(self, store: CaseStore, max_rows: int = 1000, max_age_s: float = 2.0):
        self.store, self.max_rows, self.max_age_s = store, max_rows, max_age_s
        self.rows: list[dict] = []
        self.t_first = 0.0
        self.n_parts = self.n_rows = self.n_error_rows = 0

    def add(self, rows: Iterable[dict]) -> None:
        if not self.rows:
            self.t_first = time.monotonic()
        n = len(self.rows)
        self.rows.extend(rows)
        self.n_rows += len(self.rows) - n
        self.n_error_rows += sum(r.get("status") == "error" for r in self.rows[n:])
        self.maybe_flush()

    def maybe_flush(self) -> None:
        if self.rows and (len(self.rows) >= self.max_rows or time.monotonic() - self.t_first >= self.max_age_s):
            self.flush()

    def flush(self) -> None:
        if not self.rows:
            return
        rows, self.rows = self.rows, []
        self.store.write(rows)
        self.n_parts += 1
        self.store.merge_levels()


# ----------------------------------------------------------------------------- streamed merge
def _keep_masks(files: Sequence[pq.ParquetFile]) -> list | None:
    """Per file, the rows to keep (latest attempt per case_id), or None if every case_id is distinct."""
    ids = [f.read(columns=["case_id"]).column(0) for f in files]
    total = sum(len(c) for c in ids)
    if total == 0 or pc.count_distinct(pa.chunked_array([c for col in ids for c in col.chunks],
                                                        type=pa.string())).as_py() == total:
        return None
    frames = []
    for i, (f, col) in enumerate(zip(files, ids)):
        att = f.read(columns=["attempt"]).column(0).to_numpy() if "attempt" in f.schema_arrow.names \
            else np.ones(len(col), dtype=np.int64)
        frames.append(pd.DataFrame({"file": i, "row": np.arange(len(col)), "case_id": col.to_pandas(),
                                    "attempt": pd.Series(att).fillna(1).astype(np.int64)}))
    df = pd.concat(frames, ignore_index=True)
    kept = _latest(df)
    return [np.isin(np.arange(len(col)), kept.loc[kept["file"] == i, "row"].to_numpy()) for i, col in enumerate(ids)]


def _conform(table: pa.Table, schema: pa.Schema) -> pa.Table:
    """``table`` with exactly ``schema``'s columns (missing ones null) and types (cast)."""
    cols = [table.column(f.name).cast(f.type) if f.name in table.column_names else pa.nulls(table.num_rows, f.type)
            for f in schema]
    return pa.Table.from_arrays(cols, schema=schema)


def _stream_merge(inputs: Sequence[Path], out: Path, meta: dict, on_read: Callable[[int], None]) -> None:
    """Write the rows of ``inputs`` (superseded attempts dropped) to ``out``, batch by batch."""
    files = [pq.ParquetFile(p) for p in inputs]
    schema = pa.unify_schemas([f.schema_arrow.remove_metadata() for f in files], promote_options="permissive")
    schema = schema.with_metadata(meta)
    keep = _keep_masks(files)
    with pq.ParquetWriter(out, schema) as writer:
        for i, f in enumerate(files):
            start = 0
            for batch in f.iter_batches(batch_size=BATCH_ROWS):
                table = _conform(pa.Table.from_batches([batch]), schema)
                if keep is not None:
                    table = table.filter(pa.array(keep[i][start:start + batch.num_rows]))
                start += batch.num_rows
                writer.write_table(table)
                on_read(batch.num_rows)


# ----------------------------------------------------------------------------- tables
def _with_attempt(df: pd.DataFrame) -> pd.DataFrame:
    """Stores written before ``attempt`` existed: every row is attempt 1."""
    if "attempt" not in df.columns:
        df["attempt"] = 1
    df["attempt"] = df["attempt"].fillna(1).astype(np.int64)
    return df


def _latest(df: pd.DataFrame) -> pd.DataFrame:
    """One row per case_id: the highest attempt (file order breaks ties: first kept)."""
    if df["case_id"].is_unique:
        return df.reset_index(drop=True)
    order = df.sort_values("attempt", ascending=False, kind="stable")
    keep = ~order["case_id"].duplicated(keep="first")
    return df.loc[order.index[keep.to_numpy()].sort_values()].reset_index(drop=True)


def _concat(tables: Sequence[pa.Table]) -> pa.Table:
    """Tables with different columns or types: nulls and int/float unified by Arrow, otherwise (a
    column that is text in one part and numbers in another) via pandas with the mixed column as text."""
    try:
        return pa.concat_tables(tables, promote_options="permissive")
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        frames = [t.to_pandas() for t in tables]
        return _frame_to_table(pd.concat(frames, ignore_index=True, sort=False))


def _dedupe(table: pa.Table) -> pa.Table:
    """Drop superseded attempts (rare: only after ``--retry-errors``)."""
    ids = table.column("case_id")
    if pc.count_distinct(ids).as_py() == table.num_rows:
        return table
    return _frame_to_table(_latest(_with_attempt(table.to_pandas())))


def _to_scalar(v):
    if isinstance(v, (np.generic,)):
        v = v.item()
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    return json.dumps(v, default=str)


def _is_missing(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _frame_to_table(df: pd.DataFrame) -> pa.Table:
    """DataFrame -> Arrow table; a column mixing strings and other values is stored as JSON text."""
    df = df.copy()
    for col in df.columns:
        if df[col].dtype == object:
            kinds = {type(v) for v in df[col] if not _is_missing(v)}
            if len(kinds) > 1 and str in kinds:
                df[col] = [None if _is_missing(v) else (v if isinstance(v, str) else json.dumps(v)) for v in df[col]]
    return pa.Table.from_pandas(df, preserve_index=False)


def _rows_to_table(rows: Sequence[dict]) -> pa.Table:
    """Rows (dicts of scalars; keys may differ between rows) -> Arrow table, column by column; a column
    mixing strings and other values is stored as JSON text, a missing value as null."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    arrays = []
    for k in keys:
        col = [r.get(k) for r in rows]
        try:
            arrays.append(pa.array(col, from_pandas=True))
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            col = [_to_scalar(v) for v in col]
            kinds = {type(v) for v in col if not _is_missing(v)}
            if str in kinds and len(kinds) > 1:
                col = [None if _is_missing(v) else (v if isinstance(v, str) else json.dumps(v)) for v in col]
            arrays.append(pa.array(col, from_pandas=True))
    return pa.Table.from_arrays(arrays, names=[str(k) for k in keys])


def read_results(out_dir) -> pd.DataFrame:
    """All rows of a sweep output folder, one per case (see :class:`CaseStore`)."""
    return CaseStore(out_dir).read()
