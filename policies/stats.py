"""Statistics of a comparison: means with 95 % bootstrap intervals, paired differences on the same
episodes, and aggregation over training seeds.

* **episode level**: the percentile bootstrap of the mean (``B`` resamples of the episodes,
  seeded: the same intervals on every run);
* **paired**: every policy runs the same seeded windows, so a difference against a reference
  policy is taken episode by episode and bootstrapped the same way;
* **training seeds**: a learned policy of one kind trained with ``k`` seeds is summarised by the
  mean over seeds of its per-seed means, with a t interval over the ``k`` seed means (the
  variation between trainings, which the episode bootstrap of one model does not see).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["bootstrap_ci", "mean_ci", "seed_ci", "pareto_front", "N_BOOT"]

N_BOOT = 2000


def bootstrap_ci(x, n_boot: int = N_BOOT, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``x`` (NaNs dropped; (nan, nan) when empty)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return float("nan"), float("nan")
    if len(x) == 1 or np.all(x == x[0]):
        return float(x[0]), float(x[0])
    means = x[_resamples(len(x), n_boot, seed)].mean(axis=1)
    a = 0.5 * (1.0 - level)
    lo, hi = np.quantile(means, [a, 1.0 - a])
    return float(lo), float(hi)


@lru_cache(maxsize=8)
def _resamples(n: int, n_boot: int, seed: int) -> np.ndarray:
    """The bootstrap's resample indices (n_boot, n) of ``default_rng(seed)``: the same for every metric and
    policy of a comparison with ``n`` episodes, so drawn once (read-only)."""
    idx = np.random.default_rng(seed).integers(0, n, (n_boot, n))
    idx.setflags(write=False)
    return idx


def mean_ci(x, **kw) -> tuple[float, float, float]:
    """``(mean, lo, hi)`` of ``x`` over its finite values with the bootstrap interval."""
    x = np.asarray(x, dtype=float)
    fin = x[np.isfinite(x)]
    m = float(fin.mean()) if len(fin) else float("nan")
    return (m, *bootstrap_ci(fin, **kw))


def seed_ci(seed_means, level: float = 0.95) -> tuple[float, float, float]:
    """``(mean, lo, hi)`` over training seeds: Student t interval of the mean of the seed means (the t
    quantile from ``scipy.special.stdtrit``, which ``scipy.stats.t.ppf`` calls: the same numbers without
    importing scipy.stats, ~0.5 s; at 95 % from a table of its values, :func:`_t_quantile`)."""
    x = np.asarray(seed_means, dtype=float)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return float("nan"), float("nan"), float("nan")
    m = float(x.mean())
    if len(x) == 1:
        return m, m, m
    h = float(_t_quantile(len(x) - 1, 0.5 + 0.5 * level) * x.std(ddof=1) / np.sqrt(len(x)))
    return m, m - h, m + h


#: ``scipy.special.stdtrit(df, 0.975)`` for df = 1..30 (95 % intervals over up to 31 training seeds), the same
#: floats (``tests/test_compare_batched.py``) without importing scipy.special (~0.1-0.25 s)
_T975 = (12.706204736174694, 4.302652729749462, 3.1824463052837078, 2.7764451051977934, 2.5705818356363146,
         2.4469118511449786, 2.364624251592784, 2.306004135204166, 2.262157162798205, 2.228138851986274,
         2.200985160091639, 2.1788128296672284, 2.1603686564627913, 2.144786687917804, 2.131449545559776,
         2.1199052992212546, 2.1098155778333156, 2.1009220402410382, 2.0930240544083087, 2.085963447265864,
         2.0796138447276795, 2.0738730679040254, 2.0686576104190486, 2.0638985616280245, 2.0595385527532972,
         2.0555294386428735, 2.0518305164802846, 2.0484071417952454, 2.045229642132703, 2.0422724563012378)


def _t_quantile(df: int, p: float) -> float:
    """Student's t quantile (``scipy.special.stdtrit``; tabulated for the 95 % level up to 30 degrees of freedom)."""
    if p == 0.975 and 1 <= df <= len(_T975):
        return _T975[df - 1]
    from scipy.special import stdtrit
    return float(stdtrit(df, p))


def pareto_front(cost, value) -> np.ndarray:
    """Indices of the points not dominated (lower ``cost`` and higher ``value`` are better), sorted by cost."""
    cost, value = np.asarray(cost, dtype=float), np.asarray(value, dtype=float)
    idx = [i for i in range(len(cost))
           if not np.any((cost <= cost[i]) & (value >= value[i]) & ((cost < cost[i]) | (value > value[i])))]
    return np.array(sorted(idx, key=lambda i: cost[i]), dtype=int)
