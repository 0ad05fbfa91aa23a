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
        draw_rows(bitgen_addresses(mine), u, z, 1.0, chunks)
        ur, zr = _numpy(ref, k, t)
        assert u.tobytes() == ur.tobytes() and z.tobytes() == zr.tobytes()
        for a, b in zip(mine, ref):
            assert a.bit_generator.state == b.bit_generator.state
        assert mine[0].standard_normal() == ref[0].standard_normal()   # and the streams go on alike
    assert np.sum(np.abs(zr) > _R) > 100   # the tail branch (log1p) gave > 100 of the compared normals
    # the wedge branch (exp: one more double per try) was taken: more draws than the fast path and tail explain
    fresh = np.random.default_rng(1000)
    zf = np.empty((1, 20000))
    draw_rows(bitgen_addresses([fresh]), np.empty((1, 0)), zf, 1.0, 1)
    extra = _extra_raw_draws(1000, zf.shape[1], fresh.bit_generator.state)
    assert extra > 2 * np.sum(np.abs(zf) > _R) + 50
    np.testing.assert_array_equal(zf, np.random.default_rng(1000).standard_normal((1, 20000)))


def test_other_bit_generators_and_fallback():
    """Any numpy bit generator (its own C functions); anything but a numpy Generator: nothing drawn."""
    for bg in (np.random.MT19937, np.random.Philox, np.random.SFC64, np.random.PCG64DXSM):
        mine, ref = [np.random.Generator(bg(s)) for s in range(5)], [np.random.Generator(bg(s)) for s in range(5)]
        u, z = np.empty((5, 3)), np.empty((5, 400))
        draw_rows(bitgen_addresses(mine), u, z, 1.0, 2)
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


def _fingerprint(env, steps: int, seed_actions: int = 7) -> str:
    """SHA-1 of every observation and reward of ``steps`` random-action steps (autoresets included)."""
    import hashlib

    rng, h = np.random.default_rng(seed_actions), hashlib.sha1()
    for _ in range(steps):
        obs, rew, *_ = env.step(rng.uniform(-1, 1, (env.num_envs, 1)).astype(np.float32))
        h.update(obs.tobytes()), h.update(rew.tobytes())
    return h.hexdigest()


def _venv(n=64):
    from envs.core import EnvConfig
    from envs.vector import SbarChargingVectorEnv

    return SbarChargingVectorEnv(n, scenario="nominal", config=EnvConfig(link_model="envelope"), num_threads=1)


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_env_draws_from_its_own_generators(how):
    """A deepcopy / pickle round trip of an env mid-episode: the copy and the original go on independently, each
    as a fresh env stepped the same way (the review found the copy's cached addresses pointing at the original's
    generators: the copy advanced them, and a copy pickled into another process crashed)."""
    import copy
    import pickle

    steps = 330   # past the autoreset of the 301-step windows: the compiled draws run again
    ref = _venv()
    ref.reset(seed=5)
    _fingerprint(ref, 60)
    want = _fingerprint(ref, steps)
    env = _venv()
    env.reset(seed=5)
    _fingerprint(env, 60)
    cp = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    assert _fingerprint(cp, steps) == want
    assert _fingerprint(env, steps) == want   # the original's generators were not advanced by the copy


def test_a_pickled_env_steps_in_another_process(tmp_path):
    import pickle
    import subprocess
    import sys

    env = _venv()
    env.reset(seed=9)
    _fingerprint(env, 40)
    path = tmp_path / "env.pkl"
    path.write_bytes(pickle.dumps(env))
    want = _fingerprint(env, 300)
    code = ("import pickle, sys; sys.path[:0] = [%r, %r]; import test_draw_kernel as t; "
            "print(t._fingerprint(pickle.loads(open(%r, 'rb').read()), 300))"
            % (str(__import__("pathlib").Path(__file__).parent), str(__import__("pathlib").Path(__file__).parents[1]), str(path)))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == want


def test_reset_with_a_new_seed_and_a_reinitialised_generator_look_the_generators_up_again():
    """``reset(seed=B)`` after an autoreset under seed A equals a fresh env seeded B; a generator given a new
    bit generator (``g.__init__(PCG64(k))``, the same Generator object) is drawn from its new state."""
    env, fresh = _venv(), _venv()
    env.reset(seed=1)
    _fingerprint(env, 310)
    env.reset(seed=2)
    fresh.reset(seed=2)
    assert _fingerprint(env, 320) == _fingerprint(fresh, 320)

    draws, g = Draws(), np.random.default_rng(1)
    u, z = np.empty((1, 3)), np.empty((1, 50))
    assert draws([g], u, z, 1)
    g.__init__(np.random.PCG64(99))
    assert draws([g], u, z, 1)
    ru, rz = _numpy([np.random.default_rng(99)], 3, 50)
    assert u.tobytes() == ru.tobytes() and z.tobytes() == rz.tobytes()


