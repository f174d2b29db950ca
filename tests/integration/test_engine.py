"""The Modbus engine end to end: real transports, scheduler and pollers against the simulator."""

from __future__ import annotations

import asyncio

import pytest

from bridge.core.entity import PollClass, Table
from bridge.core.mapping import builtin_mapping_names
from bridge.core.request import Write
from bridge.errors import DeviceTimeoutError, ValueRejectedError
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DeviceUpdate
from bridge.modbus.simulator import Quirks
from tests.integration.harness import (
    FAST_POLICY,
    Recorder,
    config,
    eventually,
    running,
    serving_serial,
    serving_tcp,
    simulator,
    tcp_bus,
)

H = Table.HOLDING
ALL = (PollClass.FAST, PollClass.SLOW, PollClass.ONCE)


def device(name: str, unit: int = 1, bus: str = "tcp", **fields: object) -> dict[str, object]:
    return {"id": f"{name}_{unit}", "bus": bus, "unit": unit, "mapping": name} | fields


def assert_same_values(engine: Engine, device_id: str, sim_unit: int, sim: object) -> None:
    poller = engine.devices[device_id]
    readable = [k for k, p in poller.points.items() if p.entity.readable]
    assert readable
    for key in readable:
        assert key in poller.values, f"{key} was never read"
        assert poller.values[key] == sim.value(sim_unit, key), key  # type: ignore[attr-defined]


@pytest.mark.asyncio
@pytest.mark.parametrize("name", builtin_mapping_names())
async def test_every_mapping_is_polled_over_tcp(name: str) -> None:
    sim = simulator((1, name))
    async with serving_tcp(sim) as port:
        pacing = {"protocol": {"min_request_interval": 0.01}}  # the Smartgen's 1 s, shortened
        engine = Engine(config([tcp_bus(port)], [device(name, **pacing)]))
        async with running(engine, pollers=False):
            poller = engine.devices[f"{name}_1"]
            await poller.poll(ALL)
            assert poller.health.online is True
            assert poller.health.errors == 0
            assert_same_values(engine, f"{name}_1", 1, sim)


@pytest.mark.asyncio
@pytest.mark.parametrize(
    ("name", "line"),
    [
        # Linux ptys refuse a second tcsetattr once parity is on, so no 8E1 here
        ("p2_vfd", {"transport": "rtu", "baudrate": 19200}),
        ("soft_starter", {"transport": "rtu", "baudrate": 9600, "stopbits": 2}),
        ("p2_vfd", {"transport": "ascii", "baudrate": 9600}),
    ],
    ids=["p2-rtu-19200-8N1", "soft-starter-rtu-8N2", "p2-ascii"],
)
async def test_polled_over_a_serial_line(name: str, line: dict[str, object]) -> None:
    sim = simulator((3, name))
    server_line = {k: v for k, v in line.items() if k != "transport"}
    async with serving_serial(sim, framer=str(line["transport"]), **server_line) as path:
        bus = {"id": "rs485", "port": path, "timeout": 1.0} | line
        engine = Engine(config([bus], [device(name, unit=3, bus="rs485")]))
        async with running(engine, pollers=False):
            await engine.devices[f"{name}_3"].poll(ALL)
            assert_same_values(engine, f"{name}_3", 3, sim)


@pytest.mark.asyncio
async def test_p2_with_f9_05_zero_decodes_over_rtu() -> None:
    sim = simulator((1, "p2_vfd"), two_byte_count=True)
    async with serving_serial(sim) as path:
        bus = {"id": "rs485", "transport": "rtu", "port": path, "timeout": 1.0}
        engine = Engine(config([bus], [device("p2_vfd", bus="rs485")]))
        async with running(engine, pollers=False):
            await engine.devices["p2_vfd_1"].poll(ALL)
            assert_same_values(engine, "p2_vfd_1", 1, sim)


