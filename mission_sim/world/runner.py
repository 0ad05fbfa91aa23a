"""The mission runner: trajectory -> Lm -> link -> policy -> battery, closed loop, multi-rate.

Loop (one drone, one receiver):

1. **Trajectory samples** (``sim.traj_dt_s``): pose -> Lm(pose) of the nearest pad (lookup table,
   held over the sample), propulsion power (momentum theory, held over the sample), phase.
2. **Pad gating** (transmitter side): the pad energises only in a "charge"/"hover" phase (the
   drone asks for power) and while ``k >= tx_min_k + tx_k_hysteresis``; it switches off as soon
   as ``k < tx_min_k`` (the steady secondary current ~ V1/(w Lm) would exceed the rating) or the
   phase ends. On and off are linear V1 ramps over ``link.tx_ramp_s`` (soft start), always
   simulated in fine steps. Before a planned switch-off the charge command drops to 0 first and
   the pad stays on ``sim.tx_off_delay_s`` so the receiver reaches short mode under power.
3. **Battery management** (:class:`~mission_sim.world.battery.CcCvCharger`) sets the charge command
   ``I_L*`` every ``sim.bms_period_s`` (propulsion current + CC/CV battery current, 0 when full);
   changes below ``sim.cmd_deadband_a`` are not applied.
4. **Policy** (:class:`mission_sim.contract.Policy`): observation built exactly per the contract
   (``normalise_obs`` of i2, battery V and current, rectifier current, SoC, command, last duty),
   output ``d_short``; the SBAR applies ``V2 = (4/pi) VL (1 - sin(pi d / 2))`` (eq. 9) with VL the
   battery terminal voltage.
5. **Link** (paper eq. 4): exact ZOH steps with exact energy integrals
   (:class:`~mission_sim.world.linkstep.LinkStepper`).
6. **Battery node**: rectifier current ``I_L = V2 I2 / (2 VL)``, battery current ``I_L - P_prop / VL``.
   The battery sees the step-mean current (the SBAR's smoothing capacitor), and VL of a step is
   solved *implicitly* (a quadratic) so that the link's V2, the battery's mean terminal voltage
   and the propulsion power agree exactly; every energy then closes to rounding.

**Multi-rate.** *Fine* steps of ``sim.control_period_s`` (the policy's ``control_period_s``: it is
called once per step) run around every event: pad ramps, command changes, a duty change returned
by the policy, fast Lm changes with the pad on. A fine window lasts at least ``min_fine_s`` and
ends when the SBAR output ``1 - sin(pi d / 2)`` (= V2 / ((4/pi) VL), eq. 9) moves less than
``settle_duty_tol`` per step and I2 is within ``settle_i2_tol_a`` of the steady state for the held
inputs (or after ``max_fine_s``); with the pad off it ends once the coil currents have died out.
Otherwise *coarse* steps run to the next trajectory sample (Lm, power held: the ZOH step is exact
for any length) with the policy called at most every ``coarse_policy_period_s`` and its duty held
in between; if that duty moves by more than ``duty_event_tol`` a fine window starts.
With the pad off and nothing pending, samples are merged into steps of up to ``sim.flight_dt_s``
and the policy is not called (the SBAR has nothing to do; its duty is held).

Sensor noise: ``sim.i2_noise_a`` (default 0: none) adds seeded Gaussian noise to the i2
observation only. Peak I2 and time above rated are taken on 4 points per fine step and on the
ends of coarse steps.
"""

from __future__ import annotations

import math
import time

import numpy as np

from wpt_receiver.sbar import rectifier_v2

from .battery import Battery, CcCvCharger, _ocv_cell_scalar, scalar_stepper
from ..contract import normalise_obs
from .linkstep import LinkStepper
from .power import hover_power_w
from .results import MissionResult
from .trajectory import Trajectory, plan_mission

__all__ = ["run_mission", "ENERGISE_PHASES"]

ENERGISE_PHASES = ("charge", "hover")
_FOUR_PI = 4.0 / math.pi


def _sign(v: float) -> float:
    return (v > 0.0) - (v < 0.0)


def _pad_offsets(cfg, traj: Trajectory):
    """Offsets (N, 3) of the receiver from the nearest pad (horizontally) and that pad's index."""
    pads = np.array([[p.x_m, p.y_m, p.z_m] for p in cfg.pads])
    d = traj.pos_m[:, None, :2] - pads[None, :, :2]
    idx = np.argmin(np.einsum("nkj,nkj->nk", d, d), axis=1)
    return traj.pos_m - pads[idx], idx


