"""Coupling from coil geometry: self inductances and Lm(dx, dy, dz, tilt) by Neumann integrals.

Both coils are flat multi-turn circular coils described as coaxial filament loops (one per
turn: radius, height in the coil's own frame) made of round (litz) wire of radius ``a``.

* Coaxial filaments (Maxwell 1873; Grover, *Inductance Calculations*, 1946, eq. 77):
  ``M = mu0 sqrt(a b) [(2/k - k) K(k) - (2/k) E(k)]``, ``k^2 = 4ab / ((a+b)^2 + d^2)``
  (scipy's ``ellipk(m)``/``ellipe(m)`` take ``m = k^2``).
* Self inductance of one turn of round wire with uniform current (litz):
  ``L = mu0 R (ln(8R/a) - 7/4)`` (Rosa & Grover 1912; Grover 1946 eq. 179); coil
  ``L = sum_i L_i + sum_{i != j} M_ij``.
* Laterally offset / tilted filaments: the Neumann double integral done once analytically, i.e.
  the flux of the transmitter loop's vector potential
  ``A_phi(rho, z) = mu0 I / (pi k) sqrt(a / rho) [(1 - k^2/2) K - E]`` around the receiver
  loop, ``M = (1/I) oint A . dl``, by the trapezoid rule in the loop angle (spectrally
  convergent for this smooth periodic integrand).
* Fast path (:meth:`CouplingModel.lm_h`): the whole pad coil's ``A_phi / rho`` tabulated once on
  a (rho, z) grid (cubic B-spline coefficients by ``scipy.ndimage.spline_filter``), then the same
  loop quadrature over the receiver turns, vectorised over any number of poses. The lookup (spline,
  receiver geometry, integrand) exists once, compiled, in :mod:`.coupling_kernel`; this module keeps
  the orchestration (shapes, broadcasting, the exact field below the table, the disk cache).
  The table (0.2-0.5 s to build) is cached on disk per pad geometry and grid (:mod:`wpt_receiver.diskcache`; key:
  geometry, grid, this module's source, numpy/scipy versions), so only the first run builds it.

Pose convention: ``(dx, dy, dz)`` is the receiver coil frame's origin in the pad frame (z up,
``dz`` = height of the receiver coil above the pad coil); ``tilt_rad`` rotates the receiver
about a horizontal axis through its origin at azimuth ``tilt_axis_rad`` (default pi/2: the y
axis, so a positive tilt turns the receiver's normal towards +x).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
from . import diskcache
from .params import LinkParams

__all__ = [
    "MU0", "CoilGeometry", "spiral_coil", "mutual_coaxial_h", "loop_self_h", "vector_potential_loop",
    "coil_self_h", "CouplingModel", "default_tx_coil", "default_rx_coil", "default_coupling",
    "NOMINAL_GAP_M", "calibrate_default",
]

#: poses up to which :meth:`CouplingModel.lm_h` keeps its result in the disk cache (a mission's path:
#: ~1,000 poses, ~9 kB); larger batches (long missions, maps) are computed every time
MEMO_MAX_POSES = 50_000
#: most ``lm_h`` results kept in the disk cache (the oldest removed beyond)
MEMO_ENTRIES = 32
#: :meth:`CouplingModel.lm_h` takes the exact field for a pose whose drone coil comes within this many grid steps
#: of the table's lower edge (4 cm at the default 5 mm grid: below 6 cm over the pad; 8 cm at a 10 mm grid, whose
#: spline is off by up to 2.6e-4 of the hover Lm just above a fixed 4 cm band, <= 1.4e-6 above its 8 cm band)
EXACT_ABOVE_EDGE_STEPS = 8

MU0 = 4e-7 * math.pi  # vacuum permeability [H/m] (pre-2019 exact value; 2019 SI differs by 5e-10)

# series of g(m) = (1 - m/2) K(m) - E(m) = (pi/2) sum_n c_n m^n for small m (avoids cancellation)
_A = [1.0]
for _n in range(1, 40):
    _A.append(_A[-1] * ((2 * _n - 1) / (2 * _n)) ** 2)
_C = np.array([0.0] + [_A[n] * 2 * n / (2 * n - 1) - 0.5 * _A[n - 1] for n in range(1, 40)])
_M_SERIES = 0.1


def _g(m):
    """``(1 - m/2) K(m) - E(m)`` for m in [0, 1), accurate also for m -> 0 (series below 0.1)."""
    m = np.asarray(m, dtype=float)
    out = np.empty_like(m)
    small = m < _M_SERIES
    if np.any(~small):
        from scipy.special import ellipe, ellipk  # only for the exact field (table build, below-table points)
        mb = m[~small]
        out[~small] = (1.0 - 0.5 * mb) * ellipk(mb) - ellipe(mb)
    if np.any(small):
        ms = m[small]
        out[small] = 0.5 * math.pi * np.polyval(_C[::-1], ms)
    return out


@dataclass(frozen=True)
class CoilGeometry:
    """A flat (or stacked) circular multi-turn coil as coaxial filament loops.

    Attributes
    ----------
    radius_m : tuple of float
        Radius of each turn [m] (> wire radius).
    z_m : tuple of float
        Height of each turn in the coil's own frame [m] (same length as ``radius_m``).
    wire_radius_m : float
        Radius of the (litz) wire [m]; turns closer than two wire radii are rejected.
    """

    radius_m: tuple
    z_m: tuple
    wire_radius_m: float

    def __post_init__(self):
        r = tuple(float(v) for v in np.atleast_1d(self.radius_m))
        z = tuple(float(v) for v in np.atleast_1d(self.z_m))
        a = float(self.wire_radius_m)
        object.__setattr__(self, "radius_m", r)
        object.__setattr__(self, "z_m", z)
        object.__setattr__(self, "wire_radius_m", a)
        if not (math.isfinite(a) and a > 0):
            raise ValueError(f"wire_radius_m={a!r} is invalid; valid range: (0, inf)")
        if len(r) == 0:
            raise ValueError("radius_m=() is invalid; valid range: at least one turn")
        if len(z) != len(r):
            raise ValueError(f"z_m has {len(z)} entries but radius_m has {len(r)}; valid: one height per turn")
        for i, (ri, zi) in enumerate(zip(r, z)):
            if not (math.isfinite(ri) and ri > a):
                raise ValueError(f"radius_m[{i}]={ri!r} is invalid; valid range: ({a!r}, inf) (> wire radius)")
            if not math.isfinite(zi):
                raise ValueError(f"z_m[{i}]={zi!r} is invalid; valid range: finite")
        for i in range(len(r)):
            for j in range(i):
                gap = math.hypot(r[i] - r[j], z[i] - z[j])
                if gap < 2 * a * (1 - 1e-9):
                    raise ValueError(f"turns {j} and {i} are {gap:.4g} m apart; valid range: >= 2 wire radii "
                                     f"= {2 * a:.4g} m (wires would overlap)")

    @property
    def n_turns(self) -> int:
        return len(self.radius_m)

    @property
    def outer_radius_m(self) -> float:
        return max(self.radius_m) + self.wire_radius_m

    @property
    def wire_length_m(self) -> float:
        return 2 * math.pi * sum(self.radius_m)


def spiral_coil(n_turns: int, outer_radius_m: float, pitch_m: float, wire_radius_m: float,
                z_m: float = 0.0) -> CoilGeometry:
    """Flat spiral approximated by ``n_turns`` concentric loops, outermost at ``outer_radius_m``,
    spaced by ``pitch_m`` (all at height ``z_m``)."""
    if int(n_turns) != n_turns or n_turns < 1:
        raise ValueError(f"n_turns={n_turns!r} is invalid; valid range: integer >= 1")
    r = tuple(float(outer_radius_m - i * pitch_m) for i in range(int(n_turns)))
    return CoilGeometry(r, (float(z_m),) * int(n_turns), wire_radius_m)


# --------------------------------------------------------------------------- closed forms
def _check_finite(name: str, v) -> None:
    """ValueError naming the first non-finite entry of ``v``."""
    v = np.asarray(v, dtype=float)
    bad = ~np.isfinite(v)
    if np.any(bad):
        raise ValueError(f"{name}={float(v[bad].flat[0])!r} is invalid; valid range: finite")


def _check_positive(name: str, v) -> None:
    """ValueError naming the first entry of ``v`` that is not finite and > 0."""
    v = np.asarray(v, dtype=float)
    bad = ~(np.isfinite(v) & (v > 0))
    if np.any(bad):
        raise ValueError(f"{name}={float(v[bad].flat[0])!r} is invalid; valid range: (0, inf) m")


def mutual_coaxial_h(a_m, b_m, d_m):
    """Mutual inductance of two coaxial circular filaments, radii ``a``, ``b``, axial distance ``d`` [H].

    Maxwell's formula ``mu0 sqrt(ab) [(2/k - k) K - (2/k) E] = 2 mu0 sqrt(ab) g(k^2) / k``.
    Broadcasts over arrays.
    """
    a, b, d = (np.asarray(v, dtype=float) for v in (a_m, b_m, d_m))
    _check_positive("a_m", a)
    _check_positive("b_m", b)
    _check_finite("d_m", d)
    m = 4 * a * b / ((a + b) ** 2 + d**2)
    return 2 * MU0 * np.sqrt(a * b) * _g(m) / np.sqrt(m)


def loop_self_h(radius_m, wire_radius_m):
    """Self inductance of one circular turn of round wire, uniform current: ``mu0 R (ln(8R/a) - 7/4)`` [H].

    The formula is the thin-wire limit (a << R); it is refused for ``wire_radius_m >= radius_m``
    (no such turn; there it would give a negative inductance from R/a < e^1.75 / 8 = 0.72)."""
    r = np.asarray(radius_m, dtype=float)
    a = np.asarray(wire_radius_m, dtype=float)
    _check_positive("wire_radius_m", a)
    _check_positive("radius_m", r)
    if np.any(r <= a):
        bad = np.broadcast_to(r, np.broadcast(r, a).shape)[np.broadcast_to(r <= a, np.broadcast(r, a).shape)]
        raise ValueError(f"radius_m={float(bad.flat[0])!r} is invalid; valid range: > wire_radius_m "
                         f"({float(np.max(a))!r} m)")
    return MU0 * r * (np.log(8 * r / wire_radius_m) - 1.75)


def coil_self_h(coil: CoilGeometry) -> float:
    """Self inductance of a multi-turn coil: turn self inductances plus all pairwise mutuals [H]."""
    r = np.array(coil.radius_m)
    z = np.array(coil.z_m)
    total = float(np.sum(loop_self_h(r, coil.wire_radius_m)))
    i, j = np.triu_indices(len(r), 1)
    if len(i):
        total += 2.0 * float(np.sum(mutual_coaxial_h(r[i], r[j], z[i] - z[j])))
    return total


def _code_key() -> str:
    """This module's source hash and the numpy/scipy versions (part of every disk-cache key). scipy's version comes
    from its ``.dist-info`` folder when that is unambiguous, else from ``scipy.__version__`` as before
    (:func:`.diskcache.package_version`; the same string for a pip-installed scipy): its top-level import, ~10 ms,
    came before the figure worker's fork in every mission (the table cached, scipy was not needed)."""
    src = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()
    return f"src={src} numpy={np.__version__} scipy={diskcache.package_version('scipy')}"


