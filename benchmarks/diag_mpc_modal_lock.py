"""Diagnostic: why the modal MPC's budgeted descent rings against its prediction (docs/rl.md, "Why the budgeted modal
MPC was far from the oracle").

For windows of nominal on the exact-mode link, the MPC's applied duties from its stop on are replayed open loop through
its own modal model (:mod:`policies.mpc_modal`) from its estimate at the stop, in three ways, and each step's largest
|I2| is set against the env's per-step envelope peak (``i2_peak_envelope_a``, the peak before the ripple excess):

* ``rows``: the condensed model the QP constrains (two samples a step, mid-step and end, V2 held in the short-mode
  frame: ``V2' = P(d)``);
* ``fixed``: the same model sub-stepped 16 times a step (is it the sampling?);
* ``locked``: sub-stepped 16 times with the SBAR's V2 turned onto I2's phase at every sub-step
  (``V2' = P(d) e^{j arg I2'}``: the rectifier commutates on i2; the fixed point through the feedthrough);
* ``lockrows``: the locked model the budgeted MPC's after-stop QP now linearises (:mod:`policies.mpc_lock`: 8
  sub-steps, |I2'| sampled at mid-step and end like the QP's rows).

    python benchmarks/diag_mpc_modal_lock.py [--policy mpc:0.1] [--windows 1013,1016,1004,1001] [--steps 20]
"""

from __future__ import annotations

import argparse

import numpy as np


def _closed_loop(name, window, cfg):
    """The policy's duties from its stop on, the env's per-step envelope peak [A] and the MPC's estimate at the stop."""
    from envs import SbarChargingVectorEnv
    from policies import make
    venv = SbarChargingVectorEnv(num_envs=1, scenario="nominal", config=cfg)
    pol = make(name, venv.policy_context)
    pol.reset(1)
    cap, orig = {}, pol._after_stop

    def hook(idx, z, vl, u_prev):
        cap.setdefault("z", z.copy())
        cap.setdefault("vl", vl.copy())
        return orig(idx, z, vl, u_prev)

    pol._after_stop = hook
    obs, _ = venv.reset(seed=[window])
    ds, pk = [], []
    for _ in range(venv.config.n_steps):
        d = np.asarray(pol.act(obs), dtype=float).reshape(1)
        obs, _, _, _, info = venv.step((2.0 * np.clip(d, 0.0, 1.0) - 1.0)[:, None].astype(np.float32))
        if "z" in cap:
            ds.append(info["d_short"][0])
            pk.append(info["i2_peak_envelope_a"][0])
    return pol, venv.policy_context, np.array(ds), np.array(pk), cap["z"][0], float(cap["vl"][0])


def replay(pol, ctx, ds, z, vl, n, ns=16, lock=False):
    """Largest |I2| [A] of each of the first ``n`` steps of the duties ``ds`` through the MPC's modal model from ``z``."""
    from policies.mpc_modal import _link_modes, _real_system, v2_frame_table
    from wpt_receiver import modal_kernel as mk
    m, link = pol._model, ctx.link
    mc = _link_modes(link, "schottky")[2]
    theta = v2_frame_table(link, "schottky")[3]
    d2 = mc[mk.MC_D + 3]
    c1 = mc[mk.MC_D + 2] * (-1j * link.v1_amp_v) * np.exp(-1j * theta)
    A, B = _real_system(link, "schottky", theta, ctx.control_period_s / ns)[:2]
    vc = vl + pol._vf
    s, out = z[:4].copy(), []
    for d in ds[:n]:
        u = pol._v2_of(d, vl)
        rr, ri = m.residual(np.array(u), vc)
        P = complex(u + z[4] + rr, ri)
        best = 0.0
        for _ in range(ns):
            i2 = complex(s[0] + s[2], s[1] + s[3]) + c1
            v2 = P
            if lock:
                for _p in range(3):
                    a = i2 + d2 * v2
                    v2 = P * a / abs(a)
            s = A @ s + B[:, 0] * v2.real + B[:, 1] * v2.imag + B[:, 2]
            best = max(best, abs(complex(s[0] + s[2], s[1] + s[3]) + c1 + d2 * v2))
        out.append(best)
    return np.array(out)


def rows(pol, ds, z, vl, n):
    """The condensed model's larger sample of each of the first ``n`` steps (what the after-stop QP constrains)."""
    from policies.mpc import N_PRED
    m = pol._model
    v2 = pol._v2_of(np.r_[ds, np.ones(N_PRED)][:N_PRED], vl)[None]
    i2 = z[None] @ m.F.T + m.h + v2 @ m.Gu.T + pol._rterm(v2, np.array([vl]))
    return i2.reshape(N_PRED, 2).max(axis=1)[:n]


def lock_rows(pol, ctx, ds, z, vl, n):
    """The locked model's larger sample of each of the first ``n`` steps (:func:`policies.mpc_lock.locked_rows`)."""
    from policies.mpc import N_PRED
    from policies.mpc_lock import LockedModel, locked_rows
    lm = LockedModel(ctx.link, "schottky", ctx.control_period_s)
    v2 = pol._v2_of(np.r_[ds, np.ones(N_PRED)][:N_PRED], vl)[None]
    r = locked_rows(lm, pol._model, z[None], v2, np.array([vl + pol._vf]), pol._model.M[:, :-1], grad=False)[0]
    return r.reshape(N_PRED, 2).max(axis=1)[:n]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policy", default="mpc:0.1")
    ap.add_argument("--windows", default="1013,1016,1004,1001")
    ap.add_argument("--steps", type=int, default=20)
    a = ap.parse_args(argv)
    from envs import EnvConfig
    cfg = EnvConfig(link_model="modal")
    np.set_printoptions(linewidth=200, precision=2, suppress=True)
    err = {"rows": [], "fixed": [], "locked": [], "lockrows": []}
    for w in (int(x) for x in a.windows.split(",")):
        pol, ctx, ds, pk, z, vl = _closed_loop(a.policy, w, cfg)
        n = min(a.steps, int(np.argmax(ds >= 0.999)) + 1 if np.any(ds >= 0.999) else a.steps)   # the descent
        sm = float(pol._bound_sm(z[None])[0])
        got = {"rows": rows(pol, ds, z, vl, n), "fixed": replay(pol, ctx, ds, z, vl, n),
               "locked": replay(pol, ctx, ds, z, vl, n, lock=True), "lockrows": lock_rows(pol, ctx, ds, z, vl, n)}
        print(f"{a.policy} window {w}: per-step |I2| peak over I2_sm - 1 [%], the descent's {n} steps")
        print(f"   env      {100 * (pk[:n] / sm - 1)}")
        for k, v in got.items():
            e = 100 * (v - pk[:n]) / sm
            err[k].append(e)
            print(f"   {k:8s} {100 * (v / sm - 1)}   error max {np.abs(e).max():.2f}, rms {np.sqrt((e ** 2).mean()):.2f} points")
    for k, v in err.items():
        e = np.concatenate(v)
        print(f"all windows, {k:6s}: error max {np.abs(e).max():.2f}, rms {np.sqrt((e ** 2).mean()):.2f} points of I2_sm")


if __name__ == "__main__":
    main()
