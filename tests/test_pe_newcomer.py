"""A demanding power-electronics newcomer's pass (2026-11-27 afternoon): the controller's inputs and the SBAR
mapping from Python, and ``export-controller`` with options inside its ranges. Each test failed on main."""

import math
import re
import warnings

import numpy as np
import pytest

from wpt_receiver import TABLE_I, InverseModelController, LowPassFilter, duty_from_v2_clipped
from wpt_receiver.envelope import coefficients


# ------------------------------------------------------------------ the filter Q and the control period
@pytest.mark.parametrize("tau", [1e300, 1e-300, 0.2, 9e-7, True])
def test_filter_time_constant_has_export_controllers_range(tau):
    """tau_s = 1e300 or 1e-300 gave a controller whose duty was NaN, without a word (the range was (0, inf));
    ``True`` was taken as 1 s. The range is ``export-controller --lpf-tau``'s."""
    with pytest.raises(ValueError, match=rf"^tau_s={re.escape(repr(tau))} is invalid; valid range: \[1e-06, 0.1\] s$"):
        LowPassFilter(tau)
    LowPassFilter(1e-6), LowPassFilter(0.1)                                   # the ends are valid


@pytest.mark.parametrize("order", [True, None])
def test_filter_order_refuses_a_bool_and_none(order):
    """``order=True`` built a first-order filter; ``None`` was int()'s TypeError."""
    with pytest.raises(ValueError, match=rf"^order={re.escape(repr(order))} is invalid; valid range: integer 1..8"):
        LowPassFilter(2e-4, order)


def test_control_period_above_one_second_is_refused():
    """1e300 s gave a NaN controller (expm overflowed) and d_short = nan."""
    with pytest.raises(ValueError, match=r"^control_period_s=1e\+300 is invalid; valid range: \(0, 1\] s$"):
        InverseModelController(TABLE_I, control_period_s=1e300)
    p, wlm = TABLE_I, TABLE_I.omega_rad_s * TABLE_I.lm_h              # 1 s is valid: reset is eq. 4's steady state
    v2 = (wlm * p.v1_amp_v - 11.2 * (p.r1_ohm * p.r2_ohm + wlm ** 2)) / p.r1_ohm
    assert InverseModelController(TABLE_I, control_period_s=1.0).reset(11.2) == pytest.approx(
        [duty_from_v2_clipped(v2, p.vl_v)], rel=1e-9)


def _dc_gain(ctl):
    ad, bd, cd, dd = ctl.discrete_ss
    return float(cd @ np.linalg.solve(np.eye(len(ad)) - ad, bd) + dd)


def test_controller_whose_discretisation_lost_float64_is_refused():
    """A fast, high-order Q (tau 3 us, order 6, 0.1 ms: all inside export-controller's ranges) gave a controller
    whose steady V2* was 14 % off 1/G22(0); tau 1 us order 6 at the rectifier period 229 % off (exported with
    exit 0). The check: the discrete DC gain against H(0) = -wn^2 / beta2, which holds to 1e-12 at the defaults."""
    c = coefficients(TABLE_I)
    h0 = -c.omega_n ** 2 / c.beta2
    assert _dc_gain(InverseModelController(TABLE_I)) == pytest.approx(h0, rel=1e-12)
    with pytest.raises(ValueError, match=r"^LowPassFilter\(tau_s=3e-06, order=6\) at control_period_s=0.0001 is "
                                         r"invalid: float64 loses the discretised controller \(DC gain off by 0\.141, "
                                         r"limit 0\.001\); valid: a larger tau_s or a lower order"):
        InverseModelController(TABLE_I, 1e-4, LowPassFilter(3e-6, 6))
    with warnings.catch_warnings():
        warnings.simplefilter("error")                  # refused by name, not by numpy's overflow warnings
        with pytest.raises(ValueError, match=r"DC gain off by a non-finite amount"):
            InverseModelController(TABLE_I, 1e-3, LowPassFilter(1e-6, 8))
    # the message's promise: order <= 4 holds on Table I over the whole tau range and the periods used
    for order in (1, 2, 3, 4):
        for tau in (1e-6, 1e-5, 2e-4, 0.1):
            for cp in (1e-7, TABLE_I.rectifier_period_s, 1e-3, 1e-2):
                assert _dc_gain(InverseModelController(TABLE_I, cp, LowPassFilter(tau, order))) == pytest.approx(
                    h0, rel=1e-3)


