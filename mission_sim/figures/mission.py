"""Figures of the mission world (matplotlib, Agg backend; nothing is shown on screen)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402
import numpy as np  # noqa: E402

from .common import fixed_margins, save_figure  # noqa: E402

__all__ = ["plot_lm_map", "plot_mission", "warm_up", "FIGURES"]

_FAST_PNG = 1  # zlib level of the mission figures: written on every `dronewpt mission`, so fast
#: titles at the axes' top (+ the usual pad): matplotlib's automatic placement measures every tick
#: label of the axes at each draw to clear decorations above it (none here); ~20 % of the drawing time
_TITLE_Y = 1.0


def plot_lm_map(model, dz_m: float, tilt_rad: float, path, half_width_m: float = 0.4, n: int = 81) -> str:
    """Map of Lm [uH] over a (dx, dy) grid at height ``dz_m`` and tilt ``tilt_rad``, coil outlines on top."""
    x = np.linspace(-half_width_m, half_width_m, n)
    xx, yy = np.meshgrid(x, x)
    lm = model.lm_h(xx, yy, np.full_like(xx, dz_m), np.full_like(xx, tilt_rad)) * 1e6
    fig, ax = plt.subplots(figsize=(6, 5))
    im = ax.pcolormesh(xx, yy, lm, shading="auto", cmap="viridis")
    cs = ax.contour(xx, yy, lm, levels=8, colors="w", linewidths=0.6)
    ax.clabel(cs, fmt="%.2f", fontsize=7)
    th = np.linspace(0, 2 * np.pi, 200)
    for r in (min(model.tx.radius_m), max(model.tx.radius_m)):
        ax.plot(r * np.cos(th), r * np.sin(th), "r--", lw=0.8)
    fig.colorbar(im, ax=ax, label="Lm [uH]")
    ax.set_aspect("equal")
    ax.set_xlabel("dx [m]")
    ax.set_ylabel("dy [m]")
    ax.set_title(f"Lm over the pad at dz = {dz_m:.3f} m, tilt = {np.degrees(tilt_rad):.1f} deg (pad coil dashed)")
    fig.tight_layout()
    return save_figure(fig, path)


#: the mission figures by name, in the order :func:`plot_mission` draws them
FIGURES = ("trajectory", "lm", "i2", "soc", "power")


def plot_mission(result, out_dir, which=None) -> list[str]:
    """The mission figures: trajectory over the pads, Lm(t), I2 envelope vs rated, SoC, power flows
    (``result.timeseries``: a DataFrame or a dict of numpy columns); ``which``: the names of
    :data:`FIGURES` to draw (None: all), drawn in that tuple's order. The paths written."""
    import gc
    from pathlib import Path
    if getattr(result, "timeseries", None) is None:
        from ..world.results import NO_SERIES
        raise ValueError(NO_SERIES)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plots = {"trajectory": _plot_trajectory, "lm": _plot_lm, "i2": _plot_i2, "soc": _plot_soc, "power": _plot_power}
    files = []
    gc.freeze()   # what exists now is not scanned again: collecting a figure's cycles costs ~3 ms, not ~100 ms
    try:
        for name in FIGURES:
            if which is not None and name not in which:
                continue
            files.append(plots[name](result, out))
            # a closed figure is a web of reference cycles that only the cyclic collector frees; left to
            # it, the five figures of a 50 h mission's thinned series (~20,000 points) held ~170 MB at once
            gc.collect()
    finally:
        gc.unfreeze()
    return files


def warm_up() -> None:
    """Pay matplotlib's first-drawing costs (the font files, the Agg renderer, Pillow's PNG writer) on a
    small figure written to memory: a process that waits for data (:mod:`.worker`) does it while it
    waits. Only caches are filled: the figures drawn afterwards are the same bytes."""
    import io
    fig, ax = plt.subplots(figsize=(1.5, 1.2))
    ax.plot([0.0, 1.0], [0.0, 1.0], ".-", lw=0.8)
    ax.set_xlabel("t [s]")
    ax.set_title("warm-up", y=_TITLE_Y)
    ax.legend(["x"], fontsize=8)
    try:
        fig.savefig(io.BytesIO(), format="png", dpi=110, pil_kwargs={"compress_level": _FAST_PNG})
    finally:
        plt.close(fig)


