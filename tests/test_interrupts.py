"""Signals, full disks, output locks and progress (issue 25): SIGTERM ends every command like Ctrl-C
(one line naming the signal, exit 128 + signal number: 130 SIGINT, 143 SIGTERM), a failed or
interrupted write leaves no temporary file and names the file, one mission per ``--out`` at a
time, no lock file after a run, progress bars only on a terminal."""

from __future__ import annotations

import errno
import fcntl
import os
import pty
import resource
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from mission_sim.cli import main
from mission_sim.cli.common import show_progress
from mission_sim.cli.mission import MISSION_LOCK
from mission_sim.files import OutputError, atomic_output, folder_lock
from mission_sim.signals import Interrupted, exit_status, interrupts_deferred, interrupts_raised

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
#: a mission long enough to be running when signalled: 100 Hz trajectory samples (~0.4 M rows, ~15 MB CSV)
LONG = ["--set", "sim.traj_dt_s=0.01", "--set", "sim.coarse_policy_period_s=0.01", "--set", "sim.flight_dt_s=0.01"]


def _env():
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(TESTS), os.environ.get("PYTHONPATH", "")])}


def _cli(*args):
    return [sys.executable, "-m", "mission_sim.cli", *args]


def _hidden(folder: Path) -> list[str]:
    """Temporary files and locks (every name starting with a dot), anywhere under ``folder``."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob(".*"))


# ----------------------------------------------------------------------------- signals
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_is_one_line_with_the_signal_and_its_exit_status(monkeypatch, capsys, signum):
    import mission_sim.cli.mission as cli_mission

    def killed(args):
        raise Interrupted(signum)
    monkeypatch.setattr(cli_mission, "_cmd_mission", killed)  # main builds its parser afresh: picks this up
    rc = main(["mission"])
    err = capsys.readouterr().err
    assert rc == 128 + signum == (130 if signum == signal.SIGINT else 143)
    assert err == f"dronewpt mission: interrupted ({signal.Signals(signum).name})\n"


def test_plain_keyboard_interrupt_is_sigint():
    assert exit_status(KeyboardInterrupt()) == 130 and exit_status(Interrupted(signal.SIGTERM)) == 143


def test_sigterm_raises_in_the_main_thread_and_the_handlers_are_restored():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Interrupted) as info, interrupts_raised():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(1)  # the handler runs at the next bytecode
    assert info.value.signum == signal.SIGTERM and signal.getsignal(signal.SIGTERM) is before


def test_deferred_signal_is_raised_after_the_section_not_inside_it():
    done = []
    with pytest.raises(Interrupted) as info, interrupts_deferred():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.2)
        done.append(True)  # reached: the section was not cut
    assert done == [True] and info.value.signum == signal.SIGTERM


def _run_until(cmd, out: Path, trigger: str, sig=signal.SIGTERM, timeout_s=300):
    """Start ``cmd``, wait until a file matching ``trigger`` exists in ``out``, send ``sig``."""
    proc = subprocess.Popen(cmd, cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + timeout_s
        while proc.poll() is None and time.monotonic() < deadline and not list(out.glob(trigger)):
            time.sleep(0.002)
        assert proc.poll() is None, "finished before it could be signalled: " + proc.stderr.read().decode()
        proc.send_signal(sig)
        rc = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    return rc, proc.stdout.read().decode(), proc.stderr.read().decode()


@pytest.mark.parametrize("trigger", [MISSION_LOCK, ".timeseries.tmp*.csv"], ids=["simulating", "writing-csv"])
def test_sigterm_to_a_running_mission_is_one_line_143_and_leaves_no_temporary_file(tmp_path, trigger):
    """SIGTERM while the mission simulates (its lock exists) and while it writes the 15 MB CSV (the
    temporary file exists): exit 143, one line, no temporary file, no lock, no summary.json (the set
    is incomplete)."""
    out = tmp_path / "m"
    rc, stdout, err = _run_until(_cli("mission", "--out", str(out), "--no-plot", "--csv", *LONG), out, trigger)
    assert rc == 143 and err == "dronewpt mission: interrupted (SIGTERM)\n", err
    assert stdout == "" and _hidden(out) == [] and not (out / "summary.json").exists()
    assert not (out / "timeseries.csv").exists()  # never renamed into place half written


# ----------------------------------------------------------------------------- full disk
def _fsize_limit(nbytes):
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, nbytes))


def test_file_size_limit_names_the_file_and_leaves_no_temporary_file(tmp_path):
    """``ulimit -f`` (EFBIG) on the default mission's outputs: one line naming the file, exit 4,
    nothing partial, no lock."""
    out = tmp_path / "m"
    proc = subprocess.run(_cli("mission", "--out", str(out), "--no-plot"), cwd=ROOT, env=_env(), capture_output=True,
                          text=True, timeout=300, preexec_fn=_fsize_limit(50_000))
    lines = proc.stderr.splitlines()
    assert proc.returncode == 4 and len(lines) == 1, proc.stderr
    assert f"cannot write {str(out / 'timeseries.parquet')!r}: file too large" in lines[0]
    assert sorted(p.name for p in out.iterdir()) == []  # no temporary file, no lock, no summary


def test_sweep_under_a_file_size_limit_names_the_file_and_leaves_no_temporary_file(tmp_path):
    """Case 18 of issue 25, ``sweep`` under ``ulimit -f``: was "[Errno 27] File too large" naming no file
    and a ``.compact-*.parquet.*.tmp`` left; now one line naming the Parquet file, exit 4, no
    temporary file, no lock."""
    study = tmp_path / "s.toml"
    study.write_text('[study]\nrunner = "sweep_toy:factory"\n[grid]\n"mission.hover_time_s" = '
                     f"{[float(h) for h in range(1, 201)]}\n")
    out = tmp_path / "o"
    proc = subprocess.run(_cli("sweep", str(study), "--out", str(out), "--workers", "0", "--no-plot"), cwd=ROOT,
                          env=_env(), capture_output=True, text=True, timeout=300, preexec_fn=_fsize_limit(8192))
    lines = proc.stderr.splitlines()
    assert proc.returncode == 4 and len(lines) == 1, proc.stderr
    assert f"dronewpt sweep: error: cannot write {str(out / 'cases')!r}"[:-1] in lines[0] and ".parquet'" in lines[0]
    assert "file too large" in lines[0] and _hidden(out) == []


def test_tlog_writer_names_its_file_on_a_full_disk(tmp_path):
    from mission_sim.mavlink.telemetry import TlogWriter

    class FullDisk:
        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self):
            pass
    w = TlogWriter(tmp_path / "t.tlog")
    w._fh.close()
    w._fh = FullDisk()
    with pytest.raises(OutputError, match="no space left on the device") as info:
        w.write(b"frame", 0.0)
    assert info.value.path == tmp_path / "t.tlog"


def test_full_disk_in_a_sweep_names_the_file_and_leaves_no_temporary_file(tmp_path, monkeypatch):
    """ENOSPC in the middle of writing a part of the sweep store: OutputError naming the part under
    ``cases/``, its temporary file removed, no ``.sweep.lock``, the parts written before intact."""
    from sweep_toy import ToyRunner

    from mission_sim.studies.study import case_space, load_study
    from mission_sim.studies.sweep import run_sweep

    study = tmp_path / "s.toml"
    study.write_text('[study]\nrunner = "sweep_toy:factory"\n[grid]\n"mission.hover_time_s" = [1.0, 2.0, 3.0, 4.0]\n')
    real = pq.write_table
    calls = []

    def disk_full(table, where, *a, **k):
        calls.append(where)
        if len(calls) == 2:  # the second part: half written, then the disk is full
            Path(where).write_bytes(b"PAR1 half a file")
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(table, where, *a, **k)
    monkeypatch.setattr(pq, "write_table", disk_full)
    out = tmp_path / "o"
    with pytest.raises(OutputError) as info:
        run_sweep(case_space(load_study(study)), ToyRunner(), out, progress=False, part_rows=2)
    assert info.value.path.parent == out / "cases" and info.value.path.name.startswith("part-")
    assert "no space left on the device" in str(info.value) and str(info.value.path) in str(info.value)
    assert _hidden(out) == []
    parts = list((out / "cases").glob("part-*.parquet"))
    assert len(parts) == 1 and pq.read_table(parts[0]).num_rows == 2


def test_atomic_output_keeps_other_errors_as_they_are(tmp_path):
    with pytest.raises(ValueError, match="not a storage error"), atomic_output(tmp_path / "x.csv") as tmp:
        tmp.write_text("half")
        raise ValueError("not a storage error")
    with pytest.raises(PermissionError), atomic_output(tmp_path / "y.csv") as tmp:
        tmp.write_text("half")
        raise PermissionError(errno.EACCES, "denied")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- locks
def test_second_mission_on_one_out_is_refused_before_simulating(tmp_path, capsys):
    out = tmp_path / "m"
    with folder_lock(out, MISSION_LOCK, "busy"):  # as a first mission running there holds it
        rc = main(["mission", "--out", str(out), "--no-plot", "--no-progress"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and f"--out {str(out)!r}: another mission is writing there" in err[0], err
    assert list(out.iterdir()) == []  # nothing simulated, nothing written, the lock file gone with its holder


def test_a_finished_mission_and_a_finished_sweep_leave_no_lock_file(tmp_path, capsys):
    from sweep_toy import ToyRunner

    from mission_sim.studies.study import case_space, load_study
    from mission_sim.studies.sweep import run_sweep

    assert main(["mission", "--out", str(tmp_path / "m"), "--no-plot", "--no-progress", "--format", "json"]) == 0
    assert (tmp_path / "m" / "summary.json").is_file() and _hidden(tmp_path / "m") == []
    study = tmp_path / "s.toml"
    study.write_text('[study]\nrunner = "sweep_toy:factory"\n[grid]\n"mission.hover_time_s" = [1.0, 2.0, 3.0]\n')
    res = run_sweep(case_space(load_study(study)), ToyRunner(), tmp_path / "o", progress=False)
    assert res.n_ok == 3 and _hidden(tmp_path / "o") == []


def test_sweep_lock_still_refuses_a_second_writer(tmp_path):
    from mission_sim.studies.store import CaseStore

    with CaseStore(tmp_path).lock(), pytest.raises(ValueError, match="another sweep is writing"):
        with CaseStore(tmp_path).lock():
            pass
    assert not (tmp_path / ".sweep.lock").exists()
    with CaseStore(tmp_path).lock():  # free again
        assert (tmp_path / ".sweep.lock").exists()


def test_lock_taken_on_a_file_its_holder_removed_is_retaken_on_the_new_file(tmp_path):
    """A process that opened the lock file just before its holder removed it must not believe it
    holds the lock (a third process could create a new file and lock that one)."""
    import fcntl
    path = tmp_path / MISSION_LOCK
    stale = open(path, "a+")  # opened while the first holder still had it
    path.unlink()  # the holder finished: file removed
    fcntl.flock(stale, fcntl.LOCK_EX | fcntl.LOCK_NB)  # the stale inode is free
    with folder_lock(tmp_path, MISSION_LOCK, "busy"):
        assert path.exists() and os.stat(path).st_ino != os.fstat(stale.fileno()).st_ino
    stale.close()


# ----------------------------------------------------------------------------- progress
class _Args:
    def __init__(self, **kw):
        self.__dict__.update(kw)


@pytest.mark.parametrize("tty, kw, shown", [
    (True, {}, True), (False, {}, False), (True, {"no_progress": True}, False),
    (True, {"format": "json"}, False), (False, {"progress": True}, True)])
def test_progress_only_on_a_terminal(monkeypatch, tty, kw, shown):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: tty, raising=False)
    assert show_progress(_Args(**kw)) is shown


def _stderr_on_a_pty(cmd) -> tuple[int, str]:
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a 0x0 terminal: tqdm draws nothing
    proc = subprocess.Popen(cmd, cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=slave,
                            stdin=subprocess.DEVNULL)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # EIO: the child closed its end
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    return proc.wait(timeout=300), b"".join(chunks).decode(errors="replace")


def test_mission_progress_is_drawn_on_a_terminal_and_not_when_piped(tmp_path):
    rc, tty_err = _stderr_on_a_pty(_cli("mission", "--out", str(tmp_path / "a"), "--no-plot"))
    # the series is streamed to its files while the mission runs: one bar covers simulating and writing
    assert rc == 0 and "mission:" in tty_err and "sim s" in tty_err, tty_err
    piped = subprocess.run(_cli("mission", "--out", str(tmp_path / "b"), "--no-plot"), cwd=ROOT, env=_env(),
                           capture_output=True, text=True, timeout=300)
    assert piped.returncode == 0 and piped.stderr == ""
    rc, off = _stderr_on_a_pty(_cli("mission", "--out", str(tmp_path / "c"), "--no-plot", "--no-progress"))
    assert rc == 0 and off.strip() == ""


def test_the_numba_compilation_is_announced_once():
    """In a fresh interpreter, as in ``dronewpt``: the notice is armed before numba is imported (a
    ``find_spec("numba")`` availability check first, as the mission's fast path does), then two
    kernels compile: one notice. A kernel loaded from the cache would not fire numba's event."""
    code = ("import importlib.util, sys\n"
            "from mission_sim.cli.notices import compile_notices\n"
            "with compile_notices(True):\n"
            "    assert importlib.util.find_spec('numba') is not None and 'numba' not in sys.modules\n"
            "    import numba\n"
            "    f = numba.njit(cache=False)(lambda x: 2 * x)\n"
            "    g = numba.njit(cache=False)(lambda x: 3 * x)\n"
            "    assert f(2) == 4 and g(2.0) == 6.0\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=_env(), capture_output=True, text=True,
                          timeout=300)
    from wpt_receiver.notices import NOTICE
    assert proc.returncode == 0 and proc.stderr.count(NOTICE) == 1, proc.stderr


def test_train_lists_only_the_folders_it_wrote(tmp_path):
    from policies.train import _written_dirs
    (tmp_path / "eval").mkdir()
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "a_100_steps.zip").write_bytes(b"z")
    got = _written_dirs({"eval_dir": tmp_path / "eval", "checkpoints": tmp_path / "checkpoints"})
    assert got == {"checkpoints": tmp_path / "checkpoints"} and not (tmp_path / "eval").exists()


