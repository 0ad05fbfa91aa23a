"""Streaming a mission's rows: the summary on the fly and the time series to Parquet in row groups.

The mission loop (:class:`~.loop.MissionLoop`, Python or compiled) hands its rows over in blocks
(``(n, 26)`` arrays in :data:`.loop._COLUMNS` order, at most :data:`BLOCK_ROWS` rows each) as it
produces them, so memory stays bounded whatever the mission's length:

* :class:`RowStats` keeps what the summary needs (exact energy sums, SoC extremes, the charge
  time, the highest battery voltage with the pad on);
* :class:`SeriesWriter` converts each block to the time-series columns and appends it as a row
  group to ``timeseries.parquet`` (:class:`pyarrow.parquet.ParquetWriter`, zstd with byte-stream
  split floats) and, when asked, to ``timeseries.csv`` (:class:`pyarrow.csv.CSVWriter`); with
  ``every_s`` only the first row of every ``every_s`` seconds (and the last row) is stored. Files
  are written under temporary names and renamed by :meth:`SeriesWriter.close` (nothing half-written
  under a final name; :meth:`SeriesWriter.abort` removes them);
* :class:`ThinnedSeries` keeps a bounded, thinned copy of the stored rows for figures (strided rows
  and the rows around the largest ``|I2|``), so nothing reads the file back.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

__all__ = ["RowStats", "SeriesWriter", "ThinnedSeries", "BLOCK_ROWS", "FIGURE_COLUMNS", "read_series"]

#: rows per block handed over by the loop (and per Parquet row group): ~3.4 MB of float64 rows (the
#: block-sized temporaries of the summary, edge losses and the writer are part of a run's fixed peak)
BLOCK_ROWS = 1 << 14
_ENERGY_COLS = ("e_source_j", "e_coil_loss_j", "e_rectifier_j", "e_battery_chem_j", "e_battery_r0_j",
                "e_battery_r1_j", "e_battery_c1_j", "e_propulsion_j", "e_inverter_switches_j",
                "e_rectifier_diodes_j", "e_rectifier_switches_j")


class RowStats:
    """The summary's running quantities over the blocks of rows (``columns`` = the loop's column names).

    Sums are exact to rounding: each is carried as ``math.fsum`` of the previous sum and the block. (The
    instantaneous peak is tracked by the compiled loop itself, :mod:`.loop_kernel`; nothing here grows
    with the number of rows.)"""

    def __init__(self, columns, initial_soc: float):
        self.col = {name: j for j, name in enumerate(columns)}
        self.sums = dict.fromkeys((*_ENERGY_COLS, "charge_in_j", "charge_time_s"), 0.0)
        self.min_soc = self.max_soc = float(initial_soc)
        self.vl_on_max = -math.inf
        self.n_rows = 0
        self.t_split, self.sums_after = None, 0.0
        self.straddle = None   # (start, end) [s] of the step holding t_split inside it (a merged quiet-flight step)

    def split_at(self, t_s: float) -> None:
        """Also sum the propulsion energy of the steps starting at or after ``t_s`` [s] (:attr:`sums_after`) and
        keep the bounds of the step holding ``t_s`` inside it (:attr:`straddle`: its share after ``t_s`` is the
        caller's to add, from the samples)."""
        self.t_split = float(t_s)

    def add(self, arr: np.ndarray) -> None:
        """Take one block ``arr`` (n, 26)."""
        if not len(arr):
            return
        c, s = self.col, self.sums
        for name in _ENERGY_COLS:
            s[name] = math.fsum([s[name], *arr[:, c[name]].tolist()])
        dt, vl, ib = arr[:, c["dt_s"]], arr[:, c["battery_v"]], arr[:, c["battery_current_a"]]
        s["charge_in_j"] = math.fsum([s["charge_in_j"], *(vl * np.maximum(ib, 0.0) * dt).tolist()])
        on = arr[:, c["v1_v"]] > 0
        s["charge_time_s"] = math.fsum([s["charge_time_s"], float(np.sum(dt[on]))])
        soc = arr[:, c["soc"]]
        self.min_soc, self.max_soc = min(self.min_soc, float(soc.min())), max(self.max_soc, float(soc.max()))
        self.n_rows += len(arr)
        if self.t_split is not None:
            end = arr[:, c["t_s"]]   # (a row's t_s is its step's end)
            late = end - dt >= self.t_split - 1e-9
            self.sums_after = math.fsum([self.sums_after, *arr[late, c["e_propulsion_j"]].tolist()])
            across = np.flatnonzero(~late & (end > self.t_split + 1e-9))
            if len(across):
                self.straddle = (float(end[across[0]] - dt[across[0]]), float(end[across[0]]))
        if on.any():
            self.vl_on_max = max(self.vl_on_max, float(vl[on].max()))

def _derived(loop, arr: np.ndarray) -> dict:
    """The time-series columns of one block (:meth:`~.loop.MissionLoop.timeseries`'s layout) as numpy arrays."""
    columns = loop.columns
    col = {name: arr[:, j] for j, name in enumerate(columns)}
    ri = col.pop("_row").astype(np.int64)
    pos, phase = loop.samples.pose(ri)
    out = {"t_s": col["t_s"], "dt_s": col["dt_s"], "x_m": pos[:, 0], "y_m": pos[:, 1], "z_m": pos[:, 2],
           "lm_h": col["lm_h"], "k": col["lm_h"] * loop.inv_sqrt_l1l2, "tx_on": col["v1_v"] > 0}
    for name in columns[4:]:
        out[name] = col[name].astype(bool) if name == "fine" else col[name]
    dts = col["dt_s"]
    out["propulsion_w"] = col["e_propulsion_j"] / dts
    if loop.cfg.drone.payload_kg > 0:   # (as MissionLoop.timeseries: the mass each row flew)
        out["mass_kg"] = loop.samples.row_mass_kg(ri, col["t_s"], dts)
    out["p_source_w"] = col["e_source_j"] / dts
    out["p_coil_loss_w"] = col["e_coil_loss_j"] / dts
    out["p_battery_loss_w"] = (col["e_battery_r0_j"] + col["e_battery_r1_j"]) / dts
    out["phase"] = (phase, slice(None))   # names per row (see _arrow)
    return out


def _arrow(columns: dict):
    """A ``pyarrow.Table`` of the block's columns, built from the numpy buffers directly (``pa.array``
    of a numpy array imports pandas, ~70 MB and ~0.5 s, for nothing here)."""
    import pyarrow as pa
    arrays = []
    for name, x in columns.items():
        if name == "phase":
            phases, ri = x
            names, codes = np.unique(phases[ri].astype(str), return_inverse=True)
            enc = [str(v).encode() for v in names]
            offsets = np.zeros(len(codes) + 1, dtype=np.int32)
            np.cumsum(np.array([len(e) for e in enc], dtype=np.int32)[codes], out=offsets[1:])
            data = b"".join(enc[c] for c in codes.tolist())
            arrays.append(pa.Array.from_buffers(pa.string(), len(codes), [None, pa.py_buffer(offsets),
                                                                           pa.py_buffer(data)]))
        elif x.dtype == bool:
            arrays.append(pa.Array.from_buffers(pa.bool_(), len(x), [None, pa.py_buffer(
                np.packbits(x, bitorder="little"))]))
        else:
            arrays.append(pa.Array.from_buffers(pa.float64(), len(x), [None, pa.py_buffer(
                np.ascontiguousarray(x, dtype=np.float64))]))
    return pa.Table.from_arrays(arrays, names=list(columns))


#: the time-series columns the mission figures draw (:mod:`mission_sim.figures.mission`)
FIGURE_COLUMNS = ("t_s", "x_m", "y_m", "z_m", "lm_h", "tx_on", "i2_amp_a", "fine", "d_short", "soc", "battery_v",
                  "battery_current_a", "rect_current_a", "propulsion_w", "p_source_w", "p_coil_loss_w")


def _cat(parts: list, n: int | None = None) -> dict:
    """Column-wise concatenation of column dicts (the last ``n`` rows with ``n``)."""
    out = {c: np.concatenate([p[c] for p in parts]) for c in parts[0]}
    return out if n is None else {c: v[max(len(v) - n, 0):] for c, v in out.items()}


class ThinnedSeries:
    """A bounded copy of the stored series for figures, kept as the rows are written: the rows at an
    even stride (doubled whenever more than ``2 max_points`` are kept, so between ``max_points`` and
    twice that many) and the ``half_window`` rows either side of the largest ``|I2|`` whole (the
    zoomed transient), as :func:`read_series` thins the file with ``max_points``, without reading
    it back (:class:`SeriesWriter` with ``figure_points``). Memory: ~``2 max_points + 4 half_window`` rows of :data:`FIGURE_COLUMNS`."""

    def __init__(self, max_points: int = 20_000, half_window: int = 2000):
        self.max_points, self.half = int(max_points), int(half_window)
        self.stride, self.n_seen = 1, 0
        self.kept = []                  # column dicts of strided rows
        self.recent = None              # the last ``half`` rows
        self.best, self.window, self.need_after = -math.inf, None, 0

    def add(self, cols: dict) -> None:
        """Take the columns (numpy arrays) of one block of stored rows."""
        block = {c: np.asarray(cols[c]) for c in FIGURE_COLUMNS}
        n = len(block["t_s"])
        if not n:
            return
        idx = np.arange(self.n_seen, self.n_seen + n)
        self.kept.append({c: v[idx % self.stride == 0] for c, v in block.items()})
        self.n_seen += n
        while sum(len(k["t_s"]) for k in self.kept) > 2 * self.max_points:
            self._halve()
        self._track_peak(block)

    def _halve(self) -> None:
        kept = _cat(self.kept)
        keep = np.arange(len(kept["t_s"])) % 2 == 0   # stride 2s: every other row kept so far (a multiple of s)
        self.kept, self.stride = [{c: v[keep] for c, v in kept.items()}], 2 * self.stride

    def _track_peak(self, block: dict) -> None:
        """The rows around the largest |I2| seen: taken from the last rows and this block, completed
        from the next blocks while fewer than ``half`` rows follow it."""
        if self.window is not None and self.need_after > 0:
            take = {c: v[:self.need_after] for c, v in block.items()}
            self.window = _cat([self.window, take])
            self.need_after -= len(take["t_s"])
        ext = _cat([self.recent, block]) if self.recent is not None else block
        i2 = np.abs(block["i2_amp_a"])
        j = int(np.argmax(i2))
        if i2[j] > self.best:
            jj = len(ext["t_s"]) - len(i2) + j
            lo, hi = max(jj - self.half, 0), min(jj + self.half, len(ext["t_s"]))
            self.best, self.window = float(i2[j]), {c: v[lo:hi] for c, v in ext.items()}
            self.need_after = jj + self.half - hi
        self.recent = _cat([ext], self.half)

    def frame(self, pandas: bool = True):
        """A DataFrame of the kept rows in time order (``phase`` not included); ``pandas=False``: a dict of
        numpy columns (the figures', without importing pandas)."""
        rows = _cat(self.kept) if self.kept else {c: np.empty(0) for c in FIGURE_COLUMNS}
        if self.stride > 1 and self.window is not None and len(self.window["t_s"]):
            tw = self.window["t_s"]
            keep = (rows["t_s"] < tw[0]) | (rows["t_s"] > tw[-1])
            rows = _cat([{c: v[keep] for c, v in rows.items()}, self.window])
            order = np.argsort(rows["t_s"], kind="stable")
            rows = {c: v[order] for c, v in rows.items()}
        if not pandas:
            return rows
        import pandas as pd
        return pd.DataFrame(rows)


class SeriesWriter:
    """Appends blocks of rows to ``out_dir/timeseries.parquet`` (and ``timeseries.csv`` with ``csv``).

    ``every_s`` > 0 thins the stored series: a row is kept when it is the first to end in a new
    ``every_s`` interval of simulated time (plus the run's last row, kept by :meth:`close`); the
    summary is computed from every row regardless. ``figure_points``: also keep a
    :class:`ThinnedSeries` of about that many stored rows (:attr:`thinned`) for figures. Call :meth:`close` (renames the files into place;
    returns their paths) or :meth:`abort` (removes them)."""

    def __init__(self, out_dir, csv: bool = False, every_s: float = 0.0, figure_points: int | None = None):
        self.out = Path(out_dir)
        self.csv, self.every_s, self.figure_points = bool(csv), float(every_s), figure_points
        self.thinned = None if figure_points is None else ThinnedSeries(figure_points)
        self.paths = [self.out / "timeseries.parquet"] + ([self.out / "timeseries.csv"] if csv else [])
        self.tmps = [p.with_name(f".{p.stem}.tmp{os.getpid()}{p.suffix}") for p in self.paths]
        self._pq = self._csv = None
        self._last_bin = -math.inf
        self._held = None  # the last row not kept by the thinning (written at close if it is the run's last)
        self.rows_written = 0

    def __call__(self, loop, arr: np.ndarray) -> None:
        if not len(arr):
            return
        if self.every_s > 0:
            t = arr[:, 0]
            bins = np.floor(t / self.every_s)
            keep = np.r_[bins[0] > self._last_bin, bins[1:] > bins[:-1]]
            self._last_bin = max(self._last_bin, float(bins[-1]))
            self._held = None if keep[-1] else (loop, arr[-1:].copy())
            arr = arr[keep]
        if len(arr):
            self._write(loop, arr)

    def _write(self, loop, arr) -> None:
        import pyarrow as pa
        cols = _derived(loop, arr)
        if self.thinned is not None:
            self.thinned.add(cols)
        table = _arrow(cols)
        if self._pq is None:
            import pyarrow.parquet as pq
            self.out.mkdir(parents=True, exist_ok=True)
            floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
            self._pq = _named(self.paths[0], pq.ParquetWriter, self.tmps[0], table.schema, compression="zstd",
                              use_dictionary=["phase"], use_byte_stream_split=floats)
            if self.csv:
                from pyarrow import csv as pacsv
                self._csv = _named(self.paths[1], pacsv.CSVWriter, str(self.tmps[1]), table.schema)
        _named(self.paths[0], self._pq.write_table, table, row_group_size=BLOCK_ROWS)
        if self._csv is not None:
            _named(self.paths[1], self._csv.write_table, table)
        self.rows_written += len(arr)

    def close(self) -> list[Path]:
        """Write the held last row, close the writers and rename the files into place; their paths."""
        if self._held is not None:
            self._write(*self._held)
        for w, path in zip((self._pq, self._csv), self.paths + [None]):
            if w is not None:
                _named(path, w.close)
        if self._pq is None:
            return []
        for tmp, path in zip(self.tmps, self.paths):
            os.replace(tmp, path)
        return list(self.paths)

    def restart(self) -> None:
        """Discard what was written and start again (the loop reruns the reference path from the start)."""
        self.abort()
        self.__init__(self.out, self.csv, self.every_s, self.figure_points)

    def abort(self) -> None:
        """Close and remove the temporary files (an interrupted or failed run)."""
        for w in (self._pq, self._csv):
            if w is not None:
                try:
                    w.close()
                except Exception:  # noqa: BLE001 - the files are removed anyway
                    pass
        for tmp in self.tmps:
            tmp.unlink(missing_ok=True)


def _named(path, fn, *args, **kwargs):
    """``fn(*args, **kwargs)``; a storage error (disk full, file-size limit, ...) becomes an
    :class:`~mission_sim.files.OutputError` naming the output ``path`` (exit status 4 in the CLI)."""
    try:
        return fn(*args, **kwargs)
    except OSError as exc:
        from ..files import storage_error
        named = storage_error(exc, path)
        if named is None:
            raise
        raise named from None


def read_series(path, columns=None, max_points: int | None = None, keep_peak_of: str | None = "i2_amp_a",
                frame: bool = True):
    """A DataFrame of ``columns`` from a ``timeseries.parquet``, read one row group at a time
    (``frame=False``: a dict of numpy arrays, without importing pandas, ~0.2-0.5 s; the figures').

    With ``max_points`` the rows are thinned to about that many by an even stride (figures need no
    10^7 points), except the ``+-2,000`` rows around the largest ``|keep_peak_of|`` (the transient a
    zoomed figure shows), which are kept whole. Memory: one row group plus the kept rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    f = pq.ParquetFile(path)
    n = f.metadata.num_rows
    stride = 1 if max_points is None or n <= max_points else math.ceil(n / max_points)
    if stride == 1:
        table = f.read(columns=columns)
    else:
        parts, best, offset = [], (-math.inf, None), 0
        for batch in f.iter_batches(batch_size=BLOCK_ROWS, columns=columns):
            idx = np.arange((-offset) % stride, batch.num_rows, stride)
            parts.append(batch.take(pa.array(idx)))
            if keep_peak_of is not None and keep_peak_of in batch.schema.names:
                y = np.abs(batch.column(keep_peak_of).to_numpy(zero_copy_only=False))
                j = int(np.argmax(y)) if len(y) else 0
                if len(y) and y[j] > best[0]:
                    lo, hi = max(j - 2000, 0), min(j + 2000, batch.num_rows)
                    best = (float(y[j]), batch.slice(lo, hi - lo), offset + lo)
            offset += batch.num_rows
        table = pa.Table.from_batches(parts)
        if best[1] is not None:   # the peak's window replaces the strided rows there
            t = table.column("t_s").to_numpy() if "t_s" in table.column_names else None
            if t is not None:
                win = best[1]
                tw = win.column(win.schema.get_field_index("t_s")).to_numpy()
                keep = (t < tw[0]) | (t > tw[-1])
                table = pa.concat_tables([table.filter(pa.array(keep)), pa.Table.from_batches([win])])
                table = table.sort_by("t_s")
    if not frame:
        return {name: _numpy_column(table.column(name)) for name in table.column_names}
    df = table.to_pandas()
    if "phase" in df:
        df["phase"] = df["phase"].astype("category")
    return df


def _numpy_column(col) -> np.ndarray:
    """A pyarrow ``ChunkedArray`` as a numpy array without pyarrow's ``to_numpy`` (which imports pandas,
    ~0.2-0.5 s): null-free float/integer chunks viewed from their value buffer, booleans unpacked from
    their bitmap (the Arrow columnar format: LSB first, from the chunk's offset), anything else
    (strings) through ``to_pylist`` as objects."""
    import pyarrow as pa
    fixed = {pa.float64(): np.float64, pa.float32(): np.float32, pa.int64(): np.int64, pa.int32(): np.int32,
             pa.int16(): np.int16, pa.int8(): np.int8, pa.uint8(): np.uint8}
    parts = []
    for ch in col.chunks:
        n, off, buf = len(ch), ch.offset, ch.buffers()
        if ch.null_count == 0 and ch.type in fixed:
            dt = np.dtype(fixed[ch.type])
            parts.append(np.frombuffer(buf[1], dtype=dt, count=n, offset=off * dt.itemsize) if n else np.empty(0, dt))
        elif ch.null_count == 0 and pa.types.is_boolean(ch.type):
            bits = np.unpackbits(np.frombuffer(buf[1], dtype=np.uint8), bitorder="little") if n else np.empty(0, np.uint8)
            parts.append(bits[off:off + n].astype(bool))
        else:
            parts.append(np.array(ch.to_pylist(), dtype=object))
    if not parts:
        return np.empty(0)
    return np.concatenate(parts) if len(parts) > 1 else parts[0].copy()
