"""Several policies side by side in one batched env: each on its own block of rows.

``compare`` runs every policy on the same ``n`` seeded windows. Instead of one vector env and one
300-step Python loop per policy, :class:`BlockPolicy` puts ``k`` policies in one env of ``k n`` rows
(block ``b`` = rows ``b n .. (b + 1) n - 1``, the same windows in every block) and calls each
policy's ``act`` on its own block every step: the env is built, reset and stepped once for all of
them, and each policy sees exactly the observations it would see alone (the env's rows are
independent), so each block's actions and results are those of a separate run.

Learned policies of one kind trained with several seeds (:class:`policies.rl.RLPolicy`, or
:class:`policies.residual.ResidualPolicy` with the same base, whose actors have the same layers) are
evaluated as one stacked network (:class:`StackedRL`): the seeds' weights stacked into ``(k, in, out)``
arrays and one ``np.matmul`` per layer over the ``(k, n, in)`` observations, i.e. the same float32
products per block as ``NumpyActor.forward`` (numpy's stacked matmul calls the same BLAS product for
each block) with one Python call per layer instead of ``k``; the residual seeds' base controller runs
once over all their rows. ``model_based`` and its budgeted variants run as one controller with a
budget per row (:class:`StackedModelBased`). Stacked policies get adjacent blocks (:attr:`BlockPolicy.block`).
Separate and batched runs agree row by row, to the bit (``tests/test_compare_batched.py``).
"""

from __future__ import annotations

import numpy as np

from mission_sim.contract import action_to_duty

__all__ = ["BlockPolicy", "StackedRL", "StackedModelBased", "stackable"]


def _rl_key(p):
    """What two RL policies must share to be stacked (None: not stackable)."""
    a = getattr(p, "_actor", None)
    if (a is None or a.head != "clip" or p.history != 1 or p.action_filter or p.discrete or p._mean is None
            or p._hist is not None):
        return None
    shapes = tuple(layer[0].shape if isinstance(layer, tuple) else layer for layer in a.layers)
    return ("rl", p.obs_dim, float(p._clip), shapes)


class _Absent:
    """Stands for a policy class whose module is not imported (no policy is an instance of it)."""


def _loaded(module: str, name: str):
    """``policies.<module>.<name>`` if that module is imported, else :class:`_Absent`."""
    import sys
    mod = sys.modules.get(f"{__package__}.{module}")
    return _Absent if mod is None else getattr(mod, name)


def stackable(p):
    """Key of a policy that :class:`StackedRL` or :class:`StackedModelBased` can batch with others of the
    same key, else ``None``."""
    # a class of a module not imported yet cannot be p's: the modules are looked up, not imported (the MPC's
    # forked child of ``compare`` has one policy and imported neither rl nor residual: ~0.05 s of CPU less)
    ModelBasedPolicy = _loaded("classical", "ModelBasedPolicy")
    BudgetedModelBasedPolicy = _loaded("budgeted", "BudgetedModelBasedPolicy")
    ResidualPolicy, RLPolicy = _loaded("residual", "ResidualPolicy"), _loaded("rl", "RLPolicy")

    if type(p) in (ModelBasedPolicy, BudgetedModelBasedPolicy) and not getattr(p, "eq4_relaxation", False):
        return ("model_based", p.ctx, p.lpf)
    if type(p) is RLPolicy:
        return _rl_key(p)
    if isinstance(p, ResidualPolicy) and type(p.rl) is RLPolicy and _rl_key(p.rl) is not None:
        return ("residual", p.scale, p.base_budget, p.base.lpf, _rl_key(p.rl))
    return None


