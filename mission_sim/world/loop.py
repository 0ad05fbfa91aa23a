"""The mission loop: orchestration in Python, the physics compiled (:mod:`.loop_kernel`).

:class:`MissionLoop` runs one mission (one drone, one receiver) over the trajectory samples; the
physics of each step is described in :mod:`mission_sim.world.runner`, and every formula of it lives
once, in :mod:`.loop_kernel` (numba): per trajectory interval ``[t_k, t_k+1)`` pad gating, the BMS
command, quiet flight (merged samples) or the multi-rate interval (fine window steps around events,
coarse steps in between), the policy's observation, the link's exact ZOH step with VL solved
implicitly against the battery, the depletion cut and the row. This class keeps what is not
physics: the constants from the config, the per-sample arrays (pose -> Lm, propulsion, gating
eligibility), the driver (:func:`.fastpath.run`: the kernel in chunks, progress, a Python policy's
:meth:`MissionLoop.act` when the kernel asks for a duty, sensor noise drawn from the seeded
generator, errors worded), and the result.

:meth:`MissionLoop.result` assembles the time series and the summary. Rows are handed over in
blocks as they are produced (:meth:`MissionLoop.flush`): to the summary's running quantities
(:class:`.stream.RowStats`), to an optional ``sink`` (e.g. :class:`.stream.SeriesWriter`, Parquet
row groups) and, with ``frame``, to the blocks of the DataFrame; memory stays bounded without it.
"""

from __future__ import annotations

import math

import numpy as np

from .results import MissionResult
from .samples import ENERGISE_PHASES, MissionSamples
from .stream import RowStats
from .trajectory import Trajectory

__all__ = ["MissionLoop", "ENERGISE_PHASES", "NonFiniteError"]


class NonFiniteError(ValueError):
    """A NaN or an infinity inside a run; :func:`mission_sim.world.runner.run_mission` adds the inputs
    that may have produced it (the config keys farthest from the default mission)."""

_COLUMNS = ("t_s", "dt_s", "_row", "lm_h", "v1_v", "i1_amp_a", "i2_amp_a", "d_short", "v2_v", "rect_current_a",
            "battery_v", "battery_current_a", "soc", "charge_cmd_a", "fine", "e_source_j", "e_coil_loss_j",
            "e_rectifier_j", "e_battery_chem_j", "e_battery_r0_j", "e_battery_r1_j", "e_battery_c1_j",
            "e_propulsion_j", "e_inverter_switches_j", "e_rectifier_diodes_j", "e_rectifier_switches_j")
DEVICE_GROUPS = ("inverter_switches", "rectifier_diodes", "rectifier_switches")
_COL = {name: j for j, name in enumerate(_COLUMNS)}  # column index by name


