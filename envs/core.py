"""The env's fixed settings and per-episode plans: everything a step reads, built once per
episode (batched over the episodes that start); the step itself is :mod:`envs.vector_kernel`.

Composition (gym-electric-motor style):

* physical system: the envelope link (paper eq. 4) stepped by exact ZOH
  (:func:`wpt_receiver.zoh_discretise`, the closed form :class:`wpt_receiver.EnvelopeLink` uses;
  coefficients :func:`_zoh_coefficients`, slots :data:`envs.layout.COEF`) with a true Lm that
  follows the hover pose error (:mod:`envs.plant`), the SBAR (eq. 9 with the sign of the I2
  envelope: it always absorbs power), the semiconductor devices averaged as in the mission
  (:attr:`EnvConfig.devices`: on-resistances folded into R1 / R2, forward drop on the clamp,
  short-window excess in V2) and the battery equivalent circuit (:data:`envs.layout.BAT`); the step's
  peak is turned into the instantaneous peak (harmonic ripple) by :mod:`envs.peaks`;
* reference generator: the seeded charge command (:mod:`envs.scenario`);
* reward and cost: :class:`RewardWeights` (``envs.vector_kernel._reward``);
* visualisation: :mod:`envs.render`.

Multi-rate: the link is stepped every control period ``dt_s`` (default 100 us = 17 rectifier
periods; a step in which the I2 envelope changes sign is split into rectifier-period sub-steps,
``envs.vector_kernel._substep``); the hover pose (hence Lm) is sampled every ``slow_every`` steps
(default 1 ms) and held; the battery is the equivalent circuit linearised around the episode's
initial SoC (its open-circuit voltage moves by < 1 mV over a 30 ms window, the RC branch is
integrated exactly).

Everything exogenous is computed once per episode (the command and the sensor noise by the scenario
part, :class:`envs.scenario.ScenarioPart`; pose -> Lm -> ZOH coefficients and the initial state by
:func:`build_plans`, the plant part's plans, :mod:`envs.parts`), so a step is only arithmetic, written
once in compiled form (:mod:`envs.vector_kernel`) and called by the single and the vector env.
"""

from __future__ import annotations

import math
import sys
from collections import namedtuple
from collections.abc import Mapping
from dataclasses import dataclass, fields
from functools import cached_property

import numpy as np

from mission_sim.contract import CONTROL_PERIOD_RANGE, LINK_MODELS, OBS_FIELDS
from mission_sim.validation import YAML_NUMBER_NOTE, Range, check_number
from wpt_receiver import TABLE_I, LinkParams, duty_from_v2_clipped, state_matrices, steady_state, zoh_discretise
from wpt_receiver.sbar import rectifier_current, short_weight

from .duty_sine import sin_cos_half_pi
from .layout import BAT, COEF, STATE, XC
from .plant import battery_operating_point, lm_window_h

__all__ = ["LINK_MODELS", "window_lm", "EnvConfig", "RewardWeights", "Plans", "DetunedPlan", "build_plans", "OBS_SCALE", "OBS_OFFSET", "N_COEF", "N_BAT", "kernel_function", "kernel_ref", "kernel_from_ref", "as_config", "given_config",
           "CONTROL_PERIOD_RANGE"]

FOUR_OVER_PI = 4.0 / math.pi
N_COEF = len(COEF)
N_BAT = len(BAT)

#: affine map physical -> [-1, 1] of :data:`mission_sim.contract.OBS_FIELDS` (same as normalise_obs)
OBS_SCALE = np.array([2.0 / (f.hi - f.lo) for f in OBS_FIELDS])
OBS_OFFSET = np.array([-1.0 - f.lo * 2.0 / (f.hi - f.lo) for f in OBS_FIELDS])


