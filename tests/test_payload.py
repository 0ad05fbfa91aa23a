"""Payload carried from take-off and dropped at a route's releases (DO_GRIPPER release,
``[[waypoints]] release``): the mass schedule, the power at the current mass, the plan reader, bad inputs."""

from __future__ import annotations

import dataclasses as dc
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from mission_sim.config import apply_overrides, config_from_dict, load_config_dict, policy_context
from mission_sim.plans.items import MissionItem, RawMission
from mission_sim.plans.route import route_from_items
from mission_sim.mavlink.geodesy import GeoPoint
from mission_sim.world.power import DroneParams, hover_power_w, propulsion_power_w

MISSIONS = Path(__file__).parent / "data" / "missions"
PX4_DELIVERY = MISSIONS / "px4_triangle_gripper_package_delivery.plan"


# ------------------------------------------------------------------ the power model at the current mass
def test_hover_power_goes_as_mass_to_the_1_5():
    """Momentum theory: hover shaft power = (m g)^1.5 / sqrt(2 rho A) / FM, so (P - avionics) scales as m^1.5;
    propulsion_power_w's Newton solution at rest with a mass array gives the same numbers."""
    p = DroneParams()
    masses = np.array([0.5, 1.0, 1.5, 2.0, 3.7])
    base = hover_power_w(p, 1.0) - p.avionics_w
    for m in masses:
        assert hover_power_w(p, m) - p.avionics_w == pytest.approx(base * m**1.5, rel=1e-12)
    at_rest = propulsion_power_w(p, np.zeros(5), np.zeros(5), mass_kg=masses)
    assert at_rest == pytest.approx([hover_power_w(p, m) for m in masses], rel=1e-12)
    # the take-off mass when none is given: mass_kg + payload_kg
    q = DroneParams(payload_kg=0.5)
    assert hover_power_w(q) == hover_power_w(p, 1.5)


def test_mass_argument_is_the_params_mass():
    """A mass per sample gives, sample by sample, what a DroneParams of that total mass gives (one formula: the
    mass only enters as the weight), in forward flight, climb and descent."""
    p = DroneParams(payload_kg=0.7)
    v, vz = np.array([0.0, 3.0, 8.0, 12.0, 5.0]), np.array([0.0, 2.0, -1.0, 0.0, -3.0])
    m = np.array([1.7, 1.7, 1.0, 1.2, 1.0])
    got = propulsion_power_w(p, v, vz, mass_kg=m)
    want = [propulsion_power_w(dc.replace(p, mass_kg=mi, payload_kg=0.0), vi, vzi) for mi, vi, vzi in zip(m, v, vz)]
    assert got == pytest.approx(want, rel=1e-13)
    assert got[2] < propulsion_power_w(p, 8.0, -1.0)   # lighter: less power


def test_payload_after_releases_parcels_and_all_at_once():
    from mission_sim.world.power import payload_after_releases
    left, empty = payload_after_releases(DroneParams(payload_kg=0.9, release_kg=0.3), 4)
    assert left[:2] == pytest.approx([0.6, 0.3]) and left[2] == 0.0 and left[3] == 0.0   # exactly 0: no 5e-17 left
    assert empty == 1
    left, empty = payload_after_releases(DroneParams(payload_kg=0.9), 2)   # release_kg 0: all at the first
    assert left == [0.0, 0.0] and empty == 1
    assert payload_after_releases(DroneParams(payload_kg=0.5, release_kg=0.2), 3) == (pytest.approx([0.3, 0.1, 0.0]), 0)
    assert payload_after_releases(DroneParams(), 1) == ([0.0], 1)


# ------------------------------------------------------------------ the plan reader
def _item(where, command, p2=0.0, lat=0.0, lon=0.0, alt=float("nan"), frame=3):
    return MissionItem(where, command, frame, (0.0, p2, 0.0, 0.0), lat, lon, alt)


def _raw(*items):
    return RawMission("test.plan", GeoPoint(47.0, 8.0, 400.0), tuple(items))


