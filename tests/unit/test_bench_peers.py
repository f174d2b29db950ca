"""The peers bench's configs (bench/peer_configs.py) read the same 40 registers.

Only the config generators are checked here (no peer is installed, nothing is timed): the
bridge's trimmed mapping, modbus4mqtt's YAML and modbus2mqtt's CSV must name the same
wire addresses, or the bench would compare different workloads.
"""

from __future__ import annotations

import csv
import io
import sys
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import peer_configs as workload

from bridge.config import load_config
from bridge.core.entity import PollClass


def test_the_workload_is_38_values_on_40_registers() -> None:
    registers = workload.registers()

    assert len(registers) == len(set(workload.KEYS)) == 38
    assert len(workload.wire_addresses()) == 40
    assert sum(r.words for r in registers) == 40


def test_the_bridge_reads_exactly_the_workload_every_second(tmp_path: Path) -> None:
    paths = workload.write_configs(tmp_path, "mqtt://127.0.0.1:1883", 5020, [1, 2])

    loaded = load_config(paths["bridge"])

    for device in loaded.config.devices:
        points = loaded.mappings[device.id].points()
        assert set(points) == set(workload.KEYS)
        assert {a for p in points.values() for a in p.span} == workload.wire_addresses()
        classes = {p.entity.poll_class for p in points.values()}
        assert classes <= {PollClass.FAST, PollClass.SLOW}
        assert device.poll.fast == device.poll.slow == workload.PERIOD


def test_modbus4mqtt_reads_the_same_registers(tmp_path: Path) -> None:
    paths = workload.write_configs(tmp_path, "mqtt://127.0.0.1:1883", 5020, [1, 2])

    for unit in (1, 2):
        config = yaml.safe_load(paths[f"modbus4mqtt-{unit}"].read_text())
        assert config["device_address"] == unit
        assert config["scan_batching"] == 1  # the device reads one register per request
        assert workload.modbus4mqtt_addresses(config) == workload.wire_addresses()
        topics = [entry["pub_topic"] for entry in config["registers"]]
        assert sorted(topics) == sorted(workload.KEYS)


def test_modbus2mqtt_reads_the_same_registers_one_per_request(tmp_path: Path) -> None:
    paths = workload.write_configs(tmp_path, "mqtt://127.0.0.1:1883", 5020, [1, 2])
    text = paths["modbus2mqtt"].read_text()

    for unit in (1, 2):
        assert workload.modbus2mqtt_addresses(text, unit) == workload.wire_addresses()
    pollers = [row for row in csv.DictReader(io.StringIO(text)) if row["type"] == "poll"]
    assert {row["col4"] for row in pollers} == {"1"}
    assert len(pollers) == 2 * 40


def test_scales_and_labels_come_from_the_mapping() -> None:
    config = workload.modbus4mqtt_config(5020, 1)
    by_topic = {entry["pub_topic"]: entry for entry in config["registers"]}

    assert by_topic["actual_value"]["scale"] == 0.1
    assert by_topic["start_stop"]["value_map"] == {"OFF": 0, "ON": 1}
    assert by_topic["status"]["mask"] == 0x000F
    assert by_topic["electric_life"]["type"] == "uint32"
    assert "set_topic" not in by_topic["power"]
