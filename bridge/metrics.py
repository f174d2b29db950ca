"""The Prometheus/OpenMetrics endpoint (off by default): the health counters for scrapers.

The only module that imports prometheus_client (an import-linter contract keeps it so).
``serve_metrics(config, source)`` is an async context manager: with ``config.enabled`` it
listens on ``config.host:config.port`` with the web page's HTTP server on the event loop
(bridge/web/http.py: bounded requests, timeouts, a connection cap; ``GET /metrics``,
also ``/``), and each scrape reads a fresh ``source()`` snapshot, on the
loop's thread, so nothing is shared across threads. Plain Prometheus text by default,
OpenMetrics when the scraper's Accept header asks for it.

``GET /health`` is the container's health check (the image's HEALTHCHECK, the add-on's
watchdog): is the bridge alive and serving? An answer at all says so: it is served on the
bridge's event loop, in the same task group as the MQTT session and its reconnect loop
(which never gives up), so a blocked loop gives no answer in time and a bridge whose run
ended serves nothing. It answers 200 and ``{"status": "ok"}`` whatever the field devices
do (a bridge standing by for another one on its base topic is alive too), with
``buses_down`` listing the buses that are down, if any: restarting the bridge would not
bring an unplugged gateway back, and would take every other device offline meanwhile.
``GET /health/buses`` is the bus detail: 200 and ``{"status": "ok"}`` while no bus is
down, 503 and the reason of each bus that is down (``{"status": "down", "buses":
{"rs485": "rs485: cannot open /dev/ttyUSB0: Permission denied ..."}}``) otherwise, for a
monitor that wants to be told. It stops listening (and drops open connections) when the
block ends. An address that cannot be bound raises OSError
naming it before anything else starts.

The numbers are the health document's (``bridge.core.health_report``), counters since
the bridge started:

    modbus_bridge_uptime_seconds                        gauge
    modbus_bus_connected{bus}                           gauge, 1 or 0
    modbus_bus_requests_total{bus}                      frames sent, resends included
    modbus_bus_busy_seconds_total{bus}                  time a frame was in flight
    modbus_bus_timeouts_total{bus}
    modbus_bus_frame_errors_total{bus}                  CRC, length
    modbus_bus_exceptions_total{bus}                    exception replies
    modbus_bus_reopenings_total{bus}                    failed (re)opens of the port
    modbus_device_online{device}                        gauge, 1 or 0; absent until known
    modbus_device_requests_total{device}
    modbus_device_errors_total{device}
    modbus_device_timeouts_total{device}
    modbus_device_busy_answers_total{device}            busy answers
    modbus_device_unknown_codes_total{device}           enum codes without a label (code_<n>)
    modbus_device_counter_readings_held_total{device}   counter readings held back (a 0, a
                                                        torn read, jitter, a failed read)
    modbus_device_counter_resets_total{device}          counter decreases confirmed
    modbus_device_scaled_values_held_total{device}      values read apart from their scale
                                                        factor held: the factor changed
    modbus_device_exceptions_total{device,code}
    modbus_device_latency_seconds{device,quantile}      gauge, quantile 0.5 and 0.95;
                                                        absent before the first answer
    modbus_device_last_success_timestamp_seconds{device}  gauge, absent if never
    modbus_device_consecutive_failures{device}          gauge
    modbus_device_backoff_seconds{device}               gauge, 0 unless offline
    modbus_device_writes_total{device,result}           result: done, skipped_unchanged,
                                                        rejected, failed, expired
"""

from __future__ import annotations

import contextlib
import json
import logging
from collections.abc import AsyncIterator, Callable, Iterator
from http import HTTPStatus
from operator import attrgetter

from prometheus_client.exposition import choose_encoder
from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import CollectorRegistry

from bridge.config import MetricsConfig
from bridge.core.health_report import BusSnapshot, DeviceSnapshot, Snapshot, buses_down
from bridge.web.http import Request, Response, listening

log = logging.getLogger(__name__)
PATHS = frozenset({"/", "/metrics"})
HEALTH_PATH = "/health"
BUS_HEALTH_PATH = "/health/buses"

Source = Callable[[], Snapshot]

_BUS_COUNTERS: tuple[tuple[str, str, Callable[[BusSnapshot], float]], ...] = (
    ("requests", "Frames sent on the bus, resends included", attrgetter("requests")),
    ("busy_seconds", "Time a frame was in flight on the bus", attrgetter("busy_seconds")),
    ("timeouts", "Frames not answered in time", attrgetter("timeouts")),
    ("frame_errors", "Answers that could not be parsed (CRC, length)", attrgetter("frame_errors")),
    ("exceptions", "Modbus exception replies", attrgetter("exceptions")),
    ("reopenings", "Failed attempts to (re)open the port or connection", attrgetter("reopenings")),
)
_DEVICE_COUNTERS: tuple[tuple[str, str, Callable[[DeviceSnapshot], float]], ...] = (
    ("requests", "Requests to the device (a resend is one request)", attrgetter("requests")),
    ("errors", "Failed requests: timeouts, bus down, failure exceptions", attrgetter("errors")),
    ("timeouts", "Requests not answered (or the bus was down)", attrgetter("timeouts")),
    ("busy_answers", "Busy answers (the device is alive, retried later)", attrgetter("busy")),
    (
        "unknown_codes",
        "Enum codes read that the mapping has no label for (published as code_<n>)",
        attrgetter("unknown_codes"),
    ),
    (
        "counter_readings_held",
        "Counter readings below the published value, or failed, not published",
        attrgetter("counter_readings_held"),
    ),
    (
        "counter_resets",
        "Counter decreases confirmed by readings in a row and published",
        attrgetter("counter_resets"),
    ),
    (
        "scaled_values_held",
        "Values read apart from their scale factor not published: the factor changed",
        attrgetter("scaled_values_held"),
    ),
)
_DEVICE_GAUGES: tuple[tuple[str, str, Callable[[DeviceSnapshot], float]], ...] = (
    (
        "consecutive_failures",
        "Failed requests since the last answer",
        attrgetter("consecutive_failures"),
    ),
    ("backoff_seconds", "Retry interval while offline (0 when online)", attrgetter("backoff")),
)
_WRITE_RESULTS = ("done", "skipped_unchanged", "rejected", "failed", "expired")


