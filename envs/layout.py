"""Named slots of the env's state and plan arrays: every array the step reads is indexed by name
(``state[STATE.vl, e]``, ``bat[BAT.i_load]``), not by integer positions spread over the modules.

Each layout is a namedtuple of indices (``STATE.vl == 2``); numba reads such a global as a
compile-time constant, so the compiled step (:mod:`envs.vector_kernel`) pays nothing for the names.
``len(LAYOUT)`` is the number of slots, ``LAYOUT._fields`` their names in order.
"""

from __future__ import annotations

from collections import namedtuple

__all__ = ["fields", "STATE", "BAT", "COEF", "INFO", "PAR", "SINGLE", "SLOW", "SINGLE_PAR", "CCOEF_N", "XC", "MSTATE",
           "MPAR", "MSINGLE_PAR", "CZ_MODES", "CZ_STEP", "CZ_SUB", "CZ_SAMPLE", "CZ_FAST", "CZ_FASTH", "CZ_KEY", "N_CZ",
           "FAST", "CZ_RPAR", "CZ_LEVELS", "CZ_LEVEL_N", "REFINE_LEVELS_CAP"]


def fields(name: str, names: str):
    """A namedtuple instance whose field ``f`` holds the index of ``f`` in ``names`` (space separated)."""
    cls = namedtuple(name, names)
    return cls(*range(len(cls._fields)))


#: link and battery state of a window (vector env: rows of ``_state`` (6, n); currents [A], voltages [V])
STATE = fields("State", "i1 i2 vl soc vrc d")
#: the battery row of a window (:func:`envs.core._initial_state`): OCV [V] and its slope [V/1], SoC at
#: the start, R0 [ohm], the RC branch's decay and gain [ohm] per step, SoC per A per step, hover draw [A],
#: the DC bus's decay per step
BAT = fields("Battery", "ocv0 docv soc0 r0 rc_decay rc_gain dsoc i_load bus_decay")
#: the 23 ZOH coefficients of a slow segment (:func:`envs.core._zoh_coefficients`): the step ``dt``
#: (Ad, Bd V1 as e0 e1, Bd's V2 column as b01 b11), the half step's I2 row (m10 m11 me1 mb11), the
#: rectifier-period sub-step (h, f = Bh V1, g = Bh's V2 column) and the blocked step (I2 held at 0 by the
#: rectifier: I1 -> ka I1 + ke over ``dt``, the V2 that holds I2 at 0 ``wlm I1`` = w Lm I1)
COEF = fields("Coef", "a00 a01 a10 a11 e0 e1 b01 b11 m10 m11 me1 mb11 h00 h01 h10 h11 f0 f1 g01 g11 ka ke wlm")
#: the detuned tank's complex envelope (four real states, :mod:`envs.detuned`)
XC = fields("ComplexState", "re_j1 re_j2 im_j1 im_j2")
#: coefficients of one detuned sub-step: Ad (4 x 4) then Bd (4 x 4), row-major
CCOEF_N = 32
#: the info values a step writes, in order (one row per sub-environment)
INFO = fields("Info", "t_s i2_a i2_peak_a i1_a d_short v2_v rect_current_a battery_v battery_current_a soc "
              "charge_cmd_a lm_h energy_j overcurrent cost overshoot episode_cost i2_peak_envelope_a")
#: the vector env's constants as one float array (``_par``)
PAR = fields("Par", "n_steps dt inv_rated w_track w_over i_ref vf dr vlc inv_imax")
#: the single env's state row (``st``): link state, objective, stop, battery row, detuned state
SINGLE = fields("Single", "i1 i2 vl soc vrc d run_max sm_ok sm_checked stop_k t_stop ocv0 docv soc0 r0 rc_decay "
                "rc_gain dsoc i_load bus_decay")
