"""The fair share between the bridge's polls and other masters: the pure rule
(bridge/core/fair_share.py) and the bus scheduler that applies it."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from bridge.config import load_config_data
from bridge.core.fair_share import BUS, WINDOW, FairShare
from bridge.core.protocol import Protocol
from bridge.errors import CommandExpiredError, ConfigError
from bridge.modbus.engine import Engine
from bridge.modbus.scheduler import Priority
from tests.unit.test_scheduler import READ, WRITE, ScriptedTransport, started, stop


def decisions(fair: FairShare, key: int, count: int) -> list[bool]:
    return [fair.decide(key) for _ in range(count)]


@pytest.mark.parametrize(
    ("share", "polls"),
    [(0.5, 10), (0.0, 0), (1.0, 20), (0.25, 5), (0.75, 15), (0.3, 6)],
)
def test_the_polls_take_their_share_of_the_contested_slots(share: float, polls: int) -> None:
    fair = FairShare(share)
    taken = decisions(fair, 1, 20)
    assert sum(taken) == polls
    assert (fair.yielded, fair.won) == (polls, 20 - polls)


def test_at_one_half_they_alternate_starting_with_the_poll() -> None:
    assert decisions(FairShare(0.5), 1, 6) == [True, False] * 3


def test_every_prefix_keeps_the_share_within_one_slot() -> None:
    fair = FairShare(0.4)
    taken = decisions(fair, 3, 200)
    for n in range(1, len(taken) + 1):
        window = taken[max(0, n - WINDOW) : n]
        assert abs(sum(window) - 0.4 * len(window)) <= 1.0, n


def test_units_and_the_bus_keep_their_own_counts() -> None:
    fair = FairShare(0.5)
    assert decisions(fair, 1, 3) == [True, False, True]
    assert decisions(fair, 2, 1) == [True]  # unit 2's first contest: its own count
    assert decisions(fair, BUS, 2) == [True, False]


def test_a_unit_may_have_its_own_share() -> None:
    fair = FairShare(0.5, shares={5: 1.0, 6: 0.0})
    assert decisions(fair, 5, 4) == [True] * 4
    assert decisions(fair, 6, 4) == [False] * 4
    assert decisions(fair, 7, 2) == [True, False]


def test_the_window_forgets_old_slots() -> None:
    """An hour of masters alone buys them nothing: after a long run with share 0 the unit
    is set to 0.5 and the polls have their share within one window."""
    fair = FairShare(0.0)
    decisions(fair, 1, 500)
    fair.share = 0.5
    assert decisions(fair, 1, WINDOW).count(True) >= WINDOW // 2


# --- the scheduler applies it ------------------------------------------------------------

SLOW = Protocol(min_request_interval=0.02)  # one request per 20 ms, like the genset's 1 s


async def flood(scheduler, unit: int, priority: Priority, count: int, **kw) -> list:  # type: ignore[no-untyped-def]
    return [
        asyncio.create_task(
            scheduler.submit(unit, READ, timeout=1, priority=priority, protocol=SLOW, **kw)
        )
        for _ in range(count)
    ]


@pytest.mark.asyncio
async def test_masters_flooding_a_paced_unit_leave_the_polls_half_its_slots() -> None:
    transport = ScriptedTransport()
    scheduler, task = await started(transport)
    yielded: list[int] = []
    proxy_read = READ.__class__(READ.table, 100, 1)  # registers no entity reads
    proxies = [
        asyncio.create_task(
            scheduler.submit(
                1,
                proxy_read,
                timeout=1,
                priority=Priority.PROXY,
                protocol=SLOW,
                yielded=lambda: yielded.append(1),
            )
        )
        for _ in range(10)
    ]
    polls = await flood(scheduler, 1, Priority.POLL, 10)
    await asyncio.gather(*proxies, *polls)
    went = "".join("P" if r == proxy_read else "b" for _, r, _ in transport.calls)
    assert went == "bP" * 10  # every slot contested: they alternate, the poll first
    assert len(yielded) == 10
    assert scheduler.fair.yielded == 10
    await stop(task)


@pytest.mark.asyncio
async def test_with_share_zero_the_masters_go_first_as_before() -> None:
    transport = ScriptedTransport()
    scheduler, task = await started(transport)
    scheduler.fair.share = 0.0
    proxy_read = READ.__class__(READ.table, 100, 1)
    proxies = [
        asyncio.create_task(
            scheduler.submit(1, proxy_read, timeout=1, priority=Priority.PROXY, protocol=SLOW)
        )
        for _ in range(4)
    ]
    polls = await flood(scheduler, 1, Priority.POLL, 4)
    await asyncio.gather(*proxies, *polls)
    went = "".join("P" if r == proxy_read else "b" for _, r, _ in transport.calls)
    assert went == "PPPPbbbb"
    await stop(task)


@pytest.mark.asyncio
async def test_the_bus_is_shared_too_when_masters_flood_another_unit() -> None:
    transport = ScriptedTransport()
    scheduler, task = await started(transport)
    proxies = [
        asyncio.create_task(scheduler.submit(5, READ, timeout=1, priority=Priority.PROXY))
        for _ in range(6)
    ]
    polls = [asyncio.create_task(scheduler.submit(u, READ, timeout=1)) for u in (1, 2, 3)]
    await asyncio.gather(*proxies, *polls)
    units = [unit for unit, _, _ in transport.calls]
    assert units == [1, 5, 2, 5, 3, 5, 5, 5, 5]
    await stop(task)


@pytest.mark.asyncio
async def test_commands_still_go_before_both() -> None:
    transport = ScriptedTransport(gate=asyncio.Event())
    scheduler, task = await started(transport)
    first = asyncio.create_task(scheduler.submit(1, READ, timeout=1))
    await asyncio.sleep(0.01)  # in flight
    proxy = asyncio.create_task(scheduler.submit(1, READ, timeout=1, priority=Priority.PROXY))
    poll = asyncio.create_task(scheduler.submit(1, READ, timeout=1))
    write = asyncio.create_task(scheduler.submit(1, WRITE, timeout=1, priority=Priority.WRITE))
    await asyncio.sleep(0.01)
    transport.gate.set()
    await asyncio.gather(first, proxy, poll, write)
    assert [request for _, request, _ in transport.calls][:2] == [READ, WRITE]
    await stop(task)


@pytest.mark.asyncio
async def test_a_master_waiting_past_its_deadline_is_answered_at_once_not_at_the_slot() -> None:
    """A proxied request with a deadline (the bus timeout) ends when the deadline passes,
    while its unit still rests; it is never sent (the gateway answers 0x06). The unit
    rests an hour here: the request ends while a poll queued beside it still waits for
    that slot, so it was not answered at the slot."""
    transport = ScriptedTransport()
    scheduler, task = await started(transport)
    resting = Protocol(min_request_interval=3600.0)
    await scheduler.submit(1, READ, timeout=1, protocol=resting)
    poll = asyncio.create_task(scheduler.submit(1, READ, timeout=1, protocol=resting))
    proxy = asyncio.create_task(
        scheduler.submit(
            1,
            READ,
            timeout=1,
            priority=Priority.PROXY,
            protocol=resting,
            deadline=time.monotonic() + 0.1,
        )
    )
    with pytest.raises(CommandExpiredError):
        await proxy
    assert not poll.done()  # the unit's next slot has not come
    assert len(transport.calls) == 1
    poll.cancel()
    await stop(task)


def test_the_config_sets_the_share_per_gateway_and_per_device() -> None:
    data = {
        "bridge": {"gateway": {"poll_share": 0.25}},
        "buses": [{"id": "line", "transport": "rtu", "port": "/dev/null"}],
        "devices": [
            {"id": "genset", "bus": "line", "unit": 5, "mapping": "smartgen_hgm6100"}
            | {"gateway_poll_share": 0.8},
            {"id": "pump", "bus": "line", "unit": 1, "mapping": "nastec_vasco"},
        ],
    }
    fair = Engine(load_config_data(data, Path("share.yaml"))).schedulers["line"].fair
    assert (fair.share, fair.shares) == (0.25, {5: 0.8})


@pytest.mark.parametrize(
    ("where", "value", "field"),
    [
        ("gateway", 1.5, "bridge.gateway.poll_share"),
        ("gateway", -0.1, "bridge.gateway.poll_share"),
        ("device", 2, "devices.genset.gateway_poll_share"),
        ("max_wait", 0, "bridge.gateway.max_wait"),
    ],
)
def test_a_share_or_wait_out_of_range_names_its_field(where: str, value: float, field: str) -> None:
    device: dict[str, object] = {"id": "genset", "bus": "line", "unit": 5}
    device["mapping"] = "smartgen_hgm6100"
    gateway: dict[str, object] = {}
    if where == "gateway":
        gateway["poll_share"] = value
    elif where == "max_wait":
        gateway["max_wait"] = value
    else:
        device["gateway_poll_share"] = value
    data = {
        "bridge": {"gateway": gateway},
        "buses": [{"id": "line", "transport": "rtu", "port": "/dev/null"}],
        "devices": [device],
    }
    with pytest.raises(ConfigError) as refused:
        load_config_data(data, Path("share.yaml"))
    assert any(issue.startswith(field) for issue in refused.value.issues), refused.value.issues