class SnapshotCollector:
    """A prometheus_client collector over the latest snapshot of the engine."""

    def __init__(self, source: Source) -> None:
        self.source = source

    def collect(self) -> Iterator[Metric]:
        snapshot = self.source()
        yield GaugeMetricFamily(
            "modbus_bridge_uptime_seconds", "Seconds since the bridge started", snapshot.uptime
        )
        yield from _bus_metrics(snapshot.buses)
        yield from _device_metrics(snapshot)


def _bus_metrics(buses: tuple[BusSnapshot, ...]) -> Iterator[Metric]:
    connected = GaugeMetricFamily(
        "modbus_bus_connected", "1 while the port or connection is open", labels=["bus"]
    )
    for bus in buses:
        connected.add_metric([bus.bus_id], 1.0 if bus.connected else 0.0)
    yield connected
    for name, documentation, value in _BUS_COUNTERS:
        family = CounterMetricFamily(f"modbus_bus_{name}", documentation, labels=["bus"])
        for bus in buses:
            family.add_metric([bus.bus_id], value(bus))
        yield family


def _device_metrics(snapshot: Snapshot) -> Iterator[Metric]:
    devices = snapshot.devices
    online = GaugeMetricFamily(
        "modbus_device_online", "1 online, 0 offline (absent until known)", labels=["device"]
    )
    latency = GaugeMetricFamily(
        "modbus_device_latency_seconds",
        "Request latency over the recent requests (queueing included)",
        labels=["device", "quantile"],
    )
    last = GaugeMetricFamily(
        "modbus_device_last_success_timestamp_seconds",
        "When the device last answered (Unix time)",
        labels=["device"],
    )
    exceptions = CounterMetricFamily(
        "modbus_device_exceptions", "Exception replies by code", labels=["device", "code"]
    )
    writes = CounterMetricFamily(
        "modbus_device_writes", "Write commands by how they ended", labels=["device", "result"]
    )
    for device in devices:
        name = device.device_id
        if device.online is not None:
            online.add_metric([name], 1.0 if device.online else 0.0)
        for quantile, seconds in (("0.5", device.latency_p50), ("0.95", device.latency_p95)):
            if seconds is not None:
                latency.add_metric([name, quantile], seconds)
        last_success = snapshot.last_success(device)
        if last_success is not None:
            last.add_metric([name], last_success)
        for code, count in device.exceptions:
            exceptions.add_metric([name, str(code)], count)
        for result in _WRITE_RESULTS:
            writes.add_metric([name, result], getattr(device.writes, result))
    yield from (online, latency, last, exceptions, writes)
    for metric_name, documentation, value in _DEVICE_COUNTERS:
        family = CounterMetricFamily(
            f"modbus_device_{metric_name}", documentation, labels=["device"]
        )
        for device in devices:
            family.add_metric([device.device_id], value(device))
        yield family
    for metric_name, documentation, value in _DEVICE_GAUGES:
        gauge = GaugeMetricFamily(f"modbus_device_{metric_name}", documentation, labels=["device"])
        for device in devices:
            gauge.add_metric([device.device_id], value(device))
        yield gauge


class MetricsApp:
    """Answers scrapes and health checks (served by bridge/web/http.py's server)."""

    def __init__(self, source: Source) -> None:
        self.source = source
        self.registry = CollectorRegistry()
        self.registry.register(SnapshotCollector(source))

    async def handle(self, request: Request) -> Response:
        """One request: the metrics, the health document, or why not."""
        if request.method not in ("GET", "HEAD"):
            return Response(HTTPStatus.METHOD_NOT_ALLOWED, b"GET only\n")
        if request.path == HEALTH_PATH:
            return self.health()
        if request.path == BUS_HEALTH_PATH:
            return self.bus_health()
        if request.path not in PATHS:
            return Response(
                HTTPStatus.NOT_FOUND,
                b"metrics are on /metrics, health on /health and /health/buses\n",
            )
        encoder, content_type = choose_encoder(request.headers.get("accept", ""))
        return Response(HTTPStatus.OK, encoder(self.registry), content_type)

    def health(self) -> Response:
        """200: the bridge answers; the buses that are down are named, not held against it."""
        down = sorted(buses_down(self.source()))
        document: dict[str, object] = {"status": "ok"}
        if down:
            document["buses_down"] = down
        return Response(HTTPStatus.OK, json.dumps(document).encode() + b"\n", "application/json")

    def bus_health(self) -> Response:
        """503 with each bus that is down and why, else 200."""
        down = buses_down(self.source())
        document = {"status": "down", "buses": down} if down else {"status": "ok"}
        status = HTTPStatus.SERVICE_UNAVAILABLE if down else HTTPStatus.OK
        return Response(status, json.dumps(document).encode() + b"\n", "application/json")


@contextlib.asynccontextmanager
async def serve_metrics(config: MetricsConfig, source: Source) -> AsyncIterator[None]:
    """Serve ``/metrics`` for the duration of the block when ``config.enabled``."""
    if not config.enabled:
        yield
        return
    app = MetricsApp(source)
    async with listening(app.handle, config.host, config.port, "metrics endpoint"):
        log.info("metrics on http://%s:%d/metrics", config.host, config.port)
        yield
