"""The exact-mode link's layout, constants and table, without numba (:mod:`.modal_kernel` compiles on them).

What a run of the compiled kernels needs from Python and nothing compiled: the ``lc`` / ``mc`` / ``zc`` array
layouts, the table's grid, the refinement defaults, :func:`link_constants` (a link's ``lc`` array) and
:func:`cached_table` (the SBAR table from the disk cache, or None: :func:`.modal_kernel.modal_table` builds and
stores it, with numba). Split out of :mod:`.modal_kernel` so that a mission run by an ahead-of-time build of its
loop (:mod:`mission_sim.world.aot`) packs its arrays without importing numba; :mod:`.modal_kernel` imports
every name from here (one definition each), and its numba cache, and its dependents', follow this file's
source (:func:`wpt_receiver.kernel_cache.drop_stale_cache`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .devices import IDEAL, DeviceSet
from .params import LinkParams

__all__ = ["LC_NAMES", "N_MODES_C", "N_ZOH_C", "N_D", "N_RHO", "N_PHI", "RHO_MAX", "REFINE_TOL", "REFINE_LEVELS",
           "link_constants", "table_key", "cached_table", "SOURCES"]

#: the link's source files: numba-cached code compiled on the link (``modal_kernel``'s functions, this layout's
#: constants) is stale when either changes; each dependent's stamp lists them
#: (:func:`wpt_receiver.kernel_cache.drop_stale_cache`)
SOURCES = (Path(__file__).with_name("modal_kernel.py"), Path(__file__))

#: ``lc`` (float64) layout: coil / capacitor values with the devices' resistances folded in, and the table scalars
LC_NAMES = ("l1", "l2", "r1", "r2", "c1", "c2", "omega", "rho_max", "inv_hd", "dr_short", "inv_hphi", "vf")
(LC_L1, LC_L2, LC_R1, LC_R2, LC_C1, LC_C2, LC_W, LC_RHO_MAX, LC_INV_HD, LC_DR_SHORT, LC_INV_HPHI,
 LC_VF) = range(len(LC_NAMES))
# mode coefficients ``mc`` (complex128): per mode m in (0, 1): lam' [1/s], gain of V1 and V2, state shape
# [i1, i2, vC1, vC2] per unit z; then the feedthrough D (4 states x [V1, V2])
MC_LAM, MC_G1, MC_G2, MC_S, MC_D = 0, 2, 4, 6, 14
N_MODES_C = 22
# ZOH coefficients ``zc`` (complex128): e^{lam' h} per mode, phi per mode, psi_00, psi_11, psi_01
ZC_E, ZC_PHI, ZC_PSI00, ZC_PSI11, ZC_PSI01 = 0, 2, 4, 5, 6
N_ZOH_C = 7
N_D, N_RHO, N_PHI = 51, 81, 17
RHO_MAX = 3.0          # |I2| / Vc at the top of the table [A/V]; beyond: delta ~ 1/rho, excess constant
_CACHE_VERSION = "modal-kernel-table v5"
#: adaptive refinement of the implicit V2 update (:func:`refine_level`; issue 23): a rectifier-period sub-step whose
#: end I2 moved from its start's by more than ``REFINE_TOL`` of |I2| is redone in up to 2^``REFINE_LEVELS``
#: pieces, V2 implicit at each piece's end (the env's ``EnvConfig.v2_refine_tol`` / ``v2_refine_levels`` defaults;
#: the mission's fine step, :mod:`mission_sim.world.loop_kernel`)
REFINE_TOL = 0.05
REFINE_LEVELS = 3


def link_constants(params: LinkParams, devices: DeviceSet = IDEAL, c1_f=None, c2_f=None) -> np.ndarray:
    """``lc`` array (:data:`LC_NAMES`) of a link: L [H], R [ohm] with the inverter's ``2 Ron`` and
    the rectifying path's ``Rd`` folded in (as :func:`.modal.link_matrices`), C [F] (resonant at
    ``f_hz`` unless given), omega [rad/s], the table's scalars, the shorted SBAR's excess
    resistance over ``Rd`` [ohm] (enters V2 as in :func:`wpt_receiver.sbar.rectifier_v2_folded`)
    and the rectifying path's forward drop Vf [V] (the clamp is ``VL + Vf``)."""
    p, w = params, params.omega_rad_s
    c1 = 1 / (w * w * p.l1_h) if c1_f is None else float(c1_f)
    c2 = 1 / (w * w * p.l2_h) if c2_f is None else float(c2_f)
    return np.array([p.l1_h, p.l2_h, p.r1_ohm + devices.inv_r_ohm, p.r2_ohm + devices.rect_rd_ohm, c1, c2, w,
                     RHO_MAX, float(N_D - 1), devices.short_r_ohm - devices.rect_rd_ohm, 0.5 * (N_PHI - 1),
                     devices.rect_vf_v])


def table_key(params: LinkParams, devices: DeviceSet = IDEAL) -> str:
    """The disk-cache key of a link's SBAR table (:func:`cached_table`, :func:`.modal_kernel.modal_table`)."""
    return f"{_CACHE_VERSION} {params!r} {devices!r} rho={RHO_MAX} n={N_PHI}x{N_D}x{N_RHO}"


def cached_table(params: LinkParams, devices: DeviceSet = IDEAL) -> np.ndarray | None:
    """The SBAR table of a resonant link from the disk cache (:mod:`wpt_receiver.diskcache`), or None on a miss
    (:func:`.modal_kernel.modal_table` builds and stores it; it needs numba, this module does not)."""
    from . import diskcache
    return diskcache.load("modal_table", table_key(params, devices), (2, N_PHI, N_D, N_RHO))
