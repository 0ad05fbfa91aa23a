"""The mission figures drawn by a forked process that imports matplotlib while the mission runs.

``dronewpt mission`` spends most of its time in two start-up costs that do not depend on each other:
numba (import, its registries, the compiled loop loaded from the cache) before the simulation and
matplotlib (import) before the figures. On a machine with a free core :class:`FigureWorker` overlaps
them: it forks (POSIX ``fork``: nothing is pickled at start, the config and the coupling model are
inherited) before the run, the child imports :mod:`.mission` (matplotlib without its artists' docstrings,
:func:`matplotlib_without_docstrings`) and waits; after the run the parent sends
the summary and the figures' bounded copy of the series, the child draws and writes the PNG files
(atomically, :func:`.common.save_figure`) and sends their paths back. The figures are the same as drawn
in process (same module, same data). When the load is low and the data is not there yet
it warms matplotlib up while it waits (:func:`.mission.warm_up`); when the data arrives and a core is free
(:func:`core_free`) it forks a helper (:class:`_Helper`, matplotlib and the data inherited) that draws
:data:`HELPER_FIGURES` while the worker draws the others.

Nothing outlives the command: the child is a daemon process that exits after one set of figures (its
helper reaped first; terminated if the worker is), when
the parent closes the pipe (``EOFError``, also when the parent dies), or on SIGTERM/SIGINT (its
temporary files removed, :func:`mission_sim.files.atomic_output`); :meth:`FigureWorker.close` (always
called by the command) terminates and reaps it. An error while drawing comes back to the parent and
is raised there. This module imports neither matplotlib nor multiprocessing until a worker starts.
"""

from __future__ import annotations

import os
import signal
import sys

from ..signals import blocked_across_fork, unblock_in_child
from . import PATH_SAMPLES

__all__ = ["FigureWorker", "FigureWorkerLost", "fork_available", "for_figures", "core_free", "PATH_SAMPLES", "CLOSE_WAIT_S",
           "HELPER_FIGURES", "matplotlib_without_docstrings"]

#: seconds :meth:`FigureWorker.close` waits for the child to exit by itself before terminating it
CLOSE_WAIT_S = 1.0


def fork_available() -> bool:
    """True where a process can be forked (POSIX; not on Windows or WASI)."""
    return hasattr(os, "fork") and sys.platform != "emscripten"


def for_figures(result):
    """What the figures need of a :class:`~mission_sim.world.results.MissionResult`: its summary, config and
    (thinned) time series, and its trajectory's samples when there are at most :data:`PATH_SAMPLES` (else
    None: the path is drawn from the time series); small to send to the worker."""
    from ..world.results import MissionResult
    tr = result.trajectory
    if tr is not None and len(tr) <= PATH_SAMPLES:
        tr = tr.materialise() if hasattr(tr, "materialise") else tr
    else:
        tr = None
    return MissionResult(result.timeseries, result.summary, config=result.config, trajectory=tr)


class FigureWorkerLost(RuntimeError):
    """The figure process ended or answered unreadably without drawing: the caller draws in-process."""


class FigureWorker:
    """A forked process that draws :func:`.mission.plot_mission` once (see the module notes)."""

    def __init__(self):
        import multiprocessing as mp
        ctx = mp.get_context("fork")
        sys.stdout.flush()
        sys.stderr.flush()   # nothing buffered is copied into the child (it flushes at its exit)
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, args=(child, self._conn), daemon=True, name="dronewpt-figures")
        # the child takes SIGTERM / SIGINT only inside _serve's try, never on its way to it with the parent's
        # handlers and stack (a bad input terminates the worker the instant after the fork)
        with blocked_across_fork():
            self._proc.start()
        child.close()

    def draw(self, result, out_dir) -> list[str]:
        """The figures of ``result`` (summary, config, the thinned ``timeseries``, the trajectory or None
        for a long mission) written to ``out_dir`` by the child; their paths. Raises what the child raised."""
        try:
            self._conn.send((result, str(out_dir)))
            ok, value = self._conn.recv()
        except (EOFError, BrokenPipeError, ConnectionResetError):
            raise FigureWorkerLost(f"the figure process ended without drawing (exit code {self._proc.exitcode})") from None
        except Exception as exc:  # noqa: BLE001 - the child's reply did not unpickle here
            raise FigureWorkerLost(f"the figure process's reply could not be read ({exc!r})") from None
        if not ok:
            raise value
        return value

    def close(self, wait_s: float = CLOSE_WAIT_S) -> None:
        """Reap the child: it exits by itself after drawing, or at the EOF of the closed pipe once its
        import is done; after ``wait_s`` it is terminated (its temporary files removed; 0: at once, for a
        worker whose figures will not be asked for). Idempotent."""
        self._conn.close()
        self._proc.join(timeout=wait_s)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join()


