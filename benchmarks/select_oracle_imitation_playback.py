"""Select ``oracle_imitation``'s playback (``slow``) and teacher multiplier (``lam``) on validation windows,
against the MPC, by the rule written in docs/rl.md ("Re-selecting the playback on the modal link").

    python benchmarks/select_oracle_imitation_playback.py --slows 1.0,1.025,1.05,1.075,1.1,1.15,1.2 \
        --lams 0.4 --scenarios sense_delay,battery_low --seed 300 --episodes 100 --link modal --json out/x.json

For every ``lam`` the five bootstrap maps are refitted (``train_oracle_imitation.dataset`` and ``fit``: the
shipped command's teacher, nominal windows 0-79, budgets floor + 0.003 / 0.006 / 0.01 / 0.016, its oracle solves
from the disk cache or solved now), then written once per ``slow`` (only the ``slow`` array and ``meta["slow"]``
differ) under ``--work``; every map of every setting of one ``lam`` and the reference ``mpc`` run side by side on
the same windows (``policies.compare.run_policies``). Per setting and scenario: the mean over the maps of the paired
overshoot difference against the reference (points) and of the return difference, the pooled window
bootstrap of both, the fraction of windows in short mode (min over the maps); then the rule: admissible if
the overshoot difference is <= ``-margin`` on every scenario, chosen the largest least return difference over
the scenarios (within 0.1 of it: the larger least overshoot margin); ``--admit upper``: admissible if the pooled
bootstrap's upper bound of the overshoot difference is < ``-margin`` on every scenario instead. ``--base mpc``
(with ``--deltas`` and ``--windows``) refits maps whose base before the stop is the MPC (the teacher solved from its
state, as ``train_oracle_imitation.py --base mpc``); with ``--models`` the maps' meta's base, lam, budgets and
training windows are kept (every loaded map must share them; ``--base``, ``--deltas``, ``--windows`` given with
``--models`` must equal them) and each re-timed map's meta is its source's with ``slow``, ``command`` (naming the
source's), ``base`` and ``windows`` set. Validation windows only: ``--seed`` must keep the windows off the training
(``--windows`` or the maps' meta's, 0-79 by default) and evaluation (1000-1099, 2000-2099) seeds. Bad options: one
line naming the option, the value and what is valid, exit 2, before anything is fitted or written.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def fit_maps(lam, link, seeds=(0, 1, 2, 3, 4), windows=(0, 80), deltas=(0.003, 0.006, 0.01, 0.016), base="model_based"):
    """The five bootstrap maps of the shipped command at multiplier ``lam`` (unslowed) and the teacher's means
    (``base``: the controller before the stop, whose state at the stop the teacher is solved from)."""
    from train_oracle_imitation import dataset

    from envs.core import EnvConfig
    from policies.oracle_imitation import fit
    config = EnvConfig(link_model=link)
    X, Y, info = dataset(["nominal"], list(range(*windows)), list(deltas), lam, base, config)
    maps = [fit(X, Y, cols=(0, 1), seed=k) for k in seeds]
    return maps, {"teacher_overshoot_pct": 100 * float(info["overshoot"].mean()),
                  "teacher_energy_j": float(info["energy_j"].mean()), "dt_s": config.dt_s}


def write_map(model, path, lam, slow, seed, link, dt_s, base="model_based", windows=(0, 80), meta=None, deltas=None):
    """``model`` (unslowed) played ``slow`` times slower, written to ``path``; its meta: the source map's ``meta``
    (a loaded map's; None: a refitted map's, from ``lam``, ``seed``, ``link``, ``dt_s``, ``deltas``) with ``slow``,
    ``command`` (naming the source's), ``base`` and ``windows`` set."""
    from policies.oracle_imitation import save_model
    m = dict(model)
    m["slow"] = np.array(float(slow))
    out = dict(meta) if meta is not None else {"scenarios": ["nominal"], "lam": lam, "seed": seed,
                                                 "features": ["d_pre", "cmd_before_a"], "control_period_s": dt_s,
                                                 "link": link}
    if deltas is not None:
        out["deltas"] = list(deltas)
    command = f"select_oracle_imitation_playback.py candidate lam={out['lam']} slow={slow}"
    out.update(slow=slow, base=base, windows=list(windows),
               command=command + (f", re-timed from: {meta['command']}" if meta and meta.get("command") else ""))
    save_model(m, path, out)


def row_stats(ms, ref) -> dict:
    """One setting's row on one scenario: the metrics ``ms`` of its maps against the reference's ``ref`` (the same
    windows): the means over the maps of the paired overshoot (points) and return differences (``dov``, ``dret``), their
    pooled window bootstrap, per map, the means of overshoot, energy after the stop, return, the least fraction in
    short mode."""
    from policies.stats import mean_ci
    dov = [m["overshoot_pct"] - ref["overshoot_pct"] for m in ms]
    dret = [m["return"] - ref["return"] for m in ms]
    return {"dov": float(np.mean([d.mean() for d in dov])), "dret": float(np.mean([d.mean() for d in dret])),
            "dov_pooled": mean_ci(np.mean(dov, axis=0)), "dret_pooled": mean_ci(np.mean(dret, axis=0)),
            "dov_seeds": [float(d.mean()) for d in dov], "dret_seeds": [float(d.mean()) for d in dret],
            "overshoot_pct": float(np.mean([m["overshoot_pct"].mean() for m in ms])),
            "energy_after_stop_j": float(np.mean([m["energy_after_stop_j"].mean() for m in ms])),
            "return": float(np.mean([m["return"].mean() for m in ms])),
            "min_in_sm": min(float(np.mean(m["reached_short_mode"])) for m in ms)}


def validation_windows(ap, seed, episodes, train=(0, 80)):
    """``(first, last + 1)`` of the windows ``seed .. seed + episodes - 1``; ``ap.error`` (exit 2) when they touch the
    training windows ``train`` (``(LO, HI)``: LO .. HI - 1) or the evaluation (1000-1099, 2000-2099) windows."""
    lo, hi = seed, seed + episodes
    tlo, thi = train
    if lo < thi and hi > tlo or lo < 1100 and hi > 1000 or lo < 2100 and hi > 2000:
        ap.error(f"--seed {seed} --episodes {episodes}: windows {lo}-{hi - 1} overlap training ({tlo}-{thi - 1}) or "
                 "evaluation (1000-1099, 2000-2099) windows")
    return lo, hi


def loaded_meta(ap, pattern, link, given):
    """The maps of the glob ``pattern`` (sorted) and the meta they share: ``ap.error`` (exit 2) when there is none,
    one is fitted on another link than ``link``, or their base / lam / budgets / training windows differ, or a value
    in ``given`` (``{"base": .., "deltas": .., "windows": ..}``, None: not given on the command line) differs from
    theirs."""
    import glob

    from policies.oracle_imitation import load_model
    paths = sorted(glob.glob(pattern))
    if not paths:
        ap.error(f"--models {pattern!r}: no file matches")
    try:
        loaded = [load_model(p) for p in paths]
    except ValueError as exc:
        ap.error(f"--models {pattern!r}: {exc}")
    if any(m["meta"].get("link", "envelope") != link for m in loaded):
        ap.error(f"--models {pattern!r}: maps fitted on another link than --link {link}")
    keys = {"base": lambda m: m.get("base", "model_based"), "lam": lambda m: float(m["lam"]),
            "deltas": lambda m: [float(x) for x in m["deltas"]] if "deltas" in m else None,
            "windows": lambda m: tuple(m.get("windows", (0, 80)))}
    def text(k, v):   # as on the command line
        return ":".join(map(str, v)) if k == "windows" else ",".join(f"{x:g}" for x in v) if k == "deltas" and v else str(v)
    shared = {}
    for k, get in keys.items():
        vals = [get(m["meta"]) for m in loaded]
        if any(v != vals[0] for v in vals):
            ap.error(f"--models {pattern!r}: the maps' {k} differ "
                     f"({', '.join(f'{Path(p).name}: {text(k, v)}' for p, v in zip(paths, vals))}); valid: maps of one fit")
        shared[k] = vals[0]
    for k, v in given.items():
        if v is not None and shared[k] is not None and (tuple(v) if k == "windows" else v) != shared[k]:
            ap.error(f"--{k} {text(k, v)}: the maps of --models {pattern!r} have {k} {text(k, shared[k])}; "
                     "valid: theirs, or leave it out")
    return loaded, shared


def choose(table, margin, admit="mean"):
    """The rule (docs/rl.md): ``table[(lam, slow)][scenario] = {'dov': .., 'dret': ..}``; returns the chosen key
    (None if no setting is admissible) and the admissible keys. ``admit="mean"``: admissible if the mean overshoot
    difference is <= ``-margin`` on every scenario; ``"upper"``: if the upper bound of its pooled window bootstrap
    (``dov_pooled[2]``) is < ``-margin`` on every scenario (docs/rl.md, "The MPC before the stop on the exact-mode
    link")."""
    if admit not in ("mean", "upper"):
        raise ValueError(f"admit={admit!r} is invalid; valid values: mean, upper")
    ok = [k for k, row in table.items()
          if all((v["dov"] <= -margin) if admit == "mean" else (v["dov_pooled"][2] < -margin) for v in row.values())]
    if not ok:
        return None, ok
    worst_ret = {k: min(v["dret"] for v in table[k].values()) for k in ok}
    worst_margin = {k: min(-v["dov"] for v in table[k].values()) for k in ok}
    best = max(worst_ret.values())
    near = [k for k in ok if worst_ret[k] >= best - 0.1]
    return max(near, key=lambda k: worst_margin[k]), ok


def main(argv=None):
    from train_oracle_imitation import _conv, _in, _list, _windows

    from mission_sim.cli.common import OneLineParser
    ap = OneLineParser(prog="select_oracle_imitation_playback.py", description=__doc__.split("\n")[0])
    ap.add_argument("--slows", default=[1.0, 1.025, 1.05, 1.075, 1.1, 1.15, 1.2],
                    type=_conv("--slows", "comma-separated numbers in [1, 3]", _list(_in(1.0, 3.0))))
    ap.add_argument("--lams", default=[0.4], type=_conv("--lams", "comma-separated numbers > 0 (J per point)",
                                                        _list(_in(0.0, np.inf, True))))
    ap.add_argument("--scenarios", default="sense_delay,battery_low")
    ap.add_argument("--ref", default="mpc")
    ap.add_argument("--seed", type=int, default=300)
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--margin", type=float, default=0.10, help="overshoot margin below the reference, points")
    ap.add_argument("--admit", choices=("mean", "upper"), default="mean", help="admissible if the mean overshoot "
                    "difference is <= -margin (mean) or its pooled bootstrap upper bound < -margin (upper)")
    ap.add_argument("--base", choices=("model_based", "mpc"), default=None, help="controller before the stop of the "
                    "refitted maps (default model_based; with --models: the maps' meta's, which a given --base must equal)")
    ap.add_argument("--deltas", default=None, help="the teacher's budgets above the floor (default "
                    "0.003,0.006,0.01,0.016; with --models: the maps' meta's)",
                    type=_conv("--deltas", "comma-separated numbers in (0, 0.2]", _list(_in(0.0, 0.2, True))))
    ap.add_argument("--windows", default=None, help="the teacher's nominal training windows LO:HI (default 0:80; with "
                    "--models: the maps' meta's)", type=_conv("--windows", "LO:HI, 0 <= LO < HI, disjoint from 1000-1099",
                                                              _windows))
    ap.add_argument("--link", choices=("envelope", "modal"), default="modal")
    ap.add_argument("--models", default=None, help="glob of fitted maps to re-time instead of refitting (their meta's "
                    "lam; --lams ignored), e.g. the shipped policies/pretrained/oracle_imitation_s*.npz")
    ap.add_argument("--work", default="out/oislow/grid")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    slows, lams, scenarios = a.slows, a.lams, a.scenarios.split(",")
    metas = None
    if a.models:
        loaded, shared = loaded_meta(ap, a.models, a.link, {"base": a.base, "deltas": a.deltas, "windows": a.windows})
        lams, base, deltas, windows = [shared["lam"]], shared["base"], shared["deltas"], shared["windows"]
        metas = [m["meta"] for m in loaded]
    else:
        base, deltas, windows = a.base or "model_based", a.deltas or [0.003, 0.006, 0.01, 0.016], a.windows or (0, 80)
    lo, hi = validation_windows(ap, a.seed, a.episodes, windows)
    from envs import EnvConfig
    from policies.compare import run_policies
    config = EnvConfig(link_model=a.link)
    t0, c0, l0 = time.time(), time.process_time(), os.getloadavg()
    Path(a.work).mkdir(parents=True, exist_ok=True)
    names, teacher = {}, {}
    if a.models:
        fitted = {lams[0]: ([{k: v for k, v in m.items() if k not in ("meta", "slow")} for m in loaded],
                            {"teacher_overshoot_pct": loaded[0]["meta"].get("teacher_overshoot_pct"),
                             "teacher_energy_j": loaded[0]["meta"].get("teacher_energy_j"),
                             "dt_s": float(loaded[0]["meta"]["control_period_s"])})}
    for lam in lams:
        maps, teacher[lam] = fitted[lam] if a.models else fit_maps(lam, a.link, windows=windows, deltas=deltas, base=base)
        for slow in slows:
            names[(lam, slow)] = []
            for k, m in enumerate(maps):
                p = f"{a.work}/lam{lam:g}_slow{slow:g}_s{k}.npz"
                write_map(m, p, lam, slow, k, a.link, teacher[lam]["dt_s"], base, windows,
                          meta=metas[k] if metas else None, deltas=None if metas else deltas)
                names[(lam, slow)].append(f"oracle_imitation:{p}")
    table = {k: {} for k in names}
    for s in scenarios:
        runs = {}
        for lam in lams:   # one batched run per lam (the reference in each: the same windows, the same numbers)
            runs.update(run_policies([a.ref] + [n for k, v in names.items() if k[0] == lam for n in v], s, a.episodes,
                                     a.seed, config))
        ref = runs[a.ref].metrics
        for key, ns in names.items():
            table[key][s] = row_stats([runs[n].metrics for n in ns], ref)
        print(f"\n== {s}, windows {lo}-{hi - 1}, {a.link} link; {a.ref}: overshoot {ref['overshoot_pct'].mean():.2f} %, "
              f"E after {ref['energy_after_stop_j'].mean():.3f} J, return {ref['return'].mean():.1f}")
        print("  lam   slow   overshoot %  E after J  return  | d return (pooled 95 %)        | d overshoot pts (pooled 95 %)  | SM")
        for (lam, slow), row in table.items():
            v = row[s]
            print(f"  {lam:<5g} {slow:<6g} {v['overshoot_pct']:6.2f}      {v['energy_after_stop_j']:.3f}    {v['return']:5.1f}  | "
                  f"{v['dret']:+5.2f} [{v['dret_pooled'][1]:+5.2f}, {v['dret_pooled'][2]:+5.2f}]          | "
                  f"{v['dov']:+5.2f} [{v['dov_pooled'][1]:+5.2f}, {v['dov_pooled'][2]:+5.2f}]           | {v['min_in_sm']:.2f}")
    chosen, ok = choose(table, a.margin, a.admit)
    print(f"\nadmissible (overshoot {'mean <=' if a.admit == 'mean' else 'pooled upper bound <'} -{a.margin} pts on "
          f"{', '.join(scenarios)}): {ok}")
    print(f"chosen: {chosen}")
    info = {"seed": a.seed, "episodes": a.episodes, "link": a.link, "ref": a.ref, "margin": a.margin, "admit": a.admit,
            "base": base, "deltas": deltas, "windows": list(windows),
            "teacher": {str(k): v for k, v in teacher.items()}, "wall_s": time.time() - t0,
            "cpu_s": time.process_time() - c0, "load_before": l0, "load_after": os.getloadavg()}
    print(info)
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"info": info, "chosen": chosen, "admissible": ok,
                       "table": {f"lam={k[0]:g},slow={k[1]:g}": v for k, v in table.items()}}, f, indent=1)


if __name__ == "__main__":
    main()
