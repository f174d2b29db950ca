"""Validate the discovery snapshots with Home Assistant's own MQTT discovery code.

Not run by the test suite: Home Assistant is a large install that needs Python 3.13+.
Run it with the Python of a virtualenv that has Home Assistant:

    python3.13 -m venv /tmp/havenv && /tmp/havenv/bin/pip install homeassistant
    /tmp/havenv/bin/python tools/check_ha_discovery.py [tests/golden/discovery/X.json ...]

For each snapshot (default: every file in tests/golden/discovery/) it checks:
- a device payload against DEVICE_DISCOVERY_SCHEMA (device, origin, availability, cmps
  with platform and unique_id), and the discovery topic against HA's topic pattern;
- every component, merged the way HA merges a device payload (device, origin and the
  shared options copied in), against its platform's DISCOVERY_SCHEMA: the device_class,
  unit, state_class and options combinations of sensors, number min/max, text length...;
- options HA would silently drop (its discovery schemas remove unknown keys);
- rules HA applies only when the entity is added: entity_category config on a sensor,
  sensor state_class vs device_class, number unit vs device_class, the domain of
  default_entity_id, unique_id collisions, via_device naming the bridge device;
- every value_template, rendered by HA's template engine on a sample state document,
  gives a state the component accepts (payload_on/off, an option, a number in range).
With ``--states [PYTHON]`` it also checks each shipped mapping's states at the extremes
(raw 0, every bit set, 0x8000, the manual's min and max; ``tests/extreme_states.py``, run
by the bridge's Python, default ``.venv/bin/python``): every discovery payload published
with them against the schemas, and every state as Home Assistant takes it: the component's
value_template rendered by HA's template engine on the state document, then the state
accepted (a number in range, an option, a number for a measurement, a payload).

    /tmp/havenv/bin/python tools/check_ha_discovery.py --states .venv/bin/python

``--states-from FILE`` reads those cases from a file written by ``python -m
tests.extreme_states`` instead (``tools/ha_check.sh`` runs the tool in the chroot of
``make test-ha``, where the bridge's Python is out of reach).

Exit status 1 when anything is wrong; each problem is printed as ``file: key: message``.
"""

from __future__ import annotations

import asyncio
import importlib
import json
import math
import re
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

try:  # Home Assistant validates with probatio since 2026.3, with voluptuous before
    import probatio as schema_lib  # type: ignore[import-not-found]
except ImportError:
    import voluptuous as schema_lib  # type: ignore[import-not-found, no-redef]

from homeassistant.components.mqtt import const as mqtt_const  # type: ignore[import-not-found]
from homeassistant.components.mqtt import (  # type: ignore[import-not-found]
    device_automation,
    device_trigger,
    discovery,
    schemas,
)
from homeassistant.components.number import const as number_const  # type: ignore[import-not-found]
from homeassistant.components.sensor import DEVICE_CLASS_STATE_CLASSES  # type: ignore[import-not-found]
from homeassistant.const import __version__ as ha_version  # type: ignore[import-not-found]
from homeassistant.core import HomeAssistant  # type: ignore[import-not-found]
from homeassistant.helpers.template import Template  # type: ignore[import-not-found]

# A write-only select's state: an option by the label its link reads, else none
# (discovery_entity.command_state_template).
_LINKED = re.compile(r"^\{% set s = value_json\.(\w+) %\}\{\{ (\{.*\})\.get\(s\) \}\}$")
_NO_STATE = "{{ none }}"
_NESTED = re.compile(r"value_json\.get\('(\w+)', \{\}\)\.get\('([^']+)', \{\}\)\.get\('(\w+)'\)")
GOLDEN = Path(__file__).resolve().parent.parent / "tests" / "golden" / "discovery"
PREFIX = "homeassistant"
READ_ONLY = ("sensor", "binary_sensor")
# default_entity_id came with Home Assistant 2025.10; older versions drop it (and derive
# the entity id from the names), which is expected, so it is reported once, not per entity.
KNOWS_DEFAULT_ENTITY_ID = hasattr(mqtt_const, "CONF_DEFAULT_ENTITY_ID")