#: the single env's per-slow-segment row: the 20 ZOH coefficients, then the true Lm [H] and short-mode I2 [A]
SLOW = fields("Slow", COEF._fields + ("lm_h", "i2_sm_a"))
#: the single env's constants (``par``) before the observation maps and the peak table (V1 [V]: the
#: detuned tank's source; nd ni nq: the table's shape)
SINGLE_PAR = fields("SinglePar", "n_steps dt inv_rated w_track w_over i_ref slow_every n_sub vf dr vlc inv_imax "
                    "v1 nd ni nq")

# ---------------------------------------------------------------- the exact-mode link (EnvConfig.link_model="modal")
#: the exact-mode link's own state of a window (:mod:`envs.modal_step`; vector env: rows of ``_mstate`` (7, n),
#: single env: after the :data:`SINGLE` slots of ``st``): the two mode amplitudes (re, im;
#: :mod:`wpt_receiver.modal_kernel`), the V2 phasor held over the last step [V] and a spare slot ``e`` (the
#: SBAR's commutation angle of a secant solve; -1: the closed form needs no first guess)
MSTATE = fields("ModalState", "z0r z0i z1r z1i v2r v2i e")
#: the link coefficients of a window's current slow segment (complex, ``_coef_cur`` (n, N_CZ)): the modes
#: at its Lm (:func:`wpt_receiver.modal_kernel.modes`), the ZOH of the step, of a sub-step (V2 updated)
#: and of a peak sample within a sub-step (:func:`~wpt_receiver.modal_kernel.zoh`), and the Lm they are
#: for (the key); ``CZ_FAST`` the sub-step's affine maps (:data:`FAST`), ``CZ_FASTH`` the whole step's
CZ_MODES, CZ_STEP, CZ_SUB, CZ_SAMPLE, CZ_FAST, CZ_FASTH, CZ_KEY = 0, 22, 29, 36, 43, 57, 71
#: the adaptive refinement of a sub-step (``envs.modal_step._refine``): ``CZ_RPAR`` = complex(relative tolerance,
#: levels), then per level L = 1 ... ``REFINE_LEVELS_CAP`` a key (the piece's length [s] once made, 0 until), the
#: ZOH (7) and the affine maps (:data:`FAST`, 14) of a sub-step / 2^L, ``CZ_LEVEL_N`` complex each from ``CZ_LEVELS``
REFINE_LEVELS_CAP, CZ_RPAR, CZ_LEVELS, CZ_LEVEL_N = 5, 72, 73, 22
N_CZ = CZ_LEVELS + REFINE_LEVELS_CAP * CZ_LEVEL_N
#: a sub-step's affine maps with V2 held (``envs.modal_step._fast_coefs``; the V1 terms per volt of the
#: phasor V1): mode m's ``z_m+ = e_m z_m + k_m V1 + l_m V2``, the end I2 ``q0 + q1 V2`` with ``q0 = a0 z0 +
#: a1 z1 + b V1``, the sub-step's ``int I2 dt = c0 z0 + c1 z1 + p0 V1 + p1 V2``
FAST = fields("Fast", "e0 e1 k0 k1 l0 l1 a0 a1 b q1 c0 c1 p0 p1")
#: the modal vector env's constants (``_par``): :data:`PAR`'s first eight slots (the same indices), then V1 [V]
#: the pad's amplitude, hold_tol [A] the transient below which a step holds V2 over the control period,
#: n_q the peak samples per sub-step (``envs.modal_step._link_step``), rtol, rlevels the sub-steps' refinement
#: (``EnvConfig.v2_refine_tol`` / ``v2_refine_levels``, ``envs.modal_step._refine``)
MPAR = fields("ModalPar", "n_steps dt inv_rated w_track w_over i_ref vf dr v1 hold_tol n_q rtol rlevels")
#: the modal single env's constants (``par``) before the observation maps
MSINGLE_PAR = fields("ModalSinglePar", "n_steps dt inv_rated w_track w_over i_ref slow_every n_sub vf dr v1 hold_tol "
                     "n_q rtol rlevels")
