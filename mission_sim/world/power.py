"""Electrical propulsion power of a multirotor from momentum theory (hover, climb, forward flight).

For total thrust ``T`` over the rotor disk area ``A = n pi R^2`` (air density rho):

* hover induced velocity ``v_h = sqrt(T / (2 rho A))`` and ideal power ``T v_h``
  (Leishman, *Principles of Helicopter Aerodynamics*, 2nd ed., 2006, ch. 2);
* forward flight at airspeed ``V`` with climb rate ``v_z``: Glauert's induced velocity
  ``v_i = v_h^2 / sqrt(V_h^2 + (v_z + v_i)^2)`` (solved by Newton's method), induced + climb power
  ``T (v_i + v_z)`` (Leishman ch. 2.15 and 5); in descent the result is floored at half the
  hover induced power (momentum theory fails in the vortex-ring state);
* profile power taken constant at its hover value ``(1/FM - 1) T_hover v_h`` (FM = figure of merit);
* parasite power ``D V`` with ``D = 0.5 rho f V^2`` (``f`` equivalent flat-plate area);
* thrust ``T = sqrt((m g + D_z)^2 + D_xy^2)`` balances weight and drag;
* electrical power = shaft power / (motor x ESC efficiency) + avionics.

Default drone (``DroneParams()``), a ~1 kg quadrotor carrying an 8S (29.6 V) pack and the WPT
receiver: 4 x 10-inch rotors (R = 0.127 m), total mass 1.0 kg, FM = 0.6 (small-scale propellers
measure 0.5-0.65 in static tests: Brandt & Selig, "Propeller performance data at low Reynolds
numbers", AIAA 2011-1255), motor x ESC efficiency 0.8 (typical of small BLDC drives),
flat-plate area 0.02 m^2, avionics 8 W. These are assumptions of typical values, not one
airframe's measurements; hover electrical power comes out at ~99 W.

Payload: ``payload_kg`` is carried from take-off (total mass ``mass_kg + payload_kg``); a route's payload
releases (``[[waypoints]] release``, a mission file's DO_GRIPPER release) drop
``release_kg`` each (0: all that is left) in route order, :func:`payload_after_releases`. The power model takes
the current mass (``mass_kg=`` of :func:`propulsion_power_w` / :func:`hover_power_w`; the planned trajectory's
mass schedule, :class:`mission_sim.world.trajectory.MassSchedule`); hover power goes as
``m^1.5`` (momentum theory, the profile power taken at the same hover induced velocity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..validation import Range, check_number, check_number_fields, check_positive

__all__ = ["takeoff_excess", "DroneParams", "DRONE_RANGES", "propulsion_power_w", "hover_power_w", "payload_after_releases", "G_M_S2"]

G_M_S2 = 9.80665


#: The values a real multirotor can have for each :class:`DroneParams` field: the config's ``drone.*`` ranges
#: (:data:`mission_sim.config.PLAUSIBLE`, one source; a mission, replay, sweep or calibrate refuses a value outside
#: them naming the value and the range). They admit the multirotors of up to ~1 t without payload, from a nano
#: quadrotor (Crazyflie 2.1: 27 g, 47 mm propellers) and a 0.25 kg micro (~4.7-inch propellers, R 0.06 m) to
#: 15-35 kg heavy lifters (21- to 33-inch propellers, R 0.27-0.42 m), crop sprayers (54-inch, R 0.69 m; ~100 kg
#: take-off) and the lighter passenger multirotors (up to 18 rotors of R ~1 m, ~900 kg take-off), and calibrate's
#: fit bounds (``mavlink.calibrate.BOUNDS``); the figures are manufacturers' data sheets, rounded. Not every real
#: multirotor: heavier passenger craft (Airbus's CityAirbus demonstrator, ~2.2 t take-off) lie above ``mass_kg``'s
#: 1 t, and a passenger craft's avionics and cabin systems may draw more than ``avionics_w``'s 1 kW (no source
#: here bounds them):
#:
#: * ``mass_kg`` 0.01-1000 kg (the vehicle without payload), ``payload_kg`` and ``release_kg`` 0-1000 kg: those
#:   masses (``release_kg`` at most ``payload_kg``: :class:`DroneParams`);
#: * ``n_rotors`` 1..32 (a single rotor to 18 with margin);
#: * ``rotor_radius_m`` 0.01-2 m: 20 mm propellers to twice a passenger multirotor's rotor (R = 5 m is a light
#:   helicopter's main rotor, refused since 2026-11-28; before: 0.01-10 m);
#: * ``figure_of_merit`` 0.2-0.9: micro propellers at low Reynolds numbers ~0.3-0.5, small propellers 0.5-0.65
#:   (Brandt & Selig, above), full-scale rotors 0.7-0.8 (Leishman ch. 2); 1 is the ideal rotor (before: 0.05-1);
#: * ``drive_efficiency`` (motor x ESC) 0.2-0.98: brushed coreless micro motors ~0.3-0.6, BLDC drives 0.7-0.9, the
#:   best large ones ~0.95 (before: 0.05-1);
#: * ``flat_plate_area_m2`` 1e-4-5 m^2 (frontal area x drag coefficient ~1): a nano quadrotor ~1e-3, the default
#:   1 kg quad 0.02, a 25 kg lifter ~0.5, a passenger multirotor a few m^2 (before: (0, 100]);
#: * ``avionics_w`` 0-1000 W: none modelled to a heavy lifter's or sprayer's avionics and payload electronics
#:   (before: 0-10 kW; a passenger craft's may be above it, see above);
#: * ``air_density_kg_m3`` 0.05-2: Earth's air from cold sea level (1.4) to far above any multirotor's ceiling.
#: * ``max_takeoff_mass_kg`` 0.01-2000 kg (``mass_kg`` + ``payload_kg`` at their largest), unset by default: the
#:   airframe's maximum take-off mass from its data sheet, when the user gives it (see :class:`DroneParams`).
#:
#: :class:`DroneParams` itself checks only what its formulas need (positive, FM and efficiency in (0, 1]): a
#: physics test may build the ideal rotor (FM 1, f -> 0); a config cannot.
DRONE_RANGES: dict[str, Range] = {
    "mass_kg": Range(0.01, 1000.0, "kg"), "payload_kg": Range(0.0, 1000.0, "kg"),
    "release_kg": Range(0.0, 1000.0, "kg"),
    "n_rotors": Range(1, 32, integer=True), "rotor_radius_m": Range(0.01, 2.0, "m"),
    "figure_of_merit": Range(0.2, 0.9), "drive_efficiency": Range(0.2, 0.98),
    "flat_plate_area_m2": Range(1e-4, 5.0, "m^2"), "avionics_w": Range(0.0, 1000.0, "W"),
    "air_density_kg_m3": Range(0.05, 2.0, "kg/m^3"),
    "max_takeoff_mass_kg": Range(0.01, 2000.0, "kg"),
}


#: relative tolerance of the take-off mass check: 0.1 + 0.2 is 0.30000000000000004 in binary, not above a 0.3 kg limit
MTOM_REL_TOL = 1e-9


def takeoff_excess(label: str, mass_kg: float, payload_kg: float, max_takeoff_mass_kg: float | None,
                   fmt: str = ".3f") -> str | None:
    """``"<label> M kg [+ payload_kg P kg] is above drone.max_takeoff_mass_kg=L kg"`` when ``mass_kg + payload_kg`` is
    above the limit (:func:`above_max_takeoff`), else None (also for a mass that is not finite): the head of replay's
    and calibrate's warnings about a fitted mass."""
    if not math.isfinite(mass_kg) or not above_max_takeoff(mass_kg, payload_kg, max_takeoff_mass_kg):
        return None
    load = f" + payload_kg {payload_kg:g} kg" if payload_kg else ""
    return f"{label} {mass_kg:{fmt}} kg{load} is above drone.max_takeoff_mass_kg={max_takeoff_mass_kg:g} kg"


