"""The workload of ``bench/peers.py`` and the three configs that read it.

One Nastec VASCO pump inverter (the shipped ``nastec_vasco`` mapping: one register per
read, reserved addresses refused), 38 values on 40 registers: 13 settings including the
run switch, 11 readings including the status nibble, the 8 alarm-history slots, 4 analog
inputs and 2 u32 life counters. ``KEYS`` names them by entity key; everything else
(wire address, words, scale, labels) comes from the mapping, so the three configs are
generated from this one list and read the same registers:

* this bridge: a mapping trimmed to ``KEYS`` (``trimmed_mapping``: the shipped file with
  every other entity removed; ``status`` keeps only its nibble, so ``combo_mode`` of the
  same register goes too), every poll class at 1 s;
* modbus4mqtt 0.7.1 (YAML, README "YAML definition"): the manual's index with
  ``address_offset: -1``, ``scan_batching: 1`` (the device reads one register per
  request), ``value_map`` for the enums, ``mask`` for the status nibble, ``uint32`` for the
  counters, a ``set_topic`` on every writable register; one process per unit;
* modbus2mqtt 0.73 (CSV, README "Configuration file"): one poller of one register per
  register (the device refuses longer reads), a reference per poller with its scaling.
  A ``uint32BE`` needs both words in one poller, which this device refuses, so each
  counter is two ``uint16`` references (``<key>_hi``, ``<key>_lo``): 40 topics.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from bridge.core.entity import Access
from bridge.core.mapping import builtin_mapping_path, load_mapping

MAPPING = "nastec_vasco"
PERIOD = 1.0  # seconds between polls, for every bridge
UNIT, DEAD_UNIT = 1, 2
DEVICES = {UNIT: "pump", DEAD_UNIT: "pump2"}  # device names in topics
COMMAND_KEY = "start_stop"
KEYS = (
    # settings (read/write)
    *("start_stop", "delta_start", "sensor_full_scale", "ramp_up_time", "ramp_down_time"),
    *("pwm_frequency", "ramp_time_min_motor_frequency", "pi_proportional_gain"),
    *("pi_integral_gain", "offset_input_1", "dry_run_power_factor", "stop_delay", "unit"),
    # readings
    *("language", "actual_value", "set_value_active", "dc_bus_voltage", "motor_current"),
    *("output_frequency", "power", "module_temperature", "pcb_temperature"),
    *("motor_power_factor", "status"),
    # alarm history, analog inputs, life counters (u32)
    *(f"alarm_history_{n}" for n in range(1, 9)),
    *(f"analog_input_{n}" for n in range(1, 5)),
    *("electric_life", "motor_life"),
)
M4_PREFIX = "modbus4mqtt"  # modbus4mqtt's default --mqtt_topic_prefix
M2_PREFIX = "modbus"  # modbus2mqtt's default --mqtt-topic


@dataclass(frozen=True)
class Register:
    """One value as a register-level peer sees it."""

    key: str
    index: int  # the manual's index (wire address + 1)
    address: int  # wire address
    words: int  # 1, or 2 for a u32 (high word first)
    scale: float
    labels: dict[int, str]  # raw -> label (enum and sentinels)
    mask: int | None  # a bit field's mask
    writable: bool


def registers() -> list[Register]:
    """The values of ``KEYS`` with their wire addresses, in address order."""
    points = load_mapping(builtin_mapping_path(MAPPING)).points()
    found = []
    for key in KEYS:
        point, entity = points[key], points[key].entity
        labels = {0: "OFF", 1: "ON"} if entity.type == "bool" else dict(entity.enum or {})
        width = entity.width or 1
        mask = None if entity.bit is None else ((1 << width) - 1) << entity.bit
        found.append(
            Register(
                key=key,
                index=point.address + 1,
                address=point.address,
                words=point.count,
                scale=entity.scale,
                labels=labels | dict(entity.sentinels),
                mask=mask,
                writable=entity.access is Access.READ_WRITE,
            )
        )
    return sorted(found, key=lambda r: r.address)


def wire_addresses() -> set[int]:
    """Every register the workload reads."""
    return {r.address + i for r in registers() for i in range(r.words)}


# --- this bridge ------------------------------------------------------------------------


def trimmed_mapping() -> dict[str, Any]:
    """The shipped mapping with only the entities of ``KEYS`` (YAML document; its
    fingerprint, whose probes name other entities, left out)."""
    document = yaml.safe_load(builtin_mapping_path(MAPPING).read_text(encoding="utf-8"))
    document["entities"] = {k: v for k, v in document["entities"].items() if k in KEYS}
    document.pop("fingerprint", None)
    return dict(document)


def bridge_config(
    url: str, modbus_port: int, units: list[int], mapping: str, **mqtt_settings: Any
) -> dict[str, Any]:
    """This bridge: one TCP bus, one device per unit, the trimmed ``mapping`` (a path);
    ``mqtt_settings`` beside the defaults (``output: values`` for plain topics only)."""
    devices = [
        {
            "id": DEVICES[unit],
            "bus": "gateway",
            "unit": unit,
            "mapping": mapping,
            "poll": {"fast": PERIOD, "slow": PERIOD},
        }
        for unit in units
    ]
    bus = {"id": "gateway", "transport": "tcp", "host": "127.0.0.1", "tcp_port": modbus_port}
    mqtt = {"url": url, "client_id": "bench-bridge"} | mqtt_settings
    return {"mqtt": mqtt, "buses": [bus], "devices": devices}


# --- modbus4mqtt ------------------------------------------------------------------------


def modbus4mqtt_config(modbus_port: int, unit: int) -> dict[str, Any]:
    """modbus4mqtt's YAML for one unit (its topic prefix is ``M4_PREFIX/<device>``)."""
    entries = []
    for r in registers():
        entry: dict[str, Any] = {"pub_topic": r.key, "table": "holding", "address": r.index}
        if r.writable:
            entry["set_topic"] = f"{r.key}/set"
        if r.words == 2:
            entry["type"] = "uint32"
        if r.scale != 1:
            entry["scale"] = r.scale
        if r.mask is not None:
            entry["mask"] = r.mask
        if r.labels:
            entry["value_map"] = {label: raw for raw, label in r.labels.items()}
        entries.append(entry)
    return {
        "ip": "127.0.0.1",
        "port": modbus_port,
        "device_address": unit,
        "update_rate": PERIOD,
        "address_offset": -1,
        "scan_batching": 1,
        "registers": entries,
    }


