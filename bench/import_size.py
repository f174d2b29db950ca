"""How long ``import ha`` takes on a community-package-sized configuration, and on the
largest the importer accepts (``MAX_ENTITIES`` entities, a file under ``MAX_FILE_BYTES``).

A generated ``configuration.yaml``: ``--hubs`` TCP hubs, each with ``--sensors`` register
sensors (int16, uint32 with word swap, float32, scale/precision/unit/device class, the mix a
solar-inverter package has) spread over 3 units, plus a binary sensor and a switch per unit.
Timed: reading (``load_source``), converting (``import_ha``: every entity and every device's
mapping validated) and writing the files' texts (``render_files``), the median of
``--rounds``; the peak RSS of the process at the end.

    .venv/bin/python bench/import_size.py [--hubs 1] [--sensors 300] [--rounds 5]
"""

from __future__ import annotations

import argparse
import resource
import statistics
import tempfile
import time
from pathlib import Path

import yaml

from bridge.cli.importer import render_files
from bridge.importer.ha_modbus import import_ha
from bridge.importer.source import load_source

TYPES = [
    {
        "data_type": "int16",
        "scale": 0.1,
        "precision": 1,
        "unit_of_measurement": "V",
        "device_class": "voltage",
        "state_class": "measurement",
    },
    {
        "data_type": "uint32",
        "swap": "word",
        "unit_of_measurement": "Wh",
        "device_class": "energy",
        "state_class": "total_increasing",
    },
    {
        "data_type": "float32",
        "precision": 2,
        "unit_of_measurement": "W",
        "device_class": "power",
        "state_class": "measurement",
    },
]


def configuration(hubs: int, sensors: int) -> str:
    blocks = []
    for h in range(hubs):
        entities = [
            {"name": f"Hub {h} value {n}", "address": 2 * n, "slave": 1 + n % 3} | TYPES[n % 3]
            for n in range(sensors)
        ]
        hub = {"name": f"inverter {h}", "type": "tcp", "host": "192.0.2.1", "port": 502 + h}
        hub["sensors"] = entities
        hub["binary_sensors"] = [
            {"name": f"Hub {h} fault {u}", "address": 9000, "slave": u} for u in (1, 2, 3)
        ]
        hub["switches"] = [
            {"name": f"Hub {h} export {u}", "address": 9100, "slave": u, "verify": {}}
            for u in (1, 2, 3)
        ]
        blocks.append(hub)
    return yaml.safe_dump({"modbus": blocks}, sort_keys=False)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--hubs", type=int, default=1)
    parser.add_argument("--sensors", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "configuration.yaml"
        path.write_text(configuration(args.hubs, args.sensors), encoding="utf-8")
        phases: dict[str, list[float]] = {"read": [], "convert": [], "render": []}
        for _ in range(args.rounds):
            began = time.perf_counter()
            data = load_source(path)
            read = time.perf_counter()
            result = import_ha(data, path.name)
            converted = time.perf_counter()
            render_files(result, str(path))
            phases["read"].append(read - began)
            phases["convert"].append(converted - read)
            phases["render"].append(time.perf_counter() - converted)
        size = path.stat().st_size
    entities = sum(len(d.mapping["entities"]) for d in result.devices)
    shown = ", ".join(f"{k} {statistics.median(v) * 1000:.0f} ms" for k, v in phases.items())
    total = sum(statistics.median(v) for v in phases.values()) * 1000
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"{size / 1000:.0f} kB, {entities} entities in {len(result.devices)} devices, "
        f"{len(result.notes)} notes: {shown}; total {total:.0f} ms; peak RSS {peak:.0f} MiB"
    )


if __name__ == "__main__":
    main()
