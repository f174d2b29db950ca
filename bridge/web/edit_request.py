"""What the page may change of a configured device, checked whole before anything reads
it; what ``allow_dangerous_writes`` permits; the one-time confirmations it needs.

``parse_edit(body)`` reads ``POST api/config/devices/<id>``'s JSON body: only these
fields, each strictly typed and bounded (a 1 MB body is refused by the HTTP server before
this), at least one of them::

    {"id": "well_pump",                   a new id (the old one's topics are emptied)
     "name": "Well pump",                 "" or null: the default name (from the id)
     "unit": 4,                           1..255 (1..247 on a serial line: the config says)
     "poll": {"fast": 5, "slow": "2min"}, seconds or a duration, as in the config file
     "enabled": false,
     "allow_dangerous_writes": true,
     "confirmation": "..."}               the token of the confirmation step, if asked

Nothing else of the config is reachable from here: no bus, mapping or secret, and never
``bridge.allow_raw_writes``. ``dangerous_entities(mapping, name)`` lists the entities
whose writes the device's ``allow_dangerous_writes`` permits, by the names Home Assistant
shows. ``Confirmations`` hands out one-time tokens bound to one device and one change.
"""

from __future__ import annotations

import json
import re
import secrets
import time
from collections import OrderedDict
from dataclasses import dataclass
from http import HTTPStatus
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, StringConstraints, ValidationError

from bridge.config.edits import MAX_ID, MAX_NAME
from bridge.core.discovery_entity import shown_name
from bridge.core.mapping import Mapping
from bridge.web.config_file import ConfigChangeError

CONFIRM_FOR = 120.0  # seconds a confirmation token may be used
MAX_PENDING = 16  # confirmations waiting at once; the oldest is dropped beyond
MAX_DURATION_TEXT = 32  # characters of an interval given as text ("2min")
_TYPE_TAG = re.compile(r"^(int|float|str|bool|constrained-\w+)$")  # a union member's place
Duration = (  # an int stays one: written as given (``fast: 1``, not ``1.0``)
    Annotated[int, Field(gt=0, le=31 * 86400)]
    | Annotated[float, Field(gt=0, le=31 * 86400, allow_inf_nan=False)]
    | Annotated[str, StringConstraints(min_length=1, max_length=MAX_DURATION_TEXT)]
)


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


class PollAsk(_Strict):
    fast: Duration | None = None
    slow: Duration | None = None


class EditAsk(_Strict):
    """The body of an edit (see the module)."""

    id: Annotated[str, StringConstraints(min_length=1, max_length=MAX_ID)] | None = None
    name: Annotated[str, StringConstraints(max_length=MAX_NAME)] | None = None
    unit: Annotated[int, Field(ge=1, le=255)] | None = None
    poll: PollAsk | None = None
    enabled: bool | None = None
    allow_dangerous_writes: bool | None = None
    confirmation: Annotated[str, StringConstraints(max_length=64)] | None = None


@dataclass(frozen=True, slots=True)
class Edit:
    """An edit as the config store takes it (``EditDevice.set``), and its confirmation."""

    fields: dict[str, Any]
    confirmation: str | None


def parse_edit(body: bytes) -> Edit:
    """The edit in ``body``; ConfigChangeError (400) naming the field otherwise."""
    ask = _ask(body)
    fields: dict[str, Any] = {}
    for name in ("id", "unit", "enabled", "allow_dangerous_writes"):
        if name in ask.model_fields_set and getattr(ask, name) is not None:
            fields[name] = getattr(ask, name)
    if "name" in ask.model_fields_set:
        fields["name"] = ask.name or None  # None: the key removed, the default name shown
    if ask.poll is not None:
        fields |= {f"poll.{k}": getattr(ask.poll, k) for k in sorted(ask.poll.model_fields_set)}
        if any(v is None for k, v in fields.items() if k.startswith("poll.")):
            raise ConfigChangeError(HTTPStatus.BAD_REQUEST, "poll: give fast and slow a value")
    if not fields:
        raise ConfigChangeError(HTTPStatus.BAD_REQUEST, "nothing to change: give a field")
    return Edit(fields, ask.confirmation)


def _ask(body: bytes) -> EditAsk:
    try:
        document = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        raise ConfigChangeError(HTTPStatus.BAD_REQUEST, "not JSON") from None
    if not isinstance(document, dict):
        raise ConfigChangeError(HTTPStatus.BAD_REQUEST, "send a JSON object of the fields")
    try:
        return EditAsk.model_validate(document, strict=True)
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        where = ".".join(str(p) for p in first["loc"] if not _TYPE_TAG.match(str(p)))
        extra = first["type"] == "extra_forbidden"
        said = "not a field the page changes" if extra else first["msg"]
        if where.startswith("poll.") and not extra:  # the union's first member said
            said = "seconds (a number above 0) or a duration such as 10s"
        raise ConfigChangeError(HTTPStatus.BAD_REQUEST, f"{where[:80]}: {said}") from None


def dangerous_entities(mapping: Mapping | None, device_name: str) -> list[dict[str, Any]]:
    """The entities ``allow_dangerous_writes`` lets Home Assistant and MQTT write, by the
    names Home Assistant shows: ``{key, name, component, permits}`` (permits: "any value",
    or "values below N" for a number guarded below a limit)."""
    if mapping is None:
        return []
    listed = []
    for key, entity in mapping.entities.items():
        if not entity.writable or not (entity.dangerous or entity.dangerous_below is not None):
            continue
        below = entity.dangerous_below
        listed.append(
            {
                "key": key,
                "name": shown_name(entity.name, device_name),
                "component": entity.component.value,
                "permits": "any value" if entity.dangerous else f"values below {below:g}",
                "shown": not entity.secret,  # a secret is never in Home Assistant
            }
        )
    return listed


class Confirmations:
    """One-time tokens: each confirms one change of one device, for ``CONFIRM_FOR``."""

    def __init__(self) -> None:
        self._pending: OrderedDict[str, tuple[str, str, float]] = OrderedDict()

    def issue(self, device_id: str, fields: dict[str, Any]) -> str:
        now = time.monotonic()
        for token, (_, _, until) in list(self._pending.items()):
            if until <= now:
                del self._pending[token]
        while len(self._pending) >= MAX_PENDING:
            self._pending.popitem(last=False)
        token = secrets.token_urlsafe(24)
        self._pending[token] = (device_id, _canonical(fields), now + CONFIRM_FOR)
        return token

    def take(self, token: str | None, device_id: str, fields: dict[str, Any]) -> bool:
        """True once if ``token`` confirms exactly this change of this device, in time."""
        found = self._pending.pop(token, None) if token else None
        if found is None:
            return False
        device, change, until = found
        same = secrets.compare_digest(change, _canonical(fields)) and device == device_id
        return same and time.monotonic() < until


def _canonical(fields: dict[str, Any]) -> str:
    return json.dumps(fields, sort_keys=True, separators=(",", ":"))
