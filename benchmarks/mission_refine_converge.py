"""The mission's fine step (``mission_sim.world.loop_kernel._fine_step``) on the env's large transients and the
paper's trajectories (and the step policy's charge start, SM -> RM), refinement off / default / finer, against the switching model and the fine step's limit
(uniform sub-steps of T/256, 4,352 V2 updates per 100 us, no refinement): the largest instantaneous peak after the
transient, per-step rms against the limit, and the charge (mean I_L) against the unrefined step.

    python benchmarks/mission_refine_converge.py OUT_JSON
"""
from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import modal_substeps_study as s  # noqa: E402

_spec = importlib.util.spec_from_file_location("_tmm", ROOT / "tests" / "test_mission_modal.py")
tmm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tmm)

T = s.P.rectifier_period_s
SETTINGS = {"off (before)": (1, 0.05, 0), "default L3 tol 0.05": (1, 0.05, 3), "L5 tol 0.02": (1, 0.02, 5),
            "uniform 136": (8, 0.05, 0)}


def run(d, div, tol, levels, rest=False):
    """Per-step instantaneous peaks of the fine step with ``t_rect / div`` sub-steps."""
    old = (tmm.T, tmm.mk.REFINE_TOL)
    tmm.T, tmm.mk.REFINE_TOL = T / div, tol
    try:
        return tmm._kernel_run(d, 17 * T, levels=levels, per_step=True, rest=rest)
    finally:
        tmm.T, tmm.mk.REFINE_TOL = old


def main(out):
    res = {}
    cases = s.transient_cases()
    # the step policy's charge start in the default mission: short mode, then d = 0.27 (RM) held
    cases["rise SM->RM 0.27"] = (np.r_[np.ones(40), np.full(150, 0.27)], 40)
    cases["from rest at 0.27"] = (np.full(150, 0.27), 0)   # the pad on at full V1, the coils at rest (as the switching model)
    for name, (d, p0) in cases.items():
        sw = s.switching_peaks(d)[p0:]
        rest = name.startswith("from rest")
        lim = run(d, 256, 0.05, 0, rest)[p0:]
        base = run(d, 1, 0.05, 0, rest)[p0:]
        row = {"switching_a": float(sw.max()), "limit_a": float(lim.max()),
               "limit_vs_switching_pct": 100 * (lim.max() / sw.max() - 1)}
        for lab, (div, tol, lev) in SETTINGS.items():
            pk = run(d, div, tol, lev, rest)[p0:]
            e = pk / lim - 1
            row[lab] = dict(peak_a=float(pk.max()), vs_switching_pct=100 * (pk.max() / sw.max() - 1),
                            vs_limit_pct=100 * (pk.max() / lim.max() - 1),
                            step_rms_vs_limit_pct=100 * float(np.sqrt((e ** 2).mean())),
                            identical_to_before=bool(np.array_equal(pk, base)))
        res[name] = row
        print(name, json.dumps(row), flush=True)
    Path(out).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(sys.argv[1])
