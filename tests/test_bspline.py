"""The numpy cubic B-spline evaluation of the coupling table against scipy.ndimage (bit for bit)."""

import numpy as np
import pytest

from wpt_receiver.bspline import map_cubic_mirror, mirror_index


@pytest.mark.parametrize("shape", [(41, 37), (6, 5), (2, 9)])
def test_equals_scipy_map_coordinates(shape):
    ndimage = pytest.importorskip("scipy.ndimage")
    rng = np.random.default_rng(sum(shape))
    coef = rng.normal(size=shape)
    u = rng.uniform(0, shape[0] - 1, 5000)
    v = rng.uniform(0, shape[1] - 1, 5000)
    u[:20], u[20:40], v[40:60], v[60:80] = 0.0, shape[0] - 1, 0.0, shape[1] - 1  # the edges (mirror taps)
    u[80:100] = np.arange(20) % shape[0]  # on the knots
    want = ndimage.map_coordinates(coef, np.stack([u, v]), order=3, prefilter=False, mode="mirror")
    np.testing.assert_array_equal(map_cubic_mirror(coef, u, v), want)


def test_interpolates_the_samples():
    """Prefiltered coefficients give back the samples on the knots and a smooth function between
    them (cubic spline error ~ h^4 max|f^(4)| / 384)."""
    ndimage = pytest.importorskip("scipy.ndimage")
    x = np.arange(40.0)
    f = np.outer(np.sin(0.3 * x), np.cos(0.2 * np.arange(9.0)))
    coef = ndimage.spline_filter(f, order=3, mode="mirror")
    u, v = np.repeat(x, 9), np.tile(np.arange(9.0), 40)
    np.testing.assert_allclose(map_cubic_mirror(coef, u, v), f.ravel(), atol=1e-12)
    um = np.linspace(5.25, 30.75, 200)
    got = map_cubic_mirror(coef, um, np.full_like(um, 4.0))
    np.testing.assert_allclose(got, np.sin(0.3 * um) * np.cos(0.8), atol=1e-4)


def test_mirror_index():
    np.testing.assert_array_equal(mirror_index(np.array([-2, -1, 0, 4, 5, 6]), 5), [2, 1, 0, 4, 3, 2])
