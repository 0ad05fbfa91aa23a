"""Independent SPICE check of the switching-level model with devices (ngspice netlists).

The netlist writer is public: :mod:`wpt_receiver.switching.netlist` (also ``dronewpt netlist``);
this module keeps the scenario's constants, the ngspice runner and the model's side of the check.

The scenario (model time; SPICE time is model time - T/2): the link starts at the fundamental (phasor) solution of eq. 4 with the devices
folded in (closed form, not from the switching model), runs in RM for ``T_STEP_S``, then the
SBAR shorts (SM) until ``T_END_S``. Both simulators start from the same state, so the numbers
compare the same transient. Measured: peak |i2| over the last 4 rectifier periods before the step
(``rm_i2_a``) and before the end (``sm_i2_a``), the step peak after the switch (``step_peak_a``)
and peak |i1| before the step and at the end (``rm_i1_a``, ``sm_i1_a``).

Device models in the netlist are the ones of :mod:`wpt_receiver.devices`: every diode is a
near-ideal junction (``IS = 1 uA``, ``N = 0.01``: 4 mV at 10 A, 1 uA leakage) in series with a DC source
``vf0_v`` and a resistor ``rd_ohm``; every MOSFET channel a voltage-controlled switch with
``RON = ron_ohm``. The inverter is either (``link_<preset>.cir``) a square-wave source with the two
driven channels' resistance in series (no dead time), or (``link_bridge_<preset>.cir``) a real full
bridge: a DC source, four switches with ``RON`` of the inverter switch, each with its body diode,
and one gate source per diagonal with the dead time ``BRIDGE_DEAD_TIME_S`` after every
commutation (both diagonals off; the current freewheels through the body diodes or the bridge
blocks). The switching model then runs with the same dead time (its own ``make_schedule``).
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from wpt_receiver import TABLE_I
from wpt_receiver.devices import DeviceSet
from wpt_receiver.switching.netlist import T_END_S, T_STEP_S, initial_state, netlist  # noqa: F401 (re-exported)

HERE = Path(__file__).parent / "spice"
KEYS = ("rm_i2_a", "step_peak_a", "sm_i2_a", "rm_i1_a", "sm_i1_a")
BRIDGE_DEAD_TIME_S = 200e-9  # a realistic dead time for a 30-60 V MOSFET bridge at 85 kHz (3.4 % of T)


def run_ngspice(text: str, workdir: Path) -> dict:
    """Run ngspice in batch mode and return the measurements (``KEYS``)."""
    exe = shutil.which("ngspice")
    if exe is None:
        raise FileNotFoundError("ngspice is not installed")
    cir = Path(workdir) / "check.cir"
    cir.write_text(text)
    out = subprocess.run([exe, "-b", str(cir)], capture_output=True, text=True, timeout=900).stdout
    vals = {m.group(1).lower(): float(m.group(2))
            for m in re.finditer(r"^\s*(\w+)\s*=\s*([-+0-9.eE]+)", out, re.M)}
    # I(VSENSE) flows from C2 into the SBAR's B node: i2 of the model flows out of A, i.e. -I(VSENSE)
    peak = lambda n, s: max(abs(vals[f"{n}_{s}_max"]), abs(vals[f"{n}_{s}_min"]))  # noqa: E731
    return {"rm_i2_a": peak("rm", "i2"), "step_peak_a": peak("step", "i2"), "sm_i2_a": peak("sm", "i2"),
            "rm_i1_a": peak("rm", "i1"), "sm_i1_a": peak("sm", "i1")}


def switching_measure(p=TABLE_I, dv: DeviceSet = DeviceSet(), dead_time_s: float = 0.0, t_step_s: float = T_STEP_S,
                      t_end_s: float = T_END_S, d_short: float = 1.0) -> dict:
    """The same numbers from the event-exact switching model (dense peaks on a fine grid)."""
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    link = SwitchingLink(p, SwitchingConfig(devices=dv, dead_time_s=dead_time_s))
    T = link.T
    x0 = np.zeros(link.cir.m)
    x0[:4] = initial_state(p, dv)
    x0[-1] = 1.0
    res = _run_step(link, x0, t_step_s, t_end_s, d_short)
    ts = np.union1d(np.arange(T / 2, t_end_s, T / 400), res.seg_t)
    x, _ = res.states(ts, cols=[0, 2])
    w = 4 * T

    def peak(col, a, b):
        sel = (ts >= a) & (ts <= b)
        return float(np.max(np.abs(x[sel, col])))
    return {"rm_i2_a": peak(1, t_step_s - w, t_step_s), "step_peak_a": peak(1, t_step_s, t_end_s),
            "sm_i2_a": peak(1, t_end_s - w, t_end_s), "rm_i1_a": peak(0, t_step_s - w, t_step_s),
            "sm_i1_a": peak(0, t_end_s - w, t_end_s)}


def _run_step(link, x0, t_step_s=T_STEP_S, t_end_s=T_END_S, d_short=1.0):
    """Gate off until t_step_s, duty ``d_short`` after (both lower switches); inverter +Vdc on [0, T), -Vdc on
    [T, 2T), ..., each commutation followed by the link's dead time; from T/2. The model's own
    schedule: one gate window per period centred at (n + 1/2) T (phase pi/2), duty 0 before the
    step and ``d_short`` (1: the whole period) from it."""
    from wpt_receiver.switching.schedule import make_schedule
    T = link.T
    n_step = round(t_step_s / T)
    windows = lambda n: d_short * (np.asarray(n) >= n_step).astype(float)  # noqa: E731
    return link.run(make_schedule(T / 2, t_end_s, T, windows, math.pi / 2, link.cfg.dead_time_s), x0)


PRESETS = ("ideal", "schottky", "sic")
BRIDGE_PRESETS = ("ideal", "schottky")


def netlist_path(name: str, bridge: bool = False) -> Path:
    return HERE / (f"link_bridge_{name}.cir" if bridge else f"link_{name}.cir")


def bridge_netlist(name: str) -> str:
    """Full-bridge netlist of a preset with ``BRIDGE_DEAD_TIME_S``."""
    from wpt_receiver.devices import preset
    return netlist(dv=preset(name), label=f"{name}, full bridge", dead_time_s=BRIDGE_DEAD_TIME_S)


def main() -> None:
    """Regenerate the netlists and, with ngspice, the reference numbers: ``python tests/_spice.py``."""
    import json
    import tempfile

    from wpt_receiver.devices import preset
    ref = {"scenario": {"t_step_s": T_STEP_S, "t_end_s": T_END_S, "keys": list(KEYS)},
           "ngspice": next((ln.strip("* ").strip() for ln in subprocess.run(
               ["ngspice", "-v"], capture_output=True, text=True).stdout.splitlines() if "ngspice-" in ln), "?"),
           "results": {}}
    for name in PRESETS:
        text = netlist(dv=preset(name), label=name)
        netlist_path(name).write_text(text)
        with tempfile.TemporaryDirectory() as tmp:
            ref["results"][name] = run_ngspice(text, Path(tmp))
        print(name, ref["results"][name])
    ref["bridge"] = {"dead_time_s": BRIDGE_DEAD_TIME_S, "results": {}}
    for name in BRIDGE_PRESETS:
        text = bridge_netlist(name)
        netlist_path(name, bridge=True).write_text(text)
        with tempfile.TemporaryDirectory() as tmp:
            ref["bridge"]["results"][name] = run_ngspice(text, Path(tmp))
        print("bridge", name, ref["bridge"]["results"][name])
    (HERE / "reference.json").write_text(json.dumps(ref, indent=1) + "\n")


if __name__ == "__main__":
    main()
