"""The charge command (the reference) of every step of a batch of windows, compiled: the one source of
:func:`envs.scenario.command_profile`'s arithmetic, run over the steps in parallel chunks (``prange``; one
chunk: on the calling thread, without starting numba's thread pool).

Window ``e``'s command at step ``k`` (time ``t = k dt``) is ``cmd0`` until its command change, ``cmd1`` until
its stop, then 0 (stop charging -> short mode) to the end of the window; written into a step-major store
(steps along axis 0, windows along axis 1: a step of the env reads one row), in place. Each value depends only
on its own step and window, so the chunks do not change the numbers.

Imported when a window's command is made (numba is not imported by ``import envs``).
"""

from __future__ import annotations

from numba import njit, prange

from .chunked import run_chunks

__all__ = ["command_rows", "command_rows_parallel", "fill_commands"]


@njit(cache=True)
def command_rows(lo, hi, dt_s, t_change, t_stop, cmd0, cmd1, out):
    """Rows ``lo..hi`` (steps) of the command store ``out`` (n_steps + 1, n): ``cmd0`` while ``t < t_change``,
    else ``cmd1`` while ``t < t_stop``, else 0, with ``t = k dt_s`` (arrays (n,) over the windows)."""
    for k in range(lo, hi):
        t = k * dt_s
        for e in range(out.shape[1]):
            # (both selects' operands loaded every time: LLVM vectorises the loop, ~2.4x faster than the nested
            # conditional, whose loads it could not hoist; the same value for any inputs, NaN included)
            after = cmd1[e] if t < t_stop[e] else 0.0
            out[k, e] = cmd0[e] if t < t_change[e] else after


@njit(cache=True, parallel=True)
def command_rows_parallel(dt_s, t_change, t_stop, cmd0, cmd1, out, n_chunks):
    """:func:`command_rows` over all the steps of ``out`` in ``n_chunks`` contiguous chunks run in parallel."""
    m, c = out.shape[0], max(n_chunks, 1)
    for i in prange(c):
        command_rows(i * m // c, (i + 1) * m // c, dt_s, t_change, t_stop, cmd0, cmd1, out)


def fill_commands(dt_s, t_change, t_stop, cmd0, cmd1, out, n_chunks=1, compiled=True) -> None:
    """``out`` (n_steps + 1, n) filled by :func:`command_rows`, over ``n_chunks`` chunks of steps
    (:func:`envs.chunked.run_chunks`: one chunk on the calling thread, more in parallel; the caller sets numba's
    threads). ``compiled=False``: the same source uncompiled (tests)."""
    if not compiled:
        command_rows.py_func(0, out.shape[0], dt_s, t_change, t_stop, cmd0, cmd1, out)
    else:
        run_chunks(command_rows, command_rows_parallel, out.shape[0], n_chunks, dt_s, t_change, t_stop, cmd0, cmd1,
                   out)
