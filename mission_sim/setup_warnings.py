"""A mission's setup checked for what runs but is likely not what its user meant: one line each, naming the
value, the range where it was checked and what to do. Raised as :class:`wpt_receiver.notices.DronewptWarning`
by :func:`~mission_sim.world.runner.run_mission` (once per call, before the run: nothing per step), once per
study by a sweep (:meth:`~mission_sim.studies.mission_cases.MissionParamChecker.warnings`), printed as one line
each by the command line.

* :func:`link_range_warning`: the mission's link outside the range where the exact-mode model (the mission's
  only link) was checked against the switching model (:func:`wpt_receiver.paper.modal_range_problem`, the one
  source of the limits), at the hover pose's Lm and the pack's highest voltage (``n_series * cv_cell_v``).
* :func:`link_frequency_warning`: ``link.f_hz`` more than a factor
  :data:`wpt_receiver.params.FREQUENCY_TOLERANCE` off the coil pair's tanks' resonance (85 kHz: Table I's coils
  with their capacitors; at a factor 2 the resonant link's secondary current, 1/f, halves or doubles).
* :func:`short_mode_rating_warning`: ``coupling.tx_min_k`` below the coupling at which the steady short-mode I2
  (~ V1 / (w Lm), more as k falls) reaches ``link.rated_i2_a`` at full V1: the pad stays on where a receiver in
  short mode carries more than its rating (:func:`wpt_receiver.envelope.short_mode_rated_k`, closed form).
* :func:`unreached_pad_warnings`: a pad the route never energises (:func:`energised_pads`: no charging hover
  or loiter's hover inside its coupling range, the run's own rule): it charges nothing.
* :func:`far_pad_warnings`: a pad more than 120 m above or below home (an altitude in another frame or unit).
* :func:`payload_warnings`: a route's payload release (``[[waypoints]] release``, a mission file's DO_GRIPPER
  release) with no payload left to drop (``drone.payload_kg = 0``, or more releases than
  ``payload_kg / release_kg`` parcels): it drops nothing.
* :func:`policy_link_warning`: a policy made for another link model than the mission's (``"modal"``), if it
  predicts with it: a policy says so with a class attribute ``uses_link_model = True`` (``mpc``,
  ``model_based_budget``, ``slow_budget``, ``oracle_imitation_filtered``; not part of the
  :class:`~mission_sim.contract.Policy` protocol's required members).
"""

from __future__ import annotations

import math

__all__ = ["link_range_warning", "link_frequency_warning", "short_mode_rating_warning", "policy_overshoot", "reachable_coupling", "ring_down_warning", "RING_DOWN_WARN_S", "unreached_pad_warnings", "payload_warnings", "far_pad_warnings", "energised_pads", "policy_link_warning", "mission_warnings",
           "mission_link_params", "MISSION_LINK_MODEL", "POLICY_VL_TOL_V", "PAD_HEIGHT_WARN_M", "HOME_ORIGIN", "REPLAY_ORIGIN"]

#: the link model every mission runs (:mod:`mission_sim.world.loop_kernel` steps :mod:`wpt_receiver.modal_kernel`)
MISSION_LINK_MODEL = "modal"


def mission_link_params(cfg):
    """The mission's link at the hover pose and the pack's CV voltage: :func:`mission_sim.config.mission_link_params`
    (there, beside :func:`mission_sim.config.policy_context`, which gives the policies the same link)."""
    from .config import mission_link_params
    return mission_link_params(cfg)


def link_range_warning(cfg) -> str | None:
    """One line when the mission's link (:func:`mission_link_params`) is outside the exact-mode model's checked
    range, else None."""
    from wpt_receiver.paper import modal_range_problem
    p = mission_link_params(cfg)
    problem = modal_range_problem(p, remedy=lambda limit: (
        "the mission has no other link model, so its charging current and energies may be off; valid: raise "
        + ("link.vdc_v, use fewer cells (battery.n_series) or a lower mission.hover_gap_m (more Lm)"
           if limit == "emf_margin" else "link.vdc_v or use fewer cells (battery.n_series)")))
    if problem is None:
        return None
    return (f"link.vdc_v={cfg.link.vdc_v:g} V with battery.n_series={cfg.battery.n_series} (VL up to "
            f"{p.vl_v:.4g} V at charger.cv_cell_v={cfg.charger.cv_cell_v:g}), Lm {p.lm_h * 1e6:.3g} uH at "
            f"mission.hover_gap_m={cfg.mission.hover_gap_m:.4g}: {problem}")


