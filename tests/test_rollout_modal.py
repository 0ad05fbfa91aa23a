"""The oracle's compiled replay on the exact-mode link (envs.rollout with ``link_model="modal"``): the same numbers
as the env stepped from Python, on nominal and detuned windows, with and without a duty prefix shared by every row
(the replay's prefix cache); a closed-loop policy's duties replayed reproduce its metrics; eq. 4's env keeps its
Python path for detuned windows (its replay step has no complex envelope)."""

import numpy as np
import pytest

from envs import EnvConfig
from envs.rollout import DutyRollout
from policies.compare import run_policy

MODAL = EnvConfig(link_model="modal")
EQ4 = EnvConfig(link_model="envelope")   # named: the envs' default is the modal link since 2026-11-26
FIELDS = ("energy_j", "i2_peak_a", "rect_current_a", "overshoot", "reached_short_mode")


def _candidates(base, k0, seed, shared_prefix):
    """Four sequences: ``base`` and three perturbed after the stop step ``k0`` (the last one also before it when
    not ``shared_prefix``)."""
    rng = np.random.default_rng(seed)
    d = np.repeat(base[None], 4, axis=0)
    d[1:, k0:] = np.clip(d[1:, k0:] + 0.2 * rng.standard_normal((3, d.shape[1] - k0)), 0.0, 1.0)
    if not shared_prefix:
        d[3, :k0] = np.clip(d[3, :k0] + 0.01, 0.0, 1.0)
    return d


@pytest.mark.parametrize("scenario,seed", [("nominal", 1000), ("detuned", 1001), ("detuned_wide", 3)])
def test_compiled_modal_replay_is_the_python_step(scenario, seed):
    """Bit-identical to ``env.step`` (both run the same compiled link step; the replay only drops the Python
    between steps), detuned windows included (their C1, C2 are in the link constants); and the windows differ
    (a detuned tank moves the energy), so equality is not trivial."""
    base = run_policy("model_based", scenario, 1, seed, config=MODAL).d_short[:, 0]
    fast = DutyRollout(scenario, seed, MODAL)
    slow = DutyRollout(scenario, seed, MODAL, compiled=False)
    for shared in (True, False):
        d = _candidates(base, fast.stop_k, seed, shared)
        a, b = fast.run(d), slow.run(d)
        for f in FIELDS:
            assert np.array_equal(getattr(a, f), getattr(b, f)), f
        assert a.overshoot == pytest.approx(a.ratios.max(axis=1), abs=1e-12)
        assert not np.array_equal(a.energy_j[0], a.energy_j[1])


def test_modal_replay_reproduces_the_closed_loop():
    """A policy's duties replayed open loop on the modal env give its closed-loop overshoot and short-mode flag
    to the bit and its energy after the stop to the order of the sum."""
    tr = run_policy("model_based_budget:0.02", "nominal", 2, 1000, config=MODAL)
    for i in range(2):
        r = DutyRollout("nominal", 1000 + i, MODAL).run(np.stack([tr.d_short[:, i]] * 2))
        assert np.all(100.0 * r.overshoot == tr.metrics["overshoot_pct"][i])
        assert r.energy_after_stop_j == pytest.approx(np.full(2, tr.metrics["energy_after_stop_j"][i]), rel=1e-12)
        assert np.all(r.reached_short_mode)


def test_envelope_detuned_window_steps_from_python():
    """Eq. 4's env: a detuned window is replayed through ``env.step`` (its compiled replay is the tuned step),
    a tuned window through the compiled loop; the modal env replays both compiled."""
    assert DutyRollout("detuned", 1001, EQ4)._detuned_envelope
    assert not DutyRollout("nominal", 1001, EQ4)._detuned_envelope
    assert not DutyRollout("detuned", 1001, MODAL)._detuned_envelope
    assert not DutyRollout("detuned", 1001)._detuned_envelope   # the default: the modal link
    base = run_policy("model_based", "detuned", 1, 1001, EQ4).d_short[:, 0]
    a = DutyRollout("detuned", 1001, EQ4).run(np.stack([base] * 2))
    b = DutyRollout("detuned", 1001, EQ4, compiled=False).run(np.stack([base] * 2))
    for f in FIELDS:
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
