"""Amortised imitation of the per-window oracle: a learned map from what a receiver sees at the stop
to the oracle's open-loop duty sequence after it (issue 21, "imitation of the oracle").

The oracle (:mod:`policies.oracle`) finds, for one seeded window with the true parameters known, the
least-energy duty sequence after the stop within a measured-overshoot budget. Its sequences are
smooth ramps from the duty at the stop to short mode (duty 1), whose shape depends on the state at
the stop. This module learns that dependence from solved training windows and replays it, so a
realisable policy (observations only, no true parameter) acts below the MPC's curve:

* **Before the stop** the policy is the paper's controller (:class:`policies.classical.ModelBasedPolicy`,
  feed-forward: command and battery voltage to duty; a sensing delay does not touch it). The oracle's
  duties before the stop are the same, so the state at the stop is the one it was solved from.
* **At the stop** (a charge command of 0 after a positive one; a receiver that starts with command 0,
  a mission before its first pad, has no stop yet and keeps the base's duty) it computes
  :func:`stop_features` from its own frame history (the last :data:`HISTORY` observations, causal),
  predicts the sequence ``d_k0+j = d_pre + y_j`` for ``j < HORIZON`` (``y = [1, standardised
  features] W``, duty 1 after the horizon, clipped to [0, 1]), optionally played ``slow`` times slower
  (``y(j / slow)``), and holds that open-loop sequence until the command turns positive again. The base
  controller is stepped every period and never restarted (its state follows the zero command as its
  own would), so in a new window the duty is the base's again; ``HORIZON`` steps are learned at the
  control period in the model's meta (``control_period_s``; another period is refused).

Teacher and fit (:mod:`policies.oracle_imitation_train`, ``benchmarks/train_oracle_imitation.py``): for
training windows (seeds disjoint from the evaluation's 1000-1099) the oracle's floor ``f`` and its best
sequences within ``f + delta`` for a few ``delta``; per window the one with the least
``E + lam * overshoot [points]`` (:func:`choose_targets`: one multiplier for every window, so
overshoot is spent where it buys the most energy); ridge regression of the sequences (minus the duty
before the stop) on the features (:func:`fit`; the shipped models read the duty before the stop and
the command before it; on 80 training windows the cross-validated error, ~0.045 in duty, was no
lower with the currents, the command history, quadratic terms, nearest neighbours or an MLP: the
oracle's sequences vary between windows in ways the stop observation does not explain). The five
training seeds are bootstrap draws of the windows. Stored as ``.npz`` (8 kB: the feature columns and
normalisation, ``W``, ``slow``, the command in ``meta``); inference is one small matrix product.

The base before the stop is the model's ``meta["base"]`` (:data:`BASES`: ``model_based``, the default and the
shipped models', or ``mpc``, the MPC at budget 0, whose teacher is solved from the MPC's state at the stop:
``train_oracle_imitation.py --base mpc``; on the Lm drift it was not better than the MPC itself, docs/rl.md).

Policy: :class:`OracleImitationPolicy` (``oracle_imitation:PATH``; ``oracle_imitation`` = shipped seed 0,
``policies/pretrained/oracle_imitation_s0..4.npz``: fitted on the exact-mode link's oracle since 2026-11-26, when that
link became the envs' default, ``meta["link"] == "modal"``; the maps shipped before were fitted on eq. 4's, and
``train_oracle_imitation.py --link envelope`` gives those again).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mission_sim.contract import OBS_INDEX, PolicyContext, denormalise_obs

from .shipped import default_model

__all__ = ["BASES", "check_base", "HISTORY", "HORIZON", "stop_features", "target_sequences", "predict", "sequences_from", "save_model", "load_model",
           "choose_targets", "fit", "OracleImitationPolicy", "PRETRAINED_ORACLE_IMITATION", "FEATURE_NAMES"]

#: frames of observation history the policy keeps (the features use the last few before the stop)
HISTORY = 8
#: steps after the stop whose duties are predicted (20 ms: the longest window after its stop)
HORIZON = 200
PRETRAINED_ORACLE_IMITATION = default_model("oracle_imitation")

_I2, _VL, _IB, _IL, _SOC, _CMD, _D, _T = (OBS_INDEX[k] for k in (
    "i2_amp_a", "battery_v", "battery_current_a", "rect_current_a", "soc", "charge_cmd_a", "last_d_short",
    "t_since_stop_s"))
#: controllers the policy can run before the stop (``meta["base"]``; a model without it: ``model_based``)
BASES = ("model_based", "mpc")
FEATURE_NAMES = ("d_pre", "cmd_before_a", "vl_v", "soc", "i2_mean_a", "il_mean_a", "ib_mean_a", "d_slope",
                 "i2_per_duty")


def check_base(base) -> str:
    """``base`` if it is one of :data:`BASES`, else ``ValueError`` (one line naming it and the valid names)."""
    if base not in BASES:
        raise ValueError(f"base={base!r} is invalid; valid values: {', '.join(BASES)}")
    return base


def make_base(base: str, ctx: PolicyContext):
    """The controller before the stop: the paper's (``model_based``) or the MPC at budget 0 (``mpc``)."""
    if check_base(base) == "mpc":
        from .mpc import MPCPolicy
        return MPCPolicy(ctx)
    from .classical import ModelBasedPolicy
    return ModelBasedPolicy(ctx)


