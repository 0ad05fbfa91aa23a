"""The envs' sin(pi d/2) and cos(pi d/2) of a duty (envs.duty_sine): two polynomials in place of libm's sine in the
compiled step (docs/performance.md, "Eighth pass"). Checked against math.sin of the exact product (the reference is
libm's, itself within 1 ulp; together within 3 ulp), exact at the ends, the same numbers compiled and on arrays."""

import math

import numpy as np
import pytest

from envs.duty_sine import sin_cos_half_pi

D = np.concatenate([np.linspace(0.0, 1.0, 20001), [0.5, np.nextafter(0.5, 0.0), np.nextafter(0.5, 1.0), 1e-300, 1e-9,
                                                  1.0 - 1e-12]])


def _ulps(got, want):
    return np.abs(got - want) / np.spacing(np.maximum(np.abs(want), 1e-300))


def test_within_a_few_ulp_of_the_sine_and_cosine():
    s, c = sin_cos_half_pi(D)
    # references: libm on an argument rounded once (pi/2 d); away from d = 1 the cosine's reference is the sine of
    # pi/2 (1 - d) (1 - d exact for d >= 1/2), whose relative error is that of sin, not of the cancellation in cos
    want_s = np.array([math.sin(0.5 * math.pi * x) for x in D])
    want_c = np.array([math.sin(0.5 * math.pi * (1.0 - x)) if x >= 0.5 else math.cos(0.5 * math.pi * x) for x in D])
    assert _ulps(s, want_s).max() <= 3.0
    assert _ulps(c, want_c).max() <= 3.0
    assert np.abs(s * s + c * c - 1.0).max() <= 4e-16


def test_exact_at_the_ends_and_monotone():
    assert sin_cos_half_pi(0.0) == (0.0, 1.0)
    assert sin_cos_half_pi(1.0) == (1.0, 0.0)
    s, c = sin_cos_half_pi(np.linspace(0.0, 1.0, 4097))
    assert np.all(np.diff(s) >= 0.0) and np.all(np.diff(c) <= 0.0)


def test_compiled_scalar_equals_the_arrays():
    pytest.importorskip("numba")
    from envs.vector_kernel import _sbar

    s, c = sin_cos_half_pi(D)
    # _sbar's clamp per volt of VC is (4/pi) (1 - s) and its excess dR (d + (2/pi) s c): the compiled kernel's s and c
    for k in range(0, len(D), 97):
        mag, rx = _sbar(1.0, D[k], 1.0)
        assert mag == 4.0 / np.pi * 1.0 * (1.0 - s[k])
        assert rx == 1.0 * (D[k] + 2.0 / np.pi * s[k] * c[k])
