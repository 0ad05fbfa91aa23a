"""The budgeted model-based controller's relaxation search on the exact-mode link, compiled: the coarse grid's pass
and the fine scan of :func:`policies.budget_modal.relaxation` over a block of plans in one call each (numba,
``cache=True``), instead of one Python call per plan.

Each plan's prediction is :func:`wpt_receiver.modal_kernel.held_peak` itself (no second copy of its steps); the
duties of a block of plans are computed by the caller with numpy (:func:`wpt_receiver.duty_from_v2_clipped` on
the block, bit-equal to its rows one at a time). What a stop knows about ``P(r)`` is an interval per grid point,
``lo <= P(r) <= hi`` (``(-inf, inf)``: nothing yet; ``lo == hi``: exact; both NaN: a NaN prediction), so a point
asked once is not predicted again unless a later question needs more (a point stopped above one threshold and
asked about a higher one).

- :func:`coarse_pass` asks every coarse point "the exact ``P``, or a lower bound above (the least exact ``P`` so
  far) + ``b``" in order, as the Python loop did (module docstring of :mod:`policies.budget_modal`), so the floor,
  the target and every flag are the same numbers.
- :func:`fine_scan` asks the fine points "is ``P <= target``?" in order and stops at the first that is not (a plan
  stops as soon as its peak so far is above the target: a lower bound), as the Python loop did.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit

from wpt_receiver.modal_link import SOURCES as _LINK_SOURCES
from wpt_receiver.kernel_cache import drop_stale_cache
from wpt_receiver.modal_kernel import held_peak

__all__ = ["coarse_pass", "fine_scan", "k_tails"]


def _here():
    """This file, for :func:`wpt_receiver.kernel_cache.drop_stale_cache`."""


# held_peak is compiled into this module's cache: drop it when modal_kernel's (or its layout's) source changes
drop_stale_cache(_here, (*_LINK_SOURCES, Path(__file__)))


@njit(cache=True)
def k_tails(duties, has_tail):
    """Per plan (row of ``duties``, (m, n)): the index from which every duty is exactly 1 (short mode: the tail
    :func:`~wpt_receiver.modal_kernel.held_peak` may stop on), ``n`` when there is no tail bound (``has_tail``
    False) or the last duty is not 1."""
    m, n = duties.shape
    out = np.empty(m, np.int64)
    for j in range(m):
        k = n
        if has_tail:
            while k > 0 and duties[j, k - 1] == 1.0:
                k -= 1
        out[j] = k
    return out


@njit(cache=True)
def _predict(lc, mc, tab, zc, z0, v2_0, d, substeps, v1, vc_v, k_tail, tail_vinv, tail_x, tail_w, tail_cap, i2_ref,
             above):
    """``P`` of one plan (the overshoot ``pmax / i2_ref - 1``) from a copy of the start ``z0``, ``v2_0``
    (:func:`~wpt_receiver.modal_kernel.held_peak`: its short-mode tail's stop, and its stop once above ``above``)."""
    z = z0.copy()
    pmax = held_peak(lc, mc, tab, zc, z, v2_0, d, substeps, v1, vc_v, k_tail, tail_vinv, tail_x, tail_w, tail_cap,
                     i2_ref, above)[0]
    return pmax / i2_ref - 1.0


@njit(cache=True)
def coarse_pass(lc, mc, tab, zc, z0, v2_0, duties, substeps, v1, vc_v, tails, tail_vinv, tail_x, tail_w, tail_cap,
                i2_ref, budget, lo, hi, pc):
    """The coarse grid's pass into ``pc`` (one value per row of ``duties``): point ``i`` is asked with the
    threshold ``floor + budget`` (``floor`` the least of ``pc[:i]``, ``inf`` at first) and gets its exact ``P`` or,
    when its plan stops above that threshold, a lower bound above it (the Python loop's ``pred(r, floor +
    budget)``). ``lo``, ``hi`` (per row) are what is known about each ``P`` and are updated."""
    floor = math.inf
    for i in range(duties.shape[0]):
        above = floor + budget
        if math.isnan(lo[i]) or lo[i] == hi[i] or lo[i] > above:
            p = lo[i]                       # NaN, exact, or known to be above the threshold
        else:
            p = _predict(lc, mc, tab, zc, z0, v2_0, duties[i], substeps, v1, vc_v, tails[i], tail_vinv, tail_x,
                         tail_w, tail_cap, i2_ref, above)
            if math.isnan(p):
                lo[i] = hi[i] = p
            elif p > above:
                lo[i] = p                   # a lower bound (the plan stopped once above)
            else:
                lo[i] = hi[i] = p           # the whole plan: exact
        pc[i] = p
        if p < floor:
            floor = p


@njit(cache=True)
def fine_scan(lc, mc, tab, zc, z0, v2_0, duties, substeps, v1, vc_v, tails, tail_vinv, tail_x, tail_w, tail_cap,
              i2_ref, target, lo, hi):
    """The first row of ``duties`` (plans in increasing ``r``) whose ``P`` is not ``<= target`` (NaN counts as
    above), or the number of rows when every one is. ``lo``, ``hi`` (per row) are what is known about each ``P``:
    a row is predicted only when they do not decide it, and they are updated (a plan stopped once above the target:
    ``lo``; a whole plan: ``lo = hi = P``)."""
    for j in range(duties.shape[0]):
        if math.isnan(lo[j]) or lo[j] > target:
            return j
        if hi[j] <= target:
            continue
        p = _predict(lc, mc, tab, zc, z0, v2_0, duties[j], substeps, v1, vc_v, tails[j], tail_vinv, tail_x, tail_w,
                     tail_cap, i2_ref, target)
        if math.isnan(p):
            lo[j] = hi[j] = p
            return j
        if p > target:
            lo[j] = p   # a lower bound (the plan stopped once above)
            return j
        lo[j] = hi[j] = p
    return duties.shape[0]