def link_frequency_warning(cfg) -> str | None:
    """One line when ``link.f_hz`` lies more than a factor :data:`wpt_receiver.params.FREQUENCY_TOLERANCE` off the
    coil pair's tanks' resonance (:func:`wpt_receiver.params.resonance_warning`: the models tune the capacitors to
    ``f_hz``, and the resonant link's secondary current scales as 1/f), else None."""
    from wpt_receiver.params import resonance_warning
    return resonance_warning(mission_link_params(cfg), "link.f_hz")


def _short_mode_link(cfg):
    """The mission's link (:func:`mission_link_params`) with the devices' on-resistances folded into R1 (the
    inverter's) and R2 (the shorted SBAR's): the link of :func:`wpt_receiver.envelope.short_mode_rated_k` here."""
    dv = cfg.link.device_set()
    return mission_link_params(cfg).with_(r1_ohm=cfg.link.r1_ohm + dv.inv_r_ohm, r2_ohm=cfg.link.r2_ohm + dv.short_r_ohm)


def short_mode_rated_coupling(cfg, overshoot: float = 0.0) -> float:
    """The coupling k at which the steady short-mode I2 at full V1, times ``1 + overshoot``, reaches
    ``link.rated_i2_a`` (below it the peak is above the rating; 0.0 when it never reaches it): the k of
    :func:`short_mode_rating_warning` (0.07132 at the defaults, steady; 0.07461 with model_based's 4.6 %)."""
    from wpt_receiver.envelope import short_mode_rated_k
    return short_mode_rated_k(_short_mode_link(cfg), cfg.link.rated_i2_a, overshoot=overshoot)


def policy_overshoot(policy) -> float:
    """The fraction by which ``policy``'s RM -> SM transition peaks above the steady short-mode I2, as it declares it
    (a class attribute ``rm_sm_overshoot``, measured at Table I and at the warning's operating point, the larger:
    ``model_based`` 0.046, ``ramp`` 0.1027); 0.0 for None or a policy that declares nothing (the steady state is then
    what is bounded: :func:`short_mode_rating_warning` says so). A declared value that is not a number >= 0 (negative,
    NaN, a string) raises ``ValueError`` naming it."""
    if policy is None or not hasattr(policy, "rm_sm_overshoot"):
        return 0.0
    os_ = policy.rm_sm_overshoot
    if isinstance(os_, bool) or not isinstance(os_, (int, float)) or not (math.isfinite(os_) and os_ >= 0):
        raise ValueError(f"policy {_policy_name(policy)!r}: rm_sm_overshoot={os_!r} is invalid; valid range: [0, inf) "
                         "(a fraction of the steady short-mode I2)")
    return float(os_)


def _policy_name(policy) -> str:
    return getattr(policy, "name", type(policy).__name__)


def reachable_coupling(cfg) -> float:
    """The largest coupling ``coupling.tx_min_k`` can usefully gate at: the coupling model's k at contact (the
    receiver coil centred over the pad coil, wires touching: 0.271 for the default pair), and below
    ``1 - coupling.tx_k_hysteresis`` (the config's range for the gate)."""
    model = cfg.coupling.model()   # (the closed form at contact: a mission on a known path loads no coupling kernel)
    k_contact = float(model.k(model.lm_centred_h(model.clearance_m())))
    return min(k_contact, 1.0 - cfg.coupling.tx_k_hysteresis)


