"""One BLAS thread for the batched small-matrix work of the closed-loop rollouts.

Every control period of a ``compare`` rollout multiplies matrices of a few hundred rows (the MPC's
predictions over its horizon for the receivers of the batch, the numpy actors' layers): OpenBLAS
starts its threads on them, and the synchronisation costs more than the second core gains. Measured
on the 2-core machine under load ~7 (the MPC on 100 nominal windows, in-process): 6.2 s of CPU and
13.1 s wall with OpenBLAS' 2 threads, 2.4 s CPU and 3.6 s wall with one (same results).
:func:`single_blas_thread` holds the limit for a block (threadpoolctl's controller, built once: the
library scan costs ~10 ms, each limit ~30 us; a block inside another is a no-op, the outer one holds the
limit); without threadpoolctl it does nothing.
"""

from __future__ import annotations

import contextlib

__all__ = ["single_blas_thread"]

_CONTROLLER = []


def single_blas_thread():
    """A context manager limiting the loaded BLAS libraries to one thread (a no-op without threadpoolctl)."""
    if not _CONTROLLER:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:
            _CONTROLLER.append(None)
        else:
            _CONTROLLER.append(ThreadpoolController())
    ctl = _CONTROLLER[0]
    if ctl is None or _HELD:   # inside another such block (compare's around the MPC's act): the limit holds
        return contextlib.nullcontext()
    return _held(ctl.limit(limits=1, user_api="blas"))


_HELD = []   # the blocks open now (nested ones are no-ops: each limit and its release cost ~30 us)


@contextlib.contextmanager
def _held(limit):
    with limit:
        _HELD.append(True)
        try:
            yield
        finally:
            _HELD.pop()
