"""Figures of the mission world (matplotlib, Agg backend; nothing is shown on screen)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["plot_lm_map"]


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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return str(path)
