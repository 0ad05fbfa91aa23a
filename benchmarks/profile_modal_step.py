"""Where the exact-mode env step's time goes (``EnvConfig(link_model="modal")``, :mod:`envs.modal_step`).

The vector env (one thread, ``--n`` windows, scenario ``--scenario``) runs ``--warm`` steps with a held duty or
random actions (autoresets included); then ``--snaps`` consecutive steps' kernel inputs are captured and
each is replayed on copies (in-process, warm, process CPU time per env-step, least of ``--reps`` per snapshot):

* ``full``: :func:`envs.modal_step.step_kernel` (link + battery/reward/objective/obs/info);
* ``link``: the link part alone (:func:`_segment` where a window enters a slow segment, ``_link_of``), with the
  env's ``hold_tol`` and forced to hold (``hold_tol = inf``) or to split (``hold_tol = 0``) every window;
* ``finish`` = full - link (the part shared with eq. 4's step: :mod:`envs.vector_kernel`'s helpers);
* ``segment``: :func:`_segment` rebuilt for every window (modes + three ZOHs + two affine maps).

Counts (same snapshots): windows off the ``hold_tol`` criterion (sub-stepped), windows entering a slow
segment, and per sub-step (uncompiled replay of a sample of windows) the closed form's fallbacks
(:func:`_v2_edges`, ``sbar_implicit``) and the harmonics' shift re-lookups.

    python benchmarks/profile_modal_step.py [--n 1024] [--actions held|random] [--scenario random]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from envs import EnvConfig, SbarChargingVectorEnv  # noqa: E402
from envs import modal_step as ms  # noqa: E402
from envs.layout import MPAR  # noqa: E402


@njit(cache=True)
def _link_part(d, state, mstate, k, j, lc_all, cz_all, lm_all, slow_every, n_sub, par, tab, split_out):
    """The link half of ``envs.modal_step._chunk`` (no battery / info): returns the windows that entered a
    slow segment; ``split_out[e]`` the step's sub-stepped flag."""
    out, en, zb = np.empty(9), np.zeros(4), np.empty(4)
    dt = par[MPAR.dt]
    n_seg = 0
    for e in range(d.shape[0]):
        kk = k[e]
        jj = kk // slow_every
        if jj != j[e] or kk == 0:
            ms._segment(lc_all[e], lm_all[jj, e], dt, n_sub, int(par[MPAR.n_q]), cz_all[e], kk == 0)
            j[e] = jj
            n_seg += 1
        zb[0], zb[1], zb[2], zb[3] = mstate[0, e], mstate[1, e], mstate[2, e], mstate[3, e]
        r = ms._link_step(zb, complex(mstate[4, e], mstate[5, e]), mstate[6, e], state[2, e], d[e], lc_all[e], tab,
                          cz_all[e], dt, n_sub, int(par[MPAR.n_q]), par[MPAR.vf], par[MPAR.dr], par[MPAR.v1],
                          par[MPAR.hold_tol], out, en)
        split_out[e] = r[8]
        mstate[0, e], mstate[1, e], mstate[2, e], mstate[3, e] = zb[0], zb[1], zb[2], zb[3]
    return n_seg


@njit(cache=True)
def _segments(lc_all, cz_all, lm_all, dt, n_sub, n_q):
    for e in range(cz_all.shape[0]):
        ms._segment(lc_all[e], lm_all[0, e], dt, n_sub, n_q, cz_all[e], True)


def _capture(env, n_snaps):
    """The kernel arguments of the next ``n_snaps`` steps (copies taken before each call)."""
    plant = env.parts.plant
    snaps, orig = [], plant.step

    def grab(d, k, scenario, objective, par, ptab, obs, reward, truncated, block, chunks):
        snaps.append(dict(d=d.copy(), state=plant.state.copy(), mstate=plant.mstate.copy(), k=k.copy(),
                          j=plant.j.copy(), lc=plant.lc.copy(), cz=plant.coef_cur.copy(), bat=plant.bat.copy(),
                          cmd=scenario.cmd.copy(), noise=scenario.noise.copy(), lm=plant.lm_all.copy(),
                          ep=tuple(a.copy() for a in objective.ep), par=par.copy(), tab=plant.tab,
                          slow_every=plant.cfg.slow_every, n_sub=plant.n_sub))
        orig(d, k, scenario, objective, par, ptab, obs, reward, truncated, block, chunks)
    return snaps, grab, orig


def _copy(s):
    return {key: (v.copy() if isinstance(v, np.ndarray) and key != "tab" else
                  tuple(a.copy() for a in v) if key == "ep" else v) for key, v in s.items()}


def _full(s):
    from envs.core import OBS_OFFSET, OBS_SCALE
    n = len(s["d"])
    from envs.layout import INFO
    obs, reward = np.empty((n, 8), np.float32), np.empty(n)
    trunc, info = np.empty(n, bool), np.empty((n, len(INFO)))
    ms.step_kernel(s["d"], s["state"], s["mstate"], s["k"], s["j"], s["lc"], s["cz"], s["bat"], s["cmd"], s["noise"],
                   s["lm"], s["ep"], s["slow_every"], s["n_sub"], s["par"], OBS_SCALE, OBS_OFFSET, s["tab"], obs,
                   reward, trunc, info)


