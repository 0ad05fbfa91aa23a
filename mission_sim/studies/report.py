"""Sweep results at a glance: summary table (pandas) and PNG plots of the main trade-offs (Agg)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..figures.common import save_figure  # noqa: E402
import pandas as pd  # noqa: E402

from .study import POLICY_KEY, Study  # noqa: E402

__all__ = ["SUMMARY_METRICS", "summary_table", "error_table", "plot_sweep"]

#: metrics shown in the summary table when the runner reports them (mission summary keys; then the replay
#: runner's: re-flights with pads, replays' power comparison)
SUMMARY_METRICS = ("flight_time_gain_s", "peak_i2_a", "time_above_rated_s", "rectifier_output_j",
                   "battery_charge_in_j", "device_losses_j",
                   "energy_from_source_j", "final_soc", "energy_balance_error_rel",
                   "flight_time_gain_vs_refly_without_charging_s", "energy_from_pads_j", "final_soc_refly",
                   "min_soc_refly", "power_comparison.energy_error_rel", "power_comparison.equivalent_mass_kg")
#: further trade-off plots drawn when the rows have them (replay studies)
EXTRA_TRADEOFFS = ("flight_time_gain_vs_refly_without_charging_s", "power_comparison.energy_error_rel")


def _metric_columns(df: pd.DataFrame, study: Study) -> list[str]:
    params = set(study.parameter_keys)
    skip = {"case_id", "status", "error", "traceback", "worker", "params_json"} | params
    wanted = [m for m in SUMMARY_METRICS if m in df.columns]
    if wanted:
        return wanted
    return [c for c in df.columns if c not in skip and pd.api.types.is_numeric_dtype(df[c])][:6]


def summary_table(df: pd.DataFrame, study: Study) -> pd.DataFrame:
    """One row per policy (and ``all``): case counts (errors; missions that ended with the battery depleted, when
    the rows say) and the mean / max of the main metrics."""
    if df.empty:
        return pd.DataFrame()
    ok = df[df["status"] == "ok"]
    metrics = _metric_columns(df, study)
    key = POLICY_KEY if POLICY_KEY in df.columns else None
    groups = [("all", df, ok)]
    if key is not None and df[key].nunique() > 1:
        for p in sorted(df[key].astype(str).unique()):
            groups.append((p, df[df[key].astype(str) == p], ok[ok[key].astype(str) == p]))
    rows = []
    for name, d_all, d_ok in groups:
        row = {"group": name, "cases": len(d_all), "errors": int((d_all["status"] == "error").sum())}
        if "battery_depleted" in d_ok:   # (a mission's exit 3: counted, not folded silently into the means)
            row["battery depleted"] = int(d_ok["battery_depleted"].fillna(False).astype(bool).sum())
        for m in metrics:
            v = pd.to_numeric(d_ok[m], errors="coerce") if m in d_ok else pd.Series(dtype=float)
            row[f"{m} mean"] = float(v.mean()) if v.notna().any() else np.nan
            row[f"{m} max"] = float(v.max()) if v.notna().any() else np.nan
        rows.append(row)
    return pd.DataFrame(rows).set_index("group")


def error_table(df: pd.DataFrame, limit: int = 10) -> pd.DataFrame:
    """The failed cases (case_id, error, parameters as JSON), first ``limit``."""
    if df.empty:
        return pd.DataFrame(columns=["case_id", "error", "params_json"])
    err = df[df["status"] == "error"]
    return err[["case_id", "error", "params_json"]].head(limit).reset_index(drop=True)


def _numeric(s: pd.Series) -> bool:
    return pd.api.types.is_numeric_dtype(s) and s.nunique() > 1


def _axes(df: pd.DataFrame, study: Study) -> tuple[str | None, str | None]:
    varied = [k for k in study.varied_keys if k in df.columns and k != POLICY_KEY]
    x = study.report.get("x") or next((k for k in varied if _numeric(df[k])), None)
    hue = study.report.get("hue")
    if hue is None:
        policies = POLICY_KEY in df.columns and df[POLICY_KEY].nunique() > 1
        # a hue takes more than one value (a one-value [grid] axis is "varied" too; it became a one-line legend)
        others = [k for k in varied if k != x and df[k].nunique() > 1]
        if x in study.grid:
            # one line per hue value: another grid axis, else the policy; never a Monte Carlo parameter, whose every
            # draw became a line of its own (a legend of n random values; 2026-11-28, before: the first other varied key)
            hue = next((k for k in others if k in study.grid), None)
            if hue is None and policies:
                hue = POLICY_KEY
        else:   # x drawn at random: a scatter, coloured by another varied parameter
            hue = next(iter(others), None)
            if hue is None and policies:
                hue = POLICY_KEY
    return x, hue


def plot_sweep(df: pd.DataFrame, study: Study, out_dir, metric: str = "flight_time_gain_s") -> list[str]:
    """PNG plots of the trade-offs; returns the paths written.

    - ``tradeoff_<metric>.png``: ``metric`` against the x parameter (mean over the other parameters,
      one line per hue value; scatter when x is Monte Carlo), and a heat map over (x, hue) when both
      are grid parameters; the same for each of :data:`EXTRA_TRADEOFFS` the rows have (replay studies:
      the gain against the same detours unpowered, the energy error against the logged power).
    - ``peak_i2_by_policy.png``: peak secondary coil current (and time above rated) per policy.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ok = df[df["status"] == "ok"] if not df.empty else df
    paths = []
    if ok.empty:
        return paths
    x, hue = _axes(ok, study)
    for m in (metric, *EXTRA_TRADEOFFS):
        if m in ok.columns and x is not None:
            paths.append(_plot_tradeoff(ok, study, x, hue, m, out / f"tradeoff_{m}.png"))
    if "peak_i2_a" in ok.columns and POLICY_KEY in ok.columns:
        paths.append(_plot_by_policy(ok, out / "peak_i2_by_policy.png"))
    return paths


