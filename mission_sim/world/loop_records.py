"""The mission loop's records, status codes and work-array layout, without numba.

The compiled loop (:mod:`.loop_kernel`, which imports every name from here: one definition each) and the
Python driver (:mod:`.fastpath`) share these: the state, constants and trajectory-sample records by name, the
statuses :func:`.loop_kernel.advance` returns, the link work array's layout and the cell's open-circuit voltage
(:func:`ocv_cell`, compiled by :mod:`.loop_kernel` as ``_ocv_cell``; :func:`.fastpath.initial_state` calls it
as Python). A numba-free module so that a mission run by the loop's ahead-of-time build
(:mod:`.aot`) packs its records without importing numba.
"""

from __future__ import annotations

import math

import numpy as np

from wpt_receiver.modal_link import N_MODES_C, N_ZOH_C

from ..contract import OBS_DIM

__all__ = ["STATE_DTYPE", "CONST_DTYPE", "SAMPLE_DTYPE", "STATUS_NAMES", "OK", "DONE", "PAUSED", "FULL", "NEED_ACT",
           "NEED_NOISE", "DEPLETED", "ERR_POWER", "ERR_POLICY", "LW_SIZE", "ocv_cell"]

STATUS_NAMES = ("OK", "DONE", "PAUSED", "FULL", "NEED_ACT", "NEED_NOISE", "DEPLETED", "ERR_POWER", "ERR_POLICY",
                "NEED_DEPLETE")
OK, DONE, PAUSED, FULL, NEED_ACT, NEED_NOISE, DEPLETED, ERR_POWER, ERR_POLICY, _NEED_DEPLETE = range(10)

#: the loop's state, by name (units SI; flags bool; counters int64)
STATE_DTYPE = np.dtype([
    # cursor: sample k (global index), the per-sample arrays' first sample k0, phase 0 (start of sample k)
    # or 1 (inside its interval at time t, iteration point sub), the fine step in progress
    ("k", "i8"), ("k0", "i8"), ("phase", "i8"), ("sub", "i8"), ("t", "f8"), ("dt_f", "f8"), ("lm_s", "f8"),
    ("d_prev", "f8"), ("fresh", "?"),
    # link envelope (I1, I2) [A], pad voltage amplitude [V], int I1^2 dt, int I2^2 dt of the last step [A^2 s]
    ("x0", "f8"), ("x1", "f8"), ("v1", "f8"), ("p11", "f8"), ("p22", "f8"),
    # exact-mode link state (wpt_receiver.modal_kernel): the two mode amplitudes (re, im), the V2 phasor held
    # over the last step [V], the link's stored energy at its end [J], the instantaneous peak |i2| so far [A]
    ("z", "f8", (4,)), ("v2re", "f8"), ("v2im", "f8"), ("w_end", "f8"), ("peak_inst", "f8"),
    # pad and BMS: transmitter wants on, charge command I_L* [A], when it went to 0 / the last BMS update [s]
    ("tx_on", "?"), ("cmd", "f8"), ("t_cmd_zero", "f8"), ("t_last_bms", "f8"),
    # policy: duty d_short, last call [s], a duty handed in by Python, sensor-noise buffer position
    ("d", "f8"), ("t_last_act", "f8"), ("duty_ready", "?"), ("duty_in", "f8"), ("noise_i", "i8"),
    # battery: SoC, R1-C1 voltage [V], last terminal voltage [V], battery / rectifier current [A], charger flags
    ("soc", "f8"), ("vrc", "f8"), ("last_vl", "f8"), ("last_ib", "f8"), ("last_il", "f8"), ("cv", "?"), ("full", "?"),
    # fine window: inside one, its earliest end and its deadline [s]
    ("in_fine", "?"), ("fine_until_min", "f8"), ("fine_deadline", "f8"),
    # the protection's diodes blocked in the last step (loop_kernel._sbar_v2; coarse steps carry it then)
    ("prot_blocked", "?"),
    # peak |I2| of the envelope [A], the duty there, time above rated [s]
    ("peak_env", "f8"), ("peak_d", "f8"), ("above", "f8"),
    ("n_fine", "i8"), ("n_coarse", "i8"), ("n_windows", "i8"), ("n_cut", "i8"), ("n_rows", "i8"),
    # depletion (NaN / -1: not depleted), the battery current of the step that crossed SoC 0 [A]
    ("depleted_at", "f8"), ("depleted_k", "i8"), ("tmp_ib", "f8"),
    # ERR_POWER: time [s], propulsion power [W], SoC, the most the battery can supply [W], sample
    ("err_t", "f8"), ("err_p", "f8"), ("err_soc", "f8"), ("err_pmax", "f8"), ("err_k", "i8"),
])

