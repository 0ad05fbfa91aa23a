"""Parameter studies over one's own flight logs: `dronewpt sweep` on a study with a `[replay]` section.

A case equals `dronewpt replay LOG [--pads FILE] --set KEY=VALUE ...` (every summary number, to the bit),
bad keys / values / files are refused before anything runs (one line, exit 2), the log is parsed once
per process (not per case), and an interrupted sweep resumes with only the missing cases."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import pandas as pd
import pytest

from mission_sim.cli import main
from mission_sim.studies import replay_cases
from mission_sim.studies.sweep import read_results
from wpt_receiver.notices import DronewptWarning

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
LOG = DATA / "flightlogs" / "dronekit-python_flight.tlog"
LOG171 = DATA / "flightlogs" / "dronekit-la-testdata_log171.bin"
PADS = DATA / "missions" / "dronekit_flight_pads.csv"
BOOKKEEPING = {"case_id", "status", "error", "traceback", "case_wall_s", "case_cpu_s", "worker", "attempt",
               "params_json"}


#: the cell count of each log's pack (median logged voltage 11.1 V: the dronekit quad's 3S; 15.5 V: log171's 4S)
CELLS = {LOG: 3, LOG171: 4}


def _fitting_pack(tmp_path, log, extra: str = "") -> tuple[str, list[str]]:
    """A base mission whose pack fits ``log``'s (``cfg.toml``: ``battery.n_series`` = :data:`CELLS`, plus ``extra``
    TOML), as the study's head and the replay command's options. Tests that are not about the logged-voltage warning
    use it: the default 8S model pack on these logs warns once per study and once per command (a ``DronewptWarning``,
    an error under ``-W error``), which is not what they test."""
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(f"[battery]\nn_series = {CELLS[log]}\n{extra}")
    return '[study]\nbase = "cfg.toml"\n', ["--config", str(cfg)]


@pytest.fixture
def warnings_shown():
    """For a test that checks the command line's warning lines (a log that warns whatever the pack: log171 ends while
    armed): Python's default filter for ``DronewptWarning``, each printed once as ``dronewpt COMMAND: warning: ...``,
    whatever ``-W`` the test run was given (under ``-W error`` the command exits 2 on the first one, as it should)."""
    with warnings.catch_warnings():
        warnings.simplefilter("default", DronewptWarning)
        yield


ENDS_ARMED = "the log ends while the vehicle is armed"
EIGHT_CELLS_ON_3S = ("dronekit-python_flight.tlog: the logged battery voltage (median 11.1 V) is outside the model "
                     "pack's open-circuit range 21.2-32.8 V (battery.n_series=8")


def _warned(err: str, command: str) -> list[str]:
    """The command's warning lines (``dronewpt COMMAND: warning: ...``), their text."""
    head = f"dronewpt {command}: warning: "
    return [ln[len(head):] for ln in err.splitlines() if ln.startswith(head)]


def _study(tmp_path, replay: str, grid: str, name="s.toml", head: str = "") -> Path:
    p = tmp_path / name
    p.write_text(f"{head}[replay]\n{replay}\n[grid]\n{grid}\n")
    return p


def _swept_log171(tmp_path, capsys, replay: str, grid: str, pack_extra: str = ""):
    """A study over log171 (``[replay]`` lines ``replay``, ``[grid]`` lines ``grid``) with the 4S quad's own cell count
    (``pack_extra``: more ``[battery]`` lines), swept into ``tmp_path / "o"``; it warns once, that the log ends in
    flight. Its results, the replay command's ``--config`` arguments of the same pack and the study's warning lines."""
    head, config = _fitting_pack(tmp_path, LOG171, pack_extra)
    study = _study(tmp_path, replay, grid, head=head)
    assert _sweep(study, tmp_path / "o") == 0
    said = _warned(capsys.readouterr().err, "sweep")
    assert len(said) == 1 and ENDS_ARMED in said[0], said
    return read_results(tmp_path / "o"), config, said


def _sweep(study, out, *extra) -> int:
    return main(["sweep", str(study), "--out", str(out), "--workers", "0", "--no-plot", "--no-progress",
                 "--format", "json", *extra])


def _flat(d: dict) -> dict:
    """The replay command's JSON as the sweep's columns (the sweep's own flattening: nested tables dotted, lists
    counted)."""
    from mission_sim.studies.replay_cases import _flat as flat
    return flat(d)


def _assert_row_equals_command(row: pd.Series, cmd: dict, min_numbers: int) -> None:
    """Every number and flag of the command's summary is the row's, bit for bit (JSON null = nan)."""
    compared = 0
    for k, want in _flat(cmd).items():
        if k in ("files", "n_files", "log", "policy", "pads_file") or isinstance(want, str):
            continue
        assert k in row.index, k
        got = row[k]
        if want is None:
            assert got is None or (isinstance(got, float) and math.isnan(got)), (k, got)
        elif isinstance(want, bool):
            assert bool(got) is want, (k, got, want)
        else:
            assert float(got) == float(want), (k, got, want)   # exact: the same runs, summary-only
        compared += 1
    assert compared >= min_numbers, compared


