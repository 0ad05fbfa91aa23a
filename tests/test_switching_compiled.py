"""The switching model's event loop (:mod:`wpt_receiver.switching.compiled`, its one source) compiled against
the same source run by the interpreter (every numba function of the module swapped for its ``py_func``).

LLVM may fuse and reorder the compiled arithmetic, so the states agree to round-off (1e-9 of each state's
scale is asserted), the topology sequences and event counts are identical and the event times agree to
femtoseconds. (Until 2026-11-27 the reference was a second, hand-written numpy copy of the loop in
:mod:`wpt_receiver.switching.link`; the physics is checked against ngspice, Table II and the ``solve_ivp``
reference elsewhere.)"""

import numpy as np
import pytest

from wpt_receiver import TABLE_I
from wpt_receiver.devices import preset
from wpt_receiver.switching import SwitchingConfig, SwitchingLink

pytest.importorskip("numba")

P = TABLE_I
T = P.rectifier_period_s


def _step25():
    """The paper's RM -> SM step, shortened for the interpreter: 1 ms of RM, 2 ms of SM."""
    n = int(round(3e-3 / T))
    return (np.arange(n) * T >= 1e-3 - 1e-12).astype(float)


def _interpreted(monkeypatch):
    """Every numba function of :mod:`wpt_receiver.switching.compiled` replaced by its ``py_func`` (module
    globals: the calls inside the loop resolve to the interpreted versions)."""
    import wpt_receiver.switching.compiled as ck
    for name, f in list(vars(ck).items()):
        if hasattr(f, "py_func"):
            monkeypatch.setattr(ck, name, f.py_func)


def _ramp():
    return np.r_[np.zeros(6), np.linspace(0.0, 1.0, 40), np.ones(10)]


CASES = {
    "ideal_step25": (SwitchingConfig(), _step25),
    "schottky_dead_time_step25": (SwitchingConfig(devices=preset("schottky"), dead_time_s=3e-7), _step25),
    "sic_cap_phase_ramp": (SwitchingConfig(gate_phase_rad=1.0, dead_time_s=3e-7, c_out_f=2e-6, r_bat_ohm=0.05,
                                           devices=preset("sic")), _ramp),
    "open_inverter_ramp": (SwitchingConfig(gate_phase_rad=-0.7, dead_time_s=1e-6, r_bat_ohm=0.02), _ramp),
}


@pytest.mark.parametrize("name", list(CASES))
def test_compiled_loop_equals_its_interpreted_source(name, monkeypatch):
    cfg, duty = CASES[name]
    d = duty()
    ref, fast = SwitchingLink(P, cfg, compiled=False), SwitchingLink(P, cfg, compiled=True)
    x0f = fast.periodic_steady_state(0.0)
    sch = fast.schedule(0.0, len(d) * T, d)
    rf = fast.run(sch, x0f)   # compiled, before the module's functions are swapped for their sources
    _interpreted(monkeypatch)
    x0r = ref.periodic_steady_state(0.0)
    scale = np.abs(x0r[:ref.cir.n]) + 1.0
    assert np.all(np.abs(x0f - x0r)[:ref.cir.n] < 1e-9 * scale)
    rr = ref.run(sch, x0f)
    assert len(rf.seg_k) == len(rr.seg_k) > len(d)  # the RM half cycles add diode events
    np.testing.assert_array_equal(rf.seg_k, rr.seg_k)
    assert np.max(np.abs(rf.seg_t - rr.seg_t)) < 1e-6 * T
    ts = np.linspace(0.0, len(d) * T, 8001)
    xr, kr = rr.states(ts)
    xf, kf = rf.states(ts)
    np.testing.assert_array_equal(kf, kr)
    err = np.max(np.abs(xf - xr), axis=0)[:ref.cir.n] / np.max(np.abs(xr), axis=0)[:ref.cir.n]
    assert np.all(err < 1e-9), err
    # the energies (closed-form integrals over the segments) agree too
    er, ef = rr.energy_balance(rr.t0, rr.t_end), rf.energy_balance(rf.t0, rf.t_end)
    assert ef["source_j"] == pytest.approx(er["source_j"], rel=1e-9)


def test_compiled_is_the_default_and_capacity_grows():
    link = SwitchingLink(P)
    assert link.compiled
    # a buffer too small for the run reports FULL (the wrapper then retries with a bigger one)
    import wpt_receiver.switching.compiled as ck
    sch = link.schedule(0.0, 40 * T, 0.3)
    x0 = link.periodic_steady_state(0.3)
    a = link._packed
    args = (sch.t, sch.cmd.astype(np.int64), sch.gate.astype(np.int64), x0, a["lam"], a["vec"], a["inv"], a["trans"],
            a["grid"], a["grows"], a["gnum"], a["gsec"], a["v2open"], a["v1open"], a["sec_th"], a["pri_th"], a["h"],
            a["T"])
    status, n_small, *_ = ck.run_kernel(*args, 5, 50)
    assert status == ck.FULL and n_small == 5
    status, n, *_ = ck.run_kernel(*args, 10_000, 50)
    assert status == ck.OK and n == len(link.run(sch, x0).seg_k)


def test_compiled_run_raises_when_stuck(monkeypatch):
    """A kernel that reports zero-length chatter ends the run with a clear error (never a hang)."""
    import wpt_receiver.switching.link as lk
    monkeypatch.setattr(lk, "_MAX_ZERO_EVENTS", -1)
    link = SwitchingLink(P, SwitchingConfig(dead_time_s=3e-7), compiled=True)
    with pytest.raises(ArithmeticError, match="zero-length events"):
        link.run(link.schedule(0.0, 4 * T, 0.0), np.r_[np.zeros(link.cir.n), 1.0])


