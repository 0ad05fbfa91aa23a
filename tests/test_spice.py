"""Switching model with devices against an independent ngspice simulation of the same circuit.

The netlists and the SPICE numbers are kept in ``tests/spice/`` (regenerate with
``python tests/_spice.py``), so the comparison runs everywhere; with ngspice installed the netlists
are also re-simulated."""

import functools
import json
import shutil

import pytest
from _spice import (BRIDGE_DEAD_TIME_S, BRIDGE_PRESETS, HERE, KEYS, PRESETS, _ngspice_values, bridge_energy_netlist,
                    bridge_energy_values, bridge_netlist, keys_from_values, netlist, netlist_path, run_ngspice,
                    switching_measure)

from wpt_receiver.devices import preset

REF = json.loads((HERE / "reference.json").read_text())
BRIDGE = REF["bridge"]["results"]


@functools.cache
def _model_with_dead_time(name):
    """Switching model with the preset's devices and the bridge netlists' dead time (run once)."""
    return switching_measure(dv=preset(name), dead_time_s=BRIDGE_DEAD_TIME_S)


@pytest.mark.parametrize("name", PRESETS)
def test_netlists_in_repo_are_current(name):
    """The stored netlist is exactly what the generator writes for the current devices table."""
    assert netlist_path(name).read_text() == netlist(dv=preset(name), label=name)


@pytest.mark.parametrize("name", PRESETS)
def test_switching_model_matches_spice_reference(name):
    """RM, step peak, SM amplitude of i2 and the primary current within 0.5 % of SPICE (the SM
    primary current, a 0.2-0.5 A residual, within 1 %); the devices really move the numbers."""
    sw, sp = switching_measure(dv=preset(name)), REF["results"][name]
    for key in KEYS:
        tol = 0.01 if key == "sm_i1_a" else 0.005
        assert sw[key] == pytest.approx(sp[key], rel=tol), (key, sw[key], sp[key])
    if name != "ideal":
        ideal = REF["results"]["ideal"]
        assert sp["step_peak_a"] > 1.008 * ideal["step_peak_a"]
        assert sp["rm_i1_a"] > 1.03 * ideal["rm_i1_a"]


@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice not installed")
@pytest.mark.parametrize("name", ["schottky"])
def test_ngspice_rerun_matches_reference(name, tmp_path):
    """Re-simulate a stored netlist: ngspice reproduces the stored numbers (and so the model)."""
    got = run_ngspice(netlist_path(name).read_text(), tmp_path)
    for key in KEYS:
        assert got[key] == pytest.approx(REF["results"][name][key], rel=1e-4), key


# ---------------------------------------------------------------- full bridge with dead time


def test_bridge_reference_is_for_the_current_dead_time():
    assert REF["bridge"]["dead_time_s"] == BRIDGE_DEAD_TIME_S


@pytest.mark.parametrize("name", BRIDGE_PRESETS)
def test_bridge_netlists_in_repo_are_current(name):
    assert netlist_path(name, bridge=True).read_text() == bridge_netlist(name)


@pytest.mark.parametrize("name", BRIDGE_PRESETS)
def test_switching_model_with_dead_time_matches_spice_full_bridge(name):
    """Inverter as a real full bridge (Ron, body diodes, dead time) in SPICE against the model's
    inverter topologies (driven, freewheeling, blocked) with the same dead time: every quantity
    within 0.5 %, the SM primary current included (measured: within 0.35 %)."""
    sw, sp = _model_with_dead_time(name), BRIDGE[name]
    for key in KEYS:
        assert sw[key] == pytest.approx(sp[key], rel=0.005), (key, sw[key], sp[key])


