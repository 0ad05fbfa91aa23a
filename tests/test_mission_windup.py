"""A stateful policy answers a charge command at its control period in a mission, as on a real receiver.

``model_based_budget:b`` (b > 0) holds its relaxed reference while the command is 0, so its V2* rests at a
negative value below the clip (duty 1). When the command turns positive the controller needs tens of control
periods to bring V2* above 0 (the receiver stays shorted meanwhile). A fine window that closed on the
unchanged duty left the rest to coarse policy calls, one control period of the filter per second of flight:
the receiver stayed shorted with a positive command for 14.2 s at the default mission's first pad and 1.2 s at
the second, and the energy the charger asked for was not delivered. The mission loop keeps the window open
while the receiver is shorted under a positive command (``loop_kernel._answering``)."""

import numpy as np
import pandas as pd
import pytest

from mission_sim.config import load_config, policy_context
from mission_sim.contract import normalise_obs
from mission_sim.world.runner import run_mission
from policies import make

BUDGET = "model_based_budget:0.02"


def _shorted_after_command(ts: pd.DataFrame):
    """Per run of rows with a positive charge command: (time shorted from its start until the duty first
    leaves 1 [s], the charger's unmet power over that time ``sum VL I_L* dt`` [J])."""
    t_dt, d = ts["dt_s"].to_numpy(), ts["d_short"].to_numpy()
    cmd, vl = ts["charge_cmd_a"].to_numpy(), ts["battery_v"].to_numpy()
    pos = cmd > 0.0
    out = []
    for i in np.flatnonzero(pos & ~np.r_[False, pos[:-1]]):
        j = i
        while j < len(d) and pos[j] and d[j] >= 1.0 - 1e-9:
            j += 1
        out.append((float(t_dt[i:j].sum()), float((vl[i:j] * cmd[i:j] * t_dt[i:j]).sum())))
    return out


def _control_periods_to_answer(name: str, cfg, cmd_a: float, vl_v: float) -> int:
    """Control periods the policy, called once per control period as on the receiver's DSP, takes to leave
    duty 1 after the command steps from 0 (held 0.5 s before) to ``cmd_a``."""
    pol = make(name, policy_context(cfg))
    pol.reset(1)
    d = 1.0

    def obs(cmd, ts):
        return normalise_obs(np.array([[11.4, vl_v, -2.9, 0.0, 0.5, cmd, d, ts]]))

    for k in range(5000):
        d = float(pol.act(obs(0.0, min(k * cfg.sim.control_period_s, 0.01)))[0])
    for k in range(1, 2001):
        d = float(pol.act(obs(cmd_a, 0.0))[0])
        if d < 1.0 - 1e-9:
            return k
    raise AssertionError(f"{name} did not leave short mode in 2000 control periods")


@pytest.fixture(scope="module")
def budget_run():
    cfg = load_config()
    return cfg, run_mission(cfg, make(BUDGET, policy_context(cfg)))


def test_budgeted_controller_leaves_short_mode_at_its_control_period(budget_run):
    cfg, res = budget_run
    ts = res.timeseries
    windows = _shorted_after_command(ts)
    assert len(windows) >= 2                                  # the default mission charges at two pads
    on = ts[ts["charge_cmd_a"] > 0.0]
    # the same controller called every control period, from rest at command 0, answers a step to the mission's
    # command in n periods (the relaxation's own delay: tens of periods at b = 0.02, ~1 at b = 0)
    n = _control_periods_to_answer(BUDGET, cfg, float(on["charge_cmd_a"].max()), float(on["battery_v"].min()))
    assert n > 5
    dtc = cfg.sim.control_period_s
    for shorted_s, unmet_j in windows:
        assert shorted_s <= (n + 2) * dtc + 1e-9, windows      # before the fix: 14.2 s and 1.2 s
        # the charger's unmet energy is that delay's: VL I_L* over a few ms (before: ~2 kJ at the first pad)
        assert unmet_j <= (n + 2) * dtc * float(on["battery_v"].max() * on["charge_cmd_a"].max()) + 1e-9
        assert unmet_j < 1.0


def test_budgeted_mission_delivers_the_paper_controllers_energy(budget_run):
    """Before the stops the two controllers differ only by the relaxation's few-ms delay at each command rise,
    so the battery's gross charge and final SoC agree with ``model_based``'s within the energy of a few ms of
    charging plus a fraction of a joule per stop (the relaxation's after-stop energy); before the fix the budgeted
    mission charged 981 J more (later, from a lower SoC) and ended 0.003 lower in SoC."""
    cfg, res = budget_run
    ref = run_mission(cfg, make("model_based", policy_context(cfg))).summary
    s = res.summary
    assert abs(s["battery_charge_in_j"] - ref["battery_charge_in_j"]) < 5.0
    # 5 J of a 4680 C pack at ~30 V: ~4e-5 in SoC
    assert abs(s["final_soc"] - ref["final_soc"]) < 1e-4
    assert s["energy_balance_error_rel"] < 1e-9
