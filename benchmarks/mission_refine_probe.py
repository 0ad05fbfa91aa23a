"""Does the env's refinement criterion (issue 23) trigger in a mission?

Runs ``dronewpt mission`` (the embedded default unless more arguments are given) on an INSTRUMENTED COPY of
``mission_sim/world/loop_kernel.py`` (written to a temporary folder and compiled there; the shipped kernel and
its numba cache are untouched): the fine step's rows are not merged (one row per rectifier-period sub-step), and
each row's ``v2_v`` column holds ``|I2 end - I2 start| / max(|I2 start|, |I2 end|)`` of the step instead of v2
(I2 start: the state's phasor with the V2 held over the previous step, as ``_substeps`` starts from). Prints, per
policy, how many fine sub-steps (d < 1, pad on) exceed the env's ``v2_refine_tol`` (0.05) and the level
``envs.modal_step._level`` (now ``wpt_receiver.modal_kernel.refine_level``) would pick (at most 3), and where (time,
phase: the duty and the command around). The counts in docs/performance.md ("Adaptive refinement of the mission's
fine step") are of the kernel before the mission's refinement (branch modalconv); on a kernel that refines, the rows
are the pieces (the unrefined try's row is dropped), so the counts are of what is left above the tolerance.

    python benchmarks/mission_refine_probe.py OUT_JSON [POLICY ...]
"""
from __future__ import annotations

import importlib.util
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
TOL, LEVELS = 0.05, 3
_PATCHES = (
    ("from .. import contract as _contract\nfrom ..contract import OBS_DIM",
     "from mission_sim import contract as _contract\nfrom mission_sim.contract import OBS_DIM"),
    ("    if st.n_rows - n0 <= 1:\n        return\n    out, last", "    if True:\n        return\n    out, last"),
    ("    i1n, i2n = phasors(mc, z, v1c, v2)\n",
     "    i1n, i2n = phasors(mc, z, v1c, v2)\n"
     "    i2s_probe = phasors(mc, st.z, v1c, complex(st.v2re, st.v2im))[1]\n"
     "    den_probe = max(abs(i2s_probe), abs(i2n))\n"
     "    ratio_probe = abs(i2n - i2s_probe) / den_probe if den_probe > 0.0 else 0.0\n"),
    ("    v2_row = (v2 * i2n.conjugate()).real / a2 if a2 > 0.0 else v2.real   # v2's fundamental in phase with i2\n",
     "    v2_row = ratio_probe\n"),
)


def probe_module():
    """The instrumented copy of the loop kernel, imported in place of :mod:`mission_sim.world.loop_kernel`."""
    src = (ROOT / "mission_sim/world/loop_kernel.py").read_text()
    for old, new in _PATCHES:
        assert src.count(old) == 1, old
        src = src.replace(old, new)
    d = Path(tempfile.mkdtemp(prefix="mission_refine_probe_"))
    f = d / "loop_kernel_probe.py"
    f.write_text(src)
    import mission_sim.world as world
    spec = importlib.util.spec_from_file_location("mission_sim.world.loop_kernel", f)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["mission_sim.world.loop_kernel"] = mod
    spec.loader.exec_module(mod)
    world.loop_kernel = mod
    return mod


def level(r):
    """``wpt_receiver.modal_kernel.refine_level`` of a sub-step whose relative change is ``r``."""
    lev = 0
    while r > TOL and lev < LEVELS:
        lev, r = lev + 1, r / 2
    return lev


def analyse(df, t_rect):
    sub = df[(df["fine"] > 0) & (df["d_short"] < 1.0) & (df["v1_v"] > 0.0)]
    split = sub[sub["dt_s"] < 1.5 * t_rect]
    r = split["v2_v"].to_numpy()
    lev = np.array([level(x) for x in r])
    hits = split[r > TOL]
    events = []
    if len(hits):
        t = hits["t_s"].to_numpy()
        starts = np.r_[0, np.nonzero(np.diff(t) > 0.01)[0] + 1]
        for a, b in zip(starts, np.r_[starts[1:], len(t)]):
            h = hits.iloc[a:b]
            events.append(dict(t0_s=float(t[a]), t1_s=float(t[b - 1]), n=int(b - a), max_ratio=float(h["v2_v"].max()),
                               d_range=[float(h["d_short"].min()), float(h["d_short"].max())],
                               cmd_a=float(h["charge_cmd_a"].iloc[0]), v1_v=float(h["v1_v"].iloc[0]),
                               i2_range_a=[float(h["i2_amp_a"].abs().min()), float(h["i2_amp_a"].abs().max())]))
    return dict(sub_steps=int(len(split)), unsplit_fine_rectifying=int(len(sub) - len(split)),
                above_tol=int((r > TOL).sum()), levels={str(L): int((lev == L).sum()) for L in range(LEVELS + 1)},
                max_ratio=float(r.max()) if len(r) else 0.0, p99_ratio=float(np.quantile(r, 0.99)) if len(r) else 0.0,
                extra_piece_solves=int(sum((1 << L) for L in lev if L > 0)), events=events)


def main(out, policies):
    probe_module()
    from mission_sim.cli import main as cli
    from wpt_receiver.params import TABLE_I
    res = {}
    for p in policies:
        d = Path(tempfile.mkdtemp(prefix="probe_out_"))
        rc = cli(["mission", "--policy", p, "--out", str(d), "--no-plot", "--no-progress", "--every", "0",
                  "--format", "json"])
        df = pd.read_parquet(next(d.glob("*.parquet")))
        res[p] = dict(rc=rc, **analyse(df, TABLE_I.rectifier_period_s))
        print(p, json.dumps({k: v for k, v in res[p].items() if k != "events"}), flush=True)
        for e in res[p]["events"]:
            print("   ", json.dumps(e), flush=True)
    Path(out).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:] or ["model_based", "step", "ramp", "model_based_budget:0.02"])
