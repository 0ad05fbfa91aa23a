"""Loose ends left by earlier sessions (2026-11-27 afternoon; docs/robustness.md, "Loose ends (2026-11-27
afternoon)"): each test fails on the tree before its fix (``main`` 875a414), but the guards of valid inputs
(``..._still_run``, ``..._still_flies_its_route``, the physics of the frequency tolerance), which pass on both."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest

from mission_sim.cli import main
from _cli_helpers import one_error_line as _one_error_line   # exit 2, one line on stderr, no traceback

_LOG = str(Path(__file__).resolve().parent / "data" / "flightlogs" / "dronekit-python_flight.tlog")
_FAR = ("pads.0.z_m={z} is outside +-120 m of {origin} (the pad is {d} m below it: a drone charging there flies up "
        "or down to it); valid: a pad's height within +-120 m of it (a pads file's alt in metres above mean sea level, "
        "not above the ground, not feet; [[pads]] z_m and --set pads.<i>.z_m in metres above it)")


def _ours(caught) -> list[str]:
    from wpt_receiver.notices import DronewptWarning
    return [str(w.message) for w in caught if issubclass(w.category, DronewptWarning)]


# ------------------------------------------------------------------ 1. the far pad among the setup warnings
def test_a_sweep_counts_the_far_pad_among_its_setup_warnings(tmp_path):
    """A study whose cases put the pad 200 m / 130 m below home: the cases run with ``warn=False`` (warned once per
    study), and the study's lines had no word of it (only the link and unreached-pad kinds were counted)."""
    import policies
    from mission_sim.studies.prepare import prepare_study
    from mission_sim.studies.study import load_study
    (tmp_path / "s.toml").write_text('[study]\nname = "low"\n[grid]\n"pads.0.z_m" = [-200.0, 0.0, -130.0]\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prepare_study(load_study(tmp_path / "s.toml"), policies.make, policies.available())
    assert _ours(caught) == ["2 of 3 cases of study 'low' have a pad more than 120 m above or below its frame's "
                             "origin, e.g.: " + _FAR.format(z=-200, origin="the mission's home", d=200)]


def test_a_refly_summary_lists_the_far_pad(capsys, tmp_path):
    """``replay --pads`` with the pad 150 m below the ``--pad`` origin: warned during the run, but the summary's
    ``warnings`` (``refly_summary.json``, ``--format json``; a ``[replay]`` study's ``n_warnings``) had no word."""
    (tmp_path / "low.csv").write_text("lat,lon,alt,hover_time_s\n-35.3620800,149.1658531,0,10\n")
    argv = ["replay", _LOG, "--pads", str(tmp_path / "low.csv"), "--pad=-35.36208,149.1658531,150", "--window",
            "440,620", "--no-plot", "--format", "json", "--no-progress", "--out", str(tmp_path / "o"),
            "--set", "battery.n_series=3"]
    assert main(argv) == 0
    cap = capsys.readouterr()
    line = _FAR.format(z=-150, origin="the replay's pad frame origin", d=150)
    assert json.loads(cap.out)["warnings"].count(line) == 1
    assert json.loads((tmp_path / "o" / "refly_summary.json").read_text())["warnings"].count(line) == 1
    assert cap.err.splitlines().count(f"dronewpt replay: warning: {line}") == 1   # still once on stderr


def test_a_plain_replay_summary_lists_the_far_pad_once(capsys, tmp_path):
    """Plain ``replay`` (no ``--pads``: one pad at the origin) with ``--set pads.0.z_m=-200``: ``replay_log(..., cfg)``
    lists the far pad in the summary's ``warnings`` (``--format json``, ``replay_summary.json``), once, as stderr."""
    argv = ["replay", _LOG, "--window", "440,620", "--set", "pads.0.z_m=-200", "--set", "battery.n_series=3",
            "--no-plot", "--format", "json", "--no-progress", "--out", str(tmp_path / "o")]
    assert main(argv) == 0
    cap = capsys.readouterr()
    line = _FAR.format(z=-200, origin="the replay's pad frame origin", d=200)
    assert json.loads(cap.out)["warnings"].count(line) == 1
    assert json.loads((tmp_path / "o" / "replay_summary.json").read_text())["warnings"].count(line) == 1
    assert cap.err.splitlines().count(f"dronewpt replay: warning: {line}") == 1


def test_a_replay_study_names_the_replays_pad_frame_origin(tmp_path):
    """A ``[replay]`` study's far pad is about the replay's pad frame origin (``ReplayCaseRunner._pad_origin``,
    ``REPLAY_ORIGIN``), not the mission's home: one study line, counting the one case of two."""
    import policies
    from mission_sim.studies.prepare import prepare_study
    from mission_sim.studies.study import load_study
    (tmp_path / "s.toml").write_text(f'[study]\nname = "rlow"\n[replay]\nlog = {_LOG!r}\nwindow = [440.0, 620.0]\n'
                                     '[grid]\n"pads.0.z_m" = [-200.0, 0.0]\n"battery.n_series" = [3]\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prepare_study(load_study(tmp_path / "s.toml"), policies.make, policies.available())
    assert _ours(caught) == ["1 of 2 cases of study 'rlow' have a pad more than 120 m above or below its frame's "
                             "origin, e.g.: " + _FAR.format(z=-200, origin="the replay's pad frame origin", d=200)]


# ------------------------------------------------------------------ 2. file keys no file read uses
_PLAN = str(Path(__file__).resolve().parent / "data" / "missions" / "qgc_simple_square.plan")
_NO_FILE = "there is no mission file (--plan or mission.file)"


@pytest.mark.parametrize("argv, text", [
    (["mission", "--dry-run", "--set", 'mission.from_log="flown"'],
     f"--set mission.from_log='flown' is invalid: it chooses what a flight log read as the mission file gives (its "
     f"uploaded mission or its flown track), and {_NO_FILE}; valid: a flight log (.tlog, .bin, .log, .ulg) as --plan "
     "or mission.file, or leave the key out"),
    (["mission", "--dry-run", "--plan", _PLAN, "--set", 'mission.from_log="uploaded"'],
     "--set mission.from_log='uploaded' is invalid: it chooses what a flight log read as the mission file gives (its "
     "uploaded mission or its flown track), and the mission file 'qgc_simple_square.plan' is not a log; valid: "),
    (["mission", "--dry-run", "--set", "mission.pad_radius_m=50"],
     f"--set mission.pad_radius_m=50 is invalid: it chooses which loiters of a mission file charge at a pad, and "
     f"{_NO_FILE}; valid: a mission file, or leave the key out (a config's [[waypoints]] charge with action = "
     '"charge")'),
    (["telemetry", "--set", "mission.pad_radius_m=50", "--duration", "1"], "--set mission.pad_radius_m=50 is invalid"),
])
def test_a_file_key_no_file_read_uses_is_refused(capsys, argv, text):
    """Before: exit 0, the value changed nothing (a .plan is read whatever from_log says; pad_radius_m picks which
    loiters of a mission file charge, and there was none)."""
    line = _one_error_line(capsys, argv)
    assert line.startswith(f"dronewpt {argv[0]}: error: {text}"), line


def test_the_file_keys_with_a_log_as_mission_file_still_run(capsys):
    """The keys where they are read: a log as ``--plan`` (``from_log``, ``pad_radius_m``) and a .plan
    (``pad_radius_m``): exit 0."""
    log = _LOG
    assert main(["mission", "--dry-run", "--plan", log, "--set", 'mission.from_log="flown"',
                 "--set", "mission.pad_radius_m=20"]) == 0
    assert main(["mission", "--dry-run", "--plan", _PLAN, "--set", "mission.pad_radius_m=20"]) == 0
    capsys.readouterr()


# ------------------------------------------------------------------ 3. a route's pattern keys in a config file
_ROUTE = '[[waypoints]]\naction = "loiter"\nx_m = 10.0\nz_m = 20.0\nhold_s = 5.0\n'
_UNUSED = ("is invalid: the mission flies a route (--plan, mission.file or [[waypoints]]), which never reads it (the "
           "built-in pattern's, as are ")


@pytest.mark.parametrize("body, plan, key", [
    ("[mission]\ncruise_altitude_m = 60.0\n" + _ROUTE, False, "mission.cruise_altitude_m=60.0"),
    ("[mission]\nland_y_m = 3.0\n" + _ROUTE, False, "mission.land_y_m=3.0"),
    ("[mission]\nhover_time_s = 30.0\n", True, "mission.hover_time_s=30.0"),   # the route is --plan's
])
def test_a_config_files_pattern_key_under_a_route_is_refused_as_sets(capsys, tmp_path, body, plan, key):
    """Before: exit 0, the route flown, the file's value ignored (``--set`` of the same key was refused)."""
    (tmp_path / "r.toml").write_text(body)
    argv = ["mission", str(tmp_path / "r.toml"), "--dry-run"] + (["--plan", _PLAN] if plan else [])
    line = _one_error_line(capsys, argv)
    assert line.startswith(f"dronewpt mission: error: config file {str(tmp_path / 'r.toml')!r}: {key} {_UNUSED}"), line


def test_a_config_file_without_its_pattern_keys_still_flies_its_route(capsys, tmp_path):
    """Only the keys the user's file sets are refused (the default laid under it has every key): a route file with other
    [mission] keys, and a pattern key without a route, run."""
    (tmp_path / "r.toml").write_text("[mission]\ncruise_speed_m_s = 6.0\n" + _ROUTE)
    (tmp_path / "alt.toml").write_text("[mission]\ncruise_altitude_m = 60.0\n")
    assert main(["mission", str(tmp_path / "r.toml"), "--dry-run"]) == 0
    assert main(["mission", str(tmp_path / "alt.toml"), "--dry-run"]) == 0
    capsys.readouterr()


def test_a_mission_studys_base_with_a_pattern_key_under_its_route_is_refused(tmp_path):
    """The mission studies fly their base's route: its own ``[mission] cruise_altitude_m`` beside ``[[waypoints]]`` is
    refused there too (``prepare``'s :func:`~mission_sim.config.check_file_route_keys`)."""
    import policies
    from mission_sim.studies.prepare import prepare_study
    from mission_sim.studies.study import load_study
    (tmp_path / "r.toml").write_text("[mission]\ncruise_altitude_m = 60.0\n" + _ROUTE)
    (tmp_path / "s.toml").write_text('[study]\nname = "s"\nbase = "r.toml"\n[grid]\n"drone.mass_kg" = [1.0, 1.2]\n')
    with pytest.raises(ValueError) as exc:
        prepare_study(load_study(tmp_path / "s.toml"), policies.make, policies.available())
    assert str(exc.value).startswith(f"config file {str(tmp_path / 'r.toml')!r}: mission.cruise_altitude_m=60.0 "
                                     f"{_UNUSED}"), str(exc.value)


def test_replay_reads_a_route_configs_hover_time_and_flies_the_log(capsys, tmp_path):
    """The file-key check ran inside ``load_config_dict``, for every caller: ``replay --pads`` refused a route config's
    ``mission.hover_time_s`` (exit 2, "the mission flies a route"), the default hover of its pads without their own,
    and plain ``replay`` its ``cruise_altitude_m`` (the log's track is flown, never the route). Both run (as ``main``),
    the detours hovering the file's 30 s."""
    (tmp_path / "pads.csv").write_text("lat,lon\n-35.3620800,149.1658531\n-35.3622242,149.1656661\n")
    (tmp_path / "hover.toml").write_text("[mission]\nhover_time_s = 30.0\n" + _ROUTE)
    (tmp_path / "alt.toml").write_text("[mission]\ncruise_altitude_m = 60.0\n" + _ROUTE)
    common = ["--window", "440,620", "--no-plot", "--format", "json", "--no-progress", "--set", "battery.n_series=3"]
    assert main(["replay", _LOG, "--pads", str(tmp_path / "pads.csv"), "--config", str(tmp_path / "hover.toml"),
                 "--out", str(tmp_path / "o")] + common) == 0
    detours = json.loads(capsys.readouterr().out)["detours"]
    assert [(d["pad"], d["hover_s"]) for d in detours] == [(1, 30.0), (0, 30.0)]
    assert main(["replay", _LOG, "--config", str(tmp_path / "alt.toml"), "--out", str(tmp_path / "p")] + common) == 0
    capsys.readouterr()


# ------------------------------------------------------------------ 4. a re-flight makes the logged track once
def test_a_refly_makes_the_logged_track_once(capsys, tmp_path, monkeypatch):
    """``replay LOG --pads`` cut the log to its window and made the logged track three times (the origin, the plan
    checked for its errors, the plan again in ``refly_log``): three window checks. Now once, the same outputs."""
    import mission_sim.mavlink.replay as rp
    calls = {"track_from_log": 0, "check_window": 0}
    for name in calls:
        def counted(*a, _f=getattr(rp, name), _n=name, **k):
            calls[_n] += 1
            return _f(*a, **k)
        monkeypatch.setattr(rp, name, counted)
    pads = Path(__file__).resolve().parent / "data" / "missions" / "dronekit_flight_pads.csv"
    argv = ["replay", _LOG, "--pads", str(pads), "--window", "440,620", "--out", str(tmp_path / "o"), "--format",
            "json", "--no-progress", "--no-plot", "--set", "battery.n_series=3", "--ground-gap", "0.3"]
    assert main(argv) == 0
    assert calls == {"track_from_log": 1, "check_window": 1}
    assert len(json.loads(capsys.readouterr().out)["detours"]) == 2


def test_plan_refly_on_a_given_track_is_the_plan_made_from_the_log():
    """``plan_refly(..., track=T)`` (T made at another ground gap) gives the plan it makes from the log, bit for bit."""
    import numpy as np

    from mission_sim.config import config_from_dict, config_to_dict, load_config
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import track_from_log
    from mission_sim.plans.pads import read_pads
    from mission_sim.plans.refly import plan_refly, refly_base
    log = read_log(_LOG)
    track = track_from_log(log, window=(440.0, 620.0))
    pads = read_pads(Path(__file__).resolve().parent / "data" / "missions" / "dronekit_flight_pads.csv")
    cfg = config_from_dict(refly_base(config_to_dict(load_config()), pads, track.pad))
    kw = dict(pad=track.pad, window=(440.0, 620.0), ground_gap_m=0.3)
    made, given = plan_refly(log, cfg, **kw), plan_refly(log, cfg, track=track, **kw)
    for a, b in zip((made[0].t_s, made[0].pos_m, made[0].tilt_rad, made[0].armed, made[1]),
                    (given[0].t_s, given[0].pos_m, given[0].tilt_rad, given[0].armed, given[1])):
        assert a.tobytes() == b.tobytes()
    assert made[0].ground_gap_m == given[0].ground_gap_m == 0.3 and made[2:] == given[2:]
    other = track_from_log(log, window=(440.0, 620.0), ground_gap_m=0.3)
    assert not np.array_equal(track.pos_m[:, 2], other.pos_m[:, 2])   # (the given track was at another gap)


# ------------------------------------------------------------------ 5. a drive frequency far off the coils' resonance
_FREQ = ("{key}=1.356e+07 Hz is 159.5x the tanks' resonance 85000 Hz (1/(2 pi sqrt(L C)) of the coil pair, L1 236 uH "
         "with C1 14.86 nF, L2 18.9 uH with C2 185.5 nF): the model tunes C1, C2 to {key} and runs, but a resonant "
         "series-series link's secondary current V1/(2 pi f Lm) scales as 1/f, 0.00627x its value at 85000 Hz (outside "
         "the factor 2 where it halves or doubles); valid: {key} in [42500, 170000] Hz, or coils made for it")


def test_a_link_far_off_its_tanks_resonance_warns_once(capsys, tmp_path):
    """``netlist --link f_hz=13.56e6`` (and a mission at ``link.f_hz=13.56e6``: peak I2 0.084 A, almost nothing charged) ran
    without a word. One line naming f_hz, the tanks' resonance from L and C and the ratio."""
    assert main(["netlist", "--link", "f_hz=13.56e6", "--out", str(tmp_path / "n.cir")]) == 0
    assert capsys.readouterr().err.splitlines() == ["dronewpt netlist: warning: " + _FREQ.format(key="--link f_hz")]
    from mission_sim.config import config_from_dict, load_config_dict
    from mission_sim.setup_warnings import mission_warnings
    cfg = config_from_dict({**load_config_dict(), "link": {**load_config_dict()["link"], "f_hz": 13.56e6}})
    assert mission_warnings(cfg).count(_FREQ.format(key="link.f_hz")) == 1


@pytest.mark.parametrize("f_hz, warns", [(85e3, False), (42.5e3, False), (170e3, False), (171e3, True), (40e3, True),
                                         (1e4, True), (3e7, True)])
def test_the_frequency_tolerance_is_a_factor_2_either_way(f_hz, warns):
    from wpt_receiver import TABLE_I
    from wpt_receiver.params import resonance_warning
    assert (resonance_warning(TABLE_I.with_(f_hz=f_hz)) is not None) is warns
    assert resonance_warning(TABLE_I.with_(f_hz=13.56e6, l1_h=0.5e-6, l2_h=0.4e-6, lm_h=0.1e-6)) is None   # own coils


@pytest.mark.parametrize("f_hz, warns", [(170e3, False), (42.5e3, False), (171e3, True), (42e3, True)])
def test_a_missions_link_warns_outside_the_stated_range_only(f_hz, warns):
    """The mission's L1 from the coupling model is 0.00023600000000000102 H, not Table I's 236 uH to the bit: the
    resonance from it and Table I's C1 was 84999.99999999981 Hz, so ``link.f_hz = 170000`` (2.0000000000000044x)
    warned though the line says [42500, 170000] Hz is valid. Table I's coils resonate at Table I's f_hz."""
    from mission_sim.config import config_from_dict, load_config_dict
    from mission_sim.setup_warnings import mission_warnings
    from wpt_receiver.params import FREQUENCY_TOLERANCE
    d = load_config_dict()
    cfg = config_from_dict({**d, "link": {**d["link"], "f_hz": f_hz}})
    freq = [w for w in mission_warnings(cfg) if w.startswith(f"link.f_hz={f_hz:.6g} Hz is ")]
    assert len(freq) == warns, freq
    assert not warns or f"valid: link.f_hz in [{85e3 / FREQUENCY_TOLERANCE:.6g}, {85e3 * FREQUENCY_TOLERANCE:.6g}] Hz" \
        in freq[0]


def test_the_tolerance_is_where_the_resonant_links_current_halves():
    """The physics of the factor 2: the models tune C to f_hz; the rectification-mode I2 of the resonant link
    (``rm_state.rm_steady``, devices ideal) at twice 85 kHz is half its value at 85 kHz (0.508), at 13.56 MHz 1/154."""
    from wpt_receiver import TABLE_I
    from wpt_receiver.rm_state import rm_steady
    i2 = {f: float(rm_steady(TABLE_I.with_(f_hz=f), None, None)["i2_a"]) for f in (85e3, 170e3, 13.56e6)}
    assert 0.45 < i2[170e3] / i2[85e3] < 0.55 and i2[13.56e6] < 0.01 * i2[85e3]


def test_a_sweep_counts_the_link_frequency_warning(tmp_path):
    import policies
    from mission_sim.studies.prepare import prepare_study
    from mission_sim.studies.study import load_study
    (tmp_path / "s.toml").write_text('[study]\nname = "f"\n[grid]\n"link.f_hz" = [85000.0, 13.56e6]\n')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        prepare_study(load_study(tmp_path / "s.toml"), policies.make, policies.available())
    assert _ours(caught) == ["1 of 2 cases of study 'f' have a link.f_hz more than a factor 2 off the coil pair's "
                             "tanks' resonance, e.g.: " + _FREQ.format(key="link.f_hz")]


# ------------------------------------------------------------------ 6. the switching model's "stuck" error
def test_the_stuck_error_names_the_interval_it_is_stuck_in(monkeypatch):
    """A schedule with repeated times (interval 1 is [T, T]): stuck there (an event at every zero-length step, the
    kernel's ``_first_event`` swapped, ``compiled=False`` running the same source), the error named interval 2 (cmd=1,
    gate=1: the last interval starting at T, ``searchsorted``); now the kernel's own interval (cmd=-1, gate=0)."""
    import numpy as np

    import wpt_receiver.switching.compiled as ck
    import wpt_receiver.switching.link as lk
    from wpt_receiver import TABLE_I
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    from wpt_receiver.switching.schedule import Schedule
    monkeypatch.setattr(lk, "_MAX_ZERO_EVENTS", 0)
    monkeypatch.setattr(ck, "_first_event", lambda z, z_end, rows, ng, gk, lam, h, tau, tol:
                        (0.0, 0) if tau == 0.0 else (0.0, -1))   # an event only where an interval has no length
    link = SwitchingLink(TABLE_I, SwitchingConfig(), compiled=False)
    T = 0.5 / TABLE_I.f_hz
    sch = Schedule(t=np.array([0.0, T, T, 4 * T]), cmd=np.array([1, -1, 1]), gate=np.array([0, 0, 1]))
    with pytest.raises(ArithmeticError) as exc:
        link.run(sch, np.r_[np.zeros(link.cir.n), 1.0])
    assert f"at t={T!r} s in topology (-1, 2) (cmd=-1, gate=0); state " in str(exc.value), str(exc.value)


# ------------------------------------------------------------------ 7. the solve_ivp reference without numba
def test_the_solve_ivp_reference_imports_no_numba():
    """A fresh process that imports ``wpt_receiver.switching.ivp`` and calls ``simulate_ivp`` imported numba for the
    kernel's mode rules (0.85-1.27 s against 0.51-0.56 s for the call, docs/performance.md); the rules are now the
    numba-free ``mode_rules``, which the kernel compiles in (one copy)."""
    import subprocess
    import sys
    code = ("import sys, numpy as np\n"
            "from wpt_receiver import TABLE_I\n"
            "from wpt_receiver.switching import SwitchingConfig\n"
            "from wpt_receiver.switching.ivp import simulate_ivp\n"
            "from wpt_receiver.switching.schedule import Schedule\n"
            "T = 0.5 / TABLE_I.f_hz\n"
            "t, x = simulate_ivp(TABLE_I, SwitchingConfig(), Schedule(np.array([0.0, T]), np.array([1]), "
            "np.array([1])), np.zeros(4))\n"
            "print(len(t) > 1, 'numba' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "False"], out
    import wpt_receiver.switching.compiled as ck
    import wpt_receiver.switching.mode_rules as rules
    assert ck._modes is rules._modes and ck._after_event is rules._after_event   # one copy of the rules


def test_the_kernels_numba_cache_depends_on_the_mode_rules_and_the_circuit():
    """numba keys ``compiled.py``'s cache on that file alone, while its loop compiles in ``mode_rules.py``'s rules and
    ``circuit.py``'s constants: its ``drop_stale_cache`` must name both (removing it, or either file, failed no test).
    A fresh process records the dependencies each module declares at its import (``kernel_cache.drop_stale_cache``
    swapped for a recorder before ``compiled`` is imported)."""
    from _cache_deps import declared_cache_deps
    seen = declared_cache_deps("wpt_receiver.switching.compiled")
    assert sorted(seen["compiled.py"]) == ["circuit.py", "mode_rules.py"], seen
