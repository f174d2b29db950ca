"""Logs a user reads: one line when a device goes offline and one when it recovers (not one
per failed poll), structured fields on them, and ``--log-format json`` for containers."""

from __future__ import annotations

import asyncio
import json
import logging
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from bridge.cli.lifecycle import JsonFormatter
from bridge.modbus.engine import Engine
from bridge.modbus.simulator import Quirks
from tests.integration.harness import (
    FAST_POLICY,
    config,
    eventually,
    running,
    serving_tcp,
    simulator,
    tcp_bus,
)
from tests.integration.mosquitto import Broker
from tests.ports import free_port


def events(records: list[logging.LogRecord], device: str) -> list[str]:
    return [r.event for r in records if getattr(r, "device", None) == device]  # type: ignore[attr-defined]


@pytest.mark.asyncio
async def test_one_line_offline_and_one_when_back_however_many_polls_fail(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="bridge")
    sim = simulator((1, "soft_starter"), (2, "soft_starter"))
    async with serving_tcp(sim) as port:
        poll = {"poll": {"fast": 0.05, "slow": 1}}
        devices = [
            {"id": f"starter_{unit}", "bus": "tcp", "unit": unit, "mapping": "soft_starter"} | poll
            for unit in (1, 2)
        ]
        engine = Engine(config([tcp_bus(port, timeout=0.1)], devices), policy=FAST_POLICY)
        async with running(engine):
            dead = engine.devices["starter_2"]
            await eventually(lambda: dead.health.online is True)
            sim.set_quirks(2, Quirks(dead=True))
            await eventually(lambda: dead.health.online is False)
            failures = dead.health.errors
            await eventually(lambda: dead.health.errors >= failures + 3)  # backoff probes fail
            sim.set_quirks(2, Quirks())
            await eventually(lambda: dead.health.online is True)
    assert events(caplog.records, "starter_2") == [
        "device_online",
        "device_offline",
        "device_recovered",
    ]
    assert events(caplog.records, "starter_1") == ["device_online"]
    (offline,) = [r for r in caplog.records if getattr(r, "event", "") == "device_offline"]
    assert offline.levelno == logging.WARNING
    assert (offline.unit, offline.bus) == (2, "tcp")  # type: ignore[attr-defined]
    assert "starter_2 (unit 2 on tcp) offline after" in offline.getMessage()


def test_json_lines_carry_the_record_and_its_fields() -> None:
    logger = logging.getLogger("bridge.test")
    record = logger.makeRecord(
        "bridge.test",
        logging.WARNING,
        __file__,
        1,
        "%s offline",
        ("pump",),
        None,
        extra={"event": "device_offline", "device": "pump", "unit": 3, "path": Path("/x")},
    )
    document = json.loads(JsonFormatter().format(record))
    assert document["level"] == "warning"
    assert document["logger"] == "bridge.test"
    assert document["message"] == "pump offline"
    assert document["event"] == "device_offline"
    assert (document["device"], document["unit"], document["path"]) == ("pump", 3, "/x")
    assert document["time"].endswith("+00:00")
    assert "args" not in document and "msg" not in document
    try:
        raise ValueError("boom")
    except ValueError:
        failed = logger.makeRecord(
            "bridge.test", logging.ERROR, __file__, 1, "x", (), sys.exc_info()
        )
    assert "ValueError: boom" in json.loads(JsonFormatter().format(failed))["exception"]


@pytest.mark.asyncio
async def test_run_logs_json_lines_for_containers(mosquitto: Broker, tmp_path: Path) -> None:
    """``run --log-format json``: every stderr line is a JSON object; a dead unit says so once."""
    port = free_port()
    simulate = [sys.executable, "-m", "bridge.cli", "simulate", "--tcp", f"127.0.0.1:{port}"]
    simulate += ["--mapping", "soft_starter", "--unit", "1", "--dead", "2", "--tick", "0"]
    path = tmp_path / "config.yaml"
    path.write_text(
        f"mqtt: {{url: '{mosquitto.url}'}}\n"
        f"buses: [{{id: gw, transport: tcp, host: 127.0.0.1, tcp_port: {port}, timeout: 0.2}}]\n"
        "devices:\n"
        "  - {id: live, bus: gw, unit: 1, mapping: soft_starter, poll: {fast: 0.1}}\n"
        "  - {id: gone, bus: gw, unit: 2, mapping: soft_starter, poll: {fast: 0.1}}\n"
    )
    with subprocess.Popen(simulate, stdout=subprocess.PIPE, text=True) as simulator_process:
        try:
            assert simulator_process.stdout is not None
            await asyncio.wait_for(asyncio.to_thread(simulator_process.stdout.readline), 20)
            run = [sys.executable, "-m", "bridge.cli", "run", "-c", str(path), "--log-format"]
            bridge = subprocess.Popen([*run, "json"], stderr=subprocess.PIPE, text=True)
            lines: list[dict[str, object]] = []
            assert bridge.stderr is not None
            async with asyncio.timeout(30):
                while not any(line.get("event") == "device_offline" for line in lines):
                    text = await asyncio.to_thread(bridge.stderr.readline)
                    assert text, f"bridge ended: {lines}"
                    lines.append(json.loads(text))
            await asyncio.sleep(1.0)  # more failed probes: no more offline lines
            bridge.send_signal(signal.SIGINT)
            _, rest = await asyncio.wait_for(asyncio.to_thread(bridge.communicate), 20)
            lines += [json.loads(text) for text in (rest or "").splitlines()]
            assert bridge.returncode == 0
        finally:
            simulator_process.terminate()
            simulator_process.wait(10)
    offline = [line for line in lines if line.get("event") == "device_offline"]
    assert [line["device"] for line in offline] == ["gone"]
    assert offline[0]["level"] == "warning" and offline[0]["unit"] == 2
    assert {"time", "level", "logger", "message"} <= set(lines[0])
    (connected,) = [line for line in lines if line.get("event") == "mqtt_up"]
    assert connected["level"] == "info"
    assert connected["message"] == f"MQTT connected to {mosquitto.url} (MQTT 5)"
