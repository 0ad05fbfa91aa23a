"""In-process A/B of two versions of the vector env's kernel (:func:`envs.vector_kernel.env_step`): this
tree's against another revision's (``git show REV:envs/vector_kernel.py``, loaded as a second module of the
``envs`` package from a temporary directory with that revision's ``layout.py`` and ``objective.py`` beside it:
numba's cache keys on them; its relative imports resolve to this tree's ``envs.layout`` and ``envs.objective``,
so the two revisions must share those), alternated on one captured step of the vector env (one thread).

The step is captured mid-episode (``--warm`` steps after ``reset(seed=1)``, uniform random actions); each
call runs on the captured inputs with the arrays the step mutates (state, step and slow indices, the
objective's running values, the outputs) restored before it, outside the timed region. Prints whether the
two kernels give the same outputs to the bit (every array), then thread CPU time per env-step of each (min,
lower quartile, median of ``--calls`` alternating calls) and the load average before and after. Kernel
only: no autoreset, no Python side of ``env.step`` (see ``bench_env.py`` for those).

    python benchmarks/ab_env_kernel.py [--rev aa14d7e] [--n 4096 16384] [--calls 300] [--scenario nominal]
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def load_revision(rev: str):
    """``envs/vector_kernel.py`` of git revision ``rev`` as the module ``envs._vk_<rev>``, with that revision's
    ``layout.py``, ``objective.py`` and (where it has one) ``duty_sine.py`` beside it (numba's cache keys on them) and
    imported by the kernel as modules of their own (``envs._vk_<rev>_layout``, ...): the kernel's relative imports of
    them are rewritten, so a revision whose layout differs from this tree's (e.g. a renamed slot) runs its own. The
    captured arguments are this tree's: a slot whose meaning changed between the trees gives different outputs,
    not a different cost."""
    import envs

    tmp = Path(tempfile.mkdtemp(prefix=f"vk_{rev}_"))
    src = subprocess.run(["git", "show", f"{rev}:envs/vector_kernel.py"], cwd=ROOT, check=True,
                         capture_output=True).stdout.decode()
    for dep in ("layout", "objective", "duty_sine"):
        got = subprocess.run(["git", "show", f"{rev}:envs/{dep}.py"], cwd=ROOT, capture_output=True)
        if got.returncode:
            continue   # (duty_sine.py is new in the eighth pass)
        (tmp / f"{dep}.py").write_bytes(got.stdout)
        name = f"envs._vk_{rev}_{dep}"
        spec = importlib.util.spec_from_file_location(name, tmp / f"{dep}.py")
        mod = importlib.util.module_from_spec(spec)
        mod.__package__ = envs.__name__
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
        src = src.replace(f"from .{dep} import", f"from ._vk_{rev}_{dep} import")
    (tmp / "vector_kernel.py").write_text(src)
    name = f"envs._vk_{rev}"
    spec = importlib.util.spec_from_file_location(name, tmp / "vector_kernel.py")
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = envs.__name__
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def _arrays(args):
    """The arrays of a kernel call's arguments, tuples flattened, in order."""
    out = []
    for x in args:
        if isinstance(x, tuple):
            out += _arrays(x)
        elif isinstance(x, np.ndarray):
            out.append(x)
    return out


def _rebuild(args, it):
    """``args`` with its arrays replaced, in order, by those of the iterator ``it``."""
    out = []
    for x in args:
        if isinstance(x, tuple):
            out.append(tuple(_rebuild(x, it)))
        else:
            out.append(next(it) if isinstance(x, np.ndarray) else x)
    return out


def capture(n: int, scenario: str, warm: int, kernel=None):
    """One ``env_step`` call of the vector env (one thread) after ``warm`` random steps: ``(args, snapshot,
    mutated)``: the call's arguments on private copies, the copies' values before the call, and the indices
    of the arrays the call changes. ``kernel``: the ``env_step`` that steps the env up to the captured call (default
    this tree's; another revision's when the two kernels' trajectories differ, e.g. in which windows they split)."""
    from envs import EnvConfig
    from envs.vector import SbarChargingVectorEnv

    env = SbarChargingVectorEnv(n, scenario=scenario, num_threads=1, config=EnvConfig(link_model="envelope"))   # eq. 4's kernel
    if kernel is not None:
        env.parts.plant.kernel = kernel
    env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(warm):
        env.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    kern, seen = env.parts.plant.kernel, []

    def record(*a):
        seen.append((a, [x.copy() for x in _arrays(a)]))
        return kern(*a)

    env.parts.plant.kernel = record
    env.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    a, snap = seen[0]
    work = [s.copy() for s in snap]
    args = _rebuild(a, iter(work))
    kern(*args)
    mutated = [i for i, (w, s) in enumerate(zip(work, snap)) if not np.array_equal(w, s)]
    return args, work, snap, mutated


def run(n: int, rev_mod, calls: int, scenario: str, warm: int, trajectory: str = "this") -> dict:
    """Same-bits check and alternating timing of this tree's kernel and ``rev_mod``'s at width ``n``."""
    from envs.vector_kernel import env_step as new

    args, work, snap, mutated = capture(n, scenario, warm, rev_mod.env_step if trajectory == "revision" else None)

    def restore():
        for i in mutated:
            np.copyto(work[i], snap[i])

    kernels = {"revision": rev_mod.env_step, "this tree": new}
    outs = {}
    for name, f in kernels.items():
        restore()
        f(*args)
        outs[name] = [w.copy() for w in work]
    same = all(np.array_equal(a, b) for a, b in zip(*outs.values()))
    times = {name: [] for name in kernels}
    for _ in range(calls):
        for name, f in kernels.items():
            restore()
            t0 = time.thread_time_ns()
            f(*args)
            times[name].append((time.thread_time_ns() - t0) / n)
    return {"same_bits": same, **{k: np.percentile(v, [0, 25, 50]) for k, v in times.items()}}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="aa14d7e", help="git revision of the other kernel (default aa14d7e)")
    ap.add_argument("--n", type=int, nargs="+", default=[4096, 16384])
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--scenario", default="nominal")
    ap.add_argument("--warm", type=int, default=120, help="random steps before the captured one (default 120)")
    ap.add_argument("--trajectory", choices=("this", "revision"), default="this",
                    help="whose kernel steps the env up to the captured call (default this tree's)")
    a = ap.parse_args(argv)
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    mod = load_revision(a.rev)
    for n in a.n:
        r = run(n, mod, a.calls, a.scenario, a.warm, a.trajectory)
        print(f"N = {n}: outputs the same to the bit: {r['same_bits']}; thread CPU ns per env-step (min / q25 / "
              f"median of {a.calls}): {a.rev} " + " / ".join(f"{x:.1f}" for x in r["revision"])
              + ", this tree " + " / ".join(f"{x:.1f}" for x in r["this tree"]), flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
