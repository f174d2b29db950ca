"""Normal operation logs no warning, at any output mode and scale (issue 27, item 3).

aiomqtt logs ``There are N pending publish calls.`` at WARNING for every publish beyond
ten unacknowledged ones: with ``mqtt.output: both`` one Vacon drive's start logged 135 such
lines and 50 devices 16,779 in 40 s. A start of many devices publishing every value is
normal operation: the count of WARNING lines is asserted, not any timing.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from bridge.app import Bridge
from bridge.config import MqttConfig, load_config_data
from bridge.mqtt import MqttClient
from bridge.mqtt import session as session_module
from tests.integration.harness import eventually, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.proxy import relayed
from tests.integration.test_one_bridge import started

DEVICES = 50  # units of the five seed models (ten of each) on one simulated gateway
SEEDS = ("nastec_vasco", "p2_vfd", "soft_starter", "vacon_nx", "smartgen_hgm6100")


@pytest.mark.asyncio
@pytest.mark.timeout(120)
async def test_a_start_of_many_devices_with_every_value_published_logs_no_warning(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture
) -> None:
    units = [(unit, SEEDS[unit % len(SEEDS)]) for unit in range(1, DEVICES + 1)]
    sim = simulator(*units, tick=1.0)
    async with serving_tcp(sim) as port:
        data = {
            "mqtt": {"url": mosquitto.url, "output": "both", "discovery": "device"},
            "buses": [
                {
                    "id": "gw",
                    "transport": "tcp",
                    "host": "127.0.0.1",
                    "tcp_port": port,
                    "timeout": 1.0,
                }
            ],
            "devices": [
                {
                    "id": f"d{unit}",
                    "bus": "gw",
                    "unit": unit,
                    "mapping": name,
                    "poll": {"fast": 1.0, "slow": 5.0},
                    "protocol": {"min_request_interval": 0.0},
                }
                for unit, name in units
            ],
        }
        bridge = Bridge(load_config_data(data, Path("many.yaml")))
        with caplog.at_level(logging.WARNING, logger="bridge"):
            async with started(bridge):
                await eventually(
                    lambda: all(p.health.online for p in bridge.engine.devices.values()), 60
                )
                await eventually(lambda: not bridge.discovery.pending, 30)
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert warnings == [], f"{len(warnings)} warnings, the first: {warnings[:3]}"


@pytest.mark.asyncio
async def test_a_broker_slower_than_the_bridge_is_said_once_with_numbers(
    mosquitto: Broker, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Acknowledgements a second late (shortened from 30 s to 0.5 s here): one WARNING for
    the session, with how long and how many."""
    monkeypatch.setattr(session_module, "BACKLOG_SAID_AFTER", 0.5)
    async with relayed(mosquitto) as (relay, url):
        client = MqttClient(MqttConfig(url=url), will_topic="t/state")
        async with client:
            relay.delay = 1.0
            with caplog.at_level(logging.WARNING, logger="bridge"):
                for _ in range(3):
                    await client.publish_many((f"t/{i}", "x", False) for i in range(40))
    said = [r.getMessage() for r in caplog.records if "slower than the bridge" in r.getMessage()]
    assert len(said) == 1, said
    assert "publishes wait" in said[0]
