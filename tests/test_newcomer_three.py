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


def test_sweep_plot_hue_is_never_a_one_value_axis():
    """A one-value [grid] axis (`drone.mass_kg = [1.0]`, listed before the others) counts as varied: it became the
    hue, one line with the policies averaged into it (reviewer, 2026-11-28)."""
    doc = {"study": {"name": "mine"},
           "grid": {"drone.mass_kg": [1.0], "battery.capacity_ah": [2.0, 4.0], "policy": ["step", "model_based"]},
           "monte_carlo": {"n": 3, "seed": 1, "params": {"wind.speed_m_s": {"uniform": [0.0, 6.0]}}}}
    study = parse_study(doc)
    assert "drone.mass_kg" in study.varied_keys
    rows = _rows().assign(**{"drone.mass_kg": 1.0})
    assert _axes(rows, study) == ("battery.capacity_ah", "policy")
    # a scatter over the draws: coloured by the grid axis that varies, not the one-value one
    doc["report"] = {"x": "wind.speed_m_s"}
    assert _axes(rows, parse_study(doc)) == ("wind.speed_m_s", "battery.capacity_ah")


def test_sweep_heat_map_tells_adjacent_cells_and_ticks_apart(monkeypatch, tmp_path):
    """The heat map wrote each cell's mean with 3 significant figures: two adjacent cells at 12.341 and 12.344 both
    read '12.3'. Cells and ticks now take the fewest figures (>= 3 / 6) that tell neighbours apart, no float noise."""
    import mission_sim.studies.report as report
    figs = []
    monkeypatch.setattr(report, "save_figure", lambda fig, path: figs.append(fig) or str(path))
    study = parse_study({"study": {"name": "mine"},
                         "grid": {"battery.capacity_ah": [2.0, 2.0001, 4.0],
                                  "wind.speed_m_s": [0.1 + 0.2, 6.0]}})
    means = {(2.0, 0.1 + 0.2): 12.341, (2.0001, 0.1 + 0.2): 12.344, (4.0, 0.1 + 0.2): 15.0,
             (2.0, 6.0): 0.5, (2.0001, 6.0): 0.75, (4.0, 6.0): 1.0}
    rows = pd.DataFrame([{"battery.capacity_ah": c, "wind.speed_m_s": w, "flight_time_gain_s": m, "status": "ok"}
                         for (c, w), m in means.items()])
    report.plot_sweep(rows, study, tmp_path)
    heat = figs[0].axes[1]
    assert [t.get_text() for t in heat.get_xticklabels()] == ["2", "2.0001", "4"]
    assert [t.get_text() for t in heat.get_yticklabels()] == ["0.3", "6"]
    assert sorted(t.get_text() for t in heat.texts) == sorted(["12.341", "12.344", "15", "0.5", "0.75", "1"])


# --- pads files a newcomer brings ------------------------------------------------------------------------------------

import json  # noqa: E402
import re  # noqa: E402

import pytest  # noqa: E402

from mission_sim.plans.pads import read_pads  # noqa: E402


@pytest.mark.parametrize("column", ["alt_ft", "Alt (ft)", "height", "elevation_m", "z", "height_m_agl", "Hgt (feet)"])
def test_pads_csv_altitude_under_another_name_is_refused(tmp_path, column):
    """`name,lat,lon,alt_ft` was read with every pad on the home's ground (the column ignored without a word)."""
    f = tmp_path / "pads.csv"
    f.write_text(f"name,lat,lon,{column}\nA,47.3982819,8.5469211,1600\n")
    with pytest.raises(ValueError, match=rf"pads.csv: column {re.escape(repr(column.lower()))} looks like a pad altitude.*valid: "
                                         r"a column alt in metres above mean sea level"):
        read_pads(f)


def test_pads_csv_other_columns_still_ignored(tmp_path):
    f = tmp_path / "pads.csv"
    f.write_text("name,lat,lon,alt,height_note,zone\nA,47.3982819,8.5469211,490.5,roof,3\n")
    (pad,) = read_pads(f)
    assert pad.point.alt_m == 490.5
    f.write_text("name,lat,lon,zone,note\nA,47.3982819,8.5469211,3,x\n")
    assert read_pads(f)[0].point.alt_m is None


