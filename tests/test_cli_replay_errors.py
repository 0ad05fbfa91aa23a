"""`dronewpt replay` / `telemetry` bad input: one-line errors, exit status 2, no traceback."""

from pathlib import Path

import numpy as np
import pytest

from _flightlogs import log_path
from mission_sim.cli import main


def _one_line_error(capsys, argv, *needles):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for n in needles:
        assert n in err[0], err[0]
    return err[0]


def test_missing_log(capsys, tmp_path):
    _one_line_error(capsys, ["replay", str(tmp_path / "nope.tlog")], "nope.tlog", "does not exist")


@pytest.mark.parametrize("suffix", [".tlog", ".bin"])
def test_empty_log(capsys, tmp_path, suffix):
    p = tmp_path / f"empty{suffix}"
    p.write_bytes(b"")
    _one_line_error(capsys, ["replay", str(p)], "no usable position")


def test_truncated_log_without_position(capsys, tmp_path):
    p = tmp_path / "head.tlog"
    p.write_bytes(log_path("dronekit-python_flight.tlog").read_bytes()[:20_000])  # before any 3D fix
    _one_line_error(capsys, ["replay", str(p)], "no usable position", "GPS fix >= 3")


def test_garbage_log(capsys, tmp_path):
    p = tmp_path / "junk.bin"
    p.write_bytes(np.random.default_rng(1).integers(0, 256, 50_000, dtype=np.uint8).tobytes())
    _one_line_error(capsys, ["replay", str(p)], "no usable position")


@pytest.mark.parametrize("pad", ["1,2,3,4", "north,east", "95,10", "-35,149,nan"])
def test_bad_pad(capsys, pad):
    _one_line_error(capsys, ["replay", str(log_path("uavlogviewer_vtol_sitl.tlog")), f"--pad={pad}"], "--pad")


def test_bad_window(capsys):
    _one_line_error(capsys, ["replay", str(log_path("uavlogviewer_vtol_sitl.tlog")), "--window", "9,3"],
                    "--window", "T0,T1")
    # a window past the log's end (207.9 s): refused naming the log's time range (it said "no usable position")
    _one_line_error(capsys, ["replay", str(log_path("uavlogviewer_vtol_sitl.tlog")), "--window", "500,600"],
                    "--window 500,600 is invalid: the log ends at 207.886 s; valid: 0 <= T0 < T1 <= 208.886 s")


@pytest.mark.parametrize("pads", [[], ["--pads", str(Path(__file__).parent / "data" / "missions" / "dronekit_flight_pads.csv")]])
def test_a_window_that_ends_after_the_log_is_refused_not_cut(capsys, tmp_path, pads):
    """2026-11-27: `replay LOG --window 440,2000` on a log that ends at 1377 s replayed 440..1377 s without a word
    (also with --pads); now one line naming the log's time range, nothing written. A window ending within
    WINDOW_END_SLACK_S (1 s) of the end, a rounded-up end, is still taken."""
    log = str(log_path("dronekit-python_flight.tlog"))
    _one_line_error(capsys, ["replay", log, *pads, "--window", "440,2000", "--out", str(tmp_path / "o"),
                             "--no-progress"],
                    "--window 440,2000 is invalid: the log ends at 1377.029 s; valid: 0 <= T0 < T1 <= 1378.029 s of log "
                    "time (its time range 0..1377.029 s; 1 s allowed for a rounded end)")
    assert not (tmp_path / "o").exists()
    from mission_sim.mavlink.logs import read_log
    from mission_sim.mavlink.replay import replay_span, track_from_log
    flight = read_log(log)
    assert replay_span(flight, (440.0, 1378.0))[0] == (440.0, 1378.0)
    # the bound the message gives is the one taken (it printed the log's end, 1 s short of it); track_from_log, which
    # cuts the log to the window, checks it (every path: replay, calibrate, refly, the studies)
    assert track_from_log(flight, window=(440.0, 1378.029)).t_offset_s >= 440.0
    with pytest.raises(ValueError, match=r"T1 <= 1378\.029 s"):
        track_from_log(flight, window=(440.0, 1378.03))


@pytest.mark.parametrize("argv,needle", [
    (["--connect", "udpout:localhost"], "udpout:HOST:PORT"),
    (["--connect", "none"], "--tlog"),
    (["--home=-35,149"], "altitude"),
    (["--follow", "serial:/dev/x"], "--follow"),
])
def test_telemetry_bad_input(capsys, argv, needle):
    _one_line_error(capsys, ["telemetry", *argv], needle)


def test_reach_without_pads(capsys, tmp_path):
    """2026-11-27: `replay LOG --reach 10` without --pads replayed the log (exit 0), --reach ignored; a replay study's
    `reach_m` without `pads` was already refused."""
    out = tmp_path / "r"
    err = _one_line_error(capsys, ["replay", str(log_path("dronekit-python_flight.tlog")), "--reach", "10",
                                   "--out", str(out)])
    assert err == "dronewpt replay: error: --reach is only used with --pads; add --pads FILE or drop --reach"
    assert not out.exists()


@pytest.mark.parametrize("key", ["mission.pads_file", "mission.file", "mission.from_log", "mission.pad_radius_m"])
def test_set_of_a_mission_file_key_is_refused(key, capsys, tmp_path):
    """2026-11-27: `replay LOG --set mission.pads_file=pads.csv` (instead of --pads) replayed the log about one pad at
    the take-off spot, exit 0: the key was read, then replaced by the log's route and the replay's pad."""
    out = tmp_path / "r"
    err = _one_line_error(capsys, ["replay", str(log_path("dronekit-python_flight.tlog")), "--set", f"{key}=x",
                                   "--out", str(out)])
    assert err == (f"dronewpt replay: error: --set {key} is not used by replay: the route is the log's, the pads are "
                   "--pads FILE (or --pad); valid: drop it (with pads: --pads FILE)")
    assert not out.exists()


def test_pads_with_a_window_where_the_vehicle_never_flew(capsys, tmp_path):
    """2026-11-27: `replay LOG --pads P --window 1,300` (on the ground) said "no pad within --reach 500 m of the airborne
    track (pad 0 at inf m, pad 1 at inf m)", as if the pads were too far; it is the window that holds no flight."""
    from pathlib import Path
    pads = Path(__file__).resolve().parents[1] / "examples" / "study_replay_pads.csv"
    err = _one_line_error(capsys, ["replay", str(log_path("dronekit-python_flight.tlog")), "--pads", str(pads),
                                   "--window", "1,300", "--out", str(tmp_path / "r")])
    assert err == ("dronewpt replay: error: dronekit-python_flight.tlog: the vehicle is not airborne (armed and more "
                   "than 1 m above the take-off spot) anywhere in the window 1..300 s, so there is no track to make a "
                   "detour from; valid: a --window or --segment in which it flew")
    assert not (tmp_path / "r").exists()