def modbus4mqtt_addresses(config: dict[str, Any]) -> set[int]:
    offset = config["address_offset"]
    words = {"uint16": 1, "uint32": 2}
    return {
        entry["address"] + offset + i
        for entry in config["registers"]
        for i in range(words[entry.get("type", "uint16")])
    }


# --- modbus2mqtt ------------------------------------------------------------------------


def modbus2mqtt_topics(r: Register) -> list[tuple[str, int]]:
    """The references of one value: ``(topic, wire address)``; a u32 is two words."""
    if r.words == 1:
        return [(r.key, r.address)]
    return [(f"{r.key}_hi", r.address), (f"{r.key}_lo", r.address + 1)]


def modbus2mqtt_config(units: list[int]) -> str:
    """modbus2mqtt's CSV: a poller of one register and its reference per register."""
    out = io.StringIO()
    rows = csv.writer(out, lineterminator="\n")
    rows.writerow(["type", "topic", "col2", "col3", "col4", "col5", "col6"])
    for unit in units:
        for r in registers():
            for topic, address in modbus2mqtt_topics(r):
                rows.writerow(["poll", DEVICES[unit], unit, address, 1, "holding_register", PERIOD])
                scale = "" if r.scale == 1 else r.scale
                rows.writerow(["ref", topic, address, "rw" if r.writable else "r", "uint16", scale])
    return out.getvalue()


def modbus2mqtt_addresses(config: str, unit: int) -> set[int]:
    found = set()
    poller_unit = 0
    for row in csv.DictReader(io.StringIO(config)):
        if row["type"] == "poll":
            poller_unit = int(row["col2"])
        elif row["type"] == "ref" and poller_unit == unit:
            found.add(int(row["col2"]))
    return found


def write_configs(folder: Path, url: str, modbus_port: int, units: list[int]) -> dict[str, Path]:
    """Write every config into ``folder``; their paths by name."""
    paths = {"mapping": folder / "pump40.yaml", "bridge": folder / "bridge.yaml"}
    paths["mapping"].write_text(yaml.safe_dump(trimmed_mapping(), sort_keys=False))
    config = bridge_config(url, modbus_port, units, paths["mapping"].name)
    paths["bridge"].write_text(yaml.safe_dump(config, sort_keys=False))
    plain = bridge_config(
        url, modbus_port, units, paths["mapping"].name, output="values", discovery="off"
    )
    paths["bridge-values"] = folder / "bridge-values.yaml"
    paths["bridge-values"].write_text(yaml.safe_dump(plain, sort_keys=False))
    for unit in units:
        path = folder / f"modbus4mqtt-{DEVICES[unit]}.yaml"
        path.write_text(yaml.safe_dump(modbus4mqtt_config(modbus_port, unit), sort_keys=False))
        paths[f"modbus4mqtt-{unit}"] = path
    paths["modbus2mqtt"] = folder / "modbus2mqtt.csv"
    paths["modbus2mqtt"].write_text(modbus2mqtt_config(units))
    return paths