def test_a_refly_case_equals_the_replay_command_with_pads_drone_and_set(tmp_path, capsys, warnings_shown):
    """The 8S model drone re-flies the 3S quad's route (its charging is what the physics below checks: on its 8S
    link a 3S pack gains less from a longer hover than it spends hovering): both the study and the command say so."""
    drone = tmp_path / "drone.toml"
    drone.write_text("[drone]\nmass_kg = 1.2\nfigure_of_merit = 0.62\n")
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\nwindow = [440.0, 620.0]\ndrone = "drone.toml"',
                   '"pads.0.hover_time_s" = [30.0, 75.0]\n"battery.capacity_ah" = 1.6')
    assert _sweep(study, tmp_path / "o") == 0
    df = read_results(tmp_path / "o")
    said = _warned(capsys.readouterr().err, "sweep")
    assert len(said) == 1 and said[0].startswith("2 of 2 cases of study 's' have a logged battery voltage outside "
                                                 f"their model pack's open-circuit range, e.g.: {EIGHT_CELLS_ON_3S}")
    assert len(df) == 2 and (df["status"] == "ok").all()
    row = df[df["pads.0.hover_time_s"] == 75.0].iloc[0]
    assert main(["replay", str(LOG), "--pads", str(PADS), "--window", "440,620", "--drone", str(drone),
                 "--set", "pads.0.hover_time_s=75.0", "--set", "battery.capacity_ah=1.6", "--out", str(tmp_path / "r"),
                 "--format", "json", "--no-plot", "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert [w[:len(EIGHT_CELLS_ON_3S)] for w in _warned(err, "replay")] == [EIGHT_CELLS_ON_3S]
    cmd = json.loads(out)
    _assert_row_equals_command(row, cmd, min_numbers=25)
    # the --drone file reached the command (it was ignored with --pads before) and the case
    assert cmd["drone_mass_kg"] == 1.2 and row["drone_mass_kg"] == 1.2
    # physics: a longer charging hover over pad 0 buys more flight time, against the logged flight and
    # against the same detours unpowered; the detours' extra time is the hover difference
    short = df[df["pads.0.hover_time_s"] == 30.0].iloc[0]
    assert row["flight_time_gain_s"] > short["flight_time_gain_s"]
    assert row["flight_time_gain_vs_refly_without_charging_s"] > short["flight_time_gain_vs_refly_without_charging_s"]
    assert row["detour_time_s"] - short["detour_time_s"] == pytest.approx(45.0, abs=0.25)
    assert row["min_soc_refly"] <= row["final_soc_refly"]


def test_a_replay_case_without_pads_equals_the_replay_command(tmp_path, capsys, warnings_shown):
    """log171's 4S quad replayed with its own cell count; the log ends in flight, which both the study and the
    command say (once)."""
    df, config, said = _swept_log171(tmp_path, capsys, f'log = "{LOG171}"', '"drone.mass_kg" = [1.0, 1.83]',
                               "capacity_ah = 1.5\n")   # [study] base = the replay's --config
    row = df[df["drone.mass_kg"] == 1.83].iloc[0]
    assert main(["replay", str(LOG171), *config, "--set", "drone.mass_kg=1.83",
                 "--out", str(tmp_path / "r"), "--format", "json", "--no-plot", "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert _warned(err, "replay") == said
    cmd = json.loads(out)
    _assert_row_equals_command(row, cmd, min_numbers=30)
    # the power comparison is there (read from the rows as produced, no time series kept): at the
    # heavier mass the model's airborne energy is closer to the logged one (docs: equivalent mass 1.83 kg)
    light = df[df["drone.mass_kg"] == 1.0].iloc[0]
    assert abs(row["power_comparison.energy_error_rel"]) < 0.05 < abs(light["power_comparison.energy_error_rel"])


def test_a_replay_case_with_pad_equals_the_replay_command_with_pad(tmp_path, capsys, warnings_shown):
    """``[replay] pad = "LAT,LON,ALT"`` is the command's ``--pad``: the pad (the frame origin) 1.32 m below the
    take-off spot of log171 (590.82 m AMSL), ~15 m south-east of it. The 4S quad's own cell count; the log ends in
    flight, which the study says."""
    pad = "-35.36245,149.16595,589.5"
    df, config, said = _swept_log171(tmp_path, capsys, f'log = "{LOG171}"\npad = "{pad}"', '"drone.mass_kg" = [1.0, 1.83]')
    row = df[df["drone.mass_kg"] == 1.83].iloc[0]
    out = [*config, "--out", str(tmp_path / "r"), "--format", "json", "--no-plot", "--no-progress"]
    assert main(["replay", str(LOG171), f"--pad={pad}", "--set", "drone.mass_kg=1.83", *out]) == 0
    cmd = json.loads(capsys.readouterr().out)
    _assert_row_equals_command(row, cmd, min_numbers=30)
    # the pad reached the case: heights are above it (1.32 m more than above the take-off spot)
    assert main(["replay", str(LOG171), "--set", "drone.mass_kg=1.83", *out]) == 0
    default = json.loads(capsys.readouterr().out)
    assert row["max_alt_m"] - default["max_alt_m"] == pytest.approx(590.82 - 589.5, abs=1e-6)


def test_a_refly_case_with_pad_equals_the_command_with_pad_and_pads(tmp_path, capsys):
    """With ``pads``, ``pad`` is the pads' frame origin as with ``replay --pad ... --pads``; one without altitude
    takes the take-off spot's (590.76 m AMSL)."""
    pad = "-35.36235,149.16575"
    head, config = _fitting_pack(tmp_path, LOG)
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\npad = "{pad}"\nwindow = [440.0, 620.0]',
                   '"mission.hover_time_s" = [30.0, 60.0]', head=head)
    assert _sweep(study, tmp_path / "o") == 0
    df = read_results(tmp_path / "o")
    capsys.readouterr()
    row = df[df["mission.hover_time_s"] == 60.0].iloc[0]
    assert main(["replay", str(LOG), *config, f"--pad={pad}", "--pads", str(PADS), "--window", "440,620",
                 "--set", "mission.hover_time_s=60.0", "--out", str(tmp_path / "r"), "--format", "json", "--no-plot",
                 "--no-progress"]) == 0
    cmd = json.loads(capsys.readouterr().out)
    _assert_row_equals_command(row, cmd, min_numbers=25)
    assert (row["pad_frame_origin.lat_deg"], row["pad_frame_origin.lon_deg"], row["pad_frame_origin.alt_m"]) == (
        -35.36235, 149.16575, 590.76)


@pytest.mark.parametrize("pad", ["1,2,3,4", "-35.36", "north,east", "95,10", "-35.36,149.16,20000", 5])
def test_a_bad_pad_is_the_commands_error_in_the_study_files_words(tmp_path, capsys, pad):
    """The command's parser checks ``[replay] pad`` (one source): the same line, ``--pad`` named as the key."""
    study = _study(tmp_path, f'log = "{LOG}"\npad = {json.dumps(pad)}', '"drone.mass_kg" = [1.0, 2.0]')
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert main(["replay", str(LOG), f"--pad={pad}", "--out", str(tmp_path / "r"), "--no-progress"]) == 2
    cmd = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 == len(cmd) and "valid" in err[0], err
    shown = repr(pad)
    assert err[0].split(f"[replay] pad = {shown}", 1)[1] == cmd[0].split(f"--pad {str(pad)!r}", 1)[1], (err, cmd)
    assert not (tmp_path / "o").exists() and not (tmp_path / "r").exists()


@pytest.mark.parametrize("array, text", [("[-35.36245, 149.16595, 589.5]", "-35.36245,149.16595,589.5"),
                                         ("[-35.36245, 149.16595]", "-35.36245,149.16595")])
def test_a_pad_array_is_the_same_study_as_its_text(tmp_path, array, text):
    """``pad = [lat, lon]`` / ``[lat, lon, alt]``: the same point, fingerprint and case ids as the text."""
    import policies
    from mission_sim.studies.study import load_study
    from mission_sim.studies.sweep import prepare_study
    got = {}
    for name, pad in (("a.toml", array), ("t.toml", json.dumps(text))):
        st = load_study(_study(tmp_path, f'log = "{LOG171}"\npad = {pad}', '"drone.mass_kg" = [1.0, 1.83]', name=name))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DronewptWarning)   # (log171 ends armed)
            _, cases, fingerprint = prepare_study(st, policies.make, policies.available())
        got[name] = (st.replay["pad"], fingerprint, [c.case_id for c in cases])
    assert got["a.toml"] == got["t.toml"]
    assert (got["a.toml"][0].lat_deg, got["a.toml"][0].lon_deg) == (-35.36245, 149.16595)


@pytest.mark.parametrize("array, words", [
    ("[95, 10]", ": latitude 95.0 is invalid; valid range: (-90, 90) degrees"),   # as the text '95,10'
    ("[-35.36, 149.16, 20000]", ": altitude 20000.0 is invalid; valid range: [-500, 10000] m AMSL"),
    ("[1, 2, 3, 4]", " is invalid; valid format: [LAT, LON] or [LAT, LON, ALT]"),
    ("[-35.36]", " is invalid; valid format: [LAT, LON] or [LAT, LON, ALT]"),
    ('["north", "east"]', " is invalid; valid format: [LAT, LON] or [LAT, LON, ALT]"),
    ("[true, 149.16]", " is invalid; valid format: [LAT, LON] or [LAT, LON, ALT]"),
])
def test_a_bad_pad_array_is_one_line_naming_it(tmp_path, capsys, array, words):
    study = _study(tmp_path, f'log = "{LOG}"\npad = {array}', '"drone.mass_kg" = [1.0, 2.0]')
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"[replay] pad = [" in err[0] and words in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_pads_file_far_from_the_pad_is_the_commands_error_naming_the_study_key(tmp_path, capsys):
    """``pads`` about a ``pad`` ~4,000 km away: the command's line (a pad far from the frame origin), its ``--pad``
    named as the study's ``[replay] pad``."""
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\npad = "0,0"', '"drone.mass_kg" = [1.0, 2.0]')
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert main(["replay", str(LOG), "--pad=0,0", "--pads", str(PADS), "--out", str(tmp_path / "r"),
                 "--no-progress"]) == 2
    cmd = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 == len(cmd) and "km from the replay's pad frame origin" in cmd[0], (err, cmd)
    assert "--pad" not in err[0] and "(the take-off spot, or [replay] pad)" in err[0], err
    assert err[0].split(": ", 1)[1] == cmd[0].split(": ", 1)[1].replace("or --pad)", "or [replay] pad)"), (err, cmd)
    assert not (tmp_path / "o").exists()


def _warning_lines(err: str, command: str) -> list[str]:
    """The command's warning lines but the logged voltage's (the study counts that one per case)."""
    return [w for w in _warned(err, command) if "logged battery voltage" not in w]


@pytest.mark.parametrize("replay, flags, words", [
    # a pad 40 km south of the flight (replay --pad): the drone never comes near it
    (f'log = "{LOG}"\npad = "-35.0,149.16575"\nwindow = [440.0, 620.0]', ["--pad=-35.0,149.16575", "--window",
                                                                         "440,620"], "40 km from the nearest point"),
    (f'log = "{LOG171}"', [], "the log ends while the vehicle is armed"),   # log171 is cut off in flight
    (f'log = "{LOG171}"\npads = "{PADS}"', ["--pads", str(PADS)], "the log ends while the vehicle is armed"),
])
def test_a_replay_study_warns_the_logs_warnings_once_as_the_command_does(tmp_path, capsys, replay, flags, words,
                                                                        warnings_shown):
    """The warnings ``dronewpt replay`` gives about the log (replay_warnings: the log, the pad, the window; the same
    in every case) are the study's, once, in its words; each case still counts them (n_warnings, as the command's
    summary)."""
    study = _study(tmp_path, replay, '"drone.mass_kg" = [1.0, 1.3]')
    assert _sweep(study, tmp_path / "o") == 0
    got = _warning_lines(capsys.readouterr().err, "sweep")
    assert main(["replay", str(LOG if "dronekit-python" in replay else LOG171), *flags, "--set", "drone.mass_kg=1.3",
                 "--out", str(tmp_path / "r"), "--format", "json", "--no-plot", "--no-progress"]) == 0
    out, err = capsys.readouterr()
    want = [w.replace("check --pad", "check [replay] pad") for w in _warning_lines(err, "replay")]
    assert len(want) == 1 and words in want[0], want
    assert got == want, (got, want)
    row = read_results(tmp_path / "o").set_index("drone.mass_kg").loc[1.3]
    assert row["n_warnings"] == len(json.loads(out)["warnings"]) >= 1


def test_the_log_is_parsed_once_per_process_not_per_case(tmp_path, monkeypatch):
    from mission_sim.mavlink import logs
    calls = []
    real = logs.read_log
    monkeypatch.setattr(logs, "read_log", lambda path, *a, **k: calls.append(path) or real(path, *a, **k))
    monkeypatch.setattr(replay_cases, "_INPUTS", {})
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\nwindow = [440.0, 620.0]',
                   '"drone.mass_kg" = [1.0, 1.1, 1.2]', head=_fitting_pack(tmp_path, LOG)[0])
    assert _sweep(study, tmp_path / "o") == 0
    assert len(read_results(tmp_path / "o")) == 3 and len(calls) == 1


@pytest.mark.parametrize("grid, words", [
    ('"drone.mas_kg" = [1.0, 2.0]', ["drone.mas_kg", "mass_kg"]),
    ('"drone.mass_kg" = [1.0, -1.0]', ["1 of 2 cases", "drone.mass_kg=-1.0", "valid range", "nothing was run"]),
    ('"pads.7.hover_time_s" = [10.0, 20.0]', ["pads.7.hover_time_s", "0..1"]),
    ('policy = ["step", "bang"]', ["policy='bang'", "model_based"]),
    ('"sim.traj_dt_s" = [0.2, 1e-5]', ["sim.traj_dt_s=1e-05", "valid range"]),
    ('"pads.0.x_m" = [3000.0, 4000.0]\n"pads.1.x_m" = 3000.0', ["2 of 2 cases", "no pad within", "[replay] reach_m"]),
    # read with the files when the base is loaded: every case re-flew the same pads, even with a missing file
    ('"mission.pads_file" = ["/nonexistent.csv", "b.csv"]', ["study key 'mission.pads_file' is invalid"]),
])
def test_bad_keys_and_values_are_refused_before_anything_runs(tmp_path, capsys, monkeypatch, grid, words):
    ran = []
    monkeypatch.setattr(replay_cases.ReplayCaseRunner, "__call__", lambda self, p: ran.append(p) or {})
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\nwindow = [440.0, 620.0]', grid)
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert not ran and not (tmp_path / "o").exists()


@pytest.mark.parametrize("replay, words", [
    ('log = "missing.tlog"', ["[replay] log", "missing.tlog", "does not exist"]),
    ('log = "notes.tlog"', ["[replay] log", "notes.tlog", "no usable position"]),
    ('log = "."', ["[replay] log", "is a folder"]),
    (f'log = "{LOG}"\npads = "nopads.csv"', ["[replay] pads", "nopads.csv", "does not exist"]),
    (f'log = "{LOG}"\nsegment = 3', ["[replay] segment = 3", "1..2"]),
    (f'log = "{LOG}"\npads = "{PADS}"\nsegment = 1', ["not airborne", "anywhere in boot segment 1 (window 0..254.433 s)",
                                                    "valid: a [replay] window = or [replay] segment = in which it flew"]),
    ('pads = "x.csv"', ["[replay] has no log"]),
    (f'log = "{LOG}"\nwindow = [5.0, 1.0]', ["[replay] window", "T0 < T1"]),
    # past the log's end (1377.029 s): the cases replayed 440..1377 s without a word
    (f'log = "{LOG}"\nwindow = [440.0, 2000.0]', ["[replay] window = [440, 2000] is invalid: the log ends at 1377.029 s; "
                                                  "valid: 0 <= T0 < T1 <= 1378.029 s"]),
    (f'log = "{LOG}"\nlogg = 1', ["[replay] key 'logg' is unknown", "ground_gap_m"]),
])
def test_a_study_on_a_missing_or_non_log_file_is_one_line(tmp_path, capsys, replay, words):
    (tmp_path / "notes.tlog").write_text("not a flight log\n" * 50)
    study = _study(tmp_path, replay, '"drone.mass_kg" = [1.0, 2.0]')
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert not (tmp_path / "o").exists()


def test_an_interrupted_replay_sweep_resumes_with_only_the_missing_cases(tmp_path, capsys, monkeypatch):
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\nwindow = [440.0, 620.0]',
                   '"drone.mass_kg" = [1.0, 1.2]\n"mission.hover_time_s" = [20.0, 40.0]', head=_fitting_pack(tmp_path, LOG)[0])
    real = replay_cases.ReplayCaseRunner.__call__
    ran = []

    def interrupted_after_two(self, params):
        if len(ran) == 2:
            raise KeyboardInterrupt
        ran.append(params)
        return real(self, params)

    monkeypatch.setattr(replay_cases.ReplayCaseRunner, "__call__", interrupted_after_two)
    assert _sweep(study, tmp_path / "o") == 130
    assert len(read_results(tmp_path / "o")) == 2      # what finished is stored
    capsys.readouterr()

    def counting(self, params):
        ran.append(params)
        return real(self, params)

    monkeypatch.setattr(replay_cases.ReplayCaseRunner, "__call__", counting)
    assert _sweep(study, tmp_path / "o") == 0
    s = json.loads(capsys.readouterr().out)
    assert (s["cases"], s["skipped"], s["run"], s["ok"]) == (4, 2, 2, 4)
    assert len(ran) == 4 and len({json.dumps(p, sort_keys=True) for p in ran}) == 4   # each case run once
    resumed = read_results(tmp_path / "o")
    # equal, bit for bit, to an uninterrupted sweep
    assert _sweep(study, tmp_path / "whole") == 0
    whole = read_results(tmp_path / "whole")
    volatile = ["case_wall_s", "case_cpu_s", "worker", "attempt", "traceback"]
    pd.testing.assert_frame_equal(resumed.drop(columns=volatile).sort_values("case_id").reset_index(drop=True),
                                  whole.drop(columns=volatile).sort_values("case_id").reset_index(drop=True),
                                  check_exact=True)
    # the folder records the code that made the rows, the log-to-replay code included (a resume by another
    # version of it is refused, as for missions)
    from mission_sim.studies.status import physics_code_hash
    man = json.loads((tmp_path / "o" / "sweep.json").read_text())
    assert man["physics_code"] == physics_code_hash(replay=True) != physics_code_hash()
    # and the status sees the study done
    capsys.readouterr()
    assert main(["sweep", "--status", str(tmp_path / "o")]) == 0
    assert "4 cases, 4 done (100.0 %): 4 ok, 0 failed, 0 pending" in capsys.readouterr().out


