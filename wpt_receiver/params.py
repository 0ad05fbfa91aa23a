"""Link parameters of the series-series WPT link with an SBAR receiver.

The default values are the paper's Table I (Fujimoto, Hamada, Fujimoto, "Proposal on model
based current overshoot suppression of receiver side coil in drone WPT system").
All values are SI: henry, ohm, volt, hertz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

__all__ = ["LinkParams", "TABLE_I", "FREQUENCY_TOLERANCE", "resonance_warning", "warn_off_resonance", "positive_number",
           "positive_numbers"]


def positive_number(name: str, value, unit: str = "", what: str = "") -> float:
    """``value`` as a float after checking it is one finite number > 0 (a Python or numpy number; a bool is refused:
    float(True) = 1.0 would pass as 1 H, 1 ohm, 1 Hz, 1 V): the check of every :class:`LinkParams` field, for any
    other link quantity too (:func:`positive_numbers` for one per step; :func:`check_v1`). The error is one line naming
    ``name``, the value and the range ``(0, inf)``, in ``unit`` when given, ``what`` after it in brackets."""
    rng = f"(0, inf){' ' + unit if unit else ''}{f' ({what})' if what else ''}"
    if isinstance(value, (bool, np.bool_)) or (isinstance(value, np.ndarray) and value.ndim):
        raise ValueError(f"{name}={value!r} is not a number; valid range: {rng}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is not a number; valid range: {rng}") from None
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name}={v!r} is invalid; valid range: {rng}")
    return v


def positive_numbers(name: str, values, unit: str = "", size: int | None = None, what: str = "",
                     any_shape: bool = False):
    """:func:`positive_number` for a number or a 1-D sequence of them (e.g. one per step of a run: ``size`` of them
    when given; ``any_shape``: an array of any shape, for a function that broadcasts): the float (a number) or float
    array, after checking every entry; the error names the first bad entry (or the length, or the type) and the valid
    range."""
    if np.ndim(values) == 0:
        return positive_number(name, values, unit, what)
    rng = f"(0, inf){' ' + unit if unit else ''}{f' ({what})' if what else ''}"
    if (values.dtype.kind == "b" if isinstance(values, np.ndarray)
            else any(isinstance(v, (bool, np.bool_)) for v in np.ravel(np.asarray(values, dtype=object)))):
        raise ValueError(f"{name} holds a bool; valid range: {rng}")
    try:
        v = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} holds a value that is not a number; valid range: {rng}") from None
    if not any_shape and (v.ndim != 1 or (size is not None and v.size != size)):
        want = "a number or a 1-D sequence" + ("" if size is None else f" of {size} (one per step)")
        raise ValueError(f"{name} of shape {v.shape} is invalid; valid: {want}")
    bad = ~(np.isfinite(v) & (v > 0))
    if np.any(bad):
        positive_number(name, float(v[bad].flat[0]), unit, what)   # (raises, naming the first bad entry)
    return v


def lm_limit_h(p) -> float:
    """The mutual inductance [H] at which the coupling ``k = Lm / sqrt(L1 L2)`` reaches 1 (``p``: a link, anything with
    ``l1_h`` and ``l2_h``): every valid Lm lies below it (:class:`LinkParams`, :func:`wpt_receiver.envelope.check_lm`)."""
    return math.sqrt(p.l1_h * p.l2_h)


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
            object.__setattr__(self, fld.name, positive_number(fld.name, getattr(self, fld.name)))
        lim = lm_limit_h(self)
        if not self.lm_h < lim:   # (the rule of envelope.check_lm too: one limit, one comparison)
            raise ValueError(
                f"coupling k = lm_h/sqrt(l1_h*l2_h) = {self.k:.4g} (lm_h={self.lm_h!r}) is invalid; "
                f"valid range: 0 < k < 1, i.e. lm_h < {lim:.6g} H"
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

    def at_default_vl(self) -> "LinkParams":
        """This link at ``LinkParams``' default VL: the key of tables that hold the pack voltage only on their own
        grid or through the inverter's harmonics (the env's peak table, the modal MPC's SBAR table), so that links
        differing only in VL share one."""
        return self.with_(vl_v=type(self)().vl_v)


TABLE_I = LinkParams()


#: the drive frequency may be this factor off the tanks' resonance, either way, before :func:`resonance_warning` says
#: so. Every model here tunes C1, C2 to ``f_hz`` (C = 1 / ((2 pi f)^2 L)), so the link runs resonant whatever f_hz;
#: and a resonant series-series link drives its secondary as a current source, I2 = V1 / (2 pi f Lm) in rectification
#: mode: at twice the coil pair's own resonance it carries half the current (the default mission's peak I2 13.3 A at
#: 85 kHz, 6.8 A at 170 kHz, 0.084 A and almost no charge at 13.56 MHz), at half of it twice the current
FREQUENCY_TOLERANCE = 2.0


def check_v1(v1_v, array_ok: bool = False):
    """``v1_v`` [V], the inverter's fundamental amplitude, as a float after checking it is in (0, inf) (a NaN gave a
    NaN run or duty, a negative V1 short mode, without a word): one rule for :func:`wpt_receiver.envelope.simulate`,
    :func:`~wpt_receiver.envelope.steady_state` and :meth:`wpt_receiver.inverse_controller.InverseModelController.reset`,
    :func:`positive_number`'s (a bool refused, as for every link quantity). ``array_ok`` (``steady_state``, which
    broadcasts): an array of any shape is checked elementwise and returned as a float array, naming the first bad
    value (:func:`positive_numbers`); otherwise (the default) an array is refused as not one number."""
    what = "the inverter's fundamental"
    if array_ok:
        return positive_numbers("v1_v", v1_v, "V", what=what, any_shape=True)
    return positive_number("v1_v", v1_v, "V", what)


def check_control_period(control_period_s, shown=None) -> float:
    """A control period [s] as a float after checking it is in (0, 1] s (NaN fails; 1e300 s gave a NaN controller, a
    zero period a run of zero length): one rule for the controller and the exact-mode runs. ``shown``: the value
    the message names (default ``control_period_s``)."""
    try:
        v = float(control_period_s)
    except (TypeError, ValueError):
        v = math.nan
    if not 0 < v <= 1.0:
        raise ValueError(f"control_period_s={control_period_s if shown is None else shown!r} is invalid; valid range: "
                         "(0, 1] s")
    return v


def resonance_warning(p: LinkParams, what: str = "f_hz") -> str | None:
    """One line when ``p.f_hz`` lies more than a factor :data:`FREQUENCY_TOLERANCE` off the resonance of the tanks
    that Table I's coils (``p``'s, when they are Table I's L1, L2) make with Table I's capacitors (C = 1 / ((2 pi
    85 kHz)^2 L), the pair's hardware; their resonance 1 / (2 pi sqrt(L C)) is Table I's f_hz): naming ``what`` (the
    key the user set), the tanks' resonance and the ratio. None inside the tolerance, its ends included, and for
    other coils (their capacitors are the user's design: the models tune them to ``f_hz``)."""
    ref = TABLE_I
    if not (math.isclose(p.l1_h, ref.l1_h, rel_tol=1e-9) and math.isclose(p.l2_h, ref.l2_h, rel_tol=1e-9)):
        return None
    w0 = 2.0 * math.pi * ref.f_hz
    c1, c2 = 1.0 / (w0 * w0 * ref.l1_h), 1.0 / (w0 * w0 * ref.l2_h)
    # 1/(2 pi sqrt(L1 C1)), the secondary's the same (L2 C2 = L1 C1), is Table I's f_hz: taken as it is, not
    # recomputed from an L1 within isclose of Table I's (a mission's, 0.00023600000000000102 H from the coupling
    # model, gave 84999.99999999981 Hz, and 170 kHz, the range's stated end, 2.0000000000000044x: a warning)
    f0 = ref.f_hz
    ratio = p.f_hz / f0
    if 1.0 / FREQUENCY_TOLERANCE <= ratio <= FREQUENCY_TOLERANCE:
        return None
    tol = FREQUENCY_TOLERANCE
    return (f"{what}={p.f_hz:.6g} Hz is {ratio:.4g}x the tanks' resonance {f0:.6g} Hz (1/(2 pi sqrt(L C)) of the coil "
            f"pair, L1 {p.l1_h * 1e6:.4g} uH with C1 {c1 * 1e9:.4g} nF, L2 {p.l2_h * 1e6:.4g} uH with C2 "
            f"{c2 * 1e9:.4g} nF): the model tunes C1, C2 to {what} and runs, but a resonant series-series link's "
            f"secondary current V1/(2 pi f Lm) scales as 1/f, {1.0 / ratio:.3g}x its value at {f0:.6g} Hz "
            f"(outside the factor {tol:g} where it halves or doubles); valid: {what} in [{f0 / tol:.6g}, "
            f"{f0 * tol:.6g}] Hz, or coils made for it")


def warn_off_resonance(p: LinkParams) -> None:
    """:func:`resonance_warning` of ``p`` (naming ``f_hz``) as a :class:`~wpt_receiver.notices.DronewptWarning`, once,
    when it has one: the one rule of the library's entry points that take a link (:func:`wpt_receiver.paper.run_paper`,
    :func:`wpt_receiver.c_export.controller_spec`, :func:`wpt_receiver.switching.netlist.netlist`, the envs), which
    ``dronewpt paper`` / ``netlist`` / ``export-controller --link f_hz`` print as they are (the CLI's own copy until
    2026-11-27 evening; a mission's ``link.f_hz`` is :mod:`mission_sim.setup_warnings`')."""
    text = resonance_warning(p)
    if text is not None:
        from .notices import warn
        warn(text)
