"""A takeoff carries its own altitude: NAV_TAKEOFF with param7 an AMSL altitude (PX4 and the sim-vehicle
read it so), yaw and position NaN, sent through MAVSDK's MavlinkDirect. No MIS_TAKEOFF_ALT is set, so no
parameter save is waited out before arming, and a copy that arrives after liftoff climbs to the same
altitude rather than on from where the drone is. A vehicle without a global position estimate gets
MAVSDK's takeoff to MIS_TAKEOFF_ALT (test_mavsdk_takeoff_copies, test_mavsdk_parameter_save).

MAVSDK's plugins are replaced by fakes (named so) and telemetry is written into the backend's cache as
MAVSDK's thread would; real takeoffs with the altitude in the command run against PX4 in test_px4_sitl
and against the sim-vehicle in test_flight_mavsdk."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import pytest
from mavsdk.plugins.mavlink_direct import MavlinkDirectError, MavlinkDirectResult, MavlinkMessage

from flight.errors import CommandDeniedError
from flight.mavsdk.link import COMMAND_ATTEMPTS, MavsdkConfig
from flight.mavsdk.vehicle import MavsdkVehicle
from flight.types import FlightMode

HOME_AMSL_M = 488.0


class FakeMavlinkDirect:
    """Answers each COMMAND_LONG with `result` (a MAV_RESULT), or raises MavlinkDirectError(TIMEOUT) when
    `result` is None (every ack lost); `on_command` says what the vehicle did with it."""

    def __init__(self, vehicle: MavsdkVehicle, result: int | None, on_command: object) -> None:
        self.vehicle, self.result, self.on_command = vehicle, result, on_command
        self.sent: list[tuple[MavlinkMessage, dict]] = []

    def send_command(self, message: MavlinkMessage) -> MavlinkMessage:
        fields = json.loads(message.fields_json)
        self.sent.append((message, fields))
        self.on_command(self.vehicle._cache, len(self.sent))  # type: ignore[operator]
        self.vehicle._cache.link.heard()
        if self.result is None:
            raise MavlinkDirectError(MavlinkDirectResult.TIMEOUT, "send_command()", message)
        ack = {"command": fields["command"], "result": self.result}
        return MavlinkMessage("COMMAND_ACK", fields["target_system"], 1, 245, 190, json.dumps(ack))


class FakeMavsdkAction:
    """MAVSDK's takeoff path, counted: it must not be used while the vehicle has a global position."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def set_takeoff_altitude(self, altitude_m: float) -> None:
        self.calls.append(f"set_takeoff_altitude({altitude_m})")

    def takeoff(self) -> None:
        self.calls.append("takeoff()")


def _arrive(cache: object, height_m: float) -> None:
    cache.mode, cache.in_air = FlightMode.HOLD, True  # type: ignore[attr-defined]
    cache.position, cache.velocity = (0.0, 0.0, -height_m), (0.0, 0.0, 0.0)  # type: ignore[attr-defined]


def _ready_vehicle(
    result: int | None, on_command: object, global_position: bool = True, height_m: float = 0.0
) -> tuple[MavsdkVehicle, FakeMavlinkDirect, FakeMavsdkAction]:
    """Armed by this backend on ground 0.02 m below its estimate's origin, `height_m` above it now."""
    vehicle = MavsdkVehicle(MavsdkConfig(url="udpin://127.0.0.1:14540", link_timeout_s=5.0))
    direct, action = FakeMavlinkDirect(vehicle, result, on_command), FakeMavsdkAction()
    vehicle._direct, vehicle._action = direct, action  # type: ignore[assignment]
    vehicle._system = SimpleNamespace(get_system_id=lambda: 7)
    amsl_m = HOME_AMSL_M + height_m
    vehicle._telemetry = SimpleNamespace(position=lambda: SimpleNamespace(absolute_altitude_m=amsl_m))  # type: ignore[assignment]
    vehicle._ground_down_m = 0.02
    cache = vehicle._cache
    cache.armed, cache.in_air, cache.mode = True, False, FlightMode.HOLD
    cache.global_position_ok = global_position
    cache.position = (0.0, 0.0, 0.02 - height_m)
    cache.link.heard()
    vehicle._arm_asked = True
    return vehicle, direct, action