def _plot_trajectory(result, out) -> str:
    """Trajectory over the pads (plan view) and the height of the receiver coil."""
    ts = result.timeseries
    cfg = result.config
    fig, (ax, az) = plt.subplots(1, 2, figsize=(11, 4.5), gridspec_kw={"width_ratios": [1.2, 1]})
    t_path, p_path = _path(result.trajectory, ts)
    ax.plot(*_plan_path(p_path[:, 0], p_path[:, 1]), color="0.4", lw=1, label="path")
    on = np.asarray(ts["tx_on"], bool)
    ax.plot(ts["x_m"][on], ts["y_m"][on], ".", ms=2, color="tab:orange", label="pad energised")
    r = 0.25
    if cfg is not None:
        r = max(cfg.coupling.model().tx.radius_m)
        for i, p in _distinct_pads(cfg.pads):
            ax.add_patch(plt.Circle((p.x_m, p.y_m), r, color="tab:red", alpha=0.4))
            ax.annotate(f"pad {i}", (p.x_m, p.y_m), textcoords="offset points", xytext=(6, 6))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("trajectory over the pads (pad frame)", y=_TITLE_Y)
    az.plot(*_envelope(t_path, p_path[:, 2]), color="0.3")
    az.set_xlabel("t [s]")
    az.set_ylabel("z [m]")
    az.set_yscale("symlog", linthresh=0.5)
    ticks = [0.0, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0]
    zmax = float(np.max(p_path[:, 2])) if len(p_path) else 1.0
    az.set_yticks([v for v in ticks if v <= 1.5 * zmax])
    az.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    az.set_title("height of the receiver coil", y=_TITLE_Y)
    az.grid(alpha=0.3)
    fixed_margins(fig, 0.8, 0.2, 0.6, 0.4, wspace=0.2)  # [in]: no tight_layout
    return save_figure(fig, out / "trajectory.png", compress_level=_FAST_PNG)


from . import PATH_SAMPLES as _PATH_SAMPLES  # noqa: E402 - beyond it the path comes from the series


def _path(tr, ts):
    """Times [s] and positions (n, 3) [m] of the path to draw: the trajectory's samples, or for a long
    mission (whose planned trajectory is not held in memory; or ``tr`` None) the stored, thinned time series."""
    if tr is not None and len(tr) <= _PATH_SAMPLES:
        return tr.t_s, tr.pos_m
    return np.asarray(ts["t_s"]), np.column_stack([np.asarray(ts[c]) for c in ("x_m", "y_m", "z_m")])


#: time bins of a drawn line (about the axes' width in pixels); a line of more than 4 points a bin is
#: drawn as each bin's first, smallest, largest and last point: its envelope at the pixel scale
_DRAW_BINS = 1000


def _envelope_idx(t, *ys, bins: int = _DRAW_BINS) -> np.ndarray:
    """Indices of the points of ``ys`` (sharing the ascending times ``t``) to draw: all of them up to
    ``4 bins`` points, else per equal-time bin its first and last point and each series' smallest and
    largest. Agg's memory and time for a line grow with its crossings of the pixel grid: a 50 h
    mission's thinned series (~23,000 points) drew with a ~170 MB peak per line, its envelope does not."""
    t = np.asarray(t, dtype=float)
    n = len(t)
    if n <= 4 * bins:
        return np.arange(n)
    starts = np.unique(np.searchsorted(t, np.linspace(t[0], t[-1], bins + 1)[:-1]))
    ends = np.r_[starts[1:], n]
    keep = [starts, ends - 1]
    for y in ys:
        y = np.asarray(y, dtype=float)
        keep.append(starts + np.array([np.argmin(y[a:b]) for a, b in zip(starts, ends)]))
        keep.append(starts + np.array([np.argmax(y[a:b]) for a, b in zip(starts, ends)]))
    return np.unique(np.concatenate(keep))


