"""Loose ends of 2026-11-28 early morning: `sizing`'s defaults from the sizing rules (all of them), one story for
logs with an unknown armed state (`replay`, `mission --plan`, `calibrate`), one ground height, the policies' VL."""

from __future__ import annotations

import dataclasses

import pytest


def _patched_rules(monkeypatch, **fields):
    """``wpt_receiver.sizing.SizingRules`` with other defaults ``fields``."""
    import wpt_receiver.sizing as sizing
    rules = dataclasses.make_dataclass("SizingRules", [(k, float, dataclasses.field(default=v)) for k, v in
                                                       fields.items()], bases=(sizing.SizingRules,), frozen=True)
    monkeypatch.setattr(sizing, "SizingRules", rules)
    return rules


def _row() -> dict:
    """A stub sizing row (the table's columns)."""
    from mission_sim.cli.sizing import _COLUMNS
    return {c: 1.0 for c in _COLUMNS} | {"policy": "step", "part": "x", "v_case": None, "edge_ring_peak_v": 2.0,
                                         "turn_off_peak_a": 3.0}


def test_sizing_t_protect_and_c_out_defaults_and_help_come_from_the_sizing_rules(monkeypatch, capsys):
    """`sizing --t-protect` and `--c-out` had defaults 1e-4 s and 4.7e-3 F, copies of ``SizingRules``' (only
    ``--margin`` read the rules): other rules' defaults are now what a run without the options sizes with, and what
    --help says; a given value still wins."""
    import mission_sim.cli.sizing as cli_sizing
    from mission_sim.cli import main
    rules = _patched_rules(monkeypatch, margin=1.5, t_protect_s=2.5e-4, c_out_f=1e-3, v_margin=1.2)
    sized = []   # (the rules each run sizes with; the rows are stubbed: no simulation)
    monkeypatch.setattr(cli_sizing, "_rows", lambda args: sized.append(cli_sizing._rules(args)) or [_row()])
    assert main(["sizing", "--no-plot"]) == 0
    assert sized.pop() == rules()
    assert main(["sizing", "--no-plot", "--t-protect", "3e-5", "--c-out", "2e-3"]) == 0
    assert sized.pop() == rules(t_protect_s=3e-5, c_out_f=2e-3)
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["sizing", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default 0.00025, wpt_receiver.sizing.SizingRules); the voltage rating is 1.2 x" in text
    assert "(default 0.001, wpt_receiver.sizing.SizingRules)" in text
    assert "x worst-case |i2|, 1 .. 10 (default 1.5, wpt_receiver.sizing.SizingRules)" in text and "1.25" not in text
    assert "1e-4" not in text and "4.7e-3" not in text and "0.0047" not in text
    assert "1.1 x" not in text   # the description names the rules' v_margin, not a copy of its value


def test_sizing_table_prints_the_rules_it_sized_with(monkeypatch, capsys):
    """The table's footer said "ambient 40 C, sink +50 K", "V rating = 1.1 x" and "8 nH", copies of the rules'
    defaults: it prints the rules the rows were sized with (the rows are stubbed: no simulation)."""
    import mission_sim.cli.sizing as cli_sizing
    from mission_sim.cli import main
    _patched_rules(monkeypatch, t_amb_c=25.0, dt_sink_k=30.0, v_margin=1.3, l_stray_h=5e-9)
    monkeypatch.setattr(cli_sizing, "_rows", lambda args: [_row()])
    assert main(["sizing", "--no-plot"]) == 0
    out = capsys.readouterr().out
    assert "(ambient 25 C, sink +30 K); V rating = 1.3 x the simulated" in out
    assert "with 5 nH stray loop inductance" in out and "1.1 x" not in out


# --------------------------------------------------------------- logs whose armed state is unknown: one story
FLIGHTLOGS = __import__("pathlib").Path(__file__).parent / "data" / "flightlogs"
GROUND_LOGS = ["amc_backend_log_80k.bin", "pymavlink_test.BIN"]   # on the ground, no armed-state record (SOURCES.md)


