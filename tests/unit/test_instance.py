"""Who a running bridge is, and who else holds its base topic (bridge/core/instance.py)."""

from __future__ import annotations

import json

import pytest

from bridge.core.instance import (
    MAX_INFO,
    Instance,
    answering_instance,
    instance_of,
    taken_message,
)

ONE = Instance("a1b2c3d4e5f6", "nas", 42, 1_800_000_000.5)


def test_a_new_instance_names_this_process() -> None:
    first, second = Instance.new(1.0), Instance.new(1.0)
    assert first.id != second.id and len(first.id) == 12
    assert first.pid == second.pid and first.host == second.host


def test_the_document_reads_back() -> None:
    info = json.dumps({"version": "x", "instance": ONE.document()}).encode()
    assert instance_of(info) == ONE
    answer = json.dumps({"status": "ok", "data": {"instance": ONE.document()}}).encode()
    assert answering_instance(answer) == ONE


@pytest.mark.parametrize(
    "payload",
    [
        None,
        b"",
        b"online",
        b"[1, 2]",
        b"{}",
        b'{"instance": null}',
        b'{"instance": []}',
        b'{"instance": {"id": "x", "host": "h", "pid": 1}}',
        b'{"instance": {"id": 5, "host": "h", "pid": 1, "started": 1}}',
        b'{"instance": {"id": "x", "host": "h", "pid": true, "started": 1}}',
        b'{"instance": {"id": "x", "host": "h", "pid": 1, "started": false}}',
        b'{"instance": {"id": "x", "host": "h", "pid": 1.5, "started": 1}}',
        b"[" * 100_000 + b"]" * 100_000,  # nested beyond the recursion limit
        b'{"instance": {"id": "x", "host": "' + b"h" * MAX_INFO + b'", "pid": 1, "started": 1}}',
        b"\xff\xfe",
    ],
)
def test_anything_else_names_no_instance(payload: bytes | None) -> None:
    assert instance_of(payload) is None
    assert answering_instance(payload) is None


def test_long_fields_are_cut() -> None:
    info = {"instance": {"id": "i" * 500, "host": "h" * 500, "pid": 1, "started": 2}}
    found = instance_of(json.dumps(info).encode())
    assert found is not None and len(found.id) == 64 and len(found.host) == 253


@pytest.mark.parametrize(
    ("mine", "theirs", "yields"),
    [
        (10.0, 5.0, True),  # the other started first: this one stands by
        (5.0, 10.0, False),
        (5.0, 5.0, True),  # a tie: the id decides ("b..." after "a...")
    ],
)
def test_the_later_one_yields(mine: float, theirs: float, yields: bool) -> None:
    me = Instance("bbbbbbbbbbbb", "h1", 1, mine)
    other = Instance("aaaaaaaaaaaa", "h2", 2, theirs)
    assert me.yields_to(other) is yields
    assert other.yields_to(me) is not yields  # both come to the same answer


def test_the_message_names_the_other_and_what_to_do() -> None:
    said = taken_message("modbus", ONE, 10)
    assert "'modbus'" in said and "a1b2c3d4e5f6" in said and "'nas'" in said
    assert "process 42" in said and "2027-01-15T08:00:00+00:00" in said
    assert "docker stop" in said and "mqtt.base_topic" in said and "every 10 s" in said
    assert "does not name itself" in taken_message("modbus", None, 10)
