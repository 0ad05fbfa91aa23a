"""An unplanned pad switch-off (k falls below ``coupling.tx_min_k`` while the drone hovers) against the project's
time-domain switching model (:class:`wpt_receiver.switching.SwitchingLink`; docs/mission.md "Pad switch-off").

When the pad's V1 has reached 0 after its ramp and the coil currents still ring, the receiver's protection holds the
SBAR at d = 0 (plain diode rectification; ``sim.rectify_after_pad_off``, default true). From the drift run's state at
that step (I1 5.7 A, I2 ~ 0, k = 0.0748 at the drifted position) the secondary's emf w Lm I1 = 15 V is below the
clamp's fundamental (4/pi)(VL + Vf) = 42.6 V: the diodes block, I2 stays 0 and I1 decays in R1 (+ the inverter's
2 Ron). The switching model (exact, event-located, the same devices, V1 ~ 0) is the reference. With the option off
the loop shorts the secondary from that step (v2 = 0, the model before 2026-11-28): the two tanks ring freely and the
primary's energy beats into the secondary (16.8 A at the first step's end)."""

import dataclasses

import numpy as np
import pytest

from mission_sim.config import apply_overrides, config_from_dict, config_to_dict, hover_inductances, load_config
from mission_sim.contract import PolicyContext
from mission_sim.world.runner import run_mission
from mission_sim.world.trajectory import Trajectory
from policies import make

RING_S = 1.5e-3   # the compared ring-down: 15 control periods, a third of I1's decay time 2 L1 / (R1 + 2 Ron)


class _FullRectify:
    """The SBAR at d = 0 throughout (full rectification, action -1): the pad switches off at a large I1."""
    name = "full_rectify"

    def reset(self, n=1):
        pass

    def act(self, obs):
        return -np.ones((np.asarray(obs).shape[0], 1))


def _drift(rectify, policy=None, **link):
    """Hover over pad 0 at the nominal gap, then drift sideways at 0.1 m/s (still 'hover': an energising phase)
    until k falls below tx_min_k: the pad switches off unplanned, V1 ramps down over link.tx_ramp_s (``link``:
    overrides of the config's link section)."""
    cfg = load_config()
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, rectify_after_pad_off=rectify),
                              link=dataclasses.replace(cfg.link, **link))
    t = np.arange(0.0, 6.0, 0.05)
    pos = np.zeros((len(t), 3))
    pos[:, 2] = cfg.mission.hover_gap_m
    pos[:, 0] = np.clip((t - 3.0) * 0.1, 0.0, None)
    tr = Trajectory.from_samples(t, pos, phase="hover")
    pol = policy or make("model_based", PolicyContext(control_period_s=cfg.sim.control_period_s,
                                                      rated_i2_a=cfg.link.rated_i2_a))
    res = run_mission(cfg, pol, trajectory=tr, warn=False)
    ts = res.timeseries
    v1 = ts["v1_v"].to_numpy()
    rows = np.arange(len(v1))
    last_full = np.flatnonzero(v1 == v1.max())[-1]
    assert ts["k"].iloc[last_full + 1] < cfg.coupling.tx_min_k     # the switch-off is the k threshold's
    off = np.flatnonzero((v1 == 0.0) & (rows > last_full))[0]     # the first step with V1 = 0
    return cfg, res, last_full, off


@pytest.fixture(scope="module")
def drift_off():
    return _drift(True)


@pytest.fixture(scope="module")
def drift_short():
    return _drift(False)


@pytest.fixture(scope="module")
def switching_ring_down(drift_off):
    return _switching(drift_off)


def _switching(drift_off):
    """The switching model from the kernel's state at the start of the first V1 = 0 step: I1 (phasor amplitude,
    the series capacitor at its resonant phase), I2 = 0 (the kernel's 0.006 A there is below the model's tolerance
    for a blocked secondary), the row's Lm and VL, the config's devices (inverter 2 Ron, Schottky Vf0 + Rd), a
    stiff battery, Vdc = 1 nV (the inverter's switches conduct, v1 ~ 0), the SBAR's gate never on (d = 0)."""
    from wpt_receiver.params import LinkParams
    from wpt_receiver.switching.circuit import SwitchingConfig
    from wpt_receiver.switching.link import SwitchingLink
    cfg, res, _, off = drift_off
    ts = res.timeseries
    l1, l2 = hover_inductances(cfg.coupling, cfg.mission.hover_gap_m)[:2]
    i1 = ts["i1_amp_a"].iloc[off - 1]
    p = LinkParams(l1_h=l1, l2_h=l2, lm_h=ts["lm_h"].iloc[off - 1], r1_ohm=cfg.link.r1_ohm, r2_ohm=cfg.link.r2_ohm,
                   vdc_v=1e-9, vl_v=ts["battery_v"].iloc[off - 1], f_hz=cfg.link.f_hz)
    sl = SwitchingLink(p, SwitchingConfig(devices=cfg.link.device_set()))
    r = sl.run(sl.schedule(0.0, RING_S, 0.0), sl.cir.phasor_state(i1, 0.0))
    return r.envelope(), r.energy_balance(0.0, RING_S), 0.5 * l1 * i1 ** 2


