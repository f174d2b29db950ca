"""One bridge per base topic: who this running bridge is, and who else holds the topic.

Every run has an ``Instance`` (a random id, host, process id, start time), published in
the retained ``<base>/bridge/info`` and in health-check answers. At each connect, before
it subscribes to commands, the bridge reads the retained ``bridge/state``: ``online``
with another instance's id in ``bridge/info`` (and that instance answering a health check:
a retained ``online`` can outlive its bridge when the broker kept it through a restart)
means another bridge serves the topic, and this one stands by. Two bridges that started
at the same moment both pass that check; each sees the other's ``bridge/info`` arrive live,
and the one that started later (``yields_to``) stands by.
"""

from __future__ import annotations

import json
import os
import platform
import secrets
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

MAX_INFO = 1024 * 1024  # bytes of bridge/info read for the instance (any client may write it)


@dataclass(frozen=True, slots=True)
class Instance:
    """One run of a bridge."""

    id: str
    host: str
    pid: int
    started: float  # time.time() at start

    @classmethod
    def new(cls, started: float) -> Instance:
        return cls(secrets.token_hex(6), platform.node(), os.getpid(), started)

    def document(self) -> dict[str, Any]:
        return {"id": self.id, "host": self.host, "pid": self.pid, "started": self.started}

    def yields_to(self, other: Instance) -> bool:
        """Of two instances live at once, the one that started later stands by (the id
        decides a tie, so both come to the same answer)."""
        return (other.started, other.id) < (self.started, self.id)

    def describe(self) -> str:
        since = datetime.fromtimestamp(self.started, UTC).isoformat(timespec="seconds")
        return f"instance {self.id} on host {self.host!r}, process {self.pid}, since {since}"


def instance_of(info: bytes | None) -> Instance | None:
    """The instance a ``bridge/info`` document names; None when it names none (an older
    bridge, not JSON, too big, fields missing or of the wrong type)."""
    document = _document(info)
    return _instance(document.get("instance")) if document is not None else None


def answering_instance(answer: bytes | None) -> Instance | None:
    """The instance a health-check answer names (``data.instance``), if any."""
    document = _document(answer)
    data = document.get("data") if document is not None else None
    return _instance(data.get("instance")) if isinstance(data, dict) else None


def _document(payload: bytes | None) -> dict[str, Any] | None:
    if not payload or len(payload) > MAX_INFO:
        return None
    try:
        document = json.loads(payload)
    except (ValueError, RecursionError):
        return None
    return document if isinstance(document, dict) else None


def _instance(found: object) -> Instance | None:
    if not isinstance(found, dict):
        return None
    ident, host, pid, started = (found.get(k) for k in ("id", "host", "pid", "started"))
    if not (
        isinstance(ident, str)
        and isinstance(host, str)
        and isinstance(pid, int)
        and isinstance(started, int | float)
        and not isinstance(pid, bool)
        and not isinstance(started, bool)
    ):
        return None
    return Instance(ident[:64], host[:253], pid, float(started))


def taken_message(base_topic: str, other: Instance | None, retry: float) -> str:
    """What a bridge that stands by says, once: who holds the topic and what to do."""
    who = other.describe() if other is not None else "a bridge that does not name itself"
    return (
        f"another bridge serves base topic {base_topic!r} ({who}): this one takes no "
        "commands and publishes nothing while it runs. Stop one of them (an old container "
        f"left running: docker ps, docker stop NAME) or give this one its own "
        f"mqtt.base_topic; checking again every {retry:g} s"
    )