@pytest.mark.asyncio
async def test_a_dead_unit_goes_offline_and_the_live_one_keeps_polling() -> None:
    sim = simulator((1, "soft_starter"), (2, "nastec_vasco"))
    sim.set_quirks(2, Quirks(dead=True))
    recorder = Recorder()
    async with serving_tcp(sim) as port:
        poll = {"poll": {"fast": 0.1, "slow": 1}}
        loaded = config(
            [tcp_bus(port, timeout=0.2)],
            [device("soft_starter", 1, **poll), device("nastec_vasco", 2, **poll)],
        )
        engine = Engine(loaded, recorder, policy=FAST_POLICY)
        async with running(engine):
            dead, live = engine.devices["nastec_vasco_2"], engine.devices["soft_starter_1"]
            await eventually(lambda: dead.health.online is False)
            updates_before = len(recorder.of("soft_starter_1"))
            requests_before = live.health.requests
            await eventually(lambda: live.health.requests >= requests_before + 20)
            assert live.health.online is True
            assert recorder.of("nastec_vasco_2")[-1].online is False
            sim.set_quirks(2, Quirks())  # the unit comes back: no restart needed
            await eventually(lambda: dead.health.online is True)
            await eventually(lambda: "status" in dead.values)
            assert dead.values["status"] == sim.value(2, "status")
    assert len(recorder.of("soft_starter_1")) >= updates_before


@pytest.mark.asyncio
async def test_a_write_reaches_the_wire_and_is_read_back() -> None:
    sim = simulator((1, "nastec_vasco"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("nastec_vasco")]))
        async with running(engine, pollers=False):
            value = await engine.write("nastec_vasco_1", "operating_frequency", 41)
            assert value == 41
            assert sim.value(1, "operating_frequency") == 41
            assert sim.writes[-1] == (1, Write(6, H, 0x37, (41,)))


@pytest.mark.asyncio
async def test_the_acknowledged_value_is_published_before_the_read_back() -> None:
    """FC06 answers once the unit took the register: the value goes out then, one
    transaction before the read-back that confirms it."""
    sim = simulator((1, "soft_starter"))
    seen: list[tuple[int, object]] = []
    async with serving_tcp(sim) as port:
        engine: Engine | None = None

        def record(update: DeviceUpdate) -> None:
            if "motor_run" in update.changed and engine is not None:
                transactions = engine.schedulers["tcp"].counters.transactions
                seen.append((transactions, update.values["motor_run"]))

        engine = Engine(config([tcp_bus(port)], [device("soft_starter")]), record)
        async with running(engine, pollers=False):
            starter = engine.devices["soft_starter_1"]
            await starter.poll(ALL)
            new = not starter.values["motor_run"]
            seen.clear()
            assert await engine.write("soft_starter_1", "motor_run", new) is new
            total = engine.schedulers["tcp"].counters.transactions
    assert seen == [(total - 1, new)]  # published after the write, not again after read-back


@pytest.mark.asyncio
async def test_a_signed_setting_writes_the_sign_bit_then_the_magnitude() -> None:
    sim = simulator((1, "nastec_vasco"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("nastec_vasco")]))
        async with running(engine, pollers=False):
            before = sim.image(1)[(H, 0x4B)]
            assert await engine.write("nastec_vasco_1", "set_value", -2.5) == -2.5
            sign_write, magnitude_write = [w for _, w in sim.writes[-2:]]
            assert sign_write == Write(6, H, 0x4B, (before | 1 << 13,))
            assert magnitude_write == Write(6, H, 0x33, (25,))


@pytest.mark.asyncio
async def test_control_word_bits_and_the_reset_pulse() -> None:
    sim = simulator((1, "vacon_nx"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("vacon_nx", allow_dangerous_writes=True)]))
        async with running(engine, pollers=False):
            assert await engine.write("vacon_nx_1", "reverse", True) is True
            assert await engine.write("vacon_nx_1", "run", True) is True
            assert sim.image(1)[(H, 2000)] == 0b011
            await engine.write("vacon_nx_1", "fault_reset", "PRESS")
            assert [w.values[0] for _, w in sim.writes[-2:]] == [0b111, 0b011]
            assert await engine.write("vacon_nx_1", "run", False) is False
            assert sim.image(1)[(H, 2000)] == 0b010


