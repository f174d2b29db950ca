"""Every shipped mapping's states at the extremes (raw 0, every bit set, 0x8000, the
manual's min and max) are states its discovery payload accepts: Home Assistant drops a
number out of range, an enum state that is no option, a non-numeric measurement. The
same cases go through Home Assistant itself with ``tools/check_ha_discovery.py --states``
(see README, Home Assistant)."""

from __future__ import annotations

import json
import math
import re
from typing import Any

import pytest

from bridge.core.discovery_entity import TEXT_MAX
from bridge.core.mapping import builtin_mapping_names
from tests.extreme_states import Case, cases

_PLAIN = re.compile(r"^\{\{ value_json\.(\w+) \}\}$")
_TEXT = re.compile(r"^\{\{ value_json\.(\w+) if value_json\.\1 is not none else '' \}\}$")
_LINKED = re.compile(r"^\{% set s = value_json\.(\w+) %\}\{\{ (\{.*\})\.get\(s\) \}\}$")
_ALARMS = re.compile(
    r"^\{% set n = (\{.*\}) %\}\{% set text %\}\{% for k in value_json\.alarms %\}"
)


def rendered(template: str, state: dict[str, Any]) -> str:
    """What Home Assistant's template renders for the bridge's templates (Jinja prints
    Python values: None, True, 12.5)."""
    if match := _ALARMS.match(template):  # discovery_alarms.alarms_template
        names = json.loads(match.group(1))
        shown = [names.get(k, k.replace("_", " ").capitalize()) for k in state["alarms"]]
        return (", ".join(shown) or "none")[:TEXT_MAX]
    if template == "{{ none }}":  # a write-only select without a state link
        return "None"
    if match := _LINKED.match(template):  # discovery_entity.command_state_template
        return str(json.loads(match.group(2)).get(state[match.group(1)]))
    if match := _TEXT.match(template):
        value = state[match.group(1)]
        return "" if value is None else str(value)
    match = _PLAIN.match(template)
    assert match, f"a template this test does not know: {template}"
    return str(state[match.group(1)])


def refusal(platform: str, config: dict[str, Any], text: str) -> str | None:
    """Why Home Assistant would drop this state (None: it takes it)."""
    if text in ("None", "") and platform != "text":
        return None  # unknown
    if platform == "binary_sensor":
        return None if text in (config["payload_on"], config["payload_off"]) else "no payload"
    if platform == "switch":
        return None if text in (config["state_on"], config["state_off"]) else "no state"
    if "options" in config:
        return None if text in config["options"] else f"{text!r} is not an option"
    if platform == "number":
        number = float(text)
        return None if config["min"] <= number <= config["max"] else "out of range"
    if platform == "text":
        return None if len(text) <= config["max"] else "too long"
    numeric = any(k in config for k in ("unit_of_measurement", "state_class", "device_class"))
    if numeric:
        try:
            return None if math.isfinite(float(text)) else "not finite"
        except ValueError:
            return f"{text!r} is not a number"
    return None


def problems(case: Case) -> list[str]:
    json.dumps(case.state, allow_nan=False)
    found = []
    for key, config in case.discovery["cmps"].items():
        if "value_template" not in config or config["platform"] == "device_automation":
            continue  # a device trigger reads the event topic, not the state
        text = rendered(config["value_template"], case.state)
        why = refusal(config["platform"], config, text)
        if why:
            found.append(f"{case.name}: {key}: {why}")
    return found


@pytest.mark.parametrize("name", builtin_mapping_names())
def test_every_extreme_state_is_accepted_by_its_discovery(name: str) -> None:
    found = [problem for case in cases(name) for problem in problems(case)]
    assert found == []


def test_the_extremes_reach_what_home_assistant_would_drop() -> None:
    """The cases are not vacuous: a parameter reading 0 below its range, a code without a
    label, a negative reference, each state shown and admitted."""
    by_name = {case.name: case for case in cases("nastec_vasco")}
    zero = by_name["nastec_vasco[family=vasco,pv_input=absent,register_9f=pcb_temperature]"
                   "[dangerous=False] raw 0"]  # fmt: skip
    assert zero.state["ramp_up_time"] == 0
    ramp = zero.discovery["cmps"]["ramp_up_time"]
    assert (ramp["min"], ramp["max"]) == (0, 300.0)  # the manual's 1.0-300.0, and 0
    full = {c.name: c for c in cases("soft_starter")}
    top = next(c for n, c in full.items() if n.endswith("[dangerous=False] raw max"))
    assert top.state["fault_status"] == "code_65535"
    assert "code_65535" in top.discovery["cmps"]["fault_status"]["options"]
    assert "fault_status_65535" in top.state["alarms"]
    p2 = next(c for c in cases("p2_vfd") if c.name.endswith("[dangerous=False] raw max"))
    assert p2.state["set_value"] == -0.01  # 0xFFFF: a reverse reference, shown
    assert p2.discovery["cmps"]["set_value"]["min"] == -0.01