def short_mode_rating_warning(cfg, policy=None) -> str | None:
    """One line when ``coupling.tx_min_k`` (the pad switches off only below it) lies below the coupling at which the
    short-mode I2 at full V1 (``(4/pi) link.vdc_v``; the pad's coils, the devices' on-resistances in R1 and in the
    shorted R2: :func:`wpt_receiver.envelope.short_mode_rated_k`) reaches ``link.rated_i2_a`` at the peak of
    ``policy``'s RM -> SM transition: the steady I2 times ``1 +`` its declared overshoot (:func:`policy_overshoot`,
    figures measured at Table I's link and at the warning's operating point; none declared: the steady state, and
    the line says so), else None: between the two the pad energises a receiver whose transition into short mode
    peaks above its rating. The default 0.075 is above it (0.0713 steady on Table I with the default devices, 14.27 A
    at k = 0.075; 0.0746 with model_based's 4.6 %, 14.92 A; with ramp's 10.27 % 0.0787: the default gate warns).

    The remedies are closed forms: the steady short-mode I2 is proportional to V1 (eq. 4 at V2 = 0), so the largest
    ``link.vdc_v`` that keeps the peak within the rating at the gate is ``vdc * rated / ((1 + os) I2)`` (31.55 V
    steady, 30.16 V with 4.6 % at the defaults), and the rating the gate needs is ``(1 + os) I2``. When the k that
    keeps it within the rating is at or above what the coils reach (:func:`reachable_coupling`: k at contact, 0.271
    for the default pair; e.g. ``link.vdc_v=900`` asks for k >= 2.24), no pad gate does: the line says so and gives
    only those two.

    A step into short mode from rectification is not bounded here: eq. 4 puts its peak at 4.7-4.8 x the steady I2
    (67.5 A at k = 0.075, 43.0 A at 0.12), above the rating at every coupling a pad serves, which no gate fixes (the
    mission's ``time above rated`` and the sizing report it; docs/mission.md)."""
    from wpt_receiver.envelope import steady_state

    p = _short_mode_link(cfg)
    l1_h, l2_h = p.l1_h, p.l2_h   # (the coupling model's coils; the hover pose's Lm is not used)
    rated, k_min = cfg.link.rated_i2_a, cfg.coupling.tx_min_k
    os_ = policy_overshoot(policy)
    k_rated = short_mode_rated_coupling(cfg, os_)
    if not k_min < k_rated:
        return None
    # the largest short-mode I2 the pad is then on for: at tx_min_k, or at the curve's top sqrt(R1 R2) below it
    k_top = math.sqrt(p.r1_ohm * p.r2_ohm) / (p.omega_rad_s * math.sqrt(l1_h * l2_h))
    i2_max = float(steady_state(p, 0.0, lm_h=max(k_min, k_top) * math.sqrt(l1_h * l2_h))[1])
    i2_peak = (1 + os_) * i2_max
    vdc_max = cfg.link.vdc_v * rated / i2_peak   # (I2 is proportional to V1)
    if policy is None:
        peak = ""
    elif os_ == 0.0:
        peak = f" (steady I2 only; policy {_policy_name(policy)!r} declares no transition overshoot)"
    else:
        peak = (f" plus the policy {_policy_name(policy)!r} RM -> SM transition's overshoot ({100 * os_:.3g} %, "
                "measured at Table I)")
    up_to = f"{i2_max:.4g} A" if os_ == 0.0 else f"{i2_max:.4g} A steady, {i2_peak:.4g} A at the peak"
    head = (f"coupling.tx_min_k={k_min:.6g} is below k = {k_rated:.4g}, where the receiver's short-mode I2 (~ V1/(w "
            f"Lm), V1 = {p.v1_amp_v:.4g} V at link.vdc_v={cfg.link.vdc_v:g} V){peak} reaches "
            f"link.rated_i2_a={rated:g} A: the pad stays on down to k = {k_min:.6g}, with up to {up_to} in short mode")
    limits = f"link.vdc_v <= {vdc_max:.4g} V or link.rated_i2_a >= {i2_peak:.4g} A"
    k_reach = reachable_coupling(cfg)
    if k_rated >= k_reach:
        return (f"{head}; k = {k_rated:.4g} is at or above what the coils reach (k {k_reach:.3g} at contact), so no "
                f"pad gate keeps it within the rating; valid: {limits} (at the gate's k = {k_min:.6g})")
    return f"{head}; valid: coupling.tx_min_k >= {k_rated:.4g} (or {limits} at k = {k_min:.6g})"