@pytest.mark.asyncio
async def test_smartgen_commands_use_the_manual_s_on_word() -> None:
    sim = simulator((1, "smartgen_hgm6100"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("smartgen_hgm6100")]))
        async with running(engine, pollers=False):
            assert await engine.write("smartgen_hgm6100_1", "command_auto", "PRESS") is None
            assert sim.writes == [(1, Write(5, Table.COIL, 3, (0x00FF,)))]


@pytest.mark.asyncio
async def test_a_toggle_is_never_resent_after_a_timeout() -> None:
    sim = simulator((1, "smartgen_hgm6100"))
    sim.set_value(1, "manual_mode", True)
    async with serving_tcp(sim) as port:
        engine = Engine(
            config(
                [tcp_bus(port, timeout=0.2, retries=2)],
                [device("smartgen_hgm6100", allow_dangerous_writes=True)],  # a breaker
            )
        )
        async with running(engine, pollers=False):
            sim.set_quirks(1, Quirks(write_latency=0.4))  # answers after the bridge gave up
            with pytest.raises(DeviceTimeoutError):
                await engine.write("smartgen_hgm6100_1", "generator_breaker", "ON")
            with pytest.raises(DeviceTimeoutError):
                await engine.write("smartgen_hgm6100_1", "command_auto", "PRESS")
            await asyncio.sleep(0.5)
    toggles = [w for _, w in sim.writes if w.address == 5]
    modes = [w for _, w in sim.writes if w.address == 3]
    assert len(toggles) == 1
    assert len(modes) == 3  # an idempotent command may be resent


@pytest.mark.asyncio
async def test_rejected_writes_put_nothing_on_the_wire() -> None:
    sim = simulator((1, "nastec_vasco"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("nastec_vasco")]))
        async with running(engine, pollers=False):
            nastec = engine.devices["nastec_vasco_1"]
            await nastec.poll(ALL)
            low, high = nastec.values["min_motor_frequency"], nastec.values["max_motor_frequency"]
            for key, value, message in [
                ("operating_frequency", high + 1, "outside"),  # type: ignore[operator]
                ("operating_frequency", low - 1, "outside"),  # type: ignore[operator]
                ("operating_frequency", "fast", "not a number"),
                ("unit", "furlong", "is not one of"),
                ("actual_value", 3, "read-only"),
                ("modbus_address", 7, "dangerous"),
                ("nonexistent", 1, "no such entity"),
            ]:
                with pytest.raises(ValueRejectedError, match=message):
                    await engine.write("nastec_vasco_1", key, value)
    assert sim.writes == []


@pytest.mark.asyncio
async def test_eeprom_parameters_skip_unchanged_writes_and_are_rate_limited() -> None:
    sim = simulator((1, "soft_starter"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("soft_starter")]))
        async with running(engine, pollers=False):
            starter = engine.devices["soft_starter_1"]
            held = sim.value(1, "soft_start_time")
            assert await engine.write("soft_starter_1", "soft_start_time", held) == held
            assert sim.writes == []
            assert starter.writes.skipped_unchanged == 1
            await engine.write("soft_starter_1", "soft_start_time", 25)
            assert await engine.write("soft_starter_1", "soft_start_time", 25) == 25  # again
            assert starter.writes.skipped_unchanged == 2
            with pytest.raises(ValueRejectedError, match="next write allowed in"):
                await engine.write("soft_starter_1", "soft_start_time", 26)
    assert [w.values for _, w in sim.writes] == [(25,)]


@pytest.mark.asyncio
async def test_refused_addresses_are_learnt_and_avoided() -> None:
    sim = simulator((1, "p2_vfd"), refused=frozenset({0x1005}))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("p2_vfd")]))
        async with running(engine, pollers=False):
            p2 = engine.devices["p2_vfd_1"]
            await p2.poll(ALL)
            assert (H, 0x1005) in p2.refused
            assert p2.values["output_power"] is None
            assert p2.values["output_current"] == sim.value(1, "output_current")
            errors = p2.health.exceptions[2]
            await p2.poll(ALL)
            assert p2.health.exceptions[2] == errors  # the plan no longer asks for it
            assert p2.health.online is True


