"""Figure of a drone power-model calibration (matplotlib, Agg backend; nothing is shown on screen)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..world.power import propulsion_power_w  # noqa: E402
from .common import save_figure  # noqa: E402

__all__ = ["plot_calibration"]


def _series(cal):
    tab = cal.samples.table
    air = tab["airborne"].to_numpy()
    held = air & ~tab["train"].to_numpy()
    v, vz = tab["speed_m_s"].to_numpy(), tab["climb_m_s"].to_numpy()
    return tab, air, held, propulsion_power_w(cal.drone, v, vz), propulsion_power_w(cal.default, v, vz)


def plot_calibration(cal, path, title: str = "") -> str:
    """Logged vs modelled power over time (train / held-out), vs speed, and the residuals."""
    tab, air, held, p_cal, p_def = _series(cal)
    t, p_log = tab["t_s"].to_numpy(), tab["power_w"].to_numpy()
    r = cal.report
    fig, ax = plt.subplots(2, 2, figsize=(13, 8))
    a = ax[0, 0]
    a.plot(t, p_log, ".", ms=2, color="0.4", label="logged V I")
    a.plot(t[air], p_cal[air], ".", ms=2, color="tab:blue", label="calibrated model (airborne)")
    a.plot(t[air], p_def[air], ".", ms=2, color="tab:red", alpha=0.5, label="default model (airborne)")
    # the held-out airborne samples' span: the model is drawn at airborne samples only, so the shading ends at
    # the last of them, not at the log's last battery sample (landed, disarmed: 15-20 s later on the shipped logs)
    a.axvspan(cal.samples.split_t_s, float(t[held].max()), color="tab:orange", alpha=0.12, lw=0, label="held out")
    a.set_xlabel("log time [s]"), a.set_ylabel("electrical power [W]"), a.grid(alpha=0.3)
    a.legend(fontsize=8, markerscale=4)
    a.set_title(f"held-out energy error: calibrated {100 * r['calibrated_heldout_energy_error_rel']:+.1f} %, "
                f"default {100 * r['default_heldout_energy_error_rel']:+.1f} %", fontsize=10)
    a = ax[0, 1]
    a.scatter(tab["speed_m_s"][air & ~held], p_log[air & ~held], s=4, color="0.5", label="logged (train)")
    a.scatter(tab["speed_m_s"][held], p_log[held], s=4, color="tab:orange", label="logged (held out)")
    vs = np.linspace(0.0, max(float(tab["speed_m_s"][air].max()), 1.0), 60)
    a.plot(vs, propulsion_power_w(cal.drone, vs, 0.0), color="tab:blue", label="calibrated, level flight")
    a.plot(vs, propulsion_power_w(cal.default, vs, 0.0), color="tab:red", label="default, level flight")
    a.set_xlabel("GPS ground speed [m/s]"), a.set_ylabel("power [W]"), a.grid(alpha=0.3), a.legend(fontsize=8)
    a = ax[1, 0]
    res = p_cal - p_log
    a.plot(t[air & ~held], res[air & ~held], ".", ms=2, color="0.5", label="train")
    a.plot(t[held], res[held], ".", ms=2, color="tab:orange", label="held out")
    a.axhline(0, color="k", lw=0.6)
    a.set_xlabel("log time [s]"), a.set_ylabel("model - logged [W]"), a.grid(alpha=0.3), a.legend(fontsize=8)
    a.set_title(f"held-out RMS {r['calibrated_heldout_rms_w']:.0f} W (default {r['default_heldout_rms_w']:.0f} W)",
                fontsize=10)
    a = ax[1, 1]
    a.hist([res[air & ~held], res[held]], bins=50, color=["0.5", "tab:orange"], label=["train", "held out"],
           stacked=True)
    a.set_xlabel("residual, model - logged [W]"), a.set_ylabel("samples"), a.grid(alpha=0.3), a.legend(fontsize=8)
    f = r["fitted"]
    a.set_title(f"m {f['mass_kg']:.2f} kg, FM {f['figure_of_merit']:.2f}, eta {f['drive_efficiency']:.2f}, "
                f"f {f['flat_plate_area_m2']:.3f} m2, avionics {f['avionics_w']:.1f} W", fontsize=9)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)
