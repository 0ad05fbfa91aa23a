"""How well the modal MPC's prediction (``MPCPolicy.predicted_rows`` from its estimate at the stop) predicts the
measured overshoot of the duty sequence a policy actually plays after the stop (docs/rl.md, "A safety filter on the
learned after-stop sequence"): for the plain clone (``slow = 1``), the rate filter and the QP filter (both at the
stop, limit 0), per window the open-loop prediction of the played sequence (150 steps from the stop, duty 1 after)
from the state the filter's MPC estimated at the stop, against the measured overshoot.

    python benchmarks/diag_oracle_imitation_filter.py --scenario battery_low --episodes 20 --seed 300
"""

from __future__ import annotations

import argparse

import numpy as np

SETTINGS = {
    "clone (slow 1.0)": dict(limit=1.0, slow=1.0, correction="qp"),
    "rate filter, limit 0": dict(limit=0.0, lam=None, slow=1.0, correction="rate", every_period=False,
                                 rates=(1.0, 0.97, 0.94, 0.91, 0.88, 0.85, 0.82, 0.79, 0.76)),
    "qp filter, limit 0": dict(limit=0.0, slow=1.0, correction="qp", every_period=False, smooth=0.0),
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="battery_low")
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=300)
    a = ap.parse_args(argv)
    from envs import EnvConfig, SbarChargingVectorEnv
    from policies import register
    from policies.compare import run_policies
    from policies.mpc import N_PRED
    from policies.oracle_imitation_filter import OracleImitationFilteredPolicy
    at_stop = {}

    def factory(tag, opts):
        class Recorded(OracleImitationFilteredPolicy):
            def _play(self, after, phys):
                for i in np.flatnonzero(self._j[after] == 0):
                    at_stop.setdefault(tag, {})[int(after[i])] = (self._z[after[i]].copy(), float(phys[after[i], 1]),
                                                                  self._mpc)
                return super()._play(after, phys)
        return lambda ctx, **kw: Recorded(ctx, **opts, **kw)
    names = []
    for i, (tag, opts) in enumerate(SETTINGS.items()):
        register(f"diag{i}", factory(tag, opts))
        names.append(f"diag{i}")
    config = EnvConfig(link_model="modal")
    runs = run_policies(names, a.scenario, a.episodes, a.seed, config)
    venv = SbarChargingVectorEnv(num_envs=a.episodes, scenario=a.scenario, config=config)
    venv.reset(seed=[a.seed + i for i in range(a.episodes)])
    stop_k = venv._stop_k.copy()
    for name, tag in zip(names, SETTINGS):
        tr, err = runs[name], []
        for w in range(a.episodes):
            z, vl, mpc = at_stop[tag][w]
            d = tr.d_short[stop_k[w]:stop_k[w] + N_PRED, w]
            d = np.r_[d, np.ones(N_PRED - len(d))]
            rows = mpc.predicted_rows(z[None], np.array([vl]), mpc._v2_of(d, vl)[None], None)[0]
            err.append(100.0 * (rows.max() / mpc._bound_sm(z[None])[0] - 1.0) - tr.metrics["overshoot_pct"][w])
        err = np.array(err)
        print(f"{tag:<22} predicted - measured overshoot: mean {err.mean():+.3f} sd {err.std():.3f} points; measured mean "
              f"{tr.metrics['overshoot_pct'].mean():.3f} %, E after {tr.metrics['energy_after_stop_j'].mean():.3f} J")


if __name__ == "__main__":
    main()