def _label(key: str) -> str:
    return {"policy": "policy"}.get(key, key)


def _consecutive(n: int) -> list[tuple[int, int]]:
    """Index pairs of neighbouring ticks of a sorted axis."""
    return [(i, i + 1) for i in range(n - 1)]


def _adjacent_cells(rows: int, cols: int) -> list[tuple[int, int]]:
    """Index pairs (into the row-major cells) of a heat map's horizontally and vertically adjacent cells."""
    idx = np.arange(rows * cols).reshape(rows, cols)
    return [*zip(idx[:, :-1].ravel(), idx[:, 1:].ravel()), *zip(idx[:-1, :].ravel(), idx[1:, :].ravel())]


def _distinct_labels(values, pairs, min_sig: int, max_sig: int) -> list[str]:
    """``values`` as text, floats with one number of significant figures for all: the fewest in
    [``min_sig``, ``max_sig``] at which each pair (indices into ``values``: neighbouring ticks, adjacent cells) of
    different values prints differently (2026-11-28: the cells' fixed 3 figures printed 12.341 and 12.344 both as
    '12.3'). ``max_sig`` bounds the digits, so float noise (0.1 + 0.2) never shows; other values as ``str``."""
    def text(v, n):
        return f"{v:.{n}g}" if isinstance(v, float) else str(v)
    differ = [(a, b) for a, b in pairs if isinstance(values[a], float) and isinstance(values[b], float)
              and np.isfinite(values[a]) and np.isfinite(values[b]) and values[a] != values[b]]
    n = next((n for n in range(min_sig, max_sig) if all(text(values[a], n) != text(values[b], n) for a, b in differ)),
             max_sig)
    return [text(v, n) for v in values]