def test_px4_delivery_plan_releases_after_its_landing():
    """PX4's package-delivery plan (waypoint, NAV_LAND, DO_GRIPPER release, waypoint): one release on the landing,
    at its touch-down (the segment after it is the take-off to 10 m)."""
    from mission_sim.plans.items import read_mission
    doc = json.loads(PX4_DELIVERY.read_text())
    assert doc["mission"]["items"][2]["command"] == 211 and doc["mission"]["items"][2]["params"][1] == 0
    route = route_from_items(read_mission(PX4_DELIVERY))
    assert [w.get("release", 0) for w in route] == [0, 1, 0]
    assert route[1]["action"] == "land"


@pytest.mark.parametrize("command, action, released", [
    (211, 0.0, True),             # GRIPPER_ACTION_RELEASE
    (211, float("nan"), True),    # unset param2: 0, as the autopilots read it
    (211, 1.0, False),            # GRIPPER_ACTION_GRAB: adds nothing (the mass picked up is not known)
    (211, 2.0, False),            # GRIPPER_ACTION_HOLD
    (42600, 4.0, False),          # WINCH_DELIVER: the autopilots drop nothing on it in a mission (warned)
    (42600, 0.0, False),          # WINCH_RELAXED
    (42600, 1.0, False),          # WINCH_RELATIVE_LENGTH_CONTROL: the payload still hangs on the line
    (42600, 8.0, False),          # WINCH_ABANDON_LINE
])
def test_release_commands(command, action, released):
    warnings.simplefilter("ignore")   # (WINCH_DELIVER warns: test_winch_deliver_warns_once_and_drops_nothing)
    raw = _raw(_item("item 0", 22, alt=10.0), _item("item 1", 16, lat=47.0005, lon=8.0, alt=10.0),
               _item("item 2", command, p2=action), _item("item 3", 16, lat=47.001, lon=8.0, alt=10.0),
               _item("item 4", 211, p2=1.0))
    route = route_from_items(raw)
    assert [w.get("release", 0) for w in route] == [0, int(released), 0]


def test_two_releases_on_one_waypoint_and_before_any_nav_item():
    raw = _raw(_item("item 0", 22, alt=10.0), _item("item 1", 211), _item("item 2", 211, p2=float("nan")),
               _item("item 3", 21))
    assert [w.get("release", 0) for w in route_from_items(raw)] == [2, 0]
    with pytest.raises(ValueError, match=r"^test\.plan: item 0: DO_GRIPPER \(211\) releases the payload before the "
                                         r"first navigation item.*valid: a release after"):
        route_from_items(_raw(_item("item 0", 211), _item("item 1", 22, alt=10.0)))


def test_winch_deliver_warns_once_and_drops_nothing():
    """DO_WINCH WINCH_DELIVER: the MAVLink spec's "lower, release, reel up", but neither ArduCopter (do_winch) nor PX4
    drops a payload on it in a mission: no release, one warning naming the items and saying so."""
    from wpt_receiver.notices import DronewptWarning
    raw = _raw(_item("item 0", 22, alt=10.0), _item("item 1", 42600, p2=4.0), _item("item 2", 42600, p2=4.0),
               _item("item 3", 21), _item("item 4", 42600, p2=1.0))
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        route = route_from_items(raw)
    assert [w.get("release", 0) for w in route] == [0, 0]
    said = [str(w.message) for w in rec if issubclass(w.category, DronewptWarning)]
    assert len(said) == 1 and said[0].startswith("test.plan: item 1, item 2: DO_WINCH (42600) WINCH_DELIVER drops "
                                                 "no payload here: ArduCopter")
    assert "MAVLink spec" in said[0] and "valid: a DO_GRIPPER release after it" in said[0]