def _interrupted(signum, frame):
    raise KeyboardInterrupt(f"signal {signum}")   # unwinds through atomic_output: no temporary file left


def _serve(conn, parent_end) -> None:
    """The child: import the figures, draw one set, send the paths (or the exception) back, exit. Quietly
    (no traceback) when the parent went away or it was interrupted: the parent reports what matters."""
    try:
        parent_end.close()   # EOF on recv once the parent's end is closed (also when the parent dies)
        signal.signal(signal.SIGTERM, _interrupted)
        unblock_in_child()   # blocked by the parent across the fork
        _draw_once(conn)
    except BaseException:  # noqa: BLE001, S110 - interrupted or the parent is gone: no one to tell
        pass
    finally:
        os._exit(0)


def _draw_once(conn) -> None:
    matplotlib_without_docstrings()
    from . import mission
    from .. import config  # noqa: F401 - what unpickling the result imports, before it arrives (forked early)
    if _load_low() and not conn.poll():   # while the parent simulates (not when the data waits already): ~0.03 s
        mission.warm_up()                  # off the first figure for ~0.1 s of CPU (measured)
    try:
        result, out = conn.recv()
    except EOFError:   # the parent ended before the run's end (an error, an interrupt)
        return
    helpers = HELPER_FIGURES if core_free() else ()
    conn.send_bytes(_reply_bytes(lambda: _draw_split(mission, result, out, conn, helpers)))


#: matplotlib releases on which :func:`matplotlib_without_docstrings` applies (its hooks are private: a later
#: release gets the usual import until its figures are checked, ``tests/test_figure_worker.py``)
CHECKED_MATPLOTLIB = ("3.11.",)


def matplotlib_without_docstrings() -> bool:
    """Make matplotlib's import skip what only its docstrings and ``inspect.signature`` use: every ``Artist``
    subclass builds, as the class is created, the docstring and signature of its ``set()`` from all of its
    setters' docstrings (``artist.kwdoc``, ``ArtistInspector``), and ``%(Line2D:kwdoc)s``-style substitutions
    call ``kwdoc`` too: about a quarter of ``import matplotlib.pyplot`` (measured: ~0.1 s of CPU on a quiet
    machine). Drawing uses neither (``Artist.set`` takes its keywords without the signature), so the figures
    are the same bytes. For a process that draws and exits (the figure worker, forked for it), never the
    command's own process; before matplotlib's artists are defined (a no-op if they are already: an earlier
    import in the same process). True when the hooks were found (matplotlib 3.11's ``artist.kwdoc`` and
    ``Artist._update_set_signature_and_docstring``), False on another release (:data:`CHECKED_MATPLOTLIB`) or if this
    matplotlib has none: nothing changed."""
    if "matplotlib.lines" in sys.modules:   # artists defined already (a test process that drew before)
        return False
    import matplotlib
    import matplotlib.artist as artist
    # private hooks: only on the releases whose figures were checked to the byte with and without them
    if not (str(getattr(matplotlib, "__version__", "")).startswith(CHECKED_MATPLOTLIB)
            and callable(getattr(artist, "kwdoc", None))
            and hasattr(artist.Artist, "_update_set_signature_and_docstring")):
        return False

    def flag_only(cls):   # what __init_subclass__ checks on a parent's set(): keep it, skip the rest
        cls.set._autogenerated_signature = True
    artist.kwdoc = lambda _artist: ""
    artist.Artist._update_set_signature_and_docstring = classmethod(flag_only)
    return True


def _reply_bytes(draw) -> bytes:
    """The pickled ``(True, draw())``, or ``(False, exception)`` for what it raised (an exception that does
    not pickle becomes a RuntimeError naming it): the answer of the worker and of its helper."""
    import pickle
    try:
        reply = (True, draw())
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises it
        reply = (False, exc)
    try:
        return pickle.dumps(reply)
    except Exception as exc:  # noqa: BLE001 - an exception that does not pickle (PicklingError included)
        return pickle.dumps((False, RuntimeError(f"drawing the figures failed: {reply[1]!r} ({exc})")))


