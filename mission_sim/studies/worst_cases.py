"""The worst case of each policy in a sweep's results (``dronewpt sizing --source sweep``).

A sweep stores one summary row per mission, not the time series a rectifier sizing needs (RMS and
average device currents). The case that sets the rating is the one with the largest instantaneous
``peak_i2_a``; :func:`worst_cases` finds it per policy among the cases stored ``ok``, and
:func:`case_config` rebuilds its mission from the stored parameters and the base mission, so the
caller can re-run exactly that mission and size from its time series. The base mission must be the
one the sweep ran on: its fingerprint (the manifest's, :mod:`.status`) is checked.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

from .status import read_manifest
from .store import CaseStore
from .study import POLICY_KEY, canonical_json

__all__ = ["WorstCase", "base_fingerprint", "worst_cases", "case_config"]


@dataclass(frozen=True)
class WorstCase:
    """The case of ``policy`` with the largest ``metric`` among ``n_cases`` stored ok."""

    policy: str
    case_id: str
    params: dict
    value: float
    n_cases: int


def base_fingerprint(base: dict) -> str:
    """Fingerprint of a base mission dict as a sweep records it (``sweep.json``'s ``fingerprint``)."""
    return hashlib.sha256(canonical_json(base).encode()).hexdigest()[:16]


def worst_cases(out_dir, metric: str = "peak_i2_a", base: dict | None = None) -> list[WorstCase]:
    """Per policy (in order of first appearance), the stored ok case with the largest ``metric``.

    ``base`` (the base mission dict, ``config_to_dict``) is checked against the manifest's
    fingerprint when given. ``ValueError`` naming the folder when it holds no sweep, no ok rows, no
    ``metric`` column, or was run on another base mission or with a custom case runner."""
    man = read_manifest(out_dir, "--sweep")
    head = man["doc"].get("study")   # (a damaged manifest's "study": null was an AttributeError traceback)
    if isinstance(head, dict) and head.get("runner"):
        raise ValueError(f"sweep {str(out_dir)!r} ran a custom case runner ({head['runner']}); "
                         "valid: a sweep of missions")
    if man["doc"].get("replay"):   # (said "ran on base mission ...; valid: the study's base mission")
        raise ValueError(f"sweep {str(out_dir)!r} replayed a flight log ([replay] section), its cases are not "
                         "missions to re-run; valid: a sweep of missions")
    if base is not None and base_fingerprint(base) != man["fingerprint"]:
        raise ValueError(f"sweep {str(out_dir)!r} ran on base mission {man['fingerprint']}, the given mission is "
                         f"{base_fingerprint(base)}; valid: the study's base mission (--config)")
    df = CaseStore(out_dir).read()
    if metric not in df.columns:
        raise ValueError(f"sweep {str(out_dir)!r} has no column {metric!r}; valid: a sweep of missions")
    ok = df[df["status"] == "ok"]
    if ok.empty:
        raise ValueError(f"sweep {str(out_dir)!r} has no case stored ok ({len(df)} rows); valid: a finished sweep")
    rows = []
    for policy, grp in ok.groupby(POLICY_KEY, sort=False):
        top = grp.loc[grp[metric].idxmax()]
        rows.append(WorstCase(policy=str(policy), case_id=str(top["case_id"]), params=json.loads(top["params_json"]),
                              value=float(top[metric]), n_cases=len(grp)))
    return rows


def case_config(base: dict, params: dict, extra: dict | None = None):
    """The MissionConfig of a case: ``base`` with the case's overrides (all but ``policy``), then ``extra``."""
    from ..config import apply_overrides, config_from_dict

    overrides = {k: v for k, v in params.items() if k != POLICY_KEY}
    return config_from_dict(apply_overrides(base, {**overrides, **(extra or {})}))
