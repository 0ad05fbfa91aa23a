"""Study files: parsing, validation, grid x Monte Carlo expansion, case identity."""

import tomllib

import numpy as np
import pytest

from mission_sim.studies.study import case_id, expand_cases, load_study, monte_carlo_draw, parse_study

DOC = """
[study]
name = "t"
[fixed]
"sim.duration_s" = 30.0
[grid]
mission.hover_time_s = [5, 10, 20]
"pads.1.x_m" = {linspace = [20, 60, 3]}
policy = ["step", "model_based"]
[monte_carlo]
n = 4
seed = 7
[monte_carlo.params]
"wind.speed_m_s" = {uniform = [0.0, 6.0]}
seed = {integers = [0, 1000]}
battery.capacity_ah = {normal = [5.0, 0.25]}
"""


def study(text=DOC):
    return parse_study(tomllib.loads(text), name="t")


def test_grid_times_monte_carlo_is_full_product_with_common_draws():
    s = study()
    cases = expand_cases(s)
    assert s.n_cases == len(cases) == 3 * 3 * 2 * 4
    assert len({c.case_id for c in cases}) == len(cases)
    # every grid point appears with every draw, and the draws are the same at every grid point
    draws = {tuple(sorted((k, c.params[k]) for k in s.mc_params)) for c in cases}
    assert len(draws) == 4
    points = {(c.params["mission.hover_time_s"], c.params["pads.1.x_m"], c.params["policy"]) for c in cases}
    assert points == {(h, x, p) for h in (5, 10, 20) for x in (20.0, 40.0, 60.0) for p in ("step", "model_based")}
    assert all(c.params["sim.duration_s"] == 30.0 for c in cases)
    # draws respect their distributions
    wind = np.array([c.params["wind.speed_m_s"] for c in cases])
    assert np.all((wind >= 0) & (wind < 6))
    assert all(isinstance(c.params["seed"], int) and 0 <= c.params["seed"] < 1000 for c in cases)


def test_monte_carlo_draw_j_does_not_depend_on_n_and_changes_with_seed():
    s4, s9 = study(), study(DOC.replace("n = 4", "n = 9"))
    ids4 = {c.case_id for c in expand_cases(s4)}
    ids9 = {c.case_id for c in expand_cases(s9)}
    assert ids4 < ids9 and len(ids9) == 3 * 3 * 2 * 9  # raising n keeps the old cases
    other = study(DOC.replace("seed = 7", "seed = 8"))
    assert monte_carlo_draw(s4, 0) != monte_carlo_draw(other, 0)
    assert monte_carlo_draw(s4, 2) == monte_carlo_draw(study(), 2)


def test_case_id_is_canonical_and_depends_on_base():
    a = case_id({"policy": "step", "mission.hover_time_s": 10, "x": [1, 2.0]})
    b = case_id({"mission.hover_time_s": 10.0, "x": [1.0, 2], "policy": "step"})
    assert a == b and len(a) == 16
    assert case_id({"mission.hover_time_s": 10.5}) != case_id({"mission.hover_time_s": 10})
    assert a != case_id({"policy": "step", "mission.hover_time_s": 10, "x": [1, 2]}, base_fingerprint="other")


def test_duplicate_grid_values_give_one_case_and_default_policy():
    s = study('[grid]\n"mission.hover_time_s" = [5, 5.0, 10]\n')
    cases = expand_cases(s)
    assert [c.params for c in cases] == [{"policy": "model_based", "mission.hover_time_s": 5},
                                          {"policy": "model_based", "mission.hover_time_s": 10}]


def test_a_study_that_varies_nothing_is_an_error_unless_allowed():
    for text in ("[study]\nname = 'one'\n", "", "[grid]\n[fixed]\n'a.b' = 1\n"):
        with pytest.raises(ValueError, match="varies nothing.*allow_single = true"):
            study(text)
    cases = expand_cases(study("[study]\nname = 'one'\nallow_single = true\n"))
    assert len(cases) == 1 and cases[0].params == {"policy": "model_based"}


@pytest.mark.parametrize("text, words", [
    ("[grids]\n", ["grids", "[grid]"]),
    ("[grid]\n'a.b' = []\n", ["a.b", "empty"]),
    ("[grid]\n'a.b' = {uniform = [0, 1]}\n", ["a.b", "monte_carlo"]),
    ("[grid]\n'a.b' = {linspace = [0, 1, 0]}\n", ["a.b", "num"]),
    ("[monte_carlo]\nn = 0\n[monte_carlo.params]\n'a.b' = {uniform = [0, 1]}\n", ["n = 0", ">= 1"]),
    ("[monte_carlo.params]\n'a.b' = {uniform = [1, 0]}\n", ["a.b", "lo < hi"]),
    ("[monte_carlo.params]\n'a.b' = {gauss = [1, 0]}\n", ["a.b", "normal"]),
    ("[monte_carlo.params]\n'a.b' = {loguniform = [0, 1]}\n", ["a.b", "0 < lo"]),
    ("[fixed]\n'a.b' = 1\n[grid]\n'a.b' = [1, 2]\n", ["a.b", "[fixed]", "[grid]"]),
    ("[report]\nx = 'nope'\n", ["nope", "varied"]),
    ("[study]\nrunner = 'nocolon'\n", ["nocolon", "module:factory"]),
    ("[fixed]\n'a.b' = nan\n", ["a.b", "finite"]),
])
def test_bad_study_names_the_bad_entry(text, words):
    with pytest.raises(ValueError) as err:
        study(text)
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg


def test_load_study_resolves_base_relative_to_file(tmp_path):
    (tmp_path / "m.toml").write_text("")
    (tmp_path / "s.toml").write_text("[study]\nbase = \"m.toml\"\n[grid]\nseed = [1, 2]\n")
    assert load_study(tmp_path / "s.toml").base_path == tmp_path / "m.toml"
    (tmp_path / "bad.toml").write_text('[study]\nbase = "missing.toml"\n')
    with pytest.raises(FileNotFoundError, match="missing.toml"):
        load_study(tmp_path / "bad.toml")
    with pytest.raises(FileNotFoundError, match="nofile"):
        load_study(tmp_path / "nofile.toml")
