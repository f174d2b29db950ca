"""Simulated devices follow their commands and trip on demand (bridge/core/simulation_behaviour.py),
and their values stay physically plausible."""

from __future__ import annotations

import random
from collections.abc import Mapping as AnyMapping
from typing import Any

import pytest

from bridge.core.codec import decode, encode
from bridge.core.mapping import Mapping, Point, builtin_mapping_path, load_mapping
from bridge.core.simulation import Cell, advance, build_movers, initial_image, stored_cells
from bridge.core.simulation_behaviour import (
    Behaviour,
    active_faults,
    build_behaviour,
    clear_faults,
    follow,
    is_running,
    raise_fault,
    start_image,
)
from bridge.errors import ValueRejectedError
from tests.factory import make_mapping


class Device:
    """A simulated device's image and behaviour, driven as the Modbus server drives them."""

    def __init__(self, name: str) -> None:
        self.mapping: Mapping = load_mapping(builtin_mapping_path(name))
        self.points: AnyMapping[str, Point] = self.mapping.points()
        image = initial_image(self.mapping, self.points)
        self.behaviour: Behaviour = build_behaviour(self.mapping, self.points, image)
        self.image: dict[Cell, int] = image | start_image(self.behaviour, image)

    def command(self, key: str, value: object) -> None:
        """What a command's writes do, frame by frame: stored (a command coil is not), then
        followed."""
        point = self.points[key]
        for write in encode(point, value, self.image):
            if not (write.function == 5 and not point.entity.readable):
                self.image |= stored_cells(write)
            self.image |= follow(self.behaviour, write, self.image)

    def trip(self, key: str, label: str | None = None) -> None:
        self.image |= raise_fault(self.behaviour, key, label, self.image)

    def value(self, key: str) -> Any:
        return decode(self.points[key], self.image)

    @property
    def running(self) -> bool:
        return is_running(self.behaviour, self.image)

    @property
    def faults(self) -> list[str]:
        return active_faults(self.behaviour, self.image)


# name, stop (key, value), start (key, value), reset (key, value), a fault, a motion value,
# the status when stopped and when tripped
CASES = [
    (
        "nastec_vasco",
        ("start_stop", "OFF"),
        ("start_stop", "ON"),
        ("start_stop", "OFF"),  # no reset register: switching off clears the alarm
        ("alarm_dry_running", None),
        "motor_current",
        ("off", "alarm"),
    ),
    (
        "p2_vfd",
        ("stop", "PRESS"),
        ("command", "forward_run"),
        ("fault_reset", "PRESS"),
        ("fault_code", "motor_overload"),
        "output_current",
        ("standby", "fault"),
    ),
    (
        "soft_starter",
        ("motor_run", "OFF"),
        ("motor_run", "ON"),
        ("fault_reset", "PRESS"),
        ("fault_status", "overload"),
        "phase_u_current",
        ("no_fault", "overload"),
    ),
    (
        "vacon_nx",
        ("run", "OFF"),
        ("run", "ON"),
        ("fault_reset", "PRESS"),
        ("fault_code", "fieldbus_fault"),
        "motor_current",
        (False, False),
    ),
    (
        "smartgen_hgm6100",
        ("command_stop", "PRESS"),
        ("command_start", "PRESS"),
        ("command_stop", "PRESS"),  # the Stop key resets the alarms
        ("alarm_overspeed_shutdown", None),
        "engine_speed",
        ("standby", "standby"),
    ),
]


@pytest.mark.parametrize(
    ("name", "stop", "start", "reset", "fault", "moving", "shown"),
    CASES,
    ids=[case[0] for case in CASES],
)
def test_a_device_follows_its_commands_and_trips_on_demand(
    name: str,
    stop: tuple[str, str],
    start: tuple[str, str],
    reset: tuple[str, str],
    fault: tuple[str, str | None],
    moving: str,
    shown: tuple[object, object],
) -> None:
    device = Device(name)
    status = device.mapping.status or ""
    assert device.running and device.faults == []
    running_value = device.value(moving)
    assert running_value > 0

    device.command(*stop)
    assert not device.running
    assert device.value(status) == shown[0]
    assert device.value(moving) == 0  # a stopped machine draws no current, turns no shaft

    device.command(*start)
    assert device.running
    assert device.value(moving) == running_value

    device.trip(*fault)
    assert fault[0] in device.faults
    assert not device.running
    assert device.value(status) == shown[1]
    assert device.value(moving) == 0
    device.command(*start)
    assert not device.running, "a tripped device does not start"

    device.command(*reset)
    assert device.faults == []
    device.command(*start)
    assert device.running