#: a pad switch-off's ring-down time constant [s] above which the mission warns that it runs slowly
RING_DOWN_WARN_S = 1.0


def ring_down_warning(cfg) -> str | None:
    """One line when the primary's ring-down after a pad switch-off, ``tau = 2 L1 / (R1 + 2 Ron)`` (the diodes
    blocked, I2 = 0; ``link.r1_ohm`` plus the inverter's two on-resistances), is longer than
    :data:`RING_DOWN_WARN_S`: the mission carries it in control-period pieces (~ ``tau ln(I1 / sim.settle_i2_tol_a) /
    sim.control_period_s`` per switch-off), so a run takes minutes, not seconds (docs/mission.md, "Compute at the low
    end of link.r1_ohm": ideal devices, 207 s at R1 = 1e-4 ohm, tau 4.7 s), else None. Only ``ideal`` devices leave it
    uncapped (the ``schottky`` preset's 2 Ron = 0.02 ohm caps it at 24 ms)."""
    p = mission_link_params(cfg)
    inv = cfg.link.device_set().inv_r_ohm
    tau = 2.0 * p.l1_h / (p.r1_ohm + inv)
    if not tau > RING_DOWN_WARN_S:
        return None
    r1_min = max(2.0 * p.l1_h / RING_DOWN_WARN_S - inv, 0.0)
    return (f"link.r1_ohm={cfg.link.r1_ohm:g} ohm with link.devices={cfg.link.devices!r} (inverter 2 Ron = {inv:g} "
            f"ohm): after a pad switch-off the primary rings down with tau = 2 L1 / (R1 + 2 Ron) = {tau:.3g} s, which "
            f"the mission steps in control-period pieces, so the run may take minutes (docs/mission.md, compute at the "
            f"low end of link.r1_ohm); valid for tau <= {RING_DOWN_WARN_S:g} s: link.r1_ohm >= {r1_min:.3g} or "
            "devices with on-resistance (e.g. link.devices=schottky)")


def _distance_to_route(x: float, y: float, pts: list) -> float:
    """Horizontal distance [m] of (x, y) to the polyline through ``pts`` ((x, y) pairs)."""
    if len(pts) == 1:
        return math.hypot(x - pts[0][0], y - pts[0][1])
    best = math.inf
    for (ax, ay), (bx, by) in zip(pts, pts[1:]):
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        t = 0.0 if L2 == 0.0 else min(1.0, max(0.0, ((x - ax) * dx + (y - ay) * dy) / L2))
        best = min(best, math.hypot(x - ax - t * dx, y - ay - t * dy))
    return best


def energised_pads(cfg) -> set[int]:
    """The pads that ``cfg``'s planned route energises, by the run's own rule: a hold of the route in one of
    :data:`~mission_sim.world.samples.ENERGISE_PHASES` (a ``charge`` item's charging hover, a ``loiter``'s hover)
    at a pose inside the coupling table's range of its nearest pad (:func:`~mission_sim.world.samples.near_pad`,
    as :func:`~mission_sim.world.samples.lm_along`: Lm > 0 only there). Pads at the same place count together."""
    import numpy as np

    from .world.samples import ENERGISE_PHASES, near_pad, pad_offsets
    from .world.trajectory import _segments
    holds = [p0 for phase, p0, unit, _, _ in _segments(cfg) if unit is None and phase in ENERGISE_PHASES]
    if not holds or not cfg.pads:
        return set()
    off, idx = pad_offsets(cfg, np.asarray(holds, dtype=float))
    places = {(cfg.pads[i].x_m, cfg.pads[i].y_m) for i in idx[near_pad(cfg.coupling.model(), off)]}
    return {i for i, p in enumerate(cfg.pads) if (p.x_m, p.y_m) in places}


