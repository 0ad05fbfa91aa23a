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
from wpt_receiver.switching.netlist import T_END_S, T_STEP_S, _diodes, initial_state, netlist  # noqa: F401 (re-exported)

HERE = Path(__file__).parent / "spice"
KEYS = ("rm_i2_a", "step_peak_a", "sm_i2_a", "rm_i1_a", "sm_i1_a")
BRIDGE_DEAD_TIME_S = 200e-9  # a realistic dead time for a 30-60 V MOSFET bridge at 85 kHz (3.4 % of T)


def _ngspice_values(text: str, workdir: Path, name: str, timeout_s: float) -> dict:
    """Run netlist ``text`` (written to ``workdir/name``) in ngspice batch mode: its ``.meas`` values
    by lower-case name."""
    exe = shutil.which("ngspice")
    if exe is None:
        raise FileNotFoundError("ngspice is not installed")
    cir = Path(workdir) / name
    cir.write_text(text)
    out = subprocess.run([exe, "-b", str(cir)], capture_output=True, text=True, timeout=timeout_s).stdout
    return {m.group(1).lower(): float(m.group(2)) for m in re.finditer(r"^\s*(\w+)\s*=\s*([-+0-9.eE]+)", out, re.M)}


def run_ngspice(text: str, workdir: Path) -> dict:
    """Run ngspice in batch mode and return the measurements (``KEYS``)."""
    return keys_from_values(_ngspice_values(text, workdir, "check.cir", 900))


def keys_from_values(vals: dict) -> dict:
    """``KEYS`` from a netlist's ``.meas`` values (:func:`_ngspice_values`)."""
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


_NUM = re.compile(r"^(?P<pre>[A-Za-z]+=)?(?P<num>[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)$")


def netlist_mismatches(stored: str, fresh: str, rel: float = 1e-9) -> list[str]:
    """Where two netlists differ beyond round-off: every token equal, except numbers (also ``IC=<x>``), which
    must agree to ``rel`` relative (or 1e-12 absolute). Computed initial conditions come from a steady state
    whose last bits depend on the machine's BLAS / libm paths (seen: 1e-13 relative between two x86 machines)."""
    a, b = stored.splitlines(), fresh.splitlines()
    if len(a) != len(b):
        return [f"{len(a)} lines stored, {len(b)} fresh"]
    out = []
    for n, (la, lb) in enumerate(zip(a, b), 1):
        ta, tb = la.split(), lb.split()
        if len(ta) != len(tb):
            out.append(f"line {n}: {la!r} != {lb!r}")
            continue
        for x, y in zip(ta, tb):
            if x == y:
                continue
            mx, my = _NUM.match(x), _NUM.match(y)
            if not (mx and my and mx["pre"] == my["pre"]
                    and math.isclose(float(mx["num"]), float(my["num"]), rel_tol=rel, abs_tol=1e-12)):
                out.append(f"line {n}: {x!r} != {y!r}")
    return out


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


def main_efficiency() -> None:
    """Regenerate ``eff_schottky.cir`` and ``efficiency.json``: ``python tests/_spice.py efficiency``."""
    import json
    import tempfile

    from wpt_receiver.devices import preset
    text = efficiency_netlist(dv=preset("schottky"))
    (HERE / "eff_schottky.cir").write_text(text)
    with tempfile.TemporaryDirectory() as tmp:
        got = run_ngspice_energies(text, Path(tmp))
    ref = {"d_short": EFF_DUTY, "t_end_s": EFF_T_END_S, "t_meas_s": EFF_T_MEAS_S, "ngspice": got}
    (HERE / "efficiency.json").write_text(json.dumps(ref, indent=1) + "\n")
    print(got)



# ============================================================ efficiency with edge losses (issue 23)
EFF_DUTY = 0.37          # short duty of the efficiency check (window centred on the i2 peak)
EFF_T_END_S = 1.2e-3     # SPICE run length from the model's periodic steady state
EFF_T_MEAS_S = 0.6e-3    # energies integrated over [EFF_T_END_S - EFF_T_MEAS_S, EFF_T_END_S]


def efficiency_start_state(p, dv: DeviceSet, d: float = EFF_DUTY):
    """(i1, vC1, i2, vC2) at model time T/2 of the switching model's periodic steady state at
    duty ``d`` (stiff battery, no dead time): where both simulators start."""
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    link = SwitchingLink(p, SwitchingConfig(devices=dv))
    x0 = link.periodic_steady_state(d)
    res = link.simulate([d], t_end_s=link.T / 2, x0=x0)
    return tuple(float(v) for v in link.final_state(res)[:4])