def test_the_replay_physics_code_hash_covers_the_replay_runner(monkeypatch):
    """What a replay case gives ``replay_log`` / ``refly_log`` (the pad frame origin, the options) is decided in
    ``studies/replay_cases.py``: a resume by another version of it is refused as for the replay code itself."""
    from wpt_receiver import kernel_cache
    from mission_sim.studies.status import physics_code_hash
    calls = []

    def files_hashed(files):
        calls.append({(f.parent.name, f.name) for f in files})
        return "0" * 64

    monkeypatch.setattr(kernel_cache, "dependency_hash", files_hashed)
    physics_code_hash(replay=True)
    physics_code_hash(replay=False)
    names = calls
    assert ("studies", "replay_cases.py") in names[0] and ("mavlink", "replay.py") in names[0]
    assert ("studies", "replay_cases.py") not in names[1] and ("world", "runner.py") in names[1]


def test_the_example_replay_study_is_valid_and_its_files_are_shipped():
    import policies
    from mission_sim.studies.study import load_study
    from mission_sim.studies.sweep import prepare_study
    st = load_study(ROOT / "examples" / "study_replay.toml")
    with pytest.warns(DronewptWarning, match="12 of 12 cases .* logged battery voltage"):   # the 8S drone, a 3S log
        runner, cases, _ = prepare_study(st, policies.make, policies.available())
    assert len(cases) == 12 and st.replay["log"].resolve().parent == (DATA / "flightlogs").resolve()
    assert isinstance(runner, replay_cases.ReplayCaseRunner)