class Checker:
    def __init__(self, hass: HomeAssistant) -> None:
        self.hass = hass
        self.problems: list[str] = []
        self.unique_ids: Counter[tuple[str, str]] = Counter()
        self.via_devices: set[str] = set()
        self.identifiers: set[str] = set()
        self.components = 0

    def problem(self, where: str, message: str) -> None:
        self.problems.append(f"{where}: {message}")

    def check_file(self, path: Path) -> None:
        data = json.loads(path.read_text(encoding="utf-8"))
        if isinstance(data, list):  # entity mode: [{topic, retain, payload}]
            for message in data:
                self.check_entity_message(path.name, message)
        else:
            self.check_device_payload(path.name, f"{PREFIX}/device/{path.stem}/config", data)

    def check_topic(self, where: str, topic: str) -> None:
        if not discovery.TOPIC_MATCHER.match(topic.removeprefix(f"{PREFIX}/")):
            self.problem(where, f"HA does not accept the discovery topic {topic!r}")

    def check_device_payload(self, where: str, topic: str, payload: dict[str, Any]) -> None:
        self.check_topic(where, topic)
        payload = json.loads(json.dumps(payload))
        discovery._replace_all_abbreviations(payload)  # "cmps" is short for "components"
        try:
            validated = schemas.DEVICE_DISCOVERY_SCHEMA(json.loads(json.dumps(payload)))
            validate = getattr(schemas, "validate_device_discovery_components", None)
            if validate is not None:
                validate(validated)
        except schema_lib.Invalid as exc:
            self.problem(where, f"device payload refused: {exc}")
            return
        self.identifiers.update(payload["device"].get("identifiers", []))
        if "via_device" in payload["device"]:
            self.via_devices.add(payload["device"]["via_device"])
        shared = {k: payload[k] for k in schemas.SHARED_OPTIONS if k in payload}
        for key, component in payload["components"].items():
            config = {k: v for k, v in component.items() if k != "platform"}
            config = {"device": payload["device"], "origin": payload["origin"]} | config
            for option, value in shared.items():
                config.setdefault(option, value)
            self.check_component(f"{where}: {key}", component["platform"], config)

    def check_entity_message(self, where: str, message: dict[str, Any]) -> None:
        topic = message["topic"]
        self.check_topic(where, topic)
        platform = topic.removeprefix(f"{PREFIX}/").split("/")[0]
        if not message.get("retain"):
            self.problem(f"{where}: {topic}", "discovery configs are retained")
        self.check_component(f"{where}: {topic}", platform, message["payload"])

    def check_component(self, where: str, platform: str, config: dict[str, Any]) -> None:
        self.components += 1
        if platform == "device_automation":
            self.check_trigger(where, config)
            return
        module = importlib.import_module(f"homeassistant.components.mqtt.{platform}")
        try:
            validated = module.DISCOVERY_SCHEMA(json.loads(json.dumps(config)))
        except schema_lib.Invalid as exc:
            self.problem(where, f"{platform} refused: {exc}")
            return
        dropped = sorted(set(config) - set(validated))
        if not KNOWS_DEFAULT_ENTITY_ID and "default_entity_id" in dropped:
            dropped.remove("default_entity_id")
            validated["default_entity_id"] = config["default_entity_id"]
        if dropped:
            self.problem(where, f"{platform} ignores {', '.join(dropped)}")
        self.check_entity_rules(where, platform, validated)
        self.check_template(where, platform, validated)

    def check_trigger(self, where: str, config: dict[str, Any]) -> None:
        """A device trigger: the automation type's schema lets anything through, the
        trigger's own schema (mqtt/device_trigger.py) is what Home Assistant applies."""
        try:
            device_automation.DISCOVERY_SCHEMA(json.loads(json.dumps(config)))
            validated = device_trigger.TRIGGER_DISCOVERY_SCHEMA(json.loads(json.dumps(config)))
        except schema_lib.Invalid as exc:
            self.problem(where, f"device trigger refused: {exc}")
            return
        # the device payload's shared options reach every component; a trigger has no use
        # for availability and its schema drops it (as Home Assistant does)
        shared = {*schemas.SHARED_OPTIONS, "origin", "device"}
        dropped = sorted(set(config) - set(validated) - shared)
        if dropped:
            self.problem(where, f"device trigger ignores {', '.join(dropped)}")
        key = (str(validated["type"]), str(validated["subtype"]))
        self.unique_ids[("device_trigger", f"{where.split(':', 1)[0]} {key}")] += 1

    def check_entity_rules(self, where: str, platform: str, config: dict[str, Any]) -> None:
        self.unique_ids[(platform, str(config.get("unique_id")))] += 1
        category = config.get("entity_category")
        if platform in READ_ONLY and category is not None and str(category) == "config":
            self.problem(where, f"a {platform} cannot have entity_category config")
        domain = str(config.get("default_entity_id", f"{platform}.")).partition(".")[0]
        if domain != platform:
            self.problem(where, f"default_entity_id is in domain {domain}, not {platform}")
        if "object_id" in config:
            self.problem(where, "object_id is deprecated: use default_entity_id")
        device_class = config.get("device_class")
        state_class = config.get("state_class")
        if platform == "sensor" and device_class and state_class:
            allowed = DEVICE_CLASS_STATE_CLASSES.get(device_class)
            if allowed is not None and state_class not in allowed:
                self.problem(where, f"state_class {state_class} impossible for {device_class}")
        if platform == "number" and device_class:
            units = number_const.DEVICE_CLASS_UNITS.get(device_class)
            unit = config.get("unit_of_measurement")
            if units is not None and unit not in units:
                self.problem(where, f"number unit {unit!r} is not one of {device_class}'s")

    def check_template(self, where: str, platform: str, config: dict[str, Any]) -> None:
        if "value_template" not in config:
            return
        text = config["value_template"].template
        for sample in _samples(platform, config):
            document = _document(text, sample)
            rendered = Template(text, self.hass).async_render_with_possible_json_value(
                json.dumps(document), ""
            )
            message = _refusal(platform, config, str(rendered), sample)
            if message:
                self.problem(where, f"{text} on {sample!r} renders {rendered!r}: {message}")

    def check_state_case(self, case: dict[str, Any], seen: set[str]) -> None:
        """One extreme case: its discovery payload (schemas, once per distinct payload)
        and every component's state rendered from its state document."""
        where = case["name"]
        payload = json.dumps(case["discovery"], sort_keys=True)
        if payload not in seen:
            seen.add(payload)
            problems = len(self.problems)
            self.check_device_payload(where, f"{PREFIX}/device/extremes/config", case["discovery"])
            if len(self.problems) > problems:
                return
            self.unique_ids.clear()
        for key, component in case["discovery"]["cmps"].items():
            if "value_template" not in component or component["platform"] == "device_automation":
                continue  # a trigger reads the event topic, not the state
            config = {k: v for k, v in component.items() if k != "platform"}
            module = importlib.import_module(
                f"homeassistant.components.mqtt.{component['platform']}"
            )
            validated = module.DISCOVERY_SCHEMA(config | {"device": case["discovery"]["device"]})
            rendered = Template(validated["value_template"].template, self.hass)
            text = str(
                rendered.async_render_with_possible_json_value(json.dumps(case["state"]), "")
            )
            message = _state_refusal(component["platform"], validated, text)
            if message:
                self.problem(f"{where}: {key}", f"state {text!r}: {message}")

    def finish(self) -> None:
        for (platform, unique_id), count in self.unique_ids.items():
            if count > 1:
                self.problem("all", f"{platform} unique_id {unique_id} used {count} times")
        for via in sorted(self.via_devices - self.identifiers):
            self.problem("all", f"via_device {via!r} names no device of the snapshots")


