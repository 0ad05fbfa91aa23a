"""The mission loop as a class: one method per step, the carried state as documented slots.

:class:`MissionLoop` runs one mission (one drone, one receiver) over the trajectory samples; the
physics of each step is described in :mod:`mission_sim.world.runner`. Per trajectory interval
``[t_k, t_k+1)`` (:meth:`MissionLoop.run` -> :meth:`MissionLoop.sample`):

1. pose -> Lm: precomputed for all samples (``lm_all``, ``k_all``, ``p_all``: held over a sample);
2. pad gating: :meth:`MissionLoop.gate_pad`;
3. BMS command: :meth:`MissionLoop.bms_command`;
4. then either :meth:`MissionLoop.quiet_flight` (pad off, nothing pending: merged samples, no
   policy) or :meth:`MissionLoop.interval` (multi-rate: fine window steps :meth:`MissionLoop.fine_tick`
   / coarse steps, the window opened by :meth:`MissionLoop.open_window` and closed by
   :meth:`MissionLoop.window_done`), each step calling
5. policy: :meth:`MissionLoop.act` (observation per the contract, duty ``d_short``),
6. link + 7. battery node: :meth:`MissionLoop.step` (one exact ZOH link step with VL solved
   implicitly against the battery; :meth:`MissionLoop.fine_step` splits a fine step at I2 sign
   changes).

:meth:`MissionLoop.result` assembles the time series and the summary. Rows are handed over in
blocks as they are produced (:meth:`MissionLoop.flush`): to the summary's running quantities
(:class:`.stream.RowStats`), to an optional ``sink`` (e.g. :class:`.stream.SeriesWriter`, Parquet
row groups) and, with ``frame``, to the blocks of the DataFrame; memory stays bounded without it.
"""

from __future__ import annotations

import math

import numpy as np

from wpt_receiver.sbar import rectifier_v2

from ..contract import normalise_obs
from .battery import Battery, CcCvCharger, _ocv_cell_scalar, scalar_stepper
from .linkstep import LinkStepper
from .results import MissionResult
from .samples import ENERGISE_PHASES, MissionSamples
from .stream import BLOCK_ROWS, RowStats
from .trajectory import Trajectory

__all__ = ["MissionLoop", "ENERGISE_PHASES", "NonFiniteError"]


class NonFiniteError(ValueError):
    """A NaN or an infinity inside a run; :func:`mission_sim.world.runner.run_mission` adds the inputs
    that may have produced it (the config keys farthest from the default mission)."""

_FOUR_PI = 4.0 / math.pi
_COLUMNS = ("t_s", "dt_s", "_row", "lm_h", "v1_v", "i1_amp_a", "i2_amp_a", "d_short", "v2_v", "rect_current_a",
            "battery_v", "battery_current_a", "soc", "charge_cmd_a", "fine", "e_source_j", "e_coil_loss_j",
            "e_rectifier_j", "e_battery_chem_j", "e_battery_r0_j", "e_battery_r1_j", "e_battery_c1_j",
            "e_propulsion_j", "e_inverter_switches_j", "e_rectifier_diodes_j", "e_rectifier_switches_j")
DEVICE_GROUPS = ("inverter_switches", "rectifier_diodes", "rectifier_switches")


_STEP_STATE = ("x", "soc", "vrc", "peak_env", "peak_d", "above", "last_vl", "last_ib", "last_il")  # what step() writes
_COL = {name: j for j, name in enumerate(_COLUMNS)}  # column index by name
_SOC_COL = _COL["soc"]
_SOC_TOL = 1e-9  # SoC undershoot at a depletion cut set to 0 (rounding of the fixed point)


class _Depleted(Exception):
    """Raised by :meth:`MissionLoop.deplete` to end the run where the battery reached SoC 0."""


def _sign(v: float) -> float:
    return (v > 0.0) - (v < 0.0)


