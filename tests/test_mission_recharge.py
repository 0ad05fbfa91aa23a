"""A long multi-pad mission recharges at the pads it needs (issue 22): the charger's *full* state
clears below the recharge threshold, in the Python reference loop and the compiled loop alike."""

import numpy as np
import pytest

from mission_sim.config import config_from_dict, load_config_dict
from mission_sim.contract import PolicyContext
from mission_sim.world.runner import run_mission
from policies import make


#: hover at the default mission's long pad [s] (default 120 s). The CV taper of the default pack runs with
#: the time constant ``tau = r0 Q / (n dOCV/dSoC) = 0.096 ohm * 4680 C / (8 * 0.92 V) ~ 60 s`` (near full),
#: so from CC (1.3 A) to the C/10 cut-off takes >= ln(10) tau ~ 140 s of CV after the CC part. With 120 s
#: the charger reached *full* on eq. 4's link 7.6 s before the visit's end (the 4th visit), and on the
#: exact-mode link in none of the 20 visits (its taper is slower: the model-based policy picks its duty
#: from eq. 9, which the exact link's rectifier, v2's quadrature included, does not quite deliver).
#: The test is about what happens after *full*, so the visit is long enough for the taper to finish.
LONG_HOVER_S = 180.0


def _repeated(n: int):
    d = load_config_dict(None)
    d["pads"] = [dict(p, hover_time_s=LONG_HOVER_S) if p["hover_time_s"] >= 120.0 else p for p in d["pads"]] * n
    return config_from_dict(d)


def _charging_episodes(ts, cfg) -> list[tuple[float, float]]:
    """(start, end) [s] of the runs of rows in a charge cycle: the charger's command above the load current
    (propulsion + avionics) by more than half the CC current. Not the battery current: over a pad a full pack
    floats on the charger's power path (command = load current), its current the delivery's error around the
    load (+-0.5 A in the default wind's gusts, the command held within the BMS dead band between updates)."""
    i_load = ts["propulsion_w"].to_numpy() / ts["battery_v"].to_numpy()
    t = ts["t_s"].to_numpy()
    on = ts["charge_cmd_a"].to_numpy() - i_load > 0.5 * cfg.charger.cc_current_a
    episodes, start = [], None
    for ti, c in zip(t, on):
        if c and start is None:
            start = ti
        if not c and start is not None:
            episodes.append((start, ti))
            start = None
    merged = []   # rows of one pad visit are seconds apart, pad visits tens of seconds
    for a, b in episodes:
        if merged and a - merged[-1][1] < 10.0:
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    return merged


def _soc_full(cfg) -> float:
    """The SoC at which the charger declares *full*: the CV current at the cut-off, ``OCV + (R0 + R1) I_cut = V_cv``
    (v1 at its steady ``R1 I``), so ``OCV(SoC) = cv_cell_v - (r0 + r1) cutoff`` per cell."""
    b, ch = cfg.battery, cfg.charger
    return _soc_at_ocv_cell(ch.cv_cell_v - (b.r0_ohm_cell + b.r1_ohm_cell) * ch.cutoff_current_a)


def _pad_visits(ts) -> list[tuple[int, int]]:
    """(first, last + 1) row indices of the runs of rows with the pad on."""
    on = ts["tx_on"].to_numpy().astype(bool)
    edges = np.flatnonzero(np.diff(np.r_[False, on, False].astype(int)))
    return list(zip(edges[::2], edges[1::2]))


def test_default_pads_repeated_10x_top_off_at_every_long_pad_and_never_run_low():
    """The default pads 10x with the long pad held 180 s: each pad switching on starts a new charge cycle (the host
    toggles the charger's CE on input power, TI BQ25601D), so the pack is topped off at every pad visit and the
    deepest it falls is one round's transit drain below full. Before (2026-11-27, *full* latched until the
    recharge threshold), the pack floated over the pads at whatever SoC it arrived with and drained between them
    down to the threshold: min SoC 0.879, ~1,080 s over energised pads across 9 visits without charging."""
    cfg = _repeated(10)
    pol = make("model_based", PolicyContext(control_period_s=cfg.sim.control_period_s, rated_i2_a=cfg.link.rated_i2_a))
    res = run_mission(cfg, pol)
    s, ts = res.summary, res.timeseries
    assert not s["battery_depleted"] and s["sim_time_s"] > 2000.0   # the whole mission (it used to end at 1,917 s)
    soc, t = ts["soc"].to_numpy(), ts["t_s"].to_numpy()
    # full is declared at OCV + v1 = V_cv - R0 I_cut, v1 lagging the CV taper's falling current: at most R1 I_cc
    b, ch = cfg.battery, cfg.charger
    soc_full_lo = _soc_at_ocv_cell(ch.cv_cell_v - b.r0_ohm_cell * ch.cutoff_current_a - b.r1_ohm_cell * ch.cc_current_a)
    long_visits = [(i, j) for i, j in _pad_visits(ts) if t[j - 1] - t[i] > 150.0]
    assert len(long_visits) == 10
    assert 0.985 < soc_full_lo < _soc_full(cfg) < 1.0
    for i, j in long_visits:      # topped off at every long visit, the last ones too
        assert soc[i:j].max() > soc_full_lo, (t[i], soc[i:j].max(), soc_full_lo)
    # one round (two pads, ~270 s of flight) drains < 0.02 of the 1.3 Ah pack from full
    assert soc[t > t[long_visits[0][1]]].min() > soc_full_lo - 0.02
    assert len(_charging_episodes(ts, cfg)) >= 10      # a CC phase at each long pad
    # energy: what went into the battery is what the pads' charging cycles put there (balance closes)
    assert s["energy_balance_error_rel"] < 1e-12 and s["battery_charge_in_j"] > 0