# ------------------------------------------------------------------ the mission: the drop's energy
def _hover_route_cfg(release: int, payload_kg: float, hold_after_s: float = 100.0):
    """Take off to 10 m, hover 20 s, ``release`` payload releases, hover ``hold_after_s``, land; no wind (the hover
    is exactly at rest: momentum theory's closed form)."""
    d = load_config_dict()
    d["waypoints"] = [{"action": "takeoff", "z_m": 10.0},
                      {"action": "loiter", "x_m": -15.0, "z_m": 10.0, "hold_s": 20.0, "release": release},
                      {"action": "loiter", "x_m": -15.0, "z_m": 10.0, "hold_s": hold_after_s},
                      {"action": "land", "x_m": -15.0}]
    d["wind"].update(speed_m_s=0.0, gust_sigma_m_s=0.0)
    d["drone"]["payload_kg"] = payload_kg
    return config_from_dict(d)


def _run(cfg):
    import policies
    from mission_sim.world.runner import run_mission
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        res = run_mission(cfg, policies.make("step", policy_context(cfg)), charge=False)
    return res, [str(w.message) for w in rec]


def test_drop_saves_the_closed_form_hover_energy():
    """0.5 kg dropped after a 20 s hover: over the 100 s hover after it the propulsion energy is lower than the same
    mission's without the drop by (P_h(1.5 kg) - P_h(1.0 kg)) x the hover time, P_h = momentum theory's hover power
    (to rounding: the hover is at rest); before the drop the two runs draw the same; after it the drone draws what
    the payload-free drone draws, row by row."""
    drop, _ = _run(_hover_route_cfg(1, 0.5))
    keep, _ = _run(_hover_route_cfg(0, 0.5))
    bare, _ = _run(_hover_route_cfg(0, 0.0))
    t_r = drop.trajectory.mass.release_t_s[0]
    start = drop.timeseries["t_s"] - drop.timeseries["dt_s"]
    assert drop.trajectory.mass.release_t_s.tolist() == [t_r] and 20.0 < t_r < 30.0
    for a, b in ((drop, keep), (drop, bare)):
        assert np.array_equal(a.timeseries["t_s"], b.timeseries["t_s"])   # the same steps (the pads never on)
    before = (drop.timeseries["t_s"] <= t_r).to_numpy()   # (steps ending by the drop; a merged one may hold it)
    window = ((start >= t_r + 1.0) & (drop.timeseries["t_s"] <= t_r + 99.0)).to_numpy()
    e = {k: r.timeseries["e_propulsion_j"].to_numpy() for k, r in (("drop", drop), ("keep", keep), ("bare", bare))}
    dt = drop.timeseries["dt_s"].to_numpy()
    assert np.array_equal(e["drop"][before], e["keep"][before])
    p = drop.config.drone
    closed = (hover_power_w(p, 1.5) - hover_power_w(p, 1.0)) * dt[window].sum()
    assert dt[window].sum() > 95.0
    assert e["keep"][window].sum() - e["drop"][window].sum() == pytest.approx(closed, rel=1e-9)
    assert closed > 5000.0   # (~76 W x 98 s: the drop is worth kJ)
    after = (start >= t_r).to_numpy()
    assert np.array_equal(e["drop"][after], e["bare"][after])
    # the summary's split, the mass column, the landing mass
    s = drop.summary
    assert s["takeoff_mass_kg"] == 1.5 and s["landing_mass_kg"] == 1.0
    assert s["payload_releases"] == 1 and s["first_release_t_s"] == t_r
    # the split is at the drop's sample: the quiet-flight step merging the hover's samples across it (start before
    # t_r, end after) is split by its samples' powers, the hover at 1.0 kg from t_r (on the sample grid here) on
    across = ((start < t_r) & (drop.timeseries["t_s"] > t_r)).to_numpy()
    assert across.sum() == 1 and (t_r / drop.config.sim.traj_dt_s) % 1 == pytest.approx(0, abs=1e-9)
    end = float(drop.timeseries["t_s"].to_numpy()[across][0])
    share = hover_power_w(p, 1.0) * (end - t_r)
    assert e["drop"][across][0] == pytest.approx(hover_power_w(p, 1.5) * (t_r - start.to_numpy()[across][0]) + share,
                                                 rel=1e-12)
    assert s["propulsion_energy_before_release_j"] == pytest.approx(e["drop"][~after].sum() - share, rel=1e-12)
    assert s["propulsion_energy_after_release_j"] == pytest.approx(e["drop"][after].sum() + share, rel=1e-12)
    assert keep.summary["propulsion_energy_j"] - s["propulsion_energy_j"] > closed   # (and the landing's share)
    mass = drop.timeseries["mass_kg"].to_numpy()
    assert set(mass[~after & ~across]) == {1.5} and set(mass[after]) == {1.0}
    # the row holding the drop: the mass averaged over its step as its energy is (it read 1.5, its first sample's)
    t0 = start.to_numpy()[across][0]
    assert mass[across][0] == pytest.approx((1.5 * (t_r - t0) + 1.0 * (end - t_r)) / (end - t0), rel=1e-12)
    assert 1.0 < mass[across][0] < 1.5
    assert "mass_kg" not in bare.timeseries and "takeoff_mass_kg" not in bare.summary
    # flight_time_gain_s's hover power: the landing mass's (the gain is 0 here: no charging)
    from mission_sim.world.runner import flight_time_gain_s
    cfg = drop.config
    assert flight_time_gain_s(cfg, 0.9, 0.8, 1.0) / flight_time_gain_s(cfg, 0.9, 0.8) == pytest.approx(
        hover_power_w(p, 1.5) / hover_power_w(p, 1.0), rel=1e-12)


