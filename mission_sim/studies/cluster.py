"""A Dask client for sweeps that starts and stops quietly and fast.

What Dask does by default and why this module changes it:

- Ctrl-C in a terminal sends SIGINT to the whole process group, worker processes included: each
  prints a ``KeyboardInterrupt`` traceback (30-50 lines). The worker processes are forked here by
  a multiprocessing *forkserver* (``distributed.worker.multiprocessing-method``) that is started
  with SIGINT *ignored*: the disposition survives its ``exec`` and CPython's forkserver restores
  the inherited disposition in every child it forks, so workers never see Ctrl-C; they end with
  their nanny when the driver closes the cluster or dies (they watch a pipe to it). Only the
  forkserver's start (a few ms) runs with SIGINT ignored in the driver: ignoring it for the whole
  cluster start lost a Ctrl-C, because a process-directed SIGINT goes to any thread that does not
  block it (OpenBLAS's native threads, say), which then discards it. During the rest of the start
  a Ctrl-C or a SIGTERM is recorded (:func:`mission_sim.signals.interrupts_deferred`) and raised
  once the cluster exists, which is then closed quickly: raised in the middle of Dask's start it
  left a half-built cluster whose exit hooks printed tracebacks (``Status.init`` assertion,
  forkserver ``SemLock`` FileNotFoundError).
- Closing a ``LocalCluster`` logs ``CommClosedError`` tracebacks from connections torn down in
  flight and waits for graceful worker shutdown (6-9 s). Here the loggers of ``distributed``,
  ``tornado`` and ``asyncio`` are raised to CRITICAL in the driver while the cluster lives
  (``silence_logs`` does the same in the workers), and an interrupted sweep closes the client and
  cluster with a short timeout.
- A local cluster's housekeeping is tuned for throughput (:data:`LOCAL_CLUSTER_CONFIG`, measured on
  the 2-core machine with cases that only sleep): Dask's defaults cost each worker ~6 % of a core
  (its statistical profiler samples the task thread every 10 ms; memory monitor every 100 ms) and
  the driver, which hosts the scheduler and the nannies, ~8 %; tuned: ~1.5 % per worker and ~3.5 %
  for the driver. The forkserver is started with one BLAS / OpenMP thread (Dask's own
  ``pre-spawn-environ``, which a forkserver would otherwise not pass on: numpy is preloaded there),
  so workers do not run two-thread BLAS pools that spin on the other worker's core.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading

from ..signals import interrupts_deferred

__all__ = ["dask_client", "quiet_logs", "CLOSE_TIMEOUT_S", "INTERRUPT_CLOSE_TIMEOUT_S", "LOCAL_CLUSTER_CONFIG"]

CLOSE_TIMEOUT_S = 10.0
INTERRUPT_CLOSE_TIMEOUT_S = 1.0
_NOISY = ("distributed", "tornado", "asyncio", "bokeh")
#: modules the workers' forkserver imports once (every worker is forked with them loaded); the last one puts back the
#: driver's PYTHONSAFEPATH / PYTHONPATH (:func:`_driver_path_environ`) before any worker is forked
FORKSERVER_PRELOAD = ("mission_sim.studies.sweep", "numba", "mission_sim.studies._forkserver_env")
#: Dask settings of the local cluster (scheduler, nannies and workers read them at their start)
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,  # stack sampling of the task thread every 10 ms
    "distributed.admin.tick.interval": "1s",  # event-loop health check (default every 20 ms)
    "distributed.worker.memory.monitor-interval": "500ms",  # nanny and worker memory polls (100 ms)
    "distributed.admin.system-monitor.interval": "2s",  # dashboard metrics (500 ms); no dashboard here
    "distributed.admin.system-monitor.gil.enabled": False,
}


@contextlib.contextmanager
def quiet_logs(level: int = logging.CRITICAL):
    """Raise the level of the Dask-related loggers (and their handlers) while inside."""
    saved = []
    for name in _NOISY:
        lg = logging.getLogger(name)
        saved.append((lg, lg.level, [(h, h.level) for h in lg.handlers]))
        lg.setLevel(level)
        for h in lg.handlers:
            h.setLevel(level)
    try:
        yield
    finally:
        for lg, lvl, handlers in saved:
            lg.setLevel(lvl)
            for h, hl in handlers:
                h.setLevel(hl)


def _start_forkserver() -> None:
    """Start the multiprocessing forkserver the Dask nannies fork workers from, with SIGINT ignored
    (inherited by every worker). Dask's preload list is set first (``get_mp_context``) and
    :data:`FORKSERVER_PRELOAD` added, so the server imports ``distributed``, numpy, pandas, pyarrow,
    numba and the sweep engine once instead of in every worker (measured: ~1 s of CPU per worker)."""
    import multiprocessing.forkserver
    from multiprocessing import resource_tracker

    from distributed.utils import get_mp_context

    ctx = get_mp_context()
    ctx.set_forkserver_preload(list(dict.fromkeys(multiprocessing.forkserver._forkserver._preload_modules
                                                  + list(FORKSERVER_PRELOAD))))
    resource_tracker.ensure_running()  # spawned by the forkserver's start otherwise: not in the shield
    # a Ctrl-C meanwhile is raised on leaving
    with _sigint_shielded(), _environ({**_pre_spawn_environ(), **_driver_path_environ()}):
        multiprocessing.forkserver.ensure_running()


def _driver_path_environ() -> dict[str, str]:
    """The forkserver imports :data:`FORKSERVER_PRELOAD` on the driver's ``sys.path``: Python <= 3.13's forkserver
    (``python -c``) ignores the ``sys_path`` it is handed and puts the current folder first, so a sweep started inside
    a checkout ran its workers on the checkout's ``mission_sim`` while the driver ran the installed one (2026-11-28:
    a fresh venv's first sweep from the clone compiled every kernel again, under the clone's path). ``PYTHONSAFEPATH``
    drops the current folder, ``PYTHONPATH`` gives the driver's entries in the driver's order. Their previous values
    travel in ``DRONEWPT_FORKSERVER_RESTORE``: the last preloaded module (:mod:`._forkserver_env`) puts them back in
    the forkserver's environment, so the workers (and the Pythons they start) see the driver's originals."""
    import json
    import sys

    from ._forkserver_env import RESTORE_VAR

    return {"PYTHONSAFEPATH": "1", "PYTHONPATH": os.pathsep.join(os.path.abspath(e) if e == "" else e for e in sys.path),
            RESTORE_VAR: json.dumps({k: os.environ.get(k) for k in ("PYTHONSAFEPATH", "PYTHONPATH")})}


def _pre_spawn_environ() -> dict[str, str]:
    """Dask's ``distributed.nanny.pre-spawn-environ`` (one BLAS / OpenMP thread per worker) as strings;
    values already set in the environment win, as in Dask."""
    import dask

    cfg = dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {}
    return {k: os.environ.get(k, str(v)) for k, v in cfg.items() if v is not None and k.endswith("_NUM_THREADS")}


@contextlib.contextmanager
def _environ(values: dict[str, str]):
    """``os.environ`` updated with ``values`` while inside (restored on leaving)."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextlib.contextmanager
