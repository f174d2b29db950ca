"""A running bridge with one simulated seed device, the genset (smartgen_hgm6100, unit 5,
whose mapping leaves registers 32 and 33 free and readable), and the web page on."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path

from bridge.app import Bridge
from bridge.config import load_config_data
from tests.integration.harness import cancel, serving_tcp, simulator
from tests.integration.mosquitto import Broker
from tests.integration.web import Site, listening
from tests.ports import free_port

GENSET = 5
FREE = 32  # wire address of a register the genset's mapping leaves free
STATE = "state"  # bridge.state_dir, relative to the config file


@contextlib.asynccontextmanager
async def genset_site(broker: Broker, folder: Path) -> AsyncIterator[Site]:
    sim = simulator((GENSET, "smartgen_hgm6100"), tick=0)
    port = free_port()
    async with serving_tcp(sim) as modbus_port:
        data = {
            "mqtt": {"url": broker.url},
            "bridge": {
                "state_dir": STATE,
                "web": {"enabled": True, "host": "127.0.0.1", "port": port},
            },
            "buses": [{"id": "tcp", "transport": "tcp", "host": "127.0.0.1"}
                      | {"tcp_port": modbus_port, "timeout": 0.3}],
            "devices": [{"id": "genset", "bus": "tcp", "unit": GENSET}
                        | {"mapping": "smartgen_hgm6100", "poll": {"fast": 0.2, "slow": 2}}],
        }  # fmt: skip
        running = Bridge(load_config_data(data, folder / "config.yaml"))
        task = asyncio.create_task(running.run())
        try:
            await listening(port)
            yield Site(running, sim, port)
        finally:
            await cancel(task)
