"""Writes with conditions and spacing on a real bus (the Smartgen and P2 simulators over
Modbus TCP): a key with ``requires`` goes alone, a toggle's spacing counts only attempts
that went out, a mapping reload keeps it, and a lock the bridge would undo is refused."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from bridge.core.mapping import load_mapping
from bridge.errors import CommandExpiredError, CommandRejectedError, DeviceTimeoutError
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller
from bridge.modbus.simulator import Quirks, SimulatedUnit, Simulator
from tests.integration.harness import config, running, serving_tcp, simulator, tcp_bus
from tests.integration.test_seed_behaviours import (
    GEN_TOGGLE,
    P2_PASSWORD,
    device,
    smartgen_device,
    writes_to,
)

SMARTGEN = "smartgen_hgm6100"


@contextlib.asynccontextmanager
async def manual_genset() -> AsyncIterator[tuple[Simulator, Engine, DevicePoller]]:
    """A simulated genset in manual mode on its own bus, read once (its conditions and
    breaker state known); no polls, so every write seen is the test's."""
    sim = simulator((1, SMARTGEN))
    sim.set_value(1, "manual_mode", True)
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [smartgen_device()]))
        async with running(engine, pollers=False):
            genset = engine.devices[SMARTGEN]
            await genset.read_now()
            yield sim, engine, genset


@pytest.mark.asyncio
async def test_a_key_with_conditions_is_refused_beside_other_keys() -> None:
    """In manual mode, ``command_auto`` with ``command_start`` in one command: the start's
    condition (manual mode) was read before the command, which leaves manual mode first.
    Nothing is written; alone, each goes through."""
    async with manual_genset() as (sim, _, genset):
        with pytest.raises(CommandRejectedError) as caught:
            await genset.write_many({"command_auto": "PRESS", "command_start": "PRESS"})
        for key in ("command_auto", "command_start"):  # both have conditions
            assert "send it in a command of its own" in caught.value.reason(key)
        assert writes_to(sim, 1) == []
        await genset.write_many({"command_start": "PRESS"})
        assert len(writes_to(sim, 1)) == 1


@pytest.mark.asyncio
async def test_a_toggle_that_expired_unsent_does_not_hold_up_the_next() -> None:
    """The breaker toggle's 2 s spacing counts attempts that went out: one dropped at its
    expiry before a byte was sent leaves the next command free."""
    async with manual_genset() as (sim, _, genset):
        with pytest.raises(CommandExpiredError) as caught:
            await genset.write_many({"generator_breaker": True}, deadline=time.monotonic() - 1)
        assert caught.value.sent is False
        assert writes_to(sim, 1) == []
        await genset.write_many({"generator_breaker": True})
        assert [w.address for w in writes_to(sim, 1)] == [GEN_TOGGLE]


@pytest.mark.asyncio
async def test_a_mapping_reload_keeps_the_toggle_spacing() -> None:
    """Reloading the mapping right after a toggle does not let a second toggle out within
    its 2 s (the device may still be acting on the first)."""
    async with manual_genset() as (sim, engine, genset):
        await genset.write_many({"generator_breaker": True})
        reloaded = await engine.replace_mapping(SMARTGEN, genset.mapping)
        await reloaded.read_now()
        with pytest.raises(CommandRejectedError) as caught:
            await reloaded.write_many({"generator_breaker": False})
        assert "not again within 2 s" in caught.value.reason("generator_breaker")
        assert [w.address for w in writes_to(sim, 1)] == [GEN_TOGGLE]


P2_LOCK = 0x1F01


