"""Coupling from coil geometry against closed forms and an independent Neumann double integral."""

import json
import math

import numpy as np
import pytest

from wpt_receiver import TABLE_I
from wpt_receiver.coupling import (MU0, NOMINAL_GAP_M, CoilGeometry, CouplingModel, default_coupling,
                                   default_rx_coil, default_tx_coil, loop_self_h, mutual_coaxial_h, spiral_coil)


def neumann_double(c1, n1, r1, c2, n2, r2, n=400):
    """Brute-force Neumann integral mu0/4pi oint oint dl1.dl2/|x1-x2| for two loops (centre, normal, radius)."""
    def frame(nrm):
        nrm = np.asarray(nrm, float) / np.linalg.norm(nrm)
        u = np.cross(nrm, [0, 1, 0] if abs(nrm[1]) < 0.9 else [1, 0, 0])
        u /= np.linalg.norm(u)
        return u, np.cross(nrm, u)
    th = 2 * np.pi * np.arange(n) / n
    u1, v1 = frame(n1)
    u2, v2 = frame(n2)
    p1 = np.asarray(c1) + r1 * (np.cos(th)[:, None] * u1 + np.sin(th)[:, None] * v1)
    p2 = np.asarray(c2) + r2 * (np.cos(th)[:, None] * u2 + np.sin(th)[:, None] * v2)
    t1 = r1 * (-np.sin(th)[:, None] * u1 + np.cos(th)[:, None] * v1)
    t2 = r2 * (-np.sin(th)[:, None] * u2 + np.cos(th)[:, None] * v2)
    d = np.linalg.norm(p1[:, None, :] - p2[None, :, :], axis=-1)
    return MU0 / (4 * np.pi) * np.sum((t1 @ t2.T) / d) * (2 * np.pi / n) ** 2


def test_default_calibration_matches_table_i():
    m = default_coupling()
    assert m.l1_h == pytest.approx(236e-6, rel=1e-9)
    assert m.l2_h == pytest.approx(18.9e-6, rel=1e-9)
    assert m.lm_exact_h(0, 0, NOMINAL_GAP_M) == pytest.approx(6.25e-6, rel=1e-9)
    assert m.lm_h(0, 0, NOMINAL_GAP_M) == pytest.approx(6.25e-6, rel=1e-6)
    p = m.link_params(TABLE_I, m.lm_h(0, 0, NOMINAL_GAP_M))
    assert p.k == pytest.approx(TABLE_I.k, rel=1e-6)
    # physically plausible: pad ~0.5 m, drone coil ~0.24 m, hover gap 0.1-0.3 m, wires don't overlap
    assert 0.4 < 2 * default_tx_coil().outer_radius_m < 0.6 and 0.2 < 2 * default_rx_coil().outer_radius_m < 0.3
    assert 0.1 < NOMINAL_GAP_M < 0.3


def test_maxwell_formula_against_independent_neumann_integral():
    for a, b, d in ((0.1, 0.1, 0.05), (0.25, 0.08, 0.17), (0.2, 0.12, 0.6)):
        ref = neumann_double([0, 0, 0], [0, 0, 1], a, [0, 0, d], [0, 0, 1], b)
        assert mutual_coaxial_h(a, b, d) == pytest.approx(ref, rel=1e-6)
    # far field: dipole limit mu0 pi a^2 b^2 / (2 d^3)
    a, b, d = 0.1, 0.05, 20.0
    assert mutual_coaxial_h(a, b, d) == pytest.approx(MU0 * np.pi * a**2 * b**2 / (2 * d**3), rel=1e-4)
    # thin-loop self inductance formula sanity: grows with radius, positive
    assert 0 < loop_self_h(0.05, 1e-3) < loop_self_h(0.1, 1e-3)


def test_coaxial_general_path_matches_summed_maxwell():
    m = default_coupling()
    tx, rx = m.tx, m.rx
    for dz in (0.05, NOMINAL_GAP_M, 0.4):
        a = np.array(tx.radius_m)[:, None]
        b = np.array(rx.radius_m)[None, :]
        maxwell = float(np.sum(mutual_coaxial_h(a, b, dz + np.array(rx.z_m)[None, :] - np.array(tx.z_m)[:, None])))
        assert m.lm_exact_h(0, 0, dz) == pytest.approx(maxwell, rel=1e-6)
        assert m.lm_h(0, 0, dz) == pytest.approx(maxwell, rel=1e-6)


