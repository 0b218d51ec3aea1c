"""Typed flight errors. Each carries the call that failed (`origin`) and why (`result`, `detail`).

Like MAVSDK's `OffboardError(result, "start()")`, so that a log line or a caught
exception says which step of a flight went wrong without a traceback.
"""

from __future__ import annotations


class FlightError(Exception):
    """Base class: `origin` is the call that failed, `result` a short code, `detail` the explanation."""

    def __init__(self, origin: str, result: str, detail: str = "") -> None:
        self.origin = origin
        self.result = result
        self.detail = detail
        self.aftermath = ""
        super().__init__(f"{origin}: {result}" + (f" ({detail})" if detail else ""))

    def add_aftermath(self, text: str) -> None:
        """Say what was done about the failure (the message, and so a report, ends with it)."""
        self.aftermath = text
        self.args = (f"{self.args[0]}; {text}",)


class ConnectionUrlError(FlightError, ValueError):
    """The connection URL cannot work; the message says how to fix it."""

    def __init__(self, url: str, detail: str) -> None:
        self.url = url
        super().__init__("connect()", "CONNECTION_URL_INVALID", f"{url!r}: {detail}")


class VehicleConnectionError(FlightError):
    """No autopilot answered on the connection, or the connection could not be opened."""


class FlightTimeoutError(FlightError):
    """A wait on the vehicle ran past its timeout."""

    def __init__(self, origin: str, timeout_s: float, waiting_for: str) -> None:
        self.timeout_s = timeout_s
        self.waiting_for = waiting_for
        super().__init__(origin, "TIMEOUT", f"no {waiting_for} within {timeout_s:.1f} s")


class CommandDeniedError(FlightError):
    """The vehicle (or the backend, for a command that cannot be sent in this state) refused a command."""


class ModeChangeError(FlightError):
    """A mode change was acknowledged (or not) but telemetry never showed the requested mode."""

    def __init__(self, origin: str, wanted: str, observed: str, timeout_s: float) -> None:
        self.wanted = wanted
        self.observed = observed
        super().__init__(
            origin,
            "MODE_NOT_CONFIRMED",
            f"wanted {wanted}, telemetry still shows {observed} after {timeout_s:.1f} s",
        )


class LinkLostError(FlightError):
    """The vehicle stopped answering: no heartbeat or telemetry for longer than the link timeout."""

    def __init__(self, origin: str, silent_s: float, timeout_s: float, why: str | None = None) -> None:
        self.silent_s = silent_s
        self.timeout_s = timeout_s
        detail = f"no telemetry for {silent_s:.1f} s (link timeout {timeout_s:.1f} s)"
        super().__init__(origin, "LINK_LOST", detail if why is None else f"{why}; {detail}")


class OffboardInterruptedError(FlightError):
    """The vehicle left offboard by itself (failsafe, pilot switch): setpoints no longer steer it."""

    def __init__(self, origin: str, mode: str, status_text: str = "") -> None:
        self.mode = mode
        self.status_text = status_text
        detail = f"vehicle switched to {mode}" + (f": {status_text!r}" if status_text else "")
        super().__init__(origin, "OFFBOARD_LOST", detail)


class GeofenceBreachError(FlightError):
    """The vehicle is outside the geofence box (beyond its margin) around the start point."""


class TakeoffOvershootError(FlightError):
    """A takeoff climbed well past the altitude asked for (and was stopped in Hold): on PX4, copies of one
    takeoff command each start a new takeoff from the altitude the drone has reached (see
    `flight.mavsdk.vehicle.MavsdkVehicle.takeoff`)."""

    def __init__(self, origin: str, height_m: float, asked_m: float, limit_m: float) -> None:
        super().__init__(
            origin,
            "TAKEOFF_OVERSHOOT",
            f"climbed to {height_m:.2f} m on a takeoff to {asked_m:.2f} m (the limit is {limit_m:.2f} m): "
            "stopped in Hold",
        )