def stop_features(frames) -> np.ndarray:
    """Features (n, F) of the physical observation history ``frames`` (n, HISTORY, OBS_DIM) whose last
    frame is the first one with charge command 0 (the stop): the duty applied before the stop, the
    command before it, battery voltage and SoC, the means of the last four pre-stop frames of I2, I_L
    and the battery current (a sensing delay shifts them by a few frames; before the stop they are near
    steady), the duty's slope over those frames and I2 over the rectification-mode current scale
    ``(1 - d)`` (tells a weaker coupling, e.g. a falling Lm, from a stronger one)."""
    f = np.asarray(frames, dtype=float)
    last, pre = f[:, -1, :], f[:, -5:-1, :]
    d_pre = last[:, _D]
    i2 = pre[:, :, _I2].mean(axis=1)
    return np.column_stack([
        d_pre, f[:, -2, _CMD], last[:, _VL], last[:, _SOC], i2, pre[:, :, _IL].mean(axis=1),
        pre[:, :, _IB].mean(axis=1), d_pre - pre[:, 0, _D], i2 / np.maximum(1.0 - d_pre, 0.05)])


def choose_targets(energy_j, overshoot, lam_j_per_pt: float) -> np.ndarray:
    """Per window the index of the budget with the least ``E + lam * overshoot [points]`` (n,): one
    multiplier for all windows, so overshoot is spent where it buys the most energy (a larger ``lam``
    gives a lower mean overshoot)."""
    return np.argmin(np.asarray(energy_j) + lam_j_per_pt * 100.0 * np.asarray(overshoot), axis=1)


def target_sequences(duties, k0) -> np.ndarray:
    """The oracle's duties after the stop relative to the duty before it, ``d[k0 + j] - d[k0 - 1]`` for
    ``j < HORIZON`` (n, HORIZON); a window shorter than that is padded with its last value."""
    out = np.empty((len(k0), HORIZON))
    for i, (d, k) in enumerate(zip(duties, k0)):
        seg = d[k:k + HORIZON]
        out[i] = np.r_[seg, np.full(HORIZON - len(seg), seg[-1])] - d[k - 1]
    return out


def _design(model, features) -> np.ndarray:
    """``[1, standardised features]`` (n, 1 + F) of the model's feature columns."""
    f = np.atleast_2d(np.asarray(features, dtype=float))[:, model["cols"]]
    return np.column_stack([np.ones(len(f)), (f - model["feat_mean"]) / model["feat_std"]])


