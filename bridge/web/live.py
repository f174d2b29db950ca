"""What the web page watches: value changes and refused commands, handed to its event streams.

The bridge tells its ``WebFeed`` what changed (``changed``, called with each poller
update) and what it refused (``refused``, with each ``<device>/error`` message); both
return at once and cost nothing while nobody watches. Each open event stream is a
``Watcher``: the keys changed on the device it shows and the refusals since its last
send, merged while it is busy, so a slow browser costs memory bounded by the mapping's
size (and ``MAX_PENDING`` refusals), never a queue that grows.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from bridge.core.health_report import iso_utc

RECENT = 50  # refused commands the errors page shows
MAX_PENDING = 20  # refusals a watcher keeps between two sends; older ones are dropped


@dataclass(eq=False, slots=True)
class Watcher:
    """One event stream's pending news."""

    device: str | None  # the device whose values it shows, if any
    keys: set[str] = field(default_factory=set)
    refusals: deque[dict[str, Any]] = field(default_factory=lambda: deque(maxlen=MAX_PENDING))
    changed: bool = False  # some device changed (state, status, alarms may differ)
    wake: asyncio.Event = field(default_factory=asyncio.Event)

    def take(self) -> tuple[set[str], list[dict[str, Any]], bool]:
        """The news since the last call (and forget it)."""
        keys, self.keys = self.keys, set()
        refusals = list(self.refusals)
        self.refusals.clear()
        changed, self.changed = self.changed, False
        self.wake.clear()
        return keys, refusals, changed


class WebFeed:
    """Value changes and refusals, for whoever watches."""

    def __init__(self) -> None:
        self.recent: deque[dict[str, Any]] = deque(maxlen=RECENT)
        self.refused = 0  # refusals since the start
        self._watchers: set[Watcher] = set()

    def changed(self, device_id: str, keys: frozenset[str] | set[str]) -> None:
        for watcher in self._watchers:
            watcher.changed = True
            if watcher.device == device_id:
                watcher.keys |= keys
            watcher.wake.set()

    def refused_command(self, device_id: str, document: str) -> None:
        """One ``<device>/error`` message (``document`` is its JSON)."""
        entry = {"time": iso_utc(time.time()), "device": device_id, **json.loads(document)}
        self.recent.append(entry)
        self.refused += 1
        for watcher in self._watchers:
            watcher.refusals.append(entry)
            watcher.wake.set()

    @contextlib.contextmanager
    def watch(self, device: str | None) -> Iterator[Watcher]:
        watcher = Watcher(device)
        self._watchers.add(watcher)
        try:
            yield watcher
        finally:
            self._watchers.discard(watcher)

    @property
    def watchers(self) -> int:
        return len(self._watchers)