def test_default_mission_with_hysteresis_holds_a_full_pack_at_cv():
    """The hysteresis policy delivers more than its command at times (its band, and gusts): a full pack's command is
    the load less ``(OCV + v1 - V_cv) / R0`` (the CV law's current where it is negative), so the pack is drawn back
    to CV in proportion. Checked on the default mission: SoC never above 1 (on main, command 0 when full and no CV
    rule, it reached 1.006), no command 0 while the pad stays on (an on-off rule at CV gave 4 commands to 0 for 2
    pad switch-offs), and the pack above ``V_cv + R0 deadband`` for at most one BMS period per pad visit: below that
    excess the CV correction is smaller than the dead band and is not applied; above it the next BMS update (at
    most ``bms_period_s`` later) applies it, which the policy then delivers on average. Measured: max SoC 0.9899,
    0.6 s above ``V_cv + R0 deadband`` (3 mV/cell), max 3.6 mV/cell above CV."""
    from mission_sim.config import policy_context
    from mission_sim.world.fastpath import battery_values, constants
    from mission_sim.world.loop_kernel import _bat_step

    cfg = config_from_dict(load_config_dict(None))
    res = run_mission(cfg, make("hysteresis", policy_context(cfg)))
    s, ts = res.summary, res.timeseries
    b, ch, sim = cfg.battery, cfg.charger, cfg.sim
    soc, t, dt = ts["soc"].to_numpy(), ts["t_s"].to_numpy(), ts["dt_s"].to_numpy()
    assert s["battery_full"] and soc.max() <= 1.0
    # v1 of the RC pair, stepped with the kernel's battery step over the rows' mean currents (exact for them)
    c = constants(battery_values(b, ch)).view(np.recarray)[0]
    v1, x = np.empty(len(ts)), 0.0
    for k, (i_b, h) in enumerate(zip(ts["battery_current_a"].to_numpy(), dt)):
        x = _bat_step(c, 0.5, x, i_b, h)[1]
        v1[k] = x
    from mission_sim.world.battery import ocv_cell_v
    excess = b.n_series * ocv_cell_v(soc) + v1 - ch.cv_cell_v * b.n_series
    visits = _pad_visits(ts)
    assert dt[excess > b.r0_ohm * sim.cmd_deadband_a].sum() <= sim.bms_period_s * len(visits)
    # commands to 0 only as a pad switches off (the command drops, the pad ramps down tx_off_delay_s later)
    cmd, on = ts["charge_cmd_a"].to_numpy(), ts["tx_on"].to_numpy().astype(bool)
    to_zero = np.flatnonzero((cmd[1:] == 0.0) & (cmd[:-1] != 0.0)) + 1
    offs = np.array([t[j - 1] for _, j in visits])
    for k in to_zero:
        assert np.any((offs >= t[k]) & (offs <= t[k] + sim.tx_off_delay_s + 0.01)), t[k]


def test_recharge_is_the_same_in_the_compiled_and_the_reference_loop():
    pytest.importorskip("numba")
    from tests.test_mission_fast import assert_summaries_agree, assert_timeseries_agree
    cfg = _repeated(4)
    pol = lambda: make("model_based", PolicyContext(control_period_s=cfg.sim.control_period_s,  # noqa: E731
                                                    rated_i2_a=cfg.link.rated_i2_a))
    fast, ref = run_mission(cfg, pol(), compiled=True), run_mission(cfg, pol(), compiled=False)
    assert_summaries_agree(fast.summary, ref.summary)
    assert_timeseries_agree(fast.timeseries, ref.timeseries)
    assert len(_charging_episodes(ref.timeseries, cfg)) >= 2


