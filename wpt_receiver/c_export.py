"""The paper's controller (Fig. 5) as self-contained C99 for a DSP, generated from the Python one.

``I2ref -> Q(s) -> G22^-1(s) -> V2* -> f^-1 -> d_short*``: the same discrete state-space recursion as
:class:`wpt_receiver.inverse_controller.InverseModelController` (the cascade ``H = Q G22^-1``
discretised with a zero-order hold at the control period, controller canonical form, the same
``Ad, Bd, Cd, Dd``), the same steady-state reset ``x = u x_ss`` and the same duty mapping as
:func:`wpt_receiver.sbar.duty_from_v2_clipped` (inverse of eq. 9 with its clamps):
``d = (2/pi) asin(clamp(1 - V2* / ((4/pi) VL), 0, 1))``. The charge-command front end of
:class:`policies.classical.ModelBasedPolicy` (``I_L* -> V2 target -> I2ref``) is exported too.

Every number in the C comes from the Python objects (Table I by default): nothing is retyped.
The recursion is written out (unrolled) for the filter order, so the operations per control step
are read off the generated code (:func:`count_ops`). Two variants, ``float`` (``dwpt_f32_*``) and
``double`` (``dwpt_f64_*``), can be linked into one program.

Float32 accuracy: :func:`float32_duty_bound` is a first-order running error bound (Higham,
*Accuracy and Stability of Numerical Algorithms*, 2nd ed., sec. 3.1 and 3.5: ``|fl(sum a_i b_i) -
sum a_i b_i| <= gamma_m sum |a_i b_i|``, ``gamma_m = m u / (1 - m u)``, ``u = 2^-24``) of the
float32 code against exact arithmetic: coefficient rounding, input rounding and each step's
rounding are propagated through the exact recursion (``|Cd Ad^j|``), the duty's error interval
through the monotone ``asin``; the bound is doubled to cover second-order terms and libm's
``asinf`` (<= 2 ulp assumed).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from string import Template

import numpy as np

from .envelope import steady_state
from .inverse_controller import InverseModelController, LowPassFilter
from .params import TABLE_I, LinkParams, warn_off_resonance
from .sbar import duty_from_v2_clipped

__all__ = ["ControllerSpec", "controller_spec", "generate_c", "count_ops", "python_duties", "float32_duty_bound",
           "test_vectors", "write_export", "PRECISIONS", "F64_TOLERANCE", "MAX_VECTORS", "check_vector_count"]

#: variant name -> (C type, literal suffix, asin, sqrt)
PRECISIONS = {"f32": ("float", "f", "asinf", "sqrtf"), "f64": ("double", "", "asin", "sqrt")}
F64_TOLERANCE = 1e-9   # |duty_C - duty_Python| for the double variant
_U32 = 2.0 ** -24      # unit roundoff of IEEE single


@dataclass(frozen=True)
class ControllerSpec:
    """Everything the C controller bakes in (SI units). ``ad (k, k), bd, cd, xss (k,)``: the
    discrete ``H = Q G22^-1`` of the Python controller; ``i2_sm_a`` the short-mode I2 of the assumed
    model; ``wlm_v1, det, r1_ohm`` the assumed link's constants of ``target_v2``."""

    params: LinkParams
    lpf: LowPassFilter
    control_period_s: float
    ad: np.ndarray
    bd: np.ndarray
    cd: np.ndarray
    dd: float
    xss: np.ndarray
    i2_sm_a: float
    wlm_v1: float
    det: float
    r1_ohm: float

    @property
    def nx(self) -> int:
        return len(self.bd)

    def controller(self) -> InverseModelController:
        """A fresh Python controller with the same model (the reference the C is checked against)."""
        return InverseModelController(self.params, self.control_period_s, self.lpf, n=1)


