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
* lookup (:func:`inst_peak`): per grid point the least-squares line of the excess in VL through
  the three tables (:func:`fold_vl`; the excess grows with the clamp voltage, nearly linearly),
  bilinear in (duty, sqrt(|I2|/80 A)) as ``PeakTable``.

Error bound against :meth:`SbarHarmonics.peak` evaluated exactly at the true Lm and VL (checked by
``tests/test_env_devices.py``): within 0.5 % for |I2| >= 3 A and within 0.05 A for |I2| >= 2 A,
over duties 0..1, Lm 0.75-1.5 x nominal and VL 29-33 V (the envs' operating range), for the
``ideal`` and ``schottky`` sets. One table at nominal VL alone would be off by up to 2.7 % at
33 V (the excess grows with the clamp voltage); Lm moves it by < 0.4 %, so Lm is not indexed.

The excess is applied to the step's envelope peak (the largest |I2| of the step's samples; the
peak grows with |I2| at a fixed duty, so the largest sample gives the largest instantaneous
peak). It can be slightly negative (-0.03 A at most, short mode at 80 A: harmonics in
anti-phase flatten the crest).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["VL_GRID_V", "I2_MAX_A", "LOOKUP_SCALARS", "peak_table", "fold_vl", "inst_peak", "inst_peak_array", "PeakLookup"]

VL_GRID_V = (27.0, 31.0, 35.0)
I2_MAX_A = 80.0
N_D, N_I = 51, 81
#: the scalars of the lookup, as the compiled kernels get them: the VL of the fold [V], 1/I2_MAX_A [1/A]
LOOKUP_SCALARS = (VL_GRID_V[1], 1.0 / I2_MAX_A)
_VLC, _INV_IMAX = LOOKUP_SCALARS
_CACHE_VERSION = "env-peak-table v1"


def peak_table(link, devices) -> np.ndarray:
    """The excess table (len(VL_GRID_V), N_D, N_I) [A] for a link (its nominal Lm) and a
    :class:`wpt_receiver.devices.DeviceSet`; from the disk cache when there, else built (~1.3-4.7 s). The
    table is at :data:`VL_GRID_V`, whatever the link's own VL: links that differ only in VL share one (keyed at
    ``LinkParams``' default VL)."""
    return _peak_table(link.at_default_vl(), devices)


@lru_cache(maxsize=8)
def _peak_table(link, devices) -> np.ndarray:
    """:func:`peak_table` of a link at ``LinkParams``' default VL."""
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


def fold_vl(tab: np.ndarray) -> np.ndarray:
    """The (N_D, N_I, 2) lookup table from :func:`peak_table`: per grid point the least-squares line of
    the excess in VL over :data:`VL_GRID_V`, ``excess = A + B (VL - 31 V)`` (``[..., 0]`` = A,
    ``[..., 1]`` = B); a corner's two values side by side for the compiled kernels."""
    v = np.asarray(VL_GRID_V) - VL_GRID_V[1]
    a = tab.mean(axis=0)
    b = np.tensordot(v, tab - a, axes=(0, 0)) / np.dot(v, v)
    return np.ascontiguousarray(np.stack([a, b], axis=-1))


def inst_peak(pk, d, vl, tab) -> float:
    """Instantaneous peak [A] for an envelope peak ``pk >= 0``, duty ``d`` in [0, 1] and battery
    voltage ``vl`` (floats); ``tab`` the :func:`fold_vl` table: the envs' step's own lookup
    (:func:`envs.vector_kernel._inst_peak`: bilinear in (duty, sqrt(pk / I2_MAX_A)) on A and B, then
    ``A + B (VL - 31 V)``)."""
    from .vector_kernel import _inst_peak
    return _inst_peak(float(pk), float(d), float(vl), tab, _VLC, _INV_IMAX)


def inst_peak_array(pk, d, vl, tab) -> np.ndarray:
    """:func:`inst_peak` of every element of the arrays (n,) ``pk``, ``d``, ``vl``."""
    from .vector_kernel import inst_peak_rows
    pk, d, vl = (np.ascontiguousarray(x, dtype=float) for x in np.broadcast_arrays(pk, d, vl))
    out = np.empty(pk.shape[0])
    inst_peak_rows(pk, d, vl, tab, _VLC, _INV_IMAX, out)
    return out


class PeakLookup:
    """The env's lookup for one (link, devices): ``scalar(pk, d, vl)`` on floats, ``array(pk, d, vl)``
    on numpy arrays (both the compiled step's own lookup); ``table`` the (3, 51, 81) excesses at :data:`VL_GRID_V`, ``kernel_table`` the
    (51, 81, 2) :func:`fold_vl` table all lookups read."""

    def __init__(self, link, devices):
        self.table = peak_table(link, devices)
        self.kernel_table = fold_vl(self.table)

    def scalar(self, pk, d, vl):
        return inst_peak(pk, d, vl, self.kernel_table)

    def array(self, pk, d, vl):
        return inst_peak_array(np.atleast_1d(pk), np.atleast_1d(d), np.atleast_1d(vl), self.kernel_table)