def test_the_takeoff_carries_its_altitude_and_nothing_is_set_before_arming() -> None:
    vehicle, direct, action = _ready_vehicle(0, lambda cache, _n: _arrive(cache, 1.2))
    vehicle.prepare_takeoff(1.2)  # nothing to prepare: no parameter, no wait for PX4's save
    vehicle.takeoff(1.2, timeout_s=2.0)
    assert action.calls == []
    [(message, fields)] = direct.sent
    assert (message.message_name, message.target_system_id, message.target_component_id) == (
        "COMMAND_LONG",
        7,
        1,
    )
    assert (fields["command"], fields["target_system"], fields["target_component"]) == (22, 7, 1)
    assert (
        fields["param4"] is None and fields["param5"] is None and fields["param6"] is None
    )  # NaN: as they are
    assert fields["param7"] == pytest.approx(HOME_AMSL_M + 1.2)


def test_the_altitude_is_above_the_ground_it_stood_on_not_above_where_it_is() -> None:
    # A second attempt (the vehicle disarmed and was armed again) from 0.3 m up: still 1.2 m above ground.
    vehicle, direct, _ = _ready_vehicle(0, lambda cache, _n: _arrive(cache, 1.2), height_m=0.3)
    vehicle.takeoff(1.2, timeout_s=2.0)
    assert direct.sent[0][1]["param7"] == pytest.approx(HOME_AMSL_M + 1.2)


def test_a_refused_takeoff_is_named_as_mavsdk_names_it_with_the_vehicles_words() -> None:
    vehicle, direct, _ = _ready_vehicle(2, lambda cache, _n: None)  # MAV_RESULT_DENIED
    vehicle._cache.texts.add("CRITICAL: Takeoff denied! Please disarm and retry")
    with pytest.raises(CommandDeniedError, match=r"takeoff\(\): COMMAND_DENIED.*Takeoff denied"):
        vehicle.takeoff(1.0, timeout_s=2.0)
    assert len(direct.sent) == 1


def test_a_takeoff_the_vehicle_never_saw_is_sent_again_and_one_it_shows_is_not() -> None:
    vehicle, direct, _ = _ready_vehicle(None, lambda cache, _n: None)  # every ack lost, nothing happens
    with pytest.raises(CommandDeniedError, match="TIMEOUT"):
        vehicle.takeoff(1.0, timeout_s=0.2)
    assert len(direct.sent) == COMMAND_ATTEMPTS
    assert len({fields["param7"] for _, fields in direct.sent}) == 1  # every copy: the same altitude

    def started(cache: object, _n: int) -> None:
        cache.mode = FlightMode.TAKEOFF  # type: ignore[attr-defined]

    vehicle, direct, _ = _ready_vehicle(None, started)
    with pytest.raises(Exception, match="takeoff"):  # the fake never finishes the climb
        vehicle.takeoff(1.0, timeout_s=0.2)
    assert len(direct.sent) == 1


def test_without_a_global_position_the_takeoff_is_mavsdks_to_mis_takeoff_alt() -> None:
    vehicle, direct, action = _ready_vehicle(0, lambda cache, _n: None, global_position=False)

    def arrive_on_takeoff() -> None:
        action.calls.append("takeoff()")
        _arrive(vehicle._cache, 1.0)

    action.takeoff = arrive_on_takeoff  # type: ignore[method-assign]
    vehicle.takeoff(1.0, timeout_s=2.0)
    assert direct.sent == [] and action.calls == ["set_takeoff_altitude(1.0)", "takeoff()"]
    assert math.isnan(vehicle._takeoff_amsl_m(1.0))


def test_a_global_position_flagged_but_never_received_is_no_altitude() -> None:
    vehicle, _, _ = _ready_vehicle(0, lambda cache, _n: None)
    assert vehicle._takeoff_amsl_m(1.0) == pytest.approx(HOME_AMSL_M + 1.0)
    nan = SimpleNamespace(absolute_altitude_m=math.nan)  # MAVSDK's position before any arrived
    vehicle._telemetry = SimpleNamespace(position=lambda: nan)  # type: ignore[assignment]
    assert math.isnan(vehicle._takeoff_amsl_m(1.0))