def fit(features, targets, cols=(0, 1), ridge: float = 1e-2, seed=None) -> dict:
    """Behaviour cloning of the oracle: ridge regression of the target sequences (n, HORIZON) on the
    standardised feature columns ``cols`` of :func:`stop_features` (linear: on the training windows the
    map's cross-validated error was no better with quadratic terms, k nearest neighbours or an MLP, see
    docs/rl.md); ``seed`` (int) fits on a bootstrap draw of the windows (the training seeds)."""
    X = np.asarray(features, dtype=float)[:, list(cols)]
    Y = np.asarray(targets, dtype=float)
    if seed is not None:
        idx = np.random.default_rng(int(seed)).integers(0, len(X), len(X))
        X, Y = X[idx], Y[idx]
    fm, fs = X.mean(axis=0), X.std(axis=0)
    fs = np.where(fs > 1e-6, fs, np.inf)     # a feature constant in training is ignored (weight 0)
    model = {"cols": np.asarray(cols, dtype=int), "feat_mean": fm, "feat_std": fs}
    D = np.column_stack([np.ones(len(X)), (X - fm) / fs])
    model["W"] = np.linalg.solve(D.T @ D + ridge * np.eye(D.shape[1]), D.T @ Y)
    return model


def predict(model, features) -> np.ndarray:
    """The model's target sequences (n, HORIZON) (duty after the stop minus the duty before it) for
    features (n, F): the clone ``phi W``, played ``slow`` times slower if the model says so."""
    D = _design(model, features)
    y = D @ model["W"]
    s = float(model.get("slow", 1.0))
    if s != 1.0:   # the sequence played ``s`` times slower: y(j / s), the last value held
        j = np.arange(HORIZON) / s
        y = np.array([np.interp(j, np.arange(HORIZON), row) for row in y])
    return y


def sequences_from(model, features, d_pre) -> np.ndarray:
    """Absolute duties after the stop (n, HORIZON) in [0, 1]: ``d_pre + predict``."""
    return np.clip(np.asarray(d_pre, dtype=float)[:, None] + predict(model, features), 0.0, 1.0)


def save_model(model: dict, path, meta: dict) -> None:
    """Write ``model`` (+ ``meta`` as JSON) to ``path`` (.npz) under a temporary name, then rename
    (:func:`mission_sim.files.atomic_output`: the temporary file is removed if writing fails)."""
    import json

    from mission_sim.files import atomic_output
    with atomic_output(path) as tmp:
        np.savez(tmp, meta=np.array(json.dumps(meta)), **model)


def _check_model(z: dict) -> str:
    """What is wrong with the arrays ``z`` of a model file ('' if nothing): keys W, cols, feat_mean,
    feat_std (and meta with control_period_s), W (1 + len(cols), HORIZON), cols in FEATURE_NAMES, slow >= 1."""
    import json
    missing = [k for k in ("W", "cols", "feat_mean", "feat_std", "meta") if k not in z]
    if missing:
        return f"no {', '.join(missing)}"
    cols, W = z["cols"], z["W"]
    if cols.ndim != 1 or not np.issubdtype(cols.dtype, np.integer) or len(cols) == 0 \
            or not np.all((cols >= 0) & (cols < len(FEATURE_NAMES))):
        return f"cols {cols.tolist()!r} not indices into FEATURE_NAMES (0..{len(FEATURE_NAMES) - 1})"
    if W.shape != (1 + len(cols), HORIZON):
        return f"W of shape {W.shape}, not {(1 + len(cols), HORIZON)}"
    if z["feat_mean"].shape != cols.shape or z["feat_std"].shape != cols.shape:
        return f"feat_mean/feat_std of shapes {z['feat_mean'].shape}/{z['feat_std'].shape}, not {cols.shape}"
    slow = z.get("slow", np.array(1.0))
    if slow.shape != () or not float(slow) >= 1.0:
        return f"slow={slow.tolist()!r}, not a number >= 1"
    try:
        meta = json.loads(str(z["meta"]))
        dt = float(meta["control_period_s"])
    except (ValueError, KeyError, TypeError):
        return "no control_period_s in its meta"
    if meta.get("base", "model_based") not in BASES:
        return f"base={meta['base']!r} in its meta, not one of {', '.join(BASES)}"
    if not (np.isfinite(dt) and dt > 0):
        return f"control_period_s={dt!r} in its meta, not > 0"
    return ""


