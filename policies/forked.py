"""One piece of work in a forked child process, beside the parent's own (the second core).

``compare`` spends ~40 % of its CPU in the MPC's rollouts (one QP per receiver and control period,
:mod:`policies.mpc`), a block no other policy's run depends on. :class:`Forked` runs such a
function in a child forked from the parent (the child inherits the imported modules and numba's
loaded kernels: no second start-up) while the parent runs the rest; :meth:`Forked.result` returns
its value (an exception in the child is raised in the parent). Nothing is lost if the child dies
(killed, out of memory): the parent then runs the function itself. The results are those of the same
function run in-process (the same arithmetic; ``tests/test_compare_batched.py``).

Only where it is safe and useful (:func:`available`): the ``fork`` start method (Linux), more than
one CPU, not inside a daemon process, and numba's thread pool not yet started in the parent (a pool's threads do not survive a
fork; the compiled parallel step starts it on its first call, so fork before the first env step).
"""

from __future__ import annotations

import os
import sys

from mission_sim.signals import blocked_across_fork, unblock_in_child

__all__ = ["Forked", "available"]


def available() -> bool:
    """Whether :class:`Forked` would fork (else it runs the function in-process at :meth:`result`)."""
    import multiprocessing as mp

    if not sys.platform.startswith("linux") or "fork" not in mp.get_all_start_methods():
        return False
    if len(os.sched_getaffinity(0)) < 2 or mp.current_process().daemon:   # a daemon may not have children
        return False
    if "numba" in sys.modules:
        try:
            sys.modules["numba"].threading_layer()   # raises until the thread pool is started
        except ValueError:
            return True
        return False
    return True


def _child(conn, fn, args):
    try:
        unblock_in_child()   # blocked by the parent across the fork (mission_sim.signals.blocked_across_fork)
        out = ("ok", fn(*args))
    except BaseException as exc:   # noqa: BLE001 - handed to the parent, which raises it
        out = ("error", exc)
    try:
        conn.send(out)
    finally:
        conn.close()
        os._exit(0)   # no atexit handlers, no flushing of the parent's inherited buffers


class Forked:
    """``fn(*args)`` in a forked child when :func:`available`, else at :meth:`result` in-process."""

    def __init__(self, fn, *args):
        self.fn, self.args, self.proc = fn, args, None
        if available():
            import multiprocessing as mp
            ctx = mp.get_context("fork")
            self._recv, send = ctx.Pipe(duplex=False)
            self.proc = ctx.Process(target=_child, args=(send, fn, args), daemon=True)
            try:
                with blocked_across_fork():   # the child takes SIGINT / SIGTERM only inside _child's try
                    self.proc.start()
            except OSError:   # no process to be had (limits): run it in-process at result()
                self.proc = None
                self._recv.close()
            send.close()

    def result(self):
        if self.proc is None:
            return self.fn(*self.args)
        try:
            kind, value = self._recv.recv()
        except Exception:  # noqa: BLE001 - died without an answer, or one that does not unpickle: run it here
            kind, value = "lost", None
        finally:
            self._recv.close()
            self.proc.join()
        if kind == "error":
            raise value
        return self.fn(*self.args) if kind == "lost" else value

    def cancel(self) -> None:
        """Stop the child (the parent failed: its result is not wanted)."""
        if self.proc is not None and self.proc.is_alive():
            self.proc.terminate()
            self.proc.join()
        if self.proc is not None:
            self._recv.close()