def controller_spec(params: LinkParams = TABLE_I, control_period_s: float | None = None,
                    lpf: LowPassFilter = LowPassFilter()) -> ControllerSpec:
    """The numbers of the Python controller for ``params`` at ``control_period_s`` (default: the
    rectifier period T = 1/(2f), one duty per half cycle as in the paper); warns an ``f_hz`` far off the coils'
    resonance (:func:`wpt_receiver.params.warn_off_resonance`)."""
    warn_off_resonance(params)
    ctl = InverseModelController(params, control_period_s, lpf, n=1)
    ad, bd, cd, dd = ctl.discrete_ss
    wlm = params.omega_rad_s * params.lm_h   # policies.classical._link_constants, same expression order
    return ControllerSpec(params, lpf, ctl.control_period_s, ad.copy(), bd.copy(), np.asarray(cd, float).copy(),
                          float(dd), ctl._xss.copy(), float(ctl.i2_sm_a), wlm * params.v1_amp_v,
                          params.r1_ohm * params.r2_ohm + wlm**2, params.r1_ohm)


# ============================================================================ C text
_HEADER = Template("""\
/* $banner */
#ifndef ${PU}_H
#define ${PU}_H

typedef $REAL ${P}_real;
#define ${PU}_NX $NX  /* states of H = Q G22^-1: filter order $ORDER + 1 */

/* Parameters: the discrete H = Q(s) G22^-1(s) (ZOH at the control period) and the assumed link. */
typedef struct {
    ${P}_real ad[${PU}_NX][${PU}_NX]; /* x+ = Ad x + Bd u, u = I2ref - I2_sm */
    ${P}_real bd[${PU}_NX];
    ${P}_real cd[${PU}_NX];          /* V2* = Cd x + Dd u [V] */
    ${P}_real dd;
    ${P}_real xss[${PU}_NX];         /* steady state per unit input: x = u xss (reset) */
    ${P}_real i2_sm_a;               /* short-mode I2 of the assumed model [A] */
    ${P}_real wlm_v1;                /* omega Lm V1 [V ohm] (as in target_v2) */
    ${P}_real wlm_v1_sq;             /* wlm_v1^2 [V^2 ohm^2] */
    ${P}_real det_ohm2;              /* R1 R2 + (omega Lm)^2 [ohm^2] */
    ${P}_real r1_ohm;                /* R1 [ohm] */
    ${P}_real control_period_s;      /* the period Ad, Bd were discretised at [s] (information) */
} ${P}_params;

typedef struct { ${P}_real x[${PU}_NX]; } ${P}_state;

/* $defaults */
extern const ${P}_params ${P}_default_params;

/* Start at the steady state of i2_ref_a (call once before the first step, or on a new window). */
void ${P}_reset(const ${P}_params *p, ${P}_state *s, ${P}_real i2_ref_a);
/* One control period: I2ref [A] in, V2* [V] out (before saturation); updates the state. */
${P}_real ${P}_v2_cmd(const ${P}_params *p, ${P}_state *s, ${P}_real i2_ref_a);
/* Inverse of eq. 9 with clamps: d = (2/pi) asin(clamp(1 - V2 / ((4/pi) VL), 0, 1)); NaN gives 0. */
${P}_real ${P}_duty_from_v2(${P}_real v2_v, ${P}_real vl_v);
/* One control period: I2ref [A] and measured VL [V] in, short duty d_short* [-] out. */
${P}_real ${P}_step(const ${P}_params *p, ${P}_state *s, ${P}_real i2_ref_a, ${P}_real vl_v);
/* I2ref [A] for a charge command I_L* [A] at VL [V] (the assumed steady I2 of the target V2). */
${P}_real ${P}_i2_ref_from_command(const ${P}_params *p, ${P}_real charge_cmd_a, ${P}_real vl_v);

#endif
""")