def _coil_self_h_cached(coil: CoilGeometry) -> float:
    """:func:`coil_self_h` through the disk cache: the elliptic integrals need ``scipy.special``
    (~0.2 s to import), which a mission with a cached coupling table otherwise never loads."""
    key = f"coil-self-h v1 coil={coil!r} {_code_key()}"
    got = diskcache.load("coil_self_h", key, (1,))
    if got is not None:
        return float(got[0])
    val = coil_self_h(coil)
    diskcache.store("coil_self_h", key, np.array([val]))
    return val


def vector_potential_loop(a_m, rho_m, z_m):
    """``A_phi / rho`` [H/m^2 per A] of a unit-current loop of radius ``a`` at the origin (z = 0 plane).

    ``A_phi = mu0 / (pi k) sqrt(a / rho) g(k^2)`` with ``k^2 = 4 a rho / ((a + rho)^2 + z^2)``;
    divided by rho so the value is finite and smooth on the axis (limit ``mu0 a^2 / (4 (a^2 + z^2)^1.5)``).
    """
    a, rho, z = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (a_m, rho_m, z_m)))
    den = (a + rho) ** 2 + z**2
    m = 4 * a * rho / den
    out = np.empty(np.shape(m))
    on = m < 1e-12
    if np.any(~on):
        mm = m[~on]
        out[~on] = MU0 / math.pi * np.sqrt(a[~on] / rho[~on]) * _g(mm) / np.sqrt(mm) / rho[~on]
    if np.any(on):
        # g(m)/sqrt(m) ~ pi m^1.5 / 32 -> A/rho -> mu0 a^2 / (4 (a^2 + z^2)^1.5)
        out[on] = MU0 * a[on] ** 2 / (4 * (a[on] ** 2 + z[on] ** 2) ** 1.5)
    return out