def load_model(path) -> dict:
    """The model's arrays (``W``, ``cols``, ``feat_mean``, ``feat_std``, ``slow``) and its parsed ``meta``
    (dict, with the ``control_period_s`` it was trained at); ``ValueError`` naming the file and what
    was expected when it is not such a model (not an npz, keys or shapes wrong)."""
    import json
    import zipfile
    expected = (f"an oracle imitation model (.npz with W (1 + len(cols), {HORIZON}), cols in FEATURE_NAMES, "
                "feat_mean, feat_std, slow >= 1, meta with control_period_s and base in BASES)")
    try:
        if not zipfile.is_zipfile(path):
            raise ValueError("not an .npz (zip) archive")
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"oracle imitation model {str(path)!r} is unreadable ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__}); "
                         f"valid: {expected}") from None
    wrong = _check_model(arrays)
    if wrong:
        raise ValueError(f"oracle imitation model {str(path)!r} is invalid: {wrong}; valid: {expected}")
    arrays["meta"] = json.loads(str(arrays["meta"]))
    return arrays


class OracleImitationPolicy:
    """The base (the paper's controller, or the MPC if the model's meta says so) before the stop, the learned
    oracle sequence from the stop on (module notes).

    Causal: the duty at step k depends on the observations up to k only (the frame history and the
    sequence latched at the stop). The base controller is stepped every period (so before every stop
    the duty is exactly ``model_based``'s, whose state follows the zero command after a stop as its own
    would). A stop is a command of 0 after a positive one: a receiver that starts with command 0 (a
    mission before its first pad) has the base's duty; one whose command turns positive after its stop
    is in a new window and is released."""

    name = "oracle_imitation"

    def __init__(self, ctx: PolicyContext = PolicyContext(), path=PRETRAINED_ORACLE_IMITATION):
        self.ctx = ctx
        self.model = load_model(path)
        dt = float(self.model["meta"]["control_period_s"])
        if abs(ctx.control_period_s - dt) > 1e-9 * dt:    # its HORIZON steps are learned at this period
            raise ValueError(f"control_period_s={ctx.control_period_s!r} is invalid for {Path(path).name}; "
                             f"valid value: {dt!r} (the period it was trained at)")
        self.base = make_base(self.model["meta"].get("base", "model_based"), ctx)
        self.reset(1)

    def reset(self, n: int = 1) -> None:
        self.n = int(n)
        self.base.reset(self.n)
        self._hist = None
        self._seq = np.zeros((self.n, HORIZON))
        self._j = np.full(self.n, -1)      # steps since the stop (-1: no sequence latched)
        self._armed = np.zeros(self.n, dtype=bool)   # a positive command seen since the last stop

    def act(self, obs):
        o = np.atleast_2d(np.asarray(obs, dtype=float))
        if len(o) != self.n:
            self.reset(len(o))
        phys = denormalise_obs(o)
        if self._hist is None:
            self._hist = np.repeat(phys[:, None, :], HISTORY, axis=1)
        else:
            self._hist = np.concatenate([self._hist[:, 1:], phys[:, None, :]], axis=1)
        charging = phys[:, _CMD] > 0.0
        self._j[charging] = -1
        self._armed |= charging
        d = np.asarray(self.base.act(o), dtype=float).reshape(-1)
        stop = np.flatnonzero(~charging & self._armed)
        if len(stop):
            self._seq[stop] = sequences_from(self.model, stop_features(self._hist[stop]), phys[stop, _D])
            self._j[stop] = 0
            self._armed[stop] = False
        after = np.flatnonzero(self._j >= 0)
        d[after] = self._play(after, phys)
        self._j[after] += 1
        return d

    def _play(self, after, phys):
        """The duties (len(after),) of the receivers ``after`` (indices; a sequence latched, ``self._j`` steps since
        their stop, 0 at it): the sequence at step ``j``, duty 1 past its horizon (``phys`` unused here)."""
        j = self._j[after]
        return np.where(j < HORIZON, self._seq[after, np.minimum(j, HORIZON - 1)], 1.0)
