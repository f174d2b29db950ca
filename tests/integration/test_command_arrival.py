"""A command's expiry counts from its arrival, not from when the message loop reads it
(it may wait while a session starts: discovery, the stale-config sweep). The dispatcher
on a real engine and simulator; the message as the MQTT client hands it over."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Coroutine
from typing import Any

import pytest

from bridge.core.topics import Action, CommandTopic
from bridge.dispatcher import Dispatcher
from bridge.modbus.engine import Engine
from bridge.mqtt.session import Message
from tests.integration.harness import config, running, serving_tcp, simulator, tcp_bus
from tests.integration.test_seed_behaviours import device, writes_to

EXPIRY = 5.0


def message(payload: bytes, received: float | None) -> Message:
    return Message(
        topic="modbus/vacon_nx/pd_in_1/set",
        payload=payload,
        qos=1,
        retain=False,
        duplicate=False,
        mid=None,
        received=received,
    )


@pytest.mark.asyncio
async def test_a_command_that_waited_past_its_expiry_before_it_was_read_is_dropped() -> None:
    sim = simulator((1, "vacon_nx"))
    errors: list[str] = []
    tasks: list[asyncio.Task[None]] = []

    def spawn(work: Coroutine[Any, Any, None], _: Callable[[str], None]) -> None:
        tasks.append(asyncio.create_task(work))

    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("vacon_nx")]))
        async with running(engine, pollers=False):
            await engine.devices["vacon_nx"].read_now()
            dispatcher = Dispatcher(
                engine,
                EXPIRY,
                spawn=spawn,
                error=lambda _d, _k, _v, reason: errors.append(reason),
                read=lambda _d: None,
            )
            target = CommandTopic("vacon_nx", "pd_in_1", Action.SET)
            waited = time.monotonic() - EXPIRY - 1  # arrived 6 s ago, read only now
            dispatcher.handle(target, message(b"7", waited))
            await asyncio.gather(*tasks)
            assert errors == ["expired: not executed within the command expiry"]
            assert writes_to(sim, 1) == []
            dispatcher.handle(target, message(b"8", time.monotonic()))  # arrived just now
            await asyncio.gather(*tasks)
            assert [w.values for w in writes_to(sim, 1)] == [(8,)]
