"""The bridge: the Modbus engine and the MQTT session wired together.

``Bridge(loaded).run()`` runs one TaskGroup: the engine (every bus and device) and the
MQTT session, which reconnects by itself. Every (re)connect subscribes to the command
topics, clears retained discovery configs the bridge no longer produces, publishes
discovery and the whole state. Pollers report changes; a publisher sends the device's
JSON, the changed plain values and its availability. Commands go through the dispatcher
(bridge/dispatcher.py: retained ones refused, bounded, all or nothing, never late);
anything refused or failing goes to ``<base>/<device>/error``. Handling one message never
waits for a device or a broker round trip, and no exception from one message leaves the
message loop. Home Assistant's ``online`` asks for one republish, half a second later
(however many arrive meanwhile). At most ``MAX_REQUESTS`` management requests run at a time.
A subscription the broker refuses (an ACL) is logged, and the session goes on
publishing without it. Each session publishes ``<base>/bridge/health`` every
``bridge.health_interval``; the optional metrics endpoint serves the same counters for the
whole run, and the optional web page (bridge/web) shows the same values, health and
refusals, fed by ``feed``. A clean stop (Ctrl-C, SIGTERM) sets every device's availability
``offline`` before ``bridge/state`` goes ``offline``; the demo (``remove_on_stop``) empties
every retained message it published. One bridge per base topic: before a connection says
``online``, ``_alone`` checks that no other live bridge serves the topic (else this one
stands by without polling: bridge/core/instance.py), and a bridge that comes up beside
this one later is told apart by the ``bridge/info`` it publishes.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import logging
import time
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any

from bridge import __version__
from bridge.config import LoadedConfig, MetricsConfig
from bridge.core.commands import check_size, error_document
from bridge.core.discovery import (
    Origin,
    Publish,
)
from bridge.core.health_report import HealthReporter, Snapshot
from bridge.core.instance import Instance, instance_of, taken_message
from bridge.core.management_request import response
from bridge.core.state import compact, plain_payload, published, state_document
from bridge.core.topics import Topics
from bridge.discovery_publisher import DiscoveryPublisher
from bridge.dispatcher import RETAINED, Dispatcher
from bridge.errors import ValueRejectedError, first_of
from bridge.management import Management
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DevicePoller, DeviceUpdate
from bridge.mqtt import (
    BaseTopicTakenError,
    Message,
    MqttClient,
    MqttError,
    MqttPublishError,
    run_with_reconnect,
)
from bridge.mqtt.reconnect import STANDBY_RETRY
from bridge.standby import check_alone
from bridge.subscriptions import Subscriptions, Wanted
from bridge.web import WebFeed, serve_web

log = logging.getLogger(__name__)
Outgoing = tuple[str, str, bool]  # topic, payload, retain
OUTBOX = 200  # non-retained messages kept while the broker is away
HA_SETTLE = 0.5  # seconds after Home Assistant's "online" before republishing
HA_REPUBLISH_GAP = 30.0  # seconds at least between two republishes Home Assistant asks for
MAX_REQUESTS = 8  # management requests running at a time; more are answered "busy"
STATE_AFTER_DISCOVERY = 1.0  # seconds: a device's state again after its discovery changed


class Bridge:
    """One config's buses and devices, published over one MQTT connection."""

    def __init__(
        self, loaded: LoadedConfig, *, remove_on_stop: bool = False, must_connect: bool = False
    ) -> None:
        config = loaded.config
        self.loaded = loaded
        self.remove_on_stop = remove_on_stop  # the demo: leave nothing on the broker
        self.must_connect = must_connect  # the demo: a first connect that fails ends run()
        self.mqtt = config.mqtt
        self.topics = Topics(config.mqtt.base_topic, config.mqtt.discovery_prefix)
        self.origin = Origin(sw_version=__version__)
        self.engine = Engine(loaded, self._on_update)
        self.discovery = DiscoveryPublisher(loaded, self.engine, self.topics, self.origin)
        self._wake = asyncio.Event()
        self._dirty: dict[str, set[str]] = {}
        self._outbox: deque[Publish] = deque(maxlen=OUTBOX)
        self.dropped = 0  # messages the full outbox dropped (counted in bridge/health)
        self._availability: dict[str, str] = {}
        self.feed = WebFeed()  # what the web page watches: value changes, refusals
        self.dispatcher = Dispatcher(
            self.engine,
            self.mqtt.command_expiry,
            spawn=self._spawn,
            error=self._error,
            read=self._publish_state,
        )
        self._requests = 0  # management requests running
        self._group: asyncio.TaskGroup | None = None
        self._health = HealthReporter()  # rates since the previous report
        # "online" while connected, "offline" between, "standby" while another bridge
        # serves the base topic
        self.mqtt_state = "connecting"
        self.instance = Instance.new(time.time())
        self._rival: Instance | None = None  # a bridge that came up beside this one
        self._info_due = False  # bridge/info again: another bridge overwrote it
        self._engine: asyncio.Task[None] | None = None
        self.subscriptions = Subscriptions(self._wanted(), max(1, self.mqtt.qos))
        self.management = Management(
            loaded,
            self.engine,
            on_reload=self._reloaded,
            mqtt_state=lambda: self.mqtt_state,
            instance=self.instance,
        )
        self._republish = False  # after a mapping reload: info, discovery and state
        # requests beyond the management API, by command (the demo's "demo/fault")
        self.extra_requests: dict[str, Callable[[bytes], Awaitable[str]]] = {}
        self._ha_online = asyncio.Event()  # Home Assistant said online: republish soon

    # --- running ----------------------------------------------------------------------

    async def run(self) -> None:
        """Run until cancelled."""
        metrics = _metrics(self.loaded.config.bridge.metrics, self.engine.snapshot)
        web = serve_web(self.loaded.config.bridge.web, self)
        async with metrics, web, asyncio.TaskGroup() as group:
            self._group = group
            self._engine = group.create_task(self.engine.run(), name="engine")
            group.create_task(
                run_with_reconnect(
                    self.mqtt,
                    self.topics.bridge_state,
                    self._session,
                    on_state=self._mqtt_is,
                    first_connect_required=self.must_connect,
                    announce=False,  # the session says online after check_alone
                ),
                name="mqtt",
            )

    @property
    def mqtt_subscriptions(self) -> dict[str, str]:
        """Which subscription groups the broker holds (live), waits on or refused."""
        return dict(self.subscriptions.states)

    def _wanted(self) -> list[Wanted]:
        topics = self.topics
        commands = (*topics.command_filters(), topics.bridge_requests)
        return [
            # at QoS 0: a clean session keeps nothing across connections, so QoS 1 would
            # add only a redelivery (a command twice is worse than once lost) and, on NATS,
            # a JetStream consumer per subscription, which after a node failure took the
            # SUBACK and then lost commands for seconds (tests/integration/test_cluster.py)
            Wanted(
                "commands",
                commands,
                "commands and requests do not reach the bridge",
                live_only=True,
                level=logging.ERROR,
                qos=0,
            ),
            Wanted("home_assistant", (topics.ha_status,), "Home Assistant's restarts go unnoticed"),
            Wanted(
                "bridge_info",  # a bridge that comes up beside this one says so there
                (topics.bridge_info,),
                "a second bridge on this base topic goes unnoticed",
                level=logging.DEBUG,
            ),
        ]

    def _mqtt_is(self, state: str) -> None:
        """Follow the MQTT side; a bridge that stands by does not poll (a device that takes
        one TCP client, or one master on its line, is the other bridge's)."""
        self.mqtt_state = state
        if state == "standby" and self._engine is not None:
            self._engine.cancel()  # a write in flight is finished first
            self._engine = None

    def _polling(self) -> None:
        """The engine runs (again, after standing by)."""
        if self._engine is None and self._group is not None:
            self._engine = self._group.create_task(self.engine.run(), name="engine")

    async def _session(self, client: MqttClient) -> None:
        """One connection: subscriptions asked for beside everything else (bridge/
        subscriptions.py); once no other bridge serves the base topic (bridge/standby.py),
        ``online``, then clean up, publish everything, and serve. A command that came
        meanwhile waits in the connection's queue (or goes with it, standing by)."""
        client.farewell = functools.partial(self._farewell, client)
        if self.remove_on_stop:
            client.goodbye = b""
        self._rival = None
        self.subscriptions.reset()
        try:
            async with asyncio.TaskGroup() as group:
                for wanted in self.subscriptions.wanted:
                    group.create_task(self.subscriptions.keep(client, wanted))
                await check_alone(client, self.topics, self.instance)
                await client.announce()
                self._polling()
                # values, devices and info in one burst: one round trip, and no value waits
                # for a slow broker's PUBACK of another message (a cluster storing them)
                await self._publish_everything(client, with_info=True)
                # commands are served from here on; discovery (its stale-config sweep takes
                # a second or more) goes out beside them, then what publishes changes
                group.create_task(self._discovery_then_publishers(client, group))
                async for message in client.messages():
                    self._handle(message)
                    if self._rival is not None:
                        raise BaseTopicTakenError(
                            taken_message(self.mqtt.base_topic, self._rival, STANDBY_RETRY)
                        )
        except ExceptionGroup as failed:  # the MQTT error, so the reconnect loop sees it
            raise first_of(failed, MqttError) or failed from None

    async def _discovery_then_publishers(
        self, client: MqttClient, group: asyncio.TaskGroup
    ) -> None:
        """Discovery first (a change published before it would publish it a second
        time), then the tasks that publish changes, refreshes, republishes and health."""
        await self.discovery.publish(client, clear_stale=True)
        for work in (
            self._publisher,
            self._refresher,
            self._home_assistant_returns,
            self._health_reports,
        ):
            group.create_task(work(client))

    def _farewell(self, client: MqttClient) -> list[tuple[str, str]]:
        """What a clean stop publishes before ``bridge/state`` goes offline: each device
        offline (plain MQTT clients and Node-RED see it, not only Home Assistant), or, with
        ``remove_on_stop``, an empty retained message on every topic this session left one
        on, discovery configs first (Home Assistant removes the devices)."""
        if not self.remove_on_stop:
            return [(self.topics.availability(d), "offline") for d in self.engine.devices]
        prefix = f"{self.topics.discovery_prefix}/"
        left = sorted(client.retained_topics - {self.topics.bridge_state})
        ordered = [t for t in left if t.startswith(prefix)] + [
            t for t in left if not t.startswith(prefix)
        ]
        return [(topic, "") for topic in ordered]

    async def _publisher(self, client: MqttClient) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            await self._flush(client)

    async def _home_assistant_returns(self, client: MqttClient) -> None:
        """Discovery and state again after Home Assistant says ``online``: ``HA_SETTLE``
        seconds after it, however many come, and at most once per ``HA_REPUBLISH_GAP``
        (anyone may publish ``online``: a sustained flood must not keep the bridge
        republishing everything)."""
        last = -HA_REPUBLISH_GAP
        while True:
            await self._ha_online.wait()
            await asyncio.sleep(max(HA_SETTLE, last + HA_REPUBLISH_GAP - time.monotonic()))
            self._ha_online.clear()
            last = time.monotonic()
            log.info("Home Assistant is online: publishing discovery and state again")
            await self.discovery.publish(client)
            await self._publish_everything(client)

    async def _refresher(self, client: MqttClient) -> None:
        while True:
            await asyncio.sleep(self.mqtt.state_refresh)
            await self._publish_everything(client)

    async def _health_reports(self, client: MqttClient) -> None:
        """``<base>/bridge/health`` now and every ``health_interval``, retained: Home
        Assistant's health sensors read it as soon as they subscribe, not one interval
        later (when 0: never, and a report an earlier run left is cleared)."""
        interval = self.loaded.config.bridge.health_interval
        if interval <= 0:
            await client.publish(self.topics.bridge_health, "", retain=True)
        while interval > 0:
            report = self._health.report(self.engine.snapshot())
            counters = self.dispatcher.counters
            report["mqtt"] = {
                "state": self.mqtt_state,
                "broker": client.broker,
                "subscriptions": self.mqtt_subscriptions,
            }
            report["messages"] = {
                "commands": counters.commands,
                "refused": counters.refused,
                "coalesced": counters.coalesced,
                "dropped": self.dropped,
            }
            await client.publish(self.topics.bridge_health, compact(report), retain=True)
            await asyncio.sleep(interval)

    # --- state ------------------------------------------------------------------------

    def _on_update(self, update: DeviceUpdate) -> None:
        self._dirty.setdefault(update.device_id, set()).update(update.changed)
        self._wake.set()
        self.feed.changed(update.device_id, update.changed)

    async def _flush(self, client: MqttClient) -> None:
        if self._info_due:
            self._info_due = False
            await self._publish_info(client)
        if self._republish:  # after a mapping reload: new entities, new discovery
            self._republish = False
            self._ha_online.clear()
            await self._publish_info(client)
            await self.discovery.publish(client, clear_stale=True)
            await self._publish_everything(client)
        dirty, self._dirty = self._dirty, {}
        burst: list[Outgoing] = []
        devices_changed = False
        for device_id, keys in dirty.items():
            poller = self.engine.devices[device_id]
            due = self.discovery.due(poller, keys)  # first: the payload admits the values
            if due and await self.discovery.publish(client, only=device_id):
                self._spawn(self._state_again(device_id))
            devices_changed |= self._device_messages(poller, keys, burst)
        await client.publish_many(burst)
        if devices_changed:
            await self._publish_devices_list(client)
        while self._outbox:
            message = self._outbox.popleft()
            try:
                await client.publish(message.topic, message.payload, retain=message.retain)
            except MqttPublishError as exc:
                log.warning("%s", exc)

    def _device_messages(self, poller: DevicePoller, keys: set[str], burst: list[Outgoing]) -> bool:
        """Add a device's JSON, changed plain values and availability (when it changed) to
        ``burst``; True if the availability changed."""
        device_id = poller.device.id
        topics = self.topics
        output = self.mqtt.output
        if poller.values and output != "values":
            document = state_document(poller.mapping, poller.points, poller.values)
            burst.append((topics.device(device_id), compact(document), True))
        if output != "json":
            for key in sorted(keys & set(published(poller.points))):
                payload = plain_payload(poller.values.get(key))
                burst.append((topics.value(device_id, key), payload, True))
        # online once it answered and its values are out, offline once it stopped
        # answering; before its first poll settled, nothing (a retained "offline" for a
        # device that is only being asked would be a false alarm)
        if poller.health.online is False:
            availability = "offline"
        elif poller.health.online and poller.values:
            availability = "online"
        else:
            return False
        if self._availability.get(device_id) != availability:
            self._availability[device_id] = availability
            burst.append((topics.availability(device_id), availability, True))
            return True
        return False

    async def _publish_everything(self, client: MqttClient, *, with_info: bool = False) -> None:
        """Every device's state and availability, the devices list (and ``bridge/info``),
        sent at once and acknowledged together."""
        self._availability.clear()
        burst: list[Outgoing] = []
        for poller in self.engine.devices.values():
            self._device_messages(poller, set(published(poller.points)), burst)
        burst.append((self.topics.bridge_devices, self._devices_list(), True))
        if with_info:
            burst.append((self.topics.bridge_info, self._info(), True))
        await client.publish_many(burst)

    async def _publish_devices_list(self, client: MqttClient) -> None:
        await client.publish(self.topics.bridge_devices, self._devices_list(), retain=True)

    def _devices_list(self) -> str:
        listing = [
            {
                "id": p.device.id,
                "name": p.device.display_name,
                "mapping": p.device.mapping,
                "model": f"{p.mapping.manufacturer} {p.mapping.model}",
                "bus": p.device.bus,
                "unit": p.device.unit,
                "state": _availability_word(p.health.online),
            }
            for p in self.engine.devices.values()
        ]
        return compact(listing)

    # --- commands ---------------------------------------------------------------------

    def _handle(self, message: Message) -> None:
        """Route one message; never waits, and nothing it raises leaves the message loop."""
        try:
            self._route(message)
        except Exception:  # one message must never stop the bridge
            log.exception("a message on %s could not be handled", message.topic[:200])

    def _route(self, message: Message) -> None:
        request = self.topics.parse_request(message.topic)
        if request is not None:
            self._request(request, message)
            return
        if message.topic == self.topics.ha_status:
            if message.payload.strip() == b"online":
                self._ha_online.set()
            return
        if message.topic == self.topics.bridge_info:
            self._another_info(message)
            return
        target = self.topics.parse_command(message.topic)
        if target is not None:
            self.dispatcher.handle(target, message)

    def _another_info(self, message: Message) -> None:
        """A live ``bridge/info`` of another instance: a bridge came up beside this one.
        The one that started later stands by; this one, if it stays, says it is the one
        serving the topic (the retained record named the other)."""
        other = instance_of(message.payload)
        if message.retain or other is None or other.id == self.instance.id:
            return  # the record from before this session, an older bridge, or this one
        if self.instance.yields_to(other):
            self._rival = other
        else:
            log.error(
                "another bridge came up on base topic %r (%s); this one keeps serving it",
                self.mqtt.base_topic,
                other.describe(),
            )
            self._info_due = True
            self._wake.set()

    def _spawn(self, work: Any, failed: Callable[[str], None] | None = None) -> None:
        """Run a command's or request's work in the bridge's TaskGroup; whatever it raises
        is logged (and reported through ``failed``), never taken for the bridge's end."""
        if self._group is None:
            raise RuntimeError("the bridge is not running")
        self._group.create_task(_guarded(work, failed))

    async def _state_again(self, device_id: str) -> None:
        """Publish a device's state once more after Home Assistant took its new discovery:
        it applies a changed payload in the background, and a state that arrived first (a
        code now in the options, a number now in range) would have been dropped."""
        await asyncio.sleep(STATE_AFTER_DISCOVERY)
        self._publish_state(device_id)

    def _publish_state(self, device_id: str) -> None:
        """Have the publisher send the device's state (changed or not): after a read on
        request, or after Home Assistant took a new discovery payload."""
        self._dirty.setdefault(device_id, set())
        self._wake.set()

    # --- management -------------------------------------------------------------------

    def _request(self, command: str, message: Message) -> None:
        """Start one management request, or answer at once why not."""
        try:
            if message.retain:
                raise ValueRejectedError(RETAINED)
            check_size(message.payload)
            if self._requests >= MAX_REQUESTS:
                raise ValueRejectedError(f"busy: {self._requests} requests are running")
        except ValueRejectedError as exc:
            self.dispatcher.counters.refused += 1
            self._respond(command, response(error=str(exc)))
            return
        self._requests += 1
        self._spawn(self._answer(command, message.payload))

    async def _answer(self, command: str, payload: bytes) -> None:
        """Run one management request and queue its response."""
        try:
            extra = self.extra_requests.get(command)
            answer = await (extra(payload) if extra else self.management.handle(command, payload))
        except Exception as exc:  # a request must never stop the bridge
            log.exception("management request %s failed", command[:200])
            answer = response(error=f"internal error: {exc}")
        finally:
            self._requests -= 1
        self._respond(command, answer)

    def _respond(self, command: str, answer: str) -> None:
        self._queue(Publish(self.topics.bridge_response(command), answer, retain=False))

    def _queue(self, message: Publish) -> None:
        """Queue a non-retained message; when the outbox is full the oldest is dropped
        (and counted)."""
        if len(self._outbox) == self._outbox.maxlen:
            self.dropped += 1
        self._outbox.append(message)
        self._wake.set()

    async def _reloaded(self, device_ids: list[str]) -> None:
        log.info("mappings reloaded for %s", ", ".join(device_ids))
        for device_id in device_ids:
            self.discovery.forget(device_id)
            self._dirty.pop(device_id, None)
        self._republish = True
        self._wake.set()

    async def _publish_info(self, client: MqttClient) -> None:
        await client.publish(self.topics.bridge_info, self._info(), retain=True)

    def _info(self) -> str:
        return json.dumps(self.management.info(), default=str)

    def _error(self, device_id: str, key: str | None, value: object, error: str) -> None:
        payload = error_document(key, value, error)
        log.info("%s refused: %s", device_id[:100], payload)
        self._queue(Publish(self.topics.error(device_id), payload, retain=False))
        self.feed.refused_command(device_id, payload)


def _metrics(
    config: MetricsConfig, source: Callable[[], Snapshot]
) -> contextlib.AbstractAsyncContextManager[None]:
    """The metrics endpoint while the bridge runs, if enabled (prometheus_client is loaded
    only then: it costs memory ``run`` does not otherwise need)."""
    if not config.enabled:
        return contextlib.nullcontext()
    from bridge.metrics import serve_metrics  # noqa: PLC0415

    return serve_metrics(config, source)


async def _guarded(work: Any, failed: Callable[[str], None] | None) -> None:
    try:
        await work
    except Exception as exc:  # one command or request must never stop the bridge
        log.exception("internal error while handling a command or request")
        if failed is not None:
            failed(f"internal error: {type(exc).__name__}")


def _availability_word(online: bool | None) -> str:
    return "unknown" if online is None else "online" if online else "offline"
