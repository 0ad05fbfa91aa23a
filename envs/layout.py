"""Named slots of the env's state and plan arrays: every array the step reads is indexed by name
(``state[STATE.vl, e]``, ``bat[BAT.i_load]``), not by integer positions spread over the modules.

Each layout is a namedtuple of indices (``STATE.vl == 2``); numba reads such a global as a
compile-time constant, so the compiled step (:mod:`envs.vector_kernel`) pays nothing for the names.
``len(LAYOUT)`` is the number of slots, ``LAYOUT._fields`` their names in order.
"""

from __future__ import annotations

from collections import namedtuple

__all__ = ["fields", "STATE", "BAT", "COEF", "INFO", "PAR", "SINGLE", "SLOW", "SINGLE_PAR", "CCOEF_N", "XC"]


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
#: the 20 ZOH coefficients of a slow segment (:func:`envs.core._zoh_coefficients`): the step ``dt``
#: (Ad, Bd V1 as e0 e1, Bd's V2 column as b01 b11), the half step's I2 row (m10 m11 me1 mb11) and the
#: rectifier-period sub-step (h, f = Bh V1, g = Bh's V2 column)
COEF = fields("Coef", "a00 a01 a10 a11 e0 e1 b01 b11 m10 m11 me1 mb11 h00 h01 h10 h11 f0 f1 g01 g11")
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
