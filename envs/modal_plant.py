"""The plant's link model, chosen per env (gym-electric-motor's swappable physical system):
``EnvConfig(link_model="envelope")`` is eq. 4's envelope with the ripple table
(:class:`envs.parts.PlantPart`, :mod:`envs.vector_kernel`; the default until 2026-11-26); ``link_model="modal"``
(the default since, issue 23) is the mission's exact-mode link (this module's :class:`ModalPlantPart` / :class:`ModalSinglePlant`, the compiled step
:mod:`envs.modal_step`).

The choice is made once, when the env is built (:func:`vector_plant`, :func:`single_plant`): each link
has its own compiled entry, so the default step carries no branch for the other. The scenario,
objective and observation parts are shared; the plant parts differ in their plans and arrays:

* plans (:func:`build_modal_plans`): the true Lm per slow segment (:func:`envs.core.window_lm`), the
  battery rows and the first duty as eq. 4's start (:func:`envs.core._initial_state`: the duty that
  delivers the first command), then the exact-mode link's periodic steady state at that duty
  (:func:`envs.modal_step.start_link`, with VL settled once on its DC current); the link constants per
  window (:func:`wpt_receiver.modal_kernel.link_constants`, a detuned window's C1, C2 in them);
* arrays: :data:`envs.layout.STATE` as eq. 4's plant (i1, i2, vl, soc, vrc, d) plus the link's own
  :data:`envs.layout.MSTATE` (``mstate``: mode amplitudes, V2 phasor), the current slow segment's modes
  and ZOH (``coef_cur``, :data:`envs.layout.N_CZ` complex per window), the SBAR table ``tab``;
* the first info values (I_L, instantaneous peak, v2 in phase) are the steady state's (``start_values``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from wpt_receiver.params import warn_off_resonance

from .core import OBS_OFFSET, OBS_SCALE, DetunedPlan, EnvConfig, Plans, _initial_state, window_lm
from .layout import BAT, MPAR, MSINGLE_PAR, MSTATE, N_CZ, SINGLE, SLOW, STATE
from .parts import PlantPart, SinglePlant
from .plant import ENV_BATTERY

__all__ = ["ModalPlans", "build_modal_plans", "ModalPlantPart", "ModalSinglePlant", "vector_plant", "single_plant",
           "warn_link_range"]


def _kernel_function(name: str, compiled: bool = True):
    """:func:`envs.modal_step.kernel_function` (imported when a modal env is built: numba loads then)."""
    from .modal_step import kernel_function as get
    return get(name, compiled)


def vector_plant(cfg: EnvConfig, n: int, compiled: bool = True) -> PlantPart:
    """The vector env's plant part of ``cfg.link_model`` (:func:`warn_link_range` for the exact-mode link)."""
    warn_off_resonance(cfg.link)
    if cfg.link_model != "modal":
        return PlantPart(cfg, n, compiled)
    warn_link_range(cfg)
    return ModalPlantPart(cfg, n, compiled)


def single_plant(cfg: EnvConfig, compiled: bool = True) -> SinglePlant:
    """The single env's plant part of ``cfg.link_model`` (:func:`warn_link_range` for the exact-mode link)."""
    warn_off_resonance(cfg.link)
    if cfg.link_model != "modal":
        return SinglePlant(cfg, compiled)
    warn_link_range(cfg)
    return ModalSinglePlant(cfg, compiled)


@lru_cache(maxsize=1)
def _plant_lm_vl() -> tuple[float, float]:
    """The plant's Lm at the hover pose [H] and its pack's highest open-circuit voltage [V] (the env's true Lm and
    VL come from the coupling model and the battery, not from ``EnvConfig.link``'s ``lm_h`` / ``vl_v``)."""
    from mission_sim.world.battery import BatteryParams, ocv_cell_v
    from wpt_receiver.coupling import NOMINAL_GAP_M, default_coupling
    lm = float(default_coupling().lm_h(0.0, 0.0, NOMINAL_GAP_M, 0.0))
    return lm, BatteryParams().n_series * float(ocv_cell_v(1.0))


def warn_link_range(cfg: EnvConfig) -> None:
    """A :class:`~wpt_receiver.notices.DronewptWarning` when the env's link (``cfg.link`` at the hover pose's Lm and
    the pack's full voltage: :func:`_plant_lm_vl`) is outside the range where the exact-mode model was checked
    against the switching model (:func:`wpt_receiver.paper.modal_range_problem`, the limits' one source); once
    per env built (~50 us), nothing per step."""
    from wpt_receiver.paper import modal_range_problem
    lm, vl = _plant_lm_vl()
    problem = modal_range_problem(cfg.link.with_(lm_h=lm, vl_v=vl), remedy=(
        "the env has no switching-level link, so its currents, peaks and energies may be off; valid: an "
        "EnvConfig(link=...) inside that range"))
    if problem is not None:
        from wpt_receiver.notices import warn
        warn(f"EnvConfig link (vdc_v={cfg.link.vdc_v:g} V, r1_ohm={cfg.link.r1_ohm:g}, f_hz={cfg.link.f_hz:g}) with the "
             f"env's pack (VL up to {vl:.3g} V) at the hover pose (Lm {lm * 1e6:.3g} uH): {problem}")


