"""Mission results: the time series, the summary, and writing them (Parquet, CSV, JSON)."""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass, field
from pathlib import Path

from ..files import atomic_output

__all__ = ["MissionResult", "SUMMARY_KEYS", "TIMESERIES_COLUMNS", "NO_SERIES", "depletion_text"]

#: the error of writing (or drawing) a result without its time series
NO_SERIES = ("the result holds no time series (run_mission(..., frame=False)); valid: a result of run_mission(..., "
             "frame=True), or the rows streamed to a folder by run_mission(..., sink=SeriesWriter(folder)) and read "
             "back with mission_sim.world.stream.read_series")

SUMMARY_KEYS = ("sim_time_s", "wall_s", "energy_from_source_j", "rectifier_output_j", "battery_charge_in_j",
                "propulsion_energy_j", "losses_j", "device_losses_j", "dc_to_battery_efficiency",
                "energy_balance_error_rel", "final_soc", "peak_i2_a", "time_above_rated_s", "flight_time_gain_s")
TIMESERIES_COLUMNS = ("t_s", "x_m", "y_m", "z_m", "lm_h", "tx_on", "i1_amp_a", "i2_amp_a", "d_short", "v2_v",
                      "rect_current_a", "battery_v", "battery_current_a", "soc", "propulsion_w")


def depletion_text(s: dict) -> str:
    """One line on where the battery ran out (summary keys ``depleted_at_s``, ``depleted_pad_distance_m``,
    ``min_soc``): ``dronewpt mission``, ``replay`` and ``telemetry`` and the replay studies all word it here."""
    if s.get("depleted_at_s") is None:
        return f"battery depleted (min SoC {s['min_soc']:.3f})"
    return (f"battery depleted at t = {s['depleted_at_s']:.1f} s, {s['depleted_pad_distance_m']:.0f} m from the "
            f"nearest pad; the mission ended there")


@dataclass
class MissionResult:
    """Result of :func:`mission_sim.world.runner.run_mission`.

    timeseries : one row per simulation step (fine and coarse; ``dt_s`` is the step length, values
        are at the step's end, currents ``rect_current_a``/``battery_current_a`` and powers are step means;
        None only for the uncharged baseline run that ``run_mission`` keeps internally)
    summary : energies [J], SoC, peak I2, time above rated, flight-time gain, step counts, wall time
    """

    timeseries: "pandas.DataFrame | None"
    summary: dict
    config: object = None
    trajectory: object = None
    extra: dict = field(default_factory=dict)

    def write(self, out_dir, figures=None, progress: bool = False, csv: bool = False) -> list[Path]:
        """Write ``timeseries.parquet``, ``timeseries.csv`` (only with ``csv=True``, as ``dronewpt mission --csv``;
        the default until 2026-11-27 was True), the figures of ``figures(result, out_dir)``
        (if given, e.g. :func:`mission_sim.figures.mission.plot_mission`) and ``summary.json`` last.

        Every file is written under a temporary name and renamed when complete (removed on any failure:
        an exception, Ctrl-C, SIGTERM, a full disk), and a ``summary.json`` left by an earlier run is
        removed first, so ``summary.json`` is present exactly when the whole set of this run is
        complete. ``progress``: a tqdm bar over the files (the CSV, the long one, in row chunks).
        Returns the paths.
        """
        if self.timeseries is None:
            raise ValueError(NO_SERIES)
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "summary.json").unlink(missing_ok=True)
        ts = self.timeseries.copy()
        ts["phase"] = ts["phase"].astype(str)
        paths = [out / "timeseries.parquet"] + ([out / "timeseries.csv"] if csv else [])
        steps = 1 + csv + (figures is not None) + 1
        with _files_bar(steps, progress) as bar:
            bar.set_description_str(f"writing {paths[0].name}")
            with atomic_output(paths[0]) as tmp:
                ts.to_parquet(tmp, index=False)
            bar.update(1)
            if csv:
                bar.set_description_str(f"writing {paths[1].name}")
                with atomic_output(paths[1]) as tmp:
                    _write_csv(ts, tmp, bar.update)
            if figures is not None:
                bar.set_description_str("writing figures")
                paths.extend(Path(f) for f in figures(self, out))
                bar.update(1)
            paths.append(out / "summary.json")
            with atomic_output(paths[-1]) as tmp:
                tmp.write_text(json.dumps(self.summary, indent=2))
            bar.update(1)
        return paths


class _NoBar(contextlib.nullcontext):
    def __enter__(self):
        return self

    def update(self, n=1):
        pass

    def set_description_str(self, s=""):
        pass


def _files_bar(steps: int, progress: bool):
    """A tqdm bar over ``steps`` files (fractions allowed), or a no-op one (tqdm not even imported)."""
    if not progress:
        return _NoBar()
    from tqdm import tqdm
    return tqdm(total=steps, unit="file", desc="writing", leave=False, dynamic_ncols=True,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total} files [{elapsed}<{remaining}]")


#: rows per chunk of the CSV write (progress between chunks; the text is the same as one ``to_csv``)
CSV_CHUNK_ROWS = 50_000


def _write_csv(ts: pd.DataFrame, path, advance) -> None:
    """``ts.to_csv(path, index=False)`` in row chunks, calling ``advance(fraction)`` after each (the
    fractions add up to 1)."""
    n = len(ts)
    with open(path, "w", newline="") as fh:
        if n == 0:
            ts.to_csv(fh, index=False)
        for i in range(0, n, CSV_CHUNK_ROWS):
            part = ts.iloc[i:i + CSV_CHUNK_ROWS]
            part.to_csv(fh, index=False, header=i == 0)
            advance(len(part) / n)
    if n == 0:
        advance(1.0)