def _link(s, hold=None):
    par = s["par"].copy()
    if hold is not None:
        par[MPAR.hold_tol] = hold
    split = np.zeros(len(s["d"]), np.bool_)
    n_seg = _link_part(s["d"], s["state"], s["mstate"], s["k"], s["j"], s["lc"], s["cz"], s["lm"], s["slow_every"],
                       s["n_sub"], par, s["tab"], split)
    return n_seg, int(split.sum())


def _time(snaps, fn, reps):
    """CPU time of ``fn`` on fresh copies of every snapshot [ns per env-step]: per snapshot the least of
    ``reps`` runs (process CPU time: a descheduled process is not charged), summed."""
    tot = 0.0
    for s in snaps:
        best = np.inf
        for _ in range(reps):
            c = _copy(s)
            t0 = time.process_time()
            fn(c)
            best = min(best, time.process_time() - t0)
        tot += best
    return 1e9 * tot / (len(snaps) * len(snaps[0]["d"]))


def _fallbacks(snaps, n_win=200):
    """Counts of the closed form's fallbacks and the shift re-lookups per sub-step, on the first ``n_win``
    windows of every snapshot, uncompiled (module globals wrapped with counters)."""
    cnt = {"v2_closed": 0, "v2_edges": 0, "sbar_implicit": 0, "sbar_shift": 0}
    counted = ("_v2_closed", "_v2_edges", "sbar_implicit", "sbar_shift")
    plain = ("_link_step", "_link_pre", "_link_rest", "_substeps", "_refine", "_solve", "_reshift", "_sub_v2",
             "_sub_track")
    saved = {name: getattr(ms, name) for name in counted + plain if hasattr(ms, name)}

    def wrap(name):
        f = saved[name]
        f = getattr(f, "py_func", f) if name.startswith("_v2") else f

        def g(*a):
            cnt[name.lstrip("_")] += 1
            return f(*a)
        return g
    try:
        for name in counted:
            setattr(ms, name, wrap(name))
        for name in plain:
            if name in saved:
                setattr(ms, name, saved[name].py_func)
        for s in snaps:
            c = _copy(s)
            sub = {key: (v[..., :n_win] if key in ("state", "mstate", "lm") else v[:n_win]
                         if key in ("d", "k", "j", "lc", "cz") else v) for key, v in c.items()}
            _link_part.py_func(sub["d"], sub["state"], sub["mstate"], sub["k"], sub["j"], sub["lc"], sub["cz"],
                               sub["lm"], sub["slow_every"], sub["n_sub"], sub["par"], sub["tab"],
                               np.zeros(n_win, np.bool_))
    finally:
        for name, f in saved.items():
            setattr(ms, name, f)
    return cnt


def captured_steps(n, actions, scenario, warm, snaps, seed):
    """``snaps`` plant steps of a modal vector env of ``n`` windows (after ``warm`` steps; ``actions`` "random"
    or "held" duties), captured for replay (:func:`_capture`)."""
    env = SbarChargingVectorEnv(num_envs=n, scenario=scenario, num_threads=1, config=EnvConfig(link_model="modal"))
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)

    def act():
        return (rng.uniform(-1, 1, (n, 1)) if actions == "random" else np.zeros((n, 1))).astype(np.float32)
    for _ in range(warm):
        env.step(act())
    shots, grab, orig = _capture(env, snaps)
    env.parts.plant.step = grab
    for _ in range(snaps):
        env.step(act())
    env.parts.plant.step = orig
    return shots


def run(n=1024, actions="random", scenario="random", warm=60, snaps=20, reps=3, seed=0):
    shots = captured_steps(n, actions, scenario, warm, snaps, seed)
    res = {"n": n, "actions": actions, "scenario": scenario, "load_avg_1min": os.getloadavg()[0]}
    counts = [_link(_copy(s)) for s in shots]
    res["split_fraction"] = sum(c[1] for c in counts) / (snaps * n)
    res["segment_fraction"] = sum(c[0] for c in counts) / (snaps * n)
    _full(_copy(shots[0]))
    res["full_ns"] = _time(shots, _full, reps)
    res["link_ns"] = _time(shots, lambda c: _link(c), reps)
    res["link_held_all_ns"] = _time(shots, lambda c: _link(c, np.inf), reps)
    res["link_split_all_ns"] = _time(shots, lambda c: _link(c, 0.0), reps)
    res["finish_ns"] = res["full_ns"] - res["link_ns"]
    s0 = shots[0]
    cfg = EnvConfig(link_model="modal")

    def seg(c):
        _segments(c["lc"], c["cz"], c["lm"], cfg.dt_s, cfg.modal_n_sub, cfg.modal_n_q)
    seg(_copy(s0))
    res["segment_rebuild_ns_each"] = _time(shots[:3], seg, reps)
    cnt = _fallbacks(shots[:4])
    res["substep_counts_200win_4steps"] = cnt
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1024)
    ap.add_argument("--actions", choices=("held", "random"), default="random")
    ap.add_argument("--scenario", default="random")
    ap.add_argument("--warm", type=int, default=60)
    ap.add_argument("--snaps", type=int, default=20)
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args(argv)
    print(json.dumps(run(a.n, a.actions, a.scenario, a.warm, a.snaps, a.reps), indent=1))


if __name__ == "__main__":
    main()
