"""policies.forked's child (compare's second core) ends inside its own code when it is terminated the
instant after the fork (:meth:`Forked.cancel`, or a Ctrl-C to the process group): SIGINT and SIGTERM are
blocked across the fork (mission_sim.signals.blocked_across_fork) and taken only inside ``_child``'s try."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from policies import forked

ROOT = Path(__file__).resolve().parents[1]

_RACE = r"""
import os, sys, time
from pathlib import Path
from mission_sim.signals import interrupts_raised
from policies.forked import Forked
marks = Path(sys.argv[2])
def job(i):
    time.sleep(1.0)
    (marks / str(i)).touch()          # reached only by a child whose cancel was lost
pid0, codes = os.getpid(), []
with interrupts_raised():             # the command's handlers: SIGTERM raises in the process that takes it
    for i in range(int(sys.argv[1])):
        try:
            f = Forked(job, i)
            f.cancel()                # terminate at once
        except BaseException:         # noqa: BLE001
            if os.getpid() != pid0:
                os._exit(3)           # a child that escaped with the parent's stack
            raise
        if os.getpid() != pid0:
            os._exit(3)
        codes.append(f.proc.exitcode)
print(sorted(set(codes)))
"""


@pytest.mark.skipif(not forked.available(), reason="no fork on this platform or a single CPU: Forked runs in-process")
def test_a_forked_child_cancelled_right_after_the_fork_ends_in_its_own_code(tmp_path):
    """Before the block, a SIGTERM that reached the child before Python's after-fork bookkeeping was
    cleared with it (lost): the cancelled child ran its whole job (here: touched its mark after 1 s)."""
    r = subprocess.run([sys.executable, "-c", _RACE, "20", str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                       timeout=600, env={**os.environ,
                                         "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])})
    assert r.returncode == 0, r.stderr[-2000:]
    codes = eval(r.stdout.strip().splitlines()[-1])   # noqa: S307 - our own printed list of ints
    assert codes == [0], codes            # every child ended through _child's os._exit(0): none escaped (3)
    assert sorted(p.name for p in tmp_path.iterdir()) == []   # and none ran its job after the cancel