_SOURCE = Template("""\
/* $banner */
#include <math.h>
#include "$HNAME"

/* duty_from_v2's clamps send a NaN V2* to d = 0 by IEEE comparisons; -ffast-math / -ffinite-math-only let the
   compiler assume no NaN (gcc 12 -O2 -ffast-math then gives d = 1). Define DWPT_ALLOW_FAST_MATH to build anyway. */
#if (defined(__FAST_MATH__) || (defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__)) && !defined(DWPT_ALLOW_FAST_MATH)
#error "compile without -ffast-math / -ffinite-math-only (a NaN V2* must give d = 0), or define DWPT_ALLOW_FAST_MATH"
#endif

#define ${PU}_FOUR_OVER_PI $FOUR_OVER_PI$F
#define ${PU}_TWO_OVER_PI $TWO_OVER_PI$F

const ${P}_params ${P}_default_params = {
$INIT
};

void ${P}_reset(const ${P}_params *p, ${P}_state *s, ${P}_real i2_ref_a)
{
    const ${P}_real u = i2_ref_a - p->i2_sm_a;
$RESET
}

${P}_real ${P}_v2_cmd(const ${P}_params *p, ${P}_state *s, ${P}_real i2_ref_a)
{
    const ${P}_real u = i2_ref_a - p->i2_sm_a;
    const ${P}_real v2 = $V2EXPR;
$XNEW
$XSTORE
    return v2;
}

${P}_real ${P}_duty_from_v2(${P}_real v2_v, ${P}_real vl_v)
{
    ${P}_real s = 1.0$F - v2_v / (${PU}_FOUR_OVER_PI * vl_v);
    if (!(s > 0.0$F)) s = 0.0$F;
    if (s > 1.0$F) s = 1.0$F;
    return ${PU}_TWO_OVER_PI * $ASIN(s);
}

${P}_real ${P}_step(const ${P}_params *p, ${P}_state *s, ${P}_real i2_ref_a, ${P}_real vl_v)
{
    return ${P}_duty_from_v2(${P}_v2_cmd(p, s, i2_ref_a), vl_v);
}

${P}_real ${P}_i2_ref_from_command(const ${P}_params *p, ${P}_real charge_cmd_a, ${P}_real vl_v)
{
    const ${P}_real il = charge_cmd_a > 0.0$F ? charge_cmd_a : 0.0$F;
    ${P}_real disc = p->wlm_v1_sq - 8.0$F * p->r1_ohm * vl_v * il * p->det_ohm2;
    ${P}_real v2;
    if (!(disc > 0.0$F)) disc = 0.0$F;
    v2 = (p->wlm_v1 - $SQRT(disc)) / (2.0$F * p->r1_ohm);
    if (!(v2 > 0.0$F)) v2 = 0.0$F;
    if (v2 > ${PU}_FOUR_OVER_PI * vl_v) v2 = ${PU}_FOUR_OVER_PI * vl_v;
    return (p->wlm_v1 - p->r1_ohm * v2) / p->det_ohm2;
}
""")


def _lit(v: float, suffix: str) -> str:
    """C literal of ``v`` (shortest repr that round-trips the double; the compiler rounds it to
    float for the float variant)."""
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"coefficient {v!r} is not finite; valid: finite numbers")
    return f"{v!r}{suffix}"


def _initialiser(spec: ControllerSpec, sfx: str) -> str:
    vec = lambda a: "{" + ", ".join(_lit(x, sfx) for x in a) + "}"  # noqa: E731
    items = [("ad", "{" + ", ".join(vec(r) for r in spec.ad) + "}"), ("bd", vec(spec.bd)), ("cd", vec(spec.cd)),
             ("dd", _lit(spec.dd, sfx)), ("xss", vec(spec.xss)), ("i2_sm_a", _lit(spec.i2_sm_a, sfx)),
             ("wlm_v1", _lit(spec.wlm_v1, sfx)), ("wlm_v1_sq", _lit(spec.wlm_v1**2, sfx)),
             ("det_ohm2", _lit(spec.det, sfx)), ("r1_ohm", _lit(spec.r1_ohm, sfx)),
             ("control_period_s", _lit(spec.control_period_s, sfx))]
    return ",\n".join(f"    {val} /* {name} */" for name, val in items)


def _recursion(spec: ControllerSpec, real: str) -> dict:  # real: the C typedef name
    """The unrolled statements of the state update (same operation order as the Python controller:
    ``x @ Cd + Dd u`` and ``x @ Ad.T + u Bd``)."""
    n = spec.nx
    v2 = " + ".join([f"p->cd[{j}] * s->x[{j}]" for j in range(n)] + ["p->dd * u"])
    xnew = "\n".join(f"    const {real} x{i} = " + " + ".join([f"p->ad[{i}][{j}] * s->x[{j}]" for j in range(n)]
                                                                 + [f"p->bd[{i}] * u"]) + ";" for i in range(n))
    store = "\n".join(f"    s->x[{i}] = x{i};" for i in range(n))
    reset = "\n".join(f"    s->x[{i}] = u * p->xss[{i}];" for i in range(n))
    return {"V2EXPR": v2, "XNEW": xnew, "XSTORE": store, "RESET": reset}


