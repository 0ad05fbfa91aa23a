"""Link parameters of the series-series WPT link with an SBAR receiver.

The default values are the paper's Table I (Fujimoto, Hamada, Fujimoto, "Proposal on model
based current overshoot suppression of receiver side coil in drone WPT system").
All values are SI: henry, ohm, volt, hertz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

__all__ = ["LinkParams", "TABLE_I"]


@dataclass(frozen=True)
class LinkParams:
    """Parameters of the WPT link (paper Table I by default).

    Attributes
    ----------
    l1_h, l2_h : primary / secondary self inductance [H]
    lm_h : mutual inductance [H]
    r1_ohm, r2_ohm : primary / secondary coil resistance [ohm]
    vdc_v : inverter DC input voltage [V]
    vl_v : battery (load) DC voltage [V]
    f_hz : inverter switching frequency = resonant frequency [Hz]
    """

    l1_h: float = 236e-6
    l2_h: float = 18.9e-6
    lm_h: float = 6.25e-6
    r1_ohm: float = 108e-3
    r2_ohm: float = 32.5e-3
    vdc_v: float = 30.0
    vl_v: float = 30.0
    f_hz: float = 85e3

    def __post_init__(self) -> None:
        for fld in fields(self):
            value = getattr(self, fld.name)
            if isinstance(value, (bool, np.bool_)):   # float(True) = 1.0 would pass as 1 H, 1 ohm, 1 Hz
                raise ValueError(f"{fld.name}={value!r} is not a number; valid range: (0, inf)")
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise ValueError(f"{fld.name}={value!r} is not a number; valid range: (0, inf)") from None
            if not math.isfinite(value) or value <= 0.0:
                raise ValueError(f"{fld.name}={value!r} is invalid; valid range: (0, inf), finite")
            object.__setattr__(self, fld.name, value)
        k = self.k
        if k >= 1.0:
            raise ValueError(
                f"coupling k = lm_h/sqrt(l1_h*l2_h) = {k:.4g} (lm_h={self.lm_h!r}) is invalid; "
                f"valid range: 0 < k < 1, i.e. lm_h < {math.sqrt(self.l1_h * self.l2_h):.6g} H"
            )

    # ------------------------------------------------------------------ derived
    @property
    def omega_rad_s(self) -> float:
        """Angular switching frequency omega = 2 pi f [rad/s]."""
        return 2.0 * math.pi * self.f_hz

    @property
    def k(self) -> float:
        """Coupling coefficient k = Lm / sqrt(L1 L2) [-]."""
        return self.lm_h / math.sqrt(self.l1_h * self.l2_h)

    @property
    def v1_amp_v(self) -> float:
        """Fundamental amplitude of the inverter square wave, V1 = (4/pi) Vdc [V]."""
        return 4.0 / math.pi * self.vdc_v

    @property
    def v2_rm_amp_v(self) -> float:
        """Fundamental amplitude of v2 in rectification mode, (4/pi) VL [V] (eq. 9 at d=0)."""
        return 4.0 / math.pi * self.vl_v

    @property
    def rectifier_period_s(self) -> float:
        """SBAR operating period T = half the inverter period [s]."""
        return 0.5 / self.f_hz

    def with_(self, **changes: float) -> "LinkParams":
        """Copy with some fields changed (validated again); an unknown field name is a ValueError naming the
        valid ones (``with_(lm=...)`` gave dataclasses' TypeError about ``__init__``)."""
        names = [f.name for f in fields(self)]
        bad = [k for k in changes if k not in names]
        if bad:
            raise ValueError(f"{bad[0]!r} is not a LinkParams field; valid: {', '.join(names)}")
        return replace(self, **changes)


TABLE_I = LinkParams()