@pytest.mark.asyncio
@pytest.mark.parametrize("with_password", [True, False])
async def test_a_lock_the_bridge_would_undo_at_once_is_refused(
    with_password: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The P2 holding its password in the config: pressing ``lock_parameters`` would lock
    the drive and the bridge would unlock it on the next poll, so it is refused, saying so.
    Without a password the press is written (the drive then stays locked: asked for)."""
    monkeypatch.setenv("P2_PASSWORD", str(P2_PASSWORD))
    fields = {"password_env": "P2_PASSWORD"} if with_password else {}
    p2 = device("p2_vfd", allow_dangerous_writes=True, **fields)
    sim = simulator((1, "p2_vfd"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [p2]))
        async with running(engine, pollers=False):
            drive = engine.devices["p2_vfd"]
            if with_password:
                with pytest.raises(CommandRejectedError) as caught:
                    await drive.write_many({"lock_parameters": "PRESS"})
                assert "unlocks it again on its next request" in caught.value.reason(
                    "lock_parameters"
                )
                assert writes_to(sim, 1) == []
            else:
                await drive.write_many({"lock_parameters": "PRESS"})
                assert [(w.address, w.values) for w in writes_to(sim, 1)] == [(P2_LOCK, (0x55AA,))]


SPACED = """
manufacturer: Test
model: Spaced
description: a coil and a register at the same address, each written at most every 2 s
source: {title: test}
entities:
  relay: {name: Relay, address: 5, table: coil, access: rw, write_interval: 2s}
  setpoint: {name: Setpoint, address: 5, access: rw, write_interval: 2s}
"""


@pytest.mark.asyncio
async def test_write_spacing_is_kept_per_coil_and_per_register(tmp_path: Path) -> None:
    """Coil 5 and holding register 5 are two things: writing one does not hold up the
    other; each keeps its own spacing."""
    path = tmp_path / "spaced.yaml"
    path.write_text(SPACED)
    sim = Simulator([SimulatedUnit(1, load_mapping(path))])
    async with serving_tcp(sim) as port:
        unit = {"id": "spaced", "bus": "tcp", "unit": 1, "mapping": str(path)}
        engine = Engine(config([tcp_bus(port)], [unit]))
        async with running(engine, pollers=False):
            spaced = engine.devices["spaced"]
            await spaced.write_many({"relay": True})
            await spaced.write_many({"setpoint": 7})
            with pytest.raises(CommandRejectedError) as caught:
                await spaced.write_many({"setpoint": 8})
            assert "not again within 2 s" in caught.value.reason("setpoint")
    assert [(w.table.value, w.address, w.values) for w in writes_to(sim, 1)] == [
        ("coil", 5, (0xFF00,)),
        ("holding", 5, (7,)),
    ]


TOGGLE = """
manufacturer: Test
model: Toggle
description: a breaker toggle whose mapping forgot idempotent false
source: {title: test}
entities:
  breaker: {name: Breaker, address: 5, table: coil, access: w, toggle_of: closed}
  closed: {name: Closed, address: 7, table: coil}
"""


@pytest.mark.asyncio
async def test_a_toggle_is_never_resent_even_if_its_mapping_says_idempotent(
    tmp_path: Path,
) -> None:
    """The unit acts on the toggle but answers after the timeout: with the bus's retries a
    resend would flip the breaker back. A ``toggle_of`` entity is sent once, whatever its
    ``idempotent`` says."""
    path = tmp_path / "toggle.yaml"
    path.write_text(TOGGLE)
    sim = Simulator([SimulatedUnit(1, load_mapping(path), quirks=Quirks(write_latency=0.5))])
    async with serving_tcp(sim) as port:
        unit = {"id": "toggle", "bus": "tcp", "unit": 1, "mapping": str(path)}
        engine = Engine(config([tcp_bus(port, timeout=0.3, retries=1)], [unit]))
        async with running(engine, pollers=False):
            with pytest.raises(DeviceTimeoutError):
                await engine.devices["toggle"].write_many({"breaker": True})
            await asyncio.sleep(0.8)  # a resend would have reached the unit by now
    assert [(w.table.value, w.address) for w in writes_to(sim, 1)] == [("coil", 5)]


@pytest.mark.asyncio
async def test_a_toggle_sent_by_the_replaced_poller_holds_up_the_new_one() -> None:
    """A command still running on the poller a reload replaced toggles the breaker: the
    new poller's next toggle within 2 s is refused (they share the spacing)."""
    async with manual_genset() as (sim, engine, genset):
        reloaded = await engine.replace_mapping(SMARTGEN, genset.mapping)
        await reloaded.read_now()
        await genset.write_many({"generator_breaker": True})  # the earlier poller
        with pytest.raises(CommandRejectedError) as caught:
            await reloaded.write_many({"generator_breaker": False})
        assert "not again within 2 s" in caught.value.reason("generator_breaker")
        assert [w.address for w in writes_to(sim, 1)] == [GEN_TOGGLE]