@pytest.mark.parametrize("study_file", [ROOT / "examples" / "study_replay.toml", "log171"])
def test_a_study_without_pad_keeps_its_case_ids(tmp_path, study_file):
    """``[replay] pad`` is new: a study without it keeps its fingerprint and case ids, i.e. those of the code before
    it (the fingerprint's ``ident``: the replay's base mission with the pads about the take-off spot, the files'
    sha256 and the other options as they were; computed here from the inputs, not from a run)."""
    import hashlib

    import policies
    from mission_sim.mavlink.replay import default_pad
    from mission_sim.studies.study import canonical_json, case_id, load_study
    from mission_sim.studies.sweep import prepare_study
    if study_file == "log171":
        study_file = _study(tmp_path, f'log = "{LOG171}"', '"drone.mass_kg" = [1.0, 1.83]')
    st = load_study(study_file)
    assert "pad" not in st.replay
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DronewptWarning)   # (the 8S drone on a 3S log, a log ending armed)
        _, cases, fingerprint = prepare_study(st, policies.make, policies.available())
    o = st.replay
    sha = {k: hashlib.sha256(Path(o[k]).read_bytes()).hexdigest() if k in o else None for k in ("log", "pads")}
    log = replay_cases.load_inputs("log", o["log"], sha["log"])
    pads = replay_cases.load_inputs("pads", o["pads"], sha["pads"]) if "pads" in o else None
    ident = {"runner": "replay v1", "base": replay_cases._base(st, o, default_pad(log), pads), **sha,
             "options": {k: v for k, v in o.items() if k not in ("log", "pads", "drone")}}
    before = hashlib.sha256(canonical_json(ident).encode()).hexdigest()[:16]
    assert fingerprint == before
    ids = [c.case_id for c in cases]
    assert ids == [case_id(params, before) for params in cases.params()] and len(set(ids)) == len(cases) > 1