def test_protection_rings_down_as_the_switching_model(drift_off, switching_ring_down):
    cfg, res, last_full, off = drift_off
    env, eb, w1 = switching_ring_down
    ts = res.timeseries
    t = ts["t_s"].to_numpy()
    t0 = t[off - 1]
    ring = (t > t0) & (t <= t0 + RING_S + 1e-9)
    assert ring.sum() == 15 and (ts["d_short"].to_numpy()[ring] == 0.0).all()   # the applied duty is recorded
    assert ts["i1_amp_a"].iloc[off - 1] > 3.0 and ts["d_short"].iloc[off - 1] > 0.5   # the policy's duty before
    # the switching model: the diodes block (I2 = 0, nothing into the battery), I1 decays
    assert env["i2_env_a"].max() < 1e-6 and abs(eb["battery_j"]) < 1e-9
    # the kernel: max |I2| within 0.05 A of it (its rows are step-end phasors; 0.05 A is 0.3 % of the 15 A rating,
    # far below the 8.7-19.8 A of a gated or shorted secondary from this state), the energy into the battery
    # within 0.1 % of the primary's stored energy w1 (3.8 mJ; the blocked diodes pass none), I1 at the end
    # within 1 % (the same R1 + 2 Ron decay; the switching model's per-half-cycle peak of a decaying sine)
    i2 = np.abs(ts["i2_amp_a"].to_numpy()[ring])
    assert i2.max() <= env["i2_env_a"].max() + 0.05
    assert abs(ts["e_rectifier_j"].to_numpy()[ring].sum() - eb["battery_j"]) < 1e-3 * w1
    assert ts["i1_amp_a"].to_numpy()[ring][-1] == pytest.approx(env["i1_env_a"].dropna().iloc[-1], rel=0.01)
    assert ts["i1_amp_a"].to_numpy()[ring][-1] < 0.8 * ts["i1_amp_a"].iloc[off - 1]   # it did decay


def test_protection_never_rectifies_backwards(drift_off):
    cfg, res, _, off = drift_off
    ts = res.timeseries
    s = res.summary
    assert s["energy_balance_error_rel"] < 1e-12
    assert ts["e_rectifier_j"].sum() == pytest.approx(s["rectifier_output_j"], rel=1e-12)
    # from V1 = 0 to the end (the whole ring-down, until the currents have died out): no step returns energy
    # from the battery through the rectifier, no negative device loss (the sliding SBAR envelope at d = 0.59 and
    # the always-conducting clamp at d = 0 both did: -66.5 uJ / -11 mJ)
    # (the first step books the feedthrough's stored-energy jump at V1's change to the rectifier: tens of nJ at most,
    # -11 nJ in the gust example; 1e-5 of the primary's stored energy w1 = 3.8 mJ)
    w1 = 0.5 * hover_inductances(cfg.coupling, cfg.mission.hover_gap_m)[0] * ts["i1_amp_a"].iloc[off - 1] ** 2
    for col in ("e_rectifier_j", "e_rectifier_diodes_j", "e_rectifier_switches_j"):
        assert ts[col].to_numpy()[off:].min() >= -1e-5 * w1, col
    assert np.abs(ts["i2_amp_a"].to_numpy()[off:]).max() < 0.05
    assert res.summary["peak_i2_a"] < cfg.link.rated_i2_a and res.summary["time_above_rated_s"] == 0.0
    # the currents die out (the window ends; no ringing left for the coarse steps)
    assert abs(ts["i1_amp_a"].iloc[-1]) < 1e-3 and abs(ts["i2_amp_a"].iloc[-1]) < 1e-3


def test_without_the_protection_the_secondary_is_shorted(drift_off, drift_short):
    """``sim.rectify_after_pad_off = false``: v2 = 0 from V1 = 0 (the short-mode / upper case): the primary's
    energy beats into the secondary above the rating; with the protection the same run's peak stays below it."""
    cfg, res, last_full, off = drift_short
    ts = res.timeseries
    i2 = np.abs(ts["i2_amp_a"].to_numpy())
    t = ts["t_s"].to_numpy()
    on_level = i2[(t > t[last_full] - 0.5) & (np.arange(len(t)) <= last_full)].max()   # I2 while the pad was on
    assert 10.0 < on_level < cfg.link.rated_i2_a
    assert i2[off] > cfg.link.rated_i2_a > on_level                     # the beat: 16.8 A at the first step's end
    assert (ts["v2_v"].to_numpy()[off:off + 10] == 0.0).all()
    assert res.summary["peak_i2_a"] > cfg.link.rated_i2_a
    assert drift_off[1].summary["peak_i2_a"] < cfg.link.rated_i2_a < res.summary["peak_i2_a"]