def _sigint_shielded():
    """While the forkserver is spawned: SIGINT ignored (the disposition survives ``exec``, so the
    workers never see Ctrl-C, and Python and asyncio then install no KeyboardInterrupt handler in
    them) and blocked in this thread (a Ctrl-C sent to this thread stays pending) - on leaving, the
    handler is restored and a pending Ctrl-C raised here. Keep it short: a Ctrl-C sent to the
    process meanwhile may be taken by another thread that does not block it and is then lost."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    old_handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old_handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)


def _connect(scheduler: str, timeout_s: float):
    from distributed import Client

    try:
        return Client(scheduler, timeout=timeout_s, set_as_default=False)
    except Exception as exc:  # noqa: BLE001 - address errors come as OSError, TimeoutError, ValueError, ...
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"--scheduler {scheduler!r}: cannot connect to a Dask scheduler ({msg})") from None


def _local_cluster(workers: int | None):
    from distributed import LocalCluster

    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise ValueError(f"workers={n!r} is invalid; valid range: integer >= 1")
    return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                        silence_logs=logging.CRITICAL)


def _start_local(workers: int | None):
    """A local cluster whose workers ignore SIGINT (forked by a forkserver that ignores it) and a
    client to it."""
    import dask
    from distributed import Client

    dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"})
    _start_forkserver()
    with dask.config.set(LOCAL_CLUSTER_CONFIG):  # read by the scheduler, nannies and workers as they start
        cluster = _local_cluster(workers)
    try:
        return cluster, Client(cluster, set_as_default=False)
    except BaseException:
        cluster.close(timeout=INTERRUPT_CLOSE_TIMEOUT_S)
        raise


def _close(client, cluster, interrupted: bool) -> None:
    """Close the client, then the cluster. A Ctrl-C / SIGTERM while closing does not leave the cluster
    open (Dask's exit hook would then wait 10 s for it): the rest closes with the short timeout and
    the interrupt is raised afterwards."""
    timeout = INTERRUPT_CLOSE_TIMEOUT_S if interrupted else CLOSE_TIMEOUT_S
    caught = None
    for obj in (client, cluster):
        while obj is not None:
            try:
                obj.close(timeout=timeout)
                break
            except KeyboardInterrupt as exc:  # once more, quickly (a second Ctrl-C gives up on this one)
                if caught is not None:
                    break
                caught, timeout = exc, INTERRUPT_CLOSE_TIMEOUT_S
            except Exception:  # noqa: BLE001 - already closed, connection gone: nothing left to close
                break
    if caught is not None:
        raise caught


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None, *, connect_timeout_s: float = 10.0):
    """A ``distributed.Client``: to ``scheduler`` if given, else to a new local cluster of ``workers``
    single-threaded worker processes (default: one per CPU). Closed on exit, quietly; after an
    exception (Ctrl-C, SIGTERM turned into KeyboardInterrupt) with a 1 s timeout."""
    cluster = client = None
    interrupted = True
    with quiet_logs():
        try:
            if scheduler is not None:
                client = _connect(scheduler, connect_timeout_s)
            else:
                with interrupts_deferred():  # Ctrl-C or SIGTERM: raised once the cluster exists
                    cluster, client = _start_local(workers)
            yield client
            interrupted = False
        finally:
            _close(client, cluster, interrupted)