class MissionLoop:
    """One mission run: constants from the config, per-sample arrays, and the state the loop carries."""

    columns = _COLUMNS  # the layout of a row (and of the blocks handed to the sink)

    __slots__ = {
        # --- constants (set once)
        "cfg": "mission config", "policy": "the Policy (contract)", "traj": "the Trajectory",
        "charge": "False: pads never energised", "sim": "cfg.sim", "lk": "cfg.link",
        "base": "link parameters at the hover gap", "st": "LinkStepper (exact ZOH link steps)",
        "v1_nom": "nominal pad voltage amplitude [V]", "bp": "battery parameters",
        "bat": "Battery (vector of 1; synced for the charger)", "charger": "CcCvCharger (BMS)",
        "rng": "noise generator (seed, 1)", "dtc": "control period = fine step [s]",
        "k_on": "coupling to switch the pad on [-]", "k_off": "coupling to switch it off [-]",
        "ramp_rate": "pad V1 ramp rate [V/s]", "rated": "rated I2 [A]",
        "inv_sqrt_l1l2": "1/sqrt(L1 L2) [1/H] (k = Lm / sqrt(L1 L2))", "t_rect": "rectifier period 1/(2f) [s]",
        "r0": "battery R0 [ohm]", "r1b": "battery R1 [ohm]", "n_cells": "cells in series",
        "tau1": "battery R1-C1 time constant [s]", "bat_step": "scalar battery stepper",
        "dev": "DeviceSet (cfg.link.devices)", "vf": "forward drop of the rectifying path [V]",
        "dr_short": "shorted-SBAR resistance minus the folded Rd [ohm]",
        "peak_env": "peak |I2| of the envelope [A]", "peak_d": "duty at that peak [-]",
        # --- per-sample arrays (pose -> Lm, propulsion, gating eligibility)
        "lm_all": "Lm per sample [H]", "k_all": "coupling per sample [-]", "p_all": "propulsion power [W]",
        "t_all": "sample times [s]", "eligible": "sample in an energising phase (and charge)",
        "n": "number of samples", "samples": "samples.MissionSamples: the per-sample arrays, chunk by chunk",
        # --- loop state
        "x": "link envelope state (I1, I2) [A]", "v1": "pad voltage amplitude [V]",
        "tx_on": "pad wants to be on (V1 ramps to v1_nom) / off (to 0)", "cmd": "charge command I_L* [A]",
        "d": "SBAR duty d_short [-] (1: short mode)", "soc": "battery SoC [-]", "vrc": "battery R1-C1 voltage [V]",
        "last_vl": "last battery terminal voltage [V]", "last_ib": "last battery current [A]",
        "last_il": "last rectifier current [A]", "in_fine": "inside a fine window",
        "fine_until_min": "earliest end of the fine window [s]", "fine_deadline": "forced end of it [s]",
        "t_cmd_zero": "time the command went to 0 [s]", "t_last_bms": "last BMS update [s]",
        "t_last_act": "last policy call [s]", "w0": "initial stored link energy [J]",
        "peak_i2": "peak |I2| [A]", "above": "time with |I2| above rated [s]",
        "n_fine": "fine steps", "n_coarse": "coarse steps", "n_windows": "fine windows",
        "n_cut": "fine windows cut at max_fine_s", "rows": "one tuple per step (_COLUMNS)",
        "depleted_at": "time the battery reached SoC 0 (the mission ended there) [s], else None",
        "depleted_k": "trajectory sample where it did, else None",
        "compiled": "run the compiled fast path (mission_sim.world.fastpath) when it applies",
        "frame": "build the time-series DataFrame (False: the summary only, timeseries None)",
        "sink": "callable(loop, block) taking each block of rows (e.g. stream.SeriesWriter), or None",
        "stats": "stream.RowStats: the summary's running quantities", "blocks": "row blocks kept for the frame",
        "edge_j": "switching-edge energies so far (rectifier, inverter) [J] (add_edges)",
    }

    def __init__(self, cfg, policy, traj: Trajectory, charge: bool, lm_all, compiled: bool | None = None,
                 frame: bool = True, sink=None):
        self.cfg, self.policy, self.traj, self.charge = cfg, policy, traj, charge
        self.compiled, self.frame, self.sink = compiled, frame, sink
        self.sim, self.lk = sim, lk = cfg.sim, cfg.link
        model = cfg.coupling.model()
        self.base = base = lk.link_params(model.l1_h, model.l2_h, float(model.lm_h(0.0, 0.0, cfg.mission.hover_gap_m)))
        # devices, averaged (wpt_receiver.sbar.rectifier_v2_devices): the inverter's 2 Ron and the
        # rectifying path's Rd are folded into R1 / R2 of the stepper; the forward drops add to the
        # clamp VL; the shorted channels' excess over Rd enters V2 as (2 Ron - Rd) w(d) I2
        self.dev = dev = lk.device_set()
        self.vf, self.dr_short = dev.rect_vf_v, dev.short_r_ohm - dev.rect_rd_ohm
        self.st = LinkStepper(model.l1_h, model.l2_h, lk.r1_ohm + dev.inv_r_ohm, lk.r2_ohm + dev.rect_rd_ohm,
                              base.omega_rad_s)
        self.v1_nom = base.v1_amp_v
        self.bp = bp = cfg.battery
        self.bat = Battery(bp, 1)
        self.charger = CcCvCharger(cfg.charger, self.bat)
        self.rng = np.random.default_rng([cfg.seed, 1])
        self.dtc = sim.control_period_s
        self.k_on = cfg.coupling.tx_min_k + cfg.coupling.tx_k_hysteresis
        self.k_off = cfg.coupling.tx_min_k
        self.ramp_rate = self.v1_nom / lk.tx_ramp_s if lk.tx_ramp_s > 0 else math.inf
        self.rated = lk.rated_i2_a
        self.t_rect = 0.5 / base.f_hz
        self.r0, self.r1b, self.n_cells, self.tau1 = bp.r0_ohm, bp.r1_ohm, bp.n_series, bp.tau1_s
        self.bat_step = scalar_stepper(bp)
        self.inv_sqrt_l1l2 = 1.0 / math.sqrt(model.l1_h * model.l2_h)
        # the per-sample arrays come in chunks (the compiled path); materialise() makes all at once
        self.samples = MissionSamples(cfg, traj, charge, lm_all)
        self.n = self.samples.n
        self.lm_all = self.k_all = self.p_all = self.t_all = self.eligible = None
        self._reset_state()

    def _reset_state(self):
        self.x = (0.0, 0.0)
        self.v1 = 0.0
        self.tx_on = False
        self.cmd = 0.0
        self.d = 1.0  # short mode until told otherwise
        self.soc, self.vrc = float(self.bat.soc[0]), float(self.bat.v1_v[0])
        self.last_vl = float(self.bat.terminal_v(0.0)[0])
        self.last_ib = self.last_il = 0.0
        self.fine_until_min = self.fine_deadline = -1.0
        self.in_fine = False
        self.t_cmd_zero = self.t_last_bms = self.t_last_act = -math.inf
        self.policy.reset(1)
        self.w0 = self.st.stored_j(self.x)
        self.peak_i2 = self.above = 0.0
        self.peak_env, self.peak_d = 0.0, 1.0
        self.n_fine = self.n_coarse = self.n_windows = self.n_cut = 0
        self.rows = []
        self.blocks = []
        self.stats = RowStats(_COLUMNS, 2.0 * self.harmonics(2.0 * self.n_cells * 4.2).ripple_bound_a(),
                              self.bp.initial_soc)
        self.edge_j = (0.0, 0.0)      # switching-edge energies [J], rectifier and inverter (add_edges)
        self.depleted_at = self.depleted_k = None

    # ------------------------------------------------------------------ the outer loop
    def run(self, progress: bool = False) -> MissionResult:
        """Step through all trajectory intervals; returns the assembled result.

        ``compiled`` (None: when it applies, see :func:`.fastpath.usable`) runs the same loop compiled
        (:mod:`.loop_kernel`); the Python methods below are the reference it is tested against."""
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=self.samples.t_last_s - self.samples.t_first_s, unit="sim s", desc="mission", leave=False,
                       bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}]")
        if self.compiled is not False and self._run_fast(bar):
            if bar is not None:
                bar.close()
            return self.result()
        self.materialise()
        t_all, k = self.t_all, 0
        try:
            while k < self.n - 1:
                j = self.sample(k)
                if bar is not None:
                    bar.update(float(t_all[j]) - float(t_all[k]))
                k = j
                if len(self.rows) >= BLOCK_ROWS:
                    self.flush()
        except _Depleted:
            pass  # the mission ends where the battery ran out (see deplete)
        if bar is not None:
            bar.close()
        return self.result()

    def materialise(self):
        """The per-sample arrays of all samples at once (the reference path; the compiled one takes chunks)."""
        c = self.samples.chunk(0, self.n)
        self.t_all, self.lm_all, self.k_all, self.p_all = c.t_s, c.lm_h, c.k, c.p_w
        self.eligible = c.elig != 0.0

    def _run_fast(self, bar) -> bool:
        """The compiled run (:mod:`.fastpath`) if it applies; True when done. On an error status (or an
        interval too long) the state is reset for the reference path, which runs from the start."""
        from . import fastpath
        if not fastpath.usable(self):
            if self.compiled:
                raise ValueError("compiled=True needs numba, a policy with the kernel hook (mission_sim.contract."
                                 "Policy) and sim.i2_noise_a = 0; pass compiled=None or False")
            return False
        if fastpath.run_compiled(self, bar):
            return True
        if self.sink is not None and hasattr(self.sink, "restart"):
            self.sink.restart()  # rows of the abandoned compiled attempt
        self._reset_state()
        if bar is not None:
            bar.reset()
        return False

    def sample(self, k: int) -> int:
        """One trajectory sample k: gating, BMS, then quiet merged steps or the interval; next k."""
        t_k = float(self.t_all[k])
        # "ending" = the energising phase ends at the next sample, so charging stops (command 0,
        # then the pad ramps down) while the drone still hovers
        ending = self.eligible[k] and not self.eligible[k + 1]
        event = self.gate_pad(k, t_k, ending)
        event = self.bms_command(k, t_k, ending) or event
        if event:
            self.open_window(t_k)
        if not self.in_fine and not self.tx_on and self.v1 == 0.0 and self.cmd == 0.0:
            return self.quiet_flight(k, t_k)
        self.interval(k, t_k, ending)
        return k + 1

    # ------------------------------------------------------------------ pad gating, BMS
    def gate_pad(self, k: int, t_k: float, ending: bool) -> bool:
        """Pad gating (transmitter side) at sample k; True if it is an event (opens a fine window)."""
        kk = float(self.k_all[k])
        if self.tx_on:
            if kk < self.k_off:
                self.tx_on = False      # safety: switch off at once (ramp down)
                if self.cmd != 0.0:
                    self.t_cmd_zero = t_k
                self.cmd = 0.0
            elif not self.eligible[k] or ending:
                if self.cmd != 0.0:
                    self.cmd = 0.0
                    self.t_cmd_zero = t_k
                elif t_k - self.t_cmd_zero >= self.sim.tx_off_delay_s:
                    self.tx_on = False
                # else: the switch-off happens inside this interval
            else:
                return False
            return True
        if self.eligible[k] and not ending and kk >= self.k_on and self.v1 == 0.0:
            self.tx_on = True
            return True
        return False

    def bms_command(self, k: int, t_k: float, ending: bool) -> bool:
        """Battery management: new charge command every ``bms_period_s`` (deadband); True if changed."""
        sim = self.sim
        if not (self.tx_on and self.v1 == self.v1_nom and self.eligible[k] and not ending
                and t_k - self.t_last_bms >= sim.bms_period_s - 1e-12):
            return False
        self.t_last_bms = t_k
        self.bat.soc[0], self.bat.v1_v[0] = self.soc, self.vrc
        i_prop = self.p_all[k] / self.last_vl
        new = float(self.charger.command_a(i_prop)[0])
        if abs(new - self.cmd) > sim.cmd_deadband_a or (new == 0.0) != (self.cmd == 0.0):
            if new == 0.0:
                self.t_cmd_zero = t_k
            self.cmd = new
            return True
        return False

    # ------------------------------------------------------------------ multi-rate windowing
    def open_window(self, t: float):
        """Start a fine window at t (lasts at least ``min_fine_s``, at most ``max_fine_s``)."""
        self.in_fine = True
        self.n_windows += 1
        self.fine_until_min = t + self.sim.min_fine_s
        self.fine_deadline = t + self.sim.max_fine_s

    def quiet_flight(self, k: int, t_k: float) -> int:
        """Pad off, nothing pending: merge samples into one step of up to ``flight_dt_s``; next k.

        The SBAR has nothing to do: the policy is not called (its duty is held)."""
        t_all, eligible, n = self.t_all, self.eligible, self.n
        j = k + 1
        while j < n - 1 and not eligible[j] and t_all[j + 1] - t_k <= self.sim.flight_dt_s + 1e-9:
            j += 1
        dt = float(t_all[j] - t_k)
        p_mean = float(np.dot(self.p_all[k:j], np.diff(t_all[k:j + 1]))) / dt
        self.step(t_k, dt, float(self.lm_all[k]), p_mean, k, False)
        self.n_coarse += 1
        return j

    def interval(self, k: int, t_k: float, ending: bool):
        """One trajectory interval: fine steps while needed, then one coarse step to t_k+1.

        With the pad on and Lm changing fast within the interval (or k crossing the switch-off
        threshold), fine steps use Lm interpolated linearly in time and gating is checked per step.
        """
        sim = self.sim
        t_next = float(self.t_all[k + 1])
        p_k = float(self.p_all[k])
        lm = float(self.lm_all[k])
        lm_n = float(self.lm_all[k + 1])
        fast_lm = abs(lm_n - lm) > sim.lm_rel_tol * max(abs(lm), 1e-9) or float(self.k_all[k + 1]) < self.k_off
        off_due = not self.eligible[k] or ending
        t = t_k
        fresh = False
        while t < t_next - 1e-12:
            if fast_lm and self.v1 > 0.0 and not self.in_fine:
                self.open_window(t)
            if not self.in_fine and t - self.t_last_act >= sim.coarse_policy_period_s - 1e-12:
                fresh = self.coarse_policy(t)
            if self.in_fine:
                dt = min(self.dtc, t_next - t)
                lm_s = lm
                if fast_lm:
                    lm_s = lm + (lm_n - lm) * (t + 0.5 * dt - t_k) / (t_next - t_k)
                self.fine_tick(t, dt, lm_s, p_k, k, fast_lm, off_due, fresh)
                fresh = False
                t += dt
            else:
                self.step(t, t_next - t, lm, p_k, k, False)
                self.n_coarse += 1
                t = t_next

    def coarse_policy(self, t: float) -> bool:
        """Policy call outside a fine window; a duty move above ``duty_event_tol`` opens one.

        Returns True if it did (that call's duty is then applied in the first fine step)."""
        d_new = self.act(t)
        self.t_last_act = t
        moved = abs(d_new - self.d) > self.sim.duty_event_tol
        self.d = d_new
        if moved:
            self.open_window(t)
        return moved

    def fine_tick(self, t: float, dt: float, lm_s: float, p_k: float, k: int, fast_lm: bool, off_due: bool,
                  fresh: bool):
        """One fine step at t: per-step gating and V1 ramp, policy call, link step, window end check."""
        if fast_lm and self.tx_on and lm_s * self.inv_sqrt_l1l2 < self.k_off:
            self.tx_on = False
            self.cmd = 0.0
        if self.tx_on and self.cmd == 0.0 and off_due and t - self.t_cmd_zero >= self.sim.tx_off_delay_s:
            self.tx_on = False
        v1 = self.v1
        target = self.v1_nom if self.tx_on else 0.0
        if v1 != target:
            step_v = self.ramp_rate * dt
            self.v1 = v1 = min(target, v1 + step_v) if target > v1 else max(target, v1 - step_v)
        d_prev = self.d
        if not fresh:
            self.d = self.act(t)
        self.t_last_act = t
        self.fine_step(t, dt, lm_s, p_k, k)
        self.n_fine += 1
        if fast_lm and v1 > 0.0:
            return
        self.window_done(t + dt, d_prev, lm_s)

    def window_done(self, t: float, d_prev: float, lm: float):
        """Close the fine window once the SBAR output and I2 have settled (or at its deadline).

        Settles on the SBAR's output (V2 / ((4/pi) VL) = 1 - sin(pi d / 2)), not on the duty: near
        short mode the duty is ill-conditioned (arcsin) while V2 has settled."""
        sim = self.sim
        dv = abs(math.sin(0.5 * math.pi * self.d) - math.sin(0.5 * math.pi * d_prev))
        if t >= self.fine_until_min and (dv < sim.settle_duty_tol or self.v1 == 0.0) and self.settled(lm):
            self.in_fine = False
        elif t >= self.fine_deadline and self.v1 == (self.v1_nom if self.tx_on else 0.0):
            self.in_fine = False
            self.n_cut += 1

    def settled(self, lm: float) -> bool:
        """V1 at its target and I2 within ``settle_i2_tol_a`` of the steady state for the held inputs."""
        v1, x, tol = self.v1, self.x, self.sim.settle_i2_tol_a
        if abs(v1 - (self.v1_nom if self.tx_on else 0.0)) > 0.0:
            return False
        if v1 == 0.0:  # pad off: the duty no longer matters once the coil currents have died out
            return abs(x[0]) < tol and abs(x[1]) < tol
        st = self.st
        c = _FOUR_PI * (1.0 - math.sin(0.5 * math.pi * self.d))
        wlm = self.base.omega_rad_s * lm
        r2 = st.r2 + self.dr_short * (self.d + math.sin(math.pi * self.d) / math.pi)
        det = st.r1 * r2 + wlm * wlm
        i2ss = (wlm * v1 - st.r1 * c * (self.last_vl + self.vf)) / det if lm > 0 else 0.0
        return abs(x[1] - i2ss) < tol

    # ------------------------------------------------------------------ policy
    def act(self, t: float) -> float:
        """Policy step at time ``t`` [s]: observation per the contract (measured |I2| + optional noise,
        time since the command went to 0, saturating at 1 s here and at 10 ms in the contract), duty in [0, 1]."""
        sim = self.sim
        t_since = min(t - self.t_cmd_zero, 1.0) if self.cmd == 0.0 else 0.0
        # the receiver's sensor measures the magnitude of the coil current envelope
        i2m = abs(self.x[1]) + (sim.i2_noise_a * self.rng.standard_normal() if sim.i2_noise_a > 0 else 0.0)
        obs = normalise_obs(np.array([[i2m, self.last_vl, self.last_ib, self.last_il, self.soc, self.cmd, self.d, t_since]]))
        out = float(np.asarray(self.policy.act(obs)).reshape(-1)[0])
        if not math.isfinite(out):
            raise NonFiniteError(f"policy {getattr(self.policy, 'name', self.policy)!r} returned d_short={out!r}; "
                             f"valid range: [0, 1]")
        return min(max(out, 0.0), 1.0)

    # ------------------------------------------------------------------ link + battery node
    def fine_step(self, t0: float, dt: float, lm: float, p_prop: float, row_k: int):
        """A fine step; split into rectifier-period sub-steps when I2 changes sign inside it.

        V2 = f(d) VL sign(I2) switches with the sign of the envelope; holding the sign of the step's
        start over a step that is a sizeable part of the envelope's ringing period (2 pi / wd ~ 250 us)
        would feed the ringing instead of damping it. The envelope model resolves one rectifier period
        T = 1/(2f) anyway, so the crossing is resolved to T (the duty is held: the policy is not called).
        """
        x, d, v1, t_rect = self.x, self.d, self.v1, self.t_rect
        if v1 > 0.0 and d < 1.0 and dt > 1.5 * t_rect and x[1] != 0.0:
            st = self.st
            lm_eff = lm if lm > 0 else 1e-12
            v2p = (_FOUR_PI * (1.0 - math.sin(0.5 * math.pi * d)) * (self.last_vl + self.vf) * (1.0 if x[1] > 0.0 else -1.0)
                   + self.dr_short * (d + math.sin(math.pi * d) / math.pi) * x[1])
            samples = st.i2_samples(lm_eff, dt, x, v1, v2p, m=8)
            (_, _, d10, d11), (_, _, bd10, bd11), _, _ = st.disc(lm_eff, dt)
            samples.append(d10 * x[0] + d11 * x[1] + bd10 * v1 + bd11 * v2p)
            if any(s * x[1] <= 0.0 for s in samples):
                k_sub = math.ceil(dt / t_rect - 1e-9)
                h = dt / k_sub
                for j in range(k_sub):
                    self.step(t0 + j * h, h, lm, p_prop, row_k, True)
                return
        self.step(t0, dt, lm, p_prop, row_k, True)

    def step(self, t0: float, dt: float, lm: float, p_prop: float, row_k: int, fine: bool):
        """Link (eq. 4, exact ZOH) and battery node over one step, VL solved implicitly; appends a row.

        Hot path: fields are bound to locals at the top and written back at the end."""
        x, v1, d, soc, vrc, st, tau1 = self.x, self.v1, self.d, self.soc, self.vrc, self.st, self.tau1
        # SBAR fundamental (eq. 9). The diodes conduct with the instantaneous i2, so v2 is in phase with
        # i2 whatever the sign of its envelope: a negative amplitude is i2 shifted by pi (one rectifier
        # period, so the clocked short window still sits on a half-cycle peak) and V2 = f(d) sign(I2):
        # the rectifier always absorbs power. With the pad off the diodes block: nothing drives current
        # through them against the battery and the coil currents ring down in R1, R2 (the envelope model
        # has no diode to stop I2 at zero, so holding V2 over a long step would drive I2 to -V2/R2).
        c = rectifier_v2(d, 1.0, x[1], sin=math.sin, sign=_sign) if v1 > 0.0 else 0.0  # V2 per volt of VL
        # devices: V2 = c (VL + Vf) + (2 Ron - Rd) w(d) I2 (the last held at the step's start)
        w_short = d + math.sin(math.pi * d) / math.pi
        v2x = c * self.vf + (self.dr_short * w_short * x[1] if v1 > 0.0 else 0.0)
        # battery: mean terminal voltage = A0 + G * i_mean (held-current RC solution); solve VL
        # implicitly with the link so V2, the battery and the propulsion power agree exactly
        frac = tau1 * (1.0 - math.exp(-dt / tau1)) / dt
        a0 = self.n_cells * _ocv_cell_scalar(soc) + vrc * frac
        g = self.r0 + self.r1b * (1.0 - frac)
        lm_eff = lm if lm > 0 else 1e-12
        dsc = st.disc(lm_eff, dt)
        m10, m11, g1, s1 = dsc[3]
        s0 = m10 * x[0] + m11 * x[1] + g1 * v1 + s1 * v2x
        alpha = 1.0 - g * c * c * s1 / (2 * dt)
        beta = a0 + g * c * s0 / (2 * dt)
        disc = beta * beta - 4 * alpha * g * p_prop
        if disc < 0:
            raise ValueError(f"the battery cannot supply the propulsion power {p_prop:.1f} W at t={t0:.2f} s "
                             f"(SoC {soc:.3f}, phase {self.traj.phase[row_k]}): valid range: below its maximum "
                             f"{beta * beta / (4 * alpha * g):.1f} W; lighten the drone (drone.mass_kg, "
                             f"drone.payload_kg) or use a bigger battery (battery.n_series, battery.capacity_ah)")
        vl = (beta + math.sqrt(disc)) / (2 * alpha)
        v2 = c * vl + v2x
        if fine:
            self.track_peak(st.i2_samples(lm_eff, dt, x, v1, v2), d, dt / 4)
        x1, e_src, e_coil, e_rect, int_i2 = st.step(lm_eff, dt, x, v1, v2, dsc)
        i_l = 0.5 * c * int_i2 / dt
        i_p = p_prop / vl
        i_b = i_l - i_p
        soc, vrc, e_chem, e_r0, e_r1, e_c1, _ = self.bat_step(soc, vrc, i_b, dt)
        if soc < 0.0:
            soc = self.deplete(t0, dt, lm, p_prop, row_k, fine, i_b, soc)
        self.track_peak((x1[1],), d, dt / 4 if fine else dt)
        self.x, self.soc, self.vrc = x1, soc, vrc
        self.last_vl, self.last_ib, self.last_il = vl, i_b, i_l
        e_out = vl * i_l * dt
        self.rows.append((t0 + dt, dt, row_k, lm, v1, x1[0], x1[1], d, v2, i_l, vl, i_b, soc, self.cmd, fine,
                          e_src, *self.device_split(e_coil + e_rect - e_out, i_l * dt, w_short, e_out, e_chem, e_r0,
                                                    e_r1, e_c1, vl * i_p * dt)))

    def track_peak(self, i2_values, d: float, dt_each: float):
        """Running peak of |I2| (a negative envelope is a current of that size shifted by pi), the duty
        there, and the time above rated (``dt_each`` per value)."""
        for i2s in i2_values:
            i2s = abs(i2s)
            if i2s > self.peak_env:
                self.peak_env, self.peak_d = i2s, d
            if i2s > self.rated:
                self.above += dt_each

    def device_split(self, e_loss: float, charge_c: float, w_short: float, *rest):
        """``(coils, *rest, inverter switches, rectifier diodes, rectifier switches)`` [J] (the row's
        order) of a step whose link losses (coils + devices) are ``e_loss``: the coils take
        ``(R1 int I1^2 + R2 int I2^2) / 2``, the devices the folded resistances' share of
        the stepper's ``int I^2`` (:attr:`LinkStepper.last_p`), the forward drops ``Vf0 * charge``
        (``charge_c`` = int I_L dt) and the short-window excess; the rectifier switches take what
        is left, so the three plus the coils add up to ``e_loss`` exactly."""
        p11, p22 = self.st.last_p
        dev, lk = self.dev, self.lk
        e_inv = 0.5 * dev.inv_r_ohm * p11
        e_dio = dev.rect_diode.vf0_v * charge_c + 0.5 * dev.rect_diode.rd_ohm * p22 * (1.0 - w_short)
        e_coil = 0.5 * (lk.r1_ohm * p11 + lk.r2_ohm * p22)
        e_sw = 0.0 if dev.is_ideal else e_loss - e_coil - e_inv - e_dio
        return (e_loss if dev.is_ideal else e_coil), *rest, e_inv, e_dio, e_sw

    def deplete(self, t0: float, dt: float, lm: float, p_prop: float, row_k: int, fine: bool, i_b: float,
                soc_end: float) -> float:
        """The battery reaches SoC 0 inside this step (``soc_end < 0``): cut the step there and end the mission.

        SoC is linear in time for the step's held current, so it crosses 0 after ``h = SoC0 Q / -I_b``;
        I_b depends a little on the step length (VL is solved with the battery), so ``h`` is refined by
        re-running the step (fixed point; the state before it is restored between tries). The cut step
        is the run's last row, with SoC 0 to rounding (``_SOC_TOL``); ``depleted_at`` / ``depleted_k``
        record where, and ``_Depleted`` ends :meth:`run`. Called inside such a re-run, it returns
        ``soc_end`` unchanged."""
        if self.depleted_at is not None:
            return soc_end
        soc0, cap = self.soc, self.bp.capacity_c
        saved = tuple(getattr(self, name) for name in _STEP_STATE)
        self.depleted_at, h = t0, dt
        for _ in range(20):
            h = min(dt, soc0 * cap / -i_b) if i_b < 0.0 else dt
            if h <= 1e-12:  # already empty at t0
                h = 0.0
                break
            self.step(t0, h, lm, p_prop, row_k, fine)
            if abs(self.soc) <= _SOC_TOL:
                break
            i_b = self.last_ib
            self.rows.pop()
            for name, value in zip(_STEP_STATE, saved):
                setattr(self, name, value)
        if h > 0.0 and self.soc < 0.0:
            self.soc = 0.0
            self.rows[-1] = self.rows[-1][:_SOC_COL] + (0.0,) + self.rows[-1][_SOC_COL + 1:]
        self.depleted_at, self.depleted_k = t0 + h, row_k
        raise _Depleted

    def depletion_summary(self) -> dict:
        """Summary keys on where the battery ran out: ``battery_depleted``, ``depleted_at_s`` and
        ``depleted_pad_distance_m`` (drone to the nearest pad centre; both None if it did not)."""
        if self.depleted_at is None:
            return {"battery_depleted": False, "depleted_at_s": None, "depleted_pad_distance_m": None}
        pads = np.array([[p.x_m, p.y_m, p.z_m] for p in self.cfg.pads])
        dist = np.linalg.norm(pads - self.samples.pose([self.depleted_k])[0][0], axis=1)
        return {"battery_depleted": True, "depleted_at_s": float(self.depleted_at),
                "depleted_pad_distance_m": float(dist.min())}

    # ------------------------------------------------------------------ result assembly
    def flush(self):
        """Hand the rows produced so far (``rows``: tuples, or an array view from the compiled path) over
        as one block: to :attr:`stats`, the ``sink`` and (``frame``) the kept blocks; ``rows`` empties."""
        arr = np.array(self.rows, dtype=float).reshape(-1, len(_COLUMNS))
        self.rows = []
        if not len(arr):
            return
        self.stats.add(arr, self.peak_env)
        self.add_edges(arr)
        if self.sink is not None:
            self.sink(self, arr)
        if self.frame:
            self.blocks.append(arr)

    def result(self) -> MissionResult:
        """The time series (one row per step; None with ``frame`` False) and the summary with the energy balances."""
        self.flush()
        df = None
        if self.frame:
            arr = np.concatenate(self.blocks) if self.blocks else np.empty((0, len(_COLUMNS)))
            self.blocks = []
            df = self.timeseries(arr)
        return MissionResult(timeseries=df, summary=self.summary(), config=self.cfg, trajectory=self.traj)

    def harmonics(self, vl_v: float):
        """:class:`wpt_receiver.peak.SbarHarmonics` at the hover-gap Lm and battery voltage ``vl_v`` [V]."""
        from wpt_receiver.peak import SbarHarmonics
        return SbarHarmonics(self.base.with_(vl_v=vl_v), self.dev)

    def timeseries(self, arr):
        """DataFrame of the steps: the raw columns plus pose, k, tx_on, powers and phase."""
        import pandas as pd
        df = pd.DataFrame({name: arr[:, j] for j, name in enumerate(_COLUMNS)})
        df["fine"] = df["fine"].astype(bool)
        df["_row"] = df["_row"].astype(np.int64)
        ri = df.pop("_row").to_numpy()
        pos, phase = self.samples.pose(ri)
        df.insert(2, "x_m", pos[:, 0])
        df.insert(3, "y_m", pos[:, 1])
        df.insert(4, "z_m", pos[:, 2])
        df.insert(6, "k", df["lm_h"].to_numpy() * self.inv_sqrt_l1l2)
        df.insert(7, "tx_on", df["v1_v"].to_numpy() > 0)
        dts = df["dt_s"].to_numpy()
        df["propulsion_w"] = df["e_propulsion_j"] / dts
        df["p_source_w"] = df["e_source_j"] / dts
        df["p_coil_loss_w"] = df["e_coil_loss_j"] / dts
        df["p_battery_loss_w"] = (df["e_battery_r0_j"] + df["e_battery_r1_j"]) / dts
        df["phase"] = pd.Categorical(phase)
        return df

    def summary(self) -> dict:
        """Summary dict: energies (exact sums), balance errors, SoC, I2 peak, step counts (from :attr:`stats`)."""
        bp, st, smp = self.bp, self.stats, self.samples
        self.peak_i2 = self.instantaneous_peak()
        return {
            "policy": getattr(self.policy, "name", type(self.policy).__name__),
            "charge": bool(self.charge),
            "sim_time_s": float((smp.t_last_s if self.depleted_at is None else self.depleted_at) - smp.t_first_s),
            "wall_s": 0.0,
            **self.energy_summary(),
            "initial_soc": float(bp.initial_soc),
            "final_soc": float(self.soc),
            "battery_full": bool(self.charger.full[0]),
            "min_soc": float(min(st.min_soc, bp.initial_soc)),
            **self.depletion_summary(),
            "peak_i2_a": self.peak_i2,
            "peak_i2_envelope_a": self.peak_env,
            "rated_i2_a": self.rated,
            "time_above_rated_s": self.above,
            "flight_time_gain_s": 0.0,
            "fine_steps": self.n_fine,
            "coarse_steps": self.n_coarse,
            "fine_windows": self.n_windows,
            "fine_windows_cut": self.n_cut,
            "charge_time_s": st.sums["charge_time_s"],
        }

    def energy_summary(self) -> dict:
        """Energies [J] (exact sums), per device group, efficiency and the two balances.

        ``rectifier_output_j`` is the SBAR's DC output into the battery node (sum VL I_L dt; most of
        it feeds the motors while hovering over a pad), ``battery_charge_in_j`` the gross energy into
        the battery terminals while it charges (sum VL I_batt dt over I_batt > 0), and
        ``propulsion_energy_j`` what the motors drew. ``dc_to_battery_efficiency`` = rectifier
        output / inverter DC input (``energy_from_source_j``)."""
        sums = self.stats.sums
        acc = {key: sums[c] for key, c in (
            ("src", "e_source_j"), ("coil", "e_coil_loss_j"), ("rect", "e_rectifier_j"), ("chem", "e_battery_chem_j"),
            ("r0", "e_battery_r0_j"), ("r1", "e_battery_r1_j"), ("c1", "e_battery_c1_j"), ("prop", "e_propulsion_j"))}
        groups = {f"{g}_loss_j": sums[f"e_{g}_j"] for g in DEVICE_GROUPS}
        dev = math.fsum(groups.values())
        charge_in = sums["charge_in_j"]
        dw = self.st.stored_j(self.x) - self.w0
        losses = math.fsum([acc["coil"], dev, acc["r0"], acc["r1"]])
        rhs = math.fsum([acc["chem"], acc["c1"], dw, losses, acc["prop"]])
        scale = abs(acc["src"]) + abs(acc["chem"]) + abs(acc["prop"])
        link_res = math.fsum([acc["src"], -dw, -acc["coil"], -dev, -acc["rect"]])
        return {
            "energy_from_source_j": acc["src"],
            "rectifier_output_j": acc["rect"],
            "battery_charge_in_j": charge_in,
            "propulsion_energy_j": acc["prop"],
            "dc_to_battery_efficiency": acc["rect"] / acc["src"] if acc["src"] > 0 else 0.0,
            "battery_chem_delta_j": acc["chem"],
            "losses_j": losses,
            "coil_losses_j": acc["coil"],
            "battery_losses_j": acc["r0"] + acc["r1"],
            "device_losses_j": dev,
            **groups,
            "devices": self.dev.name,
            "link_stored_delta_j": dw,
            "battery_c1_delta_j": acc["c1"],
            "energy_balance_error_rel": abs(acc["src"] - rhs) / scale if scale > 0 else 0.0,
            "link_balance_error_rel": abs(link_res) / abs(acc["src"]) if acc["src"] else 0.0,
            **self.edge_summary(acc["src"], acc["rect"]),
        }

    def add_edges(self, arr) -> None:
        """Accumulate the switching-edge energies [J] of a block of rows into :attr:`edge_j`
        (rectifier, inverter): :func:`wpt_receiver.edge_losses.averaged_edge_losses` at each step's
        duty, |I2| and battery voltage while the pad is on (SBAR: hard gate edges, recovery;
        inverter: hard-switched Coss, an upper bound)."""
        from wpt_receiver.edge_losses import averaged_edge_losses
        on = arr[:, _COL["v1_v"]] > 0
        if not on.any():
            return
        dt = arr[:, _COL["dt_s"]] * on
        f = self.lk.f_hz
        e = averaged_edge_losses(arr[:, _COL["d_short"]], arr[:, _COL["i2_amp_a"]], arr[:, _COL["battery_v"]], self.dev,
                                 0.5 / f, 2 * math.pi * f, vdc_v=self.lk.vdc_v)
        self.edge_j = (math.fsum([self.edge_j[0], *(np.asarray(e["rectifier_w"]) * dt).tolist()]),
                       math.fsum([self.edge_j[1], *(np.broadcast_to(e["inverter_w"], dt.shape) * dt).tolist()]))

    def edge_summary(self, src_j: float, rect_j: float) -> dict:
        """Switching-edge energies [J] of the run (:meth:`add_edges`; estimated beside the run, not in
        the balances above), and the efficiency with them drawn from the source."""
        e_rect, e_inv = self.edge_j
        den = src_j + e_rect + e_inv
        return {"edge_losses_rectifier_j": e_rect, "edge_losses_inverter_j": e_inv,
                "dc_to_battery_efficiency_with_edges": rect_j / den if den > 0 else 0.0}

    def instantaneous_peak(self) -> float:
        """Instantaneous peak |i2| [A]: the envelope's peak plus the harmonic ripple of the SBAR at
        that duty (:class:`wpt_receiver.peak.SbarHarmonics`, at the hover-gap Lm and the highest
        battery voltage seen with the pad on), over the envelope's peak and every step whose |I2|
        is within the ripple bound of it (the ripple depends on the duty; the steps are the
        candidates :class:`.stream.RowStats` kept): screened with the tabulated
        :class:`wpt_receiver.peak.PeakTable`, evaluated exactly where the table is within 1 % of its maximum."""
        if self.peak_env == 0.0:
            return 0.0
        from wpt_receiver.peak import PeakTable
        st = self.stats
        vl = st.vl_on_max if st.vl_on_max > -math.inf else float(self.last_vl)
        harm = self.harmonics(vl)
        d, i2c = st.screened(self.peak_env - 2.0 * harm.ripple_bound_a(), (self.peak_d, self.peak_env),
                             lambda i2_min: PeakTable(harm, i2_max_a=1.05 * self.peak_env, n_d=26, n_i=21,
                                                      i2_min_a=i2_min))
        return float(np.max(harm.peak(d, i2c)))
