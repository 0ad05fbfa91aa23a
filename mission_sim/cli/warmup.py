"""``dronewpt warmup``: compile numba's kernels ahead (once per machine), so that the first
``mission``, ``compare``, ``replay`` or ``sizing`` does not spend a silent half-minute compiling.

Each stage runs a small real job through the same code path the commands use (kernels are compiled
per policy and per argument type, so running them is the only sure way to hit every signature) and
counts numba's ``numba:compile`` events, which fire only on a cache miss: a second warmup reports
every stage as loaded from the cache.
"""

from __future__ import annotations

import json
import os
import sys
import time

from .common import CliError

KERNEL_POLICIES = ("step", "ramp", "model_based")


def _add_warmup(sub):
    p = sub.add_parser("warmup", help="compile the numba kernels ahead (once per machine, ~1-3 min)",
                       description="Compile (or load from numba's disk cache) every numba kernel the commands "
                                   "use: the compiled mission loop with the step, ramp and model_based policy "
                                   "kernels (mission, replay, sweep, sizing --source mission), the batched env "
                                   "on both links and its policy kernels with the budgeted plan's search (compare, train), a 2,048-env "
                                   "vector env's parallel steps and autoresets, a single env's steps "
                                   "(gymnasium.make) and the switching model (paper "
                                   "--model switching, sizing), and builds the mission loop ahead of time into the disk cache "
                                   "(`dronewpt mission` then runs without numba; skipped with DRONEWPT_AOT=0). Prints "
                                   "each stage, how many kernels it compiled "
                                   "and how long it took.")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.set_defaults(func=_cmd_warmup)


def _missions() -> None:
    from .. import config as mconfig
    from ..world.runner import run_mission
    from .mission import make_policy
    cfg = mconfig.config_from_dict(mconfig.load_config_dict(None))
    for name in KERNEL_POLICIES:
        run_mission(cfg, make_policy(name, cfg), compiled=True)


def _envs() -> None:
    from envs import EnvConfig
    from policies.compare import run_policy
    for link in ("modal", "envelope"):   # the envs' default (exact-mode) link and eq. 4's (`--link envelope`)
        cfg = EnvConfig(link_model=link)
        for name in (*KERNEL_POLICIES, "model_based_budget:0.01"):   # + the budgeted plan's search (compare)
            run_policy(name, "nominal", 2, 1000, cfg)
    _parallel_vector_envs()


def _parallel_vector_envs() -> None:
    """What a vector env of N >= ``PARALLEL_MIN_ENVS`` on 2 threads compiles in its first steps (both links): the
    parallel step, an autoreset's parallel draws and command profile, a partial restart's draws into a new array."""
    import numba
    import numpy as np

    from envs import EnvConfig, SbarChargingVectorEnv
    n, threads = SbarChargingVectorEnv.PARALLEL_MIN_ENVS, min(2, numba.config.NUMBA_NUM_THREADS)
    for link in ("modal", "envelope"):
        env = SbarChargingVectorEnv(n, config=EnvConfig(n_steps=2, link_model=link), num_threads=threads)
        env.reset(seed=0)
        for _ in range(3):   # the episode's 2 steps, then the autoreset of all windows
            env.step(np.zeros((n, 1), np.float32))
        env.restart([0, 1])
        env.close()


def _single_envs() -> None:
    """What a single env's first steps compile (``gymnasium.make(envs.ENV_ID)``, both links, the discrete one)."""
    import envs
    for link in ("modal", "envelope"):
        for cls in (envs.SbarChargingEnv, envs.SbarChargingDiscreteEnv):
            env = cls(config=envs.EnvConfig(link_model=link))
            env.reset(seed=0)
            for _ in range(3):
                env.step(env.action_space.sample())
            env.close()


def _switching() -> None:
    from wpt_receiver import TABLE_I
    from wpt_receiver.devices import preset
    from wpt_receiver.sizing import SizingRules, size_policies
    size_policies(["step"], TABLE_I, preset("schottky"), SizingRules(), t_end_s=3e-3)


def _ahead_of_time() -> str:
    """The mission loop's ahead-of-time build (:mod:`mission_sim.world.aot`; a child process compiles it; a
    module whose bytes do not match its digest is removed and built again)."""
    from ..world import aot
    if not aot.enable():
        return f"skipped ({aot.ENV_VAR}={os.environ.get(aot.ENV_VAR, '')}, or NUMBA_DISABLE_JIT set)"
    if aot.module_dir() is None:
        from wpt_receiver.diskcache import ENV_VAR
        return f"skipped (the disk cache is off: {ENV_VAR} is empty)"
    if aot.find_module() is not None:
        return "built already"
    return "built" if aot.build() is not None else f"failed (numba's JIT is used; {aot.failed_note()})"


STAGES = (("mission loop and policy kernels (mission, replay, sweep)", _missions),
          ("mission loop built ahead of time (dronewpt mission without numba)", _ahead_of_time),
          ("batched env and policy kernels (compare, train)", _envs),
          ("single env's steps (gymnasium.make(envs.ENV_ID))", _single_envs),
          ("switching model (paper --model switching, sizing)", _switching))


def _counter():
    """A listener counting numba's compile events (cache misses), registered for the whole run."""
    from numba.core import event

    class Count(event.Listener):
        n = 0

        def on_start(self, ev):
            self.n += 1

        def on_end(self, ev):
            pass

    c = Count()
    event.register("numba:compile", c)
    return c


def _cmd_warmup(args) -> int:
    try:
        counter = _counter()
    except ImportError:
        raise CliError("numba is not installed (pip install numba); nothing to compile") from None
    rows = []
    for name, run in STAGES:
        n0, t0 = counter.n, time.perf_counter()
        note = run()
        row = {"stage": name, "kernels_compiled": counter.n - n0, "wall_s": round(time.perf_counter() - t0, 2)}
        if note is not None:
            row["result"] = note
        rows.append(row)
        if args.format == "table":
            what = row.get("result") or (f"{row['kernels_compiled']} kernels compiled" if row["kernels_compiled"]
                                         else "loaded from numba's cache")
            print(f"{name}: {what} in {row['wall_s']:.1f} s", flush=True)
    total = sum(r["wall_s"] for r in rows)
    if args.format == "json":
        print(json.dumps({"stages": rows, "wall_s": round(total, 2)}))
    else:
        print(f"warmup done in {total:.1f} s; later runs load the kernels from the cache", file=sys.stdout)
    return 0
