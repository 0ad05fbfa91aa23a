"""Rectifier sizing figure: worst-case |i2|, required rating and rectifier mass per policy."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .common import save_figure  # noqa: E402

__all__ = ["plot_sizing", "plot_open_load"]


def plot_sizing(rows, path, title: str = "") -> str:
    """Two panels: peak |i2| and required rating (left), rectifier mass split into devices and
    heat sink (right), one bar group per policy."""
    names = [r["policy"] for r in rows]
    x = range(len(rows))
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.8))
    a.bar([i - 0.2 for i in x], [r["peak_i2_a"] for r in rows], 0.4, label="worst-case |i2|")
    a.bar([i + 0.2 for i in x], [r["required_rating_a"] for r in rows], 0.4, label="required rating")
    a.set_ylabel("current [A]")
    a.set_xticks(list(x), names)
    a.legend(fontsize=8)
    a.grid(alpha=0.3, axis="y")
    dev = [r["device_mass_g"] for r in rows]
    b.bar(list(x), dev, 0.5, label="devices")
    b.bar(list(x), [r["sink_mass_g"] for r in rows], 0.5, bottom=dev, label="heat sink")
    for i, r in enumerate(rows):
        b.text(i, r["mass_g"], r["part"].replace("/", "\n"), ha="center", va="bottom", fontsize=7)
    b.set_ylabel("rectifier mass [g]")
    b.set_xticks(list(x), names)
    b.set_ylim(0, 1.35 * max(r["mass_g"] for r in rows))
    b.legend(fontsize=8, loc="upper right")
    b.grid(alpha=0.3, axis="y")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_open_load(stress: dict, path, v_rating_v: float | None = None) -> str:
    """Blocked voltage of the SBAR's devices after a battery disconnect (open-load study of
    :func:`wpt_receiver.switching.stress.voltage_stress`): one line per case (RM, while switching
    to SM), the protection's short and the chosen parts' voltage rating."""
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for d, run in stress["runs"].items():
        ax.plot(run["t_s"] * 1e6, run["v_block_v"], label=f"battery opened at d = {d:g}")
    ax.axvline(stress["t_protect_s"] * 1e6, color="k", ls="--", lw=1, label="protective short")
    if v_rating_v is not None:
        ax.axhline(v_rating_v, color="r", ls=":", lw=1, label=f"required rating {v_rating_v:.1f} V")
    ax.set_xlabel("time after the disconnect [us]")
    ax.set_ylabel("blocked voltage [V]")
    ax.set_title(f"open load, C_out = {stress['c_out_f'] * 1e6:g} uF", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)
