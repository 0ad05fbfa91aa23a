"""The vector env's compiled draws (:mod:`envs.draw_kernel`) give numpy's numbers to the bit and leave every
generator in the state numpy's calls leave it in: ``rng.random(out=u[i])`` then
``rng.standard_normal(out=noise[i])`` per window, serial and in parallel chunks, the ziggurat's rare
branches (the tail beyond r and the wedges) taken many times."""

import numpy as np
import pytest

pytest.importorskip("numba")

from envs.draw_kernel import Draws, bitgen_addresses, draw_rows  # noqa: E402

#: numpy's ziggurat's base-layer edge: a normal beyond it comes only from the tail branch (idx == 0)
_R = 3.6541528853610088


def _numpy(rngs, k, t):
    u, z = np.empty((len(rngs), k)), np.empty((len(rngs), t))
    for i, rng in enumerate(rngs):
        rng.random(out=u[i])
        rng.standard_normal(out=z[i])
    return u, z


def _same(a, b) -> bool:
    """Bit-generator states equal (dicts of ints, arrays: MT19937's key)."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b


def _extra_raw_draws(seed, n_normals, end_state):
    """How many 64-bit draws beyond one per normal a generator of ``seed`` made to reach ``end_state``
    (the ziggurat takes one per normal on its fast path and more on the wedge and tail branches)."""
    g = np.random.default_rng(seed)
    g.bit_generator.random_raw(n_normals)
    for extra in range(n_normals):
        if g.bit_generator.state == end_state:
            return extra
        g.bit_generator.random_raw(1)
    raise AssertionError("end state not reached")


@pytest.mark.parametrize("chunks", [1, 7])
def test_compiled_draws_are_numpys_to_the_bit(chunks):
    seeds = range(1000, 1600)
    mine = [np.random.default_rng(s) for s in seeds]
    ref = [np.random.default_rng(s) for s in seeds]
    k, t = 12, 2000
    for _ in range(2):   # twice: the second draws start from the states the first left
        u, z = np.empty((len(mine), k)), np.empty((len(mine), t))
        draw_rows(bitgen_addresses(mine), u, z, chunks)
        ur, zr = _numpy(ref, k, t)
        assert u.tobytes() == ur.tobytes() and z.tobytes() == zr.tobytes()
        for a, b in zip(mine, ref):
            assert a.bit_generator.state == b.bit_generator.state
        assert mine[0].standard_normal() == ref[0].standard_normal()   # and the streams go on alike
    assert np.sum(np.abs(zr) > _R) > 100   # the tail branch (log1p) gave > 100 of the compared normals
    # the wedge branch (exp: one more double per try) was taken: more draws than the fast path and tail explain
    fresh = np.random.default_rng(1000)
    zf = np.empty((1, 20000))
    draw_rows(bitgen_addresses([fresh]), np.empty((1, 0)), zf, 1)
    extra = _extra_raw_draws(1000, zf.shape[1], fresh.bit_generator.state)
    assert extra > 2 * np.sum(np.abs(zf) > _R) + 50
    np.testing.assert_array_equal(zf, np.random.default_rng(1000).standard_normal((1, 20000)))


def test_other_bit_generators_and_fallback():
    """Any numpy bit generator (its own C functions); anything but a numpy Generator: nothing drawn."""
    for bg in (np.random.MT19937, np.random.Philox, np.random.SFC64, np.random.PCG64DXSM):
        mine, ref = [np.random.Generator(bg(s)) for s in range(5)], [np.random.Generator(bg(s)) for s in range(5)]
        u, z = np.empty((5, 3)), np.empty((5, 400))
        draw_rows(bitgen_addresses(mine), u, z, 2)
        ur, zr = _numpy(ref, 3, 400)
        assert u.tobytes() == ur.tobytes() and z.tobytes() == zr.tobytes(), bg
        assert all(_same(a.bit_generator.state, b.bit_generator.state) for a, b in zip(mine, ref))
    draws = Draws()
    assert not draws([np.random.default_rng(1), np.random.RandomState(2)], np.empty((2, 1)), np.empty((2, 1)), 1)
    rngs = [np.random.default_rng(3)]
    u = np.empty((1, 2))
    assert draws(rngs, u, np.empty((1, 5)), 1) and draws(rngs, u, np.empty((1, 5)), 1)   # addresses reused
    ref = np.random.default_rng(3)
    ref.random(2), ref.standard_normal(5), ref.random(2), ref.standard_normal(5)
    assert rngs[0].bit_generator.state == ref.bit_generator.state


def test_a_generator_shared_by_windows_is_drawn_in_order():
    """One generator in two windows' slots (numpy's calls draw from it window after window): the same numbers,
    on one thread whatever the chunks."""
    g, h = np.random.default_rng(5), np.random.default_rng(6)
    gr, hr = np.random.default_rng(5), np.random.default_rng(6)
    u, z = np.empty((4, 2)), np.empty((4, 300))
    assert Draws()([g, h, g, h], u, z, 4)
    ur, zr = _numpy([gr, hr, gr, hr], 2, 300)
    assert u.tobytes() == ur.tobytes() and z.tobytes() == zr.tobytes()
    assert g.bit_generator.state == gr.bit_generator.state and h.bit_generator.state == hr.bit_generator.state
