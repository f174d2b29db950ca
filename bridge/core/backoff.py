"""How long to wait between attempts to reach the MQTT broker. Pure.

A broker restart (an upgrade, a container restart) is the common outage: the bridge must
be back within a fraction of a second of the broker accepting connections, so for the
first ``fast_window`` seconds of an outage it tries every ``initial`` seconds doubling up
to ``fast_max`` (a refused connection costs next to nothing). A longer outage backs off,
doubling up to ``slow_max``. The backoff starts over only after a good session (one that
lasted ``good_session`` seconds): a broker that accepts and drops the bridge at once
(a second client with the same id, an ACL) is not hammered, nor is one that refuses the
login (a wrong password does not get better by asking five times a second).
"""

from __future__ import annotations

import random
from dataclasses import dataclass


@dataclass(slots=True)
class ReconnectBackoff:
    """The delay before each new attempt, from failures and sessions (times: monotonic s)."""

    initial: float = 0.1
    fast_max: float = 0.4
    fast_window: float = 60.0
    slow_max: float = 30.0
    good_session: float = 10.0
    _delay: float = 0.0
    _outage_since: float | None = None
    _connected_at: float | None = None

    def connected(self, now: float) -> None:
        """A session started."""
        self._connected_at = now

    def failed(self, now: float, *, refused: bool = False) -> float:
        """An attempt failed or a session ended: the seconds to wait before the next one.
        ``refused``: the broker refused the login (CONNACK: bad user name or password,
        not authorised, banned...): backs off like an old outage."""
        if self._connected_at is not None and now - self._connected_at >= self.good_session:
            self._delay, self._outage_since = 0.0, None  # after a good session: start over
        self._connected_at = None
        if self._outage_since is None:
            self._outage_since = now
        young = not refused and now - self._outage_since < self.fast_window
        longest = self.fast_max if young else self.slow_max
        self._delay = min(longest, self.initial if self._delay == 0 else 2 * self._delay)
        return self._delay


class BrokerUrls:
    """Which broker of a cluster to try next (``mqtt.url`` as a list).

    The bridge stays on the node it is connected to; after a failed connect or a lost
    session the next attempt goes to the next node (in the configured order, or a random
    one not tried yet), at once while some node is untried since the last connect, and
    after the backoff once every node failed. A node that died costs one reconnect.
    """

    def __init__(self, urls: list[str], *, shuffled: bool = False, seed: int | None = None) -> None:
        self.urls = list(urls)
        self._random = random.Random(seed) if shuffled else None  # noqa: S311 - spreading load, not secrets
        self._index = self._random.randrange(len(self.urls)) if self._random else 0
        self._tried: set[int] = set()

    @property
    def current(self) -> str:
        return self.urls[self._index]

    def connected(self) -> None:
        self._tried.clear()

    def failed(self) -> bool:
        """The current node failed: move on to the next. True when every node failed
        since the last connect (wait as the backoff says), False when the next one is
        untried (try it at once)."""
        count = len(self.urls)
        self._tried.add(self._index)
        every = len(self._tried) >= count
        if every:
            self._tried.clear()
        others = [i for i in range(count) if i not in self._tried and i != self._index]
        if not others:
            return every  # one node: stay on it
        if self._random is not None:
            self._index = self._random.choice(others)
        else:
            self._index = min(others, key=lambda i: (i - self._index) % count)
        return every