def _lm_along(cfg, model, traj: Trajectory):
    off, idx = _pad_offsets(cfg, traj)
    lm = np.zeros(len(traj))
    rho_max, z_min, z_max = model.table_range_m
    near = (np.hypot(off[:, 0], off[:, 1]) < rho_max) & (off[:, 2] < z_max) & (off[:, 2] > 0.5 * z_min)
    if np.any(near):
        lm[near] = model.lm_h(off[near, 0], off[near, 1], off[near, 2], traj.tilt_rad[near],
                              tilt_axis_rad=traj.tilt_axis_rad[near])
    return lm, idx


def run_mission(cfg, policy, *, trajectory: Trajectory | None = None, charge: bool = True,
                progress: bool = False) -> MissionResult:
    """Run one mission; returns a :class:`~mission_sim.world.results.MissionResult`.

    ``policy`` is a :class:`mission_sim.contract.Policy` made for ``control_period_s =
    cfg.sim.control_period_s`` and ``rated_i2_a = cfg.link.rated_i2_a``. ``charge=False`` runs the
    same mission with the pads never energised. With ``charge=True`` the summary's
    ``flight_time_gain_s`` compares against that run (see :func:`flight_time_gain_s`).
    """
    wall0 = time.perf_counter()
    traj = plan_mission(cfg) if trajectory is None else trajectory
    lm_all = _lm_along(cfg, cfg.coupling.model(), traj)[0]
    res = _simulate(cfg, policy, traj, charge, progress, lm_all)
    if charge:
        base = _simulate(cfg, policy, traj, False, False, lm_all)
        res.summary["flight_time_gain_s"] = flight_time_gain_s(cfg, res.summary["final_soc"],
                                                               base.summary["final_soc"])
        res.summary["final_soc_without_charging"] = base.summary["final_soc"]
        res.summary["battery_depleted_without_charging"] = base.summary["battery_depleted"]
    else:
        res.summary["flight_time_gain_s"] = 0.0
        res.summary["final_soc_without_charging"] = res.summary["final_soc"]
        res.summary["battery_depleted_without_charging"] = res.summary["battery_depleted"]
    res.summary["wall_s"] = time.perf_counter() - wall0
    res.summary["realtime_factor"] = res.summary["sim_time_s"] / max(res.summary["wall_s"], 1e-12)
    return res


def flight_time_gain_s(cfg, final_soc_charged: float, final_soc_uncharged: float) -> float:
    """Extra hover time [s] the charged mission ends with: the difference of the usable chemical
    energy left (``n Q int_0^SoC OCV``, SoC clipped into [0, 1]: a depleted baseline counts as 0)
    divided by the electrical hover power."""
    e = cfg.battery.usable_energy_j
    return float((e(final_soc_charged) - e(final_soc_uncharged)) / hover_power_w(cfg.drone))