_WEIGHT = Range(0, math.inf, hi_open=True)
_CURRENT_SCALE = Range(0, math.inf, "A", lo_open=True, hi_open=True)
#: EnvConfig's numeric fields: (name, valid range, what follows the range in the message)
_RANGES = (("dt_s", CONTROL_PERIOD_RANGE, ""),
           ("n_steps", Range(2, 10**6, integer=True), ""),
           ("slow_every", Range(1, math.inf, integer=True), ""),
           ("rated_i2_a", Range(0, math.inf, "A", lo_open=True, hi_open=True), ""),
           ("bus_c_f", Range(0, math.inf, "F", lo_open=True, hi_open=True), ""),
           ("device_tj_c", Range(0, 175, "C"), " (0: the table's values, else [25, 175] C)"),
           ("hold_tol_a", Range(0, math.inf, "A", hi_open=True), ""),
           ("v2_updates", Range(0, 1000, integer=True), " (0: one per rectifier period)"),
           ("v2_refine_tol", Range(0, math.inf, lo_open=True, hi_open=True), ""),
           ("v2_refine_levels", Range(0, 5, integer=True), " (0: no refinement)"))
_YAML_NOTE = "; " + YAML_NUMBER_NOTE


@dataclass(frozen=True)
class RewardWeights:
    """reward = (min(I_L, I*) - tracking |I_L - I*|) / i_ref_a - overcurrent max(0, I2_peak/I2_rated - 1)

    i_ref_a : current scale [A] (about what RM delivers with Table I: (2/pi) 11.07 A = 7.05 A)
    """

    tracking: float = 1.0
    overcurrent: float = 10.0
    i_ref_a: float = 7.0

    def __post_init__(self):   # a NaN weight made every reward NaN, i_ref_a = 0 a ZeroDivisionError at the env's build
        for name, rng in (("tracking", _WEIGHT), ("overcurrent", _WEIGHT), ("i_ref_a", _CURRENT_SCALE)):
            v = getattr(self, name)
            c = check_number(f"reward {name}", v, rng)   # a numpy or torch scalar becomes the float it holds
            if type(v) not in (int, float):
                object.__setattr__(self, name, c)


