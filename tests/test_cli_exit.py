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
    assert bad.stderr.strip().splitlines() == ["dronewpt compare: error: --episodes 0 is invalid; valid range: integer 1..100000"]


def test_main_with_argv_returns():
    assert main(["compare", "--episodes", "0", "--no-plot"]) == 2   # still running: the call returned


def _run(code, **kw):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600, **kw)


def test_console_main_ends_the_process_but_main_from_code_returns():
    """The console entry point ends at once after the command (code after it never runs, atexit handlers did);
    main() called with no arguments from code returns its status, so a caller keeps its process."""
    code = ("import atexit, sys\natexit.register(lambda: print('atexit ran', flush=True))\n"
            "sys.argv = ['dronewpt', 'compare', '--episodes', '0', '--no-plot']\n"
            "import mission_sim.cli as cli\n"
            "rc = cli.main()\nprint('main returned', rc, flush=True)\n"
            "cli.console_main()\nprint('not reached', flush=True)\n")
    r = _run(code)
    assert r.returncode == 2, r.stderr
    assert r.stdout.splitlines() == ["main returned 2", "atexit ran"]


def test_closed_stdout_keeps_the_status_and_no_traceback():
    """With stdout closed (``>&-``: Python's sys.stdout is None) the command's status is kept, no traceback."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    r = subprocess.run([sys.executable, "-c", "import sys; sys.argv = ['dronewpt', 'compare', '--episodes', '0', "
                        "'--no-plot']\nimport mission_sim.cli as cli\nassert sys.stdout is None\ncli.console_main()"],
                       stderr=subprocess.PIPE, text=True, env=env, timeout=600, preexec_fn=lambda: os.close(1))
    assert r.returncode == 2
    assert "Traceback" not in r.stderr


def test_profiled_or_opted_out_runs_exit_normally(tmp_path):
    """Under cProfile (which writes its file at the normal exit) or with DRONEWPT_NO_FAST_EXIT the process
    exits as Python does: the profile is written, code after the command runs."""
    prof = tmp_path / "p.out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    r = subprocess.run([sys.executable, "-m", "cProfile", "-o", str(prof), "-m", "mission_sim.cli", "compare",
                        "--episodes", "0", "--no-plot"], capture_output=True, text=True, env=env, timeout=600)
    assert "--episodes 0 is invalid" in r.stderr and prof.stat().st_size > 0   # (cProfile's main swallows the status)
    code = ("import sys; sys.argv = ['dronewpt', 'compare', '--episodes', '0', '--no-plot']\n"
            "import mission_sim.cli as cli\nrc = cli.console_main()\nprint('after', rc, flush=True)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                       env={**env, "DRONEWPT_NO_FAST_EXIT": "1"})
    assert r.stdout.strip() == "after 2"