def _plan_path(x, y, bins: int = _DRAW_BINS):
    """The plan view's path ``(x, y)`` to draw: as it is up to ``4 bins`` points; a longer path (a long
    mission, often a route flown again and again) as its distinct segments on a ``bins`` x ``bins`` grid
    of its extent, each drawn once (NaN-separated). Agg keeps a cell per pixel a segment crosses, so a
    route retraced 835 times (~5,000 segments over the same pixels) drew with a ~50 MB peak."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if len(x) <= 4 * bins:
        return x, y
    span = max(float(np.ptp(x)), float(np.ptp(y)), 1e-9)
    q = np.rint(np.column_stack([x - x.min(), y - y.min()]) * (bins / span)).astype(np.int64)
    a, b = q[:-1], q[1:]
    first = (a[:, 0] < b[:, 0]) | ((a[:, 0] == b[:, 0]) & (a[:, 1] <= b[:, 1]))   # either direction: one key
    key = np.where(first[:, None], np.hstack([a, b]), np.hstack([b, a]))
    _, idx = np.unique(key, axis=0, return_index=True)
    idx = np.sort(idx)
    nan = np.full(len(idx), np.nan)
    return (np.column_stack([x[idx], x[idx + 1], nan]).ravel(), np.column_stack([y[idx], y[idx + 1], nan]).ravel())


def _envelope(t, y, bins: int = _DRAW_BINS):
    """``(t, y)`` to draw (:func:`_envelope_idx`)."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    k = _envelope_idx(t, y, bins=bins)
    return t[k], y[k]


def _distinct_pads(pads):
    """``(index, pad)`` of the first pad at each place (a route flown again repeats its pads)."""
    seen = set()
    for i, p in enumerate(pads):
        if (p.x_m, p.y_m) not in seen:
            seen.add((p.x_m, p.y_m))
            yield i, p


def _plot_lm(result, out) -> str:
    """Lm(t) along the mission with the pad switch-off threshold and the pad-energised spans."""
    ts = result.timeseries
    cfg = result.config
    t = np.asarray(ts["t_s"])
    on = np.asarray(ts["tx_on"], bool)
    fig, ax = plt.subplots(figsize=(10, 3.8))
    ax.plot(*_envelope(t, np.asarray(ts["lm_h"]) * 1e6), color="tab:blue", lw=0.8)
    if cfg is not None:
        m = cfg.coupling.model()
        kmin = cfg.coupling.tx_min_k
        ax.axhline(kmin * np.sqrt(m.l1_h * m.l2_h) * 1e6, color="tab:red", ls="--", lw=0.8,
                   label=f"pad switch-off threshold k = {kmin}")
    ax.axhline(6.25, color="k", ls=":", lw=0.8, label="Table I (6.25 uH)")
    ax.fill_between(t, 0, 1, where=on, transform=ax.get_xaxis_transform(), color="tab:orange", alpha=0.15,
                    label="pad energised")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("Lm [uH]")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=3)  # below: off the data
    ax.grid(alpha=0.3)
    ax.set_title("mutual inductance along the mission", y=_TITLE_Y)
    fixed_margins(fig, 0.75, 0.2, 0.95, 0.4)  # [in]: no tight_layout
    return save_figure(fig, out / "lm.png", compress_level=_FAST_PNG)