def test_off_axis_and_tilt_against_brute_force_and_refinement():
    one_tx = CoilGeometry((0.2,), (0.0,), 1e-3)
    one_rx = CoilGeometry((0.1,), (0.0,), 1e-3)
    m = CouplingModel(one_tx, one_rx)
    for dx, dy, dz, tilt in ((0.1, 0.0, 0.15, 0.0), (0.07, -0.12, 0.2, 0.25), (0.3, 0.05, 0.1, -0.4)):
        # tilt about the y axis turns the receiver normal towards +x
        nrm = [math.sin(tilt), 0.0, math.cos(tilt)]
        ref = neumann_double([0, 0, 0], [0, 0, 1], 0.2, [dx, dy, dz], nrm, 0.1)
        assert m.lm_exact_h(dx, dy, dz, tilt, n_theta=64) == pytest.approx(ref, rel=1e-6)
        assert m.lm_h(dx, dy, dz, tilt) == pytest.approx(ref, rel=1e-5)
    # refinement of the loop quadrature converges (differences shrink) for the real coils
    big = default_coupling()
    pose = (0.22, 0.05, 0.09, 0.2)
    vals = [big.lm_exact_h(*pose, n_theta=n) for n in (8, 16, 32, 64)]
    diffs = np.abs(np.diff(vals))
    assert diffs[0] > diffs[1] > diffs[2] and diffs[2] < 1e-9 * abs(vals[-1])


def test_symmetries_and_orderings():
    m = default_coupling()
    g = NOMINAL_GAP_M
    dx, dy = np.array([0.03, 0.08, 0.15]), np.array([0.05, 0.01, 0.11])
    a = m.lm_h(dx, dy, g)
    np.testing.assert_allclose(m.lm_h(dy, dx, g), a, rtol=1e-9)
    np.testing.assert_allclose(m.lm_h(-dx, dy, g), a, rtol=1e-9)
    np.testing.assert_allclose(m.lm_h(dx, -dy, g), a, rtol=1e-9)
    # tilt about y: mirror x and the tilt together
    np.testing.assert_allclose(m.lm_h(dx, dy, g, 0.2), m.lm_h(-dx, dy, g, -0.2), rtol=1e-9)
    # Lm falls with height, lateral offset and tilt at the hover pose
    z = np.linspace(0.1, 0.6, 6)
    assert np.all(np.diff(m.lm_h(0 * z, 0 * z, z)) < 0)
    r = np.linspace(0.0, 0.15, 6)
    assert np.all(np.diff(m.lm_h(r, 0 * r, g)) < 0)
    assert m.lm_h(0, 0, g, 0.3) < m.lm_h(0, 0, g, 0.1) < m.lm_h(0, 0, g)


def test_geometry_validation_names_the_bad_value():
    with pytest.raises(ValueError, match="wire_radius_m"):
        CoilGeometry((0.1,), (0.0,), -1.0)
    with pytest.raises(ValueError, match="z_m"):
        CoilGeometry((0.1, 0.09), (0.0,), 1e-3)
    with pytest.raises(ValueError, match="wires would overlap"):
        spiral_coil(5, 0.1, 1e-3, 1e-3)
    with pytest.raises(ValueError, match="radius_m"):
        CoilGeometry((0.0005,), (0.0,), 1e-3)


def test_cli_coupling_json(capsys):
    from mission_sim.cli import main
    assert main(["coupling", "--dx", "0", "--dy", "0", "--dz", str(NOMINAL_GAP_M), "--format", "json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["lm_h"] == pytest.approx(6.25e-6, rel=1e-6)
    assert out["l1_h"] == pytest.approx(236e-6, rel=1e-9) and out["l2_h"] == pytest.approx(18.9e-6, rel=1e-9)
    assert out["k"] == pytest.approx(TABLE_I.k, rel=1e-6)
    assert len(out["tx_turns"]) == 20 and len(out["rx_turns"]) == 8
    assert out["rx_turns"][0]["z_m"] == pytest.approx(NOMINAL_GAP_M)
    assert main(["coupling", "--dz", "-1"]) == 2


@pytest.mark.parametrize("pose", [(0.0, -0.006, 0.022, -0.02), (0.0, -0.184, 0.036, -0.02), (0.05, 0.1, 0.03, 0.0)])
def test_table_near_the_pad_gives_the_exact_field(pose):
    """Within 4 cm of the table's lower edge (2 cm) lm_h takes the exact field for the whole pose: the spline's
    mirror edge gave 2 % of the hover Lm off at a 2.2 cm gap and 7e-4 at the mission's 3-4 cm (2026-11-27 audit)."""
    m = default_coupling()
    ref = m.lm_exact_h(*pose, n_theta=96)
    assert m.lm_h(*pose) == pytest.approx(m.lm_exact_h(*pose), rel=1e-12)
    assert abs(m.lm_h(*pose) - ref) < 2e-5 * 6.25e-6


def test_lm_centred_is_the_table_lm_over_the_pad_centre():
    """``CouplingModel.lm_centred_h`` (Maxwell's coaxial formula over the turn pairs: what the pad-gate warning's
    'what the coils reach' reads, without the compiled table) equals ``lm_h`` of the centred, level receiver from
    contact to 10 cm, and falls with the height."""
    from wpt_receiver.coupling import default_coupling
    m = default_coupling()
    dz = np.array([m.clearance_m(), 0.02, 0.05, 0.1])
    centred = np.array([m.lm_centred_h(float(z)) for z in dz])
    assert centred == pytest.approx([float(m.lm_h(0.0, 0.0, float(z))) for z in dz], rel=1e-12)
    assert np.all(np.diff(centred) < 0)