def generate_c(spec: ControllerSpec, precision: str = "f64") -> tuple[str, str, str]:
    """``(basename, header_text, source_text)`` of the controller in ``precision`` ('f32' or 'f64');
    functions and types are prefixed ``dwpt_<precision>_``, files ``dwpt_ctl_<precision>.{h,c}``."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision={precision!r} is invalid; valid values: {', '.join(PRECISIONS)}")
    real, sfx, asin, sqrt = PRECISIONS[precision]
    p = f"dwpt_{precision}"
    base = f"dwpt_ctl_{precision}"
    lp = spec.params
    banner = (f"dronewpt: the paper's model-based SBAR controller (Fig. 5), {real}, generated by "
              f"wpt_receiver.c_export. Control period {spec.control_period_s!r} s, Q = 1/({spec.lpf.tau_s!r} s + 1)^"
              f"{spec.lpf.order}, link L1={lp.l1_h!r} L2={lp.l2_h!r} Lm={lp.lm_h!r} H, R1={lp.r1_ohm!r} "
              f"R2={lp.r2_ohm!r} ohm, Vdc={lp.vdc_v!r} VL={lp.vl_v!r} V, f={lp.f_hz!r} Hz. C99, needs only <math.h>.")
    defaults = "Defaults baked from the parameters in the banner (paper Table I unless changed)."
    sub = dict(banner=banner, P=p, PU=p.upper(), REAL=real, NX=spec.nx, ORDER=spec.lpf.order, F=sfx, ASIN=asin,
               SQRT=sqrt, HNAME=f"{base}.h", defaults=defaults, FOUR_OVER_PI=repr(4.0 / np.pi),
               TWO_OVER_PI=repr(2.0 / np.pi), INIT=_initialiser(spec, sfx), **_recursion(spec, f"{p}_real"))
    return base, _HEADER.substitute(sub), _SOURCE.substitute(sub)


# ============================================================================ operation count
_OPS = {"add": r"(?<![+\-=!<>])[+\-](?![+\-=>])", "mul": r"\*", "div": r"/", "cmp": r"[<>]",
        "sqrt": r"\bsqrtf?\(", "asin": r"\basinf?\("}


def _function_body(source: str, name: str) -> str:
    m = re.search(r"\b" + re.escape(name) + r"\([^)]*\)\s*\{", source)
    if m is None:
        raise ValueError(f"function {name!r} is not in the source")
    depth, i = 1, m.end()
    while depth:
        depth += {"{": 1, "}": -1}.get(source[i], 0)
        i += 1
    return source[m.end():i - 1]


def count_ops(source: str, functions) -> dict:
    """Floating-point operations in the bodies of ``functions`` of generated C ``source``, read off
    the text: adds (+, -), multiplies, divides, comparisons (clamps), sqrt and asin calls. The
    generated code is straight-line (unrolled), so each operator in the text runs once per call;
    calls to other listed functions are not expanded (list them all)."""
    total = dict.fromkeys(_OPS, 0)
    for fn in functions:
        body = _function_body(source, fn)
        body = re.sub(r"/\*.*?\*/", " ", body, flags=re.S)
        body = re.sub(r"\b\d+\.?\d*(?:[eE][+-]?\d+)?[fF]?\b", "0", body)   # literals (exponent signs)
        body = body.replace("->", ".")
        body = re.sub(r"\b\w+_real\b", "", body)                        # type names
        body = re.sub(r"\bconst\s+\w*\s*\*", "", body)
        for op, pat in _OPS.items():
            total[op] += len(re.findall(pat, body))
    return total


# ============================================================================ the Python reference
def python_duties(spec: ControllerSpec, kind: str, inputs, vl_v) -> np.ndarray:
    """Duties of the Python controller: ``kind='ctl'``: ``inputs`` is I2ref [A], the controller is
    reset at ``inputs[0]`` and stepped (``update1`` then ``duty_from_v2_clipped`` with ``vl_v``, as
    ``ModelBasedPolicy`` does); ``kind='finv'``: ``inputs`` is V2* [V] through f^-1 alone."""
    x = np.asarray(inputs, dtype=float)
    vl = np.broadcast_to(np.asarray(vl_v, dtype=float), x.shape)
    if kind == "finv":
        return np.array([duty_from_v2_clipped(float(a), float(b)) for a, b in zip(x, vl)])
    if kind != "ctl":
        raise ValueError(f"kind={kind!r} is invalid; valid values: 'ctl', 'finv'")
    ctl = spec.controller()
    ctl.reset(float(x[0]))
    return np.array([duty_from_v2_clipped(ctl.update1(float(a)), float(b)) for a, b in zip(x, vl)])


#: above this many control steps per case the error bound's convolutions go by FFT (np.convolve is direct,
#: O(n^2): 17.6 s at 16,000 steps, ~30 min a case at --control-period 1e-7's 160,000, uninterruptible)
_FFT_MIN_STEPS = 8192


def _positive_convolution(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.convolve(a, b)`` of two non-negative sequences; above :data:`_FFT_MIN_STEPS` by FFT plus a margin for
    the FFT's rounding, ``8 eps log2(N) |a|_2 |b|_2`` (the usual size of that rounding, not a proven bound; it is
    many orders below the float32 bound it feeds)."""
    if max(len(a), len(b)) <= _FFT_MIN_STEPS:
        return np.convolve(a, b)
    m = len(a) + len(b) - 1
    nfft = 1 << (m - 1).bit_length()
    out = np.fft.irfft(np.fft.rfft(a, nfft) * np.fft.rfft(b, nfft), nfft)[:m]
    return np.maximum(out, 0.0) + 8 * np.finfo(float).eps * math.log2(nfft) * np.linalg.norm(a) * np.linalg.norm(b)


