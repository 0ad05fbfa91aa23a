"""(helper of benchmarks/modal_refine_study.py) the converge table: largest instantaneous peak after the
transient per refinement setting, against the switching model and the fine-step limit (4352 updates, no
refinement); per-step rms against the limit; the paper's trajectories' peak and charge against today's."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import modal_substeps_study as s  # noqa: E402
from envs import modal_step as vk  # noqa: E402
from envs.layout import CZ_MODES, CZ_STEP, N_CZ  # noqa: E402
from wpt_receiver import modal_kernel as mk  # noqa: E402

P = s.P
SETTINGS = {"today (off)": (17, 0.05, 0), "L2 tol 0.05": (17, 0.05, 2), "default L3 tol 0.05": (17, 0.05, 3),
            "L3 tol 0.1": (17, 0.1, 3), "L4 tol 0.05": (17, 0.05, 4), "L5 tol 0.02": (17, 0.02, 5),
            "uniform 136": (136, 0.05, 0)}


def run(d_seq, n_sub, rtol, levels):
    lc, tab = mk.link_constants(P, s.IDEAL), mk.modal_table(P, s.IDEAL)
    cz = np.zeros(N_CZ, dtype=complex)
    vk._segment(lc, P.lm_h, s.ENV_DT, n_sub, 1, cz, True, rtol, levels)
    mc, v1 = cz[CZ_MODES:CZ_STEP], -1j * P.v1_amp_v
    z = np.zeros(4)
    v2 = mk.steady_state(lc, mc, tab, float(d_seq[0]), v1, P.vl_v, z)
    rows, e = [], -1.0
    for d in d_seq:
        v2, e, _, _, pe, p, il, _, _ = vk._link_step(z, v2, e, P.vl_v, d, lc, tab, cz, s.ENV_DT, n_sub, 1, 0.0, 0.0,
                                                     P.v1_amp_v, 1e-3, np.empty(9), np.zeros(4))
        rows.append((p, il))
    return np.array(rows).T


def main(out):
    res = {}
    for name, (d, p0) in s.transient_cases().items():
        sw = s.switching_peaks(d)[p0:]
        lim = run(d, 4352, 0.05, 0)[0][p0:]
        base_pk, base_il = run(d, 17, 0.05, 0)
        row = {"switching_a": float(sw.max()), "limit_a": float(lim.max()),
               "limit_vs_switching_pct": 100 * (lim.max() / sw.max() - 1)}
        for lab, (n, tol, lev) in SETTINGS.items():
            pk, il = run(d, n, tol, lev)
            e = pk[p0:] / lim - 1
            row[lab] = dict(vs_switching_pct=100 * (pk[p0:].max() / sw.max() - 1),
                            vs_limit_pct=100 * (pk[p0:].max() / lim.max() - 1),
                            step_rms_vs_limit_pct=100 * float(np.sqrt((e ** 2).mean())),
                            vs_today_pct=100 * (pk[p0:].max() / base_pk[p0:].max() - 1),
                            charge_vs_today_pct=100 * (il[p0:].sum() / base_il[p0:].sum() - 1),
                            identical_to_today=bool(np.array_equal(pk, base_pk) and np.array_equal(il, base_il)))
        res[name] = row
        print(name, json.dumps(row), flush=True)
    Path(out).write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main(sys.argv[1])
