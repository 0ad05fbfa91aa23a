"""The coupling table's one lookup (wpt_receiver.coupling_kernel): its own source uncompiled, scipy's
B-spline, and the exact field (issue 22).

There is no second (numpy) copy of the lookup to compare against. Instead:

* the compiled kernel against its own ``.py_func`` (every numba function of the module swapped for
  its ``py_func``: the same source run by the interpreter) on a few poses;
* the spline evaluation against ``scipy.ndimage.map_coordinates`` (the library whose
  ``spline_filter`` makes the coefficients), edges included;
* the table against the exact field (elliptic integrals, ``scipy.special.ellipk``/``ellipe``) within
  the table's stated accuracy: a physics check;
* one source: a change to one kernel formula (the loop integrand) changes the table path
  (``lm_h``) and the exact path (``lm_exact_h``, which uses the kernel's receiver geometry and
  integrand with the elliptic-integral field) alike.
"""

import math

import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

from wpt_receiver import coupling_kernel as ck
from wpt_receiver.coupling import NOMINAL_GAP_M, default_coupling


def _use_py_funcs(monkeypatch):
    """Every numba function of :mod:`wpt_receiver.coupling_kernel` replaced by its ``py_func`` (module
    globals: the kernels' Python bodies and :mod:`wpt_receiver.coupling`'s lazy imports see them)."""
    names = [n for n, v in vars(ck).items() if isinstance(v, CPUDispatcher)]
    assert {"flux_table", "receiver_points", "table_field", "loop_sum", "_spline", "_point", "_integrand"} <= set(names)
    for n in names:
        monkeypatch.setattr(ck, n, getattr(ck, n).py_func)


def _poses():
    """A few poses: hover, offset and tilted, beyond the table, and one dipping below it."""
    dx = np.array([0.0, 0.12, -0.31, 1.45, 0.02])
    dy = np.array([0.0, -0.05, 0.2, 0.3, 0.0])
    dz = np.array([NOMINAL_GAP_M, 0.25, 0.6, 0.4, 0.03])
    tilt = np.array([0.0, 0.2, -0.35, 0.1, 0.3])
    axis = np.array([math.pi / 2, 0.3, 2.0, 4.0, math.pi / 2])
    return dx, dy, dz, tilt, axis


def test_compiled_kernel_equals_its_py_func(monkeypatch):
    model = default_coupling()
    dx, dy, dz, tilt, axis = _poses()
    fast = model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis)
    fast_exact = model.lm_exact_h(dx[:2], dy[:2], dz[:2], tilt[:2], tilt_axis_rad=axis[:2])
    _use_py_funcs(monkeypatch)
    assert not isinstance(ck.flux_table, CPUDispatcher)
    slow = model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis)
    # same operations in the same order; only libm's hypot/floor may differ from LLVM's in the last bit
    np.testing.assert_allclose(slow, fast, rtol=1e-13, atol=0.0)
    np.testing.assert_allclose(model.lm_exact_h(dx[:2], dy[:2], dz[:2], tilt[:2], tilt_axis_rad=axis[:2]),
                               fast_exact, rtol=1e-13, atol=0.0)
    assert fast[3] < 0.05 * fast[0] and fast[4] > fast[0] > 0   # far: weak; below the table: strong


def test_flux_table_flags_poses_below_the_table():
    model = default_coupling()
    model.lm_h(0.0, 0.0, NOMINAL_GAP_M)
    rot = np.stack([np.eye(3)] * 3)
    org = np.array([[0.0, 0.0, NOMINAL_GAP_M], [0.0, 0.0, 0.019], [0.3, 0.0, 0.5]])
    lm, below = ck.flux_table(*model._table_args(), rot, org, model._flat_pts, model._flat_tan, float(model._w))
    assert below.tolist() == [False, True, False]
    assert np.isnan(lm[1]) and lm[0] > lm[2] > 0


@pytest.mark.parametrize("shape", [(41, 37), (6, 5), (2, 9)])
def test_spline_equals_scipy_map_coordinates(shape):
    """The kernel's B-spline is scipy.ndimage's ``map_coordinates(order=3, prefilter=False, mode="mirror")``."""
    from scipy import ndimage
    rng = np.random.default_rng(sum(shape))
    coef = rng.normal(size=shape)
    u = rng.uniform(0, shape[0] - 1, 2000)
    v = rng.uniform(0, shape[1] - 1, 2000)
    u[:20], u[20:40], v[40:60], v[60:80] = 0.0, shape[0] - 1, 0.0, shape[1] - 1  # the edges (mirror taps)
    u[80:100] = np.arange(20) % shape[0]  # on the knots
    want = ndimage.map_coordinates(coef, np.stack([u, v]), order=3, prefilter=False, mode="mirror")
    # table_field with h = 1, z0 = 0: the spline at fractional indices (u, v)
    got = ck.table_field(coef, 1.0, 0.0, shape[0] - 1.0, shape[1] - 1.0, u, v)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-14 * np.abs(coef).max())
    # beyond the table: uncoupled; below it: NaN (the caller's exact field)
    out = ck.table_field(coef, 1.0, 0.0, shape[0] - 1.0, shape[1] - 1.0, np.array([shape[0] + 0.5, 1.0]),
                         np.array([0.5, -0.25]))
    assert out[0] == 0.0 and np.isnan(out[1])