@pytest.mark.parametrize("column", ["height_note", "z_index", "agl_note", "elevation_source"])
def test_pads_csv_column_only_starting_like_a_height_is_ordinary(tmp_path, column):
    """`name,lat,lon,height_note` was refused as a pad altitude (only the name's first word was looked at), though a
    file with an alt column reads height_note as an ordinary column (reviewer, 2026-11-28)."""
    f = tmp_path / "pads.csv"
    f.write_text(f"name,lat,lon,{column}\nA,47.3982819,8.5469211,roof\n")
    (pad,) = read_pads(f)
    assert pad.point.alt_m is None and pad.point.lat_deg == 47.3982819


@pytest.mark.parametrize("text, items", [('[{"lat": 47.39, "lon": 8.54}]', "1 item"),
                                         ("[[47.39, 8.54], [47.40, 8.55]]", "2 items"), ("[]", "0 items")])
def test_a_json_array_given_as_pads_is_named(tmp_path, capsys, text, items):
    """A JSON array as the pads file was read as a CSV: "pads.json: header '[{\"lat\": 47.39' has no lat / lon
    column" (2026-11-28). It is named as what it is, with the two forms a pads file has."""
    from _cli_helpers import one_error_line
    f = tmp_path / "pads.json"
    f.write_text(text)
    line = one_error_line(capsys, ["mission", "--pads", str(f), "--dry-run", "--out", str(tmp_path / "m")])
    assert line == (f"dronewpt mission: error: pads.json: a JSON array ({items}), not a pads file; valid: a GeoJSON "
                    'object {"type": "FeatureCollection", "features": [...]} of Point / MultiPoint features '
                    "(coordinates [lon, lat] or [lon, lat, alt], property hover_time_s), or a CSV with a header "
                    "lat,lon[,alt][,hover_time_s]")
    assert not (tmp_path / "m").exists()


def test_a_csv_whose_first_cell_starts_with_a_bracket_is_still_a_csv(tmp_path):
    f = tmp_path / "pads.csv"
    f.write_text("[note],lat,lon\nA,47.3982819,8.5469211\n")
    assert read_pads(f)[0].point.lat_deg == 47.3982819


def test_a_plan_given_as_pads_is_named(tmp_path):
    """`--pads survey.plan` said 'feature 0: geometry type null is not supported; valid: Point, MultiPoint'."""
    f = tmp_path / "survey.plan"
    f.write_text(json.dumps({"fileType": "Plan", "mission": {"items": []}, "version": 1}))
    with pytest.raises(ValueError, match=r"survey.plan: a JSON object without a GeoJSON \"type\" \(a QGroundControl "
                                         r"\.plan: give it as mission / telemetry --plan, or mission.file\), not a "
                                         r"pads file"):
        read_pads(f)
    # a "type" that is not GeoJSON's is named (it was told it had none)
    f.write_text(json.dumps({"type": "Topology", "objects": {}}))
    with pytest.raises(ValueError, match=r"survey.plan: type 'Topology' is not GeoJSON's, not a pads file; valid: a "
                                         r"GeoJSON FeatureCollection"):
        read_pads(f)
    # a feature without its "type" but with a geometry is still read
    f.write_text(json.dumps({"geometry": {"type": "Point", "coordinates": [8.5, 47.4]}}))
    assert read_pads(f)[0].point.lat_deg == 47.4


# --- southern latitudes on the command line --------------------------------------------------------------------------

def test_negative_latitude_pairs_are_values():
    """`replay LOG --pad -35.36,149.16` and `telemetry --home -35.36,149.16,584` (ArduPilot SITL's own home is at
    -35.36) failed on Python 3.11 - 3.13.0 with "argument --pad: expected one argument": argparse took the value for an
    option; only `--pad=-35.36,...` worked."""
    from mission_sim.cli import build_parser
    p = build_parser()
    assert p.parse_args(["replay", "x.tlog", "--pad", "-35.3623,149.1657"]).pad is not None
    assert p.parse_args(["telemetry", "--home", "-35.363261,149.165230,584", "--connect", "none"]).home is not None
    assert p.parse_args(["replay", "x.tlog", "--window", "-5,10"]).window is not None   # (refused later, by range)