def test_trajectory_planned_for_other_masses_is_refused():
    """A trajectory keeps the mass schedule of the config it was planned from; run with a drone that gives other
    masses (planned with payload 0.5 kg and a drop, run with none; or the other way round) it is refused in one line
    rather than flying the planning masses silently. The same masses: runs (and draws what planning in the run
    draws); a route without a release under both drones flies the run's drone.total_mass_kg, as before."""
    import policies
    from mission_sim.world.runner import run_mission
    from mission_sim.world.trajectory import plan_mission
    drop, none = _hover_route_cfg(1, 0.5, hold_after_s=10.0), _hover_route_cfg(1, 0.0, hold_after_s=10.0)
    for planned, run in ((drop, none), (none, drop)):
        pol = policies.make("step", policy_context(run))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with pytest.raises(ValueError, match=r"^the trajectory was planned for (1\.5 kg, 1 kg from t = [\d.]+ s|"
                                                 r"1 kg throughout), the run's drone flies .*; valid: a trajectory "
                                                 r"planned from the run's config") as exc:
                run_mission(run, pol, trajectory=plan_mission(planned), charge=False)
        assert "\n" not in str(exc.value)
    pol = policies.make("step", policy_context(drop))
    a = run_mission(drop, pol, trajectory=plan_mission(drop), charge=False)
    b = run_mission(drop, pol, charge=False)
    assert a.summary["propulsion_energy_j"] == pytest.approx(b.summary["propulsion_energy_j"], rel=1e-12)
    light, heavy = _hover_route_cfg(0, 0.0, hold_after_s=10.0), _hover_route_cfg(0, 0.5, hold_after_s=10.0)
    r = run_mission(heavy, policies.make("step", policy_context(heavy)), trajectory=plan_mission(light), charge=False)
    assert r.summary["propulsion_energy_j"] > b.summary["propulsion_energy_j"]   # (1.5 kg throughout)


def test_trajectory_propulsion_w_follows_the_mass_schedule():
    """``Trajectory.propulsion_w`` (the materialised plan's) draws what the run draws: the hover before the drop at
    1.5 kg, after it at 1.0 kg (momentum theory's closed form: at rest, no wind), not the take-off mass throughout;
    a drone that does not give the plan's masses is refused as by the run."""
    from mission_sim.world.trajectory import plan_mission
    cfg = _hover_route_cfg(1, 0.5, hold_after_s=10.0)
    tr = plan_mission(cfg)
    p = tr.propulsion_w(cfg.drone)
    t_r = tr.mass.release_t_s[0]
    hover = tr.phase == "hover"
    speed = np.linalg.norm(tr.velocity_m_s(), axis=1)
    still = hover & (speed < 1e-9)
    before, after = still & (tr.t_s < t_r - 1.0), still & (tr.t_s > t_r + 1.0)
    assert before.sum() > 80 and after.sum() > 40
    assert np.allclose(p[before], hover_power_w(cfg.drone, 1.5), rtol=1e-12)
    assert np.allclose(p[after], hover_power_w(cfg.drone, 1.0), rtol=1e-12)
    assert hover_power_w(cfg.drone, 1.5) - hover_power_w(cfg.drone, 1.0) > 50.0
    with pytest.raises(ValueError, match=r"^the trajectory was planned for 1\.5 kg, 1 kg from t"):
        tr.propulsion_w(_hover_route_cfg(1, 0.0).drone)


