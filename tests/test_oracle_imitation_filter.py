"""oracle_imitation_filtered (policies/oracle_imitation_filter.py; docs/rl.md, "A safety filter on the learned
after-stop sequence"): the learned sequence as the reference of a filter on the modal MPC's model."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("daqp")

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "policies" / "pretrained" / "oracle_imitation_s0.npz"


@pytest.fixture(autouse=True)
def _registry_restored(monkeypatch):
    """The test policies registered here (``t_*``) leave the registry as they found it."""
    import policies
    monkeypatch.setattr(policies, "_REGISTRY", dict(policies._REGISTRY))


def _register(name, cls=None, **options):
    from policies import register
    from policies.oracle_imitation_filter import OracleImitationFilteredPolicy
    register(name, lambda ctx, **kw: (cls or OracleImitationFilteredPolicy)(ctx, path=SHIPPED, **options, **kw))
    return name


def test_a_filter_that_never_binds_plays_the_clone_bit_for_bit():
    """With a limit no predicted peak reaches (1 = twice the short-mode current) the duties of both corrections are
    the plain clone's in closed loop, bit for bit (battery_low windows 300-302, modal link), re-timed or not; a
    binding limit changes them after the stop only."""
    from envs import SbarChargingVectorEnv
    from policies import register
    from policies.compare import run_policies
    from policies.oracle_imitation import OracleImitationPolicy

    def clone10(ctx, **kw):
        pol = OracleImitationPolicy(ctx, path=SHIPPED)
        pol.model["slow"] = np.array(1.0)
        return pol
    register("t_clone10", clone10)
    names = [f"oracle_imitation:{SHIPPED}", "t_clone10", _register("t_qp1", limit=1.0, correction="qp", slow=None),
             _register("t_rate1", limit=1.0, correction="rate", lam=None, slow=None),
             _register("t_qp1_10", limit=1.0, correction="qp", slow=1.0),
             _register("t_qp0", limit=0.0, correction="qp", slow=1.0)]
    r = run_policies(names, "battery_low", 3, 300)
    d = {n: r[n].d_short for n in names}
    np.testing.assert_array_equal(d["t_qp1"], d[names[0]])
    np.testing.assert_array_equal(d["t_rate1"], d[names[0]])
    np.testing.assert_array_equal(d["t_qp1_10"], d["t_clone10"])
    assert not np.array_equal(d["t_clone10"], d[names[0]])
    venv = SbarChargingVectorEnv(num_envs=3, scenario="battery_low")
    venv.reset(seed=300)
    for i, k0 in enumerate(venv._stop_k):
        np.testing.assert_array_equal(d["t_qp0"][:k0, i], d["t_clone10"][:k0, i])
    assert not np.array_equal(d["t_qp0"], d["t_clone10"])


def test_rate_filter_takes_the_fastest_rate_within_its_limit():
    """In closed loop (battery_low windows 300-303, limit 0: it binds), every rate the filter takes keeps the
    predicted peak within the limit, or, where no rate does, within 1 mA of the least over the rates it may take
    (the floor); and no faster rate it may take would have (the least change)."""
    from policies.compare import run_policies
    from policies.oracle_imitation_filter import OracleImitationFilteredPolicy
    seen = []

    class Checked(OracleImitationFilteredPolicy):
        def _choose(self, idx, seq, tau, j, rate, vl):
            out = super()._choose(idx, seq, tau, j, rate, vl)
            z = self._z[idx]
            rates = np.asarray(self.rates)
            for i in range(len(idx)):
                peaks = []
                for r in rates:
                    one = np.array([r])
                    st = np.array([0.0 if j[i] == 0 else tau[i] + r])
                    p, lim = self._rows(idx[i:i + 1], z[i:i + 1], vl[i:i + 1], seq[i:i + 1], st, one)
                    peaks.append(p[0])
                peaks = np.array(peaks)
                may = rates <= rate[i]
                bound = max(lim[0], peaks[may].min() + 1e-3)
                k = int(np.flatnonzero(rates == out[i])[0])
                assert may[k] and peaks[k] <= bound
                assert not np.any(may[:k] & (peaks[:k] <= bound))
                seen.append(out[i])
            return out
    _register("t_rate_checked", Checked, limit=0.0, correction="rate", lam=None, slow=1.0, max_lag=200)
    r = run_policies(["t_rate_checked"], "battery_low", 4, 300)
    assert np.all(r["t_rate_checked"].metrics["reached_short_mode"])
    assert min(seen) < 1.0   # it bound


def test_qp_correction_brings_the_predicted_peak_to_its_limit():
    """Where the plan of the learned sequence predicts a peak above the limit, the least change the QP finds brings
    the MPC's (nonlinear) prediction of the changed plan to the limit plus the slack the QP kept (the least violation
    where the limit cannot be met), to the linearisation's error (0.01 A, ~0.1 point), and always below the unchanged
    plan's peak (battery_low windows 300-303, limit 0, the filter at the stop)."""
    from policies.compare import run_policies
    from policies.oracle_imitation_filter import OracleImitationFilteredPolicy
    seen = []

    class Checked(OracleImitationFilteredPolicy):
        def _project(self, z, vl, ref, rows, lim, locked):
            out = super()._project(z, vl, ref, rows, lim, locked)
            after = self._mpc.predicted_rows(z, vl, out, locked)[0].max(axis=1)
            seen.append(self.last_slack)
            assert np.all(after <= lim + self.last_slack + 0.01)
            assert np.all(after < rows.max(axis=1))
            return out
    _register("t_qp_checked", Checked, limit=0.0, correction="qp", slow=1.0, every_period=False, smooth=300.0)
    r = run_policies(["t_qp_checked"], "battery_low", 4, 300)
    assert len(seen) >= 2
    assert np.all(r["t_qp_checked"].metrics["reached_short_mode"])