@dataclass
class ModalPlans(Plans):
    """:class:`envs.core.Plans` of the exact-mode link (``coef`` None: the modes are made in the step)."""

    lc: np.ndarray | None = None        # (n, 12) link constants per window (wpt_receiver.modal_kernel.LC_NAMES)
    mstate0: np.ndarray | None = None   # (n, 7) the link's initial state (envs.layout.MSTATE)
    start: np.ndarray | None = None     # (5, n) at the start: |I1|, I2 (signed), inst. peak, I_L [A], v2 in phase [V]


def build_modal_plans(win, cfg: EnvConfig) -> ModalPlans:
    """The modal plant's plans for the windows of ``win`` (:class:`envs.scenario.Window`): true Lm, link
    constants (a detuned window's C1, C2 in them), battery rows, the initial state at the periodic steady
    state of the first duty (module docstring)."""
    draws = win.draw
    n, link = draws.n, cfg.link_folded
    lm = window_lm(win, cfg)
    c1 = np.asarray(draws.c1_detune, dtype=float).reshape(n)
    c2 = np.asarray(draws.c2_detune, dtype=float).reshape(n)
    lc = np.tile(cfg.modal_link[0], (n, 1))
    detuned = None
    if np.any(c1 != 0.0) or np.any(c2 != 0.0):   # the modes take any C1, C2 (the table is the resonant link's)
        from wpt_receiver.modal_kernel import LC_C1, LC_C2
        w = link.omega_rad_s
        detuned = DetunedPlan(None, None, (1.0 + c1) / (w * w * link.l1_h), (1.0 + c2) / (w * w * link.l2_h))
        lc[:, LC_C1], lc[:, LC_C2] = detuned.c1_f, detuned.c2_f
    soc0 = np.asarray(draws.soc0, dtype=float)
    battery, state0 = _initial_state(link, lm[:, 0], soc0, win.load_w, win.cmd_a[:, 0], cfg)
    r1 = np.full(n, ENV_BATTERY.r1_ohm)   # (the pack's RC resistance is a constant: envs.plant.battery_operating_point's)
    ms0, start, vl0, vrc0 = _link_start(cfg, lc, lm[:, 0], state0[:, STATE.d], battery, r1, state0[:, STATE.vl])
    state0[:, STATE.i1], state0[:, STATE.i2], state0[:, STATE.vl], state0[:, STATE.vrc] = start[0], start[1], vl0, vrc0
    return ModalPlans(None, lm, battery, state0, detuned, lc=lc, mstate0=ms0, start=start)


def _link_start(cfg: EnvConfig, lc, lm0, d0, battery, r1, vl_eq4):
    """The exact-mode link's periodic steady state at the first duty (:func:`envs.modal_step.start_link`)
    with the battery settled on its DC current (one pass of the fixed point through VL from eq. 4's):
    ``(mstate0 (n, 7), start (5, n), vl0, vrc0)``."""
    n = len(lm0)
    vf = cfg.device_terms[0]
    start_link = _kernel_function("start_link")
    z, v2, rows = np.empty((n, 4)), np.empty(n, dtype=complex), np.empty((5, n))
    cz = np.empty((n, N_CZ), dtype=complex)
    b = battery.T
    args = (vf, cfg.link.v1_amp_v, cfg.modal_link[1], cfg.dt_s, cfg.modal_n_sub, cfg.modal_n_q, cz, z, v2, rows)
    start_link(lc, lm0, d0, np.ascontiguousarray(vl_eq4), *args)   # one correction: VL moves by mV
    ib0 = rows[3] - b[BAT.i_load]
    vrc0 = r1 * ib0
    vl0 = b[BAT.ocv0] + b[BAT.r0] * ib0 + vrc0
    start_link(lc, lm0, d0, vl0, *args)
    ms = np.empty((n, len(MSTATE)))
    ms[:, MSTATE.z0r:MSTATE.z1i + 1] = z
    ms[:, MSTATE.v2r], ms[:, MSTATE.v2i], ms[:, MSTATE.e] = v2.real, v2.imag, -1.0
    return ms, rows, vl0, vrc0


def _modal_constants(cfg: EnvConfig) -> dict:
    """The modal plant's constants by the names of :data:`envs.layout.MPAR` / :data:`~envs.layout.MSINGLE_PAR`:
    window length, step, the devices' ``(Vf, dR)``, the sub-steps, V1 [V], the hold tolerance [A] and the peak
    samples per sub-step (``envs.modal_step._link_step``)."""
    vf, dr = cfg.device_terms
    return dict(n_steps=cfg.n_steps, dt=cfg.dt_s, slow_every=cfg.slow_every, n_sub=cfg.modal_n_sub, vf=vf, dr=dr,
                v1=cfg.link.v1_amp_v, hold_tol=cfg.hold_tol_a, n_q=cfg.modal_n_q,
                rtol=cfg.v2_refine_tol, rlevels=cfg.v2_refine_levels)


