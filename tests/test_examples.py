"""The examples: every config loads, the Home Assistant dashboard uses entity ids the
discovery really creates, and the Node-RED flow is importable and sends commands the
bridge accepts."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from bridge.config import LoadedConfig, load_config
from bridge.core.codec import encode
from bridge.core.commands import parse_get, parse_set
from bridge.core.discovery import DeviceInfo, Origin, build_bridge_discovery, build_discovery
from bridge.core.mapping import Point
from bridge.core.state import published
from bridge.core.topics import Action, Topics

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
DASHBOARD = EXAMPLES / "home-assistant" / "nastec_dashboard.yaml"
FLOW = EXAMPLES / "node-red" / "nastec_flow.json"
DEVICE = "borehole_pump"
TOPICS = Topics("modbus")
ENTITY_ID = re.compile(r"\b(?:sensor|binary_sensor|switch|number|select|button|text)\.[a-z0-9_]+")


BAD = EXAMPLES / "bad.yaml"  # mistakes on purpose: tests/test_readme.py runs check on it
CONFIGS = sorted(path for path in EXAMPLES.glob("*.yaml") if path != BAD)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_every_example_config_loads(path: Path) -> None:
    loaded = load_config(path)
    assert loaded.config.devices


def test_one_example_per_transport() -> None:
    expected = {
        "rtu-serial.yaml": "rtu",
        "tcp.yaml": "tcp",
        "rtu-over-tcp.yaml": "rtu-over-tcp",
        "ascii.yaml": "ascii",
    }
    for name, transport in expected.items():
        buses = load_config(EXAMPLES / name).config.buses
        assert {bus.transport for bus in buses} == {transport}, name


# --- the pump of examples/config.yaml -------------------------------------------------------


def _example() -> LoadedConfig:
    return load_config(EXAMPLES / "config.yaml")


def _points() -> dict[str, Point]:
    loaded = _example()
    device = next(d for d in loaded.config.devices if d.id == DEVICE)
    return loaded.mappings[DEVICE].points(device.options)


def _components() -> dict[str, dict[str, Any]]:
    """Every entity Home Assistant gets for the pump and the bridge, by default_entity_id."""
    loaded = _example()
    device = next(d for d in loaded.config.devices if d.id == DEVICE)
    info = DeviceInfo(
        id=device.id,
        name=device.display_name,
        mapping=loaded.mappings[device.id],
        options=dict(device.options),
        bus=device.bus,
        unit=device.unit,
        allow_dangerous_writes=device.allow_dangerous_writes,
        fast_interval=device.poll.fast,
        slow_interval=device.poll.slow,
    )
    base = loaded.config.mqtt.base_topic
    topics = Topics(base, loaded.config.mqtt.discovery_prefix)
    messages = build_discovery(info, topics, Origin(), mode="device")
    messages += build_bridge_discovery(topics, Origin(), base)  # as Bridge.run() does
    components = {}
    for message in messages:
        for component in json.loads(message.payload)["cmps"].values():
            if component["platform"] != "device_automation":  # a trigger is no entity
                components[component["default_entity_id"]] = component
    return components


# --- Home Assistant dashboard -----------------------------------------------------------------


def _strings(node: object) -> Iterator[str]:
    if isinstance(node, str):
        yield node
    elif isinstance(node, dict):
        for value in node.values():
            yield from _strings(value)
    elif isinstance(node, list):
        for item in node:
            yield from _strings(item)


def _cards(node: object) -> Iterator[dict[str, Any]]:
    if isinstance(node, dict):
        if "type" in node:
            yield node
        for value in node.values():
            yield from _cards(value)
    elif isinstance(node, list):
        for item in node:
            yield from _cards(item)


def _card_entities(card: dict[str, Any]) -> list[str]:
    rows = [card["entity"]] if "entity" in card else []
    for row in card.get("entities", []):
        if isinstance(row, str):
            rows.append(row)
        elif "entity" in row:
            rows.append(row["entity"])
    return rows


def _dashboard() -> dict[str, Any]:
    return yaml.safe_load(DASHBOARD.read_text(encoding="utf-8"))


def test_dashboard_uses_only_entities_the_discovery_creates() -> None:
    components = _components()
    used = {match for text in _strings(_dashboard()) for match in ENTITY_ID.findall(text)}
    assert used, "the dashboard names no entity"
    for entity_id in sorted(used):
        assert entity_id in components, f"{entity_id}: not created by the bridge's discovery"
        component = components[entity_id]
        assert entity_id.split(".")[0] == component["platform"], entity_id
        assert component["enabled_by_default"], f"{entity_id} is disabled by default"


def test_dashboard_cards() -> None:
    dashboard = _dashboard()
    [view] = dashboard["views"]
    cards = list(_cards(view["cards"]))
    kinds = {card["type"] for card in cards}
    assert {"gauge", "entities", "history-graph", "conditional"} <= kinds
    components = _components()
    gauges = {card["entity"] for card in cards if card["type"] == "gauge"}
    assert gauges == {
        "sensor.borehole_pump_actual_value",
        "sensor.borehole_pump_motor_current",
        "sensor.borehole_pump_power",
    }
    for entity_id in gauges:  # a gauge needs a numeric sensor
        assert components[entity_id].get("state_class") == "measurement", entity_id
        assert components[entity_id].get("device_class") != "enum", entity_id
    shown = {entity for card in cards for entity in _card_entities(card)}
    controls = {"switch.borehole_pump_start_stop", "number.borehole_pump_set_value"}
    status = {"sensor.borehole_pump_status", "sensor.borehole_pump_alarms"}
    assert controls | status | {"binary_sensor.modbus_connection_state"} <= shown
    for entity_id in controls:
        assert components[entity_id]["command_topic"].startswith(f"modbus/{DEVICE}/")


# --- Node-RED flow ----------------------------------------------------------------------------


def _flow() -> list[dict[str, Any]]:
    flow = json.loads(FLOW.read_text(encoding="utf-8"))
    assert isinstance(flow, list)
    assert all(isinstance(node, dict) and {"id", "type"} <= set(node) for node in flow)
    return flow


def _of_type(flow: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [node for node in flow if node["type"] == kind]


def test_flow_is_an_importable_node_red_flow() -> None:
    flow = _flow()
    ids = [node["id"] for node in flow]
    assert len(ids) == len(set(ids)), "node ids must be unique"
    [tab] = _of_type(flow, "tab")
    [broker] = _of_type(flow, "mqtt-broker")
    assert (broker["broker"], broker["port"]) == ("localhost", "1883")
    known = set(ids)
    for node in flow:
        if node["type"] in ("tab", "mqtt-broker"):
            continue  # the tab and config nodes belong to no tab
        assert node["z"] == tab["id"], node["id"]
        for output in node.get("wires", []):
            for target in output:
                assert target in known, f"{node['id']} is wired to a missing node {target}"
        if node["type"] in ("mqtt in", "mqtt out"):
            assert node["broker"] == broker["id"], node["id"]
    # Core nodes only: importable without installing anything (no node-red-dashboard).
    core = {"tab", "mqtt-broker", "mqtt in", "mqtt out", "inject", "function", "debug"}
    assert {node["type"] for node in flow} <= core | {"comment"}


def test_flow_subscribes_to_topics_the_bridge_publishes() -> None:
    flow = _flow()
    subscribed = {node["topic"]: node["datatype"] for node in _of_type(flow, "mqtt in")}
    assert subscribed[TOPICS.device(DEVICE)] == "json"
    assert subscribed[TOPICS.availability(DEVICE)] == "utf8"
    assert subscribed[TOPICS.error(DEVICE)] == "json"
    assert set(subscribed) == {
        TOPICS.device(DEVICE),
        TOPICS.availability(DEVICE),
        TOPICS.error(DEVICE),
    }


def test_flow_functions_read_keys_of_the_state_document() -> None:
    state_keys = {*published(_points()), "status", "alarms"}
    [summary] = [
        node for node in _of_type(_flow(), "function") if node["name"] == "Summarise state"
    ]
    used = set(re.findall(r"\bs\.([a-z_0-9]+)", summary["func"]))
    assert {"status", "alarms", "actual_value", "start_stop"} <= used
    assert used <= state_keys, used - state_keys


def _sent_payload(inject: dict[str, Any]) -> bytes:
    """The bytes Node-RED's mqtt out publishes for an inject node's payload."""
    kind, text = inject["payloadType"], inject["payload"]
    if kind == "json":  # parsed to an object, sent as JSON.stringify(object)
        return json.dumps(json.loads(text), separators=(",", ":")).encode()
    if kind == "num":  # a Number, sent as its string
        float(text)
        return text.encode()
    assert kind == "str", kind
    return text.encode()


def _commands() -> Iterator[tuple[str, bytes]]:
    """(topic, payload) of every message the flow publishes."""
    flow = _flow()
    by_id = {node["id"]: node for node in flow}
    fed = set()
    for inject in _of_type(flow, "inject"):
        assert inject["props"] == [{"p": "payload"}], inject["id"]  # the out node's topic
        for target in (t for output in inject["wires"] for t in output):
            out = by_id[target]
            assert out["type"] == "mqtt out", inject["id"]
            fed.add(out["id"])
            yield out["topic"], _sent_payload(inject)
    assert fed == {node["id"] for node in _of_type(flow, "mqtt out")}


def test_flow_commands_are_never_retained() -> None:
    for out in _of_type(_flow(), "mqtt out"):
        assert out["retain"] == "false", out["id"]
        assert out["topic"], out["id"]


def test_flow_commands_are_accepted_by_the_bridge() -> None:
    points = _points()
    image = {(p.table, address): 0 for p in points.values() for address in p.span}
    sent: dict[str, list[object]] = {}
    for topic, payload in _commands():
        target = TOPICS.parse_command(topic)
        assert target is not None, topic
        assert target.device_id == DEVICE, topic
        if target.action is Action.GET:
            keys = parse_get(payload)  # the bridge refuses a get of an unknown key
            assert keys is None or set(keys) <= set(published(points)), keys
            continue
        for key, value in parse_set(payload, target.key).items():
            point = points.get(key)
            assert point is not None, f"{topic}: no entity {key!r}"
            assert point.entity.writable, key
            assert not point.entity.dangerous, f"{key}: refused without allow_dangerous_writes"
            assert encode(point, value, image), (key, value)  # type, range, enum: accepted
            sent.setdefault(key, []).append(value)
    assert set(sent) == {"set_value", "start_stop"}
    assert set(sent["start_stop"]) == {"ON", "OFF"}
