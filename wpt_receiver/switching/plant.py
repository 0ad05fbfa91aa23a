"""The switching-level link as a plant of :func:`wpt_receiver.paper.run_paper`, and the check of
eq. 9 (the SBAR's V2 = f(d)) on the exact waveforms."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pandas as pd

from ..params import LinkParams
from ..sbar import v2_from_duty
from .circuit import SwitchingConfig
from .link import SwitchingLink
from .result import fundamental

__all__ = ["switching_plant", "sbar_relation", "waveform_frame"]


def waveform_frame(res, df: pd.DataFrame) -> pd.DataFrame:
    """The instantaneous waveforms of a run, units in the column names: ``t_s, i1_a, vc1_v, i2_a,
    vc2_v, v1_v, v2_v, i_load_a`` (:meth:`SwitchingResult.frame`), ``sbar_gate`` (1 = lower switches
    on) and ``inverter_cmd`` (+1 / -1 driven, 0 dead time) at the same instants ``df["t_s"]``."""
    sch = res.schedule
    j = np.clip(np.searchsorted(sch.t, df["t_s"].to_numpy(), side="right") - 1, 0, len(sch.cmd) - 1)
    return df.rename(columns={"gate": "sbar_gate"}).assign(inverter_cmd=sch.cmd[j])


@lru_cache(maxsize=16)
def _link(params: LinkParams, cfg: SwitchingConfig) -> SwitchingLink:
    return SwitchingLink(params, cfg)


def switching_plant(params: LinkParams, d_short, control_period_s: float, cfg: SwitchingConfig = SwitchingConfig(),
                    phase_rad: float | None = None) -> dict:
    """Plant model for :func:`wpt_receiver.paper.run_paper` (``MODELS["switching"]``).

    Runs the duty sequence from the periodic steady state of its first duty and returns the
    per-half-cycle envelope ``t_s, i1_a, i2_a`` (peaks), ``v2_v`` (in-phase fundamental of v2 per
    half cycle), ``i2_fund_a`` (fundamental amplitude of i2 per half cycle), ``i_load_avg_a``
    (battery current averaged per half cycle) and the raw waveforms ``t_inst_s, i2_inst_a,
    i1_inst_a, i_load_a, gate`` (``samples_per_half_cycle`` per T plus every switching instant) and
    all of them as one table ``waveforms`` (:func:`waveform_frame`).
    """
    link = _link(params, cfg)
    res = link.simulate(d_short, control_period_s, phase_rad=phase_rad)
    env = res.envelope()
    df = res.frame(np.union1d(res.sample_times(), res.seg_t))  # grid + every switching instant
    t = env["t_s"].to_numpy()
    ok = np.isfinite(env["t_i1_peak_s"].to_numpy())
    i1 = np.interp(t, env["t_i1_peak_s"].to_numpy()[ok], env["i1_env_a"].to_numpy()[ok])
    il_avg = env["i_load_avg_a"].to_numpy()
    il = df["i_load_a"].to_numpy()
    return {"t_s": t, "i1_a": i1, "i2_a": env["i2_env_a"].to_numpy(), "v2_v": env["v2_fund_v"].to_numpy(),
            "i2_fund_a": env["i2_fund_a"].to_numpy(),
            "t_inst_s": df["t_s"].to_numpy(), "i2_inst_a": df["i2_a"].to_numpy(), "i1_inst_a": df["i1_a"].to_numpy(),
            "i_load_a": il, "gate": df["gate"].to_numpy(), "i_load_avg_a": il_avg, "waveforms": waveform_frame(res, df),
            "link_params": params, "switching_config": cfg, "gate_phase_rad": link.cfg.gate_phase_rad if phase_rad is None else phase_rad}


def sbar_relation(params: LinkParams, duties, phase_rad: float | None = 0.0, cfg: SwitchingConfig = SwitchingConfig(),
                  periods: int = 2) -> pd.DataFrame:
    """Fundamental of v2 in the periodic steady state against ``d_short`` (eq. 9 check).

    ``phase_rad``: gate clock phase relative to the peak of the i2 fundamental (``i2 ~ cos wt``);
    ``None`` centres the window on the i2 half-cycle itself, i.e. midway between the diode
    commutations (found per duty by root-finding the phase that makes v2 symmetric), which is
    exactly eq. 9's assumption. Columns: ``d_short, f_d_v`` (eq. 9), ``v2_abs_v`` (magnitude of
    the fundamental), ``v2_inphase_v`` (component in phase with the i2 fundamental),
    ``err_abs_pct``/``err_inphase_pct`` (relative to f(d)), ``err_abs_fs_pct`` (relative to the
    full scale (4/pi) VL), ``phase_rad``.
    """
    from scipy.optimize import brentq

    link = _link(params, cfg)
    T = link.T
    rows = []
    for d in np.atleast_1d(np.asarray(duties, dtype=float)):
        def phasors(ph):
            x = link.periodic_steady_state(d, phase_rad=ph)
            r = link.run(link.schedule(0.0, 2 * periods * T, float(d), phase_rad=ph), x)
            return fundamental(r, 0.0, 2 * periods * T, "v2"), fundamental(r, 0.0, 2 * periods * T, "i2")

        if phase_rad is None:
            ph = brentq(lambda q: (phasors(q)[0] * np.exp(1j * q)).imag, -0.5, 0.5, xtol=1e-10)
        else:
            ph = float(phase_rad)
        v2, i2 = phasors(ph)
        f = float(v2_from_duty(d, params.vl_v))
        inph = float((v2 * np.conj(i2)).real / abs(i2))
        rows.append({"d_short": float(d), "f_d_v": f, "v2_abs_v": abs(v2), "v2_inphase_v": inph,
                     "err_abs_pct": 100 * (abs(v2) - f) / f if f > 0 else float("nan"),
                     "err_inphase_pct": 100 * (inph - f) / f if f > 0 else float("nan"),
                     "err_abs_fs_pct": 100 * (abs(v2) - f) / params.v2_rm_amp_v, "phase_rad": ph})
    return pd.DataFrame(rows)