def test_negative_latitude_home_streams(tmp_path, capsys):
    from mission_sim.cli import main
    rc = main(["telemetry", "--home", "-35.363261,149.165230,584", "--connect", "none", "--tlog",
               str(tmp_path / "t.tlog"), "--duration", "1", "--speed", "inf", "--no-progress"])
    assert rc == 0 and (tmp_path / "t.tlog").stat().st_size > 1000


# --- an RL researcher's step count -----------------------------------------------------------------------------------

@pytest.mark.parametrize("text, hint", [("1e4", " (write 10000)"), ("10k", ""), ("-1e4", "")])   # -1e4: no
# "(write -10000)", itself out of range
def test_train_timesteps_not_an_integer_names_the_range(capsys, text, hint):
    """`dronewpt train --timesteps 1e4` said "argument --timesteps: invalid int value: '1e4'" (no range, no way on)."""
    from mission_sim.cli import main
    with pytest.raises(SystemExit) as e:
        main(["train", "--algo", "ppo", "--timesteps", text, "--out", "x"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"dronewpt train: error: argument --timesteps: timesteps='{text}' is not an integer; valid range: "
                   f"integer >= 1 (0 with --imitate){hint} (see dronewpt train --help)")


def test_train_timesteps_one_range_text(capsys, tmp_path):
    """`--timesteps 1e4` said "valid range: integer >= 0", then `--timesteps 0` (no --imitate) was refused with ">= 1"
    (reviewer, 2026-11-28): every refusal of a step count gives the same range."""
    from mission_sim.cli import main
    errs = []
    for text in ("-5", "0"):
        try:
            rc = main(["train", "--algo", "ppo", "--timesteps", text, "--out", str(tmp_path / "x")])
        except SystemExit as e:
            rc = e.code
        assert rc == 2
        errs.append(capsys.readouterr().err.strip())
    assert [e.split("valid range: ")[1].removesuffix(" (see dronewpt train --help)") for e in errs] == [
        "integer >= 1 (0 with --imitate)"] * 2, errs
    assert not (tmp_path / "x").exists()


# --- `mission --config`, as the other commands spell it --------------------------------------------------------------

def test_mission_takes_config_as_telemetry_does(tmp_path, capsys):
    """`dronewpt telemetry --config m.toml` works; `dronewpt mission --config m.toml` was "unrecognized argument
    '--config'" (mission took its config only as the positional argument)."""
    from mission_sim.cli import main
    m = tmp_path / "m.toml"
    m.write_text("[mission]\ncruise_speed_m_s = 2.0\n")
    assert main(["mission", "--config", str(m), "--dry-run", "--format", "json"]) == 0
    by_option = capsys.readouterr().out
    assert main(["mission", str(m), "--dry-run", "--format", "json"]) == 0
    assert capsys.readouterr().out == by_option
    assert main(["mission", "--dry-run", "--format", "json"]) == 0
    assert capsys.readouterr().out != by_option          # the file was read: a slower cruise than the default
    other = tmp_path / "other.toml"
    other.write_text("")
    assert main(["mission", str(other), "--config", str(m), "--dry-run"]) == 2
    assert "name two mission files; valid: one of them" in capsys.readouterr().err


# --- compare's table ---------------------------------------------------------------------------------------------------

def _row(scenario, policy, over, ret, d=None):
    r = {"scenario": scenario, "policy": policy, "train_seeds": 1, "reached_short_mode": 1.0, "peak_i2_a": 12.5,
         "energy_before_stop_j": 1.4, "tracking_rmse_a": 0.7}
    for k, v in (("overshoot_pct", over), ("energy_after_stop_j", 0.5), ("return", ret), ("d_return", d)):
        if v is not None:
            r[k], r[k + "_lo"], r[k + "_hi"] = v, v - abs(v) * 0.3, v + abs(v) * 0.3
    return r


def test_compare_table_columns_line_up(capsys):
    """`dronewpt compare --episodes 5`: scenario names longer than 12 characters (lm_drift_fast, sense_delay_long)
    and intervals wider than their column (197.98 [150.16, 244.68], -1830.2 [-1886.1, -1768.5]) shifted the rest of
    their rows: the peak I2 of one row stood under another's E before."""
    import argparse

    from mission_sim.cli.learning import _print_compare
    rows = [_row("nominal", "model_based", 2.96, 31.3), _row("nominal", "step", 197.98, 2.4, -28.9),
            _row("sense_delay_long", "random", 370.54, -1830.2, -1861.4)]
    _print_compare(rows, [], argparse.Namespace(episodes=5, seed=1000, link="envelope", oracle_windows=0))
    lines = capsys.readouterr().out.splitlines()
    hdr = next(i for i, s in enumerate(lines) if s.startswith("scenario"))
    table = lines[hdr:hdr + 2 + len(rows)]
    assert len({len(s) for s in table}) == 1                    # every row as wide as the header
    col = table[0].index("peak I2 A") + len("peak I2 A")        # right-aligned: each row's 12.50 ends there
    assert all(s[col - 5:col] == "12.50" for s in table[2:])


# --- a sweep started inside a checkout ---------------------------------------------------------------------------------

def test_forkserver_workers_import_the_drivers_packages(tmp_path):
    """The sweep's forkserver (Dask's workers fork from it) preloaded `mission_sim` from the current folder: Python
    <= 3.13's forkserver ignores the sys.path it is handed and runs as `python -c` (current folder first). Started
    from a folder holding another `mission_sim` (a clone, beside an installed copy), the workers ran that one. Here
    the folder holds a stand-in package; the workers must import the driver's. The PYTHONSAFEPATH / PYTHONPATH the
    forkserver is started with must not reach the workers: they see the driver's, and a script a worker runs with
    `python helper/script.py` imports its sibling module (ModuleNotFoundError under the safe path)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    (tmp_path / "mission_sim").mkdir()
    (tmp_path / "mission_sim" / "__init__.py").write_text("STAND_IN = True\n")
    (tmp_path / "helper").mkdir()
    (tmp_path / "helper" / "sibling.py").write_text("VALUE = 42\n")
    (tmp_path / "helper" / "script.py").write_text("import sibling\nprint(sibling.VALUE)\n")
    (tmp_path / "drv").mkdir()
    script = tmp_path / "drv" / "driver.py"
    script.write_text(
        "import json, multiprocessing as mp, sys\n"
        "def where():\n"
        "    import os, subprocess, sys\n"
        "    r = subprocess.run([sys.executable, 'helper/script.py'], capture_output=True, text=True)\n"
        "    return [sys.modules['mission_sim'].__file__, os.environ.get('PYTHONSAFEPATH'),\n"
        "            os.environ.get('PYTHONPATH'), os.environ.get('DRONEWPT_FORKSERVER_RESTORE'),\n"
        "            r.stdout.strip() or r.stderr.strip().splitlines()[-1]]\n"
        "if __name__ == '__main__':\n"
        "    import mission_sim\n"
        "    from mission_sim.studies.cluster import _start_forkserver\n"
        "    _start_forkserver()\n"
        "    with mp.get_context('forkserver').Pool(1) as p:\n"
        "        print(json.dumps([mission_sim.__file__, p.apply(where)]))\n")
    user_path = os.pathsep.join([str(repo), str(tmp_path / "user_entry")])
    env = {**os.environ, "PYTHONPATH": user_path}
    env.pop("PYTHONSAFEPATH", None)
    r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    driver, (worker, safe_path, python_path, restore, helper_out) = json.loads(r.stdout.splitlines()[-1])
    assert driver == str(repo / "mission_sim" / "__init__.py")
    assert worker == driver          # before: tmp_path/mission_sim/__init__.py, the stand-in
    assert safe_path is None         # the driver's: unset (was "1")
    assert python_path == user_path  # the driver's (was the driver's whole sys.path)
    assert restore is None
    assert helper_out == "42"        # was: ModuleNotFoundError: No module named 'sibling'