def efficiency_netlist(p=TABLE_I, dv: DeviceSet = DeviceSet(), d: float = EFF_DUTY, label: str = "schottky",
                       x0=None) -> str:
    """ngspice netlist of the SBAR at a constant short duty with the devices' edge data: Schottky
    junction capacitance ``Cj`` (linear, charge-equivalent) across each upper diode, ``Coss``
    across each lower switch (each with a 0.05 ohm ESR), and each
    lower channel as a behavioural current ``min(v / Ron, limit)``: the limit ramps over
    ``t_r = 2 eon_j_va`` from 0 to the |i2| sampled at the gate-on edge (a track-and-hold) and
    falls over ``t_f = 2 eoff_j_va`` from the |i2| sampled at the gate-off edge (linear current
    rise / fall, the datasheet's ``E = V I t / 2``). The inverter is the square-wave source with
    ``2 Ron`` of ``link_<preset>.cir``. SPICE time 0 = model time T/2; windows centred on the
    model's ``n T``.

    Not in the netlist: the body diodes' reverse recovery. A charge-control junction (``TT``) on the
    near-ideal junction (``N = 0.01 .. 0.1``) of these diode models stops ngspice at the first hard
    turn-on ("timestep too small"); in the SBAR the body diodes only commutate naturally (at
    ``omega I2`` ~ 6 A/us), where the model's recovery term is ~0.01 W (reported separately)."""
    w, T = p.omega_rad_s, p.rectifier_period_s
    c1, c2 = 1 / (w * w * p.l1_h), 1 / (w * w * p.l2_h)
    i10, vc10, i20, vc20 = efficiency_start_state(p, dv, d) if x0 is None else x0
    k = p.lm_h / math.sqrt(p.l1_h * p.l2_h)
    sw, dio, body = dv.rect_switch, dv.rect_diode, dv.rect_switch.body
    tr, t_on, t_off = 1e-10, 2 * sw.eon_j_va, 2 * sw.eoff_j_va
    ts_on = (1 - d) * T / 2
    ts_off = ts_on + d * T
    ch = "V({n}) > 0 ? min(V({n})/{r!r}, V(lim)) : V({n})/{r!r}*V(gate)"
    lines = [
        f"* dronewpt SPICE efficiency check with edge losses, devices: {label}, d_short = {d!r}\n",
        f"VINV p 0 PULSE({p.vdc_v!r} {-p.vdc_v!r} {T / 2 - tr / 2!r} {tr!r} {tr!r} {T - tr!r} {2 * T!r})\n",
        f"C1 p c1 {c1!r} IC={vc10!r}\n", f"R1 c1 c {p.r1_ohm + dv.inv_r_ohm!r}\n", f"L1 c 0 {p.l1_h!r} IC={i10!r}\n",
        f"L2 a b {p.l2_h!r} IC={-i20!r}\n", f"K12 L1 L2 {k!r}\n", f"R2 bb b {p.r2_ohm!r}\n",
        f"C2 bq bb {c2!r} IC={vc20!r}\n", "VSENSE bq bn DC 0\n",
        _diodes(dio, (("U1", "a", "bat"), ("U2", "bn", "bat"))),
        _diodes(body, (("B1", "0", "a"), ("B2", "0", "bn"))),
        # the capacitances with a 0.05 ohm ESR: a shorted node discharges in ~0.1 ns, not in Ron C = 16 ps
        "".join(f"C{n} {a} e{n} {c!r}\nRE{n} e{n} {b} 0.05\n" for n, a, b, c in (
            ("J1", "a", "bat", dio.c_f), ("J2", "bn", "bat", dio.c_f), ("O1", "a", "0", sw.coss_f),
            ("O2", "bn", "0", sw.coss_f))),
        # periodic drive (PWL, repeated every T): the ideal gate, the channel's current-limit shape w
        # (0 off; 0 -> 1 in t_r at gate-on, then 1 -> 1000 in 1 ns; 1000 -> 1 at gate-off, 1 -> 0 in
        # t_f) and the track signal of the sample-and-hold (holds |i2| from 1 ns before each edge)
        _pwl("gate", T, [(0, 0), (ts_on, 0), (ts_on + tr, 1), (ts_off, 1), (ts_off + tr, 0), (T, 0)]),
        _pwl("w", T, [(0, 0), (ts_on, 0), (ts_on + t_on, 1), (ts_on + t_on + 1e-9, 1000), (ts_off - 1e-11, 1000),
                      (ts_off, 1), (ts_off + t_off, 0), (T, 0)]),
        _pwl("trk", T, [(0, 1), (ts_on - 1.1e-9, 1), (ts_on - 1e-9, 0), (ts_on + 3 * t_on, 0),
                        (ts_on + 3 * t_on + tr, 1), (ts_off - 1.1e-9, 1), (ts_off - 1e-9, 0), (ts_off + 3 * t_off, 0),
                        (ts_off + 3 * t_off + tr, 1), (T, 1)]),
        "BABS habs 0 V=abs(i(VSENSE))\n",
        "SH habs h trk 0 SWT\nCH h 0 1e-12\n",
        "BLIM lim 0 V=V(h)*V(w)\n",
        f"BCH1 a 0 I={ch.format(n='a', r=max(sw.ron_ohm, 1e-6))}\n",
        f"BCH2 bn 0 I={ch.format(n='bn', r=max(sw.ron_ohm, 1e-6))}\n",
        f"VL bat 0 DC {p.vl_v!r}\n",
        ".model DI D(IS=1e-6 N=0.01)\n",
        ".model SWT SW(VT=0.5 VH=0.1 RON=1000 ROFF=1e12)\n",
        ".options reltol=1e-6 abstol=1e-9 vntol=1e-7 method=gear maxord=2 itl4=200\n",
        f".tran {T / 1000!r} {EFF_T_END_S!r} 0 {T / 1000!r} uic\n",
        f".meas tran esrc INTEG par('-v(p)*i(vinv)') from={EFF_T_END_S - EFF_T_MEAS_S!r} to={EFF_T_END_S!r}\n",
        f".meas tran ebat INTEG par('v(bat)*i(vl)') from={EFF_T_END_S - EFF_T_MEAS_S!r} to={EFF_T_END_S!r}\n",
        ".end\n"]
    return "".join(lines)


