"""Retrain the shipped RL policies (``rl_s<k>``: unconstrained PPO; ``residual_s<k>``, ``ppo_lagrangian_s<k>``:
constrained) on the current env, one ``dronewpt train`` per seed, one after the other, and optionally install
them in ``policies/pretrained``.

    python benchmarks/retrain_shipped.py --kind rl --seeds 0-4 --timesteps 800000 --install
    python benchmarks/retrain_shipped.py --kind residual --seeds 0-4 --timesteps 400000 --budget 0.05 --install
    python benchmarks/retrain_shipped.py --kind ppo_lagrangian --seeds 0-4 --timesteps 400000 --budget 0.05 --install
    python benchmarks/retrain_shipped.py --kind rl_bc --seeds 0-4 --timesteps 800000 --install   # installs as rl_s<k>
    python benchmarks/retrain_shipped.py --kind slow_budget --seeds 0-4 --timesteps 307200 --budget 0.1 --install
    python benchmarks/retrain_shipped.py --kind imitation --seeds 0-4 --timesteps 0 --install   # a clone: no PPO steps

Each seed runs exactly the command of ``KINDS[kind]`` (``{seed}``, ``{timesteps}``, ``{budget}`` filled in;
``--budget`` is required for the constrained kinds and refused for ``rl``)
under ``nice -n 10`` into ``out/retrain/<kind>_s<k>/``; the output's own metadata holds the env config
(devices, reward), budget, multiplier history and the ``reproduce`` command. ``--install`` copies the final
model (no selection) to ``policies/pretrained/<kind>_s<k>.zip`` (``rl_bc``: PPO from a behaviour clone of
``model_based_budget:0.05``, installed as ``rl_s<k>``; its clone stays in ``out/retrain/rl_bc_s<k>/clone.zip``) and its metadata to ``.json`` (each written
under a temporary name and renamed) with a ``trained`` record added: the git commit the training ran on
(the env's version), the date, the wall and CPU time and the 1-min load average before / after (the machine is
shared). Bad options: one line on stderr, exit 2, nothing trained.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _cpu import children_cpu  # noqa: E402

#: the training command of each shipped kind (docs/rl.md, "Shipped learned policies")
KINDS = {
    "rl": ("dronewpt train --algo ppo --timesteps {timesteps} --seed {seed} --scenario random "
           "--hyperparams policies/hyperparams/ppo.yml"),
    "residual": ("dronewpt train --algo ppo --timesteps {timesteps} --seed {seed} --scenario random --lagrangian "
                 "--budget {budget} --lambda-lr 50 --residual --residual-scale 0.1 --residual-base-budget 0.01 "
                 "--hyperparams policies/hyperparams/residual.yml"),
    "ppo_lagrangian": ("dronewpt train --algo ppo --timesteps {timesteps} --seed {seed} --scenario random --lagrangian "
                       "--budget {budget} --lambda-lr 20 --hyperparams policies/hyperparams/ppo_lagrangian.yml"),
    # plain PPO started from a feed-forward behaviour clone of model_based_budget:0.05 (the current fields
    # hidden from the student); --timesteps counts the PPO steps after the clone (docs/rl.md, issue 21)
    "rl_bc": ("dronewpt train --algo ppo --timesteps {timesteps} --seed {seed} --scenario random "
              "--hyperparams policies/hyperparams/ppo.yml --imitate model_based_budget:0.05 "
              "--imitation-mask last_d_short,i2_amp_a,battery_current_a,rect_current_a "
              "--eval-every 100000 --checkpoint-every 100000"),
    # the MPC's measured-overshoot budget per window as the action (docs/rl.md, "A learned slow variable")
    "slow_budget": ("dronewpt train --algo ppo --timesteps {timesteps} --seed {seed} --scenario nominal --lagrangian "
                    "--budget {budget} --lambda-lr 50 --slow-budget 0:0.15 --slow-budget-every window "
                    "--hyperparams policies/hyperparams/slow_budget.yml --eval-every 153600 --checkpoint-every 307200"),
    # feed-forward residual clone of model_based_budget:0.02 on model_based_budget:0.01 (BC only: --timesteps 0)
    "imitation": ("dronewpt train --algo ppo --timesteps {timesteps} --seed {seed} --scenario nominal "
                  "--residual --residual-scale 0.1 --residual-base-budget 0.01 --imitate model_based_budget:0.02 "
                  "--dagger 0 --imitation-episodes 32 --imitation-epochs 60 "
                  "--imitation-mask last_d_short,i2_amp_a,battery_current_a,rect_current_a"),
}

#: kinds whose shipped models had no PPO steps (``--timesteps 0`` is their only valid count)
CLONE_ONLY = {"imitation"}

#: the shipped name a kind installs as (``policies/pretrained/<name>_s<k>``), when not the kind's own
INSTALL_AS = {"rl_bc": "rl"}


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    seeds = list(range(int(lo), int(hi or lo) + 1))
    if not seeds or seeds[0] < 0:
        raise ValueError
    return seeds


def constrained(kind: str) -> bool:
    """Whether the kind's command takes a ``--budget`` (Lagrangian)."""
    return "{budget}" in KINDS[kind]


def _commit() -> str:
    out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    return out.stdout.strip() or "unknown"


def _load() -> float:
    return float(Path("/proc/loadavg").read_text().split()[0]) if Path("/proc/loadavg").is_file() else float("nan")