def _simulate(cfg, policy, traj: Trajectory, charge: bool, progress: bool, lm_all=None) -> MissionResult:
    sim, lk = cfg.sim, cfg.link
    model = cfg.coupling.model()
    base = lk.link_params(model.l1_h, model.l2_h, float(model.lm_h(0.0, 0.0, cfg.mission.hover_gap_m)))
    st = LinkStepper(model.l1_h, model.l2_h, lk.r1_ohm, lk.r2_ohm, base.omega_rad_s)
    v1_nom = base.v1_amp_v
    bp = cfg.battery
    bat = Battery(bp, 1)
    charger = CcCvCharger(cfg.charger, bat)
    rng = np.random.default_rng([cfg.seed, 1])
    dtc = sim.control_period_s
    k_on = cfg.coupling.tx_min_k + cfg.coupling.tx_k_hysteresis
    k_off = cfg.coupling.tx_min_k
    ramp_rate = v1_nom / lk.tx_ramp_s if lk.tx_ramp_s > 0 else math.inf
    rated = lk.rated_i2_a

    if lm_all is None:
        lm_all = _lm_along(cfg, model, traj)[0]
    inv_sqrt_l1l2 = 1.0 / math.sqrt(model.l1_h * model.l2_h)
    k_all = lm_all * inv_sqrt_l1l2
    p_all = traj.propulsion_w(cfg.drone)
    t_all = traj.t_s
    eligible = np.isin(traj.phase, ENERGISE_PHASES) & charge
    n = len(t_all)

    # --- state
    x = (0.0, 0.0)
    v1 = 0.0
    tx_on = False           # pad wants to be on (V1 ramps towards v1_nom) / off (towards 0)
    cmd = 0.0
    d = 1.0                 # short mode until told otherwise
    soc, vrc = float(bat.soc[0]), float(bat.v1_v[0])
    r0, r1b, n_cells = bp.r0_ohm, bp.r1_ohm, bp.n_series
    tau1 = bp.tau1_s
    bat_step = scalar_stepper(bp)
    last_vl = float(bat.terminal_v(0.0)[0])
    last_ib = 0.0
    last_il = 0.0
    fine_until_min = -1.0
    fine_deadline = -1.0
    in_fine = False
    t_cmd_zero = -math.inf
    t_last_bms = -math.inf
    t_last_act = -math.inf
    policy.reset(1)

    w0 = st.stored_j(x)
    peak_i2 = 0.0
    above = 0.0
    n_fine = n_coarse = n_windows = n_cut = 0
    rows = []
    phase = traj.phase
    pos_all = traj.pos_m

    def act():
        # the receiver's sensor measures the magnitude of the coil current envelope
        i2m = abs(x[1]) + (sim.i2_noise_a * rng.standard_normal() if sim.i2_noise_a > 0 else 0.0)
        obs = normalise_obs(np.array([[i2m, last_vl, last_ib, last_il, soc, cmd, d]]))
        out = float(np.asarray(policy.act(obs)).reshape(-1)[0])
        if not math.isfinite(out):
            raise ValueError(f"policy {getattr(policy, 'name', policy)!r} returned d_short={out!r}; "
                             f"valid range: [0, 1]")
        return min(max(out, 0.0), 1.0)

    def do_step(t0, dt, lm, p_prop, row_k, fine):
        nonlocal x, last_vl, last_ib, last_il, peak_i2, above, soc, vrc
        # SBAR fundamental (eq. 9). The diodes conduct with the instantaneous i2, so v2 is in phase with
        # i2 whatever the sign of its envelope: a negative amplitude is i2 shifted by pi (one rectifier
        # period, so the clocked short window still sits on a half-cycle peak) and V2 = f(d) sign(I2):
        # the rectifier always absorbs power. With the pad off the diodes block: nothing drives current
        # through them against the battery and the coil currents ring down in R1, R2 (the envelope model
        # has no diode to stop I2 at zero, so holding V2 over a long step would drive I2 to -V2/R2).
        c = rectifier_v2(d, 1.0, x[1], sin=math.sin, sign=_sign) if v1 > 0.0 else 0.0  # V2 per volt of VL
        # battery: mean terminal voltage = A0 + G * i_mean (held-current RC solution); solve VL
        # implicitly with the link so V2, the battery and the propulsion power agree exactly
        frac = tau1 * (1.0 - math.exp(-dt / tau1)) / dt
        a0 = n_cells * _ocv_cell_scalar(soc) + vrc * frac
        g = r0 + r1b * (1.0 - frac)
        lm_eff = lm if lm > 0 else 1e-12
        dsc = st.disc(lm_eff, dt)
        m10, m11, g1, s1 = dsc[3]
        s0 = m10 * x[0] + m11 * x[1] + g1 * v1
        alpha = 1.0 - g * c * c * s1 / (2 * dt)
        beta = a0 + g * c * s0 / (2 * dt)
        disc = beta * beta - 4 * alpha * g * p_prop
        if disc < 0:
            raise ValueError(f"the battery cannot supply the propulsion power {p_prop:.1f} W at t={t0:.2f} s "
                             f"(SoC {soc:.3f}, phase {traj.phase[row_k]}): valid range: below its maximum "
                             f"{beta * beta / (4 * alpha * g):.1f} W; lighten the drone (drone.mass_kg, "
                             f"drone.payload_kg) or use a bigger battery (battery.n_series, battery.capacity_ah)")
        vl = (beta + math.sqrt(disc)) / (2 * alpha)
        v2 = c * vl
        if fine:
            for i2s in st.i2_samples(lm_eff, dt, x, v1, v2):
                i2s = abs(i2s)  # a negative envelope is a current of that size shifted by pi
                if i2s > peak_i2:
                    peak_i2 = i2s
                if i2s > rated:
                    above += dt / 4
        x1, e_src, e_coil, e_rect, int_i2 = st.step(lm_eff, dt, x, v1, v2, dsc)
        i_l = 0.5 * c * int_i2 / dt
        i_p = p_prop / vl
        i_b = i_l - i_p
        soc, vrc, e_chem, e_r0, e_r1, e_c1, _ = bat_step(soc, vrc, i_b, dt)
        x = x1
        if abs(x1[1]) > peak_i2:
            peak_i2 = abs(x[1])
        if abs(x[1]) > rated:
            above += dt / 4 if fine else dt
        last_vl, last_ib, last_il = vl, i_b, i_l
        rows.append((t0 + dt, dt, row_k, lm, v1, x[0], x[1], d, v2, i_l, vl, i_b, soc, cmd, fine,
                     e_src, e_coil, e_rect, e_chem, e_r0, e_r1, e_c1, vl * i_p * dt))

    t_rect = 0.5 / base.f_hz

    def fine_step(t0, dt, lm, p_prop, row_k):
        """A fine step; split into rectifier-period sub-steps when I2 changes sign inside it.

        V2 = f(d) VL sign(I2) switches with the sign of the envelope; holding the sign of the step's
        start over a step that is a sizeable part of the envelope's ringing period (2 pi / wd ~ 250 us)
        would feed the ringing instead of damping it. The envelope model resolves one rectifier period
        T = 1/(2f) anyway, so the crossing is resolved to T (the duty is held: the policy is not called).
        """
        if v1 > 0.0 and d < 1.0 and dt > 1.5 * t_rect and x[1] != 0.0:
            lm_eff = lm if lm > 0 else 1e-12
            v2p = _FOUR_PI * (1.0 - math.sin(0.5 * math.pi * d)) * last_vl * (1.0 if x[1] > 0.0 else -1.0)
            samples = st.i2_samples(lm_eff, dt, x, v1, v2p, m=8)
            (_, _, d10, d11), (_, _, bd10, bd11), _, _ = st.disc(lm_eff, dt)
            samples.append(d10 * x[0] + d11 * x[1] + bd10 * v1 + bd11 * v2p)
            if any(s * x[1] <= 0.0 for s in samples):
                k_sub = math.ceil(dt / t_rect - 1e-9)
                h = dt / k_sub
                for j in range(k_sub):
                    do_step(t0 + j * h, h, lm, p_prop, row_k, True)
                return
        do_step(t0, dt, lm, p_prop, row_k, True)

    def settled(lm):
        if abs(v1 - (v1_nom if tx_on else 0.0)) > 0.0:
            return False
        if v1 == 0.0:  # pad off: the duty no longer matters once the coil currents have died out
            return abs(x[0]) < sim.settle_i2_tol_a and abs(x[1]) < sim.settle_i2_tol_a
        c = _FOUR_PI * (1.0 - math.sin(0.5 * math.pi * d))
        wlm = base.omega_rad_s * lm
        det = lk.r1_ohm * lk.r2_ohm + wlm * wlm
        i2ss = (wlm * v1 - lk.r1_ohm * c * last_vl) / det if lm > 0 else 0.0
        return abs(x[1] - i2ss) < sim.settle_i2_tol_a

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=float(t_all[-1] - t_all[0]), unit="sim s", desc="mission", leave=False,
                   bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}]")

    k = 0
    while k < n - 1:
        t_k = float(t_all[k])
        lm = float(lm_all[k])
        kk = float(k_all[k])
        event = False
        # ---- pad gating (transmitter side); "ending" = the energising phase ends at the next sample,
        # so charging stops (command 0, then the pad ramps down) while the drone still hovers
        ending = eligible[k] and not eligible[k + 1]
        if tx_on:
            if kk < k_off:
                tx_on = False           # safety: switch off at once (ramp down)
                cmd = 0.0
                event = True
            elif not eligible[k] or ending:
                if cmd != 0.0:
                    cmd = 0.0
                    t_cmd_zero = t_k
                    event = True
                elif t_k - t_cmd_zero >= sim.tx_off_delay_s:
                    tx_on = False
                    event = True
                else:
                    event = True        # the switch-off happens inside this interval
        elif eligible[k] and not ending and kk >= k_on and v1 == 0.0:
            tx_on = True
            event = True
        # ---- battery management
        if tx_on and v1 == v1_nom and eligible[k] and not ending and t_k - t_last_bms >= sim.bms_period_s - 1e-12:
            t_last_bms = t_k
            bat.soc[0], bat.v1_v[0] = soc, vrc
            i_prop = p_all[k] / last_vl
            new = float(charger.command_a(i_prop)[0])
            if abs(new - cmd) > sim.cmd_deadband_a or (new == 0.0) != (cmd == 0.0):
                if new == 0.0:
                    t_cmd_zero = t_k
                cmd = new
                event = True
        if event:
            in_fine = True
            n_windows += 1
            fine_until_min = t_k + sim.min_fine_s
            fine_deadline = t_k + sim.max_fine_s
        t_next = float(t_all[k + 1])
        # ---- quiet flight: merge samples
        quiet = (not in_fine and not tx_on and v1 == 0.0 and cmd == 0.0)
        if quiet:
            j = k + 1
            while j < n - 1 and not eligible[j] and t_all[j + 1] - t_k <= sim.flight_dt_s + 1e-9:
                j += 1
            dt = float(t_all[j] - t_k)
            p_mean = float(np.dot(p_all[k:j], np.diff(t_all[k:j + 1]))) / dt
            # pad off, nothing pending: the SBAR has nothing to do, the policy is not called
            do_step(t_k, dt, lm, p_mean, k, False)
            n_coarse += 1
            if bar is not None:
                bar.update(dt)
            k = j
            continue
        # ---- one trajectory interval: fine steps while needed, then one coarse step to t_next.
        # With the pad on and Lm changing fast within the interval (or k crossing the switch-off
        # threshold), fine steps use Lm interpolated linearly in time and gating is checked per step.
        p_k = float(p_all[k])
        lm_n = float(lm_all[k + 1])
        fast_lm = abs(lm_n - lm) > sim.lm_rel_tol * max(abs(lm), 1e-9) or float(k_all[k + 1]) < k_off
        t = t_k
        fresh = False
        while t < t_next - 1e-12:
            if fast_lm and v1 > 0.0 and not in_fine:
                in_fine = True
                n_windows += 1
                fine_until_min = t + sim.min_fine_s
                fine_deadline = t + sim.max_fine_s
            if not in_fine and t - t_last_act >= sim.coarse_policy_period_s - 1e-12:
                d_new = act()
                t_last_act = t
                if abs(d_new - d) <= sim.duty_event_tol:
                    d = d_new
                else:
                    d = d_new
                    fresh = True  # this call's duty is applied in the first fine step
                    in_fine = True
                    n_windows += 1
                    fine_until_min = t + sim.min_fine_s
                    fine_deadline = t + sim.max_fine_s
            if in_fine:
                dt = min(dtc, t_next - t)
                lm_s = lm
                if fast_lm:
                    lm_s = lm + (lm_n - lm) * (t + 0.5 * dt - t_k) / (t_next - t_k)
                    if tx_on and lm_s * inv_sqrt_l1l2 < k_off:
                        tx_on = False
                        cmd = 0.0
                if tx_on and cmd == 0.0 and (not eligible[k] or ending) and t - t_cmd_zero >= sim.tx_off_delay_s:
                    tx_on = False
                target = v1_nom if tx_on else 0.0
                if v1 != target:
                    step_v = ramp_rate * dt
                    v1 = min(target, v1 + step_v) if target > v1 else max(target, v1 - step_v)
                d_prev = d
                if fresh:
                    fresh = False
                else:
                    d = act()
                t_last_act = t
                fine_step(t, dt, lm_s, p_k, k)
                n_fine += 1
                t += dt
                if fast_lm and v1 > 0.0:
                    continue
                # settle on the SBAR's output (V2 / ((4/pi) VL) = 1 - sin(pi d / 2)), not on the duty:
                # near short mode the duty is ill-conditioned (arcsin) while V2 has settled
                dv = abs(math.sin(0.5 * math.pi * d) - math.sin(0.5 * math.pi * d_prev))
                if t >= fine_until_min and (dv < sim.settle_duty_tol or v1 == 0.0) and settled(lm_s):
                    in_fine = False
                elif t >= fine_deadline and v1 == (v1_nom if tx_on else 0.0):
                    in_fine = False
                    n_cut += 1
            else:
                dt = t_next - t
                do_step(t, dt, lm, p_k, k, False)
                n_coarse += 1
                t = t_next
        if bar is not None:
            bar.update(t_next - t_k)
        k += 1
    if bar is not None:
        bar.close()

    import pandas as pd
    names = ("t_s", "dt_s", "_row", "lm_h", "v1_v", "i1_amp_a", "i2_amp_a", "d_short", "v2_v", "rect_current_a",
             "battery_v", "battery_current_a", "soc", "charge_cmd_a", "fine", "e_source_j", "e_coil_loss_j",
             "e_rectifier_j", "e_battery_chem_j", "e_battery_r0_j", "e_battery_r1_j", "e_battery_c1_j",
             "e_propulsion_j")
    arr = np.array(rows, dtype=float).reshape(-1, len(names))
    df = pd.DataFrame({name: arr[:, j] for j, name in enumerate(names)})
    df["fine"] = df["fine"].astype(bool)
    df["_row"] = df["_row"].astype(np.int64)
    ri = df.pop("_row").to_numpy()
    pos = pos_all[ri]
    df.insert(2, "x_m", pos[:, 0])
    df.insert(3, "y_m", pos[:, 1])
    df.insert(4, "z_m", pos[:, 2])
    df.insert(6, "k", df["lm_h"].to_numpy() * inv_sqrt_l1l2)
    df.insert(7, "tx_on", df["v1_v"].to_numpy() > 0)
    dts = df["dt_s"].to_numpy()
    df["propulsion_w"] = df["e_propulsion_j"] / dts
    df["p_source_w"] = df["e_source_j"] / dts
    df["p_coil_loss_w"] = df["e_coil_loss_j"] / dts
    df["p_battery_loss_w"] = (df["e_battery_r0_j"] + df["e_battery_r1_j"]) / dts
    df["phase"] = pd.Categorical(phase[ri])
    col = {name: j for j, name in enumerate(names)}
    acc = {key: math.fsum(arr[:, col[c]].tolist()) for key, c in (
        ("src", "e_source_j"), ("coil", "e_coil_loss_j"), ("rect", "e_rectifier_j"), ("chem", "e_battery_chem_j"),
        ("r0", "e_battery_r0_j"), ("r1", "e_battery_r1_j"), ("c1", "e_battery_c1_j"), ("prop", "e_propulsion_j"))}
    dw = st.stored_j(x) - w0
    losses = acc["coil"] + acc["r0"] + acc["r1"]
    lhs = acc["src"]
    rhs = math.fsum([acc["chem"], acc["c1"], dw, losses, acc["prop"]])
    scale = abs(acc["src"]) + abs(acc["chem"]) + abs(acc["prop"])
    link_res = math.fsum([acc["src"], -dw, -acc["coil"], -acc["rect"]])
    summary = {
        "policy": getattr(policy, "name", type(policy).__name__),
        "charge": bool(charge),
        "sim_time_s": float(t_all[-1] - t_all[0]),
        "wall_s": 0.0,
        "energy_from_source_j": acc["src"],
        "energy_to_battery_j": acc["rect"],
        "battery_chem_delta_j": acc["chem"],
        "losses_j": losses,
        "coil_losses_j": acc["coil"],
        "battery_losses_j": acc["r0"] + acc["r1"],
        "device_losses_j": 0.0,
        "link_stored_delta_j": dw,
        "battery_c1_delta_j": acc["c1"],
        "propulsion_energy_j": acc["prop"],
        "energy_balance_error_rel": abs(lhs - rhs) / scale if scale > 0 else 0.0,
        "link_balance_error_rel": abs(link_res) / abs(acc["src"]) if acc["src"] else 0.0,
        "initial_soc": float(bp.initial_soc),
        "final_soc": float(soc),
        "battery_full": bool(charger.full[0]),
        "min_soc": float(min(df["soc"].min(), bp.initial_soc)) if len(df) else float(bp.initial_soc),
        "battery_depleted": bool(len(df) and df["soc"].min() < 0.0),
        "peak_i2_a": peak_i2,
        "rated_i2_a": rated,
        "time_above_rated_s": above,
        "flight_time_gain_s": 0.0,
        "fine_steps": n_fine,
        "coarse_steps": n_coarse,
        "fine_windows": n_windows,
        "fine_windows_cut": n_cut,
        "charge_time_s": float(np.sum(dts[df["tx_on"].to_numpy()])),
    }
    return MissionResult(timeseries=df, summary=summary, config=cfg, trajectory=traj)
