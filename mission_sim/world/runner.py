"""The mission runner: trajectory -> Lm -> link -> policy -> battery, closed loop, multi-rate.

:func:`run_mission` plans the trajectory (in blocks, :class:`~.trajectory.PlannedTrajectory`) and runs the
loop, :class:`~mission_sim.world.loop.MissionLoop`, twice: charged and uncharged (for
:func:`flight_time_gain_s`). Every formula of a loop step exists once, compiled, in
:mod:`~mission_sim.world.loop_kernel` (the function doing each step in brackets); the Python side
(:mod:`~mission_sim.world.loop`, :mod:`~mission_sim.world.fastpath`) orchestrates.

Loop (one drone, one receiver):

1. **Trajectory samples** (``sim.traj_dt_s``): pose -> Lm(pose) of the nearest pad (lookup table,
   held over the sample), propulsion power (momentum theory at the sample's mass: the route's payload releases,
   :class:`~.trajectory.MassSchedule`; held over the sample), phase
   [:class:`~.samples.MissionSamples`, chunk by chunk as the loop advances (:func:`.fastpath.window`);
   ``loop_kernel.advance`` -> ``_begin_sample`` per sample].
2. **Pad gating** (transmitter side): the pad energises only in a "charge"/"hover" phase (the
   drone asks for power) and while ``k >= tx_min_k + tx_k_hysteresis``; it switches off as soon
   as ``k < tx_min_k`` (the steady secondary current ~ V1/(w Lm) would exceed the rating) or the
   phase ends. On and off are linear V1 ramps over ``link.tx_ramp_s`` (soft start), always
   simulated in fine steps. Before a planned switch-off the charge command drops to 0 first and
   the pad stays on ``sim.tx_off_delay_s`` so the receiver reaches short mode under power
   [``_gate_pad``; per fine step inside ``_fine_begin``]. After the ramp's end, while the coil currents ring,
   the receiver's protection holds the SBAR at d = 0 (diodes only; ``sim.rectify_after_pad_off``, default
   true; the rows record the applied duty); false: v2 = 0, a shorted secondary (the model before 2026-11-28:
   the primary's energy beats into it within a step, docs/mission.md "Pad switch-off") [``_protecting``].
3. **Battery management** (CC-CV, :mod:`~mission_sim.world.battery`) sets the charge command
   ``I_L*`` every ``sim.bms_period_s`` (load current + CC/CV battery current; when full the load current less
   the CV law's current above CV, the charger's power path; a new charge cycle at each pad switch-on); changes
   below ``sim.cmd_deadband_a`` are not applied, except entering or leaving *full* [``_bms_command``,
   ``_charger_command``].
4. **Policy** (:class:`mission_sim.contract.Policy`): observation built exactly per the contract
   (normalised i2, battery V and current, rectifier current, SoC, command, last duty, time since
   the stop), output ``d_short``; the SBAR applies its v2 fundamental: eq. 9's ``(4/pi) VL (1 - sin(pi
   d / 2))`` generalised to the commutation shifted by the harmonics (a quadrature part), in phase
   with i2, VL the battery terminal voltage [``_duty``: a policy's compiled ``kernel()`` is called in
   the kernel, any other policy's ``act`` by ``MissionLoop.act`` when the kernel returns ``NEED_ACT``].
5. **Link**: the exact coupled modes of eq. 1 (:mod:`wpt_receiver.modal_kernel`), exact ZOH steps with
   exact energy integrals, instantaneous peak = fundamental + the SBAR's ripple [``_step``;
   ``_fine_step`` steps in rectifier periods while the SBAR rectifies: its v2 follows i2].
6. **Battery node**: rectifier current ``I_L = Re(V2c conj I2) / (2 (VL + Vf))`` (``V2c`` the clamp part
   of v2), battery current ``I_L - P_prop / VL``.
   The battery sees the step-mean current (the SBAR's smoothing capacitor), and VL of a step is
   solved *implicitly* (a quadratic) so that the link's V2, the battery's mean terminal voltage
   and the propulsion power agree exactly; every energy then closes to rounding [``_step``,
   ``_solve_vl``, ``_bat_step``; ``_deplete`` cuts the step where SoC reaches 0].

**Multi-rate.** *Fine* steps of ``sim.control_period_s`` (the policy's ``control_period_s``: it is
called once per step) run around every event: pad ramps, command changes, a duty change returned
by the policy, fast Lm changes with the pad on. A fine window lasts at least ``min_fine_s`` and
ends when the SBAR output ``1 - sin(pi d / 2)`` (= V2 / ((4/pi) VL), eq. 9) moves less than
``settle_duty_tol`` per step and I2 is within ``settle_i2_tol_a`` of the steady state for the held
inputs (or after ``max_fine_s``); with the pad off it ends once the coil currents have died out (not before, even at ``max_fine_s``, while the
protection holds d = 0).
It does not end while the receiver is shorted (d = 1) under a positive charge command: no charging
controller rests there, and a stateful policy may be moving behind the clip (``model_based_budget``'s
V2* below 0 V after a stop): the receiver's DSP runs it every control period until it answers, so does
the window [``_answering``].
Otherwise *coarse* steps run to the next trajectory sample (Lm, power held: the ZOH step is exact
for any length) with the policy called at most every ``coarse_policy_period_s`` and its duty held
in between; if that duty moves by more than ``duty_event_tol`` a fine window starts.
With the pad off and nothing pending, samples are merged into steps of up to ``sim.flight_dt_s``
and the policy is not called (the SBAR has nothing to do; its duty is held).
[``_interval`` (fine steps ``_fine_begin`` / ``_fine_end``, coarse steps, ``_coarse_duty``),
``_open_window`` / ``_window_done`` / ``_answering`` / ``_settled``, ``_quiet_flight``; ``MissionLoop.result``
assembles the time series and the summary.]

Sensor noise: ``sim.i2_noise_a`` (default 0: none) adds seeded Gaussian noise to the i2
observation only (drawn by the driver in blocks from the loop's generator, one normal per policy
call). Peak I2 and time above rated are taken on 4 points per fine step and on the ends of
coarse steps.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .loop import ENERGISE_PHASES, MissionLoop, NonFiniteError
from .power import hover_power_w
from .results import MissionResult
from .samples import lm_along as _lm_along
from .trajectory import PlannedTrajectory, Trajectory

__all__ = ["run_mission", "check_policy_context", "warn_setup", "ENERGISE_PHASES", "_lm_along"]


def run_mission(cfg, policy, *, trajectory: Trajectory | None = None, charge: bool = True,
                progress: bool = False, compiled: bool | None = None, frame: bool = True,
                sink=None, warn: bool = True, own_route: bool | None = None) -> MissionResult:
    """Run one mission; returns a :class:`~mission_sim.world.results.MissionResult`.

    ``policy`` is a :class:`mission_sim.contract.Policy` made for ``control_period_s =
    cfg.sim.control_period_s`` and ``rated_i2_a = cfg.link.rated_i2_a``. ``charge=False`` runs the
    same mission with the pads never energised. With ``charge=True`` the summary's
    ``flight_time_gain_s`` compares against that run (see :func:`flight_time_gain_s`).
    ``compiled``: the loop's physics always runs compiled (:mod:`.loop_kernel`); None calls the policy's
    compiled ``kernel()`` hook inside it when the policy has one (else its ``act`` from Python), False
    always its Python ``act`` (the same physics; only the duty computed elsewhere), True requires the
    hook (``ValueError`` without it).
    ``frame=False`` keeps no time series in memory (``timeseries`` is None; the summary is computed on
    the fly, memory bounded whatever the mission's length); ``sink`` (e.g.
    :class:`~.stream.SeriesWriter`) receives the charged run's rows in blocks as they are produced.
    A policy whose context (``policy.ctx``) has another ``control_period_s`` or ``rated_i2_a`` than ``cfg``
    is refused (``ValueError``): make it with ``mission_sim.config.policy_context(cfg)``.
    ``warn``: before the run, :func:`mission_sim.setup_warnings.mission_warnings` as
    :class:`wpt_receiver.notices.DronewptWarning` (a link outside the exact-mode model's checked range, a pad the
    route never energises, a policy made for another link model; none with ``charge=False``); False skips them (a
    sweep warns once per study); a route's payload release with no payload left to drop warns with or without
    ``charge`` (:func:`mission_sim.setup_warnings.payload_warnings`; when the route flown is ``cfg``'s). ``own_route``: whether the pads are checked against ``cfg``'s route (None: when
    no ``trajectory`` is given, a given one is taken for a replay's, its pads about the replay's pad frame origin;
    True for a trajectory planned from ``cfg``, e.g. ``plan_mission(cfg)``; False for a replayed one, or when the
    caller said it already). A pad far above or below its frame's origin warns whatever the route.
    """
    check_run_args(cfg, policy)
    check_policy_context(cfg, policy)
    planned = trajectory is None or getattr(trajectory, "mass", None) is not None   # cfg's route (its releases) flown
    if warn and charge:   # (pads never energised: neither the link nor the pads matter)
        replay = trajectory is not None and own_route is None   # (its pads about the replay's frame origin)
        warn_setup(cfg, policy, own_route=trajectory is None if own_route is None else bool(own_route), replay=replay,
                   payload=planned)
    elif warn and planned:   # (the payload's, charged or not)
        from wpt_receiver.notices import warn as say

        from ..setup_warnings import payload_warnings
        for text in payload_warnings(cfg):
            say(text)
    try:
        res = _run_mission(cfg, policy, trajectory, charge, progress, compiled, frame, sink)
        bad = [k for k, v in res.summary.items() if isinstance(v, float) and not np.isfinite(v)]
        if bad:
            raise NonFiniteError(f"the run's {bad[0]} is {res.summary[bad[0]]!r}")
    except NonFiniteError as exc:
        from ..config import differing_keys
        keys = differing_keys(cfg)
        raise NonFiniteError(f"{exc} (a non-finite value in the run; " + (
            f"the inputs that differ from the default mission, farthest first: {', '.join(keys)})" if keys else
            "with the default mission's inputs)")) from None
    return res


def warn_setup(cfg, policy, own_route: bool = True, replay: bool = False, payload: bool | None = None) -> None:
    """:func:`mission_sim.setup_warnings.mission_warnings` of the mission, each a
    :class:`~wpt_receiver.notices.DronewptWarning` pointed at the caller outside dronewpt."""
    from wpt_receiver.notices import warn

    from ..setup_warnings import mission_warnings
    for text in mission_warnings(cfg, policy, own_route, replay, payload):
        warn(text)


def check_run_args(cfg, policy) -> None:
    """``ValueError`` naming the value when ``cfg`` is not a :class:`~mission_sim.config.MissionConfig` or ``policy``
    is not a policy object (``run_mission(cfg, "step")`` was an AttributeError deep in the loop)."""
    from ..config import MissionConfig
    if not isinstance(cfg, MissionConfig):
        raise ValueError(f"cfg={cfg!r:.80} is invalid; valid: a MissionConfig (mission_sim.config.load_config(), "
                         "or config_from_dict)")
    if not (callable(getattr(policy, "reset", None)) and callable(getattr(policy, "act", None))):
        hint = f"policies.make({policy!r}, policy_context(cfg))" if isinstance(policy, str) else \
            "policies.make('model_based', policy_context(cfg))"
        raise ValueError(f"policy={policy!r:.80} is invalid; valid: a policy object with reset() and act(), e.g. "
                         f"{hint}")


def check_policy_context(cfg, policy) -> None:
    """``ValueError`` naming both values when ``policy`` was made for another control period or rated current
    than the mission ``cfg`` (a policy made with ``policies.make(name)``'s default context for a mission with
    ``sim.control_period_s = 5e-5`` ran, its filters discretised for 100 us, silently). A policy without a
    :class:`~mission_sim.contract.PolicyContext` in ``policy.ctx`` is not checked."""
    ctx = getattr(policy, "ctx", None)
    for name, mine in (("control_period_s", cfg.sim.control_period_s), ("rated_i2_a", cfg.link.rated_i2_a)):
        theirs = getattr(ctx, name, None)
        if isinstance(theirs, float | int) and not math.isclose(theirs, mine, rel_tol=1e-9):
            key = "sim" if name == "control_period_s" else "link"
            raise ValueError(f"the policy's {name}={theirs!r} is invalid for this mission; valid: {key}.{name}="
                             f"{mine!r} (make the policy with mission_sim.config.policy_context(cfg))")


def _run_mission(cfg, policy, trajectory, charge, progress, compiled, frame=True, sink=None) -> MissionResult:
    """:func:`run_mission` without the check for non-finite results."""
    wall0 = time.perf_counter()
    traj = PlannedTrajectory(cfg) if trajectory is None else trajectory   # planned in blocks as the loop needs them
    res = _simulate(cfg, policy, traj, charge, progress, None, compiled, frame, sink)
    if charge:  # its summary only; its pads never energise, so Lm does not enter it (0: no coupling table)
        base = _simulate(cfg, policy, traj, False, False, 0.0, compiled, frame=False)
        res.summary["flight_time_gain_s"] = flight_time_gain_s(cfg, res.summary["final_soc"],
                                                               base.summary["final_soc"],
                                                               _final_mass_kg(traj)) \
            + res.summary["sim_time_s"] - base.summary["sim_time_s"]  # a depleted run ends early
    else:
        res.summary["flight_time_gain_s"] = 0.0
        base = res
    res.summary["final_soc_without_charging"] = base.summary["final_soc"]
    res.summary["battery_depleted_without_charging"] = base.summary["battery_depleted"]
    res.summary["depleted_at_s_without_charging"] = base.summary["depleted_at_s"]
    res.summary["wall_s"] = time.perf_counter() - wall0
    res.summary["realtime_factor"] = res.summary["sim_time_s"] / max(res.summary["wall_s"], 1e-12)
    return res


def _final_mass_kg(traj) -> float | None:
    """The mass a planned route ends with (its :class:`~.trajectory.MassSchedule`); None without one."""
    sched = getattr(traj, "mass", None)
    return None if sched is None else sched.final_mass_kg


def flight_time_gain_s(cfg, final_soc_charged: float, final_soc_uncharged: float,
                       mass_kg: float | None = None) -> float:
    """Extra hover time [s] the charged mission ends with: the difference of the usable chemical
    energy left (``n Q int_0^SoC OCV``) divided by the electrical hover power at the mass the mission ends with
    (``mass_kg``, the landing mass after any payload release; None: the take-off mass). (A run that depletes
    its battery ends there at SoC 0; :func:`run_mission` adds the difference of the two runs' ends.)"""
    e = cfg.battery.usable_energy_j
    return float((e(final_soc_charged) - e(final_soc_uncharged)) / hover_power_w(cfg.drone, mass_kg))


def _simulate(cfg, policy, traj: Trajectory, charge: bool, progress: bool, lm_all=None,
              compiled: bool | None = None, frame: bool = True, sink=None) -> MissionResult:
    """One run; ``lm_all``: Lm per sample [H], a constant, or None (computed chunk by chunk)."""
    return MissionLoop(cfg, policy, traj, charge, lm_all, compiled, frame, sink).run(progress)
