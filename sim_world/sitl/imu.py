"""The IMU as an autopilot sees it: the simulator's truth plus white noise, a power-on bias and a slow
bias random walk, per axis (the usual MEMS model: noise given as a density per √Hz, so the
per-sample spread follows the sample rate).

`SensorNoise` holds the sigmas of every sensor the PX4 bridge simulates (the ArduPilot bridge uses
the IMU's only: ArduPilot simulates its GPS, barometer and compass itself from the pose it is sent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

GRAVITY_NED_M_S2 = np.array([0.0, 0.0, 9.80665])


@dataclass(frozen=True)
class SensorNoise:
    """Noise, bias and drift of each sensor (1-sigma values)."""

    accel_noise_density: float = 0.002  # m/s²/√Hz (≈ 0.03 m/s² per sample at 250 Hz)
    accel_bias_m_s2: float = 0.02  # power-on bias
    accel_bias_walk: float = 0.0004  # m/s² per √s
    gyro_noise_density: float = 0.0002  # rad/s/√Hz (≈ 0.003 rad/s per sample at 250 Hz)
    gyro_bias_rad_s: float = 0.002
    gyro_bias_walk: float = 0.00004  # rad/s per √s
    mag_noise_gauss: float = 0.002  # per sample
    mag_bias_gauss: float = 0.005  # residual hard-iron offset after calibration
    baro_noise_m: float = 0.08  # per sample, as altitude
    baro_drift_m: float = 0.15  # slow drift (Gauss-Markov, below)
    baro_drift_time_s: float = 120.0
    gps_position_noise_m: float = 0.02  # white, per fix
    gps_position_drift_m: float = 0.08  # slow horizontal wander (Gauss-Markov)
    gps_altitude_drift_m: float = 0.15
    gps_drift_time_s: float = 60.0
    gps_velocity_noise_m_s: float = 0.02

    def scaled(self, factor: float) -> SensorNoise:
        """All sigmas × factor (0: perfect sensors; time constants unchanged)."""
        if not factor >= 0.0:
            raise ValueError(f"noise scale must be >= 0, got {factor}")
        return replace(
            self,
            **{f.name: getattr(self, f.name) * factor for f in fields(self) if not f.name.endswith("time_s")},
        )


@dataclass(frozen=True)
class Truth:
    """The simulator's state at one instant, in the autopilot's frames, relative to home."""

    time_s: float
    position_ned_m: np.ndarray  # (3,)
    velocity_ned_m_s: np.ndarray  # (3,)
    acceleration_ned_m_s2: np.ndarray  # (3,) kinematic, gravity not included
    rotation_ned_frd: np.ndarray  # (3, 3) body FRD vectors to NED
    rates_frd_rad_s: np.ndarray  # (3,)


@dataclass(frozen=True)
class ImuReading:
    accel_frd_m_s2: np.ndarray
    gyro_frd_rad_s: np.ndarray


class ImuModel:
    """Accelerometer (specific force) and gyro in body FRD, drawn from `rng`.

    The biases are drawn at construction (accelerometer first, then gyro), so a caller sharing the
    stream with other sensors keeps its draws in a fixed order and a run repeats exactly.
    """

    def __init__(self, noise: SensorNoise, rng: np.random.Generator, default_dt_s: float) -> None:
        self.noise, self._rng, self._default_dt_s = noise, rng, default_dt_s
        self._accel_bias = rng.normal(0.0, noise.accel_bias_m_s2, 3) if noise.accel_bias_m_s2 else np.zeros(3)
        self._gyro_bias = rng.normal(0.0, noise.gyro_bias_rad_s, 3) if noise.gyro_bias_rad_s else np.zeros(3)
        self._last_s: float | None = None

    def read(self, truth: Truth) -> ImuReading:
        n, rng = self.noise, self._rng
        last = self._last_s
        dt = self._default_dt_s if last is None or truth.time_s <= last else truth.time_s - last
        self._last_s = truth.time_s
        if n.accel_bias_walk:
            self._accel_bias = self._accel_bias + rng.normal(0.0, n.accel_bias_walk * math.sqrt(dt), 3)
        if n.gyro_bias_walk:
            self._gyro_bias = self._gyro_bias + rng.normal(0.0, n.gyro_bias_walk * math.sqrt(dt), 3)
        body_from_ned = truth.rotation_ned_frd.T
        specific_force = body_from_ned @ (truth.acceleration_ned_m_s2 - GRAVITY_NED_M_S2)
        accel = specific_force + self._accel_bias + self._white(n.accel_noise_density / math.sqrt(dt))
        gyro = truth.rates_frd_rad_s + self._gyro_bias + self._white(n.gyro_noise_density / math.sqrt(dt))
        return ImuReading(accel, gyro)

    def _white(self, sigma: float) -> np.ndarray:
        return self._rng.normal(0.0, sigma, 3) if sigma > 0 else np.zeros(3)
