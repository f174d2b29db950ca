"""``coalesce``: the packets paho queued go out in one send where nothing is due once each
is written (issue 27); a QoS 0 PUBLISH (paho calls ``on_publish`` once it is written) and a
DISCONNECT (paho closes after it) keep their own entry, and the queue's bytes, in order,
stay the same."""

from __future__ import annotations

from collections import deque
from typing import Any

from paho.mqtt.client import DISCONNECT, PUBACK, PUBLISH

from bridge.mqtt.connection import coalesce


def packet(command: int, data: bytes, qos: int = 1, pos: int = 0) -> dict[str, Any]:
    return {
        "command": command,
        "mid": 7,
        "qos": qos,
        "pos": pos,
        "to_process": len(data) - pos,
        "packet": bytearray(data),
        "info": None,
    }


def unsent(queue: deque[dict[str, Any]]) -> bytes:
    return b"".join(bytes(p["packet"][p["pos"] :]) for p in queue)


def test_acknowledged_publishes_and_acks_go_out_as_one() -> None:
    queue = deque(
        [
            packet(PUBLISH | 2, b"first", pos=2),  # partly written already
            packet(PUBACK, b"ack"),
            packet(PUBLISH | 4, b"second", qos=2),
        ]
    )
    before = unsent(queue)
    coalesce(queue)
    assert len(queue) == 1
    assert unsent(queue) == before == b"rstacksecond"
    assert queue[0]["to_process"] == len(before)
    assert queue[0]["command"] & 0xF0 not in (PUBLISH, DISCONNECT)  # nothing due once written


def test_a_qos_0_publish_and_a_disconnect_keep_their_own_entry() -> None:
    queue = deque(
        [
            packet(PUBLISH | 2, b"a"),
            packet(PUBLISH | 2, b"b"),
            packet(PUBLISH, b"zero", qos=0),
            packet(PUBLISH | 2, b"c"),
            packet(DISCONNECT, b"bye", qos=0),
        ]
    )
    before = unsent(queue)
    coalesce(queue)
    assert [bytes(p["packet"]) for p in queue] == [b"ab", b"zero", b"c", b"bye"]
    assert unsent(queue) == before
    assert queue[1]["command"] == PUBLISH and queue[3]["command"] == DISCONNECT


def test_one_packet_or_none_is_left_as_it_is() -> None:
    single = packet(PUBLISH | 2, b"only", pos=1)
    queue = deque([single])
    coalesce(queue)
    assert list(queue) == [single]
    empty: deque[dict[str, Any]] = deque()
    coalesce(empty)
    assert not empty
