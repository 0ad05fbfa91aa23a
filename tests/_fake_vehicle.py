"""A stand-in live vehicle for the --follow test: plain pymavlink, no mission_sim imports.

usage: python _fake_vehicle.py PORT SECONDS [DELAY]
After DELAY seconds (default 0) sends HEARTBEAT (1 Hz) and GLOBAL_POSITION_INT (10 Hz) to udpout:127.0.0.1:PORT for SECONDS:
standing on the home point for 1.5 s, then flying east at 2 m/s, 3 m up. Prints "ready" once
its connection is open (a loaded machine can take seconds to import pymavlink) and, at the end,
the number of positions sent.
"""

import math
import os
import sys
import time

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

HOME = (-35.363261, 149.165230, 584.0)
_PHI = math.radians(HOME[0])
M_PER_DEG_LON = 111412.84 * math.cos(_PHI) - 93.5 * math.cos(3 * _PHI)  # standard WGS84 series


def main():
    port, seconds = int(sys.argv[1]), float(sys.argv[2])
    time.sleep(float(sys.argv[3]) if len(sys.argv) > 3 else 0.0)  # let the follower bind its port
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
    print("ready", flush=True)
    t0 = time.monotonic()
    sent = 0
    for k in range(int(seconds * 10) + 1):  # bounded in count, paced at 10 Hz
        while time.monotonic() < t0 + k / 10:
            time.sleep(0.002)
        t = k / 10
        east = max(t - 1.5, 0.0) * 2.0
        up = 0.0 if t < 1.5 else 3.0
        if k % 10 == 0:
            conn.mav.heartbeat_send(2, 3, 128, 0, 4)
        conn.mav.global_position_int_send(int(t * 1000), int(HOME[0] * 1e7),
                                          int((HOME[1] + east / M_PER_DEG_LON) * 1e7),
                                          int((HOME[2] + up) * 1000), int(up * 1000), 0, 200 if t >= 1.5 else 0, 0, 0)
        sent += 1
    print(sent, flush=True)


if __name__ == "__main__":
    main()
