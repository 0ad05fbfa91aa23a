"""The RM -> SM transient of :mod:`wpt_receiver.tolerance` compiled with numba (``cache=True``).

:func:`transient_peak` steps the 2x2 complex envelope ``X+ = Ad X + Bd [V1, -V2 ph]`` with the
SBAR's fundamental in phase with J2 (``ph = J2/|J2|``, as :func:`wpt_receiver.envelope.simulate_complex`)
and returns the largest and the last |J2| from the switch on. A rectifier blocks when it can: if the
V2 input that keeps J2 at zero over the next step is within the clamp ``v2_v[k]`` (the induced emf
is below it: discontinuous, non-conducting), that input is applied and J2 stays 0. Imported on first use.
"""

from __future__ import annotations

from numba import njit

__all__ = ["transient_peak"]


@njit(cache=True)
def transient_peak(ad, bd, x0, v1, v2_v, i_switch):
    """``(max |J2| over steps >= i_switch, |J2| at the end)`` [A] of the run from ``x0`` with V2
    magnitude ``v2_v[k]`` [V] held over step ``k``."""
    x1, x2 = x0[0], x0[1]
    peak = 0.0
    for k in range(len(v2_v)):
        free = ad[1, 0] * x1 + ad[1, 1] * x2 + bd[1, 0] * v1   # J2 next with v2 = 0
        block = -free / bd[1, 1]                              # the input u2 = -V2 that keeps J2 = 0
        if abs(block) <= v2_v[k]:
            u2 = block
        else:
            m = abs(x2)
            if m > 0.0:
                ph = x2 / m
            else:
                ph = free / abs(free)
            u2 = -v2_v[k] * ph
        n1 = ad[0, 0] * x1 + ad[0, 1] * x2 + bd[0, 0] * v1 + bd[0, 1] * u2
        n2 = ad[1, 0] * x1 + ad[1, 1] * x2 + bd[1, 0] * v1 + bd[1, 1] * u2
        x1, x2 = n1, n2
        if k + 1 >= i_switch:
            a = abs(x2)
            if a > peak:
                peak = a
    return peak, abs(x2)