class MissionLoop:
    """One mission run: constants from the config, per-sample arrays, the kernel's records, the result."""

    columns = _COLUMNS  # the layout of a row (and of the blocks handed to the sink)

    __slots__ = {
        # --- constants (set once; packed into the kernel's constants record by fastpath.pack_constants)
        "cfg": "mission config", "policy": "the Policy (contract)", "traj": "the Trajectory",
        "charge": "False: pads never energised", "sim": "cfg.sim", "lk": "cfg.link",
        "base": "link parameters at the hover gap", "l1": "primary inductance [H]", "l2": "secondary inductance [H]",
        "v1_nom": "nominal pad voltage amplitude [V]", "bp": "battery parameters",
        "rng": "noise generator (seed, 1)", "dtc": "control period = fine step [s]",
        "k_on": "coupling to switch the pad on [-]", "k_off": "coupling to switch it off [-]",
        "ramp_rate": "pad V1 ramp rate [V/s]", "rated": "rated I2 [A]",
        "inv_sqrt_l1l2": "1/sqrt(L1 L2) [1/H] (k = Lm / sqrt(L1 L2))", "t_rect": "rectifier period 1/(2f) [s]",
        "dev": "DeviceSet (cfg.link.devices)",
        # --- per-sample arrays (pose -> Lm, propulsion, gating eligibility), chunk by chunk
        "samples": "samples.MissionSamples: the per-sample arrays, chunk by chunk as the loop advances",
        # --- the kernel's records (loop_kernel.CONST_DTYPE / STATE_DTYPE, 1 element each) and the output
        "consts": "the constants record", "state": "the state record (the final state after run)",
        "compiled": "None: the policy's kernel() hook when it has one; False: always its Python act(); "
                    "True: require the hook",
        "frame": "build the time-series DataFrame (False: the summary only, timeseries None)",
        "sink": "callable(loop, block) taking each block of rows (e.g. stream.SeriesWriter), or None",
        "rows": "rows not yet handed over (array view of the kernel's buffer)",
        "stats": "stream.RowStats: the summary's running quantities", "blocks": "row blocks kept for the frame",
        "edge_j": "switching-edge energies so far (rectifier, inverter) [J] (add_edges)",
    }

    def __init__(self, cfg, policy, traj: Trajectory, charge: bool, lm_all, compiled: bool | None = None,
                 frame: bool = True, sink=None):
        self.cfg, self.policy, self.traj, self.charge = cfg, policy, traj, charge
        self.compiled, self.frame, self.sink = compiled, frame, sink
        self.sim, self.lk = sim, lk = cfg.sim, cfg.link
        model = cfg.coupling.model()
        self.l1, self.l2 = model.l1_h, model.l2_h
        # (its VL is LinkParams' default 30 V, whatever the pack: each step clamps at its own battery_v + Vf, the link
        # constants hold no VL, and the SBAR table (wpt_receiver.modal_kernel.build_table) holds VL only through the
        # inverter's harmonics against the clamp. Measured 2026-11-28 with the table built at the pack's CV voltage
        # instead: the default 8S mission (pack 32.28-32.90 V; table at 32.8 V) step peak 31.2757 -> 31.2766 A,
        # charge in 4083.40 -> 4083.35 J; a 4S pack (15.90-16.53 V; table at 16.4 V) step 31.070 -> 31.062 A,
        # model_based 13.203 -> 13.196 A, energies within 1e-5. Left at 30 V: the table's disk-cache key holds the
        # whole link. The policies' link carries the pack's voltage: config.policy_context)
        self.base = base = lk.link_params(model.l1_h, model.l2_h, float(model.lm_h(0.0, 0.0, cfg.mission.hover_gap_m)))
        # devices, averaged (wpt_receiver.sbar.rectifier_v2_devices): the inverter's 2 Ron and the
        # rectifying path's Rd fold into R1 / R2 of the link; the forward drops add to the clamp VL;
        # the shorted channels' excess over Rd enters V2 as (2 Ron - Rd) w(d) I2 (loop_kernel._step)
        self.dev = lk.device_set()
        self.v1_nom = base.v1_amp_v
        self.bp = cfg.battery
        self.rng = np.random.default_rng([cfg.seed, 1])
        self.dtc = sim.control_period_s
        self.k_on = cfg.coupling.tx_min_k + cfg.coupling.tx_k_hysteresis
        self.k_off = cfg.coupling.tx_min_k
        self.ramp_rate = self.v1_nom / lk.tx_ramp_s if lk.tx_ramp_s > 0 else math.inf
        self.rated = lk.rated_i2_a
        self.t_rect = base.rectifier_period_s
        self.inv_sqrt_l1l2 = 1.0 / math.sqrt(model.l1_h * model.l2_h)
        self.samples = MissionSamples(cfg, traj, charge, lm_all)   # lm_all: per sample, a constant or None
        self.consts = self.state = None
        self.rows = []
        self.blocks = []
        self.stats = RowStats(_COLUMNS, self.bp.initial_soc)
        sched = self.samples.schedule
        if sched is not None:   # the propulsion energy after the first release that drops payload
            drops = np.flatnonzero(np.diff(np.concatenate([[sched.takeoff_mass_kg], sched.mass_after_kg])) != 0)
            self.stats.split_at(float(sched.release_t_s[drops[0]]))
        self.edge_j = (0.0, 0.0)      # switching-edge energies [J], rectifier and inverter (add_edges)

    def run(self, progress: bool = False) -> MissionResult:
        """Run the mission (:func:`.fastpath.run`: the compiled loop, this object's Python side on demand);
        returns the assembled result."""
        from . import fastpath
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=self.samples.t_last_s - self.samples.t_first_s, unit="sim s", desc="mission", leave=False,
                       bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}]")
        self.policy.reset(1)
        try:
            fastpath.run(self, bar)
        finally:
            if bar is not None:
                bar.close()
        return self.result()

    def act(self, obs) -> float:
        """A Python policy's duty for the observation ``obs`` (one normalised row per the contract, written
        by the kernel: measured |I2| with the sensor noise, battery, command, last duty, time since the
        stop); the kernel checks it is finite and clips it into [0, 1]."""
        return float(np.asarray(self.policy.act(obs.reshape(1, -1).copy())).reshape(-1)[0])

    def fail(self, status: str, st):
        """Raise the error of the kernel's status ``status`` (``ERR_POWER``, ``ERR_POLICY``), worded with the
        numbers it left in the state record ``st``."""
        if status == "ERR_POWER":
            raise ValueError(f"the battery cannot supply the propulsion power {st['err_p']:.1f} W at t={st['err_t']:.2f} s "
                             f"(SoC {st['err_soc']:.3f}, phase {self.samples.pose([st['err_k']])[1][0]}): valid range: below its "
                             f"maximum {st['err_pmax']:.1f} W; lighten the drone (drone.mass_kg, drone.payload_kg) or "
                             "use a bigger battery (battery.n_series, battery.capacity_ah)")
        if status == "ERR_POLICY":
            raise NonFiniteError(f"policy {getattr(self.policy, 'name', self.policy)!r} returned "
                                 f"d_short={float(st['duty_in'])!r}; valid range: [0, 1]")
        raise RuntimeError(f"mission kernel status {status}")  # not reached

    @property
    def st(self):
        """The state record (attribute access: ``loop.st.soc``)."""
        return self.state.view(np.recarray)[0]

    def depletion_summary(self) -> dict:
        """Summary keys on where the battery ran out: ``battery_depleted``, ``depleted_at_s`` and
        ``depleted_pad_distance_m`` (drone to the nearest pad centre; both None if it did not)."""
        st = self.st
        if math.isnan(st.depleted_at):
            return {"battery_depleted": False, "depleted_at_s": None, "depleted_pad_distance_m": None}
        pads = np.array([[p.x_m, p.y_m, p.z_m] for p in self.cfg.pads])
        dist = np.linalg.norm(pads - self.samples.pose([st.depleted_k])[0][0], axis=1)
        return {"battery_depleted": True, "depleted_at_s": float(st.depleted_at),
                "depleted_pad_distance_m": float(dist.min())}

    # ------------------------------------------------------------------ result assembly
    def flush(self):
        """Hand the rows produced so far (``rows``: tuples, or an array view from the compiled path) over
        as one block: to :attr:`stats`, the ``sink`` and (``frame``) the kept blocks; ``rows`` empties."""
        arr = np.array(self.rows, dtype=float).reshape(-1, len(_COLUMNS))
        self.rows = []
        if not len(arr):
            return
        self.stats.add(arr)
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
        if self.cfg.drone.payload_kg > 0:   # (a payload: the mass each row flew, dropped at its releases)
            df["mass_kg"] = self.samples.row_mass_kg(ri, df["t_s"].to_numpy(), dts)
        df["p_source_w"] = df["e_source_j"] / dts
        df["p_coil_loss_w"] = df["e_coil_loss_j"] / dts
        df["p_battery_loss_w"] = (df["e_battery_r0_j"] + df["e_battery_r1_j"]) / dts
        df["phase"] = pd.Categorical(phase)
        return df

    def summary(self) -> dict:
        """Summary dict: energies (exact sums), balance errors, SoC, I2 peak, step counts (from :attr:`stats`)."""
        bp, st, ks, smp = self.bp, self.stats, self.st, self.samples
        end = smp.t_last_s if math.isnan(ks.depleted_at) else ks.depleted_at
        return {
            "policy": getattr(self.policy, "name", type(self.policy).__name__),
            "charge": bool(self.charge),
            "sim_time_s": float(end - smp.t_first_s),
            "wall_s": 0.0,
            **self.energy_summary(),
            "initial_soc": float(bp.initial_soc),
            "final_soc": float(ks.soc),
            "battery_full": bool(ks.full),
            "min_soc": float(min(st.min_soc, bp.initial_soc)),
            **self.depletion_summary(),
            "peak_i2_a": (peak_i2_a := self.instantaneous_peak()),
            "peak_i2_envelope_a": float(ks.peak_env),
            "rated_i2_a": self.rated,
            "time_above_rated_s": float(ks.above),
            **self.rating_summary(peak_i2_a),
            "flight_time_gain_s": 0.0,
            "fine_steps": int(ks.n_fine),
            "coarse_steps": int(ks.n_coarse),
            "fine_windows": int(ks.n_windows),
            "fine_windows_cut": int(ks.n_cut),
            "charge_time_s": st.sums["charge_time_s"],
            **self.payload_summary(),
        }

    def payload_summary(self) -> dict:
        """With a payload (``drone.payload_kg`` > 0): the take-off and landing masses [kg], the number of releases
        and the time of the first [s] (None without one; scalars only: a sweep stores the summary as columns)
        and the propulsion energy [J] before and after the first release that dropped payload (split at the sample
        the mass changes on: a quiet-flight step merging samples across it is split by its samples' powers, held
        over each sample as the loop holds them, :meth:`_share_after`); nothing otherwise."""
        drone, smp = self.cfg.drone, self.samples
        if not drone.payload_kg > 0:
            return {}
        sched = getattr(smp.traj, "mass", None)
        times = [] if sched is None else [float(t) for t in sched.release_t_s]
        out = {"takeoff_mass_kg": float(drone.total_mass_kg),
               "landing_mass_kg": float(drone.total_mass_kg if sched is None else sched.final_mass_kg),
               "payload_releases": len(times), "first_release_t_s": times[0] if times else None}
        if smp.mass_changes:
            after = self.stats.sums_after
            if self.stats.straddle is not None:
                after = math.fsum([after, self._share_after(*self.stats.straddle, self.stats.t_split)])
            out["propulsion_energy_before_release_j"] = self.stats.sums["e_propulsion_j"] - after
            out["propulsion_energy_after_release_j"] = after
        return out

    def _share_after(self, start_s: float, end_s: float, t_release_s: float) -> float:
        """The propulsion energy [J] of the step ``[start_s, end_s]`` from the first sample at or after
        ``t_release_s`` on (the first at the lighter mass, :class:`~.trajectory.MassSchedule`): each sample's power
        held over its period, as the loop integrates it (:meth:`.samples.MissionSamples.chunk`)."""
        smp = self.samples
        sched = smp.schedule
        dt = sched.dt_s
        k_drop = max(int(math.floor(t_release_s / dt)) - 1, 0)
        while sched.at_samples([k_drop])[0] == sched.takeoff_mass_kg:   # (the schedule's own rule: one or two steps)
            k_drop += 1
        k_end = min(int(math.ceil(end_s / dt - 1e-9)), smp.n)
        if k_end <= k_drop:
            return 0.0
        last = smp.last
        try:
            c = smp.chunk(k_drop, k_end)
        finally:
            smp.last = last   # (pose() reads the loop's last chunk)
        t0 = np.maximum(c.t_s, start_s)
        t1 = np.minimum(c.t_s + dt, end_s)
        return math.fsum((c.p_w * np.maximum(t1 - t0, 0.0)).tolist())

    def rating_summary(self, peak_i2_a: float) -> dict:
        """The rectifier's continuous current rating [A] and its part (:func:`wpt_receiver.devices.current_rating`
        of ``link.devices``: the lowest of its diode leg's and switch's), to read beside ``peak_i2_a``, None for
        ``ideal`` devices; and ``rectifier_required_a``, the rating ``dronewpt sizing``'s rule asks of a part for
        that peak (:meth:`wpt_receiver.sizing.SizingRules.required_rating_a`: ``margin`` x the peak, conservative:
        a millisecond peak against the part's average rating)."""
        from wpt_receiver.devices import current_rating
        from wpt_receiver.sizing import SizingRules
        held = current_rating(self.lk.devices)
        return {"rectifier_rating_a": None if held is None else float(held[0]),
                "rectifier_rating_part": None if held is None else held[1],
                "rectifier_required_a": SizingRules(margin=SizingRules.margin).required_rating_a(peak_i2_a)}

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
        ks = self.st
        dw = float(ks.w_end)  # the link's stored energy at the end (exact modes); from rest: W0 = 0
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
        duty, |I2| and battery voltage while the pad is on, the SBAR node's capacitance at that battery voltage
        (:func:`wpt_receiver.devices.rect_node_c_f`; it was Table I's 30 V's until 2026-11-27 night) (SBAR: hard gate
        edges, recovery; inverter: hard-switched Coss at the link's Vdc, an upper bound)."""
        from wpt_receiver.devices import rect_node_c_f
        from wpt_receiver.edge_losses import averaged_edge_losses
        on = arr[:, _COL["v1_v"]] > 0
        if not on.any():
            return
        dt = arr[:, _COL["dt_s"]] * on
        b = self.base   # (the link's periods: LinkParams' one source of T and omega)
        vl = arr[:, _COL["battery_v"]]   # (the SBAR blocks each step's own pack voltage: its capacitance there)
        e = averaged_edge_losses(arr[:, _COL["d_short"]], arr[:, _COL["i2_amp_a"]], vl, self.dev,
                                 b.rectifier_period_s, b.omega_rad_s, vdc_v=self.lk.vdc_v,
                                 c_rect_f=rect_node_c_f(self.lk.devices, vl))
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
        """Instantaneous peak |i2| [A], tracked by the kernel at every step and the fine steps' quarter
        points: the exact-mode fundamental (phase included) plus the SBAR's harmonic ripple at that duty,
        phase and clamp voltage (:func:`wpt_receiver.modal_kernel.inst_peak`, the table of
        :class:`wpt_receiver.peak.SbarHarmonics` at the hover-gap Lm)."""
        return float(self.st.peak_inst)
