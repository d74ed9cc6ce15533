"""Geodetic positions to a local east-north-up frame, velocities from speed and course, units.

Recorded data give WGS-84 latitude, longitude (degrees) and altitude (metres above the
ellipsoid); trackkit works in a local Cartesian frame: x east, y north, z up, in metres, with
its origin at a reference point. The conversion is done once, when a file is read, with
``pymap3d`` (exact ECEF rotation, no flat-earth approximation), and the reference is kept
with the data so that tracks can be written back as latitude and longitude
(:meth:`EnuFrame.to_geodetic`).

Courses and headings are nautical (clockwise from north), so a speed ``s`` along course ``c``
is ``vx = s sin c`` (east), ``vy = s cos c`` (north), as ``atan2(dx, dy)`` elsewhere in trackkit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ANGLE_UNITS",
    "DISTANCE_UNITS",
    "KNOT",
    "NAUTICAL_MILE",
    "SPEED_UNITS",
    "EnuFrame",
    "velocity_from_course",
    "course_from_velocity",
    "ground_geodetic",
]

Array = NDArray[np.float64]

#: One nautical mile in metres (exact by definition).
NAUTICAL_MILE = 1852.0  # metres, exact by definition
#: One knot in metres per second.
KNOT = NAUTICAL_MILE / 3600.0  # metres per second

#: Factors to metres for the distance unit names the readers accept.
DISTANCE_UNITS = {"m": 1.0, "km": 1000.0, "nmi": NAUTICAL_MILE}
#: Factors to metres per second for the speed unit names the readers accept.
SPEED_UNITS = {"m/s": 1.0, "kn": KNOT, "km/h": 1000.0 / 3600.0}
#: Factors to radians for the angle unit names the readers accept.
ANGLE_UNITS = {"rad": 1.0, "deg": np.pi / 180.0}


def unit_factor(table: dict[str, float], unit: str, what: str) -> float:
    """The SI factor of ``unit`` from ``table``; a clear error for an unknown name."""
    try:
        return table[unit]
    except KeyError:
        raise ValueError(f"{what} unit {unit!r} is not known; expected one of "
                         f"{', '.join(map(repr, table))}") from None


@dataclass(frozen=True)
class EnuFrame:
    """A local east-north-up frame at the WGS-84 point ``(lat0, lon0, alt0)`` (deg, deg, m).

    ``to_enu`` and ``to_geodetic`` are inverse to within 1e-9 deg (far below a millimetre)
    anywhere a tracker would use one frame (hundreds of km).
    """

    lat0: float
    lon0: float
    alt0: float = 0.0

    def __post_init__(self) -> None:
        for name, lo, hi in (("lat0", -90.0, 90.0), ("lon0", -180.0, 180.0),
                             ("alt0", -np.inf, np.inf)):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"EnuFrame.{name} = {v!r}; expected a finite value in "
                                 f"[{lo}, {hi}]")
            object.__setattr__(self, name, v)

    @classmethod
    def at_median(cls, lat: ArrayLike, lon: ArrayLike, alt: float = 0.0) -> EnuFrame:
        """The frame at the median latitude and longitude of the data (robust to the odd
        wild report, unlike the mean). Longitudes are taken as given, so data that straddle
        the 180 deg meridian need an explicit reference."""
        lat = np.asarray(lat, dtype=float)
        lon = np.asarray(lon, dtype=float)
        if lat.size == 0:
            raise ValueError("EnuFrame.at_median: no positions; pass the reference explicitly")
        return cls(float(np.median(lat)), float(np.median(lon)), float(alt))

    def to_enu(self, lat: ArrayLike, lon: ArrayLike, alt: ArrayLike = 0.0
               ) -> tuple[Array, Array, Array]:
        """Latitude, longitude (deg) and altitude (m) to east, north, up (m), vectorised."""
        import pymap3d

        e, n, u = pymap3d.geodetic2enu(np.asarray(lat, dtype=float), np.asarray(lon, dtype=float),
                                       np.asarray(alt, dtype=float), self.lat0, self.lon0,
                                       self.alt0)
        return np.asarray(e, dtype=float), np.asarray(n, dtype=float), np.asarray(u, dtype=float)

    def to_geodetic(self, x: ArrayLike, y: ArrayLike, z: ArrayLike = 0.0
                    ) -> tuple[Array, Array, Array]:
        """East, north, up (m) back to latitude, longitude (deg) and altitude (m)."""
        import pymap3d

        lat, lon, alt = pymap3d.enu2geodetic(np.asarray(x, dtype=float),
                                             np.asarray(y, dtype=float),
                                             np.asarray(z, dtype=float), self.lat0, self.lon0,
                                             self.alt0)
        return (np.asarray(lat, dtype=float), np.asarray(lon, dtype=float),
                np.asarray(alt, dtype=float))


def velocity_from_course(speed: ArrayLike, course: ArrayLike, speed_unit: str = "kn",
                         course_unit: str = "deg") -> tuple[Array, Array]:
    """Speed over ground and nautical course (or heading) to ``(vx east, vy north)`` in m/s.

    ``speed_unit`` is ``"kn"``, ``"m/s"`` or ``"km/h"``; ``course_unit`` ``"deg"`` or ``"rad"``.
    nan in either input gives nan (velocity not known).
    """
    s = np.asarray(speed, dtype=float) * unit_factor(SPEED_UNITS, speed_unit, "speed")
    c = np.asarray(course, dtype=float) * unit_factor(ANGLE_UNITS, course_unit, "course")
    return s * np.sin(c), s * np.cos(c)


def course_from_velocity(vx: ArrayLike, vy: ArrayLike, speed_unit: str = "kn",
                         course_unit: str = "deg") -> tuple[Array, Array]:
    """The inverse of :func:`velocity_from_course`: ``(speed, course)`` with the course in
    [0, 360) deg (or [0, 2 pi) rad)."""
    vx = np.asarray(vx, dtype=float)
    vy = np.asarray(vy, dtype=float)
    s = np.hypot(vx, vy) / unit_factor(SPEED_UNITS, speed_unit, "speed")
    c = np.mod(np.arctan2(vx, vy), 2 * np.pi) / unit_factor(ANGLE_UNITS, course_unit, "course")
    return s, c


def ground_geodetic(frame: EnuFrame, x: Array, y: Array) -> tuple[Array, Array]:
    """Latitude and longitude (deg) of the points at east ``x``, north ``y`` (m) of ``frame``
    on the ellipsoid (altitude 0). A track is 2-D, so this is its ground point; the up
    coordinate that puts it there (about -(x^2 + y^2) / 2 R, the earth's curvature) is found
    by two corrections along the frame's up axis, exact to millimetres within 500 km."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    z = -(x * x + y * y) / (2 * 6371e3)
    for _ in range(2):
        lat, lon, alt = frame.to_geodetic(x, y, z)
        z = z - alt
    lat, lon, _ = frame.to_geodetic(x, y, z)
    return lat, lon