def _soc_at_ocv_cell(v_cell: float) -> float:
    """The SoC whose cell OCV is ``v_cell`` (bisection on the monotone OCV curve)."""
    from mission_sim.world.battery import ocv_cell_v
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if float(ocv_cell_v(mid)) < v_cell else (lo, mid)
    return 0.5 * (lo + hi)


def test_a_full_battery_hovering_over_a_pad_floats_on_the_power_path():
    """600 s hovering over pad 0 (no wind, so a constant load) from SoC 0.985: the charger charges to full, then
    its command is the load current (propulsion + avionics; the charger IC's power path), so the pad feeds the
    load and the pack is held near full. Before, a full pack's command was 0: the drone flew on the pack down to
    the recharge threshold (min SoC 0.901) and charged again, 14.6 kJ into the pack.

    The band: *full* is the CV current at the cut-off, ``OCV + (R0 + R1) I_cut = V_cv`` (v1 at its steady ``R1 I``),
    so SoC_full solves ``OCV(SoC) = cv_cell_v - (r0 + r1) cutoff`` per cell. After that the pack carries the
    difference between the load and what the receiver delivers: the command's error (the load as of the last BMS
    update, held within the dead band) plus the policy's tracking error around its command, which neither the dead
    band nor the charger bounds (the hysteresis policy, over the same 600 s, lets the pack down to SoC 0.899, the
    recharge threshold). ``delta = deadband T / Q`` (0.032 over 600 s) is the drift of a 0.25 A error held for
    the whole hover: the model-based policy's measured shortfall at this constant load (~0.07 A) plus the dead band's
    error stay inside it, so this checks the policy as much as the charger. Above CV the full command is the load
    less ``(OCV + v1 - V_cv) / R0``, so the SoC never passes 1. The start (0.985) is inside the band."""
    from mission_sim.config import policy_context
    from mission_sim.world.trajectory import Trajectory

    d = load_config_dict(None)
    d["battery"]["initial_soc"] = 0.985
    cfg = config_from_dict(d)
    hover_s = 600.0
    t = np.arange(0.0, hover_s + 1e-9, cfg.sim.traj_dt_s)
    pos = np.zeros((len(t), 3))
    pos[:, 2] = cfg.mission.hover_gap_m
    res = run_mission(cfg, make("model_based", policy_context(cfg)), trajectory=Trajectory.from_samples(t, pos, phase="hover"))
    s, ts = res.summary, res.timeseries
    b, ch = cfg.battery, cfg.charger
    soc_full = _soc_full(cfg)
    delta = cfg.sim.cmd_deadband_a * hover_s / b.capacity_c
    soc = ts["soc"].to_numpy()
    assert 0.99 < soc_full < 1.0 and delta < 0.035
    assert np.all(np.abs(soc - soc_full) <= delta), (soc.min(), soc.max(), soc_full, delta)
    assert soc.max() <= 1.0
    assert s["battery_full"] and not s["battery_depleted"]       # never down to the recharge threshold
    # the command is the load current: after the CV taper (tau ~ 60 s near full, from 0.985 done well before
    # 300 s), within the dead band of propulsion / VL
    late = (ts["t_s"] > hover_s / 2).to_numpy()
    i_load = (ts["propulsion_w"] / ts["battery_v"]).to_numpy()
    assert np.all(np.abs(ts["charge_cmd_a"].to_numpy()[late] - i_load[late]) <= cfg.sim.cmd_deadband_a)
    # the pack takes in only what brings it to full, plus the band: at most V_cv Q (SoC_full + delta - SoC_0)
    v_cv = ch.cv_cell_v * b.n_series
    assert s["battery_charge_in_j"] <= v_cv * b.capacity_c * (soc_full + delta - b.initial_soc)
    # energy: pad + pack = loads + losses (+ the link's stored energy), and the summary's balance
    pack = -(s["battery_chem_delta_j"] + s["battery_c1_delta_j"])
    rhs = s["propulsion_energy_j"] + s["losses_j"] + s["link_stored_delta_j"]
    assert s["energy_from_source_j"] + pack == pytest.approx(rhs, rel=1e-12, abs=1e-9)
    link = s["rectifier_output_j"] + s["coil_losses_j"] + s["device_losses_j"] + s["link_stored_delta_j"]
    assert s["energy_from_source_j"] == pytest.approx(link, rel=1e-12)
    assert s["energy_balance_error_rel"] < 1e-12
    # the pad carried the load: its energy covers the propulsion and the link's losses, the pack's net share
    # within its band's energy
    assert abs(pack) <= v_cv * b.capacity_c * delta
