"""The charge command (the reference) of a batch of windows, compiled (:mod:`envs.command_kernel`, the one
source of :func:`envs.scenario.command_profile`): cmd0 until the change, cmd1 until the stop, then 0, on the
step grid ``t = k dt``; the same numbers uncompiled, serial and in parallel chunks, in a new array or a
step-major store."""

import numpy as np
import pytest

pytest.importorskip("numba")

from envs.scenario import SCENARIOS, EpisodeDraw, command_profile, draw_episodes  # noqa: E402


def _draw(tc, ts, c0, c1) -> EpisodeDraw:
    n = len(tc)
    z = np.zeros(n)
    return EpisodeDraw(soc0=z, lm_scale=z + 1, wind_speed_m_s=z, record_u=z, cmd0_a=np.asarray(c0, float),
                       cmd1_a=np.asarray(c1, float), t_change_s=np.asarray(tc, float), t_stop_s=np.asarray(ts, float),
                       noise=None)


def test_the_command_steps_at_the_change_and_the_stop():
    dt = 1e-3
    # a change at exactly step 3's time (t = 3 dt: the command at step 3 is already cmd1), one between steps,
    # a change after the stop (cmd0 to the change, then 0), one never stopping within the window
    b = _draw([3 * dt, 4.5e-3, 8e-3, 2e-3], [6e-3, 7.2e-3, 5e-3, 1.0], [2.0, 3.0, 4.0, 5.0], [7.0, 6.0, 1.0, 2.5])
    cmd = command_profile(b, 10, dt)
    assert cmd.shape == (4, 11)
    np.testing.assert_array_equal(cmd[0], [2, 2, 2, 7, 7, 7, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(cmd[1], [3, 3, 3, 3, 3, 6, 6, 6, 0, 0, 0])
    np.testing.assert_array_equal(cmd[2], [4, 4, 4, 4, 4, 4, 4, 4, 0, 0, 0])
    np.testing.assert_array_equal(cmd[3], [5, 5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5, 2.5])


@pytest.mark.parametrize("chunks", [2, 7])
def test_compiled_uncompiled_and_parallel_commands_are_the_same_bits(chunks):
    rngs = [np.random.default_rng(s) for s in range(300)]
    b = draw_episodes(rngs, SCENARIOS["random"], 301)
    ref = command_profile(b, 301, 1e-4, compiled=False)
    store = np.full((302, 300), np.nan)   # the env's step-major store, written in place
    got = command_profile(b, 301, 1e-4, out=store, n_chunks=chunks)
    assert got.base is store or got.base is store.base
    assert ref.tobytes() == np.ascontiguousarray(got).tobytes() == command_profile(b, 301, 1e-4).tobytes()
    assert np.all(ref[:, 0] == b.cmd0_a) and np.all(ref[:, -1] == 0.0)   # stopped within 16 ms < 30 ms
