"""How the two recordings in this folder were made (issue 24): one run of the project's own
``dronewpt telemetry --speed 3`` stream, recorded twice.

usage: PYTHONPATH=. python tests/data/telemetry/record_mavproxy.py OUT_DIR

* ``telemetry_1x.tlog``: the .tlog that ``dronewpt telemetry --tlog`` writes itself; its receive
  timestamps are the simulation clock, so the vehicle clock (time_boot_ms) and the log clock run
  at the same rate (1x).
* ``mavproxy_speed3.tlog``: what MAVProxy 1.8.75 (``mavproxy.py --master=udpin:... --logfile=...
  --non-interactive``, headless, as tests/test_mavproxy_client.py drives it) recorded of the same
  stream over loopback UDP. MAVProxy stamps frames with the wall clock on arrival, while the
  vehicle's time_boot_ms runs 3x faster (speed 3); the log also holds MAVProxy's own GCS frames.

The mission: the embedded default with ``pads.0.hover_time_s=5`` (5 s of charging over the first pad),
the first 40 s of it (``--duration 40``: take-off, transit, charging, transit; then the stream's landing
and disarm), telemetry at
5 Hz. Written by this project (no third-party data); same licence as the repository.
"""

import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "HOME": str(out / ".home"), "PYTHONPATH": ""}
    raw = out / "mavproxy_speed3.tlog"
    gcs = subprocess.Popen([shutil.which("mavproxy.py"), f"--master=udpin:127.0.0.1:{port}", f"--logfile={raw}",
                            "--non-interactive"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        time.sleep(6.0)                                            # MAVProxy's start-up
        subprocess.run([sys.executable, "-m", "mission_sim.cli", "telemetry", "--speed", "3", "--rate", "5",
                        "--set", "pads.0.hover_time_s=5", "--duration", "40", "--connect", f"udpout:127.0.0.1:{port}",
                        "--tlog", str(out / "telemetry_1x.tlog"), "--no-progress"], check=True, timeout=300)
        time.sleep(2.0)
    finally:
        gcs.terminate()
        console = gcs.communicate(timeout=20)[0]
    (out / "mavproxy_console.txt").write_text(console)
    Path(str(raw) + ".raw").unlink(missing_ok=True)
    shutil.rmtree(out / ".home", ignore_errors=True)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