def test_two_local_workers_equal_serial_and_each_parses_the_log_once(tmp_path):
    import policies
    from mission_sim.studies.study import load_study
    from mission_sim.studies.sweep import dask_client, prepare_study, run_sweep
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\nwindow = [440.0, 620.0]',
                   '"drone.mass_kg" = [1.0, 1.4]\n"mission.hover_time_s" = [20.0, 50.0]')
    with pytest.warns(DronewptWarning, match="logged battery voltage"):   # the 8S model drone, a 3S log
        runner, cases, _ = prepare_study(load_study(study), policies.make, policies.available())
    with dask_client(workers=2) as client:
        res = run_sweep(cases, runner, tmp_path / "dask", client=client, progress=False)
        parsed = client.run(lambda: sorted(k[0] for k in __import__("mission_sim.studies.replay_cases",
                                                                       fromlist=["_INPUTS"])._INPUTS))
    serial = run_sweep(cases, runner, tmp_path / "serial", progress=False)
    assert res.n_ok == 4 and len(parsed) == 2 and all(v == ["log"] for v in parsed.values()), parsed
    volatile = ["case_wall_s", "case_cpu_s", "worker", "traceback"]
    pd.testing.assert_frame_equal(res.results.drop(columns=volatile).sort_values("case_id").reset_index(drop=True),
                                  serial.results.drop(columns=volatile).sort_values("case_id").reset_index(drop=True),
                                  check_exact=True)