def test_materialised_plan_keeps_the_drop():
    """``plan_mission`` (all samples at once: ``dronewpt telemetry``'s trajectory) carries the mass schedule: the run
    over it draws what the run planning in blocks draws."""
    import policies
    from mission_sim.world.runner import run_mission
    from mission_sim.world.trajectory import plan_mission
    cfg = _hover_route_cfg(1, 0.5, hold_after_s=10.0)
    pol = policies.make("step", policy_context(cfg))
    a = run_mission(cfg, pol, charge=False)
    b = run_mission(cfg, pol, trajectory=plan_mission(cfg), own_route=True, charge=False)
    assert b.summary["propulsion_energy_j"] == a.summary["propulsion_energy_j"]
    assert b.summary["landing_mass_kg"] == 1.0


def test_payload_zero_flies_as_before():
    """Payload 0: a route's release changes no sample's power (the take-off mass path, no mass schedule) and warns
    once that nothing is dropped; no mass column, no payload keys."""
    from mission_sim.world.samples import MissionSamples
    from mission_sim.world.trajectory import PlannedTrajectory
    with_r, without = _hover_route_cfg(1, 0.0), _hover_route_cfg(0, 0.0)
    a, b = (MissionSamples(c, PlannedTrajectory(c), False, 0.0) for c in (with_r, without))
    assert not a.mass_changes
    assert np.array_equal(a.chunk(0, a.n).p_w, b.chunk(0, b.n).p_w)
    res, said = _run(with_r)
    assert len([w for w in said if "payload" in w]) == 1
    assert "drone.payload_kg = 0: nothing is dropped" in said[0]
    from mission_sim.setup_warnings import mission_warnings   # (the charged run's and a study's set: it is in there)
    assert sum("nothing is dropped" in w for w in mission_warnings(with_r, own_route=False)) == 1
    assert not any("payload" in w for w in mission_warnings(with_r, replay=True))   # a replay flies the log's track
    assert "mass_kg" not in res.timeseries


def test_more_releases_than_parcels_warn_once():
    d = load_config_dict()
    d["waypoints"] = [{"action": "takeoff", "z_m": 10.0}, {"action": "loiter", "z_m": 10.0, "hold_s": 2.0, "release": 3},
                      {"action": "land"}]
    cfg = config_from_dict(apply_overrides(d, {"drone.payload_kg": 0.4, "drone.release_kg": 0.2}))
    from mission_sim.setup_warnings import payload_warnings
    said = payload_warnings(cfg)
    assert len(said) == 1 and said[0].startswith("1 of the route's 3 payload releases find no payload left")


# ------------------------------------------------------------------ bad inputs
@pytest.mark.parametrize("key, value, needle", [
    ("drone.payload_kg", -0.5, "drone.payload_kg=-0.5 is invalid; valid range: [0, 1000] kg"),
    ("drone.release_kg", -0.1, "drone.release_kg=-0.1 is invalid; valid range: [0, 1000] kg"),
    ("drone.release_kg", 0.3, "drone.release_kg=0.3 is invalid; valid range: [0, payload_kg=0.0] kg"),
])
def test_bad_payload_values(key, value, needle):
    with pytest.raises(ValueError) as exc:
        config_from_dict(apply_overrides(load_config_dict(), {key: value}))
    assert str(exc.value).startswith(needle) and "\n" not in str(exc.value)