def _v2_error_bound(spec: ControllerSpec, i2_ref) -> tuple[np.ndarray, np.ndarray]:
    """``(v2_exact, |error of V2*| bound)`` of the float32 recursion, first order (module docstring)."""
    r = np.asarray(i2_ref, dtype=float)
    ad, bd, cd, dd, xss, ism, n = spec.ad, spec.bd, spec.cd, spec.dd, spec.xss, spec.i2_sm_a, spec.nx
    g = (n + 2) * _U32 / (1 - (n + 2) * _U32)           # n + 1 products, coefficients rounded
    u = r - ism
    du = _U32 * (np.abs(r) + abs(ism) + np.abs(u))     # input, I2_sm and the subtraction rounded
    x = np.empty((len(r), n))
    x[0] = u[0] * xss
    for k in range(len(r) - 1):
        x[k + 1] = ad @ x[k] + bd * u[k]
    v2 = x @ cd + dd * u
    rho = g * (np.abs(x) @ np.abs(ad).T + np.abs(u)[:, None] * np.abs(bd)) + du[:, None] * np.abs(bd)
    h = np.empty((len(r), n))                          # |Cd Ad^j|
    row = cd.copy()
    for j in range(len(r)):
        h[j] = np.abs(row)
        row = row @ ad
    e0 = np.abs(xss) * du[0] + 2 * _U32 * np.abs(xss * u[0])
    prop = np.zeros(len(r))
    for i in range(n):
        prop[1:] += _positive_convolution(rho[:-1, i], h[:, i])[:len(r) - 1]
    prop += h @ e0
    return v2, prop + abs(dd) * du + g * (np.abs(x) @ np.abs(cd) + abs(dd) * np.abs(u))


def float32_duty_bound(spec: ControllerSpec, kind: str, inputs, vl_v) -> np.ndarray:
    """Bound on ``|duty_float32 - duty_exact|`` per control step (module docstring), for the inputs of
    :func:`python_duties`. Doubled first-order bound."""
    x = np.asarray(inputs, dtype=float)
    vl = np.broadcast_to(np.asarray(vl_v, dtype=float), x.shape)
    if kind == "ctl":
        v2, dv2 = _v2_error_bound(spec, x)
    else:
        v2, dv2 = x, _U32 * np.abs(x)
    vmax = 4.0 / np.pi * vl
    q = v2 / vmax
    s = 1.0 - q
    ds = dv2 / vmax + 4 * _U32 * np.abs(q) + _U32 * np.abs(s)
    asin = lambda z: np.arcsin(np.clip(z, 0.0, 1.0))  # noqa: E731
    d = asin(s)
    dd = np.maximum(asin(s + ds) - d, d - asin(s - ds))
    return 2.0 * ((2.0 / np.pi) * dd + 8 * _U32 * (2.0 / np.pi) * d)