@pytest.mark.parametrize("name", GROUND_LOGS)
def test_refusals_of_a_ground_log_with_unknown_armed_state_offer_what_each_command_takes(capsys, tmp_path, name):
    """`replay`'s refusal of such a log ended "valid: the log of a flight, or a log holding an uploaded mission",
    which only `mission --plan` flies: `replay` now offers the log of a flight; `mission --plan` still both."""
    from mission_sim.cli import main
    assert main(["replay", str(FLIGHTLOGS / name), "--no-plot", "--no-progress", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert "no flown track: the armed state is unknown" in err and err.endswith("valid: the log of a flight"), err
    argv = ["mission", "--plan", str(FLIGHTLOGS / name), "--no-plot", "--out", str(tmp_path / "m")]
    if name == "pymavlink_test.BIN":   # (it holds an uploaded mission: the flown track on request)
        argv += ["--set", "mission.from_log=flown"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "no flown track: the armed state is unknown" in err
    assert err.endswith("valid: the log of a flight, or a log holding an uploaded mission"), err
    assert list(tmp_path.iterdir()) == []


def test_replay_figures_shade_what_the_replay_counts_as_flown():
    """The replay figures shaded ``log.armed_periods`` under "armed": nothing for a log whose armed state is unknown
    (log171 with its armed-state records taken out), whose whole track the replay flies (and matplotlib warned of an
    empty legend). They shade the flown time, labelled as such; a log with its armed state: its armed periods."""
    import dataclasses

    from mission_sim.figures.replay import _shaded_periods
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.takeoff import flown_periods
    full = read_log(FLIGHTLOGS / "dronekit-la-testdata_log171.bin")
    log = dataclasses.replace(full, armed=full.armed.iloc[0:0], armed_source=None)
    periods, label = _shaded_periods(log)
    t = log.position["t_s"].to_numpy(float)
    assert periods == flown_periods(log) == [(t.min(), t.max())] and "armed state unknown" in label
    assert _shaded_periods(full) == (full.armed_periods, "armed") and len(full.armed_periods) >= 1


def test_calibrate_takes_the_replays_flown_rule_for_a_log_with_unknown_armed_state():
    """`calibrate` read ``log.armed_periods``: a log whose armed state is unknown (log171 with its armed-state records
    taken out) had no armed sample, so 0 airborne samples ("only 0 battery samples while airborne") and every sample
    "disarmed" (avionics). It takes the replay's rule now (:func:`~mission_sim.mavlink.takeoff.flown_periods`): the
    whole track is armed, with one warning, no sample is known disarmed, the airborne samples hold every airborne
    sample of the log with its armed state (1507; 1536 with the 27 s before arming), and the fitted equivalent mass
    is within 2 % of that log's (1.80 kg both)."""
    import dataclasses

    from mission_sim.config import load_config
    from mission_sim.mavlink.calibrate import calibrate_log, calibration_samples
    from mission_sim.mavlink.logs import read_log
    from wpt_receiver.notices import DronewptWarning
    full = read_log(FLIGHTLOGS / "dronekit-la-testdata_log171.bin")
    log = dataclasses.replace(full, armed=full.armed.iloc[0:0], armed_source=None)
    known = calibration_samples(full).table
    with pytest.warns(DronewptWarning, match="the armed state is unknown .*whole GPS track") as rec:
        tab = calibration_samples(log).table
    assert len(rec) == 1
    assert not tab["disarmed"].any() and known["disarmed"].sum() > 100
    assert set(known["t_s"][known["airborne"]]) <= set(tab["t_s"][tab["airborne"]])
    assert known["airborne"].sum() <= tab["airborne"].sum() <= known["airborne"].sum() * 1.05
    drone = load_config().drone
    with pytest.warns(DronewptWarning):
        mass = calibrate_log(log, drone).drone.mass_kg
    assert mass == pytest.approx(calibrate_log(full, drone).drone.mass_kg, rel=0.02)


@pytest.mark.parametrize("name", GROUND_LOGS)
def test_calibrate_refuses_a_ground_log_with_unknown_armed_state_as_replay_does(capsys, tmp_path, name):
    """Such a log on the ground: `replay` refuses it ("no flown track: the armed state is unknown ... never rises 1 m
    above its first position"), `calibrate` said "only 0 battery samples while airborne ... calibrate needs the
    flight battery's voltage and current", as if the battery data were missing. Now the replay's line, exit 2,
    nothing written."""
    from mission_sim.cli import main
    assert main(["replay", str(FLIGHTLOGS / name), "--no-plot", "--no-progress", "--out", str(tmp_path / "r")]) == 2
    said = capsys.readouterr().err.strip().split("error: ", 1)[1]
    assert main(["calibrate", str(FLIGHTLOGS / name), "--no-plot", "--out", str(tmp_path / "c" / "d.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.split("error: ", 1)[1] == said, (err, said)
    assert "never rises 1 m above its first position" in said and list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------ one ground height
def test_one_ground_height_for_replay_calibrate_refly_and_the_flown_route(monkeypatch):
    """"Below this height above the take-off spot is the ground" was four 1.0 m constants (plans.items
    FLOWN_GROUND_M, mavlink.takeoff UNKNOWN_GROUND_M, mavlink.replay AIRBORNE_M, plans.refly AIRBORNE_M "as the
    replay's"): one now, :data:`mission_sim.mavlink.ground.GROUND_M`; set to another value, every user follows it
    (the refusals, the flown route's landings, replay's and calibrate's airborne samples, refly's detours)."""
    import math

    import numpy as np

    from mission_sim.mavlink import ground
    from mission_sim.mavlink.calibrate import calibration_samples
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import compare_power, track_from_log, unknown_armed_check
    from mission_sim.plans.items import read_mission
    from mission_sim.plans.refly import plan_detours
    from wpt_receiver.notices import DronewptWarning
    ground_log = FLIGHTLOGS / "pymavlink_test.BIN"   # on the ground, armed state unknown: its track rises 0.05 m
    log = read_log(ground_log)
    for check in (lambda: unknown_armed_check(log, track_from_log(log)), lambda: read_mission(ground_log, "flown")):
        with pytest.raises(ValueError, match="never rises 1 m above its first position"):
            check()
    flight = read_log(FLIGHTLOGS / "dronekit-la-testdata_log171.bin")   # armed, up to 11.7 m
    air = calibration_samples(flight).table
    track = track_from_log(flight)
    assert len(plan_detours(track, np.zeros((1, 3)), [1.0])[0]) == 1
    compared = compare_power(flight, track, track.t_s, np.zeros(len(track.t_s)))[1]["n_samples_airborne"]

    monkeypatch.setattr(ground, "GROUND_M", 0.01)   # below the ground log's 0.05 m: replay and the route fly it
    assert "the armed state is unknown" in unknown_armed_check(log, track_from_log(log))
    with pytest.warns(DronewptWarning, match="the armed state is unknown"):
        items = read_mission(ground_log, "flown").items
    # the route's own take-off / landing split follows too (plans.items.flown_mission): its 0.05 m rise is a
    # flight with a waypoint (MAV_CMD_NAV_WAYPOINT 16) before the landing (21), not one landing
    assert {i.command for i in items} == {16, 21} and items[-1].command == 21
    monkeypatch.setattr(ground, "GROUND_M", 0.5)    # (the refusal names the one value)
    with pytest.raises(ValueError, match=r"never rises 0.5 m above its first position \(max 0.05"):
        read_mission(ground_log, "flown")
    monkeypatch.setattr(ground, "GROUND_M", 6.0)    # above most of log171's flight: fewer airborne samples
    high = calibration_samples(flight).table
    assert 0 < high["airborne"].sum() < air["airborne"].sum() and high["height_m"][high["airborne"]].min() > 6.0
    table, summary = compare_power(flight, track, track.t_s, np.zeros(len(track.t_s)))   # replay's airborne samples
    assert 0 < summary["n_samples_airborne"] < compared and table["height_m"][table["airborne"]].min() > 6.0
    monkeypatch.setattr(ground, "GROUND_M", 20.0)   # above its whole flight: no sample to leave for a pad from
    assert plan_detours(track, np.zeros((1, 3)), [1.0]) == ([], [(0, math.inf)])


# ------------------------------------------------------------------------------------ the policies' VL
def test_the_policies_link_carries_the_mission_packs_voltage():
    """``policy_context(cfg).link.vl_v`` was Table I's 30 V whatever the pack (the default 8S pack runs at
    32.28-32.90 V): it is the charger's CV voltage ``n_series * cv_cell_v`` (the setup warnings' link, one source),
    inside the voltage the pack has in the mission; a 4S pack's is 16.4 V."""
    from mission_sim.config import apply_overrides, config_from_dict, load_config, load_config_dict, policy_context
    from mission_sim.setup_warnings import mission_link_params
    from mission_sim.world.runner import run_mission
    import policies
    cfg = load_config()
    ctx = policy_context(cfg)
    assert ctx.link == mission_link_params(cfg)
    assert ctx.link.vl_v == pytest.approx(cfg.battery.n_series * cfg.charger.cv_cell_v)
    v = run_mission(cfg, policies.make("step", ctx), warn=False).timeseries["battery_v"].to_numpy()
    assert v.min() <= ctx.link.vl_v <= v.max() and v.min() > 32.0   # (32.28-32.90 V; 30 V was below all of it)
    four = config_from_dict(apply_overrides(load_config_dict(None), {"battery.n_series": 4}))
    assert policy_context(four).link.vl_v == pytest.approx(4 * four.charger.cv_cell_v)


def test_mpc_with_a_budget_stays_under_its_rating_in_the_default_mission():
    """The modal MPC builds its clamp table at the context's VL (``policies.mpc_modal.v2_frame_table``); at 30 V,
    below the pack, ``mpc:0.02`` peaked at 32.5 A in the default mission (rated 15 A; at 29 V 32.3 A); with the
    pack's voltage in its context it peaks at 13.31 A, as ``mpc`` and ``model_based`` do."""
    pytest.importorskip("daqp")
    from mission_sim.config import load_config, policy_context
    from mission_sim.world.runner import run_mission
    import policies
    cfg = load_config()
    s = run_mission(cfg, policies.make("mpc:0.02", policy_context(cfg)), warn=False, frame=False).summary
    ref = run_mission(cfg, policies.make("model_based", policy_context(cfg)), warn=False, frame=False).summary
    assert s["peak_i2_a"] < cfg.link.rated_i2_a
    assert s["peak_i2_a"] == pytest.approx(ref["peak_i2_a"], rel=0.01)


def test_the_modal_mpc_shares_one_sbar_table_across_pack_voltages(monkeypatch):
    """The modal MPC's SBAR table (1.1 MB, seconds to build on a disk-cache miss) was built from the whole link,
    its VL included, so each pack voltage cost a table of its own: it is now the table at LinkParams' default VL,
    the one the mission loop uses, shared by links that differ only in VL (no table is built or read for a second
    voltage); the clamp stays at each link's own ``VL + Vf``."""
    import dataclasses

    from wpt_receiver import modal_kernel as mk
    from wpt_receiver.devices import preset
    from wpt_receiver.params import LinkParams
    from policies import mpc_modal
    base = LinkParams()
    a, b = (dataclasses.replace(base, vl_v=v) for v in (31.3, 33.1))
    for cached in (mpc_modal._link_modes, mpc_modal._sbar_table):   # as in a fresh process
        cached.cache_clear()
    built = []
    real = mk.modal_table
    monkeypatch.setattr(mk, "modal_table", lambda link, dev: built.append(link.vl_v) or real(link, dev))
    tab_a, tab_b = mpc_modal._link_modes(a, "schottky")[1], mpc_modal._link_modes(b, "schottky")[1]
    assert tab_a is tab_b and built == [LinkParams().vl_v]
    assert (tab_a == real(dataclasses.replace(base, vl_v=LinkParams().vl_v), preset("schottky"))).all()
    vf = preset("schottky").rect_vf_v
    assert mpc_modal.v2_frame_table(a, "schottky")[2] == pytest.approx(31.3 + vf)
    assert mpc_modal.v2_frame_table(b, "schottky")[2] == pytest.approx(33.1 + vf)


def test_the_envs_peak_table_is_shared_across_pack_voltages():
    """``envs.peaks.peak_table`` tabulates the ripple excess at its own VL grid (27, 31, 35 V) whatever the link's
    VL, yet was keyed on the whole link: each pack voltage in a policy context cost the MPC a second table (4.7 s
    of its 5 s ``make``). Links that differ only in VL now get one table, equal to the one at the default VL."""
    import dataclasses

    from envs import peaks
    from wpt_receiver.devices import preset
    from wpt_receiver.params import LinkParams
    dev = preset("schottky")
    a, b = (dataclasses.replace(LinkParams(), vl_v=v) for v in (31.3, 33.1))
    assert peaks.peak_table(a, dev) is peaks.peak_table(b, dev) is peaks.peak_table(LinkParams(), dev)
    assert peaks.PeakLookup(a, dev).table is peaks.PeakLookup(b, dev).table