def train_seed(kind: str, seed: int, timesteps: int, budget, out_root: Path, link: str = "envelope") -> dict:
    """Run one seed's command (niced) into ``out_root/<kind>_s<seed>``; returns the run's record. A folder of an
    earlier run there is moved aside first (``<kind>_s<seed>.prev-<UTC time>``, said on stderr): ``dronewpt train``
    refuses an --out holding an earlier run, and the script's rerun failed with the reason only in the seed's log."""
    out = out_root / f"{kind}_s{seed}"
    if out.exists():
        from mission_sim.files import move_aside
        moved = move_aside(out)
        print(f"retrain_shipped: moved the earlier run's {out} aside to {moved.name}", file=sys.stderr, flush=True)
    rel = out.relative_to(ROOT) if out.is_relative_to(ROOT) else out
    budget_text = "" if budget is None else f"{budget:g}"   # rl: no {budget} in its command
    cmd = KINDS[kind].format(timesteps=timesteps, seed=seed, budget=budget_text) + f" --link {link} --out {rel}"
    rec = {"commit": _commit(), "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "command": cmd,
           "load_avg_1min_before": _load()}
    t0, c0 = time.time(), children_cpu()
    with open(out_root / f"{kind}_s{seed}.log", "w") as log:
        rc = subprocess.run(["nice", "-n", "10", *cmd.split()], cwd=ROOT, stdout=log, stderr=subprocess.STDOUT).returncode
    rec.update(wall_s=round(time.time() - t0, 1), cpu_s=round(children_cpu() - c0, 1), load_avg_1min_after=_load(),
               returncode=rc)
    return rec


def install(kind: str, seed: int, out_root: Path, rec: dict) -> None:
    """Final model and metadata (plus ``trained``) into policies/pretrained, each under a temp name, renamed."""
    from mission_sim.files import atomic_output
    src = out_root / f"{kind}_s{seed}"
    from policies.shipped import SHIPPED   # (the shipped names' one table)
    dst = ROOT / "policies" / "pretrained" / f"{SHIPPED[INSTALL_AS.get(kind, kind)][0]}{seed}"
    meta = json.loads((src / "ppo_sbar.json").read_text())
    meta["trained"] = rec
    with atomic_output(dst.with_suffix(".zip")) as tmp:
        shutil.copyfile(src / "ppo_sbar.zip", tmp)
    with atomic_output(dst.with_suffix(".json")) as tmp:
        Path(tmp).write_text(json.dumps(meta, indent=2) + "\n")


def install_from(kind: str, seeds: list, out_root: Path, records: Path) -> int:
    """Install seeds already trained (evaluated first, then installed): each needs its record in ``records``
    with returncode 0 and its output folder; all are checked before any is installed."""
    recs = {}
    for line in records.read_text().splitlines() if records.is_file() else []:
        if line.startswith("{"):
            r = json.loads(line)
            if r.get("kind") == kind and r.get("returncode") == 0:
                recs[r["seed"]] = {k: v for k, v in r.items() if k not in ("kind", "seed")}
    missing = [s for s in seeds if s not in recs or not (out_root / f"{kind}_s{s}" / "ppo_sbar.zip").is_file()]
    if missing:
        print(f"retrain_shipped: --install-from {records}: seeds {missing} of --kind {kind} have no finished run; "
              f"valid: seeds with a returncode-0 record and out/{kind}_s<k>/ppo_sbar.zip", file=sys.stderr)
        return 2
    for s in seeds:
        install(kind, s, out_root, recs[s])
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kind", required=True, choices=sorted(KINDS))
    ap.add_argument("--seeds", default="0-4", help="LO-HI (default 0-4)")
    ap.add_argument("--timesteps", type=int, required=True)
    ap.add_argument("--budget", type=float, default=None,
                    help="measured-overshoot budget (fraction); required for the Lagrangian kinds (residual, ppo_lagrangian, slow_budget), not for rl, rl_bc, imitation")
    ap.add_argument("--out", default="out/retrain")
    ap.add_argument("--install", action="store_true", help="copy the final models into policies/pretrained")
    ap.add_argument("--install-from", default=None, metavar="RECORDS",
                    help="train nothing: install the finished runs of --kind / --seeds whose records (this script's "
                         "stdout, one JSON line per seed) are in RECORDS, from --out")
    ap.add_argument("--link", choices=("envelope", "modal"), default="envelope",
                    help="the env's link (default envelope: what the shipped models were trained on)")
    a = ap.parse_args(argv)
    try:
        seeds = _seeds(a.seeds)
    except ValueError:
        print(f"retrain_shipped: --seeds {a.seeds!r} is invalid; valid: LO-HI with 0 <= LO <= HI", file=sys.stderr)
        return 2
    if constrained(a.kind) != (a.budget is not None):
        print(f"retrain_shipped: --budget {'is required' if a.budget is None else 'is not valid'} with --kind {a.kind}; "
              f"valid: --budget only with {', '.join(k for k in sorted(KINDS) if constrained(k))}", file=sys.stderr)
        return 2
    steps_ok = a.timesteps == 0 if a.kind in CLONE_ONLY else a.timesteps > 0
    if not steps_ok or (a.budget is not None and not (0.0 < a.budget < 10.0)):
        shown = f"--timesteps {a.timesteps}" + ("" if a.budget is None else f" / --budget {a.budget}")
        valid = "timesteps 0 (a clone)" if a.kind in CLONE_ONLY else "timesteps > 0"
        print(f"retrain_shipped: {shown} is invalid with --kind {a.kind}; valid: {valid}, budget in (0, 10)",
              file=sys.stderr)
        return 2
    out_root = ROOT / a.out
    if a.install_from is not None:
        return install_from(a.kind, seeds, out_root, Path(a.install_from))
    out_root.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        rec = train_seed(a.kind, seed, a.timesteps, a.budget, out_root, a.link)
        print(json.dumps({"kind": a.kind, "seed": seed, **rec}), flush=True)
        if rec["returncode"] != 0:
            return 1
        if a.install:
            install(a.kind, seed, out_root, rec)
    return 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONPATH", str(ROOT))
    sys.exit(main())