def test_table_against_exact_field_random_poses():
    """The table within its accuracy (cubic spline of ``A_phi / rho`` on a 5 mm grid; the loop
    quadrature is shared): 1e-4 of the hover Lm anywhere above the table's floor (worst where the
    receiver's edge passes ~2 cm over the pad's outer turns, where the field bends sharply), 1e-5
    relative with the receiver >= 10 cm up, 1e-6 relative near the hover pose."""
    model = default_coupling()
    rng = np.random.default_rng(4)
    n = 80
    dx, dy = rng.uniform(-0.3, 0.3, n), rng.uniform(-0.3, 0.3, n)
    dz, tilt, axis = rng.uniform(0.06, 0.5, n), rng.uniform(-0.4, 0.4, n), rng.uniform(0, 2 * math.pi, n)
    table = model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis)
    exact = model.lm_exact_h(dx, dy, dz, tilt, tilt_axis_rad=axis)
    hover = model.lm_exact_h(0.0, 0.0, NOMINAL_GAP_M)
    assert np.ptp(exact) > hover                              # the poses span weak to strong coupling
    np.testing.assert_allclose(table, exact, rtol=0, atol=1e-4 * hover)
    high = dz - 0.12 * np.sin(np.abs(tilt)) > 0.1
    assert high.sum() > n // 2
    np.testing.assert_allclose(table[high], exact[high], rtol=1e-5, atol=1e-7 * hover)
    p = (np.array([0.0, 0.02, -0.03]), np.array([0.0, 0.01, 0.02]), NOMINAL_GAP_M + np.array([0, 0.01, -0.01]),
         np.array([0.0, 0.05, -0.05]))
    np.testing.assert_allclose(model.lm_h(*p), model.lm_exact_h(*p), rtol=1e-6)


def test_below_the_table_uses_the_exact_field():
    """A receiver wholly below z_min (0.02 m) gets the exact field; one dipping below it, the exact field at
    those points and the table at the rest (within the table's accuracy at its floor, near the wires: 1e-3)."""
    model = default_coupling()
    p = (np.array([0.0, 0.05, 0.1]), 0.0, np.array([0.015, 0.04, 0.05]), np.array([0.0, 0.3, -0.35]))
    lm, exact = model.lm_h(*p), model.lm_exact_h(*p)
    assert lm[0] == pytest.approx(exact[0], rel=1e-12)
    np.testing.assert_allclose(lm[1:], exact[1:], rtol=1e-3)   # the spline's mirrored floor, 2-4 cm over the turns
    assert lm[0] > model.lm_h(0.0, 0.0, 0.03) > model.lm_h(0.0, 0.0, NOMINAL_GAP_M)   # closer: more coupled


def test_one_source_a_kernel_change_reaches_table_and_exact_paths(monkeypatch):
    """Changing the kernel's loop integrand (here: scaled by 1.5) changes Lm from the table and Lm from
    the exact field alike: both paths take the receiver geometry and integrand from the one kernel.
    (Compiled numba functions freeze their globals, so the change is made on the ``py_func`` sources; the
    disk cache of Lm at known poses is off, since it keys on the kernel's file, not on a patched function.)"""
    model = default_coupling()
    model.lm_h(0.0, 0.0, 0.2)                       # the table, from the disk cache as usual
    monkeypatch.setenv("DRONEWPT_CACHE_DIR", "")    # then no cache of Lm at poses
    dx, dy, dz, tilt, axis = (v[:3] for v in _poses())
    _use_py_funcs(monkeypatch)
    before = model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis), model.lm_exact_h(dx, dy, dz, tilt, tilt_axis_rad=axis)
    plain = ck._integrand
    monkeypatch.setattr(ck, "_integrand", lambda f, x, y, tx, ty: 1.5 * plain(f, x, y, tx, ty))
    after = model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis), model.lm_exact_h(dx, dy, dz, tilt, tilt_axis_rad=axis)
    for b, a in zip(before, after):
        np.testing.assert_allclose(a, 1.5 * b, rtol=1e-14)
    # and a change to the table's spline weights reaches lm_h (and not the exact field)
    monkeypatch.setattr(ck, "_integrand", plain)
    weights = ck._weights
    monkeypatch.setattr(ck, "_weights", lambda x: (weights(x)[0], tuple(1.01 * w for w in weights(x)[1])))
    np.testing.assert_allclose(model.lm_h(dx, dy, dz, tilt, tilt_axis_rad=axis), 1.01 ** 2 * before[0], rtol=1e-12)
    np.testing.assert_allclose(model.lm_exact_h(dx, dy, dz, tilt, tilt_axis_rad=axis), before[1], rtol=1e-14)