def _pwl(node: str, period: float, pts) -> str:
    """A PWL voltage source on ``node`` repeating ``pts`` (time, value) every ``period``."""
    body = " ".join(f"{t!r} {v!r}" for t, v in pts)
    return f"V{node.upper()} {node} 0 PWL({body}) r=0\n"


def run_ngspice_energies(text: str, workdir: Path) -> dict:
    """Run an :func:`efficiency_netlist` and return ``{"source_j", "battery_j", "efficiency"}``."""
    vals = _ngspice_values(text, workdir, "eff.cir", 1800)
    src, bat = vals["esrc"], abs(vals["ebat"])
    return {"source_j": src, "battery_j": bat, "efficiency": bat / src}


def efficiency_model(p=TABLE_I, dv: DeviceSet = DeviceSet(), d: float = EFF_DUTY) -> dict:
    """The same efficiency from the event-exact switching model: conduction in the state equations,
    the SBAR's edge energies (:func:`wpt_receiver.edge_losses.edge_energies`) added to the losses
    (the secondary is a current source: the edge losses are drawn from the DC source), over the
    same window of the same run (model time = SPICE time + T/2, same start state)."""
    from wpt_receiver.edge_losses import edge_energies
    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    from wpt_receiver.switching.schedule import make_schedule
    link = SwitchingLink(p, SwitchingConfig(devices=dv))
    T = link.T
    x0 = np.zeros(link.cir.m)
    x0[:4] = efficiency_start_state(p, dv, d)
    x0[-1] = 1.0
    res = link.run(make_schedule(T / 2, T / 2 + EFF_T_END_S, T, lambda n: np.full(np.shape(n), d), 0.0, 0.0,
                                 p.omega_rad_s), x0)
    ta, tb = T / 2 + EFF_T_END_S - EFF_T_MEAS_S, T / 2 + EFF_T_END_S
    eb, ee = res.energy_balance(ta, tb), edge_energies(res, ta, tb)
    src, bat = eb["source_j"], eb["battery_j"]
    return {"source_j": src, "battery_j": bat, "efficiency_conduction": bat / src,
            "efficiency": bat / (src + ee["rect_j"]), **{k: v for k, v in ee.items()}}


