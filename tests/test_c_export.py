"""The exported C controller (``dronewpt export-controller``) against the Python controller.

Compiled with the system C compiler (``-Wall -Werror -std=c99 -O2`` plus -Wextra -Wpedantic
-Wdouble-promotion -Wfloat-conversion), run over the paper's three trajectories (f^-1 alone and
the whole controller) and a window of a real mission; float64 within 1e-9 of Python, float32
within the derived per-step bound (``c_export.float32_duty_bound``)."""

import functools
import shutil
import subprocess

import numpy as np
import pytest

from wpt_receiver import TABLE_I, LowPassFilter, c_export

pytestmark = pytest.mark.skipif(shutil.which("cc") is None, reason="no system C compiler")


@functools.cache
def _paper_export(tmp_root):
    spec = c_export.controller_spec()
    vec = c_export.test_vectors(spec)
    res = c_export.write_export(tmp_root, spec, vectors=vec)
    return spec, vec, res


@pytest.fixture(scope="module")
def paper(tmp_path_factory):
    return _paper_export(tmp_path_factory.mktemp("ctl"))


def _run(out, prec):
    prog = c_export.build_selftest(out, prec)
    status, duties, summary = c_export.run_selftest(prog)
    return status, duties, summary


def _check(out, vec, prec):
    status, duties, summary = _run(out, prec)
    assert len(duties) == len(vec), summary
    err = np.abs(duties - vec["duty"].to_numpy())
    tol = vec["duty_tol_f32"].to_numpy() if prec == "f32" else c_export.F64_TOLERANCE
    assert np.all(err <= tol), (summary, float(np.max(err / tol)))
    assert status == 0, summary
    return err


def test_float64_matches_python_on_the_paper_trajectories(paper):
    spec, vec, res = paper
    err = _check(res["files"][0].parent, vec, "f64")
    assert float(np.max(err)) <= 1e-9
    # the trajectories really move the duty over most of its range (RM 0 -> towards SM 1), both kinds of case present
    for case in ("step_ctl", "ramp_ctl", "proposed_ctl", "step_finv", "ramp_finv", "proposed_finv"):
        d = vec.loc[vec["case"] == case, "duty"].to_numpy()
        assert d[0] == pytest.approx(0.0, abs=1e-6) and d[-1] > 0.75, case


def test_float32_within_its_derived_bound(paper):
    spec, vec, res = paper
    err = _check(res["files"][0].parent, vec, "f32")
    tol = vec["duty_tol_f32"].to_numpy()
    # it is single precision (errors far above double's) and the bound is not vacuous
    assert float(np.max(err)) > 1e-7
    assert float(np.max(tol)) < 5e-3
    assert float(np.max(err / tol)) > 0.01


def test_proposed_vectors_are_the_paper_controller(paper):
    """The vectors' proposed case is what ``reference_duty('proposed')`` (the paper's run) gives."""
    from wpt_receiver.references import reference_duty
    spec, vec, _ = paper
    _, d, _ = reference_duty("proposed", TABLE_I, 1e-3, 16e-3, spec.control_period_s, spec.lpf)
    got = vec.loc[vec["case"] == "proposed_ctl", "duty"].to_numpy()
    assert np.max(np.abs(got - d)) < 1e-9


def _mission_window():
    """(ctx, lpf, [(name, i2_ref, vl)]): two fine windows of the default mission around a change of
    the charge command (start of charging, stop), I2ref from ModelBasedPolicy.i2_ref."""
    import policies
    from mission_sim.config import load_config, policy_context
    from mission_sim.world.runner import run_mission
    cfg = load_config()
    ctx = policy_context(cfg)
    pol = policies.make("model_based", ctx)
    ts = run_mission(cfg, pol).timeseries
    cmd, vl, fine = ts["charge_cmd_a"].to_numpy(), ts["battery_v"].to_numpy(), ts["fine"].to_numpy() > 0
    cases = []
    ch = np.flatnonzero(np.diff(cmd) != 0)
    for a in (ch[cmd[ch] == 0][0], ch[cmd[ch + 1] == 0][0]):   # charging starts; charging stops
        b = a + 1 + np.argmax(~fine[a + 1:])          # to the end of the fine window that follows
        sl = slice(max(a - 3, 0), b)
        cases.append((f"mission_{a}", pol.i2_ref(cmd[sl], vl[sl]), vl[sl]))
    return ctx, pol.lpf, cases


def test_mission_window_float64_and_float32(tmp_path):
    ctx, lpf, cases = _mission_window()
    assert len(cases) == 2 and all(len(c[1]) > 100 for c in cases)
    spec = c_export.controller_spec(ctx.link, ctx.control_period_s, lpf)
    vec = c_export.test_vectors(spec, extra=[(n, "ctl", r, v) for n, r, v in cases], paper=False)
    c_export.write_export(tmp_path, spec, vectors=vec)
    for prec in ("f64", "f32"):
        _check(tmp_path, vec, prec)
    for name, _, vl in cases:   # the window moves the duty and VL varies along it
        d = vec.loc[vec["case"] == name, "duty"].to_numpy()
        assert np.ptp(d) > 0.5 and np.ptp(vl) > 0.01