@pytest.mark.asyncio
async def test_a_smaller_read_limit_is_learnt(caplog: pytest.LogCaptureFixture) -> None:
    sim = simulator((1, "soft_starter"), max_read_registers=2)
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("soft_starter")]))
        async with running(engine, pollers=False):
            starter = engine.devices["soft_starter_1"]
            await starter.poll(ALL)
            assert starter.max_read is not None
            assert starter.max_read <= 2
            learnt = [r for r in caplog.records if "registers per read" in r.getMessage()]
            assert len(learnt) == 1  # said once, though several blocks showed it
            assert_same_values(engine, "soft_starter_1", 1, sim)
            refusals = sum(starter.health.exceptions.values())
            await starter.poll(ALL)
            assert sum(starter.health.exceptions.values()) == refusals


@pytest.mark.asyncio
async def test_busy_answers_are_not_a_dead_device() -> None:
    sim = simulator((1, "p2_vfd"), exception_code=8)  # busy saving to EEPROM
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("p2_vfd")]), policy=FAST_POLICY)
        async with running(engine, pollers=False):
            p2 = engine.devices["p2_vfd_1"]
            for _ in range(3):
                await p2.poll(ALL)
            assert p2.health.online is True
            assert p2.health.busy >= 3
            sim.set_quirks(1, Quirks())
            await p2.poll(ALL)
            assert_same_values(engine, "p2_vfd_1", 1, sim)


@pytest.mark.asyncio
async def test_keepalive_shortens_the_poll_interval() -> None:
    sim = simulator((1, "soft_starter"))
    async with serving_tcp(sim) as port:
        engine = Engine(config([tcp_bus(port)], [device("soft_starter", poll={"fast": 120})]))
        assert engine.devices["soft_starter_1"].intervals[PollClass.FAST] == 20.0


@pytest.mark.asyncio
async def test_a_missing_serial_port_does_not_touch_another_bus() -> None:
    sim = simulator((1, "vacon_nx"))
    recorder = Recorder()
    async with serving_tcp(sim) as port:
        unplugged = {"id": "usb", "transport": "rtu", "port": "/dev/ttyUSB-unplugged"}
        poll = {"poll": {"fast": 0.1, "slow": 1}}
        loaded = config(
            [tcp_bus(port), unplugged],
            [device("vacon_nx", **poll), device("soft_starter", 2, bus="usb", **poll)],
        )
        engine = Engine(loaded, recorder, policy=FAST_POLICY)
        async with running(engine):
            drive, starter = engine.devices["vacon_nx_1"], engine.devices["soft_starter_2"]
            await eventually(lambda: starter.health.online is False)
            start = drive.health.requests
            await eventually(lambda: drive.health.requests > start + 10)
            assert drive.health.online is True
            assert drive.health.errors == 0
            assert engine.schedulers["usb"].counters.reopenings >= 1


@pytest.mark.asyncio
async def test_rtu_over_tcp_through_a_serial_gateway() -> None:
    sim = simulator((5, "smartgen_hgm6100"), (6, "vacon_nx"))
    async with serving_tcp(sim, framer="rtu") as port:
        bus = tcp_bus(port, transport="rtu-over-tcp")
        pacing = {"protocol": {"min_request_interval": 0.01}}
        engine = Engine(
            config([bus], [device("smartgen_hgm6100", 5, **pacing), device("vacon_nx", 6)])
        )
        async with running(engine, pollers=False):
            for device_id, unit in (("smartgen_hgm6100_5", 5), ("vacon_nx_6", 6)):
                await engine.devices[device_id].poll(ALL)
                assert_same_values(engine, device_id, unit, sim)
            assert await engine.write("smartgen_hgm6100_5", "command_stop", "PRESS") is None
            assert sim.writes[-1] == (5, Write(5, Table.COIL, 1, (0x00FF,)))
