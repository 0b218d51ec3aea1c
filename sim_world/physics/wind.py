"""Wind: a constant mean plus seeded, reproducible gusts (`WindConfig`, from the ground floor).

Gusts are a first-order Gauss-Markov (Ornstein-Uhlenbeck) process per ENU axis,
the usual stand-in for low-altitude turbulence: a stationary standard deviation
``gust_std_m_s`` and a correlation time ``gust_time_constant_s``. The process is
sampled exactly on a fixed internal grid and linearly interpolated in between,
so the wind at time t depends only on the seed and t, not on how often or at
what step it is queried (queries must not go back in time).
"""

from __future__ import annotations

import math

import numpy as np

from drone_inspect_core.world_options import WindConfig


class Wind:
    """The wind velocity over time for one seeded run."""

    def __init__(self, config: WindConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else WindConfig()
        self._mean = tuple(float(v) for v in self.config.mean_enu_m_s)
        self._calm_gusts = self.config.gust_std_m_s == 0.0
        self._rng = np.random.default_rng(seed)
        period, tau = self.config.sample_period_s, self.config.gust_time_constant_s
        self._decay = math.exp(-period / tau)
        self._innovation_std = self.config.gust_std_m_s * math.sqrt(1.0 - self._decay**2)
        # Start in the stationary distribution, so gusts are as strong at t = 0 as later.
        self._k = 0  # index of the grid sample in _prev; _next is sample k + 1
        self._prev = tuple(self._rng.normal(0.0, self.config.gust_std_m_s, 3).tolist())
        self._next = self._draw_after(self._prev)

    def _draw_after(self, gust: tuple[float, ...]) -> tuple[float, ...]:
        noise = self._rng.normal(0.0, self._innovation_std, 3).tolist()
        return tuple(self._decay * g + n for g, n in zip(gust, noise, strict=True))

    def velocity_enu_m_s(self, t_s: float) -> np.ndarray:
        """Wind velocity at time t_s (ENU, m/s); t_s must not decrease from call to call by a grid step."""
        mx, my, mz = self._mean
        if self._calm_gusts:
            return np.array((mx, my, mz))
        period = self.config.sample_period_s
        if t_s < self._k * period:
            raise ValueError(
                f"Wind.velocity_enu_m_s: time {t_s:.4f} s is before the retained gust sample at "
                f"{self._k * period:.4f} s; query times must not go backwards"
            )
        while t_s >= (self._k + 1) * period:
            self._k += 1
            self._prev = self._next
            self._next = self._draw_after(self._prev)
        frac = t_s / period - self._k
        a, b = self._prev, self._next
        return np.array(
            (
                mx + a[0] + frac * (b[0] - a[0]),
                my + a[1] + frac * (b[1] - a[1]),
                mz + a[2] + frac * (b[2] - a[2]),
            )
        )
