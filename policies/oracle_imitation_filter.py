"""``oracle_imitation`` with a closed-loop safety filter after the stop (issue 21 goal 2; docs/rl.md, "A safety
filter on the learned after-stop sequence": a negative result, goal 2 not reached with it).

The learned map (:mod:`policies.oracle_imitation`) plays an open-loop duty sequence after the stop; its error
(~0.03 in duty) turns into ~0.35-0.4 points of measured overshoot, because the overshoot is a maximum over the
steps and the oracle it imitates sits on its budget. Here that sequence is the *reference* of a filter that
predicts the peak with the modal MPC's own model and estimate and changes the sequence only when the predicted
peak would exceed a limit:

* the MPC at budget 0 (:class:`policies.mpc.MPCPolicy`, on the same context) steps beside it on the same
  observations (its duties are not played): its estimator (the delay bank of Kalman filters) gives the state every
  period and its first after-stop solves the window's floor (``_relax``); nothing of its formulas is copied here;
* after the stop the plan is the learned sequence from now on over the MPC's horizon (duty 1 past the learned
  one); its peak samples are :meth:`policies.mpc.MPCPolicy.predicted_rows` (the model's I2 at mid-step and end of
  each step plus the ripple excess the env scores with; ``lock=True``: the phase-locked rows of
  :mod:`policies.mpc_lock`); the limit is the MPC's own bound at budget ``limit``: ``(1 + limit - margin) I2_sm(w)
  + relax`` (``limit = 0``: the MPC's bound at budget 0);
* within the limit the learned duty is played unchanged (bit for bit the clone's); above it the sequence is
  changed by ``correction``:

  - ``"rate"``: the least slowing of its playback: the fastest of ``rates`` (never faster than the rate so far: a
    rate change is a kink of the duty's slope, which rings the link) whose predicted peak is within the limit, or
    within 1 mA of the least over the rates (the floor), the playback lagging the steps since the stop by at most
    ``max_lag``; ``every_period=False``: decided at the stop only. With ``lam`` (J per point) the rate is chosen at
    the stop as the least predicted ``E + lam * overshoot`` instead (``E`` the MPC's after-stop energy term);
  - ``"qp"``: the least change of the plan in the MPC's V2 knots (squared change over the horizon, ``smooth`` x
    its moves between knots) whose *linearised* prediction (the rows' derivatives as the MPC's after-stop QP builds
    them) is within the limit, with the MPC's slack penalty (the least violation where none fits), each knot within
    ``trust`` [V] of the plan's, solved with daqp; the change is kept, shifted, as part of the plan.

``slow`` re-times the map first (``None``: the model's own). The defaults are the filter's best setting on the
validation windows 300-399 (``rate``, ``lam = 0.6``, ``slow = 1.0``, docs/rl.md), which did not beat the unfiltered
maps' own slow-down: the model predicts the clone's sequences to ~0.08 points but the QP's changes 0.4 points too
optimistically, and slowing buys overshoot at the same energy in every window. With a limit no peak reaches
(``limit=1``, ``lam=None``) the duties are the plain clone's bit for bit (``tests/test_oracle_imitation_filter.py``).
Options are keyword arguments (``policies.make("oracle_imitation_filtered[:PATH]", ctx, limit=...)``): ``limit`` [0, 1]
(fraction of I2_sm), ``slow`` (None or [1, 10]), ``rates`` (descending in [0, 1], the first 1), ``max_lag`` (0..200
steps), ``lock`` (bool; the exact-mode link only), ``every_period`` (bool), ``lam`` (None or >= 0), ``correction``
(``rate``, ``qp``), ``smooth`` (>= 0), ``trust`` (> 0, default unbounded); a bad value: one-line ``ValueError`` naming it and the valid range.
"""

from __future__ import annotations

import math

import numpy as np

from mission_sim.contract import PolicyContext, denormalise_obs
from mission_sim.validation import Range, check_number, real_number

from .oracle_imitation import _CMD, _D, _I2, _VL, HORIZON, PRETRAINED_ORACLE_IMITATION, OracleImitationPolicy