def _plot_tradeoff(df, study, x, hue, metric, path) -> str:
    both_grid = hue is not None and x in study.grid and hue in study.grid and len(study.grid[hue]) > 1 \
        and len(study.grid[x]) > 1
    fig, axes = plt.subplots(1, 2 if both_grid else 1, figsize=(11 if both_grid else 6, 4.2), squeeze=False)
    ax = axes[0, 0]
    y = pd.to_numeric(df[metric], errors="coerce")
    if x in study.grid:
        groups = [(None, df)] if hue is None else list(df.groupby(hue, sort=True))
        cmap = plt.get_cmap("viridis")
        for i, (h, d) in enumerate(groups):
            g = d.assign(_y=pd.to_numeric(d[metric], errors="coerce")).groupby(x)["_y"]
            mean, lo, hi = g.mean(), g.min(), g.max()
            color = cmap(i / max(len(groups) - 1, 1))
            label = None if h is None else f"{_label(hue)} = {h:.6g}" if isinstance(h, float) else f"{_label(hue)} = {h}"
            ax.plot(mean.index, mean.values, "o-", color=color, label=label)
            if (hi - lo).abs().max() > 0:
                ax.fill_between(mean.index, lo.values, hi.values, color=color, alpha=0.15, lw=0)
        if hue is not None:
            ax.legend(fontsize=8)
        ax.set_title("mean (line) and range (band) over the other parameters", fontsize=9)  # the metric: suptitle
    else:
        c = pd.to_numeric(df[hue], errors="coerce") if hue is not None and _numeric(df[hue]) else None
        sc = ax.scatter(df[x], y, c=c, s=14, cmap="viridis")
        if c is not None:
            fig.colorbar(sc, ax=ax, label=hue)
        ax.set_title(f"{metric} per case", fontsize=9)
    ax.set_xlabel(x)
    ax.set_ylabel(metric)
    ax.grid(alpha=0.3)
    if both_grid:
        ax = axes[0, 1]
        piv = df.assign(_y=y).pivot_table(index=hue, columns=x, values="_y", aggfunc="mean")
        im = ax.imshow(piv.values, origin="lower", aspect="auto", cmap="viridis")
        ax.set_xticks(range(piv.shape[1]), _distinct_labels(list(piv.columns), _consecutive(piv.shape[1]), 6, 12))
        ax.set_yticks(range(piv.shape[0]), _distinct_labels(list(piv.index), _consecutive(piv.shape[0]), 6, 12))
        cells = _distinct_labels(list(piv.values.ravel()), _adjacent_cells(*piv.shape), 3, 6)
        for (i, j), v in np.ndenumerate(piv.values):
            if np.isfinite(v):
                ax.text(j, i, cells[i * piv.shape[1] + j], ha="center", va="center", fontsize=7, color="w")
        fig.colorbar(im, ax=ax, label="mean")
        ax.set_xlabel(x)
        ax.set_ylabel(hue)
        ax.set_title(f"mean over ({x}, {hue})", fontsize=9)
    fig.suptitle(f"{study.name}: {metric}")
    fig.tight_layout()
    return save_figure(fig, path)


def _plot_by_policy(df, path) -> str:
    names = sorted(df[POLICY_KEY].astype(str).unique())
    extra = "time_above_rated_s" in df.columns
    fig, axes = plt.subplots(1, 2 if extra else 1, figsize=(10 if extra else 5.5, 4), squeeze=False)
    panels = [(axes[0, 0], "peak_i2_a", "A")] + ([(axes[0, 1], "time_above_rated_s", "s")] if extra else [])
    for ax, m, unit in panels:
        data = [pd.to_numeric(df[df[POLICY_KEY].astype(str) == n][m], errors="coerce").dropna().values for n in names]
        ax.boxplot(data, tick_labels=names, showmeans=True)
        for i, d in enumerate(data, start=1):
            ax.scatter(np.full(len(d), i) + np.linspace(-0.08, 0.08, len(d)) if len(d) else [], d, s=8,
                       color="0.3", alpha=0.6, zorder=3)
        ax.set_ylabel(f"{m} [{unit}]")
        ax.set_xlabel("policy")
        ax.grid(alpha=0.3, axis="y")
    if "rated_i2_a" in df.columns and pd.to_numeric(df["rated_i2_a"], errors="coerce").nunique() == 1:
        rated = float(pd.to_numeric(df["rated_i2_a"]).iloc[0])
        axes[0, 0].axhline(rated, color="tab:red", ls="--", lw=1, label=f"rated {rated:g} A")
        axes[0, 0].legend(fontsize=8)
    axes[0, 0].set_title("peak secondary coil current per mission", fontsize=9)
    if extra:
        axes[0, 1].set_title("time with I2 above rated per mission", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)