class StackedRL:
    """``k`` deterministic numpy actors of the same layers (RL or residual policies) on ``k`` blocks of
    ``n`` rows: the actions of each policy's own ``act`` on its block, in one pass."""

    def __init__(self, pols: list):
        self.pols = pols
        self.residual = stackable(pols[0])[0] == "residual"
        rls = [p.rl if self.residual else p for p in pols]
        self.k, self.obs_dim, self.clip = len(rls), rls[0].obs_dim, rls[0]._clip
        self.mean = np.stack([r._mean for r in rls])[:, None, :]
        self.scale_obs = np.stack([r._scale for r in rls])[:, None, :]
        acts = [r._actor for r in rls]
        self.layers = [(np.stack([a.layers[i][0] for a in acts]), np.stack([a.layers[i][1] for a in acts])[:, None, :])
                       if isinstance(layer, tuple) else layer for i, layer in enumerate(acts[0].layers)]
        self.low = np.stack([a.low for a in acts])[:, None, :]
        self.high = np.stack([a.high for a in acts])[:, None, :]

    def reset(self, n: int) -> None:
        for p in self.pols:
            p.reset(n)
        self.base = None
        if self.residual and n > 1:   # one base controller over every block (same budget and filter: the key;
            # n = 1: each its own, as a policy alone takes the scalar path on one row)
            self.base = type(self.pols[0].base)(self.pols[0].ctx, self.pols[0].base.lpf, self.pols[0].base_budget)
            self.base.reset(self.k * n)

    def _duty(self, obs32) -> np.ndarray:
        """RLPolicy.act of each block: normalise, forward, clip, ``(a + 1) / 2``; (k n,) duties."""
        o = obs32.reshape(self.k, -1, obs32.shape[1])[:, :, :self.obs_dim]
        h = np.minimum(np.maximum((o - self.mean) * self.scale_obs, -self.clip), self.clip)
        for layer in self.layers:   # in place where h is this pass's own array: the same float32 operations
            if isinstance(layer, tuple):
                h = np.matmul(h, layer[0])
                h += layer[1]
            else:
                h = layer(h, out=h) if isinstance(layer, np.ufunc) else layer(h)
        a = np.minimum(np.maximum(h, self.low), self.high)
        return action_to_duty(a[:, :, 0].reshape(-1))

    def act(self, obs) -> np.ndarray:
        from .residual import residual_duty, residual_obs

        obs = np.atleast_2d(np.asarray(obs, dtype=np.float32))
        if not self.residual:
            return self._duty(obs)
        if self.base is not None:
            d_base = np.asarray(self.base.act(obs), dtype=float).reshape(len(obs))
        else:
            n = len(obs) // self.k
            d_base = np.concatenate([np.asarray(p.base.act(obs[b * n:(b + 1) * n]), dtype=float).reshape(n)
                                     for b, p in enumerate(self.pols)])
        a = 2.0 * self._duty(residual_obs(obs, d_base)) - 1.0
        return residual_duty(d_base, a, self.pols[0].scale)


class StackedModelBased:
    """The model-based controller and its budgeted variants (:mod:`policies.budgeted`) of one filter on
    ``k`` blocks of ``n`` rows as one controller with a budget per row (``model_based`` = budget 0:
    ``ref + 0`` is ``ref``); the vector path of each policy alone (``n > 1``; one row takes the scalar
    path, so :class:`BlockPolicy` stacks only ``n > 1``)."""

    def __init__(self, pols: list):
        from .budgeted import BudgetedModelBasedPolicy

        self.pols = pols
        self.budgets = np.array([getattr(p, "budget", 0.0) for p in pols])
        self.one = BudgetedModelBasedPolicy(pols[0].ctx, pols[0].lpf, 0.0)

    def reset(self, n: int) -> None:
        self.one.reset(len(self.pols) * n)
        self.one.budget = np.repeat(self.budgets, n)   # i2_ref: where(cmd <= 0, ref + budget I2_sm, ref), per row

    def act(self, obs) -> np.ndarray:
        return self.one.act(obs)


def _stack(pols):
    return (StackedModelBased if stackable(pols[0])[0] == "model_based" else StackedRL)(pols)


class BlockPolicy:
    """Policies ``pols`` on blocks of ``n`` rows (``act`` on ``len(pols) n`` rows): policies with the same
    :func:`stackable` key (with ``n > 1``) act as one stacked policy on adjacent blocks; ``block[i]`` is
    the block of ``pols[i]`` (rows ``block[i] n .. (block[i] + 1) n - 1``)."""

    def __init__(self, pols: list, n: int):
        self.n = int(n)
        groups = {}   # key -> indices of pols, in order of first occurrence (unstackable: a group each)
        for i, p in enumerate(pols):
            key = stackable(p)
            if key is not None and key[0] == "model_based" and self.n == 1:   # one row: the scalar path alone
                key = None
            groups.setdefault(("one", i) if key is None else key, []).append(i)
        self.units, self.block = [], [0] * len(pols)   # units: (first block, number of blocks, policy)
        b = 0
        for idx in groups.values():
            for j, i in enumerate(idx):
                self.block[i] = b + j
            self.units.append((b, len(idx), _stack([pols[i] for i in idx]) if len(idx) > 1 else pols[idx[0]]))
            b += len(idx)

    def reset(self, n_rows: int) -> None:
        for _, _, p in self.units:
            p.reset(self.n)

    def act(self, obs) -> np.ndarray:
        out = np.empty(len(obs))
        n = self.n
        for b, k, p in self.units:
            rows = slice(b * n, (b + k) * n)
            d = np.asarray(p.act(obs[rows].copy()), dtype=float)
            if d.size != k * n or not np.isfinite(d).all():   # named here: the env's error names neither policy nor shape
                raise _act_error(p, d, k * n)
            out[rows] = d.reshape(k * n)
        return out


def _act_error(p, d, n: int) -> ValueError:
    """One line naming the policy whose ``act`` gave ``d`` (not ``n`` finite duties)."""
    name = getattr(p, "name", type(p).__name__)
    if d.size != n:
        return ValueError(f"policy {name!r}: act() returned shape {d.shape}; valid: ({n},), one duty in [0, 1] per "
                          "observation row")
    bad = d.reshape(-1)[~np.isfinite(d.reshape(-1))][0]
    return ValueError(f"policy {name!r}: act() returned a duty {float(bad)!r}; valid: finite duties in [0, 1]")