__all__ = ["OracleImitationFilteredPolicy", "RATES", "LIMIT", "MAX_LAG", "LOCK", "SLOW", "EVERY_PERIOD", "LAM",
           "CORRECTIONS", "CORRECTION", "SMOOTH", "TRUST"]

#: playback rates the filter may choose, fastest first (1: the learned sequence as it is; 0: held)
RATES = (1.0, 0.97, 0.94, 0.91, 0.88, 0.85, 0.82, 0.79, 0.76)
#: the limit's budget above the MPC's bound at budget 0 (fraction of the short-mode current)
LIMIT = 0.0
#: the longest lag of the playback behind the steps since the stop [control periods]
MAX_LAG = 30
#: predict with the rectifier's phase lock (policies.mpc_lock)
LOCK = False
#: the playback's slow-down (None: the model's own)
SLOW = 1.0
#: the rate re-decided every control period after the stop (False: at the stop only)
EVERY_PERIOD = True
#: (None: the limit decides) the rate chosen at the stop with the least predicted E + lam * overshoot [J per point]
LAM = 0.6
#: how the filter changes the learned sequence: ``qp`` (the least change of the plan, the MPC's QP machinery) or
#: ``rate`` (the least slowing of its playback)
CORRECTIONS = ("qp", "rate")
CORRECTION = "rate"
#: (qp) the penalty of the correction's moves between knots, relative to its squared size summed over the horizon
SMOOTH = 0.0
#: (qp) the largest change of a knot of the plan [V] (a trust region, as the MPC's locked iterations keep)
TRUST = np.inf
#: rates whose predicted peaks are within this [A] of the least are ties (the fastest of them is taken)
_TIE_A = 1e-3


def _at(seq, pos):
    """The sequences ``seq`` (n, HORIZON) at the fractional positions ``pos`` (n, m) (linear in between; exact at
    an integer position; 1 past the last)."""
    i0 = np.minimum(np.floor(pos).astype(np.int64), HORIZON - 1)
    i1 = np.minimum(i0 + 1, HORIZON - 1)
    f = pos - i0
    r = np.arange(len(seq))[:, None]
    v = seq[r, i0] * (1.0 - f) + seq[r, i1] * f
    return np.where(pos > HORIZON - 1, 1.0, v)


def _check(limit, slow, rates, max_lag, lock, ctx):
    limit = check_number("limit", limit, Range(0.0, 1.0), " (a fraction of the short-mode current)")
    if slow is not None:
        slow = check_number("slow", slow, Range(1.0, 10.0), " (or None: the model's own)")
    try:
        r = tuple(float(x) for x in rates)
    except (TypeError, ValueError):
        r = ()
    if not r or r[0] != 1.0 or any(not (0.0 <= x <= 1.0) for x in r) or any(a <= b for a, b in zip(r, r[1:])):
        raise ValueError(f"rates={rates!r} is invalid; valid: strictly descending numbers in [0, 1], the first 1.0")
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)) or not 0 <= max_lag <= HORIZON:
        raise ValueError(f"max_lag={max_lag!r} is invalid; valid range: integers 0..{HORIZON} [control periods]")
    if not isinstance(lock, (bool, np.bool_)):
        raise ValueError(f"lock={lock!r} is invalid; valid values: True, False")
    if lock and ctx.link_model != "modal":
        raise ValueError(f"lock=True is invalid on link_model={ctx.link_model!r}; valid: lock=False, or the modal link")
    return limit, slow, r, int(max_lag), bool(lock)


def _shadow_mpc(ctx):
    """The MPC at budget 0 on ``ctx`` that keeps its last estimate (``z_now``, (n, nz)) for the filter."""
    from .mpc import MPCPolicy

    class _Shadow(MPCPolicy):
        z_now = None

        def _estimate(self, *args, **kwargs):
            self.z_now = super()._estimate(*args, **kwargs)
            return self.z_now

    return _Shadow(ctx)