def above_max_takeoff(mass_kg: float, payload_kg: float, max_takeoff_mass_kg: float | None) -> bool:
    """True when ``mass_kg + payload_kg`` is above ``max_takeoff_mass_kg`` (None: no limit) by more than rounding
    (:data:`MTOM_REL_TOL`): the one test of :class:`DroneParams` and of the fitted masses of replay / calibrate."""
    if max_takeoff_mass_kg is None:
        return False
    total = float(mass_kg) + float(payload_kg)
    return total > max_takeoff_mass_kg and not math.isclose(total, max_takeoff_mass_kg, rel_tol=MTOM_REL_TOL)


@dataclass(frozen=True)
class DroneParams:
    """Multirotor parameters (SI). See module notes for where the defaults come from; a config's values must also lie
    in :data:`DRONE_RANGES` (the physical ranges, with their sources).

    ``mass_kg``: the drone ready to fly (airframe, battery, receiver) [kg]; ``payload_kg``: the payload carried
    from take-off [kg]; ``release_kg``: the payload mass dropped at each release of the route [kg] (0: the first
    release drops all of it; e.g. three 0.3 kg parcels: ``payload_kg = 0.9``, ``release_kg = 0.3``), at most
    ``payload_kg``.

    ``max_takeoff_mass_kg``: the airframe's maximum take-off mass [kg] (its data sheet's), or None (the default):
    no limit. The power model has none of its own: momentum theory gives a power for any mass, and nothing here
    knows the motors', propellers' or ESCs' limits (only the battery's maximum power stops a run, at the first
    sample it cannot supply), so a payload the drone cannot lift was flown. When set, a take-off mass
    ``mass_kg + payload_kg`` above it is refused (one line naming both); no default is assumed without a source."""

    mass_kg: float = 1.0
    payload_kg: float = 0.0
    release_kg: float = 0.0
    n_rotors: int = 4
    rotor_radius_m: float = 0.127
    figure_of_merit: float = 0.6
    drive_efficiency: float = 0.8
    flat_plate_area_m2: float = 0.02
    avionics_w: float = 8.0
    air_density_kg_m3: float = 1.225
    max_takeoff_mass_kg: float | None = None

    def __post_init__(self):
        check_number_fields(self)
        check_positive(self, "mass_kg", "rotor_radius_m", "flat_plate_area_m2", "air_density_kg_m3")
        check_positive(self, "payload_kg", "release_kg", "avionics_w", allow_zero=True)
        if self.release_kg > self.payload_kg:
            raise ValueError(f"release_kg={self.release_kg!r} is invalid; valid range: [0, payload_kg="
                             f"{self.payload_kg!r}] kg (the mass dropped at each payload release; 0: all of it)")
        mtom = self.max_takeoff_mass_kg
        if mtom is not None:
            check_positive(self, "max_takeoff_mass_kg")
            if above_max_takeoff(self.mass_kg, 0.0, mtom):
                raise ValueError(f"mass_kg={self.mass_kg!r} is invalid; valid range: [{DRONE_RANGES['mass_kg'].lo:g}, "
                                 f"max_takeoff_mass_kg={mtom!r}] kg (the airframe's maximum take-off mass)")
            if above_max_takeoff(self.mass_kg, self.payload_kg, mtom):
                raise ValueError(f"payload_kg={self.payload_kg!r} is invalid: the take-off mass mass_kg + payload_kg "
                                 f"= {self.mass_kg + self.payload_kg:g} kg is above max_takeoff_mass_kg={mtom!r} kg; "
                                 f"valid range: [0, {max(mtom - self.mass_kg, 0.0):g}] kg (a payload the drone can lift)")
        for name in ("figure_of_merit", "drive_efficiency"):
            v = float(getattr(self, name))
            if not 0 < v <= 1:
                raise ValueError(f"{name}={v!r} is invalid; valid range: (0, 1]")
        # a Python int from any whole number (4.0, np.int64(4)); a string such as "4" refused (float("4") is not
        # asked: "4" would pass and fail later, in hover_power_w's n_rotors * pi R^2)
        object.__setattr__(self, "n_rotors", check_number("n_rotors", self.n_rotors, Range(1, math.inf, integer=True)))

    @property
    def total_mass_kg(self) -> float:
        return self.mass_kg + self.payload_kg

    @property
    def disk_area_m2(self) -> float:
        return self.n_rotors * math.pi * self.rotor_radius_m**2