def _plot_i2(result, out) -> str:
    """I2 envelope against the rated current: whole mission and a zoom on the largest transient."""
    ts = result.timeseries
    t = np.asarray(ts["t_s"])
    fig, (ax, az) = plt.subplots(1, 2, figsize=(12, 4))
    i2 = np.asarray(ts["i2_amp_a"])
    rated = result.summary.get("rated_i2_a", 15.0)
    ax.plot(*_envelope(t, i2), color="tab:red", lw=0.7)
    ax.axhline(rated, color="k", ls="--", lw=0.8, label=f"rated {rated:g} A")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("I2 [A]")
    sm = result.summary
    ax.set_title(f"secondary current envelope (peak {sm.get('peak_i2_envelope_a', sm['peak_i2_a']):.1f} A; "
                 f"instantaneous {sm['peak_i2_a']:.1f} A)", y=_TITLE_Y)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fine = np.asarray(ts["fine"], bool) if "fine" in ts else np.ones(len(i2), bool)
    if np.any(fine):
        kpk = int(np.flatnonzero(fine)[np.argmax(i2[fine])])  # largest value inside a fine window
        w = (t > t[kpk] - 0.01) & (t < t[kpk] + 0.04)
        lines = az.plot((t[w] - t[kpk]) * 1e3, i2[w], ".-", ms=2, color="tab:red", lw=0.8, label="I2 envelope")
        az2 = az.twinx()
        lines += az2.plot((t[w] - t[kpk]) * 1e3, np.asarray(ts["d_short"])[w], color="tab:blue", lw=0.8,
                          label="d_short (right axis)")
        az2.set_ylim(-0.02, 1.02)  # the whole duty range, so small duty moves look small
        az2.set_ylabel("d_short [-]", color="tab:blue")
        if np.max(np.abs(i2[w])) > 0.8 * rated:  # the rating only where the current comes near it
            lines.append(az.axhline(rated, color="k", ls="--", lw=0.8, label=f"rated {rated:g} A"))
        az.legend(handles=lines, fontsize=8, loc="lower right")
        az.set_xlabel(f"time after t = {t[kpk]:.2f} s [ms]")
        az.set_ylabel("I2 [A]")
        az.set_title(f"largest transient inside a fine window ({i2[kpk]:.1f} A at t = {t[kpk]:.1f} s)", y=_TITLE_Y)
        az.grid(alpha=0.3)
    fixed_margins(fig, 0.75, 0.75, 0.6, 0.4, wspace=0.2)  # [in]: no tight_layout
    return save_figure(fig, out / "i2_envelope.png", compress_level=_FAST_PNG)


def _plot_soc(result, out) -> str:
    """State of charge and battery terminal voltage."""
    ts = result.timeseries
    t = np.asarray(ts["t_s"])
    fig, ax = plt.subplots(figsize=(10, 3.5))
    ax.plot(*_envelope(t, ts["soc"]), color="tab:green")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("SoC [-]")
    ax2 = ax.twinx()
    ax2.plot(*_envelope(t, ts["battery_v"]), color="0.5", lw=0.6)
    ax2.set_ylabel("battery terminal voltage [V]", color="0.4")
    ax.set_title(f"state of charge (final {result.summary['final_soc']:.4f}; without charging "
                 f"{result.summary.get('final_soc_without_charging', float('nan')):.4f})", y=_TITLE_Y)
    ax.grid(alpha=0.3)
    fixed_margins(fig, 0.85, 0.8, 0.6, 0.4)  # [in]: no tight_layout
    return save_figure(fig, out / "soc.png", compress_level=_FAST_PNG)


def _plot_power(result, out) -> str:
    """Power flows: pad source, rectifier, propulsion, battery terminal, coil losses."""
    ts = result.timeseries
    t = np.asarray(ts["t_s"])
    fig, ax = plt.subplots(figsize=(10, 4))
    col = {k: np.asarray(ts[k]) for k in ("p_source_w", "rect_current_a", "battery_v", "propulsion_w",
                                          "battery_current_a", "p_coil_loss_w")}
    ax.plot(*_envelope(t, col["p_source_w"]), lw=0.8, label="pad source")
    ax.plot(*_envelope(t, col["rect_current_a"] * col["battery_v"]), lw=0.8, label="rectifier -> battery node")
    ax.plot(*_envelope(t, col["propulsion_w"]), lw=0.8, label="propulsion")
    ax.plot(*_envelope(t, col["battery_current_a"] * col["battery_v"]), lw=0.8,
            label="battery terminal (+ = charging)")
    ax.plot(*_envelope(t, col["p_coil_loss_w"]), lw=0.8, label="coil losses")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("power [W]")
    ax.legend(fontsize=8, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.15))  # below: off the data
    ax.grid(alpha=0.3)
    s = result.summary
    ax.set_title(f"power flows (energy balance error {s['energy_balance_error_rel']:.1e} relative)", y=_TITLE_Y)
    fixed_margins(fig, 0.85, 0.2, 1.05, 0.4)  # [in]: no tight_layout
    return save_figure(fig, out / "power.png", compress_level=_FAST_PNG)