def test_replay_with_pads_honours_segment(tmp_path, capsys):
    """`replay --pads` flew the whole log whatever --segment said; boot segment 1 of the dronekit log
    (0..254 s) is never armed, so no pad can be reached from it, and segment 3 does not exist."""
    for seg, words in (("1", ["not airborne", "anywhere in the window 0..254.433 s"]),
                       ("3", ["--segment 3 is invalid", "1..2"])):
        assert main(["replay", str(LOG), "--pads", str(PADS), "--segment", seg, "--out", str(tmp_path / "o"),
                     "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and all(w in err[0] for w in words), err


def test_the_documented_replay_section_parses(tmp_path):
    import inspect
    import textwrap
    import tomllib

    from mission_sim.studies import study as study_mod
    doc = inspect.getdoc(study_mod)
    block = textwrap.dedent(doc.split("A ``[replay]`` section")[1].split("::\n", 1)[1].split("\n\nDistributions")[0])
    st = study_mod.parse_study({**tomllib.loads(block), "grid": {"drone.mass_kg": [1.0, 2.0]}}, base_dir=tmp_path)
    assert set(st.replay) == {"log", "pads", "pad", "drone", "window", "reach_m", "ground_gap_m"}
    seg = study_mod.parse_study({**tomllib.loads(block.replace("# segment", "segment").replace("window =", "# window =")),
                                 "grid": {"drone.mass_kg": [1.0, 2.0]}}, base_dir=tmp_path)
    assert seg.replay["segment"] == 2 and "window" not in seg.replay
    assert st.replay["log"] == tmp_path / "flight.tlog" and st.replay["window"] == (440.0, 620.0)


def test_a_depleted_replay_case_counts_the_commands_warnings(tmp_path, capsys, warnings_shown):
    """The command warned where the battery ran out, the study's row did not count it (n_warnings differed):
    both now take the summary's one list (mission_sim.mavlink.replay.replay_summary_warnings). The 4S quad's own
    cell count; the log ends in flight, which the study says."""
    df, config, said = _swept_log171(tmp_path, capsys, f'log = "{LOG171}"', '"battery.capacity_ah" = [0.05, 1.5]')
    row = df[df["battery.capacity_ah"] == 0.05].iloc[0]
    assert main(["replay", str(LOG171), *config, "--set", "battery.capacity_ah=0.05", "--out", str(tmp_path / "r"),
                 "--format", "json", "--no-plot", "--no-progress"]) == 0
    cmd = json.loads(capsys.readouterr().out)
    assert cmd["battery_depleted"] is True and bool(row["battery_depleted"])
    assert any(w.startswith("battery depleted at t = ") for w in cmd["warnings"])
    assert row["n_warnings"] == len(cmd["warnings"])
    _assert_row_equals_command(row, cmd, min_numbers=30)
    full = df[df["battery.capacity_ah"] == 1.5].iloc[0]
    assert not full["battery_depleted"] and full["n_warnings"] == row["n_warnings"] - 1


def _never_run(monkeypatch):
    from mission_sim.world import runner

    def ran(*a, **k):
        raise AssertionError("a run started")
    monkeypatch.setattr(runner, "run_mission", ran)


def test_a_refly_too_long_for_memory_is_refused_by_the_command_before_it_runs(tmp_path, capsys, monkeypatch):
    """`replay --pads --set mission.hover_time_s=100000` ran for minutes at ~2 GB: the re-flight's samples
    (logged span + detours with their charging hovers, at sim.traj_dt_s) are held to the replay's limit."""
    from mission_sim.mavlink.replay import MAX_REPLAY_SAMPLES
    _never_run(monkeypatch)
    pads = tmp_path / "pads.csv"   # the test pads without their own hover_time_s: mission.hover_time_s applies
    pads.write_text("lat,lon\n" + "".join(",".join(r.split(",")[:2]) + "\n" for r in PADS.read_text().splitlines()[1:]))
    dt = 0.2
    hover = MAX_REPLAY_SAMPLES * dt + 1.0   # one pad visited: its hover alone is over the limit
    assert main(["replay", str(LOG), "--pads", str(pads), "--window", "440,620", "--set", f"mission.hover_time_s={hover}",
                 "--set", f"sim.traj_dt_s={dt}", "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"mission.hover_time_s={hover:g}" in err[0] and "valid range: [0, " in err[0], err
    room = float(err[0].split("valid range: [0, ")[1].split("]")[0])
    assert 0 < room < hover and not (tmp_path / "o").exists()


def test_a_refly_case_too_long_for_memory_is_refused_before_the_sweep_runs(tmp_path, capsys, monkeypatch):
    """In a sweep a 20000 s hover took 13.7 s and 374 MB, the allowed 1e6 s gigabytes per worker: refused with the
    other bad values, before anything runs (a pad's own hover named by its key)."""
    _never_run(monkeypatch)
    study = _study(tmp_path, f'log = "{LOG}"\npads = "{PADS}"\nwindow = [440.0, 620.0]',
                   '"pads.0.hover_time_s" = [30.0, 1e6]\n"drone.mass_kg" = [1.0, 1.2]')
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in ("2 of 4 cases", "pads.0.hover_time_s=1e+06", "valid range",
                                                        "nothing was run")), err
    assert not (tmp_path / "o").exists()


def test_a_resume_over_a_changed_log_names_the_file(tmp_path, capsys):
    """A changed log was refused as "another study (..., another base mission)": sweep.json records the log's
    (and the pads file's) sha256 and the refusal names the changed file."""
    import hashlib
    import shutil
    log = tmp_path / "f.tlog"
    shutil.copyfile(LOG, log)
    study = _study(tmp_path, f'log = "f.tlog"\npads = "{PADS}"\nwindow = [440.0, 620.0]', '"drone.mass_kg" = [1.0, 1.2]',
                   head=_fitting_pack(tmp_path, LOG)[0])
    assert _sweep(study, tmp_path / "o") == 0
    man = json.loads((tmp_path / "o" / "sweep.json").read_text())
    assert man["inputs"] == {"[replay] log": {"path": str(log), "sha256": hashlib.sha256(LOG.read_bytes()).hexdigest()},
                             "[replay] pads": {"path": str(PADS), "sha256": hashlib.sha256(PADS.read_bytes()).hexdigest()}}
    capsys.readouterr()
    with open(log, "ab") as fh:   # the same flight with a few bytes of junk after it: still a log, another file
        fh.write(b"\0" * 64)
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()   # the refusal alone: the study's warnings come once it runs
    assert len(err) == 1 and all(w in err[0] for w in ("[replay] log", str(log), "changed since it ran",
                                                        man["inputs"]["[replay] log"]["sha256"][:12])), err
    assert "another base mission" not in err[0]


def test_a_refused_out_is_one_line_and_the_studys_warnings_follow_the_checks(tmp_path, capsys, warnings_shown):
    """``--out`` a file: the one-line refusal (exit 2), not the study's warnings before it; a sweep that runs
    says them (the 8S model drone on the 3S log) before its report."""
    study = _study(tmp_path, f'log = "{LOG}"\nwindow = [440.0, 620.0]', '"drone.mass_kg" = [1.0, 1.2]')
    (tmp_path / "file").write_text("")
    assert _sweep(study, tmp_path / "file") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0] and "warning" not in err[0], err
    assert _sweep(study, tmp_path / "o") == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dronewpt sweep: warning: 2 of 2 cases of study 's' have a logged "
                                               "battery voltage"), err


def test_a_missing_relative_log_says_paths_are_relative_to_the_study_file(tmp_path, capsys, monkeypatch):
    (tmp_path / "studies").mkdir()
    (tmp_path / "flight.tlog").write_bytes(LOG.read_bytes())   # beside the current folder, not the study file
    monkeypatch.chdir(tmp_path)
    study = _study(tmp_path / "studies", 'log = "flight.tlog"', '"drone.mass_kg" = [1.0, 2.0]')
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in (
        "[replay] log", "does not exist", "relative to the study file's folder", repr(str(tmp_path / "studies")))), err


def test_a_replay_study_that_varies_nothing_says_replay(tmp_path):
    from mission_sim.studies.study import parse_study
    with pytest.raises(ValueError, match="would replay the log once"):
        parse_study({"replay": {"log": "f.tlog"}}, base_dir=tmp_path)


def test_a_worker_that_does_not_see_the_log_parses_the_bytes_sent_with_the_warm_up(tmp_path, monkeypatch):
    """Remote `--scheduler` workers needed the log at the driver's absolute path (else every case was stored as
    an error with a bare FileNotFoundError): a log up to SHIP_MAX_BYTES goes with the warm-up, checked by its
    sha256; a larger one that a worker does not see is one line naming [replay] log."""
    import pickle
    import shutil

    import policies
    from mission_sim.studies.study import load_study
    from mission_sim.studies.sweep import prepare_study
    log = tmp_path / "f.tlog"
    shutil.copyfile(LOG, log)
    study = _study(tmp_path, f'log = "f.tlog"\npads = "{PADS}"\nwindow = [440.0, 620.0]', '"drone.mass_kg" = [1.0, 1.2]')
    with pytest.warns(DronewptWarning, match="logged battery voltage"):   # the 8S model drone, a 3S log
        runner, _, _ = prepare_study(load_study(study), policies.make, policies.available())
    params = {"drone.mass_kg": 1.2}
    want = runner(params)
    sent = pickle.dumps(runner.warm)            # what the engine sends to every worker, once
    case_runner = pickle.dumps(runner)          # what it sends with each chunk: no log bytes in it
    assert len(sent) > LOG.stat().st_size > len(case_runner)
    log.unlink()                                # the worker's machine has no such file
    monkeypatch.setattr(replay_cases, "_INPUTS", {})
    monkeypatch.setattr(replay_cases, "_SHIPPED", {})
    worker = pickle.loads(case_runner)
    with pytest.raises(ValueError, match=r"^\[replay\] log '.*f\.tlog' does not exist on worker .* shared folder\)$"):
        worker(params)
    pickle.loads(sent)()                        # the warm-up: the bytes installed, the base case replayed
    assert worker(params) == want      # the same row, bit for bit
    assert replay_cases._INPUTS[("log", str(log), runner.log_sha)].path == log


def test_segment_and_window_together_are_refused_not_one_silently_ignored(tmp_path, capsys):
    """The window won and the segment was ignored without a word, in the study and in the commands."""
    study = _study(tmp_path, f'log = "{LOG}"\nwindow = [440.0, 620.0]\nsegment = 2', '"drone.mass_kg" = [1.0, 2.0]')
    assert _sweep(study, tmp_path / "o") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in ("[replay] segment = 2", "window = [440.0, 620.0]",
                                                        "exclude each other")), err
    for pads in ([], ["--pads", str(PADS)]):
        assert main(["replay", str(LOG), *pads, "--window", "440,620", "--segment", "2", "--out", str(tmp_path / "r"),
                     "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--segment 2 and --window 440,620 exclude each other" in err[0], err
    assert not (tmp_path / "r").exists()


def test_sizing_from_a_replay_sweep_says_it_is_a_replay(tmp_path, capsys):
    """2026-11-27: `sizing --source sweep --sweep DIR` on a replay study's folder said "ran on base mission c875...,
    the given mission is 88fb...; valid: the study's base mission (--config)": no --config could ever match."""
    study = _study(tmp_path, f'log = "{LOG}"\nwindow = [440.0, 470.0]', '"drone.mass_kg" = [1.0, 1.2]',
                   head=_fitting_pack(tmp_path, LOG)[0])
    assert _sweep(study, tmp_path / "o") == 0
    capsys.readouterr()
    assert main(["sizing", "--source", "sweep", "--sweep", str(tmp_path / "o"), "--no-plot"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dronewpt sizing: error: sweep {str(tmp_path / 'o')!r} replayed a flight log ([replay] section), "
                   "its cases are not missions to re-run; valid: a sweep of missions"]


@pytest.mark.parametrize("msg,words", [
    ("--window 440,2000 is invalid: the log ends", "[replay] window = [440, 2000] is invalid: the log ends"),
    ("--window T0,599.1 or --window 700.3,T1", "[replay] window = [T0, 599.1] or [replay] window = [700.3, T1]"),
    ("--window 1e+03,-5 is invalid", "[replay] window = [1e+03, -5] is invalid"),
    # a quoted window is not a window's two numbers (it became "[replay] window = ['5, 1']")
    ("--window '5,1' is invalid", "[replay] window = '5,1' is invalid"),
])
def test_a_window_in_a_message_is_the_study_files_words(msg, words):
    assert replay_cases._study_words(msg) == words


def test_a_null_periods_list_keeps_its_counted_column():
    """A replay summary's ``*_periods_s`` lists become ``n_<key>`` columns; ``armed_periods_s`` is null for a log
    whose armed state is unknown, and was then stored as ``armed_periods_s`` (another column than every other
    log's): it is ``n_armed_periods_s`` = null. Other nulls keep their own name."""
    from mission_sim.studies.replay_cases import _flat
    got = _flat({"armed_periods_s": None, "flown_periods_s": [[0.0, 1.0], [2.0, 3.0]], "armed_time_s": None,
                 "facts": {"log_armed_periods_s": None}})
    assert got == {"n_armed_periods_s": None, "n_flown_periods_s": 2, "armed_time_s": None,
                   "facts.n_log_armed_periods_s": None}
