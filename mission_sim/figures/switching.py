"""Raw-waveform figure of the switching-level model (matplotlib, Agg; like the paper's Figs. 8-11).

Kept apart from :mod:`wpt_receiver.switching` so the simulator never imports matplotlib.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .common import save_figure  # noqa: E402

__all__ = ["plot_switching_waveforms"]


def plot_switching_waveforms(runs, out_dir, t_switch_s: float | None = None, shifted_phase_rad: float = math.pi / 2) -> list[str]:
    """Secondary current (raw i2 and its envelope) and battery current per trajectory, plus the
    proposed trajectory re-run with the gate clock shifted by ``shifted_phase_rad``.

    ``runs`` are :class:`wpt_receiver.paper.PaperRun` from the switching model. Returns the path.
    """
    from wpt_receiver.metrics import transition_metrics
    from wpt_receiver.switching import switching_plant

    runs = list(runs)
    if t_switch_s is None:
        d = runs[0].d_short
        t_switch_s = float(runs[0].t_ctrl_s[np.argmax(np.abs(np.diff(d)) > 0) + 1]) if np.any(np.diff(d)) else 0.0
    cols = [(r.trajectory, r.extra, r.metrics) for r in runs]
    prop = next((r for r in runs if r.trajectory == "proposed"), None)
    if prop is not None and "link_params" in prop.extra:
        cp = float(prop.t_ctrl_s[1] - prop.t_ctrl_s[0]) if len(prop.t_ctrl_s) > 1 else None
        out = switching_plant(prop.extra["link_params"], prop.d_short, cp, prop.extra["switching_config"],
                              phase_rad=shifted_phase_rad)
        m = transition_metrics(out["t_s"], out["i2_a"], t_switch_s, out["i1_a"], out["v2_v"],
                               i2_fund_a=out.get("i2_fund_a"))
        out = dict(out, i2_env=out["i2_a"], t_env=out["t_s"])
        cols.append((f"proposed, gate shifted {shifted_phase_rad / math.pi:.2g} pi", out, m))
    fig, axes = plt.subplots(2, len(cols), figsize=(4.0 * len(cols), 5.6), sharex=True, squeeze=False)
    for j, (name, ex, m) in enumerate(cols):
        t = (ex["t_inst_s"] - t_switch_s) * 1e3
        ax = axes[0, j]
        ax.plot(t, ex["i2_inst_a"], color="tab:red", lw=0.25)
        ax.set_title(f"{name}\nmax {m.max_current_a:.2f} A, overshoot {m.overshoot_pct:.1f} %", fontsize=9)
        ax.set_ylabel("i2 [A]")
        ax.grid(alpha=0.3)
        ax = axes[1, j]
        ax.plot(t, ex["i_load_a"], color="0.7", lw=0.25, label="i_load (raw)")
        te = (ex["t_env"] if "t_env" in ex else _env_t(runs, j)) if "i_load_avg_a" in ex else None
        if te is not None:
            ax.plot((np.asarray(te) - t_switch_s) * 1e3, ex["i_load_avg_a"], color="tab:blue", lw=1.0, label="half-cycle mean")
        ax.set_ylabel("battery current [A]")
        ax.set_xlabel("time after switch [ms]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    fig.suptitle("Switching-level model: secondary and battery current (RM -> SM)")
    fig.tight_layout()
    path = Path(out_dir) / "waveforms_switching.png"
    return [save_figure(fig, path, dpi=120)]


def _env_t(runs, j):
    return runs[j].t_s
