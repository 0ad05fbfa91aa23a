"""``dronewpt export-controller``: the paper's controller as C99 for a DSP (``wpt_receiver.c_export``)."""

from __future__ import annotations

import json
from pathlib import Path

from .common import CliError, float_arg, int_in, path_arg, prepare_out_dir

_PRECISIONS = {"float32": ("f32",), "float64": ("f64",), "both": ("f32", "f64")}


def _add_export_controller(sub):
    p = sub.add_parser("export-controller", help="write the paper's controller as C99 (float/double) + test vectors",
                       description="Write a self-contained C99 header + source of the model-based controller "
                                   "(low-pass, G22^-1 discretised at the control period, f^-1 with clamps) with "
                                   "the parameters as a struct of defaults baked from the link (Table I), in float "
                                   "and/or double, the Python controller's duties as test vectors (CSV and C header) "
                                   "and a self-test program per precision.")
    p.add_argument("--out", type=path_arg("--out"), default=Path("out/controller"), help="folder (default out/controller)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--precision", choices=tuple(_PRECISIONS), default="both", help="float32, float64 or both (default)")
    g.add_argument("--float32", dest="precision", action="store_const", const="float32", help="= --precision float32")
    g.add_argument("--float64", dest="precision", action="store_const", const="float64", help="= --precision float64")
    p.add_argument("--control-period", type=float_arg("control-period", positive=True, lo=1e-7, hi=1e-3), default=None,
                   help="control period in s, 1e-7 .. 1e-3 (default: the rectifier period 1/(2f), the paper's); "
                        "at most 200,000 test vectors: >= 4.8e-7 s")
    p.add_argument("--lpf-tau", type=float_arg("lpf-tau", positive=True, lo=1e-6, hi=1e-1), default=2e-4,
                   help="time constant of the low-pass Q in s, 1e-6 .. 0.1 (default 2e-4)")
    p.add_argument("--lpf-order", type=int_in("lpf-order", 1, 8), default=2, help="order of Q, 1 .. 8 (default 2)")
    p.add_argument("--link", action="append", default=[], metavar="KEY=VALUE",
                   help="a link parameter other than Table I (repeatable), e.g. lm_h=5e-6; keys: l1_h, l2_h, lm_h, "
                        "r1_ohm, r2_ohm, vdc_v, vl_v, f_hz")
    p.add_argument("--check", action="store_true", help="also compile the self-tests with the system C compiler "
                   "(-Wall -Werror -std=c99 -O2 ...) and run them against the vectors")
    p.add_argument("--cc", default="cc", help="C compiler for --check (default cc)")
    p.add_argument("--format", choices=("table", "json"), default="table")
    p.set_defaults(func=_cmd_export_controller)


def _link_params(items):
    from dataclasses import fields

    from wpt_receiver import TABLE_I

    from ..config import LINK_PARAM_RANGES
    from ..validation import check_range
    keys = [f.name for f in fields(TABLE_I)]
    changes = {}
    for item in items:
        key, sep, val = item.partition("=")
        if not sep or key.strip() not in keys:
            raise CliError(f"--link {item!r} is invalid; valid: KEY=VALUE with KEY one of {', '.join(keys)}")
        try:
            value = float(val)
        except ValueError:
            raise CliError(f"--link {item!r}: {val!r} is not a number") from None
        # (nan, 1e308, f_hz=1e-300 were a traceback or an overflow further on)
        check_range(f"--link {key.strip()}", value, LINK_PARAM_RANGES[key.strip()])
        if changes.get(key.strip(), value) != value:   # (the last one won without a word)
            raise CliError(f"--link {key.strip()} is given twice ({changes[key.strip()]:g} and {value:g}); valid: "
                           "each key once")
        changes[key.strip()] = value
    # (an f_hz far off the coils' resonance is warned by the library's entry point the command calls)
    return TABLE_I.with_(**changes) if changes else TABLE_I


def _cmd_export_controller(args) -> int:
    from wpt_receiver import LowPassFilter, c_export
    params = _link_params(args.link)
    spec = c_export.controller_spec(params, args.control_period, LowPassFilter(args.lpf_tau, args.lpf_order))
    c_export.check_vector_count(spec)   # --link f_hz=2.712e7 ran for minutes towards a ~380 MB header
    prepare_out_dir(args.out)   # a file in its place, read-only: one line before any work (was "[Errno 30] ...")
    precs = _PRECISIONS[args.precision]
    res = c_export.write_export(args.out, spec, precs)
    checks = {prec: _check(args.out, prec, args.cc) for prec in precs} if args.check else {}
    budget = c_export.budget(spec, res["ops"][precs[0]]["step"])
    if args.format == "json":
        print(json.dumps({"files": [str(f) for f in res["files"]], "control_period_s": spec.control_period_s,
                          "ops_per_step": res["ops"], "budget": budget, "checks": checks}))
        return 0 if all(c["status"] == 0 for c in checks.values()) else 1
    print(f"controller: H = Q G22^-1, {spec.nx} states, control period {spec.control_period_s * 1e6:.4g} us "
          f"({'the rectifier period T = 1/(2f), one duty per half cycle' if args.control_period is None else 'set'})")
    for prec in precs:
        st, cm = res["ops"][prec]["step"], res["ops"][prec]["command"]
        print(f"{prec}: per control step (I2ref, VL -> d): {_ops_text(st)}; command front end (I_L* -> I2ref): "
              f"{_ops_text(cm)}")
    print(f"budget: {budget['text']}")
    for prec, c in checks.items():
        print(f"check {prec}: {c['summary']}")
    for f in res["files"]:
        print(f"file: {f}")
    return 0 if all(c["status"] == 0 for c in checks.values()) else 1


def _ops_text(c: dict) -> str:
    return ", ".join(f"{v} {k}" for k, v in c.items() if v)


def _check(out, prec: str, cc: str) -> dict:
    import subprocess

    from wpt_receiver import c_export
    try:
        prog = c_export.build_selftest(out, prec, cc)
    except subprocess.CalledProcessError as exc:
        raise CliError(f"the generated {prec} C did not compile: {' '.join((exc.stderr or '').split())[:300]}") from None
    status, _, summary = c_export.run_selftest(prog)
    return {"status": status, "summary": summary}
