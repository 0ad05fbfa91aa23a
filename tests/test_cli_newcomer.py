"""What a newcomer ran into on a fresh clone (2026-11-26 night; every case tried is listed in
docs/robustness.md, "A newcomer's pass"): each test here failed before its fix."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from mission_sim.cli import main

MISSIONS = Path(__file__).resolve().parent / "data" / "missions"


def _one_error_line(capsys, argv) -> str:
    """``main(argv)``: exit status 2, nothing on stdout, one line on stderr (returned)."""
    assert main(argv) == 2
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in cap.err, cap.err
    assert cap.out == "", cap.out
    return lines[0]


# ------------------------------------------------------------------ a mission in a flight log
def test_log_under_a_bin_folder_is_read_not_executed(tmp_path, capfd):
    """``--plan .../bin/flight.tlog``: the uploaded mission was read with ``mavlink_connection``, which runs
    any existing file whose path contains /bin/ as a program ("executing '...'", then
    ``[Errno 13] Permission denied``, or the file run if it was executable)."""
    from mission_sim.plans.items import uploaded_mission
    src = MISSIONS / "uavlogviewer_vtol_sitl_mission.tlog"
    (tmp_path / "bin").mkdir()
    moved = tmp_path / "bin" / src.name
    shutil.copyfile(src, moved)
    capfd.readouterr()
    a, b = uploaded_mission(src), uploaded_mission(moved)
    assert len(a.items) == 4 and a.items == b.items and a.home == b.home
    assert capfd.readouterr() == ("", "")


def test_garbage_dataflash_plan_is_one_line(tmp_path, capfd):
    """``--plan garbage.bin``: pymavlink's DataFlash reader printed one "bad header 0x... at N" line per
    corrupt byte run (4,474 lines for 5 kB of noise) before the one-line error."""
    p = tmp_path / "garbage.bin"
    p.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    assert main(["mission", "--plan", str(p), "--no-plot", "--out", str(tmp_path / "m")]) == 2
    out, err = capfd.readouterr()
    assert out == "" and err.splitlines() == [
        "dronewpt mission: error: garbage.bin: no flown track: 0 usable position(s) (GPS fix >= 3) while armed"], err