def test_the_self_check_falls_back_to_numpy_when_the_compiled_draws_disagree(monkeypatch):
    import envs.draw_kernel as dk

    assert dk.compiled_draws_agree()
    monkeypatch.setattr(dk, "_AGREE", [False])
    u, z = np.empty((2, 3)), np.empty((2, 10))
    assert Draws()([np.random.default_rng(0), np.random.default_rng(1)], u, z, 1) is False


@pytest.mark.parametrize("chunks", [1, 3])
def test_the_noise_scale_is_taken_per_number_in_the_draws(chunks):
    """``scale``: every normal times the sensor noise's standard deviation, the product numpy's multiply gives
    (the store holds the noise itself; no pass of its own over it), written through a transposed view."""
    seeds = range(40)
    mine = [np.random.default_rng(s) for s in seeds]
    ref = [np.random.default_rng(s) for s in seeds]
    store = np.empty((300, len(mine)))   # step-major (T, n), as the env's noise store
    u = np.empty((len(mine), 5))
    draw_rows(bitgen_addresses(mine), u, store.T, 0.1, chunks)
    ur, zr = _numpy(ref, 5, 300)
    assert u.tobytes() == ur.tobytes()
    assert store.T.tobytes() == np.multiply(zr, 0.1).tobytes()
    assert not np.array_equal(store.T, zr)


def test_draw_episodes_scales_the_noise_alike_with_numpys_calls_and_the_compiled_draws():
    from envs.scenario import SCENARIOS, draw_episodes
    scn = SCENARIOS["random"]
    a = [np.random.default_rng(s) for s in range(9)]
    b = [np.random.default_rng(s) for s in range(9)]
    c = [np.random.default_rng(s) for s in range(9)]
    d = [np.random.default_rng(s) for s in range(9)]
    plain = draw_episodes(a, scn, 50)
    numpy_scaled = draw_episodes(b, scn, 50, noise=np.empty((50, 9)).T, scale=0.1)   # numpy's calls, strided out
    compiled = draw_episodes(c, scn, 50, fill=lambda rngs, u, z, s: Draws()(rngs, u, z, 2, s), scale=0.1)
    numpy_own = draw_episodes(d, scn, 50, scale=0.1)   # numpy's calls into its own (contiguous) array, scaled there
    assert numpy_scaled.noise.tobytes() == np.multiply(plain.noise, 0.1).tobytes()
    assert numpy_own.noise.tobytes() == np.multiply(plain.noise, 0.1).tobytes()
    assert compiled.noise.tobytes() == np.ascontiguousarray(numpy_scaled.noise).tobytes()
    assert compiled.soc0.tobytes() == plain.soc0.tobytes()


def test_restart_writes_the_compiled_envs_stores_as_the_uncompiled_ones():
    """``restart(idx)`` of some windows (not all: their draws into new arrays, then copied into the stores' columns):
    the compiled env's command and noise stores equal the uncompiled env's (numpy's calls, its noise scaled in
    :func:`envs.scenario.draw_episodes`) to the bit, the other windows' columns untouched, the same first
    observations."""
    from envs.core import EnvConfig
    from envs.vector import SbarChargingVectorEnv

    cfg = EnvConfig(n_steps=40, link_model="envelope")
    fast = SbarChargingVectorEnv(9, "random", cfg, compiled=True, num_threads=1)
    ref = SbarChargingVectorEnv(9, "random", cfg, compiled=False, num_threads=1)
    fast.reset(seed=5)
    ref.reset(seed=5)
    rng = np.random.default_rng(2)
    for _ in range(3):
        a = rng.uniform(-1, 1, (9, 1)).astype(np.float32)
        fast.step(a), ref.step(a)
    before = ref.parts.scenario.noise.copy()
    of, orf = fast.restart([1, 4, 7]), ref.restart([1, 4, 7])
    sf, sr = fast.parts.scenario, ref.parts.scenario
    assert sf.noise.tobytes() == sr.noise.tobytes() and sf.cmd.tobytes() == sr.cmd.tobytes()
    kept = [0, 2, 3, 5, 6, 8]
    assert sr.noise[:, kept].tobytes() == before[:, kept].tobytes()
    assert not np.array_equal(sr.noise[:, [1, 4, 7]], before[:, [1, 4, 7]])
    assert np.abs(sr.noise[:, [1, 4, 7]]).max() < 0.1 * 6   # the scenario's 0.1 A standard deviation, not 1
    np.testing.assert_allclose(of, orf, atol=1e-6)   # as tests/test_vector_fast.py (numpy's sums)