@pytest.mark.parametrize("name", BRIDGE_PRESETS)
def test_dead_time_really_moves_the_spice_numbers(name):
    """The comparison above exercises the dead time: in SPICE the bridge's SM amplitude differs
    from the square-wave source's by more than 1 % (so a model without the dead time would fail
    the 0.5 % criterion), and the SM primary residual by more than 10 %."""
    sq, br = REF["results"][name], BRIDGE[name]
    assert abs(br["sm_i2_a"] / sq["sm_i2_a"] - 1) > 0.01
    assert abs(br["sm_i1_a"] / sq["sm_i1_a"] - 1) > 0.10


@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice not installed")
def test_ngspice_rerun_full_bridge_matches_model_and_reference(tmp_path):
    """Re-simulate the stored Schottky full-bridge netlist: ngspice reproduces the stored numbers
    and the switching model with the same dead time is within 0.5 % of the live run. The run is of
    ``bridge_energy_netlist`` (the stored netlist plus the source / battery energy ``.meas``, the
    stored netlist's own lines unchanged): the same run reproduces ``bridge_energy.json``'s energies
    (one ngspice run for both; test_spice_bridge_energy compares the model with the stored ones)."""
    stored = netlist_path("schottky", bridge=True).read_text()
    text = bridge_energy_netlist("schottky")
    assert text.startswith(stored.removesuffix(".end\n")) and text.endswith(".end\n")
    vals = _ngspice_values(text, tmp_path, "check.cir", 3600)
    got, sw = keys_from_values(vals), _model_with_dead_time("schottky")
    for key in KEYS:
        assert got[key] == pytest.approx(BRIDGE["schottky"][key], rel=1e-4), key
        assert sw[key] == pytest.approx(got[key], rel=0.005), (key, sw[key], got[key])
    energies = json.loads((HERE / "bridge_energy.json").read_text())["ngspice"]
    e = bridge_energy_values(vals)
    assert set(e) == set(energies)
    for k, v in energies.items():
        assert e[k] == pytest.approx(v, rel=1e-4, abs=1e-9), k


# ---------------------------------------------------------------- the public writer, dronewpt netlist


def test_cli_netlist_is_the_stored_netlist(tmp_path):
    """``dronewpt netlist`` writes the stored, SPICE-checked netlist byte for byte (same generator)."""
    from mission_sim.cli import main
    out = tmp_path / "n.cir"
    assert main(["netlist", "--devices", "schottky", "--out", str(out)]) == 0
    assert out.read_text() == netlist_path("schottky").read_text()
    assert main(["netlist", "--devices", "schottky", "--dead-time", repr(BRIDGE_DEAD_TIME_S), "--out", str(out)]) == 0
    assert out.read_text().replace("schottky, full bridge, dead time 2e-07 s", "schottky, full bridge") == \
        netlist_path("schottky", bridge=True).read_text()
    assert main(["netlist", "--d-short", "1.5"]) == 2


@pytest.mark.skipif(shutil.which("ngspice") is None, reason="ngspice not installed")
def test_partial_duty_netlist_matches_switching_model(tmp_path):
    """A case no stored netlist covers (d_short = 0.5 after the step: gate windows centred on the
    model's clock) from ``dronewpt netlist``: ngspice and the switching model agree within 0.5 %,
    and the partial duty really differs from short mode."""
    from mission_sim.cli import main
    out = tmp_path / "half.cir"
    args = ["--devices", "schottky", "--t-step", "1e-3", "--t-end", "2e-3"]
    assert main(["netlist", *args, "--d-short", "0.5", "--out", str(out)]) == 0
    sp = run_ngspice(out.read_text(), tmp_path)
    sw = switching_measure(dv=preset("schottky"), t_step_s=1e-3, t_end_s=2e-3, d_short=0.5)
    for key in KEYS:
        assert sw[key] == pytest.approx(sp[key], rel=0.005), (key, sw[key], sp[key])
    full = switching_measure(dv=preset("schottky"), t_step_s=1e-3, t_end_s=2e-3, d_short=1.0)
    assert abs(full["sm_i1_a"] - sw["sm_i1_a"]) > 0.2 * sw["sm_i1_a"]
