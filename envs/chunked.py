"""The one rule for the autoreset's compiled parts that run over chunks of windows (the draws,
:mod:`envs.draw_kernel`; the command profile, :mod:`envs.command_kernel`): one chunk calls the serial loop
itself, more run the part's ``parallel=True`` function over the chunks (``prange``). Each value depends only on
its own window or step, so the chunks do not change the numbers.

Imports nothing (the kernels it is handed are compiled by their own modules)."""

from __future__ import annotations

__all__ = ["run_chunks"]


def run_chunks(serial, parallel, n: int, n_chunks: int, *args) -> None:
    """``serial(0, n, *args)`` when ``n_chunks <= 1``, else ``parallel(*args, n_chunks)`` (the caller has set
    numba's threads). One chunk calls the serial loop itself, not the parallel function with one chunk: a
    ``parallel=True`` function starts numba's thread pool at its first call even when it runs one chunk, and a
    started pool forbids the fork that ``compare`` runs its MPC in (:mod:`policies.forked`: fork before the first
    parallel call)."""
    if n_chunks <= 1:
        serial(0, n, *args)
    else:
        parallel(*args, n_chunks)
