"""The session's subscriptions, kept until the broker holds them.

A broker may refuse a SUBSCRIBE (an ACL) or not answer it in time (a cluster creating its
consumers: NATS with JetStream took seconds after a node failure, and refused some). Neither
ends the session nor holds up what it publishes: each group of filters is asked for in a
task of its own and asked again with a backoff (``RETRY_FIRST`` doubling up to
``RETRY_MAX`` seconds) until it holds. ``states`` says which groups hold (``live``), wait
for an answer or a retry (``pending``) or were refused last time (``refused``): it goes
into ``bridge/health`` and onto the web page. A group that does not hold is said once at
its level (the commands refused: ERROR, with what it costs; not answered: WARNING), again
at WARNING if the commands still do not hold after ``REMIND`` seconds, and its recovery at
INFO.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass

from bridge.mqtt import MqttClient, MqttRefusedError, MqttUnackedError

log = logging.getLogger(__name__)
RETRY_FIRST = 1.0  # seconds before a refused or unanswered subscription is asked again
RETRY_MAX = 30.0
REMIND = 60.0  # seconds without the command subscriptions before a second WARNING


@dataclass(frozen=True, slots=True)
class Wanted:
    """One group of filters asked for in one SUBSCRIBE, and what it costs while it waits."""

    name: str
    filters: tuple[str, ...]
    without_it: str  # what does not work meanwhile, for the log
    live_only: bool = False  # commands: no retained message, the retain flag kept
    level: int = logging.WARNING  # how a failure is said the first time


class Subscriptions:
    """The groups a session wants and how far each got (``states``)."""

    def __init__(self, wanted: Sequence[Wanted], qos: int) -> None:
        self.wanted = tuple(wanted)
        self.qos = qos
        self.states: dict[str, str] = {}
        self.reset()

    def reset(self) -> None:
        """A new session, or none: nothing is held."""
        self.states = {w.name: "pending" for w in self.wanted}

    async def keep(self, client: MqttClient, wanted: Wanted) -> None:
        """Subscribe to ``wanted`` and ask again until the broker holds it."""
        delay, tries, started = RETRY_FIRST, 0, time.monotonic()
        reminded = False
        while True:
            tries += 1
            try:
                await client.subscribe(*wanted.filters, qos=self.qos, live_only=wanted.live_only)
            except MqttRefusedError as exc:
                unanswered = isinstance(exc, MqttUnackedError)
                self.states[wanted.name] = "pending" if unanswered else "refused"
                waited = time.monotonic() - started
                if tries == 1:  # refused: the broker's config; unanswered: a passing state
                    level = wanted.level if not unanswered else min(wanted.level, logging.WARNING)
                    log.log(level, "%s: %s; asking again", exc, wanted.without_it)
                elif wanted.live_only and waited >= REMIND and not reminded:
                    reminded = True
                    log.warning(
                        "still no %s subscription after %.0f s (%d tries): %s",
                        wanted.name,
                        waited,
                        tries,
                        wanted.without_it,
                    )
                else:
                    log.debug("%s (try %d)", exc, tries)
                await asyncio.sleep(delay)
                delay = min(RETRY_MAX, 2 * delay)
                continue
            self.states[wanted.name] = "live"
            if tries > 1:
                log.log(
                    logging.INFO if wanted.level > logging.DEBUG else logging.DEBUG,
                    "subscribed to %s after %d tries (%.0f s)",
                    ", ".join(wanted.filters),
                    tries,
                    time.monotonic() - started,
                )
            return