def test_export_controller_refuses_a_lost_controller(capsys, tmp_path):
    from mission_sim.cli import main
    assert main(["export-controller", "--out", str(tmp_path / "c"), "--lpf-tau", "1e-6", "--lpf-order", "6"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dronewpt export-controller: error: LowPassFilter(tau_s=1e-06, order=6) at control_period_s="
                          "5.88235294117647") and "DC gain off by 2.29" in err and err.count("\n") == 1
    assert not (tmp_path / "c").exists() or not any((tmp_path / "c").iterdir())


@pytest.mark.parametrize("v1", [math.nan, -5.0, math.inf])
def test_controller_reset_checks_v1(v1):
    """reset(v1_v=nan) gave d_short = nan, reset(v1_v=-5) d_short = 1 (short), both silently."""
    with pytest.raises(ValueError, match=rf"^v1_v={re.escape(repr(v1))} is invalid; valid range: \(0, inf\) V"):
        InverseModelController(TABLE_I).reset(11.2, v1_v=v1)


# ------------------------------------------------------------------ f^-1 with clamps
def test_clipped_duty_at_zero_vl_is_the_arrays_answer_not_zerodivisionerror():
    """Python floats took a fast path that raised ZeroDivisionError at vl_v = 0.0, where an array (and the exported
    C) gives the clamped value: V2 > 0 -> d = 0, V2 < 0 -> d = 1."""
    with pytest.warns(RuntimeWarning, match="divide by zero"):
        assert duty_from_v2_clipped(10.0, 0.0) == 0.0
    with pytest.warns(RuntimeWarning, match="divide by zero"):
        assert duty_from_v2_clipped(-10.0, 0.0) == 1.0
    with pytest.warns(RuntimeWarning, match="divide by zero"):
        assert duty_from_v2_clipped(np.array([10.0, -10.0]), 0.0).tolist() == [0.0, 1.0]
    assert duty_from_v2_clipped(10.0, 30.0) == float(duty_from_v2_clipped(np.array(10.0), 30.0))


# ------------------------------------------------------------------ the modal and envelope models' runs
@pytest.mark.parametrize("which", ["python", "compiled"])
def test_modal_run_refuses_duties_outside_0_1_nan_and_a_bad_period(which):
    """``simulate_modal`` (and the compiled ``modal_kernel.simulate``) ran d = 1.5 and d = -0.1 silently, gave NaN
    currents for a NaN duty or period, a run of zero length in time for a zero period, an IndexError for no
    duties. The switching model refused all of these already, with the same message."""
    if which == "python":
        from wpt_receiver.modal import simulate_modal as sim
    else:
        from wpt_receiver.modal_kernel import simulate as sim
    for d, msg in ((1.5, r"^d_short=1.5 is out of range; valid range: \[0, 1\]$"),
                   (-0.1, r"^d_short=-0.1 is out of range"), (math.nan, r"^d_short=nan is out of range")):
        with pytest.raises(ValueError, match=msg):
            sim(TABLE_I, np.array([0.3, d]))
    with pytest.raises(ValueError, match=r"^d_short of shape \(0,\) is invalid; valid: a non-empty 1-D sequence"):
        sim(TABLE_I, np.array([]))
    for cp in (0.0, math.nan, 2.0):
        with pytest.raises(ValueError, match=rf"^control_period_s={cp!r} is invalid; valid range: \(0, 1\] s$"):
            sim(TABLE_I, np.full(3, 0.3), control_period_s=cp)
    with pytest.raises(ValueError, match=r"^substeps=0 is invalid; valid range: integer >= 1$"):
        sim(TABLE_I, np.full(3, 0.3), substeps=0)
    r = sim(TABLE_I, np.array([0.0, 1.0]))                                   # both ends valid
    assert r["d_short"].tolist() == [0.0, 0.0, 1.0]


def test_envelope_simulate_refuses_a_nan_v1_and_a_misshapen_x0():
    """``v1_v=nan`` gave a NaN run without a word; an ``x0`` of the wrong shape numpy's "could not broadcast"."""
    from wpt_receiver.envelope import simulate, steady_state
    with pytest.raises(ValueError, match=r"^v1_v=nan is invalid; valid range: \(0, inf\) V"):
        simulate(TABLE_I, np.ones(3), 1e-6, v1_v=math.nan)
    with pytest.raises(ValueError, match=r"^x0=\[0.0, 0.0, 0.0\] is invalid; valid: the \(I1, I2\) amplitudes \[A\], "
                                         r"shape \(2,\), finite$"):
        simulate(TABLE_I, np.ones(3), 1e-6, x0=np.zeros(3))
    with pytest.raises(ValueError, match=r"^x0=\[nan, 1.0\] is invalid"):
        simulate(TABLE_I, np.ones(3), 1e-6, x0=[math.nan, 1.0])
    # a given steady x0 stays put (eq. 4-5's SM steady state: I2 = w Lm V1 / (R1 R2 + (w Lm)^2) = 11.44 A)
    x0 = steady_state(TABLE_I, 0.0)
    _, _, i2 = simulate(TABLE_I, np.zeros(4), 1e-6, x0=x0)
    wlm = TABLE_I.omega_rad_s * TABLE_I.lm_h
    assert i2 == pytest.approx(np.full(5, wlm * TABLE_I.v1_amp_v / (TABLE_I.r1_ohm * TABLE_I.r2_ohm + wlm ** 2)),
                               rel=1e-12)


# ------------------------------------------------------------------ the CLI
def test_paper_refuses_out_with_no_plot(capsys, tmp_path):
    """``--out`` is the figures' folder: with ``--no-plot`` it was ignored (nothing written there, exit 0), where the
    project refuses an option that would have no effect."""
    from mission_sim.cli import main
    assert main(["paper", "--model", "envelope", "--no-plot", "--out", str(tmp_path / "p")]) == 2
    assert capsys.readouterr().err == (f"dronewpt paper: error: --out '{tmp_path / 'p'}' is only used for the figures; "
                                       "valid: drop --no-plot, or drop --out\n")
    assert not (tmp_path / "p").exists()
    assert main(["paper", "--model", "envelope", "--format", "json", "--out", str(tmp_path / "p")]) == 0
    assert [f.name for f in (tmp_path / "p").iterdir()] == ["fig6_envelope.png"]


@pytest.mark.parametrize("t_end", [math.nan, math.inf, -1.0])
def test_run_paper_names_a_bad_window_end(t_end):
    """``t_end_s=nan`` was reported as ``t_switch_s=0.001 is invalid; valid range: [0, t_end_s=nan)`` and ``inf`` as
    a control period outside ``[inf, inf]``: the value at fault is t_end_s."""
    from wpt_receiver.paper import run_paper
    with pytest.raises(ValueError, match=rf"^t_end_s={t_end!r} is invalid; valid range: \(0, inf\) s, after t_switch_s$"):
        run_paper(TABLE_I, model="envelope", t_end_s=t_end)


def test_export_controller_refuses_millions_of_test_vectors(capsys, tmp_path):
    """``--link f_hz=2.712e7`` (an ISM band, inside link.f_hz's range) at the rectifier period made 5.2 million test
    vectors: it ran for more than 5 min towards a ~380 MB header. Refused before any work, naming the period that
    fits; ``--control-period 1e-6`` exports."""
    from mission_sim.cli import main
    from wpt_receiver import c_export
    out = tmp_path / "c"
    assert main(["export-controller", "--out", str(out), "--link", "f_hz=2.712e7"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert "warning: --link f_hz=2.712e+07 Hz is 319.1x the tanks' resonance" in err[0]   # the frequency warning first
    assert err[1:] == [
        "dronewpt export-controller: error: control_period_s=1.844e-08 gives 5,207,040 test vectors (6 cases of 16 ms, "
        "one per control period); valid: at most 200,000, i.e. control_period_s >= 4.8e-07 s (--control-period)"]
    assert not out.exists()
    with pytest.warns(RuntimeWarning, match=r"^f_hz=2.712e\+07 Hz is 319.1x the tanks' resonance"):   # (the library's)
        spec = c_export.controller_spec(TABLE_I.with_(f_hz=2.712e7), 1e-6)
    assert len(c_export.test_vectors(spec)) == 6 * 16_000
    assert len(c_export.test_vectors(c_export.controller_spec())) == 16_320     # Table I: as before


def test_paper_envelope_warns_where_its_rm_state_is_a_negative_current(capsys):
    """``--model envelope --link vdc_v=1 --link vl_v=1000`` printed RM -11.96 A and a step "peak" of 1,303 A without a
    word: below an emf margin of 1 the rectifier blocks and eq. 4 with V2 held at (4/pi) VL has the battery driving
    the coil. One warning (the closed form's I2 named), exit 0; Table I none."""
    from mission_sim.cli import main
    from wpt_receiver.paper import envelope_range_problem, rm_emf_margin
    assert envelope_range_problem(TABLE_I) is None
    p = TABLE_I.with_(vdc_v=1.0, vl_v=1000.0)
    assert rm_emf_margin(p) == pytest.approx(0.0309, abs=1e-4)
    assert main(["paper", "--model", "envelope", "--no-plot", "--link", "vdc_v=1", "--link", "vl_v=1000"]) == 0
    cap = capsys.readouterr()
    assert cap.err == ("dronewpt paper: warning: emf margin wLm V1 / (R1 (4/pi) VL) = 0.0309 is below 1: the rectifier "
                       "blocks in RM, where eq. 4's envelope with V2 = (4/pi) VL held gives I2 = -11.96 A < 0 (the "
                       "battery driving the coil, which the SBAR's diodes cannot); use --model switching\n")
    assert "-11.96 A" in cap.out
    assert main(["paper", "--model", "envelope", "--no-plot"]) == 0 and capsys.readouterr().err == ""


@pytest.mark.parametrize("substeps", [float("nan"), float("inf"), None, "a"])
def test_modal_run_names_a_substeps_that_is_not_a_finite_number(substeps):
    """``check_duty_run``'s ``substeps``: NaN, inf, None and text reached Python's own errors ("cannot convert float
    NaN to integer", OverflowError, TypeError) instead of the named message."""
    from wpt_receiver.sbar import check_duty_run
    with pytest.raises(ValueError, match=r"^substeps=.* is invalid; valid range: integer >= 1$"):
        check_duty_run([0.5], 1e-4, substeps)


def test_sizing_refuses_out_with_no_plot_as_paper_and_compare_do(capsys, tmp_path):
    """``sizing --no-plot --out DIR`` ignored ``--out`` (the figure's folder: nothing written, exit 0); refused with
    ``paper``'s and ``compare``'s one message (``cli.common.figures_out``), before any simulation."""
    from mission_sim.cli import main
    assert main(["sizing", "--no-plot", "--out", str(tmp_path / "s")]) == 2
    assert capsys.readouterr().err == (f"dronewpt sizing: error: --out '{tmp_path / 's'}' is only used for the figures; "
                                       "valid: drop --no-plot, or drop --out\n")
    assert not (tmp_path / "s").exists()
