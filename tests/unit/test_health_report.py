"""The bridge/health document: rates over an interval, clamps, first report, device states."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from bridge.core.health_report import (
    BusSnapshot,
    DeviceSnapshot,
    HealthReporter,
    Snapshot,
    WriteSnapshot,
    build_health_report,
    buses_down,
    iso_utc,
)

WALL = 1_746_100_800.0  # 2025-05-01T12:00:00Z
BUS = BusSnapshot("rs485", "rtu", connected=True)
DEVICE = DeviceSnapshot("pump", "rs485", 3)


def _snapshot(
    monotonic: float,
    *,
    uptime: float | None = None,
    buses: tuple[BusSnapshot, ...] = (BUS,),
    devices: tuple[DeviceSnapshot, ...] = (DEVICE,),
) -> Snapshot:
    return Snapshot(
        wall=WALL + monotonic - 1000.0,
        monotonic=monotonic,
        uptime=monotonic - 1000.0 if uptime is None else uptime,
        buses=buses,
        devices=devices,
    )


def test_iso_utc() -> None:
    assert iso_utc(WALL) == "2025-05-01T12:00:00+00:00"
    assert iso_utc(WALL + 0.9) == "2025-05-01T12:00:00+00:00"


def test_whole_document_of_a_healthy_bus_and_device() -> None:
    previous = _snapshot(1060.0, buses=(replace(BUS, requests=100, busy_seconds=5.0),))
    bus = replace(
        BUS,
        requests=400,
        busy_seconds=20.0,
        timeouts=2,
        frame_errors=1,
        exceptions=3,
        reopenings=1,
    )
    device = replace(
        DEVICE,
        online=True,
        requests=390,
        errors=2,
        timeouts=2,
        busy=1,
        exceptions=((2, 1), (6, 1)),
        latency_p50=0.0123,
        latency_p95=0.04567,
        last_success=1119.5,
        writes=WriteSnapshot(done=3, skipped_unchanged=1, rejected=2, failed=1, expired=4),
        unknown_codes=5,
        counter_readings_held=6,
        counter_resets=1,
        scaled_values_held=2,
    )
    current = _snapshot(1120.0, buses=(bus,), devices=(device,))

    assert build_health_report(current, previous) == {
        "timestamp": "2025-05-01T12:02:00+00:00",
        "uptime_s": 120.0,
        "interval_s": 60.0,
        "buses": {
            "rs485": {
                "transport": "rtu",
                "connected": True,
                "requests": 400,
                "requests_per_s": 5.0,
                "utilisation": 0.25,
                "timeouts": 2,
                "frame_errors": 1,
                "exceptions": 3,
                "reopenings": 1,
                "error": None,
            }
        },
        "devices": {
            "pump": {
                "bus": "rs485",
                "unit": 3,
                "state": "online",
                "error": None,
                "requests": 390,
                "errors": 2,
                "timeouts": 2,
                "busy": 1,
                "exceptions": {"2": 1, "6": 1},
                "latency_p50_ms": 12.3,
                "latency_p95_ms": 45.7,
                "last_success": "2025-05-01T12:01:59+00:00",
                "consecutive_failures": 0,
                "backoff_s": 0.0,
                "writes_done": 3,
                "writes_skipped_unchanged": 1,
                "writes_rejected": 2,
                "writes_failed": 1,
                "writes_expired": 4,
                "unknown_codes": 5,
                "counter_readings_held": 6,
                "counter_resets": 1,
                "scaled_values_held": 2,
            }
        },
    }


def test_the_document_is_json() -> None:
    document = build_health_report(_snapshot(1010.0, devices=(replace(DEVICE, online=True),)))
    assert json.loads(json.dumps(document)) == document


def test_first_report_rates_cover_the_time_since_start() -> None:
    bus = replace(BUS, requests=50, busy_seconds=2.5)
    document = build_health_report(_snapshot(1010.0, buses=(bus,)))
    assert document["interval_s"] == 10.0
    assert document["buses"]["rs485"]["requests_per_s"] == 5.0
    assert document["buses"]["rs485"]["utilisation"] == 0.25


def test_first_report_at_time_zero_has_zero_rates() -> None:
    bus = replace(BUS, requests=1, busy_seconds=0.01)
    document = build_health_report(_snapshot(1000.0, buses=(bus,)))
    assert document["interval_s"] == 0.0
    assert document["buses"]["rs485"]["requests_per_s"] == 0.0
    assert document["buses"]["rs485"]["utilisation"] == 0.0


@pytest.mark.parametrize(
    ("busy_before", "busy_now", "expected"),
    [
        (0.0, 0.0, 0.0),  # idle
        (1.0, 3.5, 0.25),
        (0.0, 10.0, 1.0),  # busy all the time
        (0.0, 10.2, 1.0),  # a frame that began before the interval: clamped
    ],
)
def test_utilisation_is_a_fraction_of_the_interval(
    busy_before: float, busy_now: float, expected: float
) -> None:
    previous = _snapshot(1000.0, buses=(replace(BUS, busy_seconds=busy_before),))
    current = _snapshot(1010.0, buses=(replace(BUS, busy_seconds=busy_now),))
    assert build_health_report(current, previous)["buses"]["rs485"]["utilisation"] == expected


def test_rates_cover_only_the_last_interval() -> None:
    reporter = HealthReporter()
    counts = {1000.0: 0, 1010.0: 100, 1020.0: 130, 1025.0: 130}
    rates = [
        reporter.report(_snapshot(t, buses=(replace(BUS, requests=n),)))["buses"]["rs485"][
            "requests_per_s"
        ]
        for t, n in counts.items()
    ]
    assert rates == [0.0, 10.0, 3.0, 0.0]
    assert reporter.previous is not None
    assert reporter.previous.monotonic == 1025.0


def test_a_counter_that_went_down_counts_from_zero() -> None:
    previous = _snapshot(1000.0, buses=(replace(BUS, requests=500, busy_seconds=50.0),))
    current = _snapshot(1010.0, buses=(replace(BUS, requests=20, busy_seconds=1.0),))
    bus = build_health_report(current, previous)["buses"]["rs485"]
    assert bus["requests_per_s"] == 2.0
    assert bus["utilisation"] == 0.1


def test_a_bus_new_since_the_previous_report_counts_from_zero() -> None:
    previous = _snapshot(1000.0, buses=())
    current = _snapshot(1010.0, buses=(replace(BUS, requests=40),))
    assert build_health_report(current, previous)["buses"]["rs485"]["requests_per_s"] == 4.0


def test_clocks_going_backwards_give_zero_rates() -> None:
    previous = _snapshot(1010.0)
    current = _snapshot(1000.0, buses=(replace(BUS, requests=5),))
    document = build_health_report(current, previous)
    assert document["interval_s"] == 0.0
    assert document["buses"]["rs485"]["requests_per_s"] == 0.0


def test_offline_device() -> None:
    device = replace(
        DEVICE,
        online=False,
        requests=12,
        errors=5,
        timeouts=5,
        last_success=1003.0,
        consecutive_failures=5,
        backoff=20.0,
        latency_p50=0.01,
        latency_p95=0.02,
    )
    report = build_health_report(_snapshot(1100.0, devices=(device,)))["devices"]["pump"]
    assert report["state"] == "offline"
    assert report["consecutive_failures"] == 5
    assert report["backoff_s"] == 20.0
    assert report["last_success"] == "2025-05-01T12:00:03+00:00"
    assert (report["errors"], report["timeouts"]) == (5, 5)


def test_a_device_never_heard_of_is_unknown_with_nulls() -> None:
    report = build_health_report(_snapshot(1010.0))["devices"]["pump"]
    assert report["state"] == "unknown"
    assert report["last_success"] is None
    assert report["latency_p50_ms"] is None
    assert report["latency_p95_ms"] is None
    assert report["exceptions"] == {}


def test_exception_codes_are_string_keys_in_code_order() -> None:
    device = replace(DEVICE, online=True, exceptions=((2, 4), (6, 1), (11, 2)))
    report = build_health_report(_snapshot(1010.0, devices=(device,)))["devices"]["pump"]
    assert list(report["exceptions"].items()) == [("2", 4), ("6", 1), ("11", 2)]


def test_every_bus_and_device_by_id() -> None:
    buses = (BUS, BusSnapshot("gw", "rtu-over-tcp", connected=False))
    devices = (DEVICE, DeviceSnapshot("meter", "gw", 1, online=True))
    document = build_health_report(_snapshot(1010.0, buses=buses, devices=devices))
    assert list(document["buses"]) == ["rs485", "gw"]
    assert document["buses"]["gw"]["connected"] is False
    assert document["buses"]["gw"]["transport"] == "rtu-over-tcp"
    assert list(document["devices"]) == ["pump", "meter"]
    assert document["devices"]["meter"]["bus"] == "gw"


def test_a_bus_that_cannot_be_opened_says_why() -> None:
    reason = "rs485: cannot open /dev/ttyUSB0: Permission denied [EACCES] (...)"
    down = BusSnapshot("rs485", "rtu", connected=False, reopenings=3, down_reason=reason)
    never_opened = BusSnapshot("gw", "tcp", connected=False)
    snapshot = _snapshot(1010.0, buses=(down, never_opened, replace(BUS, bus_id="up")))
    document = build_health_report(snapshot)
    assert document["buses"]["rs485"]["error"] == reason
    assert document["buses"]["gw"]["error"] is None  # not opened yet is not down
    assert document["buses"]["up"]["error"] is None
    assert buses_down(snapshot) == {"rs485": reason}
    assert buses_down(_snapshot(1010.0)) == {}


def test_snapshot_clock_conversion() -> None:
    snapshot = _snapshot(1010.0)
    assert snapshot.wall_time(1010.0) == snapshot.wall
    assert snapshot.wall_time(1000.0) == snapshot.wall - 10.0
    assert snapshot.last_success(DEVICE) is None
    assert snapshot.last_success(replace(DEVICE, last_success=1009.0)) == snapshot.wall - 1.0


@pytest.mark.parametrize(
    ("online", "state"), [(None, "unknown"), (True, "online"), (False, "offline")]
)
def test_device_state_words(online: bool | None, state: str) -> None:
    assert replace(DEVICE, online=online).state == state


def test_snapshots_are_immutable() -> None:
    with pytest.raises(AttributeError):
        BUS.requests = 3  # type: ignore[misc]
    with pytest.raises(AttributeError):
        DEVICE.errors = 3  # type: ignore[misc]
