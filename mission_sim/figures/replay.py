"""Figures of a replayed flight log (matplotlib, Agg backend; nothing is shown on screen)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .common import save_figure  # noqa: E402

__all__ = ["plot_replay", "plot_power_comparison"]


def _shaded_periods(log) -> tuple[list, str]:
    """(periods, label) shaded on the time axes: the armed periods, or for a log whose armed state is unknown the
    time the replay counts as flown (:func:`~mission_sim.mavlink.takeoff.flown_periods`: its whole track)."""
    from ..mavlink.takeoff import flown_periods
    if log.armed_source is not None:
        return log.armed_periods, "armed"
    return flown_periods(log), "counted as flown (armed state unknown)"


def _shade_armed(ax, log, offset_s):
    periods, label = _shaded_periods(log)
    for i, (a, b) in enumerate(periods):
        ax.axvspan(a - offset_s, b - offset_s, color="tab:orange", alpha=0.12, lw=0,
                   label=label if i == 0 else None)


def plot_replay(result, path, title: str = "") -> str:
    """Track in plan, height, Lm / I2 and state of charge over the replayed flight."""
    tr, ts = result.track, result.mission.timeseries
    fig, ax = plt.subplots(2, 2, figsize=(12, 7.5))
    a = ax[0, 0]
    a.plot(tr.pos_m[:, 0], tr.pos_m[:, 1], lw=0.8)
    a.plot([0], [0], "s", color="tab:red", ms=8, label="pad")
    a.set_xlabel("east [m]"), a.set_ylabel("north [m]"), a.set_aspect("equal", "datalim")
    a.set_title(f"track, {result.summary['distance_m']:.0f} m flown")
    a.legend(), a.grid(alpha=0.3)
    a = ax[0, 1]
    a.plot(tr.t_s, tr.height_m, lw=0.8)
    _shade_armed(a, result.log, tr.t_offset_s)
    a.set_xlabel("time [s]"), a.set_ylabel("height above pad [m]"), a.grid(alpha=0.3), a.legend()
    armed = (f"armed {result.summary['armed_time_s']:.0f} s ({result.log.armed_source})" if result.log.armed_source
             else f"flown {result.summary['flown_time_s']:.0f} s (armed state unknown: the whole track)")
    a.set_title(f"max {result.summary['max_alt_m']:.1f} m, {armed}", fontsize=9)
    a = ax[1, 0]
    a.plot(ts["t_s"], ts["lm_h"] * 1e6, color="tab:blue", lw=0.8)
    a.set_xlabel("time [s]"), a.set_ylabel("Lm [uH]", color="tab:blue"), a.grid(alpha=0.3)
    b = a.twinx()
    b.plot(ts["t_s"], ts["i2_amp_a"], color="tab:red", lw=0.6)
    b.set_ylabel("I2 amplitude [A]", color="tab:red")
    a.set_title("coupling and secondary current")
    a = ax[1, 1]
    a.plot(ts["t_s"], ts["soc"], lw=0.8)
    _shade_armed(a, result.log, tr.t_offset_s)
    a.set_xlabel("time [s]"), a.set_ylabel("state of charge"), a.grid(alpha=0.3)
    a.set_title(f"rectifier out {result.summary['rectifier_output_j'] / 1e3:.2f} kJ, "
                f"propulsion {result.summary['propulsion_energy_j'] / 1e3:.1f} kJ")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_power_comparison(result, path, title: str = "") -> str:
    """Logged electrical power vs the modelled propulsion power, and the error, over the flight."""
    tab, cmp = result.power_table, result.summary.get("power_comparison", {})
    off = result.track.t_offset_s
    fig, ax = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    a = ax[0]
    t = tab["t_s"].to_numpy() - off
    a.plot(t, tab["logged_w"], lw=0.7, label=f"logged V I ({cmp.get('battery_source')})")
    a.plot(t, tab["model_w"], lw=0.9, label="model (momentum theory)")
    if np.isfinite(cmp.get("best_fit_scale", np.nan)):
        a.plot(t, tab["model_w"] * cmp["best_fit_scale"], lw=0.7, ls="--",
               label=f"model x {cmp['best_fit_scale']:.2f} (least squares)")
    _shade_armed(a, result.log, off)
    a.set_ylabel("power [W]"), a.grid(alpha=0.3), a.legend(fontsize=8)
    if "energy_error_rel" in cmp:
        a.set_title(f"airborne: logged {cmp['logged_mean_w']:.0f} W mean, model {cmp['model_mean_w']:.0f} W "
                    f"({cmp['drone_mass_kg']:g} kg); energy error {100 * cmp['energy_error_rel']:+.0f} %, "
                    f"equivalent mass {cmp['equivalent_mass_kg']:.2f} kg")
    a = ax[1]
    err = np.where(tab["airborne"], tab["error_w"], np.nan)
    a.plot(t, err, lw=0.7, color="tab:red")
    a.axhline(0, color="k", lw=0.6)
    a.set_xlabel("time [s]"), a.set_ylabel("model - logged [W] (airborne)"), a.grid(alpha=0.3)
    if "rms_error_w" in cmp:
        a.set_title(f"RMS error {cmp['rms_error_w']:.0f} W; after scaling {cmp['rms_error_after_scale_w']:.0f} W")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)