def test_command_front_end_matches_the_policy(tmp_path):
    """``i2_ref_from_command`` (C, double) against ``ModelBasedPolicy.i2_ref`` on a grid that
    crosses both clamps (no charge, more than RM can give)."""
    import policies
    from mission_sim.contract import PolicyContext
    pol = policies.make("model_based", PolicyContext())
    spec = c_export.controller_spec(pol.ctx.link, pol.ctx.control_period_s, pol.lpf)
    c_export.write_export(tmp_path, spec, ("f64",), vectors=c_export.test_vectors(spec, t_end_s=3e-3))  # noqa: E501
    cmd, vl = np.meshgrid(np.linspace(-1, 60, 41), np.linspace(20, 42, 7))
    cmd, vl = cmd.ravel(), vl.ravel()
    rows = ",\n".join(f"{{{float(a)!r}, {float(b)!r}}}" for a, b in zip(cmd, vl))
    (tmp_path / "front.c").write_text(
        '#include <stdio.h>\n#include "dwpt_ctl_f64.h"\n'
        f"static const double in[{len(cmd)}][2] = {{{rows}}};\n"
        "int main(void) { int i; for (i = 0; i < " + str(len(cmd)) + "; ++i) printf(\"%.17g\\n\", "
        "dwpt_f64_i2_ref_from_command(&dwpt_f64_default_params, in[i][0], in[i][1])); return 0; }\n")
    exe = tmp_path / "front"
    subprocess.run(["cc", *c_export.CFLAGS, "-o", str(exe), str(tmp_path / "front.c"),
                    str(tmp_path / "dwpt_ctl_f64.c"), "-lm"], check=True, capture_output=True)
    got = np.array([float(x) for x in subprocess.run([str(exe)], capture_output=True, text=True).stdout.split()])
    want = pol.i2_ref(cmd, vl)
    assert np.max(np.abs(got - want)) <= 1e-9 * np.max(np.abs(want))
    assert np.ptp(want) > 0.4   # the grid spans SM (no charge, 11.44 A) to the RM clamp (10.92 A at 30 V)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_operation_count_follows_the_generated_structure(order):
    """Ops of one step read off the generated text equal the recursion's closed form for n = order + 1
    states (u: 1 add; V2* = Cd x + Dd u: n + 1 mul, n add; x+ = Ad x + Bd u: n (n + 1) mul, n^2 add;
    f^-1: 2 mul, 1 div, 1 add, 2 clamps, 1 asin), and a C parser counts the same."""
    spec = c_export.controller_spec(lpf=LowPassFilter(2e-4, order))
    _, _, src = c_export.generate_c(spec, "f32")
    names = [f"dwpt_f32_{f}" for f in c_export.STEP_FUNCTIONS]
    ops = c_export.count_ops(src, names)
    n = order + 1
    assert ops == {"add": 1 + n + n * n + 1, "mul": (n + 1) + n * (n + 1) + 2, "div": 1, "cmp": 2, "sqrt": 0, "asin": 1}
    pycparser = pytest.importorskip("pycparser")
    assert _ast_count(pycparser, src, names) == {k: ops[k] for k in ("add", "mul", "div")}


def _ast_count(pycparser, src, names):
    """+, -, *, / BinaryOps in the named functions' ASTs (pycparser; typedefs given, no #include)."""
    from pycparser import c_ast
    import re
    body = re.sub(r"/\*.*?\*/", " ", "\n".join(ln for ln in src.splitlines() if not ln.startswith("#")), flags=re.S)
    body = body.replace("DWPT_F32_FOUR_OVER_PI", "1.0f").replace("DWPT_F32_TWO_OVER_PI", "1.0f")
    pre = ("typedef float dwpt_f32_real; typedef struct { float ad[8][8]; float bd[8]; float cd[8]; float dd; "
           "float xss[8]; float i2_sm_a; float wlm_v1; float wlm_v1_sq; float det_ohm2; float r1_ohm; "
           "float control_period_s; } dwpt_f32_params; typedef struct { float x[8]; } dwpt_f32_state;"
           "float asinf(float); float sqrtf(float);\n")
    ast = pycparser.CParser().parse(pre + body)
    counts = {"add": 0, "mul": 0, "div": 0}

    class V(c_ast.NodeVisitor):
        def visit_BinaryOp(self, node):
            key = {"+": "add", "-": "add", "*": "mul", "/": "div"}.get(node.op)
            if key:
                counts[key] += 1
            self.generic_visit(node)
    for ext in ast.ext:
        if isinstance(ext, c_ast.FuncDef) and ext.decl.name in names:
            V().visit(ext)
    return counts


def test_cli_writes_and_checks(tmp_path):
    from mission_sim.cli import main
    assert main(["export-controller", "--out", str(tmp_path), "--float64", "--format", "json"]) == 0
    assert (tmp_path / "dwpt_ctl_f64.c").exists() and not (tmp_path / "dwpt_ctl_f32.c").exists()
    with pytest.raises(SystemExit) as bad:   # refused by the option's type (argparse): exit status 2
        main(["export-controller", "--out", str(tmp_path), "--lpf-order", "0"])
    assert bad.value.code == 2
