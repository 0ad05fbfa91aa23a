"""Cost of :func:`envs.vector._set_threads` (called before every parallel vector-env step and each parallel
autoreset part) with numba's pool's private thread-local getters cached against numba's public getters (each
takes the pool's launch lock): alternating rounds in one process, nothing to change (2 threads, chunk size 1
set already), so the call is its two getter reads. Prints the median (range) of the rounds' per-call times.

    PYTHONPATH=<tree> python benchmarks/set_threads.py [rounds] [calls per round]
"""

from __future__ import annotations

import statistics
import sys
import time


def main(rounds: int = 7, calls: int = 100_000) -> None:
    import numba
    from numba.np.ufunc import parallel

    from envs import vector
    numba.set_num_threads(2)   # (launches the pool)
    numba.set_parallel_chunksize(1)
    getters = {"private": (parallel._get_num_threads, parallel._get_parallel_chunksize),
               "public": (numba.get_num_threads, numba.get_parallel_chunksize)}
    us = {k: [] for k in getters}
    for _ in range(rounds):
        for name, pair in getters.items():
            vector._GETTERS[:] = pair
            t0 = time.perf_counter()
            for _ in range(calls):
                vector._set_threads(2)
            us[name].append((time.perf_counter() - t0) / calls * 1e6)
    vector._GETTERS[:] = []
    for name, v in us.items():
        print(f"{name} getters: {statistics.median(v):.2f} us per call ({min(v):.2f}-{max(v):.2f})")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