# ============================================================================ test vectors and files
#: most test vectors of the paper's cases (16 ms at the rectifier period of 85 kHz: 16,320; 1 MHz: 192,000 in 14 s and a
#: 14 MB header; 27.12 MHz's 5.2 million ran for more than 5 min towards a ~380 MB header)
MAX_VECTORS = 200_000


def check_vector_count(spec: ControllerSpec, t_end_s: float = 16e-3) -> None:
    """Refuse a control period that would make more than :data:`MAX_VECTORS` test vectors of the paper's six cases
    (one per control period over ``t_end_s``), naming the shortest period that fits."""
    n = 6 * int(round(t_end_s / spec.control_period_s))
    if n > MAX_VECTORS:
        raise ValueError(f"control_period_s={spec.control_period_s:.4g} gives {n:,} test vectors (6 cases of "
                         f"{t_end_s * 1e3:g} ms, one per control period); valid: at most {MAX_VECTORS:,}, i.e. "
                         f"control_period_s >= {6 * t_end_s / MAX_VECTORS:.3g} s (--control-period)")


def test_vectors(spec: ControllerSpec, t_switch_s: float = 1e-3, t_end_s: float = 16e-3, extra=(), paper: bool = True):
    """Test vectors: the paper's three trajectories on the spec's control period, each as f^-1
    alone (``<name>_finv``: V2* in) and as the whole controller (``<name>_ctl``: I2ref in, the
    steady I2 of the trajectory's V2*; for ``proposed`` the paper's I2ref step), plus ``extra``
    cases ``(name, kind, inputs, vl_v)`` (``paper=False``: those alone). A DataFrame: ``case, kind, k, input, vl_v, duty`` (Python,
    float64) and ``duty_tol_f32`` (:func:`float32_duty_bound`)."""
    import pandas as pd

    from .references import reference_duty

    p = spec.params
    if paper:
        check_vector_count(spec, t_end_s)
    cases = []
    for name in ("step", "ramp", "proposed") if paper else ():
        t, _, v2 = reference_duty(name, p, t_switch_s, t_end_s, spec.control_period_s, spec.lpf)
        cases.append((f"{name}_finv", "finv", np.asarray(v2, float), p.vl_v))
        if name == "proposed":
            i2rm, i2sm = steady_state(p, p.v2_rm_amp_v)[1], steady_state(p, 0.0)[1]
            ref = np.where(t >= t_switch_s - 1e-12, i2sm, i2rm)
        else:
            ref = np.asarray(steady_state(p, np.asarray(v2, float))[1], float)
        cases.append((f"{name}_ctl", "ctl", ref, p.vl_v))
    frames = []
    for name, kind, inputs, vl in [*cases, *extra]:
        inputs = np.asarray(inputs, float)
        vl = np.broadcast_to(np.asarray(vl, float), inputs.shape).astype(float)
        frames.append(pd.DataFrame({"case": name, "kind": kind, "k": np.arange(len(inputs)), "input": inputs,
                                    "vl_v": vl, "duty": python_duties(spec, kind, inputs, vl),
                                    "duty_tol_f32": float32_duty_bound(spec, kind, inputs, vl)}))
    return pd.concat(frames, ignore_index=True)