# ============================================================ ringing of a hard turn-off edge (issue 23)
RING_CASES = ((4.0, 8e-9), (12.0, 8e-9), (12.0, 20e-9))   # (current A, stray loop inductance H)
RING_V_V, RING_R_OHM, RING_T_F_S = 30.8, 0.05, 10e-9


def ring_netlist(i_a: float, l_h: float, c_f: float, v_v: float = RING_V_V, r_ohm: float = RING_R_OHM,
                 t_f_s: float = RING_T_F_S) -> str:
    """One hard turn-off: a constant current ``i_a`` into node n, the channel's current falling
    linearly to 0 in ``t_f_s`` from t = 10 ns, node capacitance ``c_f``, clamp diode (near-ideal
    junction) in series with ``l_h`` and ``r_ohm`` to ``v_v``; measured: the peak of v(n)."""
    t0 = 10e-9
    return "".join([
        f"* dronewpt SPICE check of the edge ring: I = {i_a!r} A, Ls = {l_h!r} H, C = {c_f!r} F\n",
        f"IS 0 n DC {i_a!r}\n",
        f"BCH n 0 I={i_a!r}*max(0, min(1, 1 - (time - {t0!r})/{t_f_s!r}))\n",
        f"C n 0 {c_f!r} IC=0\n",
        "D n x DI\n", f"LS x y {l_h!r} IC=0\n", f"RS y z {r_ohm!r}\n", f"V z 0 DC {v_v!r}\n",
        ".model DI D(IS=1e-6 N=0.01)\n",
        ".options reltol=1e-7 abstol=1e-10 vntol=1e-8 method=gear\n",
        f".tran 1e-12 {t0 + t_f_s + 60e-9!r} 0 2e-12 uic\n",
        ".meas tran vpeak MAX V(n)\n", ".end\n"])


def ring_cases():
    """The ring netlists for the schottky preset's node capacitance (Coss + Cj)."""
    from wpt_receiver.devices import preset
    dv = preset("schottky")
    c = dv.rect_switch.coss_f + dv.rect_diode.c_f
    return [(i, l, c, ring_netlist(i, l, c)) for i, l in RING_CASES]


def run_ngspice_ring(text: str, workdir: Path) -> float:
    exe = shutil.which("ngspice")
    if exe is None:
        raise FileNotFoundError("ngspice is not installed")
    cir = Path(workdir) / "ring.cir"
    cir.write_text(text)
    out = subprocess.run([exe, "-b", str(cir)], capture_output=True, text=True, timeout=600).stdout
    return float(re.search(r"^\s*vpeak\s*=\s*([-+0-9.eE]+)", out, re.M).group(1))


def main_ring() -> None:
    """Regenerate ``edge_ring_<k>.cir`` and ``edge_ring.json``: ``python tests/_spice.py ring``."""
    import json
    import tempfile
    res = []
    for k, (i, l_h, c, text) in enumerate(ring_cases()):
        (HERE / f"edge_ring_{k}.cir").write_text(text)
        with tempfile.TemporaryDirectory() as tmp:
            res.append({"i_a": i, "l_stray_h": l_h, "c_f": c, "peak_v": run_ngspice_ring(text, Path(tmp))})
    (HERE / "edge_ring.json").write_text(json.dumps({"v_v": RING_V_V, "r_ohm": RING_R_OHM, "t_f_s": RING_T_F_S,
                                                     "cases": res}, indent=1) + "\n")
    print(res)


# ============================================================ source energy of the full bridge (body-diode return)
#: the windows (model time) of the bridge's energy check: the last 40 rectifier periods before the step (RM) and
#: before the end (SM)
BRIDGE_ENERGY_PERIODS = 40


def bridge_energy_windows(p=TABLE_I) -> dict:
    """``{"rm": (a, b), "sm": (a, b)}`` [s, model time] of :func:`bridge_energy_netlist`'s integrals."""
    n = BRIDGE_ENERGY_PERIODS * p.rectifier_period_s
    return {"rm": (T_STEP_S - n, T_STEP_S), "sm": (T_END_S - n, T_END_S)}


