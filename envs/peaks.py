"""Instantaneous peak |i2| of the envs: the envelope's step peak plus the SBAR's harmonic ripple.

The envelope model carries the fundamental of i2 only; the real current also carries the odd
harmonics driven by the inverter's and the SBAR's square waves (:class:`wpt_receiver.peak.SbarHarmonics`),
so its instantaneous peak differs from the envelope amplitude by an *excess* that depends on the
duty, on |I2| and on the clamp voltage ``VL + Vf`` (the ripple of v2 scales with it). The envs
look it up in a table built once per process (and stored in the disk cache,
:mod:`wpt_receiver.diskcache`) per link and device set:

* ``excess[v, j, k]`` = :class:`wpt_receiver.peak.PeakTable` excess (duty grid ``j``: 51 points on
  [0, 1]; |I2| grid ``k``: 81 points quadratic on [0, 80 A]) at the battery voltages
  :data:`VL_GRID_V` (27, 31, 35 V), the nominal Lm of the link;
* lookup (:func:`inst_peak`): bilinear in (duty, sqrt(|I2|/80 A)) as ``PeakTable``, then linear
  in VL (clamped to the grid).

Error bound against :meth:`SbarHarmonics.peak` evaluated exactly at the true Lm and VL (checked by
``tests/test_env_devices.py``): within 0.5 % for |I2| >= 3 A and within 0.12 A for |I2| >= 2 A,
over duties 0..1, Lm 0.75-1.5 x nominal and VL 29-33 V (the envs' operating range), for the
``ideal`` and ``schottky`` sets. One table at nominal VL alone would be off by up to 2.7 % at
33 V (the excess grows with the clamp voltage); Lm moves it by < 0.4 %, so Lm is not indexed.

The excess is applied to the step's envelope peak (the largest |I2| of the step's samples; the
peak grows with |I2| at a fixed duty, so the largest sample gives the largest instantaneous
peak). It can be slightly negative (-0.03 A at most, short mode at 80 A: harmonics in
anti-phase flatten the crest).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

__all__ = ["VL_GRID_V", "I2_MAX_A", "LOOKUP_SCALARS", "peak_table", "inst_peak", "inst_peak_numpy", "PeakLookup"]

VL_GRID_V = (27.0, 31.0, 35.0)
I2_MAX_A = 80.0
N_D, N_I = 51, 81
#: the scalars of the lookup, as the compiled kernels get them: first VL [V], 1/VL step [1/V], 1/I2_MAX_A [1/A]
LOOKUP_SCALARS = (VL_GRID_V[0], 1.0 / (VL_GRID_V[1] - VL_GRID_V[0]), 1.0 / I2_MAX_A)
_VL0, _INV_DV, _INV_IMAX = LOOKUP_SCALARS
_CACHE_VERSION = "env-peak-table v1"


@lru_cache(maxsize=8)
def peak_table(link, devices) -> np.ndarray:
    """The excess table (len(VL_GRID_V), N_D, N_I) [A] for a link (its nominal Lm) and a
    :class:`wpt_receiver.devices.DeviceSet`; from the disk cache when there, else built (~1.3 s)."""
    from wpt_receiver import diskcache
    key = f"{_CACHE_VERSION} {link!r} {devices!r} vl={VL_GRID_V} i2max={I2_MAX_A} n={N_D}x{N_I}"
    shape = (len(VL_GRID_V), N_D, N_I)
    tab = diskcache.load("env_peak", key, shape)
    if tab is None:
        from wpt_receiver.peak import PeakTable, SbarHarmonics
        tab = np.stack([PeakTable(SbarHarmonics(link.with_(vl_v=v), devices), i2_max_a=I2_MAX_A, n_d=N_D,
                                  n_i=N_I).excess for v in VL_GRID_V])
        diskcache.store("env_peak", key, tab)
    tab.setflags(write=False)
    return tab


def inst_peak(pk, d, vl, tab) -> float:
    """Instantaneous peak [A] for an envelope peak ``pk >= 0``, duty ``d`` in [0, 1] and battery
    voltage ``vl``, Python floats; ``tab`` the table as nested lists. The arithmetic of
    :func:`envs.vector_kernel._inst_peak`, operation for operation."""
    nv, nd, ni = len(tab), len(tab[0]), len(tab[0][0])
    x = d * (nd - 1)
    y = math.sqrt(min(pk * _INV_IMAX, 1.0)) * (ni - 1)
    j = min(int(x), nd - 2)
    k = min(int(y), ni - 2)
    fx, fy = x - j, y - k
    v = (vl - _VL0) * _INV_DV
    v = 0.0 if v < 0.0 else (nv - 1.0 if v > nv - 1.0 else v)
    m = min(int(v), nv - 2)
    fv = v - m
    a, b = tab[m], tab[m + 1]
    e0 = ((a[j][k] * (1.0 - fx) + a[j + 1][k] * fx) * (1.0 - fy) + (a[j][k + 1] * (1.0 - fx) + a[j + 1][k + 1] * fx) * fy)
    e1 = ((b[j][k] * (1.0 - fx) + b[j + 1][k] * fx) * (1.0 - fy) + (b[j][k + 1] * (1.0 - fx) + b[j + 1][k + 1] * fx) * fy)
    return pk + (e0 + fv * (e1 - e0))


def inst_peak_numpy(pk, d, vl, tab):
    """:func:`inst_peak` on arrays (n,) (the vector env's numpy path); ``tab`` the array."""
    nv, nd, ni = tab.shape
    x = d * (nd - 1)
    y = np.sqrt(np.minimum(pk * _INV_IMAX, 1.0)) * (ni - 1)
    j = np.minimum(x.astype(np.int64), nd - 2)
    k = np.minimum(y.astype(np.int64), ni - 2)
    fx, fy = x - j, y - k
    v = (vl - _VL0) * _INV_DV
    v = np.minimum(np.maximum(v, 0.0), nv - 1.0)
    m = np.minimum(v.astype(np.int64), nv - 2)
    fv = v - m

    def bil(q):
        return ((tab[q, j, k] * (1.0 - fx) + tab[q, j + 1, k] * fx) * (1.0 - fy)
                + (tab[q, j, k + 1] * (1.0 - fx) + tab[q, j + 1, k + 1] * fx) * fy)

    e0 = bil(m)
    e1 = bil(m + 1)
    return pk + (e0 + fv * (e1 - e0))


class PeakLookup:
    """The env's lookup for one (link, devices): ``scalar(pk, d, vl)`` on floats, ``array(pk, d, vl)``
    on numpy arrays; ``table`` the (3, 51, 81) array the compiled kernels read."""

    def __init__(self, link, devices):
        self.table = peak_table(link, devices)
        self._rows = self.table.tolist()

    def scalar(self, pk, d, vl):
        return inst_peak(pk, d, vl, self._rows)

    def array(self, pk, d, vl):
        return inst_peak_numpy(pk, d, vl, self.table)
