"""What the page may change of a device (bridge/web/edit_request.py): the body read whole
and strictly, what dangerous writes permit, one-time confirmations."""

from __future__ import annotations

import json
from http import HTTPStatus
from typing import Any

import pytest

from bridge.core.mapping import builtin_mapping_path, load_mapping
from bridge.web import edit_request
from bridge.web.config_file import ConfigChangeError
from bridge.web.edit_request import Confirmations, dangerous_entities, parse_edit


@pytest.mark.parametrize(
    ("body", "fields"),
    [
        ({"name": "Well pump"}, {"name": "Well pump"}),
        ({"name": ""}, {"name": None}),  # the default name again
        ({"name": None}, {"name": None}),
        ({"id": "well", "unit": 4}, {"id": "well", "unit": 4}),
        ({"poll": {"fast": 1}}, {"poll.fast": 1}),
        ({"poll": {"slow": "2min", "fast": 0.5}}, {"poll.fast": 0.5, "poll.slow": "2min"}),
        ({"enabled": False}, {"enabled": False}),
        ({"allow_dangerous_writes": True, "confirmation": "t"}, {"allow_dangerous_writes": True}),
    ],
)
def test_an_edit_becomes_the_store_s_fields(body: dict[str, Any], fields: dict[str, Any]) -> None:
    edit = parse_edit(json.dumps(body).encode())
    assert edit.fields == fields
    assert isinstance(edit.fields.get("poll.fast", 1), type(body.get("poll", {}).get("fast", 1)))


@pytest.mark.parametrize(
    ("body", "said"),
    [
        (b"", "not JSON"),
        (b"{", "not JSON"),
        (b"null", "send a JSON object"),
        (b"{}", "nothing to change"),
        (b'{"confirmation": "t"}', "nothing to change"),
        (b'{"unit": 0}', "unit: Input should be greater than or equal to 1"),
        (b'{"unit": 256}', "unit: Input should be less than or equal to 255"),
        (b'{"unit": "1"}', "unit: Input should be a valid integer"),
        (b'{"unit": 1.0}', "unit: Input should be a valid integer"),
        (b'{"enabled": 1}', "enabled: Input should be a valid boolean"),
        (b'{"name": "' + b"n" * 101 + b'"}', "name: String should have at most 100 characters"),
        (b'{"id": ""}', "id: String should have at least 1 character"),
        (b'{"poll": {"fast": true}}', "poll.fast: seconds (a number above 0) or a duration"),
        (b'{"poll": {"fast": 0}}', "poll.fast: seconds (a number above 0) or a duration"),
        (b'{"poll": {"fast": "' + b"1" * 40 + b'"}}', "poll.fast: seconds"),
        (b'{"poll": {"fast": null}}', "poll: give fast and slow a value"),
        (b'{"poll": {"entities": {}}}', "poll.entities: not a field the page changes"),
        (b'{"mapping": "x"}', "mapping: not a field the page changes"),
        (b'{"bridge": {"allow_raw_writes": true}}', "bridge: not a field the page changes"),
        (b'{"gateway_raw_writes": true}', "gateway_raw_writes: not a field the page changes"),
        (b'{"password": "1234"}', "password: not a field the page changes"),
    ],
)
def test_an_edit_is_refused_naming_its_field(body: bytes, said: str) -> None:
    with pytest.raises(ConfigChangeError) as refused:
        parse_edit(body)
    assert refused.value.status == HTTPStatus.BAD_REQUEST
    assert str(refused.value).startswith(said), str(refused.value)


def test_what_dangerous_writes_permit_by_the_names_home_assistant_shows() -> None:
    drive = load_mapping(builtin_mapping_path("vacon_nx"))
    assert dangerous_entities(drive, "Drive") == [
        {"key": "reverse", "name": "Reverse direction", "component": "switch",
         "permits": "any value", "shown": True},
        {"key": "speed_reference", "name": "Speed reference", "component": "number",
         "permits": "values below 0", "shown": True},
        {"key": "fieldbus_fault_response", "name": "Response to fieldbus fault",
         "component": "select", "permits": "any value", "shown": True},
        {"key": "slot_fault_response", "name": "Response to slot fault",
         "component": "select", "permits": "any value", "shown": True},
    ]  # fmt: skip
    pump = dangerous_entities(load_mapping(builtin_mapping_path("nastec_vasco")), "Pump")
    secret = [e["name"] for e in pump if not e["shown"]]
    assert secret and all(n.startswith("Password") for n in secret)  # named, never shown in HA
    assert dangerous_entities(None, "x") == []


DANGER = {"allow_dangerous_writes": True}


def test_a_confirmation_confirms_one_change_of_one_device_once() -> None:
    confirmations = Confirmations()
    token = confirmations.issue("drive", DANGER)
    assert not confirmations.take(None, "drive", DANGER)
    assert confirmations.take(token, "drive", dict(DANGER))
    assert not confirmations.take(token, "drive", DANGER)  # once
    other = confirmations.issue("drive", DANGER)
    assert not confirmations.take(other, "pump", DANGER)  # another device: spent too
    changed = confirmations.issue("drive", DANGER)
    assert not confirmations.take(changed, "drive", DANGER | {"unit": 5})


def test_a_confirmation_expires(monkeypatch: pytest.MonkeyPatch) -> None:
    confirmations = Confirmations()
    monkeypatch.setattr(edit_request, "CONFIRM_FOR", 0.0)
    token = confirmations.issue("drive", DANGER)
    assert not confirmations.take(token, "drive", DANGER)


def test_confirmations_waiting_are_bounded() -> None:
    confirmations = Confirmations()
    tokens = [confirmations.issue(f"d{i}", DANGER) for i in range(edit_request.MAX_PENDING + 1)]
    assert not confirmations.take(tokens[0], "d0", DANGER)  # the oldest dropped
    assert confirmations.take(tokens[-1], f"d{edit_request.MAX_PENDING}", DANGER)
