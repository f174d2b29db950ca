"""The ``<base>/bridge/health`` document, built from two consecutive snapshots. Pure.

The edge (``Engine.snapshot()``) copies its counters into a ``Snapshot``; this module turns
the current snapshot and the previous one into the JSON document below. Rates and bus
utilisation cover the interval between the two snapshots; the first report (no previous
snapshot) covers the time since the engine started, whose counters all started at zero.
A counter lower than before (a device rebuilt with fresh counters) counts from zero.

    {
      "timestamp": "2025-05-01T12:00:00+00:00",  when the snapshot was taken, UTC
      "uptime_s": 3600.0,                        since the engine started
      "interval_s": 60.0,                        what the rates and utilisation cover
      "buses": {
        "<bus id>": {
          "transport": "rtu",          rtu | ascii | tcp | rtu-over-tcp
          "connected": true,           port open / gateway connected
          "requests": 1234,            frames sent since start, resends included
          "requests_per_s": 20.567,    frames per second over the interval
          "utilisation": 0.4123,       0..1: the fraction of the interval a frame was in flight
          "timeouts": 3,               frames not answered in time
          "frame_errors": 0,           answers that could not be parsed (CRC, length)
          "exceptions": 2,             exception replies
          "reopenings": 0,             failed attempts to (re)open the port or connection
          "error": null                while the port or connection is down: why (the
                                         operating system's reason and what to do)
        }
      },
      "devices": {
        "<device id>": {
          "bus": "<bus id>", "unit": 1,
          "state": "online",           online | offline | unknown (no verdict yet)
          "error": null,               while offline for a reason beyond failed requests:
                                         the reason (a SunSpec device's walk that failed,
                                         a unit that is not SunSpec, a password lock)
          "requests": 1200,            transactions since start (a resend is one request)
          "errors": 5,                 failed requests: timeouts, bus down, failure exceptions
          "timeouts": 4,               of which no answer (or bus down)
          "busy": 0,                   busy answers (alive, retried later)
          "exceptions": {"2": 1},      exception replies by code (string keys, JSON objects)
          "latency_p50_ms": 12.3,      from submit to answer over the recent requests,
          "latency_p95_ms": 40.1,        time queued behind other devices' frames included;
                                         null before the first answer
          "last_success": "2025-05-01T11:59:59+00:00",   ISO-8601 UTC, null if never
          "consecutive_failures": 0,
          "backoff_s": 0.0,            the current retry interval while offline, else 0
          "writes_done": 3,            commands written
          "writes_skipped_unchanged": 1,   EEPROM settings already holding the value
          "writes_rejected": 0,        refused before reaching the wire (validation, guard,
                                         EEPROM rate limit)
          "writes_failed": 0,          the device or bus did not complete the write
          "writes_expired": 0,         not sent before the command expiry
          "unknown_codes": 0,          enum codes read that the mapping has no label for
                                         (published as code_<n>), counted as they appear
          "counter_readings_held": 0,  counter readings below the published value (a 0,
                                         a torn read, jitter) or failed, not published
          "counter_resets": 0,         counter decreases confirmed and published
          "scaled_values_held": 0      values read apart from their scale factor not
                                         published: the factor read differently before
                                         and after them (it changed as they were read)
        }
      }
    }
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any


@dataclass(frozen=True, slots=True)
class BusSnapshot:
    """The counters of one bus at one moment."""

    bus_id: str
    transport: str
    connected: bool
    requests: int = 0
    busy_seconds: float = 0.0
    timeouts: int = 0
    frame_errors: int = 0
    exceptions: int = 0
    reopenings: int = 0
    down_reason: str | None = None  # set while the bus is down: why the last open failed


@dataclass(frozen=True, slots=True)
class WriteSnapshot:
    """How the commands to one device ended."""

    done: int = 0
    skipped_unchanged: int = 0
    rejected: int = 0
    failed: int = 0
    expired: int = 0


@dataclass(frozen=True, slots=True)
class DeviceSnapshot:
    """The counters and state of one device at one moment (times in seconds)."""

    device_id: str
    bus: str
    unit: int
    online: bool | None = None
    requests: int = 0
    errors: int = 0
    timeouts: int = 0
    busy: int = 0
    exceptions: tuple[tuple[int, int], ...] = ()  # (code, count), ascending codes
    latency_p50: float | None = None
    latency_p95: float | None = None
    last_success: float | None = None  # monotonic, like Snapshot.monotonic
    consecutive_failures: int = 0
    backoff: float = 0.0
    writes: WriteSnapshot = WriteSnapshot()
    unknown_codes: int = 0
    counter_readings_held: int = 0
    counter_resets: int = 0
    scaled_values_held: int = 0
    error: str | None = None  # offline with a reason: a failed SunSpec walk, a lock

    @property
    def state(self) -> str:
        return "unknown" if self.online is None else "online" if self.online else "offline"


@dataclass(frozen=True, slots=True)
class Snapshot:
    """Every bus and device at one moment, with both clocks read at that moment."""

    wall: float  # time.time()
    monotonic: float  # time.monotonic()
    uptime: float  # seconds since the counters started at zero
    buses: tuple[BusSnapshot, ...] = ()
    devices: tuple[DeviceSnapshot, ...] = ()

    def wall_time(self, monotonic: float) -> float:
        """The wall-clock time of a monotonic instant before this snapshot."""
        return self.wall - (self.monotonic - monotonic)

    def last_success(self, device: DeviceSnapshot) -> float | None:
        """The wall-clock time of the device's last answer, or None if it never answered."""
        return None if device.last_success is None else self.wall_time(device.last_success)


