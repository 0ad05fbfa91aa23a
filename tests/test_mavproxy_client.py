"""A real ground station on the telemetry: MAVProxy, headless, over loopback UDP (issue 12).

MAVProxy (``mavproxy.py --non-interactive``) listens as the ground station and forwards what it
receives (``--out``) to a separate pymavlink process that records arrival times. Checked on what
MAVProxy itself says (its console lines) and on the stream it relays: one vehicle, the right
ArduCopter mode (LOITER while hover-charging, AUTO in transit; never the STABILIZE that custom
mode 0 used to show), no fence-breach alarm, battery percentage, ATTITUDE and VFR_HUD at the
requested rate, HEARTBEAT at 1 Hz of simulated time, every NAMED_VALUE_FLOAT name graphable.
"""

import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mission_sim.mavlink.telemetry import COPTER_MODES, NVF_NAMES, stream

pytest.importorskip("MAVProxy")
MAVPROXY = shutil.which("mavproxy.py")
RECEIVER = Path(__file__).with_name("_mavlink_receiver.py")
RATE_HZ, SPEED, SIM_S, SYSID = 5.0, 2.0, 10.0, 7


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _mission_series():
    """1 s of transit to a pad, 8 s hover-charging over it, 1 s of transit away (10 s)."""
    t = np.arange(0.0, SIM_S + 1e-9, 0.05)
    over = (t >= 1.0) & (t < 9.0)
    x = np.where(t < 1.0, -5.0 + 5.0 * t, np.where(over, 0.0, 5.0 * (t - 9.0)))
    i_batt = np.where(over, 1.0, -8.0)
    return pd.DataFrame({"t_s": t, "x_m": x, "y_m": 0.0 * t, "z_m": np.where(over, 0.1, 3.0),
                         "lm_h": np.where(over, 6.0e-6, 0.1e-6), "i2_amp_a": np.where(over, 11.2, 0.0),
                         "d_short": np.where(over, 0.2, 0.0), "battery_v": 31.5 + 0 * t, "battery_current_a": i_batt,
                         "soc": 0.62 + np.cumsum(i_batt * 0.05) / 4680.0, "i1_amp_a": np.where(over, 20.0, 0.0),
                         "rect_current_a": np.where(over, 1.2, 0.0), "charge_cmd_a": np.where(over, 1.3, 0.0),
                         "tx_on": over, "propulsion_w": np.where(over, 99.0, 130.0),
                         "phase": np.where(over, "charge", "transit")})


def _run_mavproxy(tmp_path, ts):
    """MAVProxy between the stream and the recording process; (MAVProxy's console, relayed messages)."""
    p_in, p_out = _free_port(), _free_port()
    env = {**os.environ, "HOME": str(tmp_path), "PYTHONPATH": ""}
    rx = subprocess.Popen([sys.executable, str(RECEIVER), str(p_out), "20"], stdout=subprocess.PIPE, text=True,
                          env=env)
    gcs = subprocess.Popen([MAVPROXY, f"--master=udpin:127.0.0.1:{p_in}", f"--out=udpout:127.0.0.1:{p_out}",
                            "--non-interactive", "--no-state"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True, cwd=tmp_path, env=env)
    lines = []
    try:
        assert rx.stdout.readline().strip() == "READY"
        for _ in range(200):                                   # bounded: MAVProxy's start-up lines
            lines.append(gcs.stdout.readline())
            if "Waiting for heartbeat" in lines[-1] or gcs.poll() is not None:
                break
        assert "Waiting for heartbeat" in lines[-1], lines
        st = stream(ts, connect=f"udpout:127.0.0.1:{p_in}", rate_hz=RATE_HZ, speed=SPEED, sysid=SYSID)
        time.sleep(1.0)
        gcs.terminate()
        lines += gcs.communicate(timeout=20)[0].splitlines()
        out, _ = rx.communicate(timeout=20)
    finally:
        for proc in (gcs, rx):
            if proc.poll() is None:
                proc.kill()
    by = {}
    for m in json.loads(out.strip().splitlines()[-1]):
        by.setdefault(m["msg"], []).append(m)
    return st, "\n".join(lines), by


@pytest.mark.skipif(MAVPROXY is None, reason="mavproxy.py not on PATH")
def test_mavproxy_sees_one_charging_arducopter(tmp_path):
    ts = _mission_series()
    st, console, by = _run_mavproxy(tmp_path, ts)
    # MAVProxy's own view: one vehicle, armed, the modes it flies, no false alarm
    assert re.findall(r"Detected vehicle (\d+):(\d+)", console) == [(str(SYSID), "1")], console
    assert "ARMED" in console and "Mode AUTO" in console and "Mode LOITER" in console, console
    assert "STABILIZE" not in console and "fence breach" not in console.lower(), console
    # the stream as MAVProxy relays it
    hb = [m for m in by["HEARTBEAT"] if m["type"] != 6]           # 6 = GCS (MAVProxy's own, if relayed)
    # the stream ends as a flight does: LAND, then disarmed; MAVProxy says so before the link goes quiet
    hb, land = hb[:-2], hb[-2:]
    assert [m["custom_mode"] for m in land] == [COPTER_MODES["LAND"]] * 2 and not land[-1]["base_mode"] & 128
    assert re.search(r"LAND> DISARMED", console), console          # the LAND prompt, then the disarm
    assert {m["sys"] for m in hb} == {SYSID} and all(m["autopilot"] == 3 and m["type"] == 2 for m in hb)
    modes = [m["custom_mode"] for m in hb]
    assert modes[0] == COPTER_MODES["AUTO"] and COPTER_MODES["LOITER"] in modes
    assert len(hb) == int(SIM_S) + 1                               # 1 Hz of simulated time: 0..10 s
    hb_wall = np.diff([m["t"] for m in hb])
    assert abs(np.median(hb_wall) - 1.0 / SPEED) < 0.1             # = 1 s of simulation at speed 2
    for name in ("ATTITUDE", "VFR_HUD", "GLOBAL_POSITION_INT", "BATTERY_STATUS"):
        assert len(by[name]) == st.ticks == int(SIM_S * RATE_HZ) + 1, name
    assert np.all(np.diff([m["time_boot_ms"] for m in by["ATTITUDE"]]) == int(1000 / RATE_HZ))
    arrival = np.array([m["t"] for m in by["ATTITUDE"]])
    wall_rate = (len(arrival) - 1) / (arrival[-1] - arrival[0])
    assert 0.8 * RATE_HZ * SPEED < wall_rate <= 1.1 * RATE_HZ * SPEED, wall_rate
    # battery percentage, the series' state of charge
    pct = [m["battery_remaining"] for m in by["SYS_STATUS"]]
    assert pct[0] == round(100 * ts["soc"].iloc[0]) == 62 and all(0 <= p <= 100 for p in pct)
    assert [m["battery_remaining"] for m in by["BATTERY_STATUS"]] == pct
    names = {m["name"] for m in by["NAMED_VALUE_FLOAT"]}
    assert names == set(NVF_NAMES) and all(re.fullmatch(r"[0-9A-Z_]{1,10}", n) for n in names)
    print(f"MAVProxy relayed ATTITUDE at {wall_rate:.2f} Hz wall (requested {RATE_HZ:g} Hz x speed {SPEED:g}), "
          f"{len(hb)} heartbeats {np.median(hb_wall):.3f} s apart (wall)")