def _rx_frame(dx, dy, dz, tilt, tilt_axis):
    """Rotation matrices (..., 3, 3) of the receiver (about a horizontal axis) and its origin (..., 3).

    All five inputs broadcast together.
    """
    dx, dy, dz, tilt, tilt_axis = np.broadcast_arrays(*(np.asarray(v, dtype=float)
                                                        for v in (dx, dy, dz, tilt, tilt_axis)))
    for name, v in (("dx_m", dx), ("dy_m", dy), ("dz_m", dz), ("tilt_rad", tilt), ("tilt_axis_rad", tilt_axis)):
        _check_finite(name, v)   # a NaN pose gave Lm = 0.0 (the table's "uncoupled") without a word
    ux, uy = np.cos(tilt_axis), np.sin(tilt_axis)
    c, s = np.cos(tilt), np.sin(tilt)
    # Rodrigues rotation about unit axis (ux, uy, 0)
    rot = np.empty(np.shape(tilt) + (3, 3))
    rot[..., 0, 0] = c + ux * ux * (1 - c)
    rot[..., 0, 1] = ux * uy * (1 - c)
    rot[..., 0, 2] = uy * s
    rot[..., 1, 0] = ux * uy * (1 - c)
    rot[..., 1, 1] = c + uy * uy * (1 - c)
    rot[..., 1, 2] = -ux * s
    rot[..., 2, 0] = -uy * s
    rot[..., 2, 1] = ux * s
    rot[..., 2, 2] = c
    org = np.stack([dx, dy, dz], axis=-1)
    return rot, org