def test_bad_release_count():
    d = load_config_dict()
    d["waypoints"] = [{"action": "takeoff", "z_m": 10.0, "release": -1}]
    with pytest.raises(ValueError, match=r"^waypoints\.0\.release=-1 is invalid; valid range: integer 0\.\.1000$"):
        config_from_dict(d)


def test_cli_negative_payload_is_one_line(capsys):
    from _cli_helpers import one_error_line
    line = one_error_line(capsys, ["mission", "--dry-run", "--set", "drone.payload_kg=-1"])
    assert "drone.payload_kg=-1" in line and "valid range: [0, 1000] kg" in line


def test_lighter_drone_is_pushed_further_by_the_gusts():
    """The position hold's error is driven by force / mass (wind.hover_error_m): after the drop the same gusts push
    the 1.0 kg drone 1.5 times as far as the 1.5 kg one (once the release's transient has died out: zeta 0.8,
    omega 2 rad/s, e^-1.6 t); before it the two trajectories are the same numbers."""
    from mission_sim.world.trajectory import PlannedTrajectory

    def cfg(release):
        d = load_config_dict()
        d["waypoints"] = [{"action": "takeoff", "z_m": 10.0},
                          {"action": "loiter", "x_m": -15.0, "z_m": 10.0, "hold_s": 10.0, "release": release},
                          {"action": "loiter", "x_m": -15.0, "z_m": 10.0, "hold_s": 60.0}, {"action": "land", "x_m": -15.0}]
        d["drone"]["payload_kg"] = 0.5
        return config_from_dict(d)
    drop, keep = (PlannedTrajectory(cfg(r)).materialise() for r in (1, 0))
    t_r = drop.mass.release_t_s[0]
    hold = np.array([-15.0, 0.0, 10.0])
    before = drop.t_s < t_r
    assert np.array_equal(drop.pos_m[before], keep.pos_m[before])
    late = (drop.t_s > t_r + 20.0) & (drop.t_s < t_r + 58.0)
    dev_drop, dev_keep = drop.pos_m[late] - hold, keep.pos_m[late] - hold
    assert np.abs(dev_keep).max() > 0.01   # (the gusts move it: default wind, 0.6 m/s gusts)
    assert dev_drop == pytest.approx(1.5 * dev_keep, rel=1e-6, abs=1e-9)


def test_config_dict_and_sweep_fingerprint_of_a_config_without_release_as_before():
    """The payload keys (``drone.release_kg``, a waypoint's ``release``) are left out of ``config_to_dict`` at 0: a
    base mission without a release has the dict, hence the sweep fingerprint, it had before them (f911edc: every
    other key), so an older sweep folder is not refused as another base mission; the raw default TOML (a replay
    study's base) lacks ``release_kg`` too. A release or a release_kg is kept (and round-trips)."""
    import hashlib
    from mission_sim.config import OMITTED_AT_DEFAULT, config_to_dict
    from mission_sim.studies.study import canonical_json
    from mission_sim.studies.worst_cases import base_fingerprint
    cfg = config_from_dict(load_config_dict(None))
    full = dc.asdict(cfg)
    before = {**full, "pads": [{k: v for k, v in p.items() if v is not None} for p in full["pads"]],
              "waypoints": [{k: v for k, v in w.items() if v is not None and k not in OMITTED_AT_DEFAULT["waypoints"]}
                            for w in full["waypoints"]],
              "drone": {k: v for k, v in full["drone"].items() if k not in OMITTED_AT_DEFAULT["drone"]}}
    assert "release_kg" in full["drone"] and "release_kg" not in before["drone"]
    assert config_to_dict(cfg) == before
    assert base_fingerprint(config_to_dict(cfg)) == hashlib.sha256(canonical_json(before).encode()).hexdigest()[:16]
    assert "release_kg" not in load_config_dict(None)["drone"]
    d = apply_overrides(load_config_dict(None), {"drone.payload_kg": 0.9, "drone.release_kg": 0.3})
    d["waypoints"] = [{"action": "takeoff", "x_m": 0.0, "y_m": 0.0, "z_m": 5.0, "release": 2},
                      {"action": "land", "x_m": 0.0, "y_m": 0.0, "z_m": 5.0}]
    out = config_to_dict(config_from_dict(d))
    assert out["drone"]["release_kg"] == 0.3 and [w.get("release") for w in out["waypoints"]] == [2, None]
    assert config_from_dict(out) == config_from_dict(d)