def test_discontinuous_conduction_above_vl_plus_vf_is_small():
    """The blocking test is the clamp's fundamental (4/pi)(VL + Vf): the envelope's always-conducting clamp cannot
    carry current below it. Real diodes conduct (discontinuously) once the emf w Lm I1 passes VL + Vf; the kernel
    neglects that. Its size from a d = 0 switch-off (I1 14.94 A, emf / (VL + Vf) = 1.22): the switching model's I2
    reaches 0.76 A and passes 1.2 mJ of the primary's 26 mJ into the battery over 1.5 ms, the kernel 0.4 mJ
    (I2 ~ 0); I1 at the end 9.72 vs 9.86 A. Pinned: the energy into the battery within 5 % of the stored energy,
    |I2| under 1 A in both, I1 at the end within 3 %."""
    run = _drift(True, _FullRectify())
    cfg, res, _, off = run
    env, eb, w1 = _switching(run)
    ts = res.timeseries
    t = ts["t_s"].to_numpy()
    ring = (t > t[off - 1]) & (t <= t[off - 1] + RING_S + 1e-9)
    assert ts["d_short"].iloc[off - 1] == 0.0 and ts["i1_amp_a"].iloc[off - 1] > 12.0
    assert 0.1 < env["i2_env_a"].max() < 1.0          # the real diodes do conduct, a little
    assert np.abs(ts["i2_amp_a"].to_numpy()[ring]).max() < 1.0
    assert abs(ts["e_rectifier_j"].to_numpy()[ring].sum() - eb["battery_j"]) < 0.05 * w1
    assert ts["i1_amp_a"].to_numpy()[ring][-1] == pytest.approx(env["i1_env_a"].dropna().iloc[-1], rel=0.03)


def test_a_slow_ring_down_is_carried_by_coarse_steps():
    """Ideal devices and r1_ohm = 1e-3: the primary's ring-down time 2 L1 / R1 is ~0.1 s, 1000 control periods.
    Once the protection's diodes block (I2 held at 0) coarse steps carry it, so the fine window ends at
    sim.max_fine_s as with the option off (before: 18,093 rows after the switch-off, I1 still 0.14 A at the run's
    end); the physics holds (I2 ~ 0, the energy balance to rounding, the currents die out)."""
    on = _drift(True, devices="ideal", r1_ohm=1e-3)
    off = _drift(False, devices="ideal", r1_ohm=1e-3)
    n_on, n_off = (len(r.timeseries) - k for _, r, _, k in (on, off))
    assert n_on < 1.5 * n_off            # 230 vs 206 rows
    cfg, res, _, k = on
    ts = res.timeseries
    assert np.abs(ts["i2_amp_a"].to_numpy()[k:]).max() < 1e-6
    assert res.summary["energy_balance_error_rel"] < 1e-12
    assert ts["e_rectifier_j"].to_numpy()[k:].min() >= -1e-9
    # coarse rows while the primary still rings (I1 > 0.1 A), the diodes blocking in them: I1 decays as the lone
    # primary's exp(-R1 t / (2 L1)) (no Ron: ideal devices) to the run's end, 1.9 s later (0.0214 vs 0.0216 of I1 at
    # the first V1 = 0 row; a v2 held over each whole coarse step instead drains it within 0.06 s into R2)
    i1, t = ts["i1_amp_a"].to_numpy(), ts["t_s"].to_numpy()
    assert ((i1[k:] > 0.1) & ~ts["fine"].to_numpy()[k:]).any()
    l1 = hover_inductances(cfg.coupling, cfg.mission.hover_gap_m)[0]
    assert i1[-1] / i1[k] == pytest.approx(np.exp(-cfg.link.r1_ohm / (2 * l1) * (t[-1] - t[k])), rel=0.02)


@pytest.mark.parametrize("value", [1, "true", None])
def test_the_option_is_a_boolean(value):
    d = apply_overrides(config_to_dict(load_config()), {"sim.rectify_after_pad_off": value})
    with pytest.raises(ValueError, match=r"^sim\.rectify_after_pad_off=.* is invalid; valid values: true, false$"):
        config_from_dict(d)
    assert config_from_dict(apply_overrides(config_to_dict(load_config()),
                                            {"sim.rectify_after_pad_off": False})).sim.rectify_after_pad_off is False


@pytest.mark.parametrize("value", [np.bool_(False), np.bool_(True)])
def test_the_option_takes_numpy_bools(value):
    """A sweep's grid (np.array([True, False])) hands numpy's bool: accepted through the overrides and the
    dataclass, stored as a Python bool (the config hashes and dumps it as TOML)."""
    cfg = config_from_dict(apply_overrides(config_to_dict(load_config()), {"sim.rectify_after_pad_off": value}))
    assert type(cfg.sim.rectify_after_pad_off) is bool and cfg.sim.rectify_after_pad_off == bool(value)
    sim = dataclasses.replace(load_config().sim, rectify_after_pad_off=value)
    assert type(sim.rectify_after_pad_off) is bool and sim.rectify_after_pad_off == bool(value)