def _document(template: str, sample: Any) -> dict[str, Any]:
    """A state document holding ``sample`` where ``template`` reads: a device's flat JSON
    (``value_json.key``), or the bridge/health report (``value_json.get('buses', {}).get('id',
    {}).get('field')``)."""
    if template == _NO_STATE:
        return {"status": sample, "alarms": []}
    nested = _NESTED.search(template)
    if nested is not None:
        section, name, field = nested.groups()
        return {section: {name: {field: sample}}}
    key = template.split("value_json.")[1].split(maxsplit=1)[0].rstrip("|")
    return {key: sample, "alarms": ["fault_a", "fault_b"]}


def _samples(platform: str, config: dict[str, Any]) -> list[Any]:
    """Values the state document may hold for a component (null = unknown)."""
    template = config["value_template"].template
    if "* 100" in template:
        return [0.25, 1.0]  # a fraction the report always holds (bus utilisation)
    if linked := _LINKED.match(template):  # the labels it shows, one it does not, unknown
        return [*json.loads(linked.group(2)), "a_label_not_linked", None]
    if template == _NO_STATE:
        return [config["options"][0], None]
    if platform in ("binary_sensor", "switch"):
        return [True, False, None]
    if config.get("options"):
        return [config["options"][0], None]
    if platform == "number":
        return [config["min"], config["max"], None]
    if platform == "text":
        return ["ABC", None]
    if config.get("unit_of_measurement") or config.get("state_class"):
        return [12.5, None]
    return ["ABC", 7, None]


