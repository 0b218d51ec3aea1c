"""A simple battery for BATTERY_STATUS and SYS_STATUS: constant currents, linear voltage.

Good enough for a client to see a plausible, falling charge: a 4S 5 Ah pack draws a
fixed current when disarmed, armed on the ground and flying; the voltage falls
linearly from full to empty with the charge used.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class BatteryConfig:
    capacity_mah: float = 5000.0
    cells: int = 4
    cell_full_v: float = 4.2
    cell_empty_v: float = 3.5
    idle_current_a: float = 0.4  # disarmed: companion computer, radios
    armed_current_a: float = 2.5  # armed, rotors idling on the ground
    flight_current_a: float = 16.0  # hover of a ~1.5 kg inspection quadrotor

    def __post_init__(self) -> None:
        if self.capacity_mah <= 0 or self.cells <= 0 or self.cell_empty_v >= self.cell_full_v:
            raise ValueError(f"BatteryConfig: implausible battery {self}")


class BatteryModel:
    """Integrates the current drawn over simulated time."""

    def __init__(self, config: BatteryConfig | None = None):
        self.config = config or BatteryConfig()
        self.consumed_mah = 0.0
        self.current_a = self.config.idle_current_a

    def update(self, dt_s: float, armed: bool, in_air: bool) -> None:
        c = self.config
        self.current_a = c.flight_current_a if in_air else (c.armed_current_a if armed else c.idle_current_a)
        self.consumed_mah = min(c.capacity_mah, self.consumed_mah + self.current_a * dt_s * 1000.0 / 3600.0)

    @property
    def remaining(self) -> float:
        """Charge left, 0..1."""
        return 1.0 - self.consumed_mah / self.config.capacity_mah

    @property
    def voltage_v(self) -> float:
        c = self.config
        return c.cells * (c.cell_empty_v + (c.cell_full_v - c.cell_empty_v) * self.remaining)
