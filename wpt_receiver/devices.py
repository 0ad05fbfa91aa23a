"""Semiconductor devices of the link: piecewise-linear conduction models and the shipped parts.

Conduction is piecewise linear:

* a diode conducts forward as ``v = vf0_v + rd_ohm * i`` (``i > 0``) and blocks otherwise;
* a MOSFET channel conducts either way as ``v = ron_ohm * i``; its body diode is a diode.

Beyond conduction (issue 23) each device carries the datasheet data of its edges: a diode's
charge-equivalent junction capacitance ``c_f`` and carrier transit time ``tt_s`` (reverse recovery,
``Qrr = tt^2 di/dt``), a switch's output capacitance ``coss_f`` and its overlap energies per volt-ampere
``eon_j_va`` / ``eoff_j_va`` (``E = k V I``, the datasheet's ``E_ref / (V_ref I_ref)``). They are
used by :mod:`wpt_receiver.edge_losses` (energy per switching edge) and :mod:`wpt_receiver.thermal`
(junction temperature); the conduction models ignore them. :func:`preset` with ``tj_c`` gives the
conduction values at a junction temperature (linear between the table's 25 and 125 C data).

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

__all__ = ["Diode", "Switch", "DeviceSet", "IDEAL", "parts", "preset", "link_preset", "preset_names", "device_set",
           "charge_equivalent_f", "rect_node_c_f", "diode_from_row", "switch_from_row", "V_BLOCK_V",
           "current_rating"]

V_BLOCK_V = 30.0   # default blocking voltage for the charge-equivalent capacitances: Table I's VL [V] (and Vdc);
#                    a link of its own: :func:`link_preset` (the rectifier's at its VL, the inverter's at its Vdc)


def _check_nonneg(obj) -> None:
    for fld in fields(obj):
        v = getattr(obj, fld.name)
        if isinstance(v, float) and not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{fld.name}={v!r} is invalid; valid range: [0, inf)")


@dataclass(frozen=True)
class Diode:
    """Forward drop ``vf0_v`` [V] plus slope resistance ``rd_ohm`` [ohm] of one conducting diode;
    ``c_f`` junction capacitance (charge-equivalent at the blocking voltage) [F], ``tt_s`` carrier
    transit time [s] (0 for a Schottky: no reverse recovery)."""

    vf0_v: float = 0.0
    rd_ohm: float = 0.0
    c_f: float = 0.0
    tt_s: float = 0.0

    def __post_init__(self):
        _check_nonneg(self)


@dataclass(frozen=True)
class Switch:
    """MOSFET: channel on-resistance ``ron_ohm`` [ohm] and its body diode; ``coss_f`` output
    capacitance (charge-equivalent at the blocking voltage) [F]; ``eon_j_va`` / ``eoff_j_va``
    overlap energy of a hard turn-on / turn-off per volt and ampere switched [J/(V A)]."""

    ron_ohm: float = 0.0
    body: Diode = Diode()
    coss_f: float = 0.0
    eon_j_va: float = 0.0
    eoff_j_va: float = 0.0

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


def charge_equivalent_f(c_ref_f: float, v_ref_v: float, v_v: float, phi_v: float = 0.5) -> float:
    """Charge-equivalent capacitance [F] over ``0 .. v_v`` of a junction capacitance given as
    ``c_ref_f`` at ``v_ref_v``, with the abrupt-junction law ``C(v) = C0 / sqrt(1 + v / phi)``:
    ``Q(V) = 2 C0 phi (sqrt(1 + V/phi) - 1)``, returned as ``Q / V``; ``v_v`` a number or an array (one per step)."""
    if isinstance(v_v, (list, tuple)) or getattr(v_v, "ndim", 0):
        import numpy as np
        v, sqrt = np.asarray(v_v, dtype=float), np.sqrt
        if c_ref_f <= 0.0:
            return np.zeros(v.shape)
    else:
        v, sqrt = v_v, math.sqrt
        if c_ref_f <= 0.0:
            return 0.0
    c0 = c_ref_f * math.sqrt(1.0 + v_ref_v / phi_v)
    return 2.0 * c0 * phi_v * (sqrt(1.0 + v / phi_v) - 1.0) / v


def _cj_f(row: dict, v_block_v):
    """One die of ``parts.toml`` diode ``row``: its junction capacitance charge-equivalent at ``v_block_v`` [F] (a
    number or an array); :func:`diode_from_row`'s and :func:`rect_node_c_f`'s one source."""
    return charge_equivalent_f(row.get("cj_ref_f", 0.0), row.get("cj_ref_v", 1.0), v_block_v)


def _coss_f(row: dict, v_block_v):
    """One die of ``parts.toml`` switch ``row``: its Coss charge-equivalent at ``v_block_v`` [F] (a number or an
    array); :func:`switch_from_row`'s and :func:`rect_node_c_f`'s one source."""
    return charge_equivalent_f(row.get("coss_ref_f", 0.0), row.get("coss_ref_v", 1.0), v_block_v)


def rect_node_c_f(name: str, v_block_v):
    """The SBAR node's capacitance [F] of preset ``name`` (its rectifier switch's Coss + diode's Cj, one die each, as
    :func:`preset` builds them: :func:`_coss_f`, :func:`_cj_f`), charge-equivalent at ``v_block_v`` [V]: a number or
    one per step (a mission's ``battery_v``, for its edge energies at each step's own voltage), each finite and > 0
    (:func:`wpt_receiver.params.positive_numbers`); 0 for "ideal"."""
    from .params import positive_numbers
    v = positive_numbers("v_block_v", v_block_v, "V")
    row = _preset_row(name)
    if row is None:
        return 0.0 * v
    return _coss_f(_row("switch", row["rect_switch"]), v) + _cj_f(_row("diode", row["rect_diode"]), v)


def _tt_s(qrr_c: float, didt_a_s: float) -> float:
    """Transit time of the charge-control diode model that recovers ``qrr_c`` at ``didt_a_s``:
    with a linear current fall the charge left at the zero crossing is ``tt^2 di/dt``."""
    return math.sqrt(qrr_c / didt_a_s) if qrr_c > 0 and didt_a_s > 0 else 0.0


def _at(row: dict, key: str, tc_key: str, tj_c, relative: bool = False) -> float:
    """Row value ``key`` at ``t_ref_c`` moved linearly to ``tj_c`` by its coefficient ``tc_key``."""
    v = row[key]
    if tj_c is None:
        return v
    dt = float(tj_c) - row.get("t_ref_c", 25.0)
    tc = row.get(tc_key, 0.0)
    return max(v * (1.0 + tc * dt), 0.0) if relative else max(v + tc * dt, 0.0)


def diode_from_row(row: dict, n: int = 1, tj_c=None, v_block_v: float = V_BLOCK_V) -> Diode:
    """A rectifier :class:`Diode` of ``n`` paralleled legs of a ``parts.toml`` diode row at junction
    temperature ``tj_c`` [C] (``None``: the row's ``t_ref_c`` values) blocking ``v_block_v``."""
    return Diode(_at(row, "vf0_v", "vf0_tc_v_k", tj_c), _at(row, "rd_ohm", "rd_tc_per_k", tj_c, True) / n,
                 n * _cj_f(row, v_block_v), 0.0)


def switch_from_row(row: dict, n: int = 1, tj_c=None, v_block_v: float = V_BLOCK_V) -> Switch:
    """A :class:`Switch` of ``n`` paralleled dies of a ``parts.toml`` switch row at ``tj_c`` [C]
    (``None``: 25 C, the row's ``ron_ohm``): R_DS(on) linear between 25 and 125 C, body knee by its
    coefficient, Coss charge-equivalent at ``v_block_v``, overlap energies per V A (n dies share the
    current: the total stays ``k V I``), recovery transit time from ``qrr_c`` at ``qrr_didt_a_s``."""
    ron = row["ron_ohm"]
    if tj_c is not None and "ron_125_ohm" in row:
        ron = max(ron + (row["ron_125_ohm"] - ron) * (float(tj_c) - 25.0) / 100.0, 0.0)
    vf = row["body_vf0_v"] + (0.0 if tj_c is None else row.get("body_vf0_tc_v_k", 0.0) * (float(tj_c) - 25.0))
    body = Diode(max(vf, 0.0), row["body_rd_ohm"] / n, 0.0, _tt_s(row.get("qrr_c", 0.0), row.get("qrr_didt_a_s", 0.0)))
    va = row.get("e_ref_v", 1.0) * row.get("e_ref_a", 1.0)
    return Switch(ron / n, body, n * _coss_f(row, v_block_v), row.get("eon_ref_j", 0.0) / va,
                  row.get("eoff_ref_j", 0.0) / va)


def _row(kind: str, name: str) -> dict:
    row = parts()[kind].get(name)
    if row is None:
        raise ValueError(f"{kind} part {name!r} is unknown; valid: {', '.join(parts()[kind])}")
    return row


def device_set(rect_diode: str, rect_switch: str, inv_switch: str, name: str | None = None, tj_c=None,
               v_block_v: float = V_BLOCK_V, v_block_inv_v: float | None = None) -> DeviceSet:
    """A :class:`DeviceSet` from part names of the shipped table (at junction temperature ``tj_c``); the rectifier's
    capacitances charge-equivalent at ``v_block_v`` [V], the inverter switch's at ``v_block_inv_v`` [V] (None: the
    same)."""
    v_inv = v_block_v if v_block_inv_v is None else v_block_inv_v
    return DeviceSet(diode_from_row(_row("diode", rect_diode), 1, tj_c, v_block_v),
                     switch_from_row(_row("switch", rect_switch), 1, tj_c, v_block_v),
                     switch_from_row(_row("switch", inv_switch), 1, tj_c, v_inv),
                     name or f"{rect_diode}/{rect_switch}/{inv_switch}")


def preset(name: str, tj_c=None, v_block_v: float = V_BLOCK_V, v_block_inv_v: float | None = None) -> DeviceSet:
    """Named device set: ``"ideal"`` (the paper's circuit) or a preset of ``parts.toml``; ``tj_c``
    [C] moves the conduction values to that junction temperature (``None``: the table's values,
    125 C Schottky data and 25 C MOSFET data); ``v_block_v`` [V] sets the rectifier's charge-equivalent
    capacitances, ``v_block_inv_v`` [V] the inverter switch's (None: ``v_block_v``; both default to Table I's 30 V:
    a link of its own takes :func:`link_preset`)."""
    from .params import positive_number
    v_block_v = positive_number("v_block_v", v_block_v, "V")   # (checked for "ideal" too: one API, one rule)
    if v_block_inv_v is not None:
        v_block_inv_v = positive_number("v_block_inv_v", v_block_inv_v, "V")
    row = _preset_row(name)
    if row is None:
        return IDEAL
    if tj_c is not None and not (math.isfinite(tj_c) and -55.0 <= tj_c <= 200.0):
        raise ValueError(f"tj_c={tj_c!r} is invalid; valid range: [-55, 200] C")
    return device_set(row["rect_diode"], row["rect_switch"], row["inv_switch"], name, tj_c, v_block_v, v_block_inv_v)


def link_preset(name: str, params, tj_c=None) -> DeviceSet:
    """:func:`preset` ``name`` on the link ``params`` (a :class:`wpt_receiver.params.LinkParams`): the SBAR's
    devices block its battery voltage ``vl_v``, the inverter's switches its ``vdc_v``, so their charge-equivalent
    capacitances (:func:`charge_equivalent_f`; the edge energies of :mod:`wpt_receiver.edge_losses`) are taken there
    instead of at Table I's 30 V (a 2S pack, 7.4 V: the SBAR node's Coss + Cj 2.96 nF, not 1.67 nF). Table I gives
    :func:`preset`'s devices."""
    return preset(name, tj_c, v_block_v=params.vl_v, v_block_inv_v=params.vdc_v)


def current_rating(name: str) -> tuple[float, str, str] | None:
    """``(rating_a, part, position)`` of the lowest continuous current rating [A] among preset ``name``'s parts that
    carry the secondary current: the SBAR's upper diode (a leg: ``parts.toml``'s ``rating_a`` is per leg, the
    datasheet's average I_F(AV) for the Schottky rectifiers) and lower switch (a die), one of each per conducting
    position (:func:`device_set`'s ``n = 1``), so each carries the whole ``|i2|`` while it conducts; ``position`` is
    ``"rectifier diode"`` or ``"rectifier switch"``. None for ``"ideal"`` (no parts). A mission's summary reports it
    beside its peak (``rectifier_rating_a``, ``rectifier_rating_part``); :func:`wpt_receiver.sizing.select_parts`
    asks each part's rating to cover ``SizingRules.margin`` x the peak."""
    row = _preset_row(name)
    if row is None:
        return None
    held = [(_row("diode", row["rect_diode"])["rating_a"], row["rect_diode"], "rectifier diode"),
            (_row("switch", row["rect_switch"])["rating_a"], row["rect_switch"], "rectifier switch")]
    return min(held, key=lambda h: h[0])


def _preset_row(name: str) -> dict | None:
    """``parts.toml``'s ``[preset.NAME]`` row of ``name``; None for ``"ideal"`` (no parts); ``ValueError`` naming
    the valid names for an unknown one (:func:`preset` and :func:`current_rating`'s one lookup)."""
    if name == "ideal":
        return None
    row = parts()["preset"].get(name)
    if row is None:
        raise ValueError(f"device preset {name!r} is unknown; valid: {', '.join(preset_names())}")
    return row


def envelope_params(params, devices: DeviceSet):
    """Link parameters for the envelope model with the devices' constant resistances folded in:
    ``R1 + 2 Ron`` (driven inverter channels) and ``R2 + Rd`` (rectifying path). The forward
    drops and the short-window resistance enter through
    :func:`wpt_receiver.sbar.rectifier_v2_folded` (V2 without the folded ``Rd I2``)."""
    if devices.is_ideal:
        return params
    return params.with_(r1_ohm=params.r1_ohm + devices.inv_r_ohm, r2_ohm=params.r2_ohm + devices.rect_rd_ohm)