def _refusal(platform: str, config: dict[str, Any], rendered: str, sample: Any) -> str | None:
    """Why the component would refuse the rendered state (None when it is accepted)."""
    if "in value_json.alarms" in config["value_template"].template:  # Active alarms by name
        ok = rendered in ("Fault a, Fault b", "fault_a, fault_b")
        return None if ok else "expected the joined alarm names"
    template = config["value_template"].template
    if sample is None or template == _NO_STATE:
        ok = rendered in ("None", "") if platform != "text" else rendered == ""
        return None if ok else "unknown must render None (or '' for text)"
    if linked := _LINKED.match(template):
        shown = json.loads(linked.group(2)).get(sample)
        return None if rendered == str(shown) else f"not the option linked ({shown})"
    if platform == "binary_sensor":
        ok = rendered in (config["payload_on"], config["payload_off"])
        return None if ok else "neither payload_on nor payload_off"
    if platform == "switch":
        ok = rendered in (config.get("state_on"), config.get("state_off"))
        return None if ok else "neither state_on nor state_off"
    if config.get("options"):
        return None if rendered in config["options"] else "not one of the options"
    if platform == "number":
        return None if config["min"] <= float(rendered) <= config["max"] else "out of range"
    if "* 100" in config["value_template"].template:  # a fraction shown in percent
        return None if float(rendered) == round(sample * 100, 1) else "not the percentage"
    return None if rendered == str(sample) else "changed on the way"


def _state_refusal(platform: str, config: dict[str, Any], text: str) -> str | None:
    """Why Home Assistant drops this rendered state (None: it takes it). The rules are
    those of its MQTT platforms: sensor (an enum's options, a number where a unit, state
    or device class says so), number (min..max), select (options), binary_sensor and
    switch (their payloads), text (max length)."""
    if text in ("None", "") and platform != "text":
        return None  # unknown
    if platform == "binary_sensor":
        return None if text in (config["payload_on"], config["payload_off"]) else "no payload"
    if platform == "switch":
        return None if text in (config.get("state_on"), config.get("state_off")) else "no state"
    if config.get("options"):
        return None if text in config["options"] else "not one of the options"
    if platform == "number":
        return None if config["min"] <= float(text) <= config["max"] else "out of range"
    if platform == "text":
        return None if len(text) <= config["max"] else "longer than max"
    if platform == "sensor" and (
        config.get("unit_of_measurement") or config.get("state_class") or config.get("device_class")
    ):
        try:
            return None if math.isfinite(float(text)) else "not a finite number"
        except ValueError:
            return "not a number (HA expects a numeric state)"
    return None


def _extreme_cases(python: str) -> list[dict[str, Any]]:
    """The cases of tests/extreme_states.py, computed by the bridge's own Python (or read
    from the file they were written to: ``--states-from FILE``)."""
    if python.endswith(".json"):
        cases_read: list[dict[str, Any]] = json.loads(Path(python).read_text(encoding="utf-8"))
        return cases_read
    root = Path(__file__).resolve().parent.parent
    command = [python, "-m", "tests.extreme_states"]  # the bridge's Python, named by the user
    done = subprocess.run(command, cwd=root, capture_output=True, check=True)  # noqa: S603
    cases: list[dict[str, Any]] = json.loads(done.stdout)
    return cases


async def main(paths: list[Path], states: str | None = None) -> int:
    hass = HomeAssistant(tempfile.mkdtemp(prefix="check_ha_discovery"))
    checker = Checker(hass)
    cases = _extreme_cases(states) if states is not None else []
    try:
        for path in paths:
            checker.check_file(path)
        checker.finish()
        seen: set[str] = set()
        for case in cases:
            checker.check_state_case(case, seen)
    finally:
        await hass.async_stop(force=True)
    for line in checker.problems:
        print(line)
    if not KNOWS_DEFAULT_ENTITY_ID:
        print(f"note: Home Assistant {ha_version} ignores default_entity_id (added in 2025.10)")
    extremes = f", {len(cases)} extreme state cases" if states is not None else ""
    print(
        f"Home Assistant {ha_version}: {len(paths)} files, {checker.components} components"
        f"{extremes}, {len(checker.problems)} problems"
    )
    return 1 if checker.problems else 0


if __name__ == "__main__":
    arguments = sys.argv[1:]
    python: str | None = None
    if "--states" in arguments:
        at = arguments.index("--states")
        following = arguments[at + 1 : at + 2]
        given = bool(following) and not following[0].endswith(".json")
        python = following[0] if given else ".venv/bin/python"
        del arguments[at : at + 1 + given]
    if "--states-from" in arguments:  # the cases as `python -m tests.extreme_states` wrote them
        at = arguments.index("--states-from")
        python = arguments[at + 1]
        del arguments[at : at + 2]
    files = [Path(a) for a in arguments] or sorted(GOLDEN.glob("*.json"))
    sys.exit(asyncio.run(main(files, python)))