def test_a_status_that_says_running_has_its_run_switch_on_at_start() -> None:
    """The Nastec's Run switch agrees with its status (it read off while running)."""
    pump = Device("nastec_vasco")
    assert pump.value("status") == "running"
    assert pump.value("start_stop") is True
    assert Device("vacon_nx").value("run") is True


def test_a_reverse_command_runs_in_reverse() -> None:
    drive = Device("p2_vfd")
    drive.command("reverse_run", "PRESS")
    assert drive.value("status") == "running_reverse"
    assert drive.value("running") is True
    drive.command("command", "coast_stop")
    assert drive.value("status") == "standby"


def test_a_warning_does_not_stop_a_genset_and_sets_its_summary_alarms() -> None:
    genset = Device("smartgen_hgm6100")
    genset.trip("warning_low_fuel_level")
    assert genset.running
    assert genset.faults == ["common_alarm", "common_warning", "warning_low_fuel_level"]
    genset.trip("alarm_overspeed_shutdown")
    assert not genset.running
    assert "common_shutdown" in genset.faults


def test_the_vacon_fault_bit_follows_its_fault_code() -> None:
    drive = Device("vacon_nx")
    drive.trip("fault_code")
    assert drive.faults == ["fault", "fault_code"]
    assert drive.value("fault_code") == "device_changed"  # the first fault label
    drive.trip("warning")
    assert drive.value("warning") is True


def test_a_fault_goes_into_the_alarm_history() -> None:
    pump = Device("nastec_vasco")
    slots = [pump.value(f"alarm_history_{n}") for n in range(1, 9)]
    pump.trip("alarm_rotor_locked")
    assert [pump.value(f"alarm_history_{n}") for n in range(1, 9)] == ["rotor_locked", *slots[:7]]


def test_clear_faults_clears_every_alarm_and_restarts_what_is_switched_on() -> None:
    pump = Device("nastec_vasco")
    pump.trip("alarm_undervoltage")
    pump.trip("alarm_sensor_fault")
    pump.image |= clear_faults(pump.behaviour, pump.image)
    assert pump.faults == []
    assert pump.value("status") == "running"  # its Run switch stayed on


@pytest.mark.parametrize(
    ("name", "key", "label", "message"),
    [
        ("nastec_vasco", "motor_current", None, "no alarm 'motor_current' (alarms: alarm_"),
        ("p2_vfd", "fault_code", "melted", "'melted' is not one of its faults"),
        ("nastec_vasco", "alarm_cpu", "x", "alarm_cpu is a yes/no alarm: give no label"),
    ],
)
def test_a_fault_the_device_does_not_have_is_refused(
    name: str, key: str, label: str | None, message: str
) -> None:
    device = Device(name)
    with pytest.raises(ValueRejectedError) as refused:
        device.trip(key, label)
    assert message in str(refused.value)
    assert device.faults == []


@pytest.mark.parametrize(
    ("name", "key"), [("nastec_vasco", "motor_power_factor"), ("smartgen_hgm6100", "power_factor")]
)
def test_a_power_factor_stays_within_one(name: str, key: str) -> None:
    device = Device(name)
    movers = build_movers(device.points, device.image)
    rng = random.Random(7)
    seen = []
    for _ in range(300):
        device.image |= advance(movers, device.image, rng)
        seen.append(device.value(key))
    assert min(seen) > 0 and max(seen) <= 1.0
    assert len(set(seen)) > 3  # it moves


def test_alarm_history_slots_hold_different_alarms() -> None:
    pump = Device("nastec_vasco")
    slots = [pump.value(f"alarm_history_{n}") for n in range(1, 9)]
    assert None not in slots
    assert len(set(slots)) == 8


def test_a_run_switch_with_its_own_words_starts_and_stops_the_device() -> None:
    """A switch that writes 0x0100/0x0200 (``words``) runs the device on its ON word only."""
    mapping = make_mapping(
        {
            "run": {"name": "Run", "address": 0, "type": "bool", "access": "rw"}
            | {"words": {"write_on": 0x0100, "write_off": 0x0200}},
            "status": {"name": "Status", "address": 1, "enum": {0: "stopped", 1: "running"}},
        },
        status="status",
    )
    points = mapping.points()
    image = initial_image(mapping, points)
    behaviour = build_behaviour(mapping, points, image)
    for command, status in (("OFF", "stopped"), ("ON", "running"), ("OFF", "stopped")):
        for write in encode(points["run"], command, image):
            image = image | stored_cells(write)
            image |= follow(behaviour, write, image)
        assert (decode(points["run"], image), decode(points["status"], image)) == (
            command == "ON",
            status,
        )