#: the figures a helper forked by the worker draws while the worker draws the others (about half the
#: drawing time each: on two free cores the figures take about half as long)
HELPER_FIGURES = ("i2", "soc")


def _cpus() -> int:
    """The CPUs this process may run on (its affinity where the platform has one); may raise OSError."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _load_low() -> bool:
    """The 1-minute load average below the usable CPUs minus 0.5 (True where there is none): the warm-up's gate
    (it runs while the parent simulates, so the running count says nothing about whether the worker waits)."""
    try:
        cpus = _cpus()
        return os.getloadavg()[0] < cpus - 0.5
    except OSError:
        return True


def core_free() -> bool:
    """True when a core is free for the helper now: at most ``CPUs - 1`` runnable tasks (this process
    included) in each of three reads of ``/proc/loadavg``'s running count, 1 ms apart; where that file is
    missing, the 1-minute load average below the usable CPUs minus 0.5. On a busy machine the helper gains
    no time and costs ~0.2 s of CPU (its copy-on-write pages; measured at load ~7 on 2 cores: CPU 3.48
    against 3.28 s, wall the same within the spread). The running count, not the 1-minute average: on an
    otherwise idle machine the average still counts the last minute's runs of the command itself (1.2-2.0
    during back-to-back runs), which turned the helper off when both cores were free."""
    try:
        cpus = _cpus()
    except OSError:
        cpus = os.cpu_count() or 1
    try:
        import time
        for i in range(3):
            if i:
                time.sleep(0.001)
            with open("/proc/loadavg") as f:
                running = int(f.read().split()[3].split("/")[0])
            if running > cpus - 1:
                return False
        return True
    except (OSError, ValueError, IndexError):
        return _load_low()


def _draw_split(mission, result, out, conn, helper_figures=HELPER_FIGURES) -> list[str]:
    """All of ``mission.FIGURES``: ``helper_figures`` by a forked :class:`_Helper`, the rest here at the
    same time; a helper that dies is replaced by drawing its figures here. The paths, in ``FIGURES`` order."""
    theirs = tuple(n for n in mission.FIGURES if n in helper_figures)
    mine = tuple(n for n in mission.FIGURES if n not in theirs)
    if not theirs:   # no helper (no free core): all drawn here
        return mission.plot_mission(result, out, which=mine)
    helper = _Helper(mission, result, out, theirs, conn)
    try:
        files = dict(zip(mine, mission.plot_mission(result, out, which=mine)))
        got = helper.result()
        files.update(zip(theirs, got if got is not None else mission.plot_mission(result, out, which=theirs)))
    finally:
        helper.close()
    return [files[n] for n in mission.FIGURES]


class _Helper:
    """A process forked from the worker (matplotlib loaded, the data inherited) that draws ``names`` and
    sends the paths, or the exception, back through a pipe; it exits after that. SIGTERM (inherited
    handler) ends it like the worker, its temporary files removed."""

    def __init__(self, mission, result, out, names, conn):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:   # the helper
            try:
                os.close(r)
                conn.close()   # the parent's pipe stays the worker's alone
                data = _reply_bytes(lambda: mission.plot_mission(result, out, which=names))
                with os.fdopen(w, "wb") as f:
                    f.write(data)
            except BaseException:  # noqa: BLE001, S110 - interrupted or the worker is gone
                pass
            finally:
                os._exit(0)
        os.close(w)
        self._pid, self._r = pid, r

    def result(self):
        """The helper's paths (once it is done); None if it died or answered unreadably; raises what it raised."""
        import pickle
        with os.fdopen(self._r, "rb") as f:
            self._r = None
            data = f.read()   # up to the helper's exit (EOF)
        self._reap()
        try:
            ok, value = pickle.loads(data)
        except Exception:  # noqa: BLE001 - killed mid-way, or an unreadable answer: drawn by the caller
            return None
        if not ok:
            raise value
        return value

    def _reap(self) -> None:
        if self._pid is not None:
            os.waitpid(self._pid, 0)
            self._pid = None

    def close(self) -> None:
        """Terminate and reap the helper if it still runs (the worker was interrupted). Idempotent."""
        if self._r is not None:
            os.close(self._r)
            self._r = None
        if self._pid is not None:
            import signal
            try:
                os.kill(self._pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            self._reap()