def bridge_energy_netlist(name: str = "schottky", p=TABLE_I) -> str:
    """:func:`bridge_netlist` with ``.meas INTEG`` of the DC source's net energy ``esrc_<w>`` (int Vdc i_dc), the
    part it takes back ``eret_<w>`` (int max(-Vdc i_dc, 0): the body diodes freewheeling into Vdc in the dead time
    and whenever i1 runs against the driven diagonal) and the battery's ``ebat_<w>`` over each window of
    :func:`bridge_energy_windows` (SPICE time = model time - T/2)."""
    meas = []
    for w, (a, b) in bridge_energy_windows(p).items():
        a, b = a - p.rectifier_period_s / 2, b - p.rectifier_period_s / 2
        meas += [f".meas tran esrc_{w} INTEG par('-{p.vdc_v!r}*i(VDC)') from={a!r} to={b!r}\n",
                 f".meas tran eret_{w} INTEG par('max({p.vdc_v!r}*i(VDC),0)') from={a!r} to={b!r}\n",
                 f".meas tran ebat_{w} INTEG par('-{p.vl_v!r}*i(VL)') from={a!r} to={b!r}\n"]
    return bridge_netlist(name).replace(".end\n", "".join(meas) + ".end\n")


def bridge_energy_sha1(name: str = "schottky") -> str:
    """SHA-1 of :func:`bridge_energy_netlist`'s text (stored in ``bridge_energy.json``: a changed netlist is caught
    without ngspice)."""
    import hashlib
    return hashlib.sha1(bridge_energy_netlist(name).encode()).hexdigest()


def bridge_energy_values(vals: dict) -> dict:
    """The ``esrc_*``, ``eret_*``, ``ebat_*`` [J] of a :func:`bridge_energy_netlist`'s ``.meas`` values."""
    return {k: v for k, v in vals.items() if k.startswith(("esrc_", "eret_", "ebat_"))}


def run_ngspice_bridge_energy(text: str, workdir: Path) -> dict:
    """Run a :func:`bridge_energy_netlist`: its ``esrc_*``, ``eret_*``, ``ebat_*`` [J]."""
    return bridge_energy_values(_ngspice_values(text, workdir, "bridge_energy.cir", 3600))


def bridge_energy_model(dv: DeviceSet, p=TABLE_I, samples_per_period: int = 4000) -> dict:
    """The same energies from the switching model with the bridge's dead time (closed-form ``energy_balance``; the
    returned part from ``samples_per_period`` samples of the source current per rectifier period), plus its
    balance residual and device groups per window: ``{"<key>_<w>": J}``."""
    from scipy.integrate import trapezoid

    from wpt_receiver.switching import SwitchingConfig, SwitchingLink
    link = SwitchingLink(p, SwitchingConfig(devices=dv, dead_time_s=BRIDGE_DEAD_TIME_S))
    x0 = np.zeros(link.cir.m)
    x0[:4] = initial_state(p, dv)
    x0[-1] = 1.0
    res = _run_step(link, x0)
    rows, out = res.circuit.rows, {}
    for w, (a, b) in bridge_energy_windows(p).items():
        e = res.energy_balance(a, b)
        out.update({f"esrc_{w}": e["source_j"], f"ebat_{w}": e["battery_j"], f"resid_{w}": e["residual_j"],
                    f"inverter_diodes_{w}": e["inverter_diodes_loss_j"],
                    f"inverter_switches_{w}": e["inverter_switches_loss_j"]})
        ts = np.linspace(a, b, samples_per_period * BRIDGE_ENERGY_PERIODS + 1)
        x, k = res.states(ts)
        i_src = np.einsum("ij,ij->i", np.array([rows[kk]["i_src"] for kk in k]), x)
        out[f"eret_{w}"] = float(trapezoid(np.maximum(-p.vdc_v * i_src, 0.0), x=ts))
    return out


def main_bridge_energy() -> None:
    """Regenerate ``bridge_energy.json`` (ngspice, ~3 min): ``python tests/_spice.py bridge_energy``."""
    import json
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        got = run_ngspice_bridge_energy(bridge_energy_netlist("schottky"), Path(tmp))
    (HERE / "bridge_energy.json").write_text(json.dumps({"preset": "schottky", "dead_time_s": BRIDGE_DEAD_TIME_S,
                                                         "periods": BRIDGE_ENERGY_PERIODS,
                                                         "netlist_sha1": bridge_energy_sha1("schottky"), "ngspice": got},
                                                        indent=1) + "\n")
    print(got)


if __name__ == "__main__":
    import sys
    {"efficiency": main_efficiency, "ring": main_ring, "bridge_energy": main_bridge_energy}.get(sys.argv[1] if len(sys.argv) > 1 else "", main)()