def _route_points(cfg) -> list:
    """(x, y) of the route's corners, from the mission's start (``mission.start_x_m``, ``start_y_m``)."""
    from .world.trajectory import _path
    path = _path(cfg)
    return [(float(p0[0]), float(p0[1])) for _, p0, _, _, _ in path.segs] + [(float(path.pos[0]), float(path.pos[1]))]


def unreached_pad_warnings(cfg) -> list[str]:
    """One line per pad that ``cfg.waypoints``' route never energises (:func:`energised_pads`; the built-in route,
    no waypoints, charges at every pad): its index, position, the route's closest horizontal approach and the
    remedy for the route's kind (a mission file's loiter near the pad, a config's ``charge`` item)."""
    if not cfg.waypoints or not cfg.pads:
        return []
    reached = energised_pads(cfg)
    if len(reached) >= len(cfg.pads):
        return []
    from .plans.route import CHARGE_CLEARANCE_M
    pts = _route_points(cfg)
    out = []
    for i, pad in enumerate(cfg.pads):
        if i in reached:
            continue
        d = _distance_to_route(pad.x_m, pad.y_m, pts)
        if cfg.mission.file:
            valid = (f"a loiter item within mission.pad_radius_m={cfg.mission.pad_radius_m:g} m of the pad and at "
                     f"least {CHARGE_CLEARANCE_M:g} m above it (it becomes a charging hover), a larger "
                     "mission.pad_radius_m, or leave the pad out of --pads")
        else:
            valid = f'a [[waypoints]] item with action = "charge", pad = {i}, or leave the pad out'
        out.append(f"pad {i} at ({pad.x_m:.1f}, {pad.y_m:.1f}) m charges nothing: the route never hovers over it "
                   f"(closest approach {d:.1f} m); valid: {valid}")
    return out


#: a pad farther above or below the mission's home than this is likely an altitude in another frame or unit (a
#: pads file's ``alt`` is m AMSL: 0 meant as "on the ground", feet for metres): the common legal ceiling of drones
#: (EU open category 120 m, US 400 ft)
PAD_HEIGHT_WARN_M = 120.0
#: the pad frame's origin as a far pad's line names it: a planned mission's, a replay's or re-flight's
HOME_ORIGIN, REPLAY_ORIGIN = "the mission's home", "the replay's pad frame origin"


def far_pad_warnings(cfg, origin: str = HOME_ORIGIN) -> list[str]:
    """One line per pad more than :data:`PAD_HEIGHT_WARN_M` above or below ``origin``, the pad frame's (a pads
    file's ``alt = 0`` at a home 488 m AMSL put the pad 488 m below it, and a route loitering over it flew down there
    to charge, without a word; a re-flight's detours too, about the replay's pad frame origin: +1918 s)."""
    return [f"pads.{i}.z_m={pad.z_m:.6g} is outside +-{PAD_HEIGHT_WARN_M:g} m of {origin} (the pad is "
            f"{abs(pad.z_m):.0f} m {'above' if pad.z_m > 0 else 'below'} it: a drone charging there flies up or down "
            f"to it); valid: a pad's height within +-{PAD_HEIGHT_WARN_M:g} m of it (a pads file's alt in metres above "
            "mean sea level, not above the ground, not feet; [[pads]] z_m and --set pads.<i>.z_m in metres above it)"
            for i, pad in enumerate(cfg.pads) if abs(pad.z_m) > PAD_HEIGHT_WARN_M]


#: how far below the pack's CV voltage a link-model policy's context VL may be before it warns [V] (the default 8S
#: pack flies at 32.28-32.90 V, its CV voltage 32.8 V; ``mpc:0.02`` with VL 31 V peaked at 13.63 A, 29-30 V at
#: 32.3-32.5 A, 2.2x its 15 A rating)
POLICY_VL_TOL_V = 1.0


