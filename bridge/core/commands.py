"""Command payloads: parsing, expiry and duplicate detection. Pure (time is passed in).

``<base>/<device>/set`` takes a JSON object ``{key: value, ...}``; ``<base>/<device>/<key>/set``
takes a plain value: a number, ``true``/``false``, ``ON``/``OFF``, an enum label, ``PRESS``,
or a JSON value. ``<base>/<device>/get`` takes nothing (read everything) or a JSON object
or list naming the keys. What the value means for the entity (type, range, enum label)
is checked by the codec when the command is encoded; here only the payload's shape is.

Bounds: a payload longer than ``MAX_PAYLOAD`` bytes is refused before it is decoded or
parsed, and an error quotes at most ``ECHO`` characters of what it refuses
(``error_document`` is always valid JSON: no bare NaN, no megabytes echoed back).
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from dataclasses import dataclass

from bridge.errors import ValueRejectedError

MAX_PAYLOAD = 65536  # bytes of a command or management request
ECHO = 64  # characters of a refused value quoted back
ERROR_TEXT = 500  # characters of an error message
MAX_KEYS = 100  # keys of one /set (a device has up to about 200 entities, few writable)


@dataclass(frozen=True, slots=True)
class Command:
    """One /set: the keys and values written together (all or nothing) to one device,
    and the time (monotonic seconds) it stops being worth executing."""

    device_id: str
    items: dict[str, object]
    received: float
    expires: float

    @classmethod
    def arrived(
        cls,
        device_id: str,
        items: dict[str, object],
        received: float,
        expiry: float,
        message_expiry: float | None = None,
    ) -> Command:
        """A /set that arrived at ``received``, in time for ``expiry`` seconds (the
        bridge's ``mqtt.command_expiry``) or the publisher's MQTT 5 message expiry,
        whichever ends first; both counted from its arrival."""
        lifetime = expiry if message_expiry is None else min(expiry, message_expiry)
        return cls(device_id, items, received, received + lifetime)

    def expired(self, now: float) -> bool:
        """True once ``now`` is past the expiry (``past_deadline``)."""
        return past_deadline(self.expires, now)


def past_deadline(deadline: float | None, now: float) -> bool:
    """The rule of a command's time: True once ``now`` is beyond ``deadline``; at the
    deadline itself it is still in time; with no deadline (None) never. The dispatcher
    applies it before a command runs (``Command.expired``), the scheduler right before
    the command's first frame is sent (the deadline it was given)."""
    return deadline is not None and now > deadline


def parse_set(payload: bytes, key: str | None) -> dict[str, object]:
    """``{key: value}`` from a /set payload; ValueRejectedError naming what is wrong."""
    text = _text(payload)
    if key is not None:
        return {key: _plain(text)}
    try:
        data = _json(text)
    except ValueError:
        raise ValueRejectedError("a device /set payload is a JSON object {key: value}") from None
    if not isinstance(data, dict) or not data:
        raise ValueRejectedError("a device /set payload is a non-empty JSON object {key: value}")
    if len(data) > MAX_KEYS:
        raise ValueRejectedError(f"{len(data)} keys in one /set: at most {MAX_KEYS}")
    return dict(data)


def parse_get(payload: bytes) -> list[str] | None:
    """The keys a /get asks for, or None for every value."""
    text = _text(payload).strip()
    if not text:
        return None
    try:
        data = _json(text)
    except ValueError:
        raise ValueRejectedError('a /get payload is empty, {"key": ""} or ["key", ...]') from None
    keys = list(data) if isinstance(data, dict | list) else None
    if not keys or not all(isinstance(k, str) for k in keys):
        raise ValueRejectedError('a /get payload is empty, {"key": ""} or ["key", ...]')
    return keys


def check_size(payload: bytes) -> None:
    """ValueRejectedError for a payload beyond ``MAX_PAYLOAD`` (before anything parses it)."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueRejectedError(
            f"payload of {len(payload)} bytes refused: at most {MAX_PAYLOAD} bytes"
        )


def echo(value: object) -> object:
    """``value`` as an error quotes it: JSON scalars as they are, anything else (long text,
    bytes, objects, NaN) as text cut to ``ECHO`` characters."""
    if value is None or isinstance(value, bool | int):
        return value if not isinstance(value, int) or abs(value) < 10**15 else _cut(str(value))
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, bytes):
        text = value[:ECHO].decode("utf-8", errors="replace")
        return text if len(value) <= ECHO else f"{text}... ({len(value)} bytes)"
    if isinstance(value, str):
        return _cut(value)
    return _cut(repr(value))


def _cut(text: str, limit: int = ECHO) -> str:
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


def error_document(key: str | None, value: object, error: str) -> str:
    """The JSON of ``<device>/error``: ``{key, value, error}``, bounded and always valid."""
    shown_key = key if key is None else _cut(key)
    document = {"key": shown_key, "value": echo(value), "error": _cut(error, ERROR_TEXT)}
    return json.dumps(document, allow_nan=False)


def _text(payload: bytes) -> str:
    check_size(payload)
    try:
        return payload.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueRejectedError("payload is not UTF-8 text") from None


def _json(text: str) -> object:
    """``json.loads``, with nesting deeper than the parser can follow (``[[[[...``, which
    raises RecursionError) refused like any other malformed JSON: ValueError."""
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None


def _plain(text: str) -> object:
    """A plain value: JSON scalars as such (``45``, ``4.5``, ``true``, ``"x"``), else text."""
    stripped = text.strip()
    if not stripped:
        raise ValueRejectedError("empty payload")
    try:
        value = _json(stripped)
    except ValueError:
        return stripped
    if isinstance(value, dict | list):
        raise ValueRejectedError("a /<key>/set payload is one plain value, not an object")
    return value


class RecentMessages:
    """Remembers recent command messages so a redelivered duplicate (QoS 1/2 with the DUP
    flag, same packet id, topic and payload) is not executed twice."""

    def __init__(self, window: float, size: int = 1024) -> None:
        self.window = window
        self.size = size
        self._seen: OrderedDict[tuple[str, bytes, int], float] = OrderedDict()

    def is_duplicate(
        self, topic: str, payload: bytes, mid: int | None, duplicate: bool, now: float
    ) -> bool:
        """Record a message; True when it repeats one seen within the window."""
        while self._seen and (
            next(iter(self._seen.values())) < now - self.window or len(self._seen) > self.size
        ):
            self._seen.popitem(last=False)
        if mid is None or mid == 0:
            return False
        signature = (topic, payload, mid)
        if duplicate and signature in self._seen:
            return True
        self._seen[signature] = now
        return False
