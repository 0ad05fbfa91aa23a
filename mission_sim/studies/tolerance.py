"""Tolerance Monte Carlo of the receiver (``dronewpt tolerance``) on the sweep engine.

Each draw of :func:`wpt_receiver.tolerance.draw_scales` is one case of :func:`.sweep.run_sweep`
(params: the draw index and its seven scale factors; a case id from them, the spreads, the seed and
the devices), run by :class:`ToleranceRunner` (:func:`wpt_receiver.tolerance.draw_metrics`), so
10^4 draws are chunked onto Dask workers, stored in the resumable Parquet store and survive an
interruption like any sweep. :func:`summarise` turns the rows into distributions and yields.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from .study import Case, canonical_json, case_id

__all__ = ["ToleranceRunner", "tolerance_cases", "summarise", "nominal_link_problem", "METRICS"]

METRICS = ("rm_power_w", "efficiency", "rm_i2_a", "step_peak_a", "proposed_peak_a")


_TRANSITIONS: dict = {}  # (devices name, link) -> TransitionSet, built once per process (driver or worker)


def _link(link):
    """The nominal link of a runner: ``link`` (a :class:`wpt_receiver.LinkParams`), Table I when None."""
    if link is None:
        from wpt_receiver import TABLE_I
        return TABLE_I
    return link


def nominal_link_problem(link=None, devices_name: str = "ideal", clamp_margin: float | None = None) -> str | None:
    """Why a nominal link gives no tolerance study, or None: it transfers no power in RM (its yields would count every
    draw as delivering 0.9 x 0 W, its peaks NaN). The rule is the paper's (:func:`wpt_receiver.paper.rm_emf_margin`,
    :func:`wpt_receiver.paper.envelope_range_problem`): the rectifier conducts iff the emf margin, ``clamp_margin`` of
    the closed-form RM state :func:`wpt_receiver.rm_state.rm_steady` with the study's devices, is above 1. Computed
    from ``link`` (None: Table I) and ``devices_name`` (~0.1 ms, nothing simulated) unless ``clamp_margin`` is given
    (a nominal draw's). One message for ``dronewpt tolerance --link`` (before anything is prepared) and
    :func:`summarise`."""
    if clamp_margin is None:
        from wpt_receiver.devices import preset
        from wpt_receiver.rm_state import rm_steady
        clamp_margin = float(rm_steady(_link(link), None, None, preset(devices_name))["clamp_margin"])
    if clamp_margin > 1.0:
        return None
    return (f"the nominal link transfers no power in RM: its emf margin {clamp_margin:.3g} (the induced emf over the "
            "battery clamp, |E| / (V2 |G22|)) is not above 1; valid: a nominal link whose emf margin exceeds 1 (a "
            "higher vdc_v or lm_h, a lower vl_v or r1_ohm)")


def _transitions(devices_name: str, link=None):
    """The nominal duty sequences for ``devices_name`` on ``link`` (None: Table I), built on first use in this
    process (~1.6 s of CPU with the scipy.signal import): a Dask task unpickles a fresh runner, so the cache lives
    here, not on the runner."""
    ts = _TRANSITIONS.get((devices_name, link))
    if ts is None:
        from wpt_receiver.devices import preset
        from wpt_receiver.tolerance import TransitionSet
        ts = _TRANSITIONS[(devices_name, link)] = TransitionSet.build(_link(link), devices=preset(devices_name))
    return ts


@dataclass(frozen=True)
class ToleranceRunner:
    """Case runner: params ``{"draw": j, "l1": .., "c1": .., ...}`` -> the draw's metrics. Picklable.

    ``transitions``: the nominal duty sequences (:class:`~wpt_receiver.tolerance.TransitionSet`,
    ~60 kB) when the caller has built them (:meth:`with_transitions`): they travel with the runner,
    so a Dask worker never imports scipy.signal nor re-runs the controllers (~1.6 s of CPU each);
    otherwise built once per process on first use (:func:`_transitions`). :meth:`warm` (called once
    on every worker by the sweep engine) runs the nominal draw: imports and numba's cache."""

    devices_name: str = "ideal"
    transitions: object = field(default=None, repr=False, compare=False)
    link: object = None   # the nominal link (a wpt_receiver.LinkParams; None: Table I) the draws scatter around

    def with_transitions(self) -> "ToleranceRunner":
        """This runner carrying its duty sequences (built here, once)."""
        return ToleranceRunner(self.devices_name, _transitions(self.devices_name, self.link), self.link)

    def __call__(self, params: dict) -> dict:
        from wpt_receiver.tolerance import SCALES, draw_link, draw_metrics
        p, c1, c2 = draw_link([params[k] for k in SCALES], _link(self.link))
        return draw_metrics(p, c1, c2, self.transitions or _transitions(self.devices_name, self.link))

    def warm(self) -> None:
        """The nominal draw once: imports, the duty sequences, numba's cache of the transient."""
        from wpt_receiver.tolerance import SCALES
        self({"draw": -1, **dict.fromkeys(SCALES, 1.0)})


def tolerance_cases(spreads, n: int, seed: int, devices_name: str, link=None) -> list[Case]:
    """The draws as sweep cases (scale factors rounded to 12 digits in the params: stable ids). ``link``: the nominal
    link (None or Table I: the ids as before; another link is part of every id, so a store never mixes links)."""
    from wpt_receiver import TABLE_I
    from wpt_receiver.tolerance import SCALES, draw_scales
    scales = np.round(draw_scales(spreads, n, seed), 12)
    own = {} if link is None or link == TABLE_I else {"link": {k: float(v) for k, v in vars(link).items()}}
    base = canonical_json({"spreads": [spreads.c, spreads.l, spreads.lm, spreads.r], "seed": int(seed),
                           "devices": devices_name, "study": "tolerance v1", **own})
    cases = []
    for j, row in enumerate(scales):
        params = {"draw": j, **{k: float(v) for k, v in zip(SCALES, row)}}
        pj = canonical_json(params)
        cases.append(Case(case_id(params, base, pj), params, pj))
    return cases


def _interval(x: np.ndarray) -> tuple[float, float]:
    """95 % Wilson interval of a proportion."""
    n, k = len(x), float(np.sum(x))
    if n == 0:
        return float("nan"), float("nan")
    z, ph = 1.96, k / n
    c = (ph + z * z / (2 * n)) / (1 + z * z / n)
    h = z * np.sqrt(ph * (1 - ph) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, float(c - h)), min(1.0, float(c + h))


def summarise(df: pd.DataFrame, nominal: dict, margin: float = 1.25, min_power_frac: float = 0.9) -> dict:
    """Distributions (percentiles) of :data:`METRICS` and the yields: a draw passes for a controller
    when its RM power is at least ``min_power_frac`` of the nominal and its peak |J2| is within the
    rating ``margin`` x the nominal peak of that controller (the receiver sized for the nominal
    link, as ``sizing`` does). Yields with 95 % Wilson intervals. Peak percentiles are over the draws
    that transfer power in RM (the others have NaN peaks). A nominal link that transfers no power in RM is refused
    (:func:`nominal_link_problem`)."""
    problem = nominal_link_problem(clamp_margin=nominal["clamp_margin"])
    if problem is not None:
        raise ValueError(problem)
    ok = df[df["status"] == "ok"]
    dist = {m: {q: float(np.nanpercentile(ok[m].to_numpy(float), q)) for q in (1, 5, 25, 50, 75, 95, 99)}
            | {"mean": float(np.nanmean(ok[m].to_numpy(float))), "n": int(np.isfinite(ok[m].to_numpy(float)).sum())}
            for m in METRICS}
    power_ok = ok["rm_power_w"].to_numpy() >= min_power_frac * nominal["rm_power_w"]
    yields = {"power": (float(power_ok.mean()), *_interval(power_ok))}
    for pol in ("step", "proposed"):
        rating = margin * nominal[f"{pol}_peak_a"]
        peak = ok[f"{pol}_peak_a"].to_numpy(float)
        peak_ok = peak <= rating   # NaN (no RM transfer): not within
        both = power_ok & peak_ok
        conducting = peak_ok[np.isfinite(peak)]   # the rating alone, among the draws that transfer power
        yields[f"{pol}_rating"] = (float(conducting.mean()) if len(conducting) else float("nan"), *_interval(conducting))
        yields[pol] = (float(both.mean()), *_interval(both))
        dist[f"{pol}_rating_a"] = rating
    return {"n": int(len(ok)), "n_error": int(len(df) - len(ok)), "distributions": dist, "yields": yields,
            "nominal": nominal, "margin": margin, "min_power_frac": min_power_frac,
            "estimator": _estimator_flags(ok, nominal, min_power_frac)}


def _estimator_flags(ok: pd.DataFrame, nominal: dict, min_power_frac: float) -> dict:
    """How many draws the envelope estimator is not validated for: conducting in RM but below
    ``TRUSTED_POWER_FRAC`` of the nominal power (discontinuous conduction; RM |i2| off by up to
    -97/+123 % against the switching model), and how many may sit on the other side of the power
    threshold: estimated within [0.90, 1.04) x the threshold (the estimator's measured RM error is
    -10 % at worst just below the threshold, +4 % at worst above it), so their pass / fail is uncertain."""
    from wpt_receiver.tolerance import MIN_CONDUCTION_A, TRUSTED_POWER_FRAC
    frac = ok["rm_power_w"].to_numpy(float) / nominal["rm_power_w"]
    conducting = ok["rm_i2_a"].to_numpy(float) >= MIN_CONDUCTION_A
    flagged = conducting & (frac < TRUSTED_POWER_FRAC)
    near = (frac >= 0.90 * min_power_frac) & (frac < 1.04 * min_power_frac)
    n = max(len(ok), 1)
    return {"trusted_power_frac": TRUSTED_POWER_FRAC, "flagged": int(flagged.sum()), "flagged_frac": float(flagged.sum() / n),
            "near_threshold": int(near.sum()), "near_threshold_frac": float(near.sum() / n),
            "blocked": int((~conducting).sum())}