class OracleImitationFilteredPolicy(OracleImitationPolicy):
    """The learned oracle sequence after the stop, slowed where the MPC's model predicts a peak above the limit
    (module notes); before the stop the model's base, as :class:`OracleImitationPolicy`. ``binds`` (n,): the
    steps after the stop of each receiver in which the filter did not play rate 1."""

    name = "oracle_imitation_filtered"
    uses_link_model = True   # the MPC's model and estimator of the context's link_model

    def __init__(self, ctx: PolicyContext = PolicyContext(), path=PRETRAINED_ORACLE_IMITATION, limit=LIMIT,
                 slow=SLOW, rates=RATES, max_lag=MAX_LAG, lock=LOCK, every_period=EVERY_PERIOD, lam=LAM,
                 correction=CORRECTION, smooth=SMOOTH, trust=TRUST):
        self.limit, slow, self.rates, self.max_lag, self.lock = _check(limit, slow, rates, max_lag, lock, ctx)
        if not isinstance(every_period, (bool, np.bool_)):
            raise ValueError(f"every_period={every_period!r} is invalid; valid values: True, False")
        self.every_period = bool(every_period)
        self.lam = None if lam is None else check_number("lam", lam, Range(0.0, math.inf, "J per point"),
                                                           " (or None: the limit decides)")
        if correction not in CORRECTIONS:
            raise ValueError(f"correction={correction!r} is invalid; valid values: {', '.join(CORRECTIONS)}")
        self.correction = correction
        self.smooth = check_number("smooth", smooth, Range(0.0, math.inf), " (the move penalty of the correction)")
        self.trust = math.inf if real_number(trust) == math.inf else check_number(   # inf: no trust region
            "trust", trust, Range(0.0, math.inf, "V", lo_open=True), " (the largest change of a knot; inf: none)")
        self._mpc = _shadow_mpc(ctx)   # budget 0: its estimate, floor and predicted rows; its duties are not played
        super().__init__(ctx, path)
        if slow is not None:
            self.model["slow"] = np.array(slow)

    def _locked(self, z):
        """The estimates ``z`` (n, nz) whose rows predict with the phase lock (the MPC's gate, |w| <= its tail's), or
        None without ``lock``."""
        if not self.lock:
            return None
        from .mpc import _TAIL_W_MAX
        return np.abs(z[:, -1]) <= _TAIL_W_MAX

    def reset(self, n: int = 1) -> None:
        super().reset(n)
        self._mpc.reset(self.n)
        self._tau = np.zeros(self.n)
        self._rate = np.ones(self.n)
        from .mpc import N_PRED
        self._corr = np.zeros((self.n, N_PRED))   # (qp) the correction of the plan in V2 [V], from now on
        self._z = None
        self.binds = np.zeros(self.n, dtype=np.int64)

    def act(self, obs):
        from .threads import single_blas_thread
        o = np.atleast_2d(np.asarray(obs, dtype=float))
        if len(o) != self.n:
            self.reset(len(o))
        phys = denormalise_obs(o)
        new = np.flatnonzero((phys[:, _CMD] > 0.0) & (self._j >= 0))   # charging again after its stop: a new window
        self.binds[new] = 0
        with single_blas_thread():
            self._mpc._act(o)   # the MPC's step on what the receiver measured (its duty is not played)
            self._z = self._mpc.z_now
            return super().act(o)

    def _play(self, after, phys):
        if self.correction == "qp":
            return self._play_qp(after, phys)
        j, seq = self._j[after], self._seq[after]
        rate = np.where(j == 0, 1.0, self._rate[after])   # at the stop: rate 1 again, the sequence from its start
        tau = self._tau[after]
        # where the rate can change anything (with lam: at the stop only)
        go = np.flatnonzero((j == 0) | ((tau < HORIZON - 1) & self.every_period & (self.lam is None)))
        if len(go):
            rate[go] = self._choose(after[go], seq[go], tau[go], j[go], rate[go], phys[after[go], _VL])
        tau = np.where(j == 0, 0.0, tau + rate)
        self._tau[after], self._rate[after] = tau, rate
        self.binds[after] += rate != 1.0
        return _at(seq, tau[:, None])[:, 0]

    def _rows(self, idx, z, vl, seq, start, rate):
        """Predicted peak samples' maximum (m,) [A] and the limit (m,) [A] of the sequences ``seq`` (m, HORIZON)
        played from the position ``start`` (m,) on at ``rate`` (m,) from the estimates ``z`` (m, nz) of the
        receivers ``idx`` (m,)."""
        from .mpc import N_PRED
        mpc = self._mpc
        pos = start[:, None] + rate[:, None] * np.arange(N_PRED)[None, :]
        plan = mpc._v2_of(_at(seq, pos), vl[:, None])
        locked = self._locked(z)
        rows, margin = mpc.predicted_rows(z, vl, plan, locked)
        return rows.max(axis=1), (1.0 + self.limit - margin) * mpc._bound_sm(z) + mpc._relax[idx]

    def _choose(self, idx, seq, tau, j, rate, vl):
        """The playback rate (m,) of the receivers ``idx`` (m,) this period, ``rate`` (m,) the one so far, ``tau``
        the phase played last (module notes)."""
        z = self._z[idx]
        first = j == 0
        out = rate.copy()
        if self.lam is not None:   # at the stop: the rate of least predicted energy + lam * predicted overshoot
            f = np.flatnonzero(first)
            if len(f):
                out[f] = self._choose_lam(idx[f], z[f], vl[f], seq[f])
            return out
        start = np.where(first, 0.0, tau + rate)
        peak1, lim = self._rows(idx, z, vl, seq, start, rate)
        bind = np.flatnonzero(peak1 > lim)
        if not len(bind):
            return out
        rates = np.asarray(self.rates)
        k = len(rates)
        b = np.repeat(bind, k)
        r = np.tile(rates, len(bind))
        st = np.where(first[b], 0.0, tau[b] + r)
        peak = self._rows(idx[b], z[b], vl[b], seq[b], st, r)[0].reshape(len(bind), k)
        # never faster than the rate so far (a rate change is a kink of the duty's slope, which rings the link);
        # the phase may lag the steps since the stop by at most max_lag
        allowed = (rates[None, :] <= rate[bind, None]) & (first[bind, None] | (st.reshape(len(bind), k)
                                                                                >= (j[bind] - self.max_lag)[:, None]))
        allowed[np.arange(len(bind)), np.argmax(rates[None, :] <= rate[bind, None], axis=1)] = True
        peak[~allowed] = np.inf
        bound = np.maximum(lim[bind], peak.min(axis=1) + _TIE_A)
        out[bind] = rates[np.argmax(peak <= bound[:, None], axis=1)]   # the fastest within the bound
        return out

    def _choose_lam(self, idx, z, vl, seq):
        """At the stop: per receiver the rate of :data:`RATES` with the least ``E + lam * overshoot [points]``, both
        predicted over the MPC's horizon (``E`` the energy after the stop, ``sum V2 I2_sm(w) / 2 dt``, the MPC's
        after-stop energy term; the overshoot from the predicted peak samples)."""
        from .mpc import N_PRED
        mpc = self._mpc
        rates = np.asarray(self.rates)
        k, m = len(rates), len(idx)
        b = np.repeat(np.arange(m), k)
        r = np.tile(rates, m)
        pos = r[:, None] * np.arange(N_PRED)[None, :]
        plan = mpc._v2_of(_at(seq[b], pos), vl[b, None])
        locked = self._locked(z[b])
        rows = mpc.predicted_rows(z[b], vl[b], plan, locked)[0]
        sm = mpc._bound_sm(z[b])
        cost = plan.sum(axis=1) * sm * 0.5 * self.ctx.control_period_s + self.lam * 100.0 * (rows.max(axis=1) / sm - 1.0)
        return rates[np.argmin(cost.reshape(m, k), axis=1)]

    def _play_qp(self, after, phys):
        """``correction="qp"``: the learned sequence from step ``j`` on plus the correction planned so far (in V2,
        shifted a step each period; none at the stop) is the plan; where it predicts a peak above the limit, the
        least change of it (in the MPC's V2 knots, the squared V2 change summed over the horizon) that keeps the
        linearised prediction within the limit (a slack at the MPC's penalty: the least violation where none does,
        the window's floor) is the new correction. The first move of the plan is played: the learned duty itself
        where no correction was ever needed."""
        from wpt_receiver import duty_from_v2_clipped

        from .mpc import N_PRED
        j, seq = self._j[after], self._seq[after]
        out = _at(seq, j[:, None].astype(float))[:, 0]
        corr = self._corr[after]
        corr[j == 0] = 0.0
        corr[j > 0] = np.concatenate([corr[j > 0, 1:], np.zeros((int((j > 0).sum()), 1))], axis=1)
        self._corr[after] = corr
        go = np.flatnonzero((j < HORIZON - 1 + N_PRED) & ((j == 0) | self.every_period | np.any(corr != 0.0, axis=1)))
        if not len(go):
            return out
        mpc, idx = self._mpc, after[go]
        z, vl = self._z[idx], phys[idx, _VL]
        pos = j[go, None] + np.arange(N_PRED)[None, :].astype(float)
        ref = mpc._v2_of(_at(seq[go], pos), vl[:, None])
        vmax = 4.0 / np.pi * (vl + mpc._vf)
        plan = np.clip(ref + corr[go], 0.0, vmax[:, None])
        locked = self._locked(z)
        rows, margin = mpc.predicted_rows(z, vl, plan, locked)
        lim = (1.0 + self.limit - margin) * mpc._bound_sm(z) + mpc._relax[idx]
        bind = np.flatnonzero((rows.max(axis=1) > lim) & ((j[go] == 0) | self.every_period))
        if len(bind):
            plan[bind] = self._project(z[bind], vl[bind], plan[bind], rows[bind], lim[bind],
                                       None if locked is None else locked[bind])
            self.binds[idx[bind]] += 1
        self._corr[idx] = plan - ref
        moved = np.flatnonzero(np.any(self._corr[idx] != 0.0, axis=1))
        if len(moved):
            out[go[moved]] = duty_from_v2_clipped(plan[moved, 0], vl[moved] + mpc._vf)
        return out

    def _project(self, z, vl, ref, rows, lim, locked):
        """The plans [V] (m, N_PRED): the least change ``M dv`` of the plans ``ref`` (m, N_PRED) whose linearised
        predicted peak samples (``rows`` (m, 2 N_PRED) at ``ref``; the MPC's rows and derivatives) are within
        ``lim`` (m,) [A] (module notes): one QP per receiver with daqp, as the MPC's."""
        import daqp

        from .mpc import _BIG, _SLACK_Q, _SLACK_W
        mpc = self._mpc
        M = mpc._model.M
        f = M.shape[1] - 1
        m = len(z)
        _, slope = mpc._excess(ref, vl)
        A = np.empty((m, rows.shape[1], f))
        lk = np.zeros(m, dtype=bool) if locked is None else locked
        if lk.any():
            A[lk] = mpc._locked_rows(z[lk], ref[lk], vl[lk])[1]
        un = ~lk
        if un.any():
            A[un] = mpc._Gf
            if mpc._modal:
                A[un] += mpc._residual_lin(np.zeros((int(un.sum()), rows.shape[1])), ref[un], vl[un], f)[1][:, :, :f]
        A += slope.repeat(2, axis=1)[:, :, None] * mpc._M2[None]
        Mf = M[:, :f]
        H = np.zeros((f + 1, f + 1))
        D = np.eye(f) - np.eye(f, k=-1)
        H[:f, :f] = 2.0 * (Mf.T @ Mf + self.smooth * D.T @ D) + 1e-9 * np.eye(f)
        H[f, f] = 2.0 * _SLACK_Q
        q = np.zeros(f + 1)
        q[f] = _SLACK_W
        knots = np.asarray(mpc._knots)
        vmax = 4.0 / np.pi * (vl + mpc._vf)
        sense = np.zeros(f + 1 + rows.shape[1], dtype=np.int32)
        out = ref.copy()
        self.last_slack = np.zeros(m)   # [A] the least violation each QP kept (0: the limit met)
        for i in range(m):
            Ai = np.concatenate([A[i], -np.ones((rows.shape[1], 1))], axis=1)
            bu = np.concatenate([np.minimum(vmax[i] - ref[i, knots], self.trust), [_BIG], lim[i] - rows[i]])
            bl = np.concatenate([np.maximum(-ref[i, knots], -self.trust), [0.0], np.full(rows.shape[1], -_BIG)])
            x, _, flag, _ = daqp.solve(H, q, Ai, bu, bl, sense.copy())
            if flag >= 1:
                out[i] = np.clip(ref[i] + M[:, :f] @ x[:f], 0.0, vmax[i])
                self.last_slack[i] = x[f]
        return out
