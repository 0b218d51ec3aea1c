"""The drone's sensors as PX4 sees them: truth plus realistic noise, bias and drift.

Each sensor follows the usual model of a MEMS or GNSS part: white noise given as a
noise density (per √Hz, so the per-sample spread follows the sample rate), a bias
drawn at power-on, and a slow random walk of that bias. The defaults are those of
a good small flight controller (ICM-42688-class IMU, MS5611-class barometer,
a u-blox M9-class GNSS without RTK) and far below what PX4's SIH injects in v1.15
(SIH's accelerometer noise put PX4's height estimate 1.3 m off its own truth).
`SensorNoise.scaled(0)` gives perfect sensors, for tests that isolate PX4's control.

Frames: inputs are the simulator's truth in NED / body FRD; outputs are in the
units of HIL_SENSOR and HIL_GPS (m/s², rad/s, gauss, hPa, °C, degrees, metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_world.px4_bridge.geodesy import HomePoint, MagneticField, pressure_hpa, temperature_c
from sim_world.sitl.imu import GRAVITY_NED_M_S2, ImuModel, ImuReading, SensorNoise, Truth

__all__ = [
    "GRAVITY_NED_M_S2", "BaroReading", "GpsReading", "ImuReading", "SensorNoise", "SensorSuite", "Truth",
]  # fmt: skip


@dataclass(frozen=True)
class BaroReading:
    pressure_hpa: float
    pressure_altitude_m: float
    temperature_c: float


@dataclass(frozen=True)
class GpsReading:
    latitude_deg: float
    longitude_deg: float
    altitude_amsl_m: float
    velocity_ned_m_s: np.ndarray
    eph_m: float
    epv_m: float
    satellites: int


class _GaussMarkov:
    """A first-order Gauss-Markov process with a given stationary sigma and time constant."""

    def __init__(self, rng: np.random.Generator, sigma: float, time_s: float, size: int) -> None:
        self._rng, self._sigma, self._time_s = rng, sigma, time_s
        self.value = rng.normal(0.0, sigma, size) if sigma > 0 else np.zeros(size)

    def step(self, dt_s: float) -> np.ndarray:
        if self._sigma > 0:
            decay = math.exp(-dt_s / self._time_s)
            self.value = decay * self.value + self._rng.normal(
                0.0, self._sigma * math.sqrt(1.0 - decay * decay), self.value.shape
            )
        return self.value


class SensorSuite:
    """Noisy sensors over the simulator's truth; one seeded random stream, so a run repeats exactly."""

    def __init__(self, home: HomePoint, field: MagneticField, noise: SensorNoise, seed: int) -> None:
        self.home, self.field, self.noise = home, field, noise
        rng = self._rng = np.random.default_rng(seed)
        self._imu = ImuModel(noise, rng, default_dt_s=0.004)  # draws the accelerometer and gyro biases first
        self._mag_bias = rng.normal(0.0, noise.mag_bias_gauss, 3) if noise.mag_bias_gauss else np.zeros(3)
        self._baro_drift = _GaussMarkov(rng, noise.baro_drift_m, noise.baro_drift_time_s, 1)
        self._gps_drift = _GaussMarkov(rng, 1.0, noise.gps_drift_time_s, 3)
        self._gps_sigma = np.array([noise.gps_position_drift_m] * 2 + [noise.gps_altitude_drift_m])
        self._field_ned = np.array(field.as_tuple())
        self._last_gps_s: float | None = None
        self._last_baro_s: float | None = None

    def imu(self, truth: Truth) -> ImuReading:
        """Accelerometer (specific force) and gyro in body FRD."""
        return self._imu.read(truth)

    def mag(self, truth: Truth) -> np.ndarray:
        """The Earth's field in body FRD, gauss."""
        field_body = truth.rotation_ned_frd.T @ self._field_ned
        return field_body + self._mag_bias + self._white(self.noise.mag_noise_gauss)

    def baro(self, truth: Truth) -> BaroReading:
        dt = self._dt(truth.time_s, self._last_baro_s, 0.02)
        self._last_baro_s = truth.time_s
        altitude = self.home.altitude_amsl_m - float(truth.position_ned_m[2])
        drift = float(self._baro_drift.step(dt)[0])
        measured = altitude + drift + float(self._white(self.noise.baro_noise_m, 1)[0])
        return BaroReading(pressure_hpa(measured), measured, temperature_c(altitude))

    def gps(self, truth: Truth) -> GpsReading:
        n = self.noise
        dt = self._dt(truth.time_s, self._last_gps_s, 0.1)
        self._last_gps_s = truth.time_s
        error = self._gps_drift.step(dt) * self._gps_sigma + self._white(n.gps_position_noise_m)
        north, east, down = (truth.position_ned_m + error).tolist()
        lat, lon, alt = self.home.to_global(north, east, down)
        velocity = truth.velocity_ned_m_s + self._white(n.gps_velocity_noise_m_s)
        return GpsReading(lat, lon, alt, velocity, eph_m=0.5, epv_m=0.8, satellites=16)

    def _white(self, sigma: float, size: int = 3) -> np.ndarray:
        return self._rng.normal(0.0, sigma, size) if sigma > 0 else np.zeros(size)

    @staticmethod
    def _dt(now_s: float, last_s: float | None, default_s: float) -> float:
        return default_s if last_s is None or now_s <= last_s else now_s - last_s
