"""Cost of ``envelope.steady_state``'s input checks (2026-11-27 evening): this tree's ``steady_state`` against
``main``'s (no checks), alternating in one process, thread CPU time per call (medians and ranges of ``--rounds``
rounds, each ``--calls`` calls after a warm-up). Cases: a scalar V2 (Python float); V2 and Lm arrays of n links (what
``policies.online`` calls once per step), n = 8, 64, 1024.

    python benchmarks/bench_steady_state_checks.py --main /work/main [--rounds 9] [--calls 20000]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import sys
import time

import numpy as np


def _load_main_envelope(root):
    """main's ``wpt_receiver.envelope`` as a separate module (its package imported under another name)."""
    spec = importlib.util.spec_from_file_location("main_wpt_receiver", os.path.join(root, "wpt_receiver", "__init__.py"),
                                                  submodule_search_locations=[os.path.join(root, "wpt_receiver")])
    pkg = importlib.util.module_from_spec(spec)
    sys.modules["main_wpt_receiver"] = pkg
    spec.loader.exec_module(pkg)
    return importlib.import_module("main_wpt_receiver.envelope")


def _per_call_us(f, args, kwargs, calls):
    t0 = time.thread_time_ns()
    for _ in range(calls):
        f(*args, **kwargs)
    return (time.thread_time_ns() - t0) / calls / 1e3


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--main", required=True, help="the peer tree (main: no checks in steady_state; a commit's wpt_receiver extracted by git archive)")
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--calls", type=int, default=20000)
    a = ap.parse_args(argv)
    from wpt_receiver import TABLE_I
    from wpt_receiver.envelope import steady_state as ours
    theirs = _load_main_envelope(a.main).steady_state
    p = TABLE_I
    cases = {"scalar v2": ((p, 10.0), {})}
    for n in (8, 64, 1024):
        v2 = np.linspace(5.0, 40.0, n)
        cases[f"n={n} v2, lm"] = ((p, v2), {"lm_h": np.linspace(4e-6, 9e-6, n)})
    print(f"load before: {os.getloadavg()}")
    for name, (args, kw) in cases.items():
        for f in (ours, theirs):   # warm-up
            _per_call_us(f, args, kw, a.calls // 10)
        ra, rb = [], []
        for _ in range(a.rounds):   # alternating
            ra.append(_per_call_us(ours, args, kw, a.calls))
            rb.append(_per_call_us(theirs, args, kw, a.calls))
        diff = [x - y for x, y in zip(ra, rb)]
        print(f"{name:16s} ours {statistics.median(ra):7.2f} us ({min(ra):.2f}-{max(ra):.2f})  main "
              f"{statistics.median(rb):7.2f} us ({min(rb):.2f}-{max(rb):.2f})  checks +{statistics.median(diff):.2f} us "
              f"(pairwise median, {min(diff):.2f}..{max(diff):.2f}), n={a.rounds}")
    print(f"load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
