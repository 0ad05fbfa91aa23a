"""The switching model's mode rules, numba-free: which diodes conduct and whether the inverter freewheels after a
drive change (:func:`_modes`) and after a guard event (:func:`_after_event`), on the circuit's rows
(:func:`mode_rows`). One source for both users: :mod:`.compiled` compiles them into its event loop
(``numba.extending.register_jitable``: numba compiles them where the kernel calls them; its cache is dropped when this
file changes, :func:`wpt_receiver.kernel_cache.drop_stale_cache`), and the slow ``solve_ivp`` reference
(:mod:`.ivp`) calls them as plain Python, so it imports no numba (a fresh process's first call took ~1.3 s more
to import numba and load the compiled rules).
"""

from __future__ import annotations

import numpy as np

from .circuit import I1, I2, P_OPEN, PRIMARY, S_OPEN, S_SHORT, SECONDARY

__all__ = ["mode_rows"]

_NONE = 99  # "not decided yet" for a primary mode


def mode_rows(cir) -> tuple:
    """The rows the mode rules (:func:`_modes`, :func:`_after_event`) read, of a :class:`~.circuit.Circuit`:
    ``(v2open (5, m) per primary index, v1open (4, m) per secondary index, sec_th (m,), pri_th)``."""
    return (np.array([cir.v2_open_row(p) for p in PRIMARY]), np.array([cir.v1_open_row(s) for s in SECONDARY]),
            np.asarray(cir.rect_threshold_row(), dtype=float), float(cir.inverter_threshold_v))


def _pidx(p):
    """Index of primary mode ``p`` in PRIMARY = (1, -1, 2, -2, P_OPEN)."""
    if p == 1:
        return 0
    if p == -1:
        return 1
    if p == 2:
        return 2
    if p == -2:
        return 3
    return 4


def _sidx(s):
    """Index of secondary mode ``s`` in SECONDARY = (1, -1, S_SHORT, S_OPEN)."""
    if s == 1:
        return 0
    if s == -1:
        return 1
    if s == S_SHORT:
        return 2
    return 3


def _dot(x, row):
    acc = 0.0
    for i in range(x.shape[0]):
        acc += x[i] * row[i]
    return acc


def _secondary_at_zero(x, p, v2open, sec_th):
    """Diode state when i2 = 0 and the gate is off: by the open-circuit voltage against the output voltage
    plus the forward drops."""
    v, th = _dot(x, v2open[_pidx(p)]), _dot(x, sec_th)
    return 1 if v > th else (-1 if v < -th else S_OPEN)


def _primary_at_zero(x, s, v1open, pri_th):
    """Inverter freewheel state when i1 = 0 during dead time (+-2 = freewheeling)."""
    v = _dot(x, v1open[_sidx(s)])
    return 2 if v > pri_th else (-2 if v < -pri_th else P_OPEN)


def _modes(x, cmd, gate, v2open, v1open, sec_th, pri_th):
    """Modes after a drive change: the inverter follows its command (in dead time the current freewheels
    through the diodes opposite to its sign), the SBAR shorts while the gate is on, else the diode pair of
    the current's sign conducts; a zero current is decided by the open-circuit voltage."""
    if cmd != 0:
        p = cmd
    else:
        p = -2 if x[I1] > 0 else (2 if x[I1] < 0 else _NONE)
    if gate:
        s = S_SHORT
    elif x[I2] > 0:
        s = 1
    elif x[I2] < 0:
        s = -1
    else:
        s = _secondary_at_zero(x, p if p != _NONE else P_OPEN, v2open, sec_th)
    if p == _NONE:
        p = _primary_at_zero(x, s, v1open, pri_th)
    return p, s


def _after_event(x, secondary, p, s, chatter, v2open, v1open, sec_th, pri_th):
    """New modes after a guard event (``x`` is modified in place: a current that stops is set to 0).
    ``chatter``: several zero-length events in a row; take the blocked state."""
    if secondary:
        if s == 1 or s == -1 or chatter:
            x[I2] = 0.0
            s = S_OPEN if chatter else _secondary_at_zero(x, p, v2open, sec_th)
        else:
            s = 1 if _dot(x, v2open[_pidx(p)]) > 0 else -1
        if s == S_OPEN:
            x[I2] = 0.0
    else:
        if p == 2 or p == -2 or chatter:
            x[I1] = 0.0
            p = P_OPEN if chatter else _primary_at_zero(x, s, v1open, pri_th)
        else:
            p = 2 if _dot(x, v1open[_sidx(s)]) > 0 else -2
        if p == P_OPEN:
            x[I1] = 0.0
    return p, s
