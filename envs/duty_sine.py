"""``sin(pi d / 2)`` and ``cos(pi d / 2)`` of a duty ``d`` in [0, 1] by two polynomials: the SBAR's duty terms of
the envs (the clamp ``(4/pi) VC (1 - sin(pi d/2))`` and the short window's weight ``w(d) = d + sin(pi d)/pi``,
``sin(pi d) = 2 sin(pi d/2) cos(pi d/2)``), one source for the compiled step (:mod:`envs.vector_kernel`, both envs)
and the plans' initial state (:mod:`envs.core`). No libm call: inlined into the step, the CPU overlaps it across
windows (libm's ``sin`` was ~13-17 ns per window of the step's one-thread CPU; numba has no SVML here).

``y = min(d, 1 - d)`` in [0, 1/2] (exact: ``1 - d`` for d >= 1/2); ``sin(pi y/2) = y S(y^2)`` (degree 13, odd) and
``cos(pi y/2) = C(y^2)`` (degree 14, even), relative least-squares fits at Chebyshev nodes (``mpmath``, 50 digits;
``benchmarks/fit_duty_sine.py`` reproduces them to the bit; ``benchmarks/env_accuracy.py``'s section in
docs/performance.md, "Eighth pass"); ``sin(pi d/2)`` is the one of the two for ``y = d``, the other for ``y = 1 - d``. Against the correctly rounded values on 142,858 duties in [0, 1]:
the sine within 2 ulp (mean 0.19 ulp; libm's ``sin(0.5 * pi * d)``: 2 ulp, mean 0.24, its argument rounded), the
cosine within 1 ulp (``sqrt(1 - s^2)``, used before, lost up to 1.3e-11 near d = 1). Exact at d = 0 and d = 1 (0 and 1).

Plain arithmetic on floats or numpy arrays (the selects are products with 0 / 1, exact for finite values); numba
compiles it inlined (``envs.vector_kernel._sin_cos``). numba is not imported here.
"""

from __future__ import annotations

__all__ = ["sin_cos_half_pi"]

# sin(pi y / 2) / y on y in [0, 1/2], in powers of y^2
_S0, _S1, _S2, _S3 = 1.5707963267948966, -0.6459640975062447, 0.0796926262460585, -0.004681754132567202
_S4, _S5, _S6 = 0.00016044115230749134, -3.5986484842791955e-06, 5.634575893131115e-08
# cos(pi y / 2) on y in [0, 1/2], in powers of y^2
_C1, _C2, _C3 = -1.2337005501361697, 0.2536695079010468, -0.020863480763312965
_C4, _C5, _C6, _C7 = 0.0009192602741979189, -2.520203683590357e-05, 4.710611181951305e-07, -6.32138408244628e-09


def sin_cos_half_pi(d):
    """``(sin(pi d/2), cos(pi d/2))`` for a duty ``d`` in [0, 1] (a float or an array; outside [0, 1] the numbers
    are not the sine's)."""
    hi = d > 0.5
    lo = 1 - hi
    y = d + hi * (1.0 - 2.0 * d)   # min(d, 1 - d), exact
    u = y * y
    sy = y * (_S0 + u * (_S1 + u * (_S2 + u * (_S3 + u * (_S4 + u * (_S5 + u * _S6))))))
    cy = 1.0 + u * (_C1 + u * (_C2 + u * (_C3 + u * (_C4 + u * (_C5 + u * (_C6 + u * _C7))))))
    return lo * sy + hi * cy, lo * cy + hi * sy
