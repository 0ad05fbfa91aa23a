"""Separate receiving process for the loopback test: plain pymavlink, no mission_sim imports.

usage: python _mavlink_receiver.py PORT MAX_SECONDS [IDLE_SECONDS]
Binds udpin:127.0.0.1:PORT, prints READY, receives until MAX_SECONDS have passed or IDLE_SECONDS
(default 1) after the last message, then prints one JSON line: every message as {msg, t (arrival,
s), fields...}.
"""

import json
import os
import socket
import sys
import time

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

FIELDS = {
    "HEARTBEAT": ("type", "autopilot", "base_mode", "custom_mode", "system_status"),
    "SYS_STATUS": ("voltage_battery", "current_battery", "battery_remaining", "onboard_control_sensors_present",
                   "onboard_control_sensors_enabled", "onboard_control_sensors_health"),
    "ATTITUDE": ("time_boot_ms", "roll", "pitch", "yaw"),
    "VFR_HUD": ("groundspeed", "heading", "throttle", "alt", "climb"),
    "BATTERY_STATUS": ("voltages", "current_battery", "current_consumed", "energy_consumed",
                       "battery_remaining", "charge_state"),
    "GLOBAL_POSITION_INT": ("time_boot_ms", "lat", "lon", "alt", "relative_alt", "vx", "vy", "vz"),
    "GPS_RAW_INT": ("fix_type", "lat", "lon", "eph", "epv", "satellites_visible", "cog"),
    "EXTENDED_SYS_STATE": ("landed_state",),
    "NAMED_VALUE_FLOAT": ("time_boot_ms", "name", "value"),
}


def main():
    port, max_s = int(sys.argv[1]), float(sys.argv[2])
    idle_s = float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
    # a 4 MB receive buffer: on a loaded machine a fast sender (--speed 100) must not overflow the
    # default one while this process waits for the CPU (loopback UDP drops only on a full buffer)
    conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    print("READY", flush=True)
    t0 = time.monotonic()
    out, last = [], None
    for _ in range(100_000):  # bounded in count and in time
        now = time.monotonic()
        if now - t0 > max_s or (last is not None and now - last > idle_s):
            break
        msg = conn.recv_match(blocking=True, timeout=0.1)
        if msg is None:
            continue
        last = time.monotonic()
        typ = msg.get_type()
        rec = {"msg": typ, "t": last - t0, "version": 2 if msg.get_msgbuf()[:1] == b"\xfd" else 1,
               "sys": msg.get_srcSystem(), "comp": msg.get_srcComponent()}
        for f in FIELDS.get(typ, ()):
            v = getattr(msg, f)
            rec[f] = list(v) if isinstance(v, (list, tuple)) else v
        out.append(rec)
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
