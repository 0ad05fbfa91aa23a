"""The command line ends its process as soon as the command is done (``mission_sim.cli._exit_now``: no
teardown of every module), with everything it printed delivered and its exit status kept; ``main(argv)``
called from Python returns as before."""

import json
import os
import subprocess
import sys

from mission_sim.cli import main


def _cli(*args):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run([sys.executable, "-m", "mission_sim.cli", *args], capture_output=True, text=True, env=env,
                          timeout=600)


def test_command_line_output_complete_and_status_kept():
    out = _cli("compare", "--episodes", "2", "--policies", "step,ramp", "--scenarios", "nominal", "--no-plot",
               "--no-frontier", "--format", "json")
    assert out.returncode == 0, out.stderr[-2000:]
    rows = json.loads(out.stdout)["rows"]   # the whole document arrived (a lost buffer would cut it)
    assert [r["policy"] for r in rows] == ["step", "ramp"]
    bad = _cli("compare", "--episodes", "0", "--no-plot")
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == ["dronewpt compare: error: --episodes 0 is invalid; valid range: 1..100000"]


def test_main_with_argv_returns():
    assert main(["compare", "--episodes", "0", "--no-plot"]) == 2   # still running: the call returned