@dataclass(frozen=True)
class EnvConfig:
    """Fixed settings of an environment (episode randomness lives in the :class:`Scenario`).

    link : the link parameters (Table I; or a dict of LinkParams fields, Table I's for the others); the true Lm
        replaces ``link.lm_h`` per pose
    dt_s : control period = env step [s] (default 17 rectifier periods = 100 us)
    n_steps : steps per episode (truncation), default 300 (30 ms)
    slow_every : pose / Lm update every this many steps
    rated_i2_a : rated secondary coil current amplitude [A] (cost above it)
    bus_c_f : smoothing capacitor on the SBAR's DC side [F] (assumption: 4.7 mF, tau = R0 C ~ 0.45 ms)
    devices : semiconductor preset of the link (``wpt_receiver/parts.toml``), the mission's default
        ``"schottky"``; ``"ideal"`` is the paper's circuit. Applied as in the mission
        (:class:`mission_sim.world.loop.MissionLoop`): the inverter's 2 Ron folded into R1, the
        rectifying path's Rd into R2, the forward drop added to the clamp ``VL + Vf``, the shorted
        channels' excess ``(2 Ron - Rd) w(d) I2`` added to V2 (see ``envs.vector_kernel._link_step``).
    device_tj_c : junction temperature of the devices' conduction values [C] (0 = the table's, as
        the mission's ``link.device_tj_c``); ``device_terms`` keeps its ``(Vf, dR)`` interface.
    link_model : the plant's link model, one of :data:`LINK_MODELS`: ``"modal"`` (the default since
        2026-11-26, issue 23: one peak estimator in the mission, ``paper`` and the envs) the mission's
        exact-mode link (:mod:`envs.modal_step`: eq. 1's coupled modes, the SBAR's v2 with its quadrature,
        the phase-aware instantaneous peak; within 0.23 % of the switching model's peak on the paper's
        trajectories where eq. 4 + ripple is 2.85 % low on the V2* ramp; an env-step costs ~2.2 us of kernel CPU with
        the duty held and ~15.5 us with random actions against eq. 4's ~0.1-0.15 us: ``benchmarks/ab_modal_step.py``,
        N = 1024, one thread, load 6-7, 2026-11-26, docs/performance.md); ``"envelope"`` eq. 4's envelope with the ripple table for the peak
        (:mod:`envs.vector_kernel`; the default until 2026-11-26, what every shipped RL model was trained on:
        ``EnvConfig(link_model="envelope")``, ``--link envelope``).
        The env's :attr:`policy_context` carries the link model: ``mpc`` predicts with the exact modes on
        it (:mod:`policies.mpc_modal`); ``model_based_budget`` plans its after-stop duties with them
        (:mod:`policies.budget_modal`, docs/budget_search_cost.md).
    hold_tol_a : (modal) a step holds V2 over the control period when the link is within this [A] of the
        steady state of the step's inputs (the ringing, and the error of the held V2, stay below it);
        else it runs in ``v2_updates`` sub-steps (``envs.modal_step._link_step``)
    v2_updates : (modal) sub-steps of a step that is not held, V2 updated at each; 0 (default): one per
        rectifier period, as the mission's fine step; else :attr:`n_sub` (the rectifier periods per step, 17
        at the default ``dt_s``) to 1000; |I2| sampled at least once per rectifier period.
        V2 follows i2's phase, which moves with the modes' beat (125 us at Table I); fewer updates than
        rectifier periods let the held V2 feed the tank (``tests/test_env_modal.py``): under random duties
        (16 windows x 300 steps) 1 update put the energy 138 % / 450 % off the default's (nominal / random),
        2 updates 76-77 %, 4 21-22 %, 8 4.2-4.7 %, 16 0.55-1.1 %, so 1 .. n_sub - 1 are refused (2026-11-28).
        One update per rectifier period alone put a large transient's peak 9-22 % low (docs/performance.md, "Fewer V2
        updates per modal env step"); the refinement below fixes that where it is needed.
    v2_refine_tol, v2_refine_levels : (modal) a sub-step whose end I2 moved from its start's by more than
        ``v2_refine_tol`` of |I2| is redone in 2^L pieces (L <= ``v2_refine_levels``; 0: never), V2 implicit at
        each piece's end (``envs.modal_step._refine``). The defaults (0.05, 3) put a large transient's peak
        (a drop to RM, random duties) within ~2 % of the envelope's fine-step limit (without: 10-25 % low), for
        ~5x the step's CPU under random actions; (0.02, 5) within ~0.3 %, ~13x. Smooth control on tuned windows
        does not trigger it (nominal ``model_based`` / ``mpc`` windows bit-identical to the unrefined step); on
        detuned windows it does (peaks move by up to ~5 A there: those windows ring). Only with one update per
        rectifier period or more (``v2_updates`` 0 or >= :attr:`n_sub`, the only values accepted; the kernel,
        driven with fewer sub-steps than rectifier periods, samples |I2| between updates and does not refine:
        docs/performance.md, "Adaptive refinement of the modal env step").
        Defaults: :data:`wpt_receiver.modal_kernel.REFINE_TOL` / ``REFINE_LEVELS`` (the mission's too).
    """

    link: LinkParams = TABLE_I
    dt_s: float = 17 * TABLE_I.rectifier_period_s
    n_steps: int = 300
    slow_every: int = 10
    rated_i2_a: float = 15.0
    bus_c_f: float = 4.7e-3
    reward: RewardWeights = RewardWeights()
    devices: str = "schottky"
    device_tj_c: float = 0.0
    link_model: str = "modal"
    hold_tol_a: float = 1e-3
    v2_updates: int = 0
    v2_refine_tol: float = 0.05   # = wpt_receiver.modal_kernel.REFINE_TOL (a test keeps them equal; not imported:
    v2_refine_levels: int = 3     # = REFINE_LEVELS   the eq. 4 env does not load the modal kernel)

    def __post_init__(self):
        from wpt_receiver.devices import preset_names
        if isinstance(self.reward, Mapping):   # EnvConfig(reward={"overcurrent": 20}): its fields by name
            object.__setattr__(self, "reward", _from_mapping(RewardWeights, self.reward, "reward"))
        if not isinstance(self.reward, RewardWeights):
            raise ValueError(f"reward={self.reward!r} is invalid; valid: an envs.RewardWeights or a dict of its fields")
        if isinstance(self.link, Mapping):   # LinkParams fields, Table I's for the others (env.spec.to_json's form)
            object.__setattr__(self, "link", TABLE_I.with_(**self.link))
        if not isinstance(self.link, LinkParams):
            raise ValueError(f"link={self.link!r} is invalid; valid: a wpt_receiver.LinkParams or a dict of its fields "
                             "(default TABLE_I)")
        if self.link_model not in LINK_MODELS:
            raise ValueError(f"link_model={self.link_model!r} is invalid; valid values: {', '.join(LINK_MODELS)}")
        for name, rng, note in _RANGES:   # one real number each (YAML 1.1 reads 1e-4 as the string "1e-4")
            v = getattr(self, name)
            c = check_number(name, v, rng, note + _YAML_NOTE * isinstance(v, str))
            if rng.integer or type(v) not in (int, float):   # whole numbers as int (n_steps=40.0 stepped nothing)
                object.__setattr__(self, name, c)
        if 1 <= self.v2_updates < self.n_sub:   # fewer V2 updates than rectifier periods: V2 held while i2 turns
            hi = f"{self.n_sub}..1000" if self.n_sub <= 1000 else "none above 1000"
            raise ValueError(f"v2_updates={self.v2_updates!r} is invalid; valid: 0 (one per rectifier period) or {hi} at "
                             f"dt_s={self.dt_s:.6g} s ({self.n_sub} rectifier periods per step): fewer V2 updates than "
                             "rectifier periods hold V2 while i2 turns (random duties: energy 0.5-450 % off)")
        if not (self.device_tj_c == 0.0 or 25.0 <= self.device_tj_c <= 175.0):
            raise ValueError(f"device_tj_c={self.device_tj_c!r} is invalid; valid range: 0 (table values) or "
                             "[25, 175] C")
        if not isinstance(self.devices, str) or self.devices not in preset_names():
            raise ValueError(f"devices={self.devices!r} is invalid; valid values: {', '.join(preset_names())}")

    def stated_fields(self) -> list:
        """``(name, value)`` of the fields: ``link_model`` always (a record must not depend on which link is
        the default: the default changed from ``"envelope"`` to ``"modal"`` on 2026-11-26), the exact-mode
        link's step options (``hold_tol_a``, ``v2_updates``, ``v2_refine_tol``, ``v2_refine_levels``) only where
        they differ from their defaults. The one rule of :meth:`__repr__` (the oracle's disk-cache keys hold
        the repr, :mod:`policies.oracle`: eq. 4's and the modal link's keys always differ) and of the trained
        models' metadata (``policies.train.config_dict``)."""
        opt = {"hold_tol_a", "v2_updates", "v2_refine_tol", "v2_refine_levels"}
        return [(f.name, getattr(self, f.name)) for f in fields(self)
                if f.name not in opt or getattr(self, f.name) != f.default]

    def __repr__(self):
        """The dataclass's repr over :meth:`stated_fields`."""
        return f"{type(self).__qualname__}({', '.join(f'{k}={v!r}' for k, v in self.stated_fields())})"

    def device_set(self):
        """The :class:`wpt_receiver.devices.DeviceSet` of ``devices``."""
        return self._derived[0]

    @property
    def link_folded(self) -> LinkParams:
        """The link with the devices' constant resistances folded in (R1 + 2 Ron, R2 + Rd): what the
        envelope is stepped with (:func:`wpt_receiver.devices.envelope_params`)."""
        return self._derived[1]

    @property
    def device_terms(self) -> tuple:
        """``(Vf, dR)`` of the step (``envs.vector_kernel._sbar``): the rectifying path's forward drop [V] and the shorted
        channels' resistance minus the folded Rd [ohm] (both 0 for ``"ideal"``)."""
        return self._derived[2]

    @cached_property   # every episode start asks (the config is frozen)
    def _derived(self):
        from wpt_receiver.devices import envelope_params, preset
        dev = preset(self.devices, tj_c=self.device_tj_c or None)
        return dev, envelope_params(self.link, dev), (dev.rect_vf_v, dev.short_r_ohm - dev.rect_rd_ohm)

    @property
    def n_slow(self) -> int:
        return -(-self.n_steps // self.slow_every)

    @property
    def n_sub(self) -> int:
        """Rectifier-period sub-steps of a step in which I2 changes sign (17 at the default)."""
        return max(1, math.ceil(self.dt_s / self.link.rectifier_period_s - 1e-9))

    @cached_property
    def modal_link(self):
        """``(lc, table)`` of the ``"modal"`` link: :func:`wpt_receiver.modal_kernel.link_constants` of the link
        with the devices (resonant) and its :func:`~wpt_receiver.modal_kernel.modal_table` (one per link and
        device set, at the nominal Lm and VL; disk-cached)."""
        from wpt_receiver import modal_kernel as mk
        dev = self.device_set()
        return mk.link_constants(self.link, dev), mk.modal_table(self.link, dev)

    @property
    def modal_n_sub(self) -> int:
        """(modal) sub-steps (V2 updated) of a step that is not held (``v2_updates``; 0: :attr:`n_sub`, the
        rectifier periods per step)."""
        return int(self.v2_updates) or self.n_sub

    @property
    def modal_n_q(self) -> int:
        """(modal) samples of |I2| per sub-step (together at least one per rectifier period)."""
        return -(-self.n_sub // self.modal_n_sub)


@dataclass
class DetunedPlan:
    """A detuned tank's plans (:mod:`envs.detuned`) for ``n`` windows."""

    coef: np.ndarray         # (n, S, 32) complex-envelope ZOH coefficients per slow segment (CCOEF_N)
    xc0: np.ndarray          # (n, 4) initial complex state (envs.layout.XC)
    c1_f: np.ndarray         # (n,) C1 [F]
    c2_f: np.ndarray         # (n,) C2 [F]


@dataclass
class Plans:
    """The plant's per-episode plans and initial state for ``n`` windows (all arrays lead with n; slots
    by name: :mod:`envs.layout`). The command and the sensor noise are the scenario part's
    (:class:`envs.scenario.Window`), the short-mode current and the stop step the objective's."""

    coef: np.ndarray | None  # (n, S, N_COEF) ZOH coefficients per slow segment (envs.layout.COEF); None: table only
    lm_h: np.ndarray         # (n, S) true Lm per slow segment
    battery: np.ndarray      # (n, 9) battery row per episode (envs.layout.BAT)
    state0: np.ndarray       # (n, 6) initial link and battery state (envs.layout.STATE)
    detuned: DetunedPlan | None = None   # detuned windows (envs.detuned)
    zoh: np.ndarray | None = None        # (U, N_COEF) the coefficients of each distinct Lm: coef = zoh[coef_ix]
    coef_ix: np.ndarray | None = None    # (n, S) row of ``zoh`` per window and slow segment


def _from_mapping(cls, values: Mapping, what: str):
    """``cls(**values)`` with an unknown key refused by name (one line naming the valid keys)."""
    known = [f.name for f in fields(cls)]
    bad = sorted(set(values) - set(known), key=str)
    if bad:
        raise ValueError(f"{what} key {bad[0]!r} is invalid; valid keys: {', '.join(known)}")
    return cls(**values)


def as_config(config) -> "EnvConfig":
    """The env's :class:`EnvConfig` from ``config``: an EnvConfig, None (the defaults) or a dict of its fields
    (``gymnasium.make(ENV_ID, config={"link_model": "envelope"})``, as a YAML file of env kwargs gives it; a
    ``reward`` entry may be a dict of :class:`RewardWeights` fields); anything else, or an unknown key, is a
    one-line ``ValueError``."""
    if config is None:
        return EnvConfig()
    if isinstance(config, EnvConfig):
        return config
    if isinstance(config, Mapping):
        return _from_mapping(EnvConfig, config, "config")
    raise ValueError(f"config={config!r} is invalid; valid: an envs.EnvConfig, a dict of its fields or None")


def refuse_unknown_kwargs(cls_name: str, unknown: dict, valid: tuple) -> None:
    """A ``TypeError`` (what Python raises for an unexpected keyword, and what ``gymnasium.make`` passes on) naming
    the first keyword of ``unknown`` and the valid ones; an :class:`EnvConfig` or :class:`RewardWeights` field
    given as a keyword (``gymnasium.make(ENV_ID, n_steps=100)``) is shown where it goes (``config={...}``)."""
    if not unknown:
        return
    from dataclasses import fields
    key, value = next(iter(unknown.items()))
    where = ""
    if key in {f.name for f in fields(EnvConfig)}:
        where = f"; {key} is an EnvConfig field: config={{{key!r}: {value!r}}}"
    elif key in {f.name for f in fields(RewardWeights)}:
        where = f"; {key} is a reward weight: config={{'reward': {{{key!r}: {value!r}}}}}"
    raise TypeError(f"{cls_name}: keyword argument {key!r} is unknown; valid keywords: {', '.join(valid)}{where}")


def given_config(config):
    """``config`` for a function whose own default is None: None stays None, an EnvConfig stays, a dict of its fields
    becomes one (:func:`as_config`; hashable, and the oracle's cache keys hold its repr)."""
    return config if config is None or isinstance(config, EnvConfig) else as_config(config)


def kernel_function(name: str, compiled: bool = True):
    """:func:`envs.vector_kernel.kernel_function` (imported here, when an env is built, so ``import envs``
    does not load numba)."""
    from .vector_kernel import kernel_function as get
    return get(name, compiled)


def kernel_ref(f):
    """A compiled kernel (numba dispatcher) or its ``py_func`` by module and name, for a pickle: a pickled dispatcher is
    rebuilt in another process without its disk cache and compiled again (7-9 s a process for the single env's step,
    2026-11-27); :func:`kernel_from_ref` looks the module's own up again, by that module's ``kernel_function`` (the
    env step's modules: :mod:`envs.vector_kernel`, :mod:`envs.modal_step`). Anything else is returned as it is."""
    base = getattr(f, "py_func", f)
    name, module = getattr(base, "__name__", None), getattr(base, "__module__", None)
    if module is None or not module.startswith("envs.") or name is None \
            or not hasattr(sys.modules.get(module), "kernel_function"):
        return f
    return _KernelRef(module, name, base is not f)


def kernel_from_ref(ref):
    """The kernel :func:`kernel_ref` named (``ref`` itself when it is not a reference): its module's
    ``kernel_function(name, compiled)``, the one lookup."""
    if not isinstance(ref, _KernelRef):
        return ref
    import importlib
    return importlib.import_module(ref.module).kernel_function(ref.name, ref.compiled)


_KernelRef = namedtuple("_KernelRef", "module name compiled")


def _steady_v2(link: LinkParams, lm, il, vl):
    """V2 [V] that delivers DC current ``il`` at battery voltage ``vl`` in steady state (lossless
    rectifier: V2 I2 / 2 = VL I_L with I2 = (w Lm V1 - R1 V2)/det), saturated at RM."""
    x = link.omega_rad_s * lm
    det = link.r1_ohm * link.r2_ohm + x * x
    disc = np.maximum((x * link.v1_amp_v) ** 2 - 8.0 * link.r1_ohm * vl * il * det, 0.0)
    return np.minimum(np.maximum((x * link.v1_amp_v - np.sqrt(disc)) / (2.0 * link.r1_ohm), 0.0), FOUR_OVER_PI * vl)


def build_plans(win, cfg: EnvConfig, table: bool = False) -> Plans:
    """The plant's plans for the windows of ``win`` (an :class:`envs.scenario.Window`: draws, command,
    hover draw), on arrays over the windows: the true Lm per slow segment, the link's coefficients, the
    battery row and the initial state delivering the first command, a detuned tank's complex plans.
    The coefficients of each distinct Lm are made once (``zoh``, indexed per window and slow segment by
    ``coef_ix``); ``table=True`` keeps only that table (the vector env's store: windows sharing an Lm share
    one row, no per-window copies), else ``coef`` holds them per window (the same numbers)."""
    draws = win.draw
    n, S, link = draws.n, cfg.n_slow, cfg.link_folded
    lm = window_lm(win, cfg)
    # windows without wind share one Lm: discretise each distinct value once (same numbers)
    flat = lm.ravel()
    if np.all(flat == flat[0]):   # one Lm for all (no wind, no drift): no sort
        lm_u, back = flat[:1], np.zeros(flat.size, dtype=np.intp)
    else:
        lm_u, back = np.unique(flat, return_inverse=True)
    zoh = _zoh_coefficients(link, lm_u, cfg)
    coef_ix = back.reshape(n, S)
    coef = None if table else zoh[coef_ix]
    battery, state0 = _initial_state(link, lm[:, 0], np.asarray(draws.soc0, dtype=float), win.load_w,
                                     win.cmd_a[:, 0], cfg)
    c1 = np.asarray(draws.c1_detune, dtype=float).reshape(n)
    c2 = np.asarray(draws.c2_detune, dtype=float).reshape(n)
    detuned = None
    if np.any(c1 != 0.0) or np.any(c2 != 0.0):   # the detuned link; its I1, I2 start at |J1|, |J2|
        from .detuned import magnitudes
        detuned = _detuned_plans(link, lm, c1, c2, state0[:, STATE.vl], state0[:, STATE.d], cfg)
        state0[:, STATE.i1], state0[:, STATE.i2] = magnitudes(detuned.xc0)
    return Plans(coef, lm, battery, state0, detuned, zoh, coef_ix)


def window_lm(win, cfg: EnvConfig) -> np.ndarray:
    """The true Lm [H] (n, S) of the windows of ``win`` per slow segment: the hover pose's
    (:func:`envs.plant.lm_window_h`), scaled, drifting linearly in time (scenario ``lm_drift``)."""
    draws, T, S = win.draw, cfg.n_steps, cfg.n_slow
    t_slow = np.arange(S) * (cfg.slow_every * cfg.dt_s)
    lm = lm_window_h(draws.wind_speed_m_s, draws.record_u, t_slow)
    lm *= np.asarray(draws.lm_scale)[:, None]
    drift = np.asarray(draws.lm_drift, dtype=float)
    if np.any(drift != 0.0):   # Lm moving within the window (scenario lm_drift): linear in time
        lm *= 1.0 + drift[:, None] * (t_slow / (T * cfg.dt_s))[None, :]
    return lm


def _detuned_plans(link, lm, c1_rel, c2_rel, vl0, d0, cfg: EnvConfig):
    """ZOH coefficients of the complex envelope per window and slow segment and the steady state at
    the first duty (:mod:`envs.detuned`; ``c*_rel`` the relative capacitor errors)."""
    from .detuned import complex_steady, zoh_complex
    w = link.omega_rad_s
    c1 = (1.0 + c1_rel) / (w * w * link.l1_h)
    c2 = (1.0 + c2_rel) / (w * w * link.l2_h)
    n, S = lm.shape
    keys = np.stack([lm.ravel(), np.repeat(c1, S), np.repeat(c2, S)], axis=1)
    uk, back = np.unique(keys, axis=0, return_inverse=True)
    coef = zoh_complex(link, uk[:, 0], uk[:, 1], uk[:, 2], cfg.dt_s / cfg.n_sub)[back.ravel()].reshape(n, S, 32)
    vf, dr = cfg.device_terms
    v2 = FOUR_OVER_PI * (vl0 + vf) * (1.0 - sin_cos_half_pi(d0)[0])
    j1, j2 = complex_steady(link, lm[:, 0], c1, c2, v2, dr * short_weight(d0))
    xc0 = np.empty((n, len(XC)))
    xc0[:, XC.re_j1], xc0[:, XC.re_j2], xc0[:, XC.im_j1], xc0[:, XC.im_j2] = j1.real, j2.real, j1.imag, j2.imag
    return DetunedPlan(coef, xc0, c1, c2)


def _zoh_coefficients(link: LinkParams, lm, cfg: EnvConfig) -> np.ndarray:
    """The ZOH coefficients (:data:`envs.layout.COEF`) of the step for every Lm in ``lm`` (flattened, (n*S, 23))."""
    a, b = state_matrices(link, lm.ravel())
    n = len(a)
    # the three step lengths (step, half step, sub-step) in one call: elementwise, the same numbers
    dt = np.repeat([cfg.dt_s, 0.5 * cfg.dt_s, cfg.dt_s / cfg.n_sub], n)
    ad3, bd3 = zoh_discretise(np.concatenate([a, a, a]), b, dt)
    ad, am, ah = ad3[:n], ad3[n:2 * n], ad3[2 * n:]
    bd, bm, bh = bd3[:n], bd3[n:2 * n], bd3[2 * n:]
    bad = np.flatnonzero(bh[:, 1, 1] >= 0.0)   # the implicit clamp's g11 (envs.vector_kernel._substep) must be < 0
    if bad.size:
        raise ValueError(f"Lm = {lm.ravel()[bad[0]]:.4g} H with n_sub = {cfg.n_sub} (sub-step {cfg.dt_s / cfg.n_sub:.3g} s) "
                         f"gives the sub-step's g11 = {bh[bad[0], 1, 1]:.3g} >= 0; valid: sub-steps of at most one "
                         f"rectifier period, n_sub >= {math.ceil(cfg.dt_s / link.rectifier_period_s - 1e-9)}")
    v1 = link.v1_amp_v
    # the blocked step (I2 = 0 held by V2 = -(A10 I1 + B10 V1) / B11; eq. 4's B10 = 0 and B01 = 0, so
    # V2 = A10 I1 / -B11 = w Lm I1 and dI1/dt = A00 I1 + B00 V1 alone): exact over dt
    a00 = a[:, 0, 0]
    ka = np.exp(a00 * cfg.dt_s)
    blocked = np.stack([ka, (ka - 1.0) * (b[0, 0] * v1) / a00, a[:, 1, 0] / -b[1, 1]], axis=1)
    # columns: Ad00 Ad01 Ad10 Ad11, Bd00 V1, Bd10 V1, Bd01, Bd11, Am10 Am11, Bm10 V1, Bm11, the same 8 for Ah, Bh,
    # the blocked step's three
    return np.concatenate([ad.reshape(n, 4), bd[:, :, 0] * v1, bd[:, :, 1], am[:, 1, :], bm[:, 1, :1] * v1,
                           bm[:, 1, 1:], ah.reshape(n, 4), bh[:, :, 0] * v1, bh[:, :, 1], blocked], axis=1)


def _initial_state(link: LinkParams, lm0, soc0, load_w, cmd0, cfg: EnvConfig):
    """Battery rows of :class:`Plans` and the steady state delivering the first command ``cmd0``
    (fixed point through the battery voltage): ``(battery (n, 9), state0 (n, 6))`` by the names of
    :data:`envs.layout.BAT` and :data:`envs.layout.STATE`. ``link`` has the
    devices' resistances folded in; ``(vf, dr)`` = :attr:`EnvConfig.device_terms` as in the step
    (the clamp is ``VL + vf``, the short-window excess ``dr w(d) I2`` acts as a resistance in series with R2)."""
    vf, dr = cfg.device_terms
    soc0 = np.asarray(soc0, dtype=float)
    if soc0.size > 1 and bool(np.all(soc0 == soc0[0])):   # one SoC for all (most scenarios): the circuit once
        ocv, docv, r0, r1, tau1, cap = (np.broadcast_to(x, soc0.shape) for x in battery_operating_point(soc0[:1]))
    else:   # (elementwise: the same numbers either way)
        ocv, docv, r0, r1, tau1, cap = battery_operating_point(soc0)
    i_load = load_w / ocv   # hover draw, constant over 30 ms
    vl = ocv + (r0 + r1) * (cmd0 - i_load)
    for _ in range(2):
        v2 = _steady_v2(link, lm0, cmd0, vl + vf)
        i1, i2 = steady_state(link, v2, lm0)
        il = v2 * i2 / (2.0 * (vl + vf))
        vl = ocv + (r0 + r1) * (il - i_load)
    d0 = duty_from_v2_clipped(v2, vl + vf)
    v2 = FOUR_OVER_PI * (vl + vf) * (1.0 - sin_cos_half_pi(d0)[0])
    # steady state with V2 = v2 + dr w(d0) I2 (eq. 4; i2 > 0: V2 <= RM's, below w Lm V1 / R1)
    r2e = link.r2_ohm + dr * short_weight(d0)
    wlm = link.omega_rad_s * np.asarray(lm0, dtype=float)
    det = link.r1_ohm * r2e + wlm**2
    i2 = (wlm * link.v1_amp_v - link.r1_ohm * v2) / det
    i1 = (r2e * link.v1_amp_v + wlm * v2) / det
    ib0 = rectifier_current(d0, np.abs(i2)) - i_load
    vrc0 = r1 * ib0
    vl0 = ocv + r0 * ib0 + vrc0
    decay = np.exp(-cfg.dt_s / tau1)
    bus_decay = np.exp(-cfg.dt_s / (r0 * cfg.bus_c_f))
    row = dict(ocv0=ocv, docv=docv, soc0=soc0, r0=r0, rc_decay=decay, rc_gain=r1 * (1.0 - decay),
               dsoc=cfg.dt_s / (3600.0 * cap), i_load=i_load, bus_decay=bus_decay)
    battery = np.stack([np.broadcast_to(row[f], np.shape(ocv)) for f in BAT._fields], axis=-1)
    start = dict(i1=i1, i2=i2, vl=vl0, soc=battery[:, BAT.soc0], vrc=vrc0, d=d0)
    return battery, np.stack([start[f] for f in STATE._fields], axis=-1)
