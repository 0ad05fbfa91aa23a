"""Figure of a what-if re-flight (``dronewpt replay LOG --pads FILE``): the logged track and its
re-flight with pad detours in plan, the state of charge of both, and the pad power."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .common import save_figure  # noqa: E402

__all__ = ["plot_refly"]


def plot_refly(result, path, title: str = "") -> str:
    """Plan view (logged track, re-flight, pads), SoC over time (logged as flown vs re-flight), pad power."""
    s = result.summary
    tr, nw = result.track, result.refly_track
    fig, ax = plt.subplots(1, 3, figsize=(16, 5))
    a = ax[0]
    a.plot(nw.pos_m[:, 0], nw.pos_m[:, 1], lw=1.0, color="tab:blue", label="re-flight with pad detours")
    a.plot(tr.pos_m[:, 0], tr.pos_m[:, 1], lw=0.7, color="0.5", label="logged track")
    a.plot(result.pads_xyz[:, 0], result.pads_xyz[:, 1], "s", color="tab:red", ms=8, label="pads")
    for k, p in enumerate(result.pads_xyz):
        a.annotate(f" pad {k}", (p[0], p[1]), fontsize=8)
    a.plot([0], [0], "k^", ms=7, label="take-off (frame origin)")
    a.set_xlabel("east [m]"), a.set_ylabel("north [m]"), a.set_aspect("equal", "datalim")
    a.grid(alpha=0.3), a.legend(fontsize=8)
    a.set_title(f"{len(s['detours'])} detour(s), +{s['detour_time_s']:.0f} s of flight")
    a = ax[1]
    o, r = result.original.timeseries, result.refly.timeseries
    a.plot(o["t_s"], o["soc"], color="0.4", lw=1.0, label=f"logged flight, no pads (end {s['final_soc_logged_flight']:.3f})")
    a.plot(r["t_s"], r["soc"], color="tab:blue", lw=1.0, label=f"re-flight, pads on (end {s['final_soc_refly']:.3f})")
    a.axhline(s["final_soc_refly_without_charging"], color="tab:blue", ls=":", lw=0.9,
              label=f"re-flight end, pads off ({s['final_soc_refly_without_charging']:.3f})")
    a.set_xlabel("time [s]"), a.set_ylabel("state of charge"), a.grid(alpha=0.3), a.legend(fontsize=8)
    a.set_title(f"flight time gain {s['flight_time_gain_s']:+.0f} s vs the logged flight "
                f"({s['flight_time_gain_vs_refly_without_charging_s']:+.0f} s vs pads off)", fontsize=9)
    a = ax[2]
    a.plot(r["t_s"], r["p_source_w"], color="tab:red", lw=0.8, label="pad (source) power")
    a.plot(r["t_s"], r["propulsion_w"], color="tab:green", lw=0.6, label="propulsion power (model)")
    a.set_xlabel("time [s]"), a.set_ylabel("power [W]"), a.grid(alpha=0.3), a.legend(fontsize=8)
    a.set_title(f"from the pads {s['energy_from_pads_j'] / 1e3:.1f} kJ, into the battery "
                f"{s['battery_charge_in_j'] / 1e3:.1f} kJ", fontsize=9)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)