def iso_utc(wall: float) -> str:
    """ISO-8601 in UTC to the second: ``2025-05-01T12:00:00+00:00``."""
    return datetime.fromtimestamp(wall, UTC).isoformat(timespec="seconds")


def build_health_report(current: Snapshot, previous: Snapshot | None = None) -> dict[str, Any]:
    """The health document of ``current``, rates over the time since ``previous`` (or
    since the start when there is none)."""
    interval = current.uptime if previous is None else current.monotonic - previous.monotonic
    interval = max(0.0, interval)
    old_buses = {bus.bus_id: bus for bus in previous.buses} if previous is not None else {}
    return {
        "timestamp": iso_utc(current.wall),
        "uptime_s": round(current.uptime, 1),
        "interval_s": round(interval, 3),
        "buses": {
            bus.bus_id: _bus_report(bus, old_buses.get(bus.bus_id), interval)
            for bus in current.buses
        },
        "devices": {
            device.device_id: _device_report(device, current) for device in current.devices
        },
    }


def buses_down(snapshot: Snapshot) -> dict[str, str]:
    """The buses that are down, each with the reason (empty when every bus is up or has
    not been opened yet): what the container health check reports."""
    return {bus.bus_id: bus.down_reason for bus in snapshot.buses if bus.down_reason}


class HealthReporter:
    """Keeps the previous snapshot so that each report covers the time since the last one."""

    def __init__(self) -> None:
        self.previous: Snapshot | None = None

    def report(self, snapshot: Snapshot) -> dict[str, Any]:
        """The document for ``snapshot``; the next report's rates start from it."""
        document = build_health_report(snapshot, self.previous)
        self.previous = snapshot
        return document


def _bus_report(bus: BusSnapshot, old: BusSnapshot | None, interval: float) -> dict[str, Any]:
    requests = _delta(bus.requests, old.requests if old else 0)
    busy = _delta(bus.busy_seconds, old.busy_seconds if old else 0.0)
    return {
        "transport": bus.transport,
        "connected": bus.connected,
        "requests": bus.requests,
        "requests_per_s": round(requests / interval, 3) if interval > 0 else 0.0,
        "utilisation": round(min(1.0, busy / interval), 4) if interval > 0 else 0.0,
        "timeouts": bus.timeouts,
        "frame_errors": bus.frame_errors,
        "exceptions": bus.exceptions,
        "reopenings": bus.reopenings,
        "error": bus.down_reason,
    }


def _device_report(device: DeviceSnapshot, snapshot: Snapshot) -> dict[str, Any]:
    last_success = snapshot.last_success(device)
    writes = device.writes
    return {
        "bus": device.bus,
        "unit": device.unit,
        "state": device.state,
        "error": device.error,
        "requests": device.requests,
        "errors": device.errors,
        "timeouts": device.timeouts,
        "busy": device.busy,
        "exceptions": {str(code): count for code, count in device.exceptions},
        "latency_p50_ms": _milliseconds(device.latency_p50),
        "latency_p95_ms": _milliseconds(device.latency_p95),
        "last_success": None if last_success is None else iso_utc(last_success),
        "consecutive_failures": device.consecutive_failures,
        "backoff_s": round(device.backoff, 3),
        "writes_done": writes.done,
        "writes_skipped_unchanged": writes.skipped_unchanged,
        "writes_rejected": writes.rejected,
        "writes_failed": writes.failed,
        "writes_expired": writes.expired,
        "unknown_codes": device.unknown_codes,
        "counter_readings_held": device.counter_readings_held,
        "counter_resets": device.counter_resets,
        "scaled_values_held": device.scaled_values_held,
    }


def _delta(now: float, before: float) -> float:
    """What a counter grew by; a counter that went down was restarted from zero."""
    return now - before if now >= before else now


def _milliseconds(seconds: float | None) -> float | None:
    return None if seconds is None else round(seconds * 1000, 1)
