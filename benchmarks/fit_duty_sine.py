"""The coefficients of :mod:`envs.duty_sine` (``sin(pi d/2)``, ``cos(pi d/2)`` by two polynomials), fitted again.

``y`` in [0, 1/2] at ``n`` Chebyshev nodes ``y_k = (1 - cos(pi (2k + 1) / (2n))) / 4`` (default 64), 50 digits
(mpmath); relative least squares (each row divided by the function's value), every coefficient free:

* ``sin(pi y/2) = y S(y^2)``, ``S`` of degree 6 in ``u = y^2`` (``_S0`` .. ``_S6``);
* ``cos(pi y/2) = C(y^2)``, ``C`` of degree 7 in ``u`` (``C0`` fitted too: it comes out 1 - 1.4e-20 and rounds to
  1.0, which the module writes as the literal ``1.0``; ``_C1`` .. ``_C7``).

The normal equations are solved at 50 digits and the results rounded to float64. Deterministic: any ``n`` from 32
up gives the same float64 coefficients, and they are envs.duty_sine's to the bit (checked 2026-11-28 at n = 32, 64,
128; at n = 16 four of the 15 differ in their last digits). ``--check`` exits 1 if any differs from the module's.

    python benchmarks/fit_duty_sine.py [--nodes 64] [--check]
"""

from __future__ import annotations

import argparse
import sys

import mpmath as mp


def chebyshev_nodes(n: int):
    """``n`` Chebyshev nodes on y in [0, 1/2] (mpmath numbers)."""
    return [(1 - mp.cos(mp.pi * (2 * k + 1) / (2 * n))) / 4 for k in range(n)]


def _relative_lsq(rows, values):
    """Least squares of ``sum c_i row_i = value`` with every row divided by its value (relative error)."""
    a = mp.matrix([[x / v for x in r] for r, v in zip(rows, values)])
    b = mp.matrix([1] * len(values))
    return mp.lu_solve(a.T * a, a.T * b)


def fit(n: int = 64, dps: int = 50):
    """``(S, C)``: float64 coefficients of ``S(u)`` (7, ``S0``..``S6``) and ``C(u)`` (8, ``C0``..``C7``)."""
    with mp.workdps(dps):
        ys = chebyshev_nodes(n)
        s = _relative_lsq([[y * (y * y) ** i for i in range(7)] for y in ys], [mp.sin(mp.pi * y / 2) for y in ys])
        c = _relative_lsq([[(y * y) ** i for i in range(8)] for y in ys], [mp.cos(mp.pi * y / 2) for y in ys])
        return [float(x) for x in s], [float(x) for x in c]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nodes", type=int, default=64, help="Chebyshev nodes on [0, 1/2] (default 64; >= 32 for the module's)")
    ap.add_argument("--check", action="store_true", help="compare with envs.duty_sine; exit 1 on any difference")
    args = ap.parse_args(argv)
    if args.nodes < 8:
        ap.error(f"--nodes {args.nodes} is invalid; valid range: >= 8")
    s, c = fit(args.nodes)
    for i, x in enumerate(s):
        print(f"_S{i} = {x!r}")
    for i, x in enumerate(c):
        print(f"_C{i} = {x!r}")
    if not args.check:
        return 0
    from envs import duty_sine as ds
    have = [getattr(ds, f"_S{i}") for i in range(7)] + [1.0] + [getattr(ds, f"_C{i}") for i in range(1, 8)]
    got = s + c
    names = [f"_S{i}" for i in range(7)] + [f"_C{i}" for i in range(8)]
    bad = [(nm, g, h) for nm, g, h in zip(names, got, have) if g != h]
    for nm, g, h in bad:
        print(f"differs: {nm} fitted {g!r}, module {h!r}", file=sys.stderr)
    print("reproduces envs.duty_sine to the bit" if not bad else f"{len(bad)} of {len(names)} differ")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