def propulsion_power_w(p: DroneParams, airspeed_m_s, climb_rate_m_s=0.0, mass_kg=None):
    """Electrical propulsion power [W] at horizontal airspeed [m/s] and climb rate [m/s] (arrays broadcast);
    ``mass_kg``: the total mass flown [kg] (an array broadcast with them: a mass schedule), None for
    ``p.total_mass_kg`` (the take-off mass)."""
    v = np.abs(np.asarray(airspeed_m_s, dtype=float))
    vz = np.asarray(climb_rate_m_s, dtype=float)
    rho, f, area = p.air_density_kg_m3, p.flat_plate_area_m2, p.disk_area_m2
    if mass_kg is None:
        v, vz = np.broadcast_arrays(v, vz)
        w = p.total_mass_kg * G_M_S2
    else:
        v, vz, w = np.broadcast_arrays(v, vz, np.asarray(mass_kg, dtype=float) * G_M_S2)
    d_xy = 0.5 * rho * f * v * v
    d_z = 0.5 * rho * f * vz * np.abs(vz)
    thrust = np.hypot(w + d_z, d_xy)
    vh = np.sqrt(thrust / (2 * rho * area))
    # Newton on F(vi) = vi sqrt(V^2 + (vz + vi)^2) - vh^2, start from the climb solution
    vi = np.maximum(-0.5 * vz + np.sqrt(0.25 * vz * vz + vh * vh), 0.05 * vh)
    for _ in range(30):
        s = np.sqrt(v * v + (vz + vi) ** 2)
        fval = vi * s - vh * vh
        dfdv = s + vi * (vz + vi) / s
        vi = np.maximum(vi - fval / dfdv, 1e-6)
    vh_hover = np.sqrt(w / (2 * rho * area))   # (IEEE sqrt is correctly rounded: math.sqrt's bits for a scalar)
    p_induced = thrust * (vi + vz)
    p_induced = np.where(vz < 0, np.maximum(p_induced, 0.5 * w * vh_hover), p_induced)
    p_profile = (1.0 / p.figure_of_merit - 1.0) * w * vh_hover
    p_shaft = p_induced + p_profile + d_xy * v
    out = p_shaft / p.drive_efficiency + p.avionics_w
    return out if out.ndim else float(out)