def policy_link_warning(cfg, policy) -> str | None:
    """One line when ``policy`` predicts with its context's link model (``uses_link_model``: ``mpc``,
    ``model_based_budget``, ...) and that (``policy.ctx.link_model``) is not the mission's (a standalone
    ``PolicyContext()`` is eq. 4's ``"envelope"``: ``mpc`` would predict with eq. 4 on the mission's exact-mode
    link), or its context's link VL is more than :data:`POLICY_VL_TOL_V` below the mission's pack (its CV voltage,
    :func:`mission_link_params`: a hand-made ``PolicyContext(link_model="modal")`` keeps Table I's 30 V, and the
    modal MPC's clamp is then too low), else None. A policy that does not read it (``model_based``, ``step``, ...)
    runs the same either way."""
    ctx = getattr(policy, "ctx", None)
    model = getattr(ctx, "link_model", None)
    if not getattr(policy, "uses_link_model", False) or not isinstance(model, str):
        return None
    name = getattr(policy, "name", type(policy).__name__)
    if model != MISSION_LINK_MODEL:
        return (f"the policy {name!r} predicts with link_model={model!r}, the mission runs {MISSION_LINK_MODEL!r} (the "
                "exact-mode link): it assumes another plant than it controls; valid: make it with "
                "mission_sim.config.policy_context(cfg)")
    vl, pack = getattr(getattr(ctx, "link", None), "vl_v", None), mission_link_params(cfg).vl_v
    if isinstance(vl, (int, float)) and vl < pack - POLICY_VL_TOL_V:
        return (f"the policy {name!r} predicts with its link at VL = {vl:g} V, the mission's pack charges to "
                f"{pack:g} V: its clamp is too low and it may overshoot its current rating; valid: a context VL within "
                f"{POLICY_VL_TOL_V:g} V below the pack's, as mission_sim.config.policy_context(cfg) makes it")
    return None


def mission_warnings(cfg, policy=None, own_route: bool = True, replay: bool = False,
                     payload: bool | None = None) -> list[str]:
    """Every setup warning of a mission (``own_route``: ``cfg``'s route is flown, not a replayed trajectory, so its
    pads can be checked against it; ``replay``: the trajectory is a replay's, whose pad frame origin is the take-off
    spot or ``--pad``, not the mission's home; ``payload``: ``cfg``'s route is flown, so its payload releases are
    (None: unless ``replay``; :func:`payload_warnings`). A far pad warns whatever the route."""
    out = [w for w in (link_range_warning(cfg), link_frequency_warning(cfg), short_mode_rating_warning(cfg, policy),
                       ring_down_warning(cfg), policy_link_warning(cfg, policy) if policy is not None else None) if w is not None]
    out += far_pad_warnings(cfg, REPLAY_ORIGIN if replay else HOME_ORIGIN)
    if own_route:
        out += unreached_pad_warnings(cfg)
    if (not replay) if payload is None else payload:
        out += payload_warnings(cfg)
    return out


def payload_warnings(cfg) -> list[str]:
    """One line when releases of ``cfg``'s route find no payload left to drop (:func:`mission_sim.world.power.
    payload_after_releases`): ``drone.payload_kg = 0`` (the default: a delivery plan flown without its payload's
    mass), or more releases than ``payload_kg / release_kg`` parcels."""
    from .world.power import payload_after_releases
    n = sum(int(wp.release) for wp in cfg.waypoints)
    if not n:
        return []
    drone = cfg.drone
    _, empty = payload_after_releases(drone, n)
    if not empty:
        return []
    if drone.payload_kg == 0:
        return [f"the route releases a payload {n} time(s) (DO_GRIPPER release, NAV_PAYLOAD_PLACE, [[waypoints]] "
                "release) but drone.payload_kg = 0: nothing is dropped, the drone flies at drone.mass_kg throughout; "
                "valid: drone.payload_kg > 0 (the payload carried from take-off, kg) for a delivery's lighter return"]
    each = ("drone.release_kg = 0: the first release drops all of it" if drone.release_kg == 0 else
            f"drone.release_kg = {drone.release_kg:g} kg each")
    return [f"{empty} of the route's {n} payload releases find no payload left (drone.payload_kg = {drone.payload_kg:g} "
            f"kg, {each}): they drop nothing; valid: drone.release_kg = one parcel's mass and drone.payload_kg = "
            "release_kg x the number of releases"]
