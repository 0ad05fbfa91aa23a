"""A demanding newcomer's bad inputs (2026-11-27 midday; docs/robustness.md, "Newcomer's bad inputs
(2026-11-27 midday)"): each test failed on the tree before its fix (``main``)."""

from __future__ import annotations

import pytest

from mission_sim.cli import main


def _one_error_line(capsys, argv) -> str:
    """``main(argv)``: exit status 2, nothing on stdout, one line on stderr and no traceback (the line returned)."""
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    cap = capsys.readouterr()
    assert rc == 2, (rc, cap.err)
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in cap.err, cap.err
    assert cap.out == "", cap.out
    return lines[0]


# ------------------------------------------------------------------ paper / netlist / export-controller --link
@pytest.mark.parametrize("argv, text", [
    # a KeyError traceback (the "given twice" check compared nan with itself), exit 1
    (["paper", "--no-plot", "--link", "lm_h=nan"], "--link lm_h=nan is invalid; valid range: (0, 1] H"),
    (["netlist", "--link", "f_hz=nan"], "--link f_hz=nan is invalid; valid range: [10000, 1e+07] Hz"),
    (["export-controller", "--link", "vl_v=nan"], "--link vl_v=nan is invalid; valid range: (0, 1000] V"),
    # a ZeroDivisionError traceback
    (["paper", "--no-plot", "--link", "f_hz=1e-300"], "--link f_hz=1e-300 is invalid; valid range: [10000, 1e+07] Hz"),
    # RuntimeWarnings (overflow), then "i2_a[0]=nan at t_s=0.0 is not finite" naming no input
    (["paper", "--no-plot", "--link", "vdc_v=1e308"], "--link vdc_v=1e+308 is invalid; valid range: (0, 1000] V"),
    (["paper", "--no-plot", "--link", "r1_ohm=1e308"], "--link r1_ohm=1e+308 is invalid; valid range: [1e-06, 100] ohm"),
    # "c1_f=0.0 is invalid" (a derived value, not the one given)
    (["paper", "--no-plot", "--link", "l1_h=1e308"], "--link l1_h=1e+308 is invalid; valid range: [1e-09, 1] H"),
])
def test_link_values_are_checked_where_read(capsys, argv, text):
    line = _one_error_line(capsys, argv)
    assert text in line, line


def test_link_ranges_are_the_mission_configs_where_it_has_the_key():
    """One source: ``--link vdc_v`` / ``r1_ohm`` / ``r2_ohm`` / ``f_hz`` take the mission's ``[link]`` ranges."""
    from mission_sim.config import LINK_PARAM_RANGES, PLAUSIBLE
    from wpt_receiver import TABLE_I
    for key in ("vdc_v", "r1_ohm", "r2_ohm", "f_hz"):
        assert LINK_PARAM_RANGES[key] is PLAUSIBLE[f"link.{key}"]
    for key, rng in LINK_PARAM_RANGES.items():   # Table I inside every range
        assert rng.contains(getattr(TABLE_I, key)), key