def test_refine_finds_the_bracketed_root():
    """The Newton/bisection root finder, compiled and interpreted, returns a root of the bracketed sum of
    modes (the same one to 1e-11 T) on random sums of modes."""
    from wpt_receiver.switching.compiled import refine
    rng = np.random.default_rng(3)
    lam = np.array([-50.0 + 5.3e5j, -50.0 - 5.3e5j, -2e3 + 6.1e5j, -2e3 - 6.1e5j, 0.0])
    found = 0
    for _ in range(50):
        c = rng.normal(size=5) + 1j * rng.normal(size=5)
        c[1], c[3], c[4] = np.conj(c[0]), np.conj(c[2]), c[4].real
        g = lambda t: (c * np.exp(lam * t)).sum().real  # noqa: E731
        ts = np.linspace(0, 2 * T, 200)
        vals = np.array([g(t) for t in ts])
        j = np.nonzero((vals[:-1] > 0) & (vals[1:] <= 0))[0]
        if not len(j):
            continue
        found += 1
        a, b = ts[j[0]], ts[j[0] + 1]
        r_ref = refine.py_func(c, lam, a, g(a), b, g(b), 1e-12 * T)
        r_fast = refine(c, lam, a, g(a), b, g(b), 1e-12 * T)
        assert a <= r_fast <= b
        assert abs(r_fast - r_ref) <= 1e-11 * T
        assert abs(g(r_fast)) < 1e-6 * np.abs(c).sum()
    assert found >= 20


def _rules():
    """The link (dead time: every mode reachable), its circuit and the packed rows the mode rules read."""
    import wpt_receiver.switching.compiled as ck
    link = SwitchingLink(P, SwitchingConfig(dead_time_s=3e-7))
    return ck, link.cir, ck.mode_rows(link.cir)


def _states(cir, n=200):
    """Random augmented states at the circuit's scale (currents ~10 A, capacitor voltages ~1.5 kV)."""
    rng = np.random.default_rng(0)
    return [np.r_[rng.normal(size=cir.n) * [10, 1500, 10, 1500, 50][:cir.n], 1.0] for _ in range(n)]


def test_after_event_rules_follow_the_circuits_rows():
    """The mode rules after a guard event, written out here from the circuit's open-circuit rows and thresholds
    (not taken from the kernel; the comparisons above share them, and so does the ``solve_ivp`` reference)."""
    from wpt_receiver.switching.circuit import I1, I2, P_OPEN, PRIMARY, S_OPEN, SECONDARY
    ck, cir, rules = _rules()
    after = getattr(ck._after_event, "py_func", ck._after_event)
    th2 = cir.rect_threshold_row()
    for x in _states(cir):
        for s in SECONDARY:   # a blocked primary interval ends: freewheel the way the open-circuit voltage drives
            p, s2 = after(x.copy(), False, P_OPEN, s, False, *rules)
            assert (p, s2) == (2 if x @ cir.v1_open_row(s) > 0 else -2, s)
        for p0 in PRIMARY:
            # a blocked secondary interval ends: the diode pair of the open-circuit voltage's sign
            p, s = after(x.copy(), True, p0, S_OPEN, False, *rules)
            assert (p, s) == (p0, 1 if x @ cir.v2_open_row(p0) > 0 else -1)
            # a conducting secondary's current reaches 0: blocked unless the open-circuit voltage beats the threshold
            xx = x.copy()
            p, s = after(xx, True, p0, 1, False, *rules)
            v, th = xx @ cir.v2_open_row(p0), xx @ th2
            assert xx[I2] == 0.0 and (p, s) == (p0, 1 if v > th else (-1 if v < -th else S_OPEN))
            # chatter: the blocked state, the current zeroed
            xx = x.copy()
            p, s = after(xx, True, p0, 1, True, *rules)
            assert (p, s) == (p0, S_OPEN) and xx[I2] == 0.0
        for s0 in SECONDARY:  # a freewheeling primary's current reaches 0 with chatter: blocked, zeroed
            xx = x.copy()
            p, s = after(xx, False, 2, s0, True, *rules)
            assert (p, s) == (P_OPEN, s0) and xx[I1] == 0.0


def test_drive_change_rules_follow_the_circuits_rows():
    """The modes at a drive change, written out from the circuit: the inverter follows its command (in dead time
    the current freewheels against its sign), the SBAR shorts under its gate, else the pair of the current's sign."""
    from wpt_receiver.switching.circuit import I1, I2, P_OPEN, S_OPEN, S_SHORT
    ck, cir, rules = _rules()
    modes = getattr(ck._modes, "py_func", ck._modes)
    for x in _states(cir, 50):
        for cmd in (1, -1, 0):
            for gate in (0, 1):
                p, s = modes(x, cmd, gate, *rules)
                assert p == (cmd if cmd else (-2 if x[I1] > 0 else 2))
                assert s == (S_SHORT if gate else (1 if x[I2] > 0 else -1))
        # zero currents: decided by the open-circuit voltages against the thresholds
        x0 = x.copy()
        x0[I1] = x0[I2] = 0.0
        p, s = modes(x0, 0, 0, *rules)
        v2, th2 = x0 @ cir.v2_open_row(P_OPEN), x0 @ cir.rect_threshold_row()
        s_exp = 1 if v2 > th2 else (-1 if v2 < -th2 else S_OPEN)
        v1 = x0 @ cir.v1_open_row(s_exp)
        th1 = cir.inverter_threshold_v
        assert (p, s) == (2 if v1 > th1 else (-2 if v1 < -th1 else P_OPEN), s_exp)
