"""Paper Fig. 6 (V2* references and I2 envelopes of the three trajectories)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .common import save_figure  # noqa: E402

__all__ = ["plot_paper_fig6"]


def plot_paper_fig6(runs, path, t_switch_s: float, title: str = "") -> str:
    """Paper Fig. 6: V2* references on top, I2 envelopes below, one column per trajectory."""
    fig, axes = plt.subplots(2, len(runs), figsize=(4.2 * len(runs), 6), sharex=True, squeeze=False)
    for j, r in enumerate(runs):
        ms = (r.t_ctrl_s - t_switch_s) * 1e3
        ax = axes[0, j]
        ax.plot(ms, r.v2_ref_v, color="tab:blue")
        ax.set_title(f"({'abc'[j]}) {r.trajectory} V2*")
        ax.set_ylabel("V2* [V]")
        ax.grid(alpha=0.3)
        ax = axes[1, j]
        ax.plot((r.t_s - t_switch_s) * 1e3, r.i2_a, color="tab:red", label="I2 envelope")
        if "i2_inst_a" in r.extra:
            ax.plot((r.extra["t_inst_s"] - t_switch_s) * 1e3, r.extra["i2_inst_a"], color="0.6", lw=0.3, zorder=0,
                    label="i2 (instantaneous)")
        m = r.metrics
        ax.axhline(m.final_current_a, color="k", ls=":", lw=0.8, label=f"final {m.final_current_a:.2f} A")
        ax.legend(fontsize=7, loc="center right")
        ax.set_title(f"({'def'[j]}) max {m.max_current_a:.1f} A, overshoot {m.overshoot_pct:.1f} %")
        ax.set_xlabel("time after switch [ms]")
        ax.set_ylabel("I2 [A]")
        ax.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)