#: the loop's constants, by name (filled by :func:`.fastpath.pack_constants`)
CONST_DTYPE = np.dtype([
    ("dtc", "f8"), ("k_on", "f8"), ("k_off", "f8"), ("ramp_rate", "f8"), ("rated", "f8"), ("inv_sqrt_l1l2", "f8"),
    ("t_rect", "f8"), ("v1_nom", "f8"),
    # link (paper eq. 4) with the devices folded in: L1, L2 [H], R1 + 2 Ron, R2 + Rd [ohm], omega, B = (1/2L1, -1/2L2)
    ("l1", "f8"), ("l2", "f8"), ("st_r1", "f8"), ("st_r2", "f8"), ("omega", "f8"), ("b0", "f8"), ("b1", "f8"),
    # devices: forward drop of the rectifying path [V], shorted-SBAR resistance minus Rd [ohm], the loss split
    ("vf", "f8"), ("dr_short", "f8"), ("inv_r", "f8"), ("vf0", "f8"), ("rd", "f8"), ("is_ideal", "?"),
    ("coil_r1", "f8"), ("coil_r2", "f8"),
    # battery: R0, R1 [ohm], tau1 [s], C1 [F], cells in series, capacity [C]; charger: CC [A], CV [V], cut-off [A],
    # recharge [V], over-voltage trip [V]
    ("r0", "f8"), ("r1b", "f8"), ("tau1", "f8"), ("bat_c1", "f8"), ("n_cells", "f8"), ("capacity_c", "f8"),
    ("cc_a", "f8"), ("v_cv", "f8"), ("cutoff_a", "f8"), ("v_recharge", "f8"), ("v_trip", "f8"),
    # sim.*
    ("tx_off_delay", "f8"), ("bms_period", "f8"), ("cmd_deadband", "f8"), ("min_fine", "f8"), ("max_fine", "f8"),
    ("flight_dt", "f8"), ("lm_rel_tol", "f8"), ("coarse_period", "f8"), ("duty_event_tol", "f8"),
    ("settle_duty_tol", "f8"), ("settle_i2_tol", "f8"), ("noise_a", "f8"), ("rectify_off", "?"),
    # the contract's normalisation of the observation (lo, 1 / span)
    ("obs_lo", "f8", (OBS_DIM,)), ("obs_inv", "f8", (OBS_DIM,)),
    # most rows one iteration can write (a fine step split into rectifier periods, each in up to 2^levels pieces)
    ("row_margin", "i8"),
    # adaptive refinement of a fine step's rectifier-period sub-steps (_sub_step; levels 0: off)
    ("refine_tol", "f8"), ("refine_levels", "i8"),
])

#: one trajectory sample: time [s], Lm of the nearest pad [H], coupling k, propulsion power [W], energising
SAMPLE_DTYPE = np.dtype([("t", "f8"), ("lm", "f8"), ("k", "f8"), ("p", "f8"), ("elig", "?")])

#: ZOH slots per role (0: the step's length, 1: its peak samples' quarter): a refined fine step (:func:`_sub_step`)
#: steps pieces of h / 2^L between sub-steps of h, so each role keeps a few lengths instead of re-discretising
_LW_PER_ROLE = 4
_LW_SLOTS = 2 * _LW_PER_ROLE
_LW_MODES, _LW_ZOH, _LW_KEYS = 0, N_MODES_C, N_MODES_C + _LW_SLOTS * N_ZOH_C
_LW_LM, _LW_NEXT = _LW_KEYS + _LW_SLOTS, _LW_KEYS + _LW_SLOTS + 1
#: the link work array: the modes, the ZOH slots, their keys (step lengths), the modes' Lm, each role's next slot
LW_SIZE = _LW_NEXT + 2


def ocv_cell(soc):
    """Open-circuit voltage of one cell [V] (Chen & Rincon-Mora 2006 fit, :mod:`.battery`); SoC clipped into [0, 1]."""
    s = 0.0 if soc < 0.0 else (1.0 if soc > 1.0 else soc)
    return -1.031 * math.exp(-35.0 * s) + 3.685 + 0.2156 * s - 0.1178 * s * s + 0.3201 * s * s * s