def _loop_points(rx: CoilGeometry, n_theta: int):
    """Receiver loop points and tangents in the receiver frame: (turns, n_theta, 3) each, and weights."""
    th = 2 * math.pi * np.arange(n_theta) / n_theta
    r = np.array(rx.radius_m)[:, None]
    z = np.array(rx.z_m)[:, None]
    pts = np.stack([r * np.cos(th), r * np.sin(th), np.broadcast_to(z, (len(r), n_theta))], axis=-1)
    tan = np.stack([-r * np.sin(th), r * np.cos(th), np.zeros((len(r), n_theta))], axis=-1)  # dl/dtheta
    return pts, tan, 2 * math.pi / n_theta


class CouplingModel:
    """Inductances of a pad coil (tx) and a drone coil (rx) for any receiver pose.

    Parameters
    ----------
    tx, rx : CoilGeometry
        Transmitter (pad) and receiver (drone) coils in their own frames.
    n_theta : int
        Quadrature points per receiver turn (trapezoid rule; spectrally convergent).
    grid_step_m : float
        Spacing of the (rho, z) table of the pad coil's vector potential.
    rho_max_m, z_min_m, z_max_m : float
        Table range (pad frame). Poses whose receiver points leave it are computed exactly
        (below ``z_min_m``) or count as uncoupled (beyond ``rho_max_m``/``z_max_m``, where
        Lm is below ~1 % of its hover value for the default coils).
    """

    def __init__(self, tx: CoilGeometry, rx: CoilGeometry, *, n_theta: int = 24, grid_step_m: float = 5e-3,
                 rho_max_m: float = 1.5, z_min_m: float = 0.02, z_max_m: float = 1.5):
        if int(n_theta) < 8:
            raise ValueError(f"n_theta={n_theta!r} is invalid; valid range: integer >= 8")
        if not (grid_step_m > 0 and rho_max_m > 0 and z_max_m > z_min_m):
            raise ValueError(f"table range invalid: grid_step_m={grid_step_m!r} (> 0), rho_max_m={rho_max_m!r} "
                             f"(> 0), z_min_m={z_min_m!r} < z_max_m={z_max_m!r}")
        self.tx, self.rx = tx, rx
        self.n_theta = int(n_theta)
        self.l1_h = _coil_self_h_cached(tx)
        self.l2_h = _coil_self_h_cached(rx)
        self._grid = (float(grid_step_m), float(rho_max_m), float(z_min_m), float(z_max_m))
        self._table = None
        self._pts, self._tan, self._w = _loop_points(rx, self.n_theta)
        self._flat_pts = np.ascontiguousarray(self._pts.reshape(-1, 3))
        self._flat_tan = np.ascontiguousarray(self._tan.reshape(-1, 3))

    @property
    def table_range_m(self):
        """``(rho_max, z_min, z_max)`` [m] of the tabulated pad field (pad frame)."""
        return self._grid[1:]

    # ----------------------------------------------------------------- exact
    def clearance_m(self, tilt_rad=0.0):
        """The height [m] of the receiver coil's centre over the pad coil's plane at or below which their wires
        touch when it is over the pad coil (:meth:`check_clearance`): the two wire radii, plus the pad coil's highest
        turn ``max(tx.z_m)``, plus the receiver's lowest point under its centre,
        ``max_i(r_i |sin tilt_rad| - z_i cos tilt_rad)`` (turn i of radius ``r_i`` at height ``z_i`` in the receiver's
        frame, tilted: its centre at ``z_i cos tilt`` and its rim ``r_i |sin tilt|`` lower). Flat coils (every
        ``z_m`` 0): the wire radii plus the largest turn radius x ``|sin tilt_rad|``. Broadcasts over ``tilt_rad``."""
        return self._touch_band(tilt_rad)[1]

    def _touch_band(self, tilt):
        """``(lo, hi)``: the receiver centre heights ``lo <= dz <= hi`` at which the coils' wires would touch over the
        pad coil (:meth:`check_clearance`): the receiver's height range, its turns' centres ``z_i cos tilt`` plus or
        minus their rims' ``r_i |sin tilt|``, widened by the two wire radii, meets the pad coil's turns' heights
        ``[min(tx.z_m), max(tx.z_m)]`` (flat coils: ``lo = -hi``)."""
        c, s = np.cos(tilt), np.abs(np.sin(tilt))
        wires = self.tx.wire_radius_m + self.rx.wire_radius_m
        hi = wires + max(self.tx.z_m) + self._rx_drop(c, s)
        lo = min(self.tx.z_m) - wires - self._rx_drop(-c, s)   # (-c: the highest point above the centre)
        return lo, hi

    def _rx_drop(self, c, s):
        """How far [m] the receiver coil reaches below its centre, tilted with ``c = cos tilt``, ``s = |sin tilt|``
        (arrays): ``max_i(r_i s - z_i c)`` over its turns (radius ``r_i`` at height ``z_i`` in its frame). The one
        source of :meth:`_touch_band` (with ``-c``: how far it reaches above) and :meth:`_near_pad`."""
        r, z = np.asarray(self.rx.radius_m), np.asarray(self.rx.z_m)
        return (np.multiply.outer(s, r) - np.multiply.outer(c, z)).max(axis=-1)

    def check_clearance(self, dx_m, dy_m, dz_m, tilt_rad=0.0, *, above_pad: bool = False) -> None:
        """``ValueError`` naming the first pose (broadcast arrays or numbers) whose receiver coil is within
        :meth:`clearance_m` of the pad coil's plane (``abs(dz_m) <= clearance_m``: above or below it) while over it (a
        lateral offset ``hypot(dx_m, dy_m)`` below the two outer radii): the coils would touch. ``above_pad=True``:
        the receiver is a drone's, above the pad, so a ``dz_m`` below 0 is refused too, wherever it is (``valid range:
        > clearance_m``). The one rule of ``dronewpt coupling --dz`` (which calls it with ``above_pad=True``; its own
        copies until 2026-11-27 evening, and of the sign until night); :meth:`lm_h` and :meth:`lm_exact_h` do not call
        it (a mission's flown poses in wind dip below it, property tests swap the coils: they compute every pose)."""
        dx, dy, dz, tilt = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (dx_m, dy_m, dz_m, tilt_rad)))
        lo, hi = self._touch_band(tilt)
        low = (lo <= dz) & (dz <= hi)   # (NaN: False here; _rx_frame names it)
        below = (dz < 0) if above_pad else np.zeros(dz.shape, bool)
        if not (low.any() or below.any()):
            return
        reach = self.tx.outer_radius_m + self.rx.outer_radius_m
        bad = below | (low & (np.hypot(dx, dy) < reach))
        if bad.any():
            i = np.flatnonzero(bad.ravel())[0]
            z, l_, h = float(dz.flat[i]), float(lo.flat[i]), float(hi.flat[i])
            if below.flat[i]:   # (below the pad's plane: no lateral offset makes it a drone's pose)
                raise ValueError(f"dz_m={z!r} is invalid; valid range: > {h:.4g} m (the coils would touch)")
            side = f"> {h:.4g} m" if z >= (l_ + h) / 2 else f"< {l_:.4g} m"   # (the nearer side's bound)
            raise ValueError(f"dz_m={z!r} is invalid; valid range: {side} (the coils would touch), or a lateral offset "
                             f"hypot(dx_m, dy_m) >= {reach:.4g} m")

    def lm_exact_h(self, dx_m, dy_m, dz_m, tilt_rad=0.0, *, n_theta: int | None = None,
                   tilt_axis_rad=math.pi / 2):
        """Lm [H] by the loop integral of the exact (elliptic-integral) vector potential.

        Scalar or array poses (broadcast); slow (N_tx x N_rx x n_theta elliptic integrals per pose). Any pose is
        computed (coils that would touch too: :meth:`check_clearance` is the caller's, e.g. ``dronewpt coupling``).
        """
        n = self.n_theta if n_theta is None else int(n_theta)
        pts, tan, w = _loop_points(self.rx, n)
        return self._flux(dx_m, dy_m, dz_m, tilt_rad, tilt_axis_rad, pts, tan, w, self._a_exact)

    def _a_exact(self, rho, z):
        out = np.zeros(rho.shape)
        for a, zt in zip(self.tx.radius_m, self.tx.z_m):
            out += vector_potential_loop(a, rho, z - zt)
        return out

    def _flux(self, dx, dy, dz, tilt, tilt_axis, pts, tan, w, a_over_rho):
        """Lm [H] of the (broadcast) poses by :meth:`_flux_poses`, shaped like the poses."""
        rot, org = _rx_frame(dx, dy, dz, tilt, tilt_axis)
        shape = org.shape[:-1]
        out = self._flux_poses(rot.reshape(-1, 3, 3), org.reshape(-1, 3), pts, tan, w, a_over_rho)
        return out.reshape(shape) if shape else float(out[0])

    @staticmethod
    def _flux_poses(rot, org, pts, tan, w, a_over_rho):
        """Loop integral of the field ``a_over_rho(rho, z)`` (numpy: exact, or table-and-exact) over the
        receiver points of each pose (N, 3, 3), (N, 3), chunked; the receiver geometry and the integrand
        are :mod:`.coupling_kernel`'s (``receiver_points``, ``loop_sum``)."""
        from .coupling_kernel import loop_sum, receiver_points
        rot, org = np.ascontiguousarray(rot, dtype=float), np.ascontiguousarray(org, dtype=float)
        flat_p, flat_t = np.ascontiguousarray(pts.reshape(-1, 3)), np.ascontiguousarray(tan.reshape(-1, 3))
        out = np.empty(len(org))
        chunk = max(1, 200_000 // len(flat_p))
        for s in range(0, len(org), chunk):
            x, y, z, tx, ty = receiver_points(rot[s:s + chunk], org[s:s + chunk], flat_p, flat_t)
            out[s:s + chunk] = loop_sum(a_over_rho(np.hypot(x, y), z), x, y, tx, ty, float(w))
        return out

    # ----------------------------------------------------------------- table
    def table_key(self) -> str:
        """Text that identifies the tabulated field: pad geometry, grid, code and library versions."""
        return f"coupling-table v1 tx={self.tx!r} grid={self._grid!r} {_code_key()}"

    def _build_table(self):
        """Spline coefficients of the pad's ``A_phi / rho`` on the grid: from the disk cache or computed."""
        h, rho_max, z_min, z_max = self._grid
        rho = np.arange(0.0, rho_max + 0.5 * h, h)
        z = np.arange(z_min, z_max + 0.5 * h, h)
        key = self.table_key()
        coef = diskcache.load("coupling", key, (len(rho), len(z)))
        if coef is None:
            from scipy import ndimage  # 0.3 s import: only when the table is built
            rr, zz = np.meshgrid(rho, z, indexing="ij")
            coef = ndimage.spline_filter(self._a_exact(rr, zz), order=3, mode="mirror")
            diskcache.store("coupling", key, coef)
        self._table = (coef, rho, z, h)

    def _table_args(self):
        """The table as :mod:`.coupling_kernel` takes it: ``(coef, h, z0, rho_last, z_last)`` (built on first use:
        :meth:`lm_h` may answer from the disk cache of poses without it)."""
        if self._table is None:
            self._build_table()
        coef, rho_g, z_g, h = self._table
        return coef, float(h), float(z_g[0]), float(rho_g[-1]), float(z_g[-1])

    def _a_table(self, rho, z):
        """``A_phi / rho`` from the table (:func:`.coupling_kernel.table_field`), exact below the table."""
        from .coupling_kernel import table_field
        out = table_field(*self._table_args(), np.ravel(rho), np.ravel(z)).reshape(np.shape(rho))
        below = z < self._table[2][0]
        if np.any(below):
            out[below] = self._a_exact(rho[below], z[below])
        return out

    def lm_h(self, dx_m, dy_m, dz_m, tilt_rad=0.0, *, tilt_axis_rad=math.pi / 2, compiled: bool = False):
        """Lm [H] from the tabulated pad-coil field; vectorised over (broadcast) arrays of poses.

        Agrees with :meth:`lm_exact_h` to ~1e-6 relative near the hover pose (see tests).
        Receiver points beyond the table (rho > rho_max_m or z > z_max_m) contribute nothing;
        poses with a receiver point below it (z < z_min_m) use the exact field at those points.
        The lookup is :func:`.coupling_kernel.flux_table` (numba, the only implementation; imported
        here on first use). ``compiled`` is accepted for callers and ignored: there is no second
        (numpy) path any more; ``flux_table.py_func`` runs the same source uncompiled (tests).
        Up to :data:`MEMO_MAX_POSES` poses the result is kept in the disk cache keyed by the poses'
        bytes (a mission re-run on the same path, with any policy, battery or link, then needs
        neither the table nor numba: ~0.5 s of start-up); the newest :data:`MEMO_ENTRIES` are kept.
        Any pose is computed (coils that would touch too, e.g. a flown pose in wind: :meth:`check_clearance` is the
        caller's, ``dronewpt coupling`` calls it).
        """
        rot, org = _rx_frame(dx_m, dy_m, dz_m, tilt_rad, tilt_axis_rad)
        shape = org.shape[:-1]
        rot, org = np.ascontiguousarray(rot.reshape(-1, 3, 3)), np.ascontiguousarray(org.reshape(-1, 3))
        key = self._poses_key(rot, org) if len(org) <= MEMO_MAX_POSES else None
        out = None if key is None else diskcache.load("lm_poses", key, (len(org),))
        if out is None:
            out = self._lm_poses(rot, org)
            if key is not None and diskcache.store("lm_poses", key, out) is not None:
                diskcache.prune("lm_poses", MEMO_ENTRIES)
        return out.reshape(shape) if shape else float(out[0])

    def _lm_poses(self, rot, org):
        """Lm [H] of the poses ``rot`` (N, 3, 3), ``org`` (N, 3) by :func:`.coupling_kernel.flux_table`."""
        from .coupling_kernel import flux_table
        out, below = flux_table(*self._table_args(), rot, org, self._flat_pts, self._flat_tan, float(self._w))
        near = self._near_pad(rot, org)
        below &= ~near     # (a near pose's field is the exact one, whole: not the table's mix first)
        if np.any(below):  # the exact field at the points below the table, the table elsewhere
            out[below] = self._flux_poses(rot[below], org[below], self._pts, self._tan, self._w, self._a_table)
        if np.any(near):   # the spline's lower edge: the exact field for the whole pose
            out[near] = self._flux_poses(rot[near], org[near], self._pts, self._tan, self._w, self._a_exact)
        return out

    def _near_pad(self, rot, org):
        """Poses (N, 3, 3), (N, 3) whose drone coil comes lower than :data:`EXACT_ABOVE_EDGE_STEPS` grid steps above
        the table's lower edge while within its radius: there the spline (``mode="mirror"``, a zero-slope edge the
        field does not have) was off by up to 2 % of the hover Lm (receiver 2.2 cm over the pad; 7e-4 at a 3.4 cm
        hover, the mission's 3 cm floor) against <= 6e-7 from this height up at the default 5 mm grid (offsets up to 0.3 m)
        (tests/test_physics_properties.py). The coil's
        lowest point: ``dz - max_i(r_i hypot(R20, R21) - z_i R22)`` (:meth:`_rx_drop`); its nearest radius ``|(dx, dy)| - max r_i``."""
        step, rho_max, z_min, _ = self._grid
        lowest = org[:, 2] - self._rx_drop(rot[:, 2, 2], np.hypot(rot[:, 2, 0], rot[:, 2, 1]))
        return ((lowest < z_min + EXACT_ABOVE_EDGE_STEPS * step)
                & (np.hypot(org[:, 0], org[:, 1]) - max(self.rx.radius_m) <= rho_max))

    def _poses_key(self, rot, org) -> str:
        """Disk-cache key of ``lm_h`` at these poses: the table's key (geometry, grid, code, versions),
        the receiver coil, the compiled kernel's source and a hash of the pose arrays' bytes."""
        kernel = hashlib.sha256(Path(__file__).with_name("coupling_kernel.py").read_bytes()).hexdigest()
        poses = hashlib.sha256(rot.tobytes() + org.tobytes()).hexdigest()
        return f"lm-poses v1 {self.table_key()} rx={self.rx!r} kernel={kernel} n={len(org)} poses={poses}"

    def lm_centred_h(self, dz_m: float) -> float:
        """Lm [H] of the receiver centred and level over the pad at ``dz_m`` (the ``dz_m`` of :meth:`lm_h`): Maxwell's
        coaxial formula summed over the turn pairs (:func:`mutual_coaxial_h`), no table and no compiled kernel; equal
        to :meth:`lm_h` there to ~1e-15."""
        return _lm_coaxial(self.tx, self.rx, dz_m)

    def k(self, lm_h):
        """Coupling coefficient ``Lm / sqrt(L1 L2)``."""
        return np.asarray(lm_h) / math.sqrt(self.l1_h * self.l2_h)

    def link_params(self, base: LinkParams, lm_h: float) -> LinkParams:
        """``base`` with this geometry's L1, L2 and the given Lm (validated: 0 < k < 1)."""
        return replace(base, l1_h=self.l1_h, l2_h=self.l2_h, lm_h=float(lm_h))

    def turn_positions(self, dx_m=0.0, dy_m=0.0, dz_m=None, tilt_rad=0.0,
                       tilt_axis_rad: float = math.pi / 2):
        """Turn centres, radii and normals of both coils in the pad frame for one pose (lists of dicts)."""
        dz_m = NOMINAL_GAP_M if dz_m is None else dz_m
        tx = [{"radius_m": r, "x_m": 0.0, "y_m": 0.0, "z_m": z, "normal": [0.0, 0.0, 1.0]}
              for r, z in zip(self.tx.radius_m, self.tx.z_m)]
        rot, org = _rx_frame(dx_m, dy_m, dz_m, tilt_rad, tilt_axis_rad)
        normal = [float(v) for v in rot @ np.array([0.0, 0.0, 1.0])]
        rx = []
        for r, z in zip(self.rx.radius_m, self.rx.z_m):
            c = rot @ np.array([0.0, 0.0, z]) + org
            rx.append({"radius_m": r, "x_m": float(c[0]), "y_m": float(c[1]), "z_m": float(c[2]), "normal": normal})
        return tx, rx


# --------------------------------------------------------------------------- defaults
# Default coils (calibrated by calibrate_default(); see README "Mission world" for the sources):
#  pad: 20-turn flat spiral of 2.2 mm-radius litz, outermost turn at 0.25 m (a 0.5 m pad);
#  drone: 8-turn flat spiral of 1.2 mm-radius litz, outermost turn at 0.12 m (a 0.24 m coil).
# The pitches and the hover gap are solved so that L1, L2, Lm equal Table I at (0, 0, gap, 0).
_TX_TURNS, _TX_OUTER_M, _TX_WIRE_M = 20, 0.25, 2.2e-3
_RX_TURNS, _RX_OUTER_M, _RX_WIRE_M = 8, 0.12, 1.2e-3
_TX_PITCH_M = 0.004842583107587363
_RX_PITCH_M = 0.005840341416759286
NOMINAL_GAP_M = 0.1748209350881188


def _default_coils(tx_pitch, rx_pitch):
    return (spiral_coil(_TX_TURNS, _TX_OUTER_M, tx_pitch, _TX_WIRE_M),
            spiral_coil(_RX_TURNS, _RX_OUTER_M, rx_pitch, _RX_WIRE_M))


def _lm_coaxial(tx: CoilGeometry, rx: CoilGeometry, gap):
    a = np.array(tx.radius_m)[:, None]
    b = np.array(rx.radius_m)[None, :]
    d = gap + np.array(rx.z_m)[None, :] - np.array(tx.z_m)[:, None]
    return float(np.sum(mutual_coaxial_h(a, b, d)))


def calibrate_default(l1_h=236e-6, l2_h=18.9e-6, lm_h=6.25e-6):
    """Solve the pad pitch, drone pitch and hover gap for the target inductances (closed forms only).

    Returns ``(tx_pitch_m, rx_pitch_m, gap_m)``.
    """
    def res(x):
        tx, rx = _default_coils(x[0], x[1])
        return [coil_self_h(tx) / l1_h - 1, coil_self_h(rx) / l2_h - 1, _lm_coaxial(tx, rx, x[2]) / lm_h - 1]
    from scipy import optimize

    sol = optimize.least_squares(res, [8e-3, 6e-3, 0.1], bounds=([4.5e-3, 2.5e-3, 0.01], [1.2e-2, 1.4e-2, 0.5]),
                                 xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return tuple(float(v) for v in sol.x)


def default_tx_coil() -> CoilGeometry:
    """The default pad coil (see module notes)."""
    return _default_coils(_TX_PITCH_M, _RX_PITCH_M)[0]


def default_rx_coil() -> CoilGeometry:
    """The default drone coil (see module notes)."""
    return _default_coils(_TX_PITCH_M, _RX_PITCH_M)[1]


@lru_cache(maxsize=1)
def default_coupling() -> CouplingModel:
    """The default pad/drone pair: L1 = 236 uH, L2 = 18.9 uH, Lm = 6.25 uH at (0, 0, NOMINAL_GAP_M, 0)."""
    return CouplingModel(default_tx_coil(), default_rx_coil())