class ModalPlantPart(PlantPart):
    """The exact-mode link of ``n`` windows (module docstring); its step is :func:`envs.modal_step.env_step`."""

    PAR = MPAR
    mstate_names = MSTATE._fields

    def __init__(self, cfg: EnvConfig, n: int, compiled: bool = True):
        S = cfg.n_slow
        self.cfg, self.compiled, self.n_sub = cfg, compiled, cfg.modal_n_sub
        self.kernel = _kernel_function("env_step", compiled)   # also: numba imported here
        self.tab = cfg.modal_link[1]
        self.state = np.zeros((len(STATE), n))
        self.mstate = np.zeros((len(MSTATE), n))
        self.j = np.zeros(n, dtype=np.int64)
        self.lc = np.tile(cfg.modal_link[0], (n, 1))            # link constants per window
        self.coef_cur = np.zeros((n, N_CZ), dtype=complex)      # the current slow segment's modes + ZOH
        self.lm_all = np.zeros((S, n))
        self.bat = np.zeros((len(BAT), n))
        self.start0 = np.zeros((5, n))   # at the window's start: |I1|, I2, peak, I_L, v2 (ModalPlans.start)
        self.detuned = np.zeros(0, np.bool_)
        self.c_rel = None

    def constants(self, peak=None) -> dict:
        return _modal_constants(self.cfg)

    def reset(self, idx, win):
        p = build_modal_plans(win, self.cfg)
        self.lm_all[:, idx] = p.lm_h.T
        self.bat[:, idx] = p.battery.T
        self.lc[idx] = p.lc
        self.j[idx] = 0
        self.state[:, idx] = p.state0.T
        self.mstate[:, idx] = p.mstate0.T
        self.start0[:, idx] = p.start
        self._reset_detuned(idx, p.detuned)
        return p

    def _alloc_complex(self, n):
        """Nothing: a detuned window's C1, C2 are in its link constants (no complex envelope)."""

    def _set_complex(self, idx, det):
        """Nothing (see :meth:`_alloc_complex`)."""

    def start_values(self, peak):
        """``(I_L, instantaneous peak, v2 in phase with i2)`` at the windows' start: the steady state's."""
        return self.start0[3].copy(), self.start0[2].copy(), self.start0[4].copy()

    def step(self, d, k, scenario, objective, par, ptab, obs, reward, truncated, block, chunks):
        """One step of every window: the compiled :func:`envs.modal_step.env_step` (``ptab`` unused)."""
        c = self.cfg
        kern = self.kernel if self.compiled else _kernel_function("env_step", False)
        kern(d, self.state, self.mstate, k, self.j, self.lc, self.coef_cur, self.bat, scenario.cmd, scenario.noise,
             self.lm_all, objective.ep, c.slow_every, self.n_sub, par, OBS_SCALE, OBS_OFFSET, self.tab, obs, reward,
             truncated, block, chunks)


class ModalSinglePlant(SinglePlant):
    """The single env's exact-mode plant: ``st`` the :data:`SINGLE` slots then the link's :data:`MSTATE`,
    ``slow`` :data:`SLOW` per slow segment (true Lm, short-mode I2), ``lc`` the window's link constants,
    ``cz`` its current modes and ZOH; its step is :func:`envs.modal_step.single_step`."""

    PAR = MSINGLE_PAR

    def __init__(self, cfg: EnvConfig, compiled: bool = True):
        self.cfg, self.compiled = cfg, compiled
        self.kernel = _kernel_function("single_step", compiled)   # also: numba imported here
        self.tab = cfg.modal_link[1]
        self.st = self.slow = self.lc = self.start = None
        self.cz = np.zeros(N_CZ, dtype=complex)

    def constants(self, peak=None) -> dict:
        return _modal_constants(self.cfg)

    def reset(self, idx, win):
        p = build_modal_plans(win, self.cfg)
        st = np.empty(len(SINGLE) + len(MSTATE))
        for f in STATE._fields:
            st[getattr(SINGLE, f)] = p.state0[0, getattr(STATE, f)]
        for f in BAT._fields:
            st[getattr(SINGLE, f)] = p.battery[0, getattr(BAT, f)]
        st[len(SINGLE):] = p.mstate0[0]
        slow = np.zeros((p.lm_h.shape[1], len(SLOW)))
        slow[:, SLOW.lm_h] = p.lm_h[0]
        self.st, self.slow, self.lc, self.start = st, slow, np.ascontiguousarray(p.lc[0]), p.start[:, 0].copy()
        return p

    def start_values(self, peak):
        return float(self.start[3]), float(self.start[2]), float(self.start[4])

    def step(self, k, d, steps, par, obs, out):
        """The single window's step; returns the reward."""
        kern = self.kernel if self.compiled else _kernel_function("single_step", False)
        return kern(k, d, self.st, steps, self.slow, par, obs, out, self.lc, self.cz, self.tab)