_SELFTEST = Template("""\
/* Self-test of $BASE against the Python controller's duties (dwpt_vectors.h, generated with it).
 * Build: cc -Wall -Werror -std=c99 -O2 -o selftest_$PREC selftest_$PREC.c $BASE.c -lm
 * Run:   ./selftest_$PREC [print]  (exit 0 when every duty is within its tolerance: $TOLTEXT;
 *        with an argument, prints each duty with 17 digits) */
#include <math.h>
#include <stdio.h>
#include "$BASE.h"
#include "dwpt_vectors.h"

int main(int argc, char **argv)
{
    ${P}_state st;
    double max_err = 0.0, max_ratio = 0.0;
    long i, beyond = 0;
    (void)argv;
    for (i = 0; i < DWPT_NV; ++i) {
        ${P}_real d;
        double err, tol;
        if (dwpt_v_kind[i]) {
            if (dwpt_v_k[i] == 0)
                ${P}_reset(&${P}_default_params, &st, (${P}_real)dwpt_v_input[i]);
            d = ${P}_step(&${P}_default_params, &st, (${P}_real)dwpt_v_input[i], (${P}_real)dwpt_v_vl[i]);
        } else {
            d = ${P}_duty_from_v2((${P}_real)dwpt_v_input[i], (${P}_real)dwpt_v_vl[i]);
        }
        err = fabs((double)d - dwpt_v_duty[i]);
        tol = $TOL;
        if (err > max_err) max_err = err;
        if (err / tol > max_ratio) max_ratio = err / tol;
        if (!(err <= tol)) ++beyond;
        if (argc > 1) printf("%.17g\\n", (double)d);
    }
    fprintf(stderr, "$BASE: %d duties, max |C - Python| %.3g, max error/tolerance %.3g, %ld beyond\\n",
            DWPT_NV, max_err, max_ratio, beyond);
    return beyond ? 1 : 0;
}
""")


def vectors_header(vectors) -> str:
    """``dwpt_vectors.h``: the test vectors as static C arrays (doubles with 17 digits)."""
    names = list(dict.fromkeys(vectors["case"]))
    arr = lambda ctype, name, vals, fmt: (f"static const {ctype} {name}[DWPT_NV] = {{\n"  # noqa: E731
                                          + ",\n".join(fmt(v) for v in vals) + "\n};\n")
    g = lambda v: f"{float(v)!r}"  # noqa: E731
    return "".join([
        "/* dronewpt controller test vectors (wpt_receiver.c_export): per row the case, the kind (1 = whole\n"
        " * controller, I2ref [A] in, reset at k = 0; 0 = f^-1 alone, V2* [V] in), the step k, the input,\n"
        " * VL [V], the Python duty (float64) and the float32 tolerance. Cases: " + ", ".join(names) + " */\n",
        "#ifndef DWPT_VECTORS_H\n#define DWPT_VECTORS_H\n",
        f"#define DWPT_NV {len(vectors)}\n",
        arr("int", "dwpt_v_case", [names.index(c) for c in vectors["case"]], str),
        arr("int", "dwpt_v_kind", [int(k == "ctl") for k in vectors["kind"]], str),
        arr("long", "dwpt_v_k", vectors["k"], lambda v: str(int(v))),
        arr("double", "dwpt_v_input", vectors["input"], g), arr("double", "dwpt_v_vl", vectors["vl_v"], g),
        arr("double", "dwpt_v_duty", vectors["duty"], g), arr("double", "dwpt_v_tol_f32", vectors["duty_tol_f32"], g),
        "#endif\n"])


def _write_text(path: Path, text: str) -> None:
    """Write under a temporary name in the same folder, then rename (never a truncated file)."""
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


#: the functions one control step runs (I2ref, VL -> duty) and the command front end
STEP_FUNCTIONS = ("v2_cmd", "duty_from_v2", "step")
COMMAND_FUNCTIONS = ("i2_ref_from_command",)


