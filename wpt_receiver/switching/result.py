"""Result of an event-exact switching simulation: dense output, envelopes and exact integrals.

A run is stored as segments (start time, topology, modal state at the start). Between events
the state is ``x(t) = Re(V (exp(lam (t - t_seg)) * z_seg))``, so any output is evaluated exactly
and vectorised after the run: samples, half-cycle peaks, fundamentals (closed form) and energy
integrals (closed form).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .circuit import I1, I2, LOSS_GROUPS, VC1, VC2, Circuit
from .schedule import Schedule

__all__ = ["SwitchingResult", "fundamental"]


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
        """v1, v2, battery current and DC source current for states ``x`` in topologies ``k``."""
        out = {name: np.empty(len(k)) for name in ("v1", "v2", "i_load", "i_src")}
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

    def peak_abs(self, col: int, t_a: float, t_b: float, per_period: int = 8,
                 xatol_s: float = 1e-12) -> tuple[float, float]:
        """``(t, max |x_col|)`` over ``[t_a, t_b]`` [s] on the exact solution (:meth:`peaks_abs` of one window)."""
        return self.peaks_abs([(col, t_a, t_b)], per_period, xatol_s)[0]

    def peaks_abs(self, windows, per_period: int = 8, xatol_s: float = 1e-12) -> list[tuple[float, float]]:
        """``[(t, max |x_col|)]`` over each window ``(col, t_a, t_b)`` [s] on the exact solution.

        Each window is sampled at ``per_period`` points per rectifier period ``T`` (its ends included); every local
        maximum of its samples within ``cos(pi / per_period)`` of its largest (a sinusoid of period ``T`` peaks at
        most that factor above its nearest sample) is refined by a golden-section search for the maximum of
        ``|x_col|`` between its two neighbouring samples, every candidate of every window in the same vectorised
        iterations, to ``xatol_s``; a result is never below its window's largest sample. Only the windows are
        evaluated: a step's overshoot peak costs ``per_period`` samples per period of its window instead of the
        dense output of the whole run (:meth:`sample_times`); the golden section, not Newton, keeps a peak on a kink
        (a gate edge on the crest)."""
        if per_period < 4:
            raise ValueError(f"per_period={per_period!r} is invalid; valid range: >= 4 samples per period")
        cols = sorted({int(w[0]) for w in windows})
        h = self.circuit.T / per_period
        cand_t, cand_y, lo, hi, owner, which = [], [], [], [], [], []
        for i, (col, t_a, t_b) in enumerate(windows):
            if not (self.t0 <= t_a < t_b <= self.t_end):
                raise ValueError(f"window [{t_a!r}, {t_b!r}] s is invalid; valid range: t0={self.t0!r} <= t_a < "
                                 f"t_b <= t_end={self.t_end!r} s")
            n = max(int(math.ceil((t_b - t_a) / h)), 2)
            ts = np.linspace(t_a, t_b, n + 1)
            y = np.abs(self.states(ts, cols=[col])[0][:, 0])
            inner = (y[1:-1] >= y[:-2]) & (y[1:-1] >= y[2:])
            c = np.flatnonzero(np.r_[y[0] >= y[1], inner, y[-1] >= y[-2]] & (y >= math.cos(math.pi / per_period) * y.max()))
            cand_t.append(ts[c]), cand_y.append(y[c]), owner.append(np.full(len(c), i))
            lo.append(ts[np.maximum(c - 1, 0)]), hi.append(ts[np.minimum(c + 1, n)])
            which.append(np.full(len(c), cols.index(int(col))))
        cand_t, cand_y, lo, hi, owner, which = map(np.concatenate, (cand_t, cand_y, lo, hi, owner, which))
        rows = np.arange(len(which))
        f = lambda t: np.abs(self.states(t, cols=cols)[0][rows, which])  # noqa: E731
        g = (math.sqrt(5.0) - 1.0) / 2.0
        c, d = hi - g * (hi - lo), lo + g * (hi - lo)
        fc, fd = f(c), f(d)
        while np.max(hi - lo) > xatol_s:
            left = fc >= fd                      # the maximum is in [lo, d]; else in [c, hi]
            lo, hi = np.where(left, lo, c), np.where(left, d, hi)
            c, d = np.where(left, hi - g * (hi - lo), d), np.where(left, c, lo + g * (hi - lo))
            f_new = f(np.where(left, c, d))      # the one new point of each bracket
            fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
        tm = 0.5 * (lo + hi)
        v = f(tm)
        best = np.maximum(v, np.maximum(fc, fd))
        t_best = np.where(best == v, tm, np.where(best == fc, c, d))
        better = best >= cand_y                  # (a bracket where |x| is not unimodal keeps its sample)
        val, t_val = np.where(better, best, cand_y), np.where(better, t_best, cand_t)
        out = []
        for i in range(len(windows)):
            sel = np.flatnonzero(owner == i)
            j = sel[int(np.argmax(val[sel]))]
            out.append((float(t_val[j]), float(val[j])))
        return out

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
        """Energies over ``[t_a, t_b]`` [J], integrated in closed form.

        ``source_j`` (int Vdc i_dc, the DC source), ``inverter_out_j`` (int v1 i1), ``losses_j``
        (coil and battery resistances R1 i1^2 + R2 i2^2 + r_bat i_load^2), ``device_losses_j``
        (all conduction losses of the devices) and one ``<group>_loss_j`` per device group
        (:data:`~.circuit.LOSS_GROUPS`), ``battery_j`` (int VL i_load), ``rectifier_in_j``
        (int v2 i2), ``charge_c`` and ``stored_change_j``; ``residual_j`` = source - losses -
        device losses - battery - stored change (zero up to rounding for an exact simulation)."""
        cir, P = self.circuit, self.circuit.p
        e = np.eye(cir.m)
        one = e[-1]
        rows = cir.rows
        forms = [lambda k: (rows[k]["i_src"], one * P.vdc_v), lambda k: (rows[k]["v1"], e[I1]),
                 lambda k: (e[I1], e[I1] * P.r1_ohm), lambda k: (e[I2], e[I2] * P.r2_ohm),
                 lambda k: (rows[k]["i_load"], rows[k]["i_load"] * cir.cfg.r_bat_ohm),
                 lambda k: (rows[k]["i_load"], one * P.vl_v), lambda k: (rows[k]["v2"], e[I2]),
                 lambda k: (rows[k]["i_load"], one)]
        forms += [lambda k, g=g: cir.loss_forms(k)[g] for g in LOSS_GROUPS]
        vals = self.quadratic_integrals(t_a, t_b, forms)
        src, inv_out, l1, l2, lb, bat, rect, charge = vals[:8]
        groups = dict(zip(LOSS_GROUPS, vals[8:]))
        xs, _ = self.states([t_a, t_b])
        es = cir.stored_energy(xs)
        d_stored = float(es[1] - es[0])
        loss, dev = l1 + l2 + lb, float(sum(groups.values()))
        out = {"source_j": src, "inverter_out_j": inv_out, "losses_j": loss, "device_losses_j": dev,
               "battery_j": bat, "stored_change_j": d_stored, "rectifier_in_j": rect, "charge_c": charge,
               "residual_j": src - loss - dev - bat - d_stored}
        out.update({f"{g}_loss_j": v for g, v in groups.items()})
        return out

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
