"""The demo's sites: which simulated devices sit on which bus (``demo --site NAME``).

``seeds``: the five seed mappings as units 1..5 on one loopback Modbus TCP port.

``home``: a home from the device library. The grid meter, the hybrid inverter with its
battery and the wallbox share one RS-485 line (a virtual cable, bridge/modbus/null_modem.py:
RTU frames with real CRCs through a serial port, as a USB adapter gives them); the heat
pump and a SunSpec PV string inverter (``mapping: sunspec``: no mapping file, its model
chain walked; served from bridge/sunspec/demo_inverter.json) are on the LAN (Modbus
TCP). The bridge's gateway serves the RS-485 units on a loopback
TCP port, so a second master (evcc, a PLC, ``mbpoll``) reads the meter without a second
cable and without stealing the line from the bridge.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

LOOPBACK = "127.0.0.1"
SERIAL_BUS = "rs485"
LAN_BUS = "lan"
TCP_BUS = "demo"


@dataclass(frozen=True, slots=True)
class SeedDevice:
    """One simulated device of a site: its id, name, shipped mapping, unit and bus."""

    id: str
    name: str
    mapping: str
    unit: int
    bus: str = TCP_BUS
    # the controls that change how the device runs (``dangerous`` in its mapping) answer;
    # the devices are simulated, so the demo lets them: on a real site it is each
    # device's own ``allow_dangerous_writes``
    allow_dangerous: bool = False
    image: str | None = None  # a SunSpec device image in bridge/sunspec/ (mapping: sunspec)


@dataclass(frozen=True, slots=True)
class Command:
    """A control of the site: ``<base>/<device>/<key>/set`` with ``payload`` (the banner
    prints the first; the tests send each, through MQTT and through Home Assistant)."""

    device: str
    key: str
    payload: str


@dataclass(frozen=True, slots=True)
class Site:
    """A demo site: its devices, and the examples the banner prints."""

    name: str
    title: str
    devices: tuple[SeedDevice, ...]
    controls: tuple[Command, ...]
    fault: tuple[str, str]  # (device id, alarm key) for the printed fault request
    # mbpoll's options for the printed read through the gateway (a site with an RS-485 line)
    gateway_read: str = ""

    @property
    def serial(self) -> tuple[SeedDevice, ...]:
        """The devices on the RS-485 line (served by the gateway too)."""
        return tuple(d for d in self.devices if d.bus == SERIAL_BUS)

    def on(self, bus: str) -> tuple[SeedDevice, ...]:
        return tuple(d for d in self.devices if d.bus == bus)

    @property
    def buses(self) -> tuple[str, ...]:
        """The site's buses, in the order their devices are listed."""
        return tuple(dict.fromkeys(d.bus for d in self.devices))


SEEDS = (
    SeedDevice("borehole_pump", "Borehole pump", "nastec_vasco", 1),
    SeedDevice("fan_drive", "Fan drive", "p2_vfd", 2),
    SeedDevice("booster_starter", "Booster starter", "soft_starter", 3),
    SeedDevice("main_drive", "Main drive", "vacon_nx", 4),
    SeedDevice("genset", "Genset", "smartgen_hgm6100", 5),
)

HOME = (
    SeedDevice("grid_meter", "Grid meter", "eastron_sdm630", 1, SERIAL_BUS),
    SeedDevice("hybrid_inverter", "Hybrid inverter", "deye_hybrid", 2, SERIAL_BUS, True),
    SeedDevice("wallbox", "Wallbox", "abb_terra_ac", 3, SERIAL_BUS, True),
    SeedDevice("heat_pump", "Heat pump", "nibe_s", 1, LAN_BUS, True),
    SeedDevice("pv_inverter", "PV inverter", "sunspec", 2, LAN_BUS, image="demo_inverter.json"),
)

SITES = {
    "seeds": Site(
        "seeds",
        "the five seed devices",
        SEEDS,
        (Command("borehole_pump", "start_stop", "OFF"),),
        ("borehole_pump", "alarm_dry_running"),
    ),
    "home": Site(
        "home",
        "a home: grid meter, hybrid inverter with battery, wallbox, heat pump, PV inverter",
        HOME,
        (
            Command("wallbox", "current_limit_setpoint", "10"),
            Command("hybrid_inverter", "work_mode", "zero_export_to_load"),
            Command("heat_pump", "heating_offset", "2"),
        ),
        ("hybrid_inverter", "fault_f35_no_ac_grid"),
        "-a 1 -t 3:float -B -r 1 -c 3 -1",  # the grid meter's three phase voltages
    ),
}


def site_data(
    site: Site, mqtt: dict[str, Any], where: dict[str, str], web_port: int, gateway_port: int
) -> dict[str, Any]:
    """The config document of ``site``'s bridge (before validation): its buses at
    ``where``, its devices, the web page and, with an RS-485 line, the gateway."""
    bridge: dict[str, Any] = {"web": {"enabled": True, "port": web_port}}
    if site.serial:  # a second master reads the line through the bridge, not beside it
        units = {d.unit: d.id for d in site.serial}
        bridge["gateway"] = {"enabled": True, "host": LOOPBACK, "port": gateway_port}
        bridge["gateway"] |= {"units": units, "max_age": 2.0}
    data: dict[str, Any] = {
        "mqtt": mqtt,
        "bridge": bridge,
        "buses": [_bus(bus, where[bus]) for bus in site.buses],
        "devices": [
            {"id": d.id, "name": d.name, "bus": d.bus, "unit": d.unit, "mapping": d.mapping}
            | ({"allow_dangerous_writes": True} if d.allow_dangerous else {})
            for d in site.devices
        ],
    }
    return data


def _bus(bus: str, where: str) -> dict[str, Any]:
    if bus == SERIAL_BUS:
        return {"id": bus, "transport": "rtu", "port": where, "baudrate": 9600, "timeout": 0.5}
    host, _, port = where.rpartition(":")
    return {"id": bus, "transport": "tcp", "host": host, "tcp_port": int(port), "timeout": 0.5}
