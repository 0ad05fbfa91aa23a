"""The adaptive refinement of the exact-mode env step (``EnvConfig.v2_refine_tol`` / ``v2_refine_levels``,
``envs.modal_step._refine``): cost against today's kernel (the step without refinement as it was before, loaded
from a git revision) and eq. 4, and the windows' agreement (issue 23; docs/performance.md, "Adaptive refinement
of the modal env step").

* ``cost``: in-kernel thread CPU per env-step (one thread, ``n_chunks = 1``), eq. 4, today's kernel (``--old``:
  a checkout of the worktree before the change; its ``envs/modal_step.py`` is loaded as ``envs._old_modal_step``
  and stepped on the same plant), refinement off (levels 0) and the variants, all stepped alternately in one
  process on the same actions (held duty, random), median over the timed steps.
* ``env``: ``benchmarks/modal_substeps_study.py``'s window study (policy on the reference env, duties replayed
  open loop on each variant) with the reference = today's arithmetic (levels 0) and the refined variants.

    python benchmarks/modal_refine_study.py cost [--old /tmp/modal_old] [--n 1024] [--steps 40]
    python benchmarks/modal_refine_study.py env [--windows 100] [--ref off|"L5 tol 0.02"]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from envs import EnvConfig, SbarChargingVectorEnv  # noqa: E402

#: label -> EnvConfig kwargs of the modal variants (``off``: today's arithmetic, no refinement)
VARIANTS = {"off": dict(v2_refine_levels=0), "default": {}, "L2 tol 0.05": dict(v2_refine_levels=2, v2_refine_tol=0.05),
            "L3 tol 0.1": dict(v2_refine_levels=3, v2_refine_tol=0.1), "L5 tol 0.02": dict(v2_refine_levels=5, v2_refine_tol=0.02)}


def _old_kernel(old_root):
    """``env_step`` of ``old_root/envs/modal_step.py`` (today's kernel), imported inside the ``envs`` package."""
    spec = importlib.util.spec_from_file_location("envs._old_modal_step", Path(old_root) / "envs" / "modal_step.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod.env_step


def cost(n=1024, steps=40, warm=20, seed=0, old=None, actions_list=("held", "random")) -> dict:
    import modal_substeps_study as ms
    res = {}
    for actions in actions_list:
        cfgs = {"eq4": EnvConfig(link_model="envelope"), **{lab: EnvConfig(link_model="modal", **kw) for lab, kw in VARIANTS.items()}}
        if old:
            cfgs["today"] = EnvConfig(link_model="modal")
        envs, times = {}, {}
        for lab, cfg in cfgs.items():
            envs[lab] = SbarChargingVectorEnv(num_envs=n, scenario="random", config=cfg, num_threads=1)
            envs[lab].reset(seed=seed)
            if lab == "today":
                envs[lab].parts.plant.kernel = _old_kernel(old)
            times[lab] = []
        rng = np.random.default_rng(seed)
        load0 = os.getloadavg()
        for k in range(warm + steps):
            a = (rng.uniform(-1, 1, (n, 1)) if actions == "random" else np.zeros((n, 1))).astype(np.float32)
            for lab, env in envs.items():   # alternating, the same actions
                if k == warm:
                    ms._timed(env, times[lab])
                env.step(a)
        load1 = os.getloadavg()
        base = "today" if old else "off"
        med = {lab: float(np.median(t)) / n for lab, t in times.items()}
        row = {lab: dict(ns=round(med[lab]), vs_today=round(med[lab] / med[base], 3),
                         vs_eq4=round(med[lab] / med["eq4"], 2)) for lab in med}
        row["load_avg"] = [round(x, 2) for x in (*load0, *load1)]
        res[f"N={n}/{actions}"] = row
        print(n, actions, json.dumps(row), flush=True)
        for env in envs.values():
            env.close()
    return res


def env(windows=100, ref="off") -> dict:
    """The windows against ``ref`` (``off``: today's arithmetic; ``L5 tol 0.02``: the finest setting, so the
    rows say how far each setting is from converged)."""
    import modal_substeps_study as ms
    var = {"ref": VARIANTS[ref], **{k: v for k, v in VARIANTS.items() if k != ref}}
    return ms.env_study(var, windows, 1000)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("parts", nargs="+", choices=("cost", "env"))
    ap.add_argument("--old", default=None, help="a checkout of the worktree before the change (today's kernel)")
    ap.add_argument("--n", type=int, default=1024)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--windows", type=int, default=100)
    ap.add_argument("--ref", default="off", choices=tuple(VARIANTS), help="env: the windows' reference setting")
    ap.add_argument("--actions", nargs="+", default=["held", "random"], choices=("held", "random"))
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    out = {"started_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())}
    if "cost" in a.parts:
        out["cost"] = cost(a.n, a.steps, old=a.old, actions_list=a.actions)
    if "env" in a.parts:
        out["env"] = env(a.windows, a.ref)
    if a.json:
        tmp = a.json + ".tmp"
        Path(tmp).write_text(json.dumps(out, indent=1, default=float))
        os.replace(tmp, a.json)


if __name__ == "__main__":
    main()
