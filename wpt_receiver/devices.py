"""Semiconductor devices of the link: piecewise-linear conduction models and the shipped parts.

Every device is modelled in conduction only (switching losses and capacitances are left out):

* a diode conducts forward as ``v = vf0_v + rd_ohm * i`` (``i > 0``) and blocks otherwise;
* a MOSFET channel conducts either way as ``v = ron_ohm * i``; its body diode is a diode.

Where they sit (paper Fig. 2, SBAR = semi-bridgeless active rectifier):

* inverter: four switches; driven, two channels are in series with the primary
  (``v1 = +-Vdc - 2 Ron i1``); in dead time the current freewheels through two body diodes
  (``v1 = -sign(i1) (Vdc + 2 Vf0) - 2 Rd i1``);
* SBAR in rectification: one upper diode and one lower body diode in series with the secondary
  (``v2 = sign(i2) (VL + Vf0_d + Vf0_b) + (Rd_d + Rd_b) i2``);
* SBAR shorted (both lower gates on): two channels in series (``v2 = 2 Ron i2``).

:data:`IDEAL` (all zero) is the paper's circuit. :func:`preset` builds a :class:`DeviceSet` from
the shipped table ``parts.toml`` (datasheet values and sources in that file), :func:`parts`
lists it.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from functools import cached_property, lru_cache
from importlib import resources

__all__ = ["Diode", "Switch", "DeviceSet", "IDEAL", "parts", "preset", "preset_names", "device_set"]


def _check_nonneg(obj) -> None:
    for fld in fields(obj):
        v = getattr(obj, fld.name)
        if isinstance(v, float) and not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{fld.name}={v!r} is invalid; valid range: [0, inf)")


@dataclass(frozen=True)
class Diode:
    """Forward drop ``vf0_v`` [V] plus slope resistance ``rd_ohm`` [ohm] of one conducting diode."""

    vf0_v: float = 0.0
    rd_ohm: float = 0.0

    def __post_init__(self):
        _check_nonneg(self)


@dataclass(frozen=True)
class Switch:
    """MOSFET: channel on-resistance ``ron_ohm`` [ohm] and its body diode."""

    ron_ohm: float = 0.0
    body: Diode = Diode()

    def __post_init__(self):
        _check_nonneg(self)


@dataclass(frozen=True)
class DeviceSet:
    """The link's devices: SBAR upper diodes, SBAR lower switches, inverter switches.

    ``name`` labels the set (a preset name or ``"ideal"``). Derived series quantities used by the
    circuit models are properties (per conduction path, i.e. two devices in series).
    """

    rect_diode: Diode = Diode()
    rect_switch: Switch = Switch()
    inv_switch: Switch = Switch()
    name: str = "ideal"

    @property
    def rect_vf_v(self) -> float:
        """Forward drop of the rectifying path: upper diode + lower body diode [V]."""
        return self.rect_diode.vf0_v + self.rect_switch.body.vf0_v

    @property
    def rect_rd_ohm(self) -> float:
        """Slope resistance of the rectifying path [ohm]."""
        return self.rect_diode.rd_ohm + self.rect_switch.body.rd_ohm

    @property
    def short_r_ohm(self) -> float:
        """Resistance of the shorted SBAR: two lower channels [ohm]."""
        return 2.0 * self.rect_switch.ron_ohm

    @property
    def inv_r_ohm(self) -> float:
        """Resistance of the driven inverter path: two channels [ohm]."""
        return 2.0 * self.inv_switch.ron_ohm

    @property
    def fw_vf_v(self) -> float:
        """Forward drop of the freewheeling path in dead time: two body diodes [V]."""
        return 2.0 * self.inv_switch.body.vf0_v

    @property
    def fw_rd_ohm(self) -> float:
        """Slope resistance of the freewheeling path [ohm]."""
        return 2.0 * self.inv_switch.body.rd_ohm

    @cached_property   # asked every mission step; the set is frozen
    def is_ideal(self) -> bool:
        return all(v == 0.0 for v in (self.rect_vf_v, self.rect_rd_ohm, self.short_r_ohm, self.inv_r_ohm,
                                      self.fw_vf_v, self.fw_rd_ohm))


IDEAL = DeviceSet()


@lru_cache(maxsize=1)
def parts() -> dict:
    """The shipped parts table: ``{"diode": {name: row}, "switch": {...}, "preset": {...}}``."""
    text = resources.files(__package__).joinpath("parts.toml").read_text(encoding="utf-8")
    raw = tomllib.loads(text)
    return {"diode": {r["name"]: r for r in raw["diode"]}, "switch": {r["name"]: r for r in raw["switch"]},
            "preset": raw["preset"]}


def preset_names() -> list[str]:
    """Names accepted by :func:`preset` (plus ``"ideal"``)."""
    return ["ideal", *parts()["preset"]]


def _diode(name: str) -> Diode:
    row = parts()["diode"].get(name)
    if row is None:
        raise ValueError(f"diode part {name!r} is unknown; valid: {', '.join(parts()['diode'])}")
    return Diode(row["vf0_v"], row["rd_ohm"])


def _switch(name: str) -> Switch:
    row = parts()["switch"].get(name)
    if row is None:
        raise ValueError(f"switch part {name!r} is unknown; valid: {', '.join(parts()['switch'])}")
    return Switch(row["ron_ohm"], Diode(row["body_vf0_v"], row["body_rd_ohm"]))


def device_set(rect_diode: str, rect_switch: str, inv_switch: str, name: str | None = None) -> DeviceSet:
    """A :class:`DeviceSet` from part names of the shipped table."""
    return DeviceSet(_diode(rect_diode), _switch(rect_switch), _switch(inv_switch),
                     name or f"{rect_diode}/{rect_switch}/{inv_switch}")


def preset(name: str) -> DeviceSet:
    """Named device set: ``"ideal"`` (the paper's circuit) or a preset of ``parts.toml``."""
    if name == "ideal":
        return IDEAL
    row = parts()["preset"].get(name)
    if row is None:
        raise ValueError(f"device preset {name!r} is unknown; valid: {', '.join(preset_names())}")
    return device_set(row["rect_diode"], row["rect_switch"], row["inv_switch"], name)


def envelope_params(params, devices: DeviceSet):
    """Link parameters for the envelope model with the devices' constant resistances folded in:
    ``R1 + 2 Ron`` (driven inverter channels) and ``R2 + Rd`` (rectifying path). The forward
    drops and the short-window resistance enter through
    :func:`wpt_receiver.sbar.rectifier_v2_folded` (V2 without the folded ``Rd I2``)."""
    if devices.is_ideal:
        return params
    return params.with_(r1_ohm=params.r1_ohm + devices.inv_r_ohm, r2_ohm=params.r2_ohm + devices.rect_rd_ohm)