def write_export(out_dir, spec: ControllerSpec, precisions=("f32", "f64"), vectors=None) -> dict:
    """Write the controller C (header + source per precision), ``selftest_<p>.c``, ``dwpt_vectors.h``
    and ``dwpt_vectors.csv`` into ``out_dir`` (created). Returns ``{"files": [...], "ops": {precision:
    {"step": counts, "command": counts}}}`` (:func:`count_ops`)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    vectors = test_vectors(spec) if vectors is None else vectors
    files, ops = [], {}
    for prec in precisions:
        base, h, c = generate_c(spec, prec)
        pre = f"dwpt_{prec}_"
        ops[prec] = {"step": count_ops(c, [pre + f for f in STEP_FUNCTIONS]),
                     "command": count_ops(c, [pre + f for f in COMMAND_FUNCTIONS])}
        tol, toltext = (("dwpt_v_tol_f32[i]", "the per-row derived float32 bound") if prec == "f32"
                        else (repr(F64_TOLERANCE), f"{F64_TOLERANCE:g}"))
        st = _SELFTEST.substitute(BASE=base, PREC=prec, P=f"dwpt_{prec}", TOL=tol, TOLTEXT=toltext)
        for name, text in ((f"{base}.h", h), (f"{base}.c", c), (f"selftest_{prec}.c", st)):
            _write_text(out / name, text)
            files.append(out / name)
    _write_text(out / "dwpt_vectors.h", vectors_header(vectors))
    _write_text(out / "dwpt_vectors.csv", vectors.to_csv(index=False, float_format="%.17g"))
    files += [out / "dwpt_vectors.h", out / "dwpt_vectors.csv"]
    return {"files": files, "ops": ops}


#: compiler flags of :func:`build_selftest` (the issue's, plus warnings a DSP port cares about)
CFLAGS = ("-Wall", "-Wextra", "-Wpedantic", "-Wdouble-promotion", "-Wfloat-conversion", "-Werror", "-std=c99", "-O2")


def build_selftest(out_dir, precision: str, cc: str = "cc", cflags=CFLAGS) -> Path:
    """Compile ``selftest_<precision>.c`` + the controller in ``out_dir`` with the system C compiler
    (``cc cflags -o selftest_<p> ... -lm``); returns the executable. ``subprocess.CalledProcessError``
    (with the compiler's output) when it does not compile warning-free."""
    import shutil
    import subprocess

    out = Path(out_dir)
    exe = shutil.which(cc)
    if exe is None:
        raise FileNotFoundError(f"C compiler {cc!r} not found; install one (e.g. gcc) or pass another --cc")
    prog = out / f"selftest_{precision}"
    subprocess.run([exe, *cflags, "-o", str(prog), str(out / f"selftest_{precision}.c"),
                    str(out / f"dwpt_ctl_{precision}.c"), "-lm"], check=True, capture_output=True, text=True)
    return prog


def run_selftest(prog) -> tuple[int, np.ndarray, str]:
    """Run a built self-test with printing on: ``(exit status, duties, its summary line)``."""
    import subprocess

    r = subprocess.run([str(prog), "print"], capture_output=True, text=True, timeout=120)
    return r.returncode, np.array([float(x) for x in r.stdout.split()]), r.stderr.strip()


#: assumed cycle costs on a 200 MHz single-precision DSP core (C2000 FPU32 class): pipelined add,
#: multiply and compare 1, divide 10 (reciprocal estimate + Newton steps), sqrt 10, asin 60 (a
#: libm-style polynomial); an estimate for the budget, not a measurement on a DSP
ASSUMED_DSP_HZ = 200e6
ASSUMED_CYCLES = {"add": 1, "mul": 1, "cmp": 1, "div": 10, "sqrt": 10, "asin": 60}


def budget(spec: ControllerSpec, step_ops: dict) -> dict:
    """Operations of one control step against the time one control period gives: the paper updates
    ``d_short`` once per rectifier period ``T = 1/(2f)`` (5.88 us at 85 kHz, its per-half-cycle
    budget; the paper names no DSP model or clock, so the cycles are at :data:`ASSUMED_DSP_HZ` with
    :data:`ASSUMED_CYCLES`)."""
    n = sum(step_ops.values())
    cycles = sum(ASSUMED_CYCLES[k] * v for k, v in step_ops.items())
    avail = spec.control_period_s * ASSUMED_DSP_HZ
    half = spec.params.rectifier_period_s
    text = (f"{n} operations per step ({_plain(step_ops)}); control period {spec.control_period_s * 1e6:.3g} us "
            f"(half cycle T = {half * 1e6:.3g} us); at an assumed {ASSUMED_DSP_HZ / 1e6:.0f} MHz DSP "
            f"{avail:.0f} cycles per period, the step ~{cycles} cycles ({100 * cycles / avail:.1f} %)")
    return {"ops": n, "cycles_estimate": cycles, "cycles_available": avail, "fraction": cycles / avail,
            "control_period_s": spec.control_period_s, "half_cycle_s": half, "text": text}


def _plain(ops: dict) -> str:
    return ", ".join(f"{v} {k}" for k, v in ops.items() if v)