def test_after_warmup_every_kernel_loads_from_the_cache():
    """``dronewpt warmup`` compiles (or loads) every stage; run again in a new process, no stage compiles
    anything: numba fires its compile event only on a cache miss, so every kernel the commands use was
    written to the cache by the first run."""
    import json
    runs = [subprocess.run(_cli("warmup", "--format", "json"), cwd=ROOT, env=_env(), capture_output=True, text=True,
                           timeout=900) for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), runs[-1].stderr
    first, second = (json.loads(r.stdout) for r in runs)
    assert [s["stage"] for s in first["stages"]] == [s["stage"] for s in second["stages"]] and len(first["stages"]) == 5
    assert [s["kernels_compiled"] for s in second["stages"]] == [0, 0, 0, 0, 0]
    assert second["stages"][1]["result"].startswith("skipped")   # the AOT build: DRONEWPT_AOT=0 in the tests


def test_a_sigterm_swallowed_by_a_callback_is_raised_before_a_file_is_renamed_into_place(tmp_path):
    """A signal that lands while a weakref callback runs (CI hit it in import's module-lock callback: the
    mission then finished with status 0) cannot raise there; it is kept and raised before the next file
    is renamed into place, so the run still ends as interrupted and writes nothing. Without the hook the
    callback's Interrupted is only printed as "Exception ignored" and the file is written."""
    import weakref

    class _Obj:
        pass

    out = tmp_path / "summary.json"
    with pytest.raises(Interrupted) as info, interrupts_raised():
        with atomic_output(out) as tmp:
            obj = _Obj()
            ref = weakref.ref(obj, lambda r: os.kill(os.getpid(), signal.SIGTERM) or time.sleep(0.01))  # noqa: F841
            del obj   # the callback takes the signal: its Interrupted is unraisable
            Path(tmp).write_text("{}")
    assert info.value.signum == signal.SIGTERM
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("signum, rc", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_while_the_parser_is_built_is_one_line(monkeypatch, capsys, signum, rc):
    """A Ctrl-C / SIGTERM in the ~10-20 ms while argparse's parser is built or parses (before any command
    runs) gives the one line and 130 / 143, not an ``Interrupted`` traceback and exit 1 (found by timing a
    ``kill -INT`` 0.33 s after the start)."""
    import mission_sim.cli as cli
    from mission_sim.signals import Interrupted

    def interrupted():
        raise Interrupted(signum)
    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["mission"]) == rc
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dronewpt: interrupted ({signal.Signals(signum).name})"]
