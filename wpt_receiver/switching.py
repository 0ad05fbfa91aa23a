"""Switching-level (instantaneous) simulation of the link and the SBAR, event-exact.

The circuit (eq. 1, see :mod:`.switching_circuit`) is linear in each topology, so between
switching events the solution is a matrix exponential: every topology is diagonalised once and
the state is advanced *exactly* over any duration in modal coordinates. Events:

* scheduled: inverter commutations at ``k T`` (optional dead time), and the SBAR gate edges.
  The gate comes from the controller's own clock: the short window of rectifier period ``n`` is
  centred at ``n T + gate_phase_rad / omega`` and lasts ``d_short[n] T`` (``T`` = half the
  inverter period). Phase 0 centres it on the peak of the i2 fundamental (``i2 ~ cos wt``), the
  place eq. 9 assumes; :func:`sbar_relation` can instead centre it on the actual half-cycle.
* state events: diode commutations at the zero crossings of i2 (i1 in dead time) and the end of
  a blocked interval (open-circuit voltage reaching the DC voltage). They are located on a
  coarse grid of the exact solution (precomputed exponentials per topology) and refined by a
  safeguarded Newton iteration on the exact solution.

Outputs are exact dense samples (a pandas DataFrame), the per-half-cycle envelope (peak of |i1|
and |i2| in each half cycle, fundamental of i2 and v2, mean battery current) and closed-form
energy integrals. :func:`simulate_ivp`
integrates the same circuit with ``scipy.integrate.solve_ivp`` as a slow reference.

Importing this module registers ``MODELS["switching"]`` in :mod:`wpt_receiver.paper`.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pandas as pd

from .envelope import steady_state
from .params import LinkParams
from .switching_circuit import I1, I2, P_OPEN, S_OPEN, S_SHORT, VC1, VC2, Circuit, SwitchingConfig

__all__ = ["SwitchingConfig", "Circuit", "Schedule", "SwitchingResult", "SwitchingLink", "make_schedule",
           "simulate_ivp", "switching_plant", "fundamental", "sbar_relation"]

_GRID = 16           # guard sampling points per rectifier period T (root bracketing)


# ============================================================================ schedule
@dataclass(frozen=True)
class Schedule:
    """Piecewise-constant drive: interval ``j`` is ``[t[j], t[j+1])`` with inverter command
    ``cmd[j]`` (+1, -1, or 0 = dead time) and SBAR gate ``gate[j]`` (1 = lower switches on)."""

    t: np.ndarray
    cmd: np.ndarray
    gate: np.ndarray

    def gate_at(self, ts):
        j = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, len(self.gate) - 1)
        return self.gate[j]


def make_schedule(t0_s: float, t_end_s: float, T: float, d_window, phase_rad: float, dead_time_s: float = 0.0,
                  omega: float | None = None) -> Schedule:
    """Build the drive schedule on ``[t0_s, t_end_s]``.

    ``d_window(n)`` gives the short duty of the window centred at ``n T + phase/omega`` (n may be
    negative or past the end: callers clip). Windows of duty 1 touch their neighbours: the gate
    then stays on.
    """
    omega = math.pi / T if omega is None else omega
    off = phase_rad / omega
    n_lo = int(math.floor((t0_s - off) / T)) - 1
    n_hi = int(math.ceil((t_end_s - off) / T)) + 1
    n = np.arange(n_lo, n_hi + 1)
    d = np.clip(np.asarray(d_window(n), dtype=float), 0.0, 1.0)
    c = n * T + off
    k = np.arange(int(math.floor(t0_s / T)), int(math.ceil(t_end_s / T)) + 1)
    edges = np.concatenate([c - 0.5 * d * T, c + 0.5 * d * T, k * T, k * T + dead_time_s, [t0_s, t_end_s]])
    edges = np.unique(edges[(edges >= t0_s) & (edges <= t_end_s)])
    # edges closer than 1e-9 T (6 fs at 85 kHz) are one edge: adjacent d = 1 windows then touch
    # exactly instead of leaving round-off gaps of ~1e-19 s
    edges = edges[np.concatenate([[True], np.diff(edges) > 1e-9 * T])]
    edges[-1] = t_end_s
    mid = 0.5 * (edges[:-1] + edges[1:])
    kk = np.floor(mid / T)
    cmd = np.where(mid - kk * T < dead_time_s, 0, np.where(kk % 2 == 0, 1, -1)).astype(int)
    nn = np.round((mid - off) / T).astype(int)
    dn = np.clip(np.asarray(d_window(nn), dtype=float), 0.0, 1.0)
    gate = (np.abs(mid - (nn * T + off)) < 0.5 * dn * T).astype(int)
    # merge intervals with identical drive
    keep = np.concatenate([[True], (np.diff(cmd) != 0) | (np.diff(gate) != 0)])
    return Schedule(np.append(edges[:-1][keep], t_end_s), cmd[keep], gate[keep])


def duty_windows(d_short, control_period_s: float, T: float, phase_rad: float, omega: float):
    """Map a duty per control period to a duty per gate window (window n -> control period of
    its centre ``n T + phase/omega``; before 0 the first duty, after the end the last)."""
    d = np.asarray(d_short, dtype=float)
    off = phase_rad / omega

    def fn(n):
        j = np.floor((np.asarray(n) * T + off) / control_period_s + 1e-9).astype(int)
        return d[np.clip(j, 0, len(d) - 1)]
    return fn


# ============================================================================ result
@dataclass
class SwitchingResult:
    """Segments of an exact simulation plus helpers for dense output and exact integrals.

    ``seg_t`` (ns+1,) segment boundaries [s], ``seg_k`` (ns,) topology index, ``seg_z`` (ns, m)
    modal state at the start of each segment.
    """

    circuit: Circuit
    schedule: Schedule
    seg_t: np.ndarray
    seg_k: np.ndarray
    seg_z: np.ndarray

    @property
    def t0(self) -> float:
        return float(self.seg_t[0])

    @property
    def t_end(self) -> float:
        return float(self.seg_t[-1])

    def states(self, ts, cols=None, deriv: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Exact augmented states (or their ``deriv``-th time derivative) at times ``ts`` and the
        topology index there: ``(x (N, len(cols) or m), k (N,))``.

        Uses the conjugate symmetry of the modes of a real system: only one mode of each complex
        pair is evaluated (weight 2) and zero modes need no exponential."""
        ts = np.asarray(ts, dtype=float)
        j = np.clip(np.searchsorted(self.seg_t, ts, side="right") - 1, 0, len(self.seg_k) - 1)
        dt = ts - self.seg_t[j]
        k = self.seg_k[j]
        cir = self.circuit
        cols = np.arange(cir.m) if cols is None else np.atleast_1d(cols)
        x = np.empty((len(ts), len(cols)))
        for kk, sel in _groups(k, len(cir.keys)):
            keep, wgt, dyn = cir.half[kk]
            lam = cir.lam[kk][keep]
            z = self.seg_z[j[sel]][:, keep] * wgt
            z[:, dyn] *= np.exp(np.outer(dt[sel], lam[dyn]))
            if deriv:
                z *= lam**deriv
            # einsum, not @: a tall-skinny complex matmul goes to multithreaded BLAS, which is
            # 100x slower than this loop on a busy machine
            x[sel] = np.einsum("nm,cm->nc", z, cir.vec[kk][np.ix_(cols, keep)]).real
        return x, k

    def outputs(self, x, k) -> dict:
        """v1, v2 and battery current for states ``x`` in topologies ``k``."""
        out = {name: np.empty(len(k)) for name in ("v1", "v2", "i_load")}
        for kk, sel in _groups(k, len(self.circuit.keys)):
            for name, row in self.circuit.rows[kk].items():
                out[name][sel] = np.einsum("nm,m->n", x[sel], row)
        return out

    def frame(self, ts=None) -> pd.DataFrame:
        """Dense output: t_s, i1_a, vc1_v, i2_a, vc2_v, v1_v, v2_v, i_load_a, gate.

        ``ts`` defaults to ``samples_per_half_cycle`` samples per T over the whole run.
        """
        if ts is None:
            ts = self.sample_times()
        x, k = self.states(ts)
        o = self.outputs(x, k)
        return pd.DataFrame({"t_s": ts, "i1_a": x[:, I1], "vc1_v": x[:, VC1], "i2_a": x[:, I2], "vc2_v": x[:, VC2],
                             "v1_v": o["v1"], "v2_v": o["v2"], "i_load_a": o["i_load"],
                             "gate": self.schedule.gate_at(ts)})

    def sample_times(self, per_half_cycle: int | None = None) -> np.ndarray:
        n = per_half_cycle or self.circuit.cfg.samples_per_half_cycle
        h = self.circuit.T / n
        return self.t0 + np.arange(int(math.floor((self.t_end - self.t0) / h * (1 + 1e-12))) + 1) * h

    def linear_integrals(self, edges, forms, omegas) -> np.ndarray:
        """Exact ``int (r_k . x) exp(j omega t) dt`` over each ``[edges[i], edges[i+1]]``.

        ``forms``: callables ``k -> r`` (a row over the augmented state for topology ``k``);
        ``omegas``: one angular frequency per form [rad/s] (0 for a plain integral). Each piece of
        a segment contributes ``sum_a (r V)_a z_a (e^{lam_a u} e^{j w t})|_a^b / (lam_a + j w)``:
        closed form. The real part is the integral against cos, the imaginary part against sin.
        Returns a complex array (n_windows, n_forms)."""
        cir = self.circuit
        edges = np.asarray(edges, dtype=float)
        cuts = self.seg_t[(self.seg_t > edges[0]) & (self.seg_t < edges[-1])]
        pts = np.unique(np.concatenate([edges, cuts]))
        a, b = pts[:-1], pts[1:]
        mid = 0.5 * (a + b)
        j = np.clip(np.searchsorted(self.seg_t, mid, side="right") - 1, 0, len(self.seg_k) - 1)
        which = np.clip(np.searchsorted(edges, mid, side="right") - 1, 0, len(edges) - 2)
        k = self.seg_k[j]
        out = np.zeros((len(edges) - 1, len(forms)), dtype=complex)
        phases = {w: (np.exp(1j * w * a), np.exp(1j * w * b)) for w in set(omegas) if w != 0}
        for kk, sel in _groups(k, len(cir.keys)):
            lam, vec = cir.lam[kk], cir.vec[kk]
            js = j[sel]
            s0 = self.seg_t[js]
            e0 = np.exp(np.outer(a[sel] - s0, lam))
            e1 = np.exp(np.outer(b[sel] - s0, lam))
            z = self.seg_z[js]
            for i, (form, w) in enumerate(zip(forms, omegas)):
                mu = lam + 1j * w
                if w != 0:
                    num = e1 * phases[w][1][sel, None] - e0 * phases[w][0][sel, None]
                else:
                    num = e1 - e0
                with np.errstate(invalid="ignore", divide="ignore"):
                    phi = np.where(mu == 0, (b - a)[sel, None], num / np.where(mu == 0, 1.0, mu))
                vals = np.einsum("nm,nm,m->n", z, phi, form(kk) @ vec)
                np.add.at(out[:, i], which[sel], vals)
        return out

    def quadratic_integrals(self, t_a: float, t_b: float, forms) -> np.ndarray:
        """Exact integrals over ``[t_a, t_b]`` of products ``(r_k . x)(q_k . x)`` [unit*s].

        ``forms`` is a list of callables ``k -> (r, q)`` giving two rows over the augmented state
        for topology ``k``. With ``r.x = sum_a rho_a exp(lam_a t)`` in modal form, each segment
        contributes ``sum_ab rho_a kappa_b (exp((lam_a+lam_b) tau) - 1)/(lam_a+lam_b)``: closed
        form, no quadrature error whatever the stiffness of a topology."""
        cir = self.circuit
        j0 = max(0, int(np.searchsorted(self.seg_t, t_a, side="right")) - 1)
        j1 = min(len(self.seg_k), int(np.searchsorted(self.seg_t, t_b, side="left")))
        j = np.arange(j0, j1)
        s0 = np.maximum(self.seg_t[j], t_a)
        tau = np.minimum(self.seg_t[j + 1], t_b) - s0
        k = self.seg_k[j]
        out = np.zeros(len(forms))
        for kk in np.unique(k):
            sel = k == kk
            lam, vec = cir.lam[kk], cir.vec[kk]
            z = self.seg_z[j[sel]] * np.exp(np.outer(s0[sel] - self.seg_t[j[sel]], lam))
            mu = lam[:, None] + lam[None, :]
            mt = mu[None, :, :] * tau[sel][:, None, None]
            with np.errstate(invalid="ignore", divide="ignore"):
                phi = np.where(mu[None] == 0, tau[sel][:, None, None], np.expm1(mt) / mu[None])
            for i, form in enumerate(forms):
                r, q = form(kk)
                rho = (r @ vec)[None, :] * z
                kap = (q @ vec)[None, :] * z
                out[i] += np.einsum("pa,pb,pab->", rho, kap, phi).real
        return out

    def energy_balance(self, t_a: float, t_b: float) -> dict:
        """Energies over ``[t_a, t_b]`` [J], integrated in closed form: source (int v1 i1),
        resistive losses (R1 i1^2 + R2 i2^2 + r_bat i_load^2), battery (int VL i_load), energy into
        the rectifier (int v2 i2) and the change of stored energy; ``residual`` = source - losses -
        battery - stored change (zero for an exact, lossless-switch simulation)."""
        cir, P = self.circuit, self.circuit.p
        e = np.eye(cir.m)
        one = e[-1]
        rows = cir.rows
        forms = [lambda k: (rows[k]["v1"], e[I1]), lambda k: (e[I1], e[I1] * P.r1_ohm),
                 lambda k: (e[I2], e[I2] * P.r2_ohm), lambda k: (rows[k]["i_load"], rows[k]["i_load"] * cir.cfg.r_bat_ohm),
                 lambda k: (rows[k]["i_load"], one * P.vl_v), lambda k: (rows[k]["v2"], e[I2]),
                 lambda k: (rows[k]["i_load"], one)]
        src, l1, l2, lb, bat, rect, charge = self.quadratic_integrals(t_a, t_b, forms)
        xs, _ = self.states([t_a, t_b])
        es = cir.stored_energy(xs)
        d_stored = float(es[1] - es[0])
        loss = l1 + l2 + lb
        return {"source_j": src, "losses_j": loss, "battery_j": bat, "stored_change_j": d_stored,
                "rectifier_in_j": rect, "charge_c": charge, "residual_j": src - loss - bat - d_stored}

    def envelope(self, t_a: float | None = None, t_b: float | None = None) -> pd.DataFrame:
        """Per-half-cycle envelope: peak |i2| in each window ``[(n-1/2)T, (n+1/2)T)`` around the
        nominal i2 peaks ``n T`` and peak |i1| in ``[nT, (n+1)T)``; plus the fundamental of v2
        over the i2 window (in-phase with cos(wt): ``v2_fund_v``; quadrature ``v2_quad_v``) and the
        fundamental amplitude of i2 over the same window (``i2_fund_a``, the envelope model's I2)
        and the battery current averaged over the window (``i_load_avg_a``), all integrated in
        closed form on the exact solution.

        Peaks: the largest dense sample per window, refined by a parabola through its neighbours
        and then by Newton on di/dt = 0 with the exact solution (kept only if it does not lower
        the value, e.g. at a kink where a gate edge sits on the peak)."""
        cir = self.circuit
        T, N = cir.T, cir.cfg.samples_per_half_cycle
        t_a = self.t0 if t_a is None else t_a
        t_b = self.t_end if t_b is None else t_b
        n_first = int(math.ceil((t_a - self.t0) / T - 1e-9 + 0.5))  # first window fully inside, i2 windows
        n_last = int(math.floor((t_b - self.t0) / T + 1e-9 - 0.5))
        h = T / N
        ts = self.t0 + np.arange(int(round((n_first - 0.5) * N)), int(round((n_last + 0.5) * N)) + 1) * h
        x, _ = self.states(ts, cols=[I1, I2])
        x = np.column_stack([x[:, 0], np.zeros(len(ts)), x[:, 1]])
        centres = self.t0 + np.arange(n_first, n_last + 1) * T
        t2, p2 = self._refine_peaks(*_window_peaks(ts, np.abs(x[:, I2]), N), I2)
        t1, p1 = self._refine_peaks(*_window_peaks(ts[N // 2:], np.abs(x[N // 2:, I1]), N), I1)
        w = cir.p.omega_rad_s
        rows, e2 = cir.rows, np.eye(cir.m)[I2]
        edges = np.append(centres - 0.5 * T, centres[-1] + 0.5 * T)
        f = self.linear_integrals(edges, [lambda k: rows[k]["v2"], lambda k: e2, lambda k: rows[k]["i_load"]],
                                  [w, w, 0.0]) / T
        f[:, :2] *= 2.0
        f = np.column_stack([f[:, 0].real, f[:, 0].imag, f[:, 1].real, f[:, 1].imag, f[:, 2].real])
        n1 = min(len(p1), len(p2))
        return pd.DataFrame({"t_s": centres, "i2_env_a": p2, "t_i2_peak_s": t2,
                             "i1_env_a": np.r_[p1[:n1], [np.nan] * (len(p2) - n1)],
                             "t_i1_peak_s": np.r_[t1[:n1], [np.nan] * (len(p2) - n1)],
                             "v2_fund_v": f[:, 0], "v2_quad_v": f[:, 1], "i2_fund_a": np.hypot(f[:, 2], f[:, 3]),
                             "i_load_avg_a": f[:, 4]})

    def _refine_peaks(self, tp, yp, col, iters: int = 2):
        """Newton on d|i|/dt = 0 with the exact solution from the sampled peaks; a step that
        leaves the sample neighbourhood or lowers the value (a kink at the peak) is rejected."""
        h = self.circuit.T / self.circuit.cfg.samples_per_half_cycle
        t = tp.copy()
        for _ in range(iters):
            d1, _ = self.states(t, cols=[col], deriv=1)
            d2, _ = self.states(t, cols=[col], deriv=2)
            with np.errstate(invalid="ignore", divide="ignore"):
                tn = t - d1[:, 0] / d2[:, 0]
            ok = np.isfinite(tn) & (np.abs(tn - tp) < h)
            t = np.where(ok, tn, t)
        v, _ = self.states(t, cols=[col])
        v = np.abs(v[:, 0])
        better = v >= yp * (1 - 1e-9)
        return np.where(better, t, tp), np.where(better, np.maximum(v, yp), yp)


def _groups(k, nk):
    """``(value, indices)`` for each value present in the small-integer array ``k``."""
    order = np.argsort(k, kind="stable")
    bounds = np.searchsorted(k[order], np.arange(nk + 1))
    return [(v, order[bounds[v]:bounds[v + 1]]) for v in range(nk) if bounds[v + 1] > bounds[v]]


def _window_peaks(ts, y, n):
    """Peak (parabola-refined) of ``y`` in consecutive windows of ``n`` samples starting at 0."""
    nw = (len(y) - 1) // n
    yy = y[: nw * n].reshape(nw, n)
    j = np.argmax(yy, axis=1) + np.arange(nw) * n
    jl = np.clip(j - 1, 0, len(y) - 1)
    jr = np.clip(j + 1, 0, len(y) - 1)
    ym, y0, yp = y[jl], y[j], y[jr]
    den = ym - 2 * y0 + yp
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(den < 0, 0.5 * (ym - yp) / den, 0.0)
    u = np.clip(u, -0.5, 0.5)
    peak = np.maximum(y0 - 0.25 * (ym - yp) * u, y0)
    h = ts[1] - ts[0]
    return ts[j] + u * h, peak


def fundamental(result: SwitchingResult, t_a: float, t_b: float, signal: str = "v2") -> complex:
    """Complex fundamental ``a - j b`` of ``signal`` ('v2', 'i2', 'i1', 'v1', 'i_load') over
    ``[t_a, t_b]`` (an integer number of inverter periods): ``signal ~ a cos(wt) + b sin(wt)``.
    Integrated in closed form on the exact solution."""
    cir = result.circuit
    e = np.eye(cir.m)
    col = {"i1": I1, "i2": I2}
    form = (lambda k: e[col[signal]]) if signal in col else (lambda k: cir.rows[k][signal])
    f = result.linear_integrals([t_a, t_b], [form], [cir.p.omega_rad_s])[0, 0] * (2.0 / (t_b - t_a))
    return complex(f.real, -f.imag)


# ============================================================================ simulator
class SwitchingLink:
    """Event-exact simulator of one link (paper eq. 1) with the SBAR.

    Parameters
    ----------
    params : LinkParams
        Table I values by default.
    cfg : SwitchingConfig
        Capacitors, dead time, battery model, gate phase, dense-output resolution.
    """

    def __init__(self, params: LinkParams, cfg: SwitchingConfig = SwitchingConfig()):
        self.params, self.cfg = params, cfg
        self.cir = cir = Circuit(params, cfg)
        self.T = cir.T
        h = self.T / _GRID
        self._h = h
        self._grid = [np.exp(np.outer(np.arange(_GRID + 2) * h, lam)) for lam in cir.lam]
        m = cir.m
        e = np.eye(m)
        # guard rows (positive while the mode is valid), in modal coordinates per topology
        self._guards = {}
        for k, (p, s) in enumerate(cir.keys):
            sec = []
            if s in (1, -1):
                sec = [s * e[I2]]
            elif s == S_OPEN:
                vo, vop = cir.vout_row(), cir.v2_open_row(p)
                sec = [vo - vop, vo + vop]
            pri = []
            if p in (1, -1):
                pri = [-p * e[I1]]
            elif p == P_OPEN:
                vd, v1o = e[-1] * params.vdc_v, cir.v1_open_row(s)
                pri = [vd - v1o, vd + v1o]
            vec = cir.vec[k]
            self._guards[k] = ({"sec": np.array([g @ vec for g in sec]).reshape(-1, m) if sec else None,
                                "pri": np.array([g @ vec for g in pri]).reshape(-1, m) if pri else None})
        # (topology, gate, inverter command) -> (stacked guard rows or None, number of secondary rows)
        self._guard_table = {}
        for k in range(len(cir.keys)):
            for gate in (0, 1):
                for cmd in (1, -1, 0):
                    gs = self._guards[k]["sec"] if not gate else None
                    gp = self._guards[k]["pri"] if cmd == 0 else None
                    parts = [r for r in (gs, gp) if r is not None]
                    rows = np.vstack(parts) if parts else None
                    # guard values on the bracketing grid: (ge[j] @ z).real = guards at (j+1) h
                    ge = None if rows is None else self._grid[k][1:, None, :] * rows[None, :, :]
                    self._guard_table[(k, gate, cmd)] = (rows, len(gs) if gs is not None else 0, ge)
        self._v2open = {p: cir.v2_open_row(p) for p in (1, -1, P_OPEN)}
        self._v1open = {s: cir.v1_open_row(s) for s in (1, -1, S_SHORT, S_OPEN)}
        self._vout = cir.vout_row()

    # ------------------------------------------------------------------ mode rules
    def _secondary_at_zero(self, x, p):
        """Diode state when i2 = 0 and the gate is off: by the open-circuit voltage."""
        v, vo = x @ self._v2open[p], x @ self._vout
        return 1 if v > vo else (-1 if v < -vo else S_OPEN)

    def _primary_at_zero(self, x, s):
        """Inverter freewheel state when i1 = 0 during dead time."""
        v, vd = x @ self._v1open[s], self.params.vdc_v
        return 1 if v > vd else (-1 if v < -vd else P_OPEN)

    def _modes(self, x, cmd, gate, p, s):
        """Modes after a drive change: the inverter follows its command (in dead time the current
        freewheels through the diodes opposite to its sign), the SBAR shorts while the gate is on,
        else the diode pair of the current's sign conducts; a zero current is decided by the
        open-circuit voltage."""
        if cmd != 0:
            p = cmd
        else:
            p = -1 if x[I1] > 0 else (1 if x[I1] < 0 else None)
        if gate:
            s = S_SHORT
        elif x[I2] > 0:
            s = 1
        elif x[I2] < 0:
            s = -1
        else:
            s = self._secondary_at_zero(x, p if p is not None else P_OPEN)
        if p is None:
            p = self._primary_at_zero(x, s)
        return p, s

    # ------------------------------------------------------------------ core loop
    def run(self, schedule: Schedule, x0: np.ndarray) -> SwitchingResult:
        """Integrate exactly over the schedule from augmented state ``x0`` (m,)."""
        cir = self.cir
        lam, vec, inv, trans, grid = cir.lam, cir.vec, cir.inv, cir.trans, self._grid
        guards, h = self._guard_table, self._h
        ecache = {}
        tol = 1e-12 * self.T
        ts, cmds, gates = schedule.t, schedule.cmd, schedule.gate
        x = np.array(x0, dtype=float)
        x[-1] = 1.0
        p = s = None
        # initial modes
        p = int(cmds[0]) if cmds[0] != 0 else (-1 if x[I1] > 0 else (1 if x[I1] < 0 else P_OPEN))
        if gates[0]:
            s = S_SHORT
        else:
            s = 1 if x[I2] > 0 else (-1 if x[I2] < 0 else self._secondary_at_zero(x, p))
        if p == P_OPEN:
            x[I1] = 0.0
        if s == S_OPEN:
            x[I2] = 0.0
        k = cir.index[(p, s)]
        z = inv[k] @ x
        seg_t, seg_k, seg_z = [], [], []
        t = float(ts[0])
        n_int = len(cmds)
        for j in range(n_int):
            t_b = float(ts[j + 1])
            cmd, gate = int(cmds[j]), int(gates[j])
            if j > 0 and (cmd != cmds[j - 1] or gate != gates[j - 1]):
                x = (vec[k] @ z).real
                p2, s2 = self._modes(x, cmd, gate, p, s)
                if (p2, s2) != (p, s):
                    if p2 == P_OPEN or s2 == S_OPEN:
                        if p2 == P_OPEN:
                            x[I1] = 0.0
                        if s2 == S_OPEN:
                            x[I2] = 0.0
                        p, s = p2, s2
                        k = cir.index[(p, s)]
                        z = inv[k] @ x
                    else:
                        p, s = p2, s2
                        k2 = cir.index[(p, s)]
                        z = trans[k][k2] @ z
                        k = k2
            n_same = 0
            t_int = t
            while True:
                seg_t.append(t)
                seg_k.append(k)
                seg_z.append(z)
                tau = t_b - t
                rows, ns, ge = guards[(k, gate, cmd)]
                if n_same == 0 and t == t_int:  # full interval: its exponential repeats, cache it
                    key = (k, round(tau * 1e18))
                    ez = ecache.get(key)
                    if ez is None:
                        ez = ecache[key] = np.exp(lam[k] * tau)
                else:
                    ez = np.exp(lam[k] * tau)
                z_end = z * ez
                if rows is None:
                    z = z_end
                    break
                ng = len(rows)
                nj = int(tau / h)
                jh = nj
                if nj > 0:
                    bad = ((ge[:nj] @ z).real <= 0.0).ravel()
                    i = int(bad.argmax())
                    if bad[i]:
                        jh = i // ng
                if jh == nj:
                    vb = (rows @ z_end).real
                    if not (vb <= 0.0).any():
                        z = z_end
                        break
                    b = tau
                else:
                    vb = (ge[jh] @ z).real
                    b = (jh + 1) * h
                a = jh * h
                c = rows * z
                va = (c @ grid[k][jh]).real
                best, which = b, -1
                lk = lam[k].tolist()
                for gi in range(len(c)):
                    if vb[gi] <= 0.0:
                        r = _refine(c[gi].tolist(), lk, a, float(va[gi]), b, float(vb[gi]), tol)
                        if r < best or which < 0:
                            best, which = r, gi
                if best <= 1e-13 * self.T:
                    n_same += 1
                    if n_same > 4:  # a mode chatters at one instant: take the open state
                        best = 0.0
                else:
                    n_same = 0
                z = z * np.exp(lam[k] * best)
                t += best
                x = (vec[k] @ z).real
                if which < ns:  # secondary event
                    if s in (1, -1) or n_same > 4:
                        x[I2] = 0.0
                        s = self._secondary_at_zero(x, p) if n_same <= 4 else S_OPEN
                    else:  # blocked interval ends
                        s = 1 if (x @ self._v2open[p]) > 0 else -1
                    if s == S_OPEN:
                        x[I2] = 0.0
                else:
                    if p in (1, -1) or n_same > 4:
                        x[I1] = 0.0
                        p = self._primary_at_zero(x, s) if n_same <= 4 else P_OPEN
                    else:
                        p = 1 if (x @ self._v1open[s]) > 0 else -1
                    if p == P_OPEN:
                        x[I1] = 0.0
                k = cir.index[(p, s)]
                z = inv[k] @ x
                if t >= t_b:
                    break
            t = t_b
        seg_t.append(t)
        return SwitchingResult(cir, schedule, np.array(seg_t), np.array(seg_k, dtype=int), np.array(seg_z))

    # ------------------------------------------------------------------ convenience
    def final_state(self, res: SwitchingResult) -> np.ndarray:
        k = res.seg_k[-1]
        z = res.seg_z[-1] * np.exp(self.cir.lam[k] * (res.seg_t[-1] - res.seg_t[-2]))
        return (self.cir.vec[k] @ z).real

    def schedule(self, t0_s, t_end_s, d_short, control_period_s=None, phase_rad=None) -> Schedule:
        """Schedule for a duty per control period (scalar = constant duty)."""
        T = self.T
        phase = self.cfg.gate_phase_rad if phase_rad is None else float(phase_rad)
        if not math.isfinite(phase):
            raise ValueError(f"phase_rad={phase_rad!r} is invalid; valid range: finite (radians at f)")
        if control_period_s is not None and not (math.isfinite(control_period_s) and control_period_s > 0):
            raise ValueError(f"control_period_s={control_period_s!r} is invalid; valid range: (0, inf)")
        w = self.params.omega_rad_s
        if np.ndim(d_short) == 0:
            dval = float(d_short)
            fn = lambda n: np.full(np.shape(n), dval)  # noqa: E731
        else:
            fn = duty_windows(d_short, control_period_s or T, T, phase, w)
        return make_schedule(t0_s, t_end_s, T, fn, phase, self.cfg.dead_time_s, w)

    def periodic_steady_state(self, d_short: float, phase_rad=None, iters: int = 6, tol: float = 1e-11):
        """Periodic steady state at t = 0 (mod 2T) for a constant duty: Newton shooting on the
        one-inverter-period map (finite-difference Jacobian), started from the phasor solution
        of the envelope model with V2 = f(d)."""
        from .sbar import v2_from_duty
        P = self.params
        i1, i2 = steady_state(P, v2_from_duty(float(np.clip(d_short, 0, 1)), P.vl_v))
        x = self.cir.phasor_state(float(i1), float(i2))
        sch = self.schedule(0.0, 2 * self.T, float(d_short), phase_rad=phase_rad)
        n = self.cir.n
        scale = np.abs(x[:n]) + 1.0

        def pmap(xx):
            return self.final_state(self.run(sch, xx))[:n]
        for _ in range(iters):
            fx = pmap(x)
            r = fx - x[:n]
            if np.max(np.abs(r) / scale) < tol:
                break
            jac = np.empty((n, n))
            for i in range(n):
                dx = x.copy()
                eps = 1e-7 * scale[i]
                dx[i] += eps
                jac[:, i] = (pmap(dx) - fx) / eps
            x[:n] = x[:n] - np.linalg.solve(jac - np.eye(n), r)
        return x

    def simulate(self, d_short, control_period_s=None, t_end_s=None, phase_rad=None, x0=None) -> SwitchingResult:
        """Run a duty sequence (one duty per control period) from t = 0, starting at the periodic
        steady state of the first duty unless ``x0`` is given."""
        d = np.atleast_1d(np.asarray(d_short, dtype=float))
        bad = ~np.isfinite(d) | (d < 0) | (d > 1)
        if bad.any():
            raise ValueError(f"d_short={d[bad][0]!r} is out of range; valid range: [0, 1]")
        cp = self.T if control_period_s is None else float(control_period_s)
        t_end = len(d) * cp if t_end_s is None else float(t_end_s)
        if x0 is None:
            x0 = self.periodic_steady_state(d[0], phase_rad)
        return self.run(self.schedule(0.0, t_end, d, cp, phase_rad), x0)


def _refine(c, lam, a, ga, b, gb, tol):
    """Root of ``g(t) = Re(sum c exp(lam t))`` in ``[a, b]`` with ``g(a) > 0 >= g(b)``:
    Newton on the exact solution, safeguarded by bisection (plain complex scalars: faster than
    numpy for 5-6 modes)."""
    if ga <= 0.0:
        return a
    exp = cmath.exp
    cl = [ci * li for ci, li in zip(c, lam)]
    t = a + (b - a) * ga / (ga - gb)
    for _ in range(60):
        g = dg = 0j
        for ci, cli, li in zip(c, cl, lam):
            e = exp(li * t)
            g += ci * e
            dg += cli * e
        g, dg = g.real, dg.real
        if g > 0:
            a = t
        else:
            b = t
        tn = t - g / dg if dg != 0 else 0.5 * (a + b)
        if not (a < tn < b):
            tn = 0.5 * (a + b)
        if abs(tn - t) <= tol or b - a <= tol:
            return t
        t = tn
    return b


# ============================================================================ solve_ivp reference
def simulate_ivp(params: LinkParams, cfg: SwitchingConfig, schedule: Schedule, x0, rtol: float = 1e-10,
                 atol: float = 1e-10, method: str | None = None, t_eval=None):
    """Slow reference: the same circuit (written directly from eq. 1, not from the topology
    matrices) integrated by ``scipy.integrate.solve_ivp`` between events; diode commutations
    are terminal events. Returns ``(t, x)`` with x (N, n) at ``t_eval`` (default: the ends).

    ``method`` defaults to DOP853, or Radau when the smoothing capacitor makes the system stiff
    (``r_bat_ohm * c_out_f < T / 10``): an explicit method then loses accuracy on the fast mode."""
    from scipy.integrate import solve_ivp
    cir = Circuit(params, cfg)
    if method is None:
        stiff = cir.has_cap and cfg.r_bat_ohm * cfg.c_out_f < cir.T / 10
        method = "Radau" if stiff else "DOP853"
    P = params
    n = cir.n
    det = P.l1_h * P.l2_h - P.lm_h**2
    rb, cap = cfg.r_bat_ohm, cir.has_cap
    helper = SwitchingLink(params, cfg)

    def rhs_factory(p, s):
        def rhs(t, y):
            i1, vc1, i2, vc2 = y[0], y[1], y[2], y[3]
            v1 = p * P.vdc_v if p != P_OPEN else 0.0
            if s in (1, -1):
                vout = y[4] if cap else P.vl_v + rb * s * i2
                v2 = s * vout
            else:
                v2 = 0.0
            e1 = v1 - P.r1_ohm * i1 - vc1
            e2 = -v2 - P.r2_ohm * i2 - vc2
            if p != P_OPEN and s != S_OPEN:
                di1 = (P.l2_h * e1 + P.lm_h * e2) / det
                di2 = (P.lm_h * e1 + P.l1_h * e2) / det
            elif p != P_OPEN:
                di1, di2 = e1 / P.l1_h, 0.0
            elif s != S_OPEN:
                di1, di2 = 0.0, e2 / P.l2_h
            else:
                di1 = di2 = 0.0
            out = [di1, i1 / cir.c1_f, di2, i2 / cir.c2_f]
            if cap:
                il = s * i2 if s in (1, -1) else 0.0
                out.append((il - (y[4] - P.vl_v) / rb) / cfg.c_out_f)
            return out
        return rhs

    def guard_factory(p, s, cmd, gate):
        fns = []
        if not gate and s in (1, -1):
            fns.append(("sec", lambda t, y, s=s: s * y[2]))
        if not gate and s == S_OPEN:
            r1, r2 = cir.vout_row() - cir.v2_open_row(p), cir.vout_row() + cir.v2_open_row(p)
            fns.append(("sec", lambda t, y, r=r1: np.append(y, 1.0) @ r))
            fns.append(("sec", lambda t, y, r=r2: np.append(y, 1.0) @ r))
        if cmd == 0 and p in (1, -1):
            fns.append(("pri", lambda t, y, p=p: -p * y[0]))
        if cmd == 0 and p == P_OPEN:
            vd = np.eye(cir.m)[-1] * P.vdc_v
            r1, r2 = vd - cir.v1_open_row(s), vd + cir.v1_open_row(s)
            fns.append(("pri", lambda t, y, r=r1: np.append(y, 1.0) @ r))
            fns.append(("pri", lambda t, y, r=r2: np.append(y, 1.0) @ r))
        for _, f in fns:
            f.terminal, f.direction = True, -1
        return fns

    x = np.array(x0, dtype=float)[:n]
    pieces = []  # (t_a, t_b, OdeSolution)
    p = int(schedule.cmd[0]) if schedule.cmd[0] != 0 else (-1 if x[0] > 0 else 1)
    s = S_SHORT if schedule.gate[0] else (1 if x[2] > 0 else -1)
    for j in range(len(schedule.cmd)):
        t, t_b = float(schedule.t[j]), float(schedule.t[j + 1])
        cmd, gate = int(schedule.cmd[j]), int(schedule.gate[j])
        xa = np.append(x, 1.0)
        p, s = helper._modes(xa, cmd, gate, p, s)
        while t < t_b:
            gl = guard_factory(p, s, cmd, gate)
            sol = solve_ivp(rhs_factory(p, s), (t, t_b), x, method=method, rtol=rtol, atol=atol,
                            events=[f for _, f in gl] or None, dense_output=True)
            pieces.append((t, float(sol.t[-1]), sol.sol))
            x = sol.y[:, -1].copy()
            t = float(sol.t[-1])
            if sol.status == 1:
                which = [i for i, e in enumerate(sol.t_events) if len(e)][0]
                x = sol.y_events[which][0].copy()
                t = float(sol.t_events[which][0])
                xa = np.append(x, 1.0)
                if gl[which][0] == "sec":
                    if s in (1, -1):
                        xa[I2] = 0.0
                        s = helper._secondary_at_zero(xa, p)
                    else:
                        s = 1 if xa @ cir.v2_open_row(p) > 0 else -1
                    if s == S_OPEN:
                        xa[I2] = 0.0
                else:
                    if p in (1, -1):
                        xa[I1] = 0.0
                        p = helper._primary_at_zero(xa, s)
                    else:
                        p = 1 if xa @ cir.v1_open_row(s) > 0 else -1
                    if p == P_OPEN:
                        xa[I1] = 0.0
                x = xa[:n]
            else:
                t = t_b
    starts = np.array([pc[0] for pc in pieces])
    t_eval = np.asarray([schedule.t[0], schedule.t[-1]] if t_eval is None else t_eval, dtype=float)
    idx = np.clip(np.searchsorted(starts, t_eval, side="right") - 1, 0, len(pieces) - 1)
    xs = np.empty((len(t_eval), n))
    for i in np.unique(idx):
        sel = idx == i
        xs[sel] = np.atleast_2d(pieces[i][2](t_eval[sel]).T)
    return t_eval, xs


# ============================================================================ SBAR relation
def sbar_relation(params: LinkParams, duties, phase_rad: float | None = 0.0, cfg: SwitchingConfig = SwitchingConfig(),
                  periods: int = 2) -> pd.DataFrame:
    """Fundamental of v2 in the periodic steady state against ``d_short`` (eq. 9 check).

    ``phase_rad``: gate clock phase relative to the peak of the i2 fundamental (``i2 ~ cos wt``);
    ``None`` centres the window on the i2 half-cycle itself, i.e. midway between the diode
    commutations (found per duty by root-finding the phase that makes v2 symmetric), which is
    exactly eq. 9's assumption. Columns: ``d_short, f_d_v`` (eq. 9), ``v2_abs_v`` (magnitude of
    the fundamental), ``v2_inphase_v`` (component in phase with the i2 fundamental),
    ``err_abs_pct``/``err_inphase_pct`` (relative to f(d)), ``err_abs_fs_pct`` (relative to the
    full scale (4/pi) VL), ``phase_rad``.
    """
    from scipy.optimize import brentq

    from .sbar import v2_from_duty
    link = _link(params, cfg)
    T = link.T
    rows = []
    for d in np.atleast_1d(np.asarray(duties, dtype=float)):
        def phasors(ph):
            x = link.periodic_steady_state(d, phase_rad=ph)
            r = link.run(link.schedule(0.0, 2 * periods * T, float(d), phase_rad=ph), x)
            return fundamental(r, 0.0, 2 * periods * T, "v2"), fundamental(r, 0.0, 2 * periods * T, "i2")

        if phase_rad is None:
            ph = brentq(lambda q: (phasors(q)[0] * np.exp(1j * q)).imag, -0.5, 0.5, xtol=1e-10)
        else:
            ph = float(phase_rad)
        v2, i2 = phasors(ph)
        f = float(v2_from_duty(d, params.vl_v))
        inph = float((v2 * np.conj(i2)).real / abs(i2))
        rows.append({"d_short": float(d), "f_d_v": f, "v2_abs_v": abs(v2), "v2_inphase_v": inph,
                     "err_abs_pct": 100 * (abs(v2) - f) / f if f > 0 else float("nan"),
                     "err_inphase_pct": 100 * (inph - f) / f if f > 0 else float("nan"),
                     "err_abs_fs_pct": 100 * (abs(v2) - f) / params.v2_rm_amp_v, "phase_rad": ph})
    return pd.DataFrame(rows)


# ============================================================================ paper plant
@lru_cache(maxsize=16)
def _link(params: LinkParams, cfg: SwitchingConfig) -> SwitchingLink:
    return SwitchingLink(params, cfg)


def switching_plant(params: LinkParams, d_short, control_period_s: float, cfg: SwitchingConfig = SwitchingConfig(),
                    phase_rad: float | None = None) -> dict:
    """Plant model for :func:`wpt_receiver.paper.run_paper` (``MODELS["switching"]``).

    Runs the duty sequence from the periodic steady state of its first duty and returns the
    per-half-cycle envelope ``t_s, i1_a, i2_a`` (peaks), ``v2_v`` (in-phase fundamental of v2 per
    half cycle), ``i2_fund_a`` (fundamental amplitude of i2 per half cycle), ``i_load_avg_a``
    (battery current averaged per half cycle) and the raw waveforms ``t_inst_s, i2_inst_a,
    i1_inst_a, i_load_a, gate`` (``samples_per_half_cycle`` per T plus every switching instant).
    """
    link = _link(params, cfg)
    res = link.simulate(d_short, control_period_s, phase_rad=phase_rad)
    env = res.envelope()
    df = res.frame(np.union1d(res.sample_times(), res.seg_t))  # grid + every switching instant
    t = env["t_s"].to_numpy()
    ok = np.isfinite(env["t_i1_peak_s"].to_numpy())
    i1 = np.interp(t, env["t_i1_peak_s"].to_numpy()[ok], env["i1_env_a"].to_numpy()[ok])
    il_avg = env["i_load_avg_a"].to_numpy()
    il = df["i_load_a"].to_numpy()
    return {"t_s": t, "i1_a": i1, "i2_a": env["i2_env_a"].to_numpy(), "v2_v": env["v2_fund_v"].to_numpy(),
            "i2_fund_a": env["i2_fund_a"].to_numpy(),
            "t_inst_s": df["t_s"].to_numpy(), "i2_inst_a": df["i2_a"].to_numpy(), "i1_inst_a": df["i1_a"].to_numpy(),
            "i_load_a": il, "gate": df["gate"].to_numpy(), "i_load_avg_a": il_avg,
            "link_params": params, "switching_config": cfg, "gate_phase_rad": link.cfg.gate_phase_rad if phase_rad is None else phase_rad}


def _plot_extra(runs, out_dir):
    from .switching_figures import plot_switching_waveforms
    return plot_switching_waveforms(runs, out_dir)


switching_plant.plot_extra = _plot_extra


def _register():
    from . import paper
    paper.MODELS["switching"] = switching_plant


_register()