@pytest.mark.parametrize("options, names", [
    ({"limit": -0.1}, ["limit=-0.1", "[0, 1]"]), ({"limit": float("nan")}, ["limit=nan", "[0, 1]"]),
    ({"slow": 0.5}, ["slow=0.5", "[1, 10]"]), ({"rates": (0.9, 0.5)}, ["rates=(0.9, 0.5)", "the first 1.0"]),
    ({"rates": (1.0, 1.0)}, ["rates=(1.0, 1.0)", "descending"]), ({"rates": "fast"}, ["rates='fast'", "descending"]),
    ({"rates": (1.0, -0.5)}, ["rates=(1.0, -0.5)", "[0, 1]"]), ({"max_lag": -1}, ["max_lag=-1", "0..200"]),
    ({"max_lag": 2.5}, ["max_lag=2.5", "0..200"]), ({"lock": "yes"}, ["lock='yes'", "True, False"]),
    ({"every_period": 1}, ["every_period=1", "True, False"]), ({"lam": -1.0}, ["lam=-1.0", "[0, inf] J per point"]),
    ({"correction": "mpc"}, ["correction='mpc'", "qp, rate"]), ({"smooth": -2.0}, ["smooth=-2.0", "[0, inf]"]),
    ({"trust": 0.0}, ["trust=0.0", "(0, inf] V"]), ({"limit": "x"}, ["limit='x'", "[0, 1]"]),
    ({"lam": "x"}, ["lam='x'", "[0, inf]"]), ({"smooth": "x"}, ["smooth='x'", "[0, inf]"]),
    ({"trust": "x"}, ["trust='x'", "(0, inf] V"]), ({"slow": "x"}, ["slow='x'", "[1, 10]"])])
def test_bad_options_are_refused_with_one_line(options, names):
    from policies import make
    with pytest.raises(ValueError) as exc:
        make(f"oracle_imitation_filtered:{SHIPPED}", **options)
    msg = str(exc.value)
    assert "\n" not in msg and all(n in msg for n in names), msg


def test_lock_is_refused_on_eq4_link():
    from envs import EnvConfig, SbarChargingVectorEnv
    from policies import make
    venv = SbarChargingVectorEnv(num_envs=1, scenario="nominal", config=EnvConfig(link_model="envelope"))
    with pytest.raises(ValueError) as exc:
        make("oracle_imitation_filtered", venv.policy_context, lock=True)
    assert str(exc.value) == "lock=True is invalid on link_model='envelope'; valid: lock=False, or the modal link"
    make("oracle_imitation_filtered", venv.policy_context)   # unlocked: eq. 4's MPC model


@pytest.mark.parametrize("correction", ["rate", "qp"])
def test_the_phase_locked_filter_runs_on_the_modal_link(correction):
    """``lock=True`` predicts the locked rows with the MPC's gate (|w| <= its tail's); one battery_low window in closed
    loop reaches short mode with either correction (the gate was once looked up from a name not imported)."""
    from policies.compare import run_policies
    name = _register(f"t_lock_{correction}", limit=0.0, correction=correction, lock=True, slow=1.0)
    r = run_policies([name], "battery_low", 1, 300)
    assert np.all(r[name].metrics["reached_short_mode"])
