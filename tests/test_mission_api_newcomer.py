"""A mission researcher's pass over the Python API (docs/robustness.md, "A mission researcher's pass over the
Python API"): the docs' Python blocks run as pasted, a config changed in Python is checked as a file is, numpy
numbers are numbers, a policy made for another mission is refused, and the physics agrees with closed forms."""

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

import policies
from mission_sim.config import (apply_overrides, check_seed, config_from_dict, load_config, load_config_dict,
                                policy_context)
from mission_sim.world.runner import run_mission

DOC = Path(__file__).resolve().parents[1] / "docs" / "mission.md"
R = dataclasses.replace


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python\n(.*?)```", text[text.index("## From Python"):], flags=re.S)


def test_the_python_blocks_of_docs_mission_run_as_pasted(tmp_path, monkeypatch, capsys):
    """In order, in one namespace, in an empty folder; the first block's printed numbers are the ones its
    comment shows, and the sweep's cases equal the loop's missions."""
    monkeypatch.chdir(tmp_path)
    blocks = _python_blocks(DOC.read_text())
    assert len(blocks) == 5
    ns: dict = {}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), ns)
    out = capsys.readouterr().out.splitlines()
    shown = re.search(r"print\(len\(ts\).*# (.*)\n", blocks[0]).group(1)
    assert out[0] == shown
    for f in ("timeseries.parquet", "summary.json", "soc.png", "power.png"):
        assert (tmp_path / "out" / "py_mission" / f).is_file()
    assert not (tmp_path / "out" / "py_mission" / "timeseries.csv").exists()
    rows, streamed = ns["rows"], ns["streamed"].summary
    assert np.all(np.diff(np.floor(rows["t_s"].to_numpy()[:-1])) >= 1)   # one stored row per second
    assert streamed["final_soc"] == ns["s"]["final_soc"]                   # the summary uses every step
    table, done = ns["table"], ns["done"].results
    assert len(table) == 4 and len(done) == 4 and set(done["status"]) == {"ok"}
    for m in (0.8, 1.2):   # the sweep's model_based case is the loop's mission at capacity 1.3 A h
        a = table[(table.mass_kg == m) & (table.capacity_ah == 1.3)]["final_soc"].item()
        b = done[(done["drone.mass_kg"] == m) & (done["policy"] == "model_based")]["final_soc"].item()
        assert a == b


@pytest.mark.parametrize("change, message", [
    (lambda c: R(c, battery=R(c.battery, capacity_ah=1300.0)),   # mAh for A h
     "battery.capacity_ah=1300.0 is invalid; valid range: [0.01, 1000] A h"),
    (lambda c: R(c, drone=R(c.drone, payload_kg=5000.0)), "drone.payload_kg=5000.0 is invalid; valid range: [0, 1000] kg"),
    (lambda c: R(c, link=R(c.link, f_hz=85.0)), "link.f_hz=85.0 is invalid; valid range: [10000, 3e+07] Hz"),   # kHz
    (lambda c: R(c, pads=(R(c.pads[0], hover_time_s=1e7),)),
     "hover_time_s=10000000.0 is invalid; valid range: [0, 1e+06] s"),   # (the pad's own check: its shared range)
    (lambda c: R(c, pads=()), "pads=() is invalid; valid: a tuple of at least one PadConfig"),
    (lambda c: R(c, pads=c.pads[0]), "pads=PadConfig(x_m=0.0, y_m=0.0, z_m=0.0, hover_time_s=60.0) is invalid"),
    (lambda c: R(c, seed=-1), "seed=-1 is invalid; valid range: integer in [0, 2^63)"),
    (lambda c: R(c, seed=1.5), "seed=1.5 is invalid"),
    (lambda c: R(c, drone=c.battery), "drone=BatteryParams("),
    # the sections' own integer checks: 'cannot convert float NaN to integer', OverflowError for inf
    (lambda c: R(c, drone=R(c.drone, n_rotors=float("nan"))), "n_rotors=nan is invalid; valid range: integer >= 1"),
    (lambda c: R(c, battery=R(c.battery, n_series=float("inf"))), "n_series=inf is invalid; valid range: integer 1..32"),
    # a numeric string passed float() and crashed later (hover_power_w: can't multiply sequence by non-int)
    (lambda c: R(c, drone=R(c.drone, n_rotors="4")), "n_rotors='4' is invalid; valid type: integer"),
    (lambda c: R(c, battery=R(c.battery, n_series="6")), "n_series='6' is invalid; valid type: integer"),
])
def test_a_config_changed_in_python_is_checked_as_a_file_is(change, message):
    """``dataclasses.replace`` skipped config_from_dict's ranges: 1300 A h ran, pads=() died in ``min()``. Every
    numeric key with NaN, +-inf, -1, 0 and 1e308 through ``replace`` (66 keys): refused naming it, or in range."""
    with pytest.raises(ValueError) as exc:
        change(load_config())
    assert message in str(exc.value)


@pytest.mark.parametrize("change, message", [
    # accepted (float("3") passed the ranges; the string ran into the mission) ...
    (lambda c: R(c, wind=R(c.wind, speed_m_s="3")), "speed_m_s='3' is invalid; valid type: number"),
    (lambda c: R(c, battery=R(c.battery, capacity_ah="1.3")), "capacity_ah='1.3' is invalid; valid type: number"),
    (lambda c: R(c, link=R(c.link, f_hz="85000")), "f_hz='85000' is invalid; valid type: number"),
    # ... or a raw TypeError ("'<=' not supported between 'float' and 'str'", "must be real number, not str")
    (lambda c: R(c, sim=R(c.sim, control_period_s="1e-4")), "control_period_s='1e-4' is invalid; valid type: number"),
    (lambda c: R(c, pads=(R(c.pads[0], z_m="0"),)), "z_m='0' is invalid; valid type: number"),
    # bools as a file's: refused ("valid type: number"), not 1.0
    (lambda c: R(c, wind=R(c.wind, speed_m_s=True)), "speed_m_s=True is invalid; valid type: number"),
    (lambda c: R(c, mission=R(c.mission, hover_time_s=None)), "hover_time_s=None is invalid; valid type: number"),
])
def test_numbers_from_python_are_type_checked_as_a_files_are(change, message):
    with pytest.raises(ValueError) as exc:
        change(load_config())
    assert str(exc.value) == message


def test_number_types_of_files_and_set_are_unchanged():
    """TOML and ``--set`` give numbers (accepted as before) and bools (refused as before, naming the key); None
    stays allowed where the key may be absent (a pad's hover_time_s)."""
    from mission_sim.cli.common import parse_set
    from mission_sim.config import _check_section

    cfg = load_config()
    sets = parse_set(["wind.speed_m_s=3", "battery.capacity_ah=1.3", "link.f_hz=85e3", "sim.control_period_s=1e-4"])
    assert config_from_dict(apply_overrides(load_config_dict(), sets)) == cfg
    assert R(cfg, pads=(R(cfg.pads[0], hover_time_s=None),)).pads[0].hover_time_s is None
    for sets in (["wind.speed_m_s=true"], ['wind.speed_m_s="3"']):
        with pytest.raises(ValueError, match=r"^wind\.speed_m_s=(True|'3') is invalid; valid type: number$"):
            config_from_dict(apply_overrides(load_config_dict(), parse_set(sets)))
    bad = R(cfg.wind)   # a section whose value changed after its own checks: MissionConfig names the key
    object.__setattr__(bad, "speed_m_s", "3")
    with pytest.raises(ValueError, match=r"^wind\.speed_m_s='3' is invalid; valid type: number$"):
        _check_section("wind", type(bad), bad)


def test_every_key_out_of_range_through_replace_is_refused_naming_it():
    from mission_sim.config import PLAUSIBLE, WaypointConfig

    cfg = load_config()
    for key, rng in PLAUSIBLE.items():
        sec, name = key.split(".")
        for v in (float("nan"), float("inf"), -1.0, 0.0, 1e308):
            def change():
                if sec == "pads":
                    return R(cfg, pads=(R(cfg.pads[0], **{name: v}),) + cfg.pads[1:])
                if sec == "waypoints":   # (a route's speed and holds, since 2026-11-27 midday)
                    return R(cfg, waypoints=(R(WaypointConfig(action="loiter", x_m=10.0, z_m=20.0), **{name: v}),))
                return R(cfg, **{sec: R(getattr(cfg, sec), **{name: v})})
            if rng.contains(v):
                continue
            with pytest.raises(ValueError) as exc:   # (not OverflowError, not a message without the key)
                change()
            assert name in str(exc.value) or "cruise_altitude_m" in str(exc.value), (key, v, str(exc.value))


def test_a_config_changed_in_python_within_range_is_the_files_config():
    cfg = load_config()
    mine = R(cfg, battery=R(cfg.battery, capacity_ah=2.0), pads=list(cfg.pads), seed=np.int64(3))
    theirs = config_from_dict(apply_overrides(load_config_dict(), {"battery.capacity_ah": 2.0, "seed": 3}))
    assert mine == theirs and type(mine.pads) is tuple and type(mine.seed) is int
    assert len(R(cfg, pads=cfg.pads * 835).pads) == 1670   # more than a file's 100: long missions (test_budget)


def test_numpy_numbers_are_numbers():
    """``np.arange`` gives np.int64, which was 'invalid; valid type: integer' (config) and 'valid: a number,
    string or boolean' (study grids); a 1-D array was no grid."""
    from mission_sim.studies.study import case_id, expand_cases, parse_study

    d = apply_overrides(load_config_dict(), {"battery.n_series": np.int64(6), "drone.mass_kg": np.float32(1.5),
                                             "seed": np.int64(4)})
    cfg = config_from_dict(d)
    assert (cfg.battery.n_series, cfg.drone.mass_kg, cfg.seed) == (6, 1.5, 4) and type(cfg.battery.n_series) is int
    from mission_sim.world.battery import BatteryParams
    from mission_sim.world.power import DroneParams
    assert type(DroneParams(n_rotors=np.int64(6)).n_rotors) is int and type(BatteryParams(n_series=6.0).n_series) is int
    assert check_seed(np.uint8(9)) == 9
    with pytest.raises(ValueError, match=r"battery\.n_series=np\.float64\(6\.5\) is invalid; valid type: integer"):
        config_from_dict(apply_overrides(load_config_dict(), {"battery.n_series": np.float64(6.5)}))
    py = parse_study({"study": {"name": "s"}, "grid": {"battery.n_series": np.arange(6, 9),
                                                       "drone.mass_kg": np.linspace(0.8, 1.2, 3)}})
    toml = parse_study({"study": {"name": "s"}, "grid": {"battery.n_series": [6, 7, 8], "drone.mass_kg": [0.8, 1.0, 1.2]}})
    a, b = expand_cases(py, "fp"), expand_cases(toml, "fp")
    assert [c.case_id for c in a] == [c.case_id for c in b] and len(a) == 9
    assert all(type(c.params["battery.n_series"]) is int for c in a)
    assert a[0].case_id == case_id(b[0].params, "fp")


@pytest.mark.parametrize("override, message", [
    ({"sim.control_period_s": 5e-5}, "the policy's control_period_s=0.0001 is invalid for this mission; valid: "
                                     "sim.control_period_s=5e-05"),
    ({"link.rated_i2_a": 10.0}, "the policy's rated_i2_a=15.0 is invalid for this mission; valid: link.rated_i2_a=10.0"),
])
def test_run_mission_refuses_a_policy_made_for_another_mission(override, message):
    """It ran: the model-based filter discretised for 100 us, called every 50 us."""
    cfg = config_from_dict(apply_overrides(load_config_dict(), override))
    pol = policies.make("model_based", policy_context(load_config()))
    with pytest.raises(ValueError) as exc:
        run_mission(cfg, pol)
    assert message in str(exc.value)


def test_a_summary_only_result_says_how_to_get_a_time_series(tmp_path):
    from mission_sim.figures.mission import plot_mission
    from mission_sim.world.results import MissionResult

    res = MissionResult(timeseries=None, summary={})
    for call in (lambda: res.write(tmp_path / "w"), lambda: plot_mission(res, tmp_path / "p")):
        with pytest.raises(ValueError, match=r"no time series \(run_mission\(\.\.\., frame=False\)\); valid"):
            call()
    assert not (tmp_path / "w").exists()


def test_hover_power_is_momentum_theory():
    """``T^1.5 / sqrt(2 rho A) / (FM eta) + avionics`` written out here for the default drone: 98.79 W."""
    from mission_sim.world.power import hover_power_w, propulsion_power_w

    d = load_config().drone
    t = d.total_mass_kg * 9.80665
    ideal = t * math.sqrt(t / (2 * d.air_density_kg_m3 * d.n_rotors * math.pi * d.rotor_radius_m ** 2))
    p = ideal / d.figure_of_merit / d.drive_efficiency + d.avionics_w
    assert hover_power_w(d) == pytest.approx(p, rel=1e-14) and round(p, 2) == 98.79
    assert propulsion_power_w(d, 0.0, 0.0) == pytest.approx(p, rel=1e-12)


def test_flight_time_without_pads_is_usable_energy_over_hover_power():
    """Take off to 5 m, hover until the pack is empty, no wind, pads off: the pack empties after the usable
    energy ``n Q int_0^SoC0 OCV`` less the battery's losses, at the hover power (5 s of climb at more)."""
    from mission_sim.world.power import hover_power_w

    d = load_config_dict()
    d["waypoints"] = [{"action": "takeoff", "z_m": 5.0}, {"action": "loiter", "x_m": 0.0, "y_m": 0.0, "z_m": 5.0,
                                                         "hold_s": 3000.0}, {"action": "land"}]
    d["wind"].update(speed_m_s=0.0, gust_sigma_m_s=0.0)
    cfg = config_from_dict(d)
    s = run_mission(cfg, policies.make("model_based", policy_context(cfg)), charge=False, frame=False).summary
    p = hover_power_w(cfg.drone)
    assert s["battery_depleted"] and s["final_soc"] == pytest.approx(0.0, abs=1e-9)
    expected = (cfg.battery.usable_energy_j(cfg.battery.initial_soc) - s["battery_losses_j"]) / p
    assert s["depleted_at_s"] == pytest.approx(expected, abs=1.0)              # 1396.4 s against 1396.3 s
    assert cfg.battery.usable_energy_j(cfg.battery.initial_soc) / p == pytest.approx(1418.4, abs=0.1)


def test_steady_secondary_current_is_the_series_series_closed_form():
    """At resonance, V2 in phase with I2: ``|I2| = (w Lm V1 - R1 |V2|) / (R1 R2 + (w Lm)^2)`` (11.07 A in RM
    at Table I); the mission's coarse rows with the pad fully on (ideal devices: R1, R2 the link's) agree to
    2e-5, and the rectifier's DC power is the fundamental's ``|V2| |I2| / 2`` (to 2e-5)."""
    cfg = config_from_dict(apply_overrides(load_config_dict(), {"link.devices": "ideal"}))
    ts = run_mission(cfg, policies.make("model_based", policy_context(cfg)), charge=False).timeseries
    assert len(ts) and not ts["tx_on"].any()   # (charge=False: the pads stay off)
    ts = run_mission(cfg, policies.make("model_based", policy_context(cfg))).timeseries
    lk = cfg.link
    on = ts[ts["tx_on"] & ~ts["fine"] & (ts["v1_v"] > 0.99 * 4 / math.pi * lk.vdc_v)]
    assert len(on) > 500
    wm = 2 * math.pi * lk.f_hz * on["lm_h"]
    i2 = (wm * on["v1_v"] - lk.r1_ohm * on["v2_v"].abs()) / (lk.r1_ohm * lk.r2_ohm + wm ** 2)
    assert np.max(np.abs(on["i2_amp_a"] / i2 - 1)) < 2e-5
    charging = on[on["rect_current_a"] > 0.5]
    p_dc = charging["battery_v"] * charging["rect_current_a"]
    # (rect_current_a is the step mean, v2 and i2 the step's end: 8e-6 apart)
    assert np.max(np.abs(p_dc / (charging["v2_v"].abs() * charging["i2_amp_a"] / 2) - 1)) < 2e-5


def test_a_pad_below_the_home_ground_is_reached_and_charges():
    """A pad at z = -3 m (a pads file's pad lower than home) was hovered over at z = 0 (the ground clamp), 3 m
    above its coil: it never energised and the mission charged at pad 0 only, silently."""
    out = {}
    for z in (0.0, -3.0):
        cfg = config_from_dict(apply_overrides(load_config_dict(), {"pads.1.z_m": z}))
        res = run_mission(cfg, policies.make("model_based", policy_context(cfg)))
        ts = res.timeseries
        at_pad1 = ts[(ts["phase"] == "charge") & ((ts["x_m"] - 40.0).abs() < 1.0)]
        gap = at_pad1["z_m"] - z
        assert len(at_pad1) > 500 and gap.min() > 0.1 and gap.max() < 0.25
        assert ts["z_m"][~ts["phase"].isin(["approach", "charge", "depart"])].min() >= 0.0   # home's ground elsewhere
        out[z] = res.summary
    assert out[-3.0]["charge_time_s"] == pytest.approx(out[0.0]["charge_time_s"], rel=0.01)
    assert out[-3.0]["energy_from_source_j"] == pytest.approx(out[0.0]["energy_from_source_j"], rel=0.05)


def test_each_pad_is_the_ground_of_its_own_approach_charge_and_depart():
    """With pads at -3 m and 0 m the lowest pad's z was the ground of every pad: at the pad at 0 m (hover gap 0.03 m,
    8 m/s wind, 3 m/s gusts) the coil went 0.118 m below it while charging; each pad's own z limits its segments."""
    from mission_sim.world.trajectory import plan_mission

    cfg = load_config()
    cfg = R(cfg, pads=(R(cfg.pads[0], z_m=-3.0), R(cfg.pads[1], z_m=0.0)), mission=R(cfg.mission, hover_gap_m=0.03),
            wind=R(cfg.wind, speed_m_s=8.0, gust_sigma_m_s=3.0))
    tr = plan_mission(cfg)
    z, ph = tr.pos_m[:, 2], tr.phase
    for pad in cfg.pads:
        near = (np.hypot(tr.pos_m[:, 0] - pad.x_m, tr.pos_m[:, 1] - pad.y_m) < 1.0) & np.isin(
            ph, ["approach", "charge", "depart"])
        chg = near & (ph == "charge")
        assert chg.sum() > 200 and z[near].min() >= pad.z_m
        assert z[chg].min() == pad.z_m + 0.03   # the coil's floor over its own pad, reached in this wind
    assert z[~np.isin(ph, ["approach", "charge", "depart"])].min() >= 0.0


def test_run_mission_and_make_name_a_wrong_kind_of_argument():
    """2026-11-27: `run_mission(cfg, "step")` (a name where the policy object belongs) was `AttributeError: 'str' object
    has no attribute 'reset'` from inside the loop; `policies.make(None)` and `make("step", 5)` AttributeErrors too."""
    cfg = load_config()
    with pytest.raises(ValueError, match=re.escape("policy='step' is invalid; valid: a policy object with reset() and "
                                                   "act(), e.g. policies.make('step', policy_context(cfg))")):
        run_mission(cfg, "step", frame=False)
    with pytest.raises(ValueError, match=re.escape("cfg=None is invalid; valid: a MissionConfig")):
        run_mission(None, policies.make("step", policy_context(cfg)), frame=False)
    with pytest.raises(ValueError, match=re.escape("policy=None is invalid; valid: a name, one of hysteresis, ")):
        policies.make(None)
    with pytest.raises(ValueError, match=re.escape("ctx=5 is invalid; valid: a PolicyContext")):
        policies.make("step", 5)