def hover_power_w(p: DroneParams, mass_kg: float | None = None) -> float:
    """Electrical hover power [W]: ``T^1.5 / sqrt(2 rho A) / FM / eta + avionics`` with ``T = m g``, ``m`` =
    ``mass_kg`` (None: ``p.total_mass_kg``, the take-off mass)."""
    w = (p.total_mass_kg if mass_kg is None else float(mass_kg)) * G_M_S2
    return w**1.5 / math.sqrt(2 * p.air_density_kg_m3 * p.disk_area_m2) / p.figure_of_merit / p.drive_efficiency \
        + p.avionics_w


def payload_after_releases(p: DroneParams, n_releases: int) -> tuple[list[float], int]:
    """The payload left on board [kg] after each of ``n_releases`` releases in route order (each drops
    ``p.release_kg``, 0: all that is left; never more than is left), and how many of them found nothing to drop
    (no payload left: :func:`mission_sim.setup_warnings.payload_warnings` says so). A remainder below 1e-12 of the
    payload (``0.9 - 3 x 0.3`` in floats) is 0, so the drone after its last parcel weighs ``mass_kg`` exactly."""
    left, out, empty = float(p.payload_kg), [], 0
    for _ in range(int(n_releases)):
        if left <= 0.0:
            empty += 1
        drop = left if p.release_kg == 0 else min(p.release_kg, left)
        left = left - drop
        if left <= 1e-12 * p.payload_kg:
            left = 0.0
        out.append(left)
    return out, empty