def test_a_sweep_warns_once_of_a_release_without_payload(tmp_path):
    """A study over a delivery route (a release) whose cases carry no payload in some: the cases run with
    ``warn=False`` (warned once per study, as run_mission's docstring says), and the study's lines counted no payload
    warning. Now one line: 1 of 2 cases, with the run's own message as the example."""
    import policies
    from mission_sim.setup_warnings import payload_warnings
    from mission_sim.studies.prepare import prepare_study
    from mission_sim.studies.study import load_study
    from wpt_receiver.notices import DronewptWarning
    base = tmp_path / "base.toml"
    base.write_text('[wind]\nspeed_m_s = 0.0\ngust_sigma_m_s = 0.0\n'
                    '[[waypoints]]\naction = "takeoff"\nz_m = 10.0\n'
                    '[[waypoints]]\naction = "loiter"\nx_m = -15.0\nz_m = 10.0\nhold_s = 5.0\nrelease = 1\n'
                    '[[waypoints]]\naction = "land"\nx_m = -15.0\n')
    (tmp_path / "s.toml").write_text(f'[study]\nname = "drop"\nbase = {str(base)!r}\n'
                                     '[grid]\n"drone.payload_kg" = [0.0, 0.5]\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prepare_study(load_study(tmp_path / "s.toml"), policies.make, policies.available())
    said = [str(w.message) for w in caught if issubclass(w.category, DronewptWarning)]
    cfg = _hover_route_cfg(1, 0.0)
    said = [s for s in said if "pad their route never energises" not in s]   # (the base's pad: another kind)
    assert said == ["1 of 2 cases of study 'drop' have a payload release with no payload left to drop, e.g.: "
                    + payload_warnings(cfg)[0]]


def test_tilt_after_the_drop_is_the_lighter_drones():
    """Steady 5 m/s wind, no gusts, hovering at rest: the thrust leans into the drag F, tilt = atan2(F, m g), at
    1.5 kg before the drop and 1.0 kg after it (0.0416 / 0.0624 rad: the lighter drone leans further); planning the
    tilt with the take-off mass throughout would keep 0.0416 rad after the drop."""
    from mission_sim.config import config_to_dict
    from mission_sim.world.trajectory import plan_mission
    from mission_sim.world.wind import G_M_S2, drag_force_n
    d = config_to_dict(_hover_route_cfg(1, 0.5, hold_after_s=20.0))
    d["wind"].update(speed_m_s=5.0, gust_sigma_m_s=0.0)
    cfg = config_from_dict(d)
    tr = plan_mission(cfg)
    t_r = tr.mass.release_t_s[0]
    speed = np.linalg.norm(tr.velocity_m_s(), axis=1)
    still = (tr.phase == "hover") & (speed < 1e-9)
    assert np.ptp(tr.wind_m_s[still], axis=0).max() == 0.0 and np.linalg.norm(tr.wind_m_s[still][0]) == 5.0
    force = drag_force_n(cfg.wind, tr.wind_m_s[still][:1], np.zeros((1, 3)))[0]
    for sel, m in ((still & (tr.t_s < t_r - 1.0), 1.5), (still & (tr.t_s > t_r + 1.0), 1.0)):
        assert sel.sum() > 40
        want = math.atan2(math.hypot(force[0], force[1]), m * G_M_S2 - force[2])
        assert np.allclose(tr.tilt_rad[sel], want, rtol=1e-12, atol=0)
    assert tr.tilt_rad[still & (tr.t_s > t_r + 1.0)][0] > 1.4 * tr.tilt_rad[still & (tr.t_s < t_r - 1.0)][0]
