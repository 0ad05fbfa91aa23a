"""A mission's setup checked for what runs but is likely not what its user meant: one line each, naming the
value, the range where it was checked and what to do. Raised as :class:`wpt_receiver.notices.DronewptWarning`
by :func:`~mission_sim.world.runner.run_mission` (once per call, before the run: nothing per step), once per
study by a sweep (:meth:`~mission_sim.studies.mission_cases.MissionParamChecker.warnings`), printed as one line
each by the command line.

* :func:`link_range_warning`: the mission's link outside the range where the exact-mode model (the mission's
  only link) was checked against the switching model (:func:`wpt_receiver.paper.modal_range_problem`, the one
  source of the limits), at the hover pose's Lm and the pack's highest voltage (``n_series * cv_cell_v``).
* :func:`unreached_pad_warnings`: a pad no charge item of the route comes to (a mission file's loiter farther
  than ``mission.pad_radius_m`` from it): it charges nothing.
* :func:`policy_link_warning`: a policy made for another link model than the mission's (``"modal"``), if it
  predicts with it: a policy says so with a class attribute ``uses_link_model = True`` (``mpc``,
  ``model_based_budget``, ``slow_budget``, ``oracle_imitation_filtered``; not part of the
  :class:`~mission_sim.contract.Policy` protocol's required members).
"""

from __future__ import annotations

import math

__all__ = ["link_range_warning", "unreached_pad_warnings", "policy_link_warning", "mission_warnings",
           "mission_link_params", "MISSION_LINK_MODEL"]

#: the link model every mission runs (:mod:`mission_sim.world.loop_kernel` steps :mod:`wpt_receiver.modal_kernel`)
MISSION_LINK_MODEL = "modal"


def mission_link_params(cfg):
    """The mission's link as :class:`wpt_receiver.LinkParams` at the hover pose (Lm at ``(0, 0,
    mission.hover_gap_m)``, as :func:`mission_sim.config.policy_context`) and at the pack's highest voltage, the
    charger's CV voltage ``battery.n_series * charger.cv_cell_v`` (the lowest Vdc/VL and emf margin of the run)."""
    from .config import hover_inductances
    l1_h, l2_h, lm_h = hover_inductances(cfg.coupling, cfg.mission.hover_gap_m)
    return cfg.link.link_params(l1_h, l2_h, lm_h, vl_v=cfg.battery.n_series * cfg.charger.cv_cell_v)


def link_range_warning(cfg) -> str | None:
    """One line when the mission's link (:func:`mission_link_params`) is outside the exact-mode model's checked
    range, else None."""
    from wpt_receiver.paper import modal_range_problem
    p = mission_link_params(cfg)
    problem = modal_range_problem(p, remedy=(
        "the mission has no other link model, so its charging current and energies may be off; valid: raise "
        "link.vdc_v, use fewer cells (battery.n_series) or a lower mission.hover_gap_m"))
    if problem is None:
        return None
    return (f"link.vdc_v={cfg.link.vdc_v:g} V with battery.n_series={cfg.battery.n_series} (VL up to "
            f"{p.vl_v:.4g} V at charger.cv_cell_v={cfg.charger.cv_cell_v:g}), Lm {p.lm_h * 1e6:.3g} uH at "
            f"mission.hover_gap_m={cfg.mission.hover_gap_m:.4g}: {problem}")


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


def unreached_pad_warnings(cfg) -> list[str]:
    """One line per pad that no ``charge`` item of ``cfg.waypoints`` comes to (the built-in route, no waypoints,
    charges at every pad): its index, position and the route's closest horizontal approach."""
    if not cfg.waypoints:
        return []
    charged = {wp.pad for wp in cfg.waypoints if wp.action == "charge"}
    if len(charged) >= len(cfg.pads):
        return []
    pts = [(0.0, 0.0)] + [((cfg.pads[wp.pad].x_m, cfg.pads[wp.pad].y_m) if wp.action == "charge" else
                           (wp.x_m, wp.y_m)) for wp in cfg.waypoints]
    out = []
    for i, pad in enumerate(cfg.pads):
        if i not in charged:
            d = _distance_to_route(pad.x_m, pad.y_m, pts)
            out.append(f"pad {i} at ({pad.x_m:.1f}, {pad.y_m:.1f}) m charges nothing: no loiter of the route within "
                       f"mission.pad_radius_m={cfg.mission.pad_radius_m:g} m of it (closest approach {d:.1f} m); "
                       "valid: a loiter item over the pad, a larger mission.pad_radius_m, or leave the pad out")
    return out


def policy_link_warning(cfg, policy) -> str | None:
    """One line when ``policy`` predicts with its context's link model (``uses_link_model``: ``mpc``,
    ``model_based_budget``, ...) and that (``policy.ctx.link_model``) is not the mission's (a standalone
    ``PolicyContext()`` is eq. 4's ``"envelope"``: ``mpc`` would predict with eq. 4 on the mission's exact-mode
    link), else None. A policy that does not read it (``model_based``, ``step``, ...) runs the same either way."""
    model = getattr(getattr(policy, "ctx", None), "link_model", None)
    if not getattr(policy, "uses_link_model", False) or not isinstance(model, str) or model == MISSION_LINK_MODEL:
        return None
    name = getattr(policy, "name", type(policy).__name__)
    return (f"the policy {name!r} predicts with link_model={model!r}, the mission runs {MISSION_LINK_MODEL!r} (the "
            "exact-mode link): it assumes another plant than it controls; valid: make it with "
            "mission_sim.config.policy_context(cfg)")


def mission_warnings(cfg, policy=None, own_route: bool = True) -> list[str]:
    """Every setup warning of a mission (``own_route``: ``cfg``'s route is flown, not a replayed trajectory)."""
    out = [w for w in (link_range_warning(cfg), policy_link_warning(cfg, policy) if policy is not None else None)
           if w is not None]
    if own_route:
        out += unreached_pad_warnings(cfg)
    return out
