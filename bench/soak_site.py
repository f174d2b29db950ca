"""The soak's site: which devices on which bus, the bridge's config, the simulators, and a
serial line that can be made noisy.

A Modbus TCP bus with the Nastec pump (unit 1); an RS-485 line (RTU on a pty pair,
bridge/modbus/null_modem.py) with the P2 drive, the Smartgen genset (one request a
second), the soft starter, the Vacon drive and an Eastron SDM630 meter. The gateway serves
units 1, 5 and 6 to other masters. ``build_config`` writes the config (``slower``: every
poll interval half as long again, the config a reload changes to); ``DeviceFacts`` says
what the checkers need of the mappings: the guarded registers, the counters, the keys
whose published values are compared, their poll periods and offline thresholds.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from bridge.core.entity import PollClass
from bridge.core.mapping import Mapping, builtin_mapping_path, load_mapping
from bridge.modbus.simulator import SimulatedUnit, Simulator

BASE = "modbus"
TIMEOUT = 0.5  # s, both buses
HEALTH_INTERVAL = 10.0
COMMAND_EXPIRY = 3.0
OFFLINE_AFTER = 3  # the default: failed requests in a row
# id, mapping, bus, unit, fast s, slow s
DEVICES = (
    ("pump", "nastec_vasco", "tcp", 1, 2.0, 20.0),
    ("drive", "p2_vfd", "rs485", 2, 2.0, 20.0),
    ("genset", "smartgen_hgm6100", "rs485", 3, 10.0, 60.0),
    ("softstarter", "soft_starter", "rs485", 4, 2.0, 20.0),
    ("vacon", "vacon_nx", "rs485", 5, 2.0, 20.0),
    ("meter", "eastron_sdm630", "rs485", 6, 2.0, 20.0),
)
GATEWAY_UNITS = {1: "pump", 5: "vacon", 6: "meter"}
COUNTER_FAULT_KEYS = {"genset": "energy", "meter": "energy_import", "pump": "electric_life"}
COMMAND_DEVICE, COMMAND_KEYS = "vacon", tuple(f"pd_in_{n}" for n in range(1, 9))
GUARDED_TRIES = (("vacon", "reverse", "ON"), ("pump", "sensor_full_scale", "50"))
SLOWER = 1.5


def mappings() -> dict[str, Mapping]:
    return {device: load_mapping(builtin_mapping_path(name)) for device, name, *_ in DEVICES}


def units(bus: str) -> list[SimulatedUnit]:
    loaded = mappings()
    return [SimulatedUnit(unit, loaded[d]) for d, _, b, unit, *_ in DEVICES if b == bus]


def build_config(  # noqa: PLR0917 - the site's every address
    folder: Path, broker: str, tcp_port: int, serial: str, gateway_port: int, slower: bool
) -> Path:
    factor = SLOWER if slower else 1.0
    devices = [
        {
            "id": d,
            "bus": bus,
            "unit": unit,
            "mapping": name,
            "poll": {"fast": fast * factor, "slow": slow * factor},
        }
        for d, name, bus, unit, fast, slow in DEVICES
    ]
    config = {
        "mqtt": {
            "url": broker,
            "base_topic": BASE,
            "client_id": "soak-bridge",
            "command_expiry": COMMAND_EXPIRY,
        },
        "bridge": {
            "health_interval": HEALTH_INTERVAL,
            "gateway": {"enabled": True, "port": gateway_port, "units": GATEWAY_UNITS},
        },
        "buses": [
            {
                "id": "tcp",
                "transport": "tcp",
                "host": "127.0.0.1",
                "tcp_port": tcp_port,
                "timeout": TIMEOUT,
            },
            {
                "id": "rs485",
                "transport": "rtu",
                "port": serial,
                "baudrate": 19200,
                "timeout": TIMEOUT,
            },
        ],
        "devices": devices,
    }
    path = folder / "bridge.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


@dataclass(frozen=True)
class DeviceFacts:
    """What the checkers know of the site, from the mappings and the poll periods."""

    unit: dict[str, int]
    guarded: dict[tuple[int, int], str]  # (unit, wire address) -> entity key
    counters: dict[str, frozenset[str]]  # device -> total_increasing keys
    watched: dict[str, tuple[str, ...]]  # device -> keys compared with the simulator
    windows: dict[tuple[str, str], float]  # (device, key) -> its poll period (the slower config)
    thresholds: dict[str, float]  # device -> seconds silent before it must be offline


def device_facts(simulators: dict[str, Simulator]) -> DeviceFacts:
    loaded = mappings()
    facts = DeviceFacts({}, {}, {}, {}, {}, {})
    for device, _, bus, unit, fast, slow in DEVICES:
        points = loaded[device].points()
        facts.unit[device] = unit
        for key, point in points.items():
            if point.entity.dangerous:
                for address in (point.address, point.write_address):
                    facts.guarded[(unit, address)] = key
        facts.counters[device] = frozenset(
            k
            for k, p in points.items()
            if p.entity.ha and p.entity.ha.state_class == "total_increasing"
        )
        moving = simulators[bus]._device(unit).moving()
        keys = [
            m.point.key
            for m in moving
            if m.point.entity.poll_class in (PollClass.FAST, PollClass.SLOW)
        ]
        keys += list(COMMAND_KEYS) if device == COMMAND_DEVICE else []
        facts.watched[device] = tuple(keys)
        for key in keys:
            period = fast if points[key].entity.poll_class is PollClass.FAST else slow
            facts.windows[(device, key)] = period * SLOWER
        facts.thresholds[device] = OFFLINE_AFTER * (fast * SLOWER + TIMEOUT) + 5.0
    return facts


@dataclass
class NoisyLine:
    """The RS-485 line between the simulator and the bridge (null_modem's ``line``):
    ``clean`` passes replies on, ``noise`` flips a byte of about one reply in three (a
    CRC error), ``torn`` sends a reply in two parts 30-80 ms apart (a slow converter)."""

    seed: int
    mode: str = "clean"
    damaged: int = 0
    _rng: random.Random = field(init=False)
    later: Callable[[float, Callable[[], None]], object] | None = None

    def __post_init__(self) -> None:
        self._rng = random.Random(self.seed)  # noqa: S311 - noise, not secrets

    def __call__(self, data: bytes, send: Callable[[bytes], None]) -> None:
        if self.mode == "noise" and self._rng.random() < 1 / 3:
            self.damaged += 1
            spoilt = bytearray(data)
            spoilt[self._rng.randrange(len(spoilt))] ^= 1 << self._rng.randrange(8)
            send(bytes(spoilt))
        elif self.mode == "torn" and len(data) > 3 and self.later is not None:
            self.damaged += 1
            cut = self._rng.randrange(1, len(data))
            send(data[:cut])
            self.later(self._rng.uniform(0.03, 0.08), lambda: send(data[cut:]))
        else:
            send(data)
