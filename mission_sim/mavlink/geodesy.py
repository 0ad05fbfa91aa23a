"""Geodetic <-> local ENU (east, north, up) about a reference point, and the ``--pad`` text format.

A local tangent plane with the WGS84 radii of curvature at the reference latitude: east =
dlon (N + h0) cos(lat0), north = dlat (M + h0), up = h - h0. The two directions are exact
inverses of each other; the flat-plane error against the ellipsoid is about d^2 / (2 R), i.e.
8 cm of height at 1 km, far below GPS noise over a drone flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GeoPoint", "parse_geo_point", "geodetic_to_enu", "enu_to_geodetic", "PAD_FORMAT"]

_WGS84_A_M = 6378137.0
_WGS84_E2 = 6.69437999014e-3
PAD_FORMAT = "LAT,LON[,ALT] (degrees, degrees, metres above mean sea level), e.g. -35.3632,149.1652,584"


@dataclass(frozen=True)
class GeoPoint:
    """A geodetic reference point: latitude and longitude in degrees, altitude in m AMSL (None = unset)."""

    lat_deg: float
    lon_deg: float
    alt_m: float | None = None

    def __post_init__(self):
        if not (math.isfinite(self.lat_deg) and -90.0 < self.lat_deg < 90.0):
            raise ValueError(f"latitude {self.lat_deg!r} is invalid; valid range: (-90, 90) degrees")
        if not (math.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"longitude {self.lon_deg!r} is invalid; valid range: [-180, 180] degrees")
        if self.alt_m is not None and not (math.isfinite(self.alt_m) and -500.0 <= self.alt_m <= 10000.0):
            raise ValueError(f"altitude {self.alt_m!r} is invalid; valid range: [-500, 10000] m AMSL")


def parse_geo_point(text, name: str = "--pad") -> GeoPoint:
    """``"LAT,LON[,ALT]"`` (or a list of 2 or 3 numbers, e.g. a study file's TOML array) -> :class:`GeoPoint`;
    ``ValueError`` naming the bad value and the format."""
    if isinstance(text, (list, tuple)):
        if len(text) not in (2, 3) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in text):
            raise ValueError(f"{name} {text!r} is invalid; valid format: [LAT, LON] or [LAT, LON, ALT] (numbers: "
                             f"degrees, degrees, metres above mean sea level), e.g. [-35.3632, 149.1652, 584], or "
                             f"the text {PAD_FORMAT}")
        vals = [float(v) for v in text]
    else:
        parts = [p.strip() for p in str(text).split(",")]
        if len(parts) not in (2, 3):
            raise ValueError(f"{name} {text!r} is invalid; valid format: {PAD_FORMAT}")
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"{name} {text!r} is invalid; valid format: {PAD_FORMAT}") from None
    try:
        return GeoPoint(vals[0], vals[1], vals[2] if len(vals) == 3 else None)
    except ValueError as exc:
        raise ValueError(f"{name} {text!r}: {exc}") from None


def _radii_m(lat0_deg: float, h0_m: float) -> tuple[float, float]:
    """(meridian radius M + h0, prime-vertical radius (N + h0) cos lat0) in metres per radian."""
    s = math.sin(math.radians(lat0_deg))
    w = math.sqrt(1.0 - _WGS84_E2 * s * s)
    m = _WGS84_A_M * (1.0 - _WGS84_E2) / w**3
    n = _WGS84_A_M / w
    return m + h0_m, (n + h0_m) * math.cos(math.radians(lat0_deg))


def geodetic_to_enu(lat_deg, lon_deg, alt_m, ref: GeoPoint):
    """Arrays of lat/lon [deg] and alt [m AMSL] -> (east_m, north_m, up_m) about ``ref`` (alt required)."""
    if ref.alt_m is None:
        raise ValueError("the reference point needs an altitude")
    rm, rn = _radii_m(ref.lat_deg, ref.alt_m)
    dlon = (np.asarray(lon_deg, dtype=float) - ref.lon_deg + 180.0) % 360.0 - 180.0
    east = np.radians(dlon) * rn
    north = np.radians(np.asarray(lat_deg, dtype=float) - ref.lat_deg) * rm
    return east, north, np.asarray(alt_m, dtype=float) - ref.alt_m


def enu_to_geodetic(east_m, north_m, up_m, ref: GeoPoint):
    """Inverse of :func:`geodetic_to_enu`: (lat_deg, lon_deg, alt_m AMSL)."""
    if ref.alt_m is None:
        raise ValueError("the reference point needs an altitude")
    rm, rn = _radii_m(ref.lat_deg, ref.alt_m)
    lat = ref.lat_deg + np.degrees(np.asarray(north_m, dtype=float) / rm)
    lon = (ref.lon_deg + np.degrees(np.asarray(east_m, dtype=float) / rn) + 180.0) % 360.0 - 180.0
    return lat, lon, ref.alt_m + np.asarray(up_m, dtype=float)
