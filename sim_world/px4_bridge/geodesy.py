"""Where the simulated drone is on Earth: the home point, the magnetic field there, the air pressure.

PX4 checks its sensors against the Earth it expects at the GPS position: it takes
the magnetic declination, inclination and strength from its own World Magnetic
Model tables, and its barometer altitude from the standard atmosphere. The bridge
therefore computes the field with the World Magnetic Model (WMM2025, through
`pygeomag`) at the home point, so that PX4's heading estimate and the simulator's
truth agree; over a mission's few metres the field is constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

from sim_world.vehicle.telemetry import HomePoint

__all__ = ["HomePoint", "MagneticField", "magnetic_field_ned_gauss", "pressure_hpa", "temperature_c"]

SEA_LEVEL_PRESSURE_HPA = 1013.25
SEA_LEVEL_TEMPERATURE_K = 288.15
LAPSE_RATE_K_M = 0.0065
_BARO_EXPONENT = 5.255877  # g·M / (R·L) of the standard atmosphere


@dataclass(frozen=True)
class MagneticField:
    """The Earth's field at a place, in the local NED frame (gauss), with its angles."""

    north_gauss: float
    east_gauss: float
    down_gauss: float

    @property
    def strength_gauss(self) -> float:
        return math.sqrt(self.north_gauss**2 + self.east_gauss**2 + self.down_gauss**2)

    @property
    def declination_deg(self) -> float:
        return math.degrees(math.atan2(self.east_gauss, self.north_gauss))

    @property
    def inclination_deg(self) -> float:
        return math.degrees(math.atan2(self.down_gauss, math.hypot(self.north_gauss, self.east_gauss)))

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.north_gauss, self.east_gauss, self.down_gauss)


@lru_cache(maxsize=64)
def magnetic_field_ned_gauss(
    latitude_deg: float, longitude_deg: float, altitude_m: float, decimal_year: float
) -> MagneticField:
    """The World Magnetic Model's main field at a place and date (1 gauss = 100,000 nT)."""
    from pygeomag import GeoMag  # a small pure-Python WMM; imported when a bridge starts

    result = GeoMag().calculate(
        glat=latitude_deg, glon=longitude_deg, alt=altitude_m / 1000.0, time=decimal_year
    )
    return MagneticField(result.x / 1e5, result.y / 1e5, result.z / 1e5)


def pressure_hpa(altitude_amsl_m: float) -> float:
    """Static pressure of the standard atmosphere (troposphere) at an altitude above mean sea level."""
    ratio = 1.0 - LAPSE_RATE_K_M * altitude_amsl_m / SEA_LEVEL_TEMPERATURE_K
    return SEA_LEVEL_PRESSURE_HPA * ratio**_BARO_EXPONENT


def temperature_c(altitude_amsl_m: float) -> float:
    """Air temperature of the standard atmosphere at an altitude above mean sea level."""
    return SEA_LEVEL_TEMPERATURE_K - LAPSE_RATE_K_M * altitude_amsl_m - 273.15
