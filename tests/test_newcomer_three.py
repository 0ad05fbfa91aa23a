"""Three newcomers (an energy researcher, an RL researcher, a MAVLink integrator) from a clean venv, 2026-11-28:
the frictions they hit, each fixed with a test that fails without its fix."""

import pandas as pd

from mission_sim.studies.report import _axes
from mission_sim.studies.study import parse_study


def _study(report=None):
    doc = {"study": {"name": "mine"},
           "grid": {"battery.capacity_ah": [2.0, 4.0], "policy": ["step", "model_based"]},
           "monte_carlo": {"n": 3, "seed": 1, "params": {"wind.speed_m_s": {"uniform": [0.0, 6.0]}}}}
    if report:
        doc["report"] = report
    return parse_study(doc)


def _rows():
    return pd.DataFrame({"battery.capacity_ah": [2.0, 2.0, 4.0, 4.0] * 3,
                         "policy": ["step", "model_based"] * 6,
                         "wind.speed_m_s": [0.5, 0.5, 0.5, 0.5, 2.5, 2.5, 2.5, 2.5, 4.1, 4.1, 4.1, 4.1],
                         "status": "ok"})


def test_sweep_plot_lines_are_the_policies_not_the_random_draws():
    """A study with a grid axis, the policy and a Monte Carlo draw, no [report] hue: the trade-off plot drew one line
    per random wind draw (legend 'wind.speed_m_s = 1.9912343512086028', the policies averaged into the band); a line
    per policy is what the grid asked for."""
    x, hue = _axes(_rows(), _study())
    assert (x, hue) == ("battery.capacity_ah", "policy")


def test_sweep_plot_keeps_an_explicit_hue_and_a_scatter_over_draws():
    assert _axes(_rows(), _study({"hue": "wind.speed_m_s"}))[1] == "wind.speed_m_s"
    # x drawn at random (a scatter): coloured by the other varied parameter, as before
    assert _axes(_rows(), _study({"x": "wind.speed_m_s"})) == ("wind.speed_m_s", "battery.capacity_ah")
