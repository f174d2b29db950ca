"""The bridge: the Modbus engine and the MQTT session wired together.

``Bridge(loaded).run()`` runs one TaskGroup: the engine (every bus and device) and the
MQTT session, which reconnects by itself (bridge/mqtt/reconnect.py). Every (re)connect
subscribes to the command topics (at QoS 0), publishes the whole state, then ``online``
and discovery (the first one of a run also clears retained discovery configs the bridge no
longer produces), and serves commands from the base-topic check on. Commands go through
the dispatcher (bridge/dispatcher.py: retained ones refused, bounded, all or nothing, never late);
anything refused or failing goes to ``<base>/<device>/error``. Handling one message never
waits for a device or a broker round trip, and no exception from one message leaves the
message loop. At most ``MAX_REQUESTS`` management requests run at a time. A subscription
the broker refuses (an ACL) is logged, and the session goes on publishing without it.
Each session publishes ``<base>/bridge/health`` every ``bridge.health_interval``; the
optional metrics endpoint serves the same counters for the whole run, and the optional
web page (bridge/web) shows the same values, health and refusals, fed by ``feed``. A
clean stop (Ctrl-C, SIGTERM) sets every device's availability ``offline`` before
``bridge/state`` goes ``offline``; the demo (``remove_on_stop``) empties every retained
message it published. One bridge per base topic: before a connection says ``online``,
``check_alone`` (bridge/standby.py) checks that no other live bridge serves the topic
(else this one stands by without polling: bridge/core/instance.py), and a bridge that
comes up beside this one later is told apart by the ``bridge/info`` it publishes. Before
its first state, the first session of a run (and the first after standing by) reads the
device documents left retained, so counters and alarm events carry on across a restart
(bridge/carry_over.py).

The wiring: the parts call back into the bridge, and every callback is named in
``__init__`` and ``run``:

- a poll: ``Engine(on_update=_on_update)`` -> ``state.changed`` (bridge/state_publisher.py:
  dirty keys, then the device's JSON, plain values and availability, on change only) and
  ``feed.changed`` (the web page);
- a ``/set``: ``client.messages()`` in ``_session`` -> ``_handle`` -> ``_route`` ->
  ``dispatcher.handle``, which runs the write with ``spawn=_spawn`` (in the bridge's
  TaskGroup) and reports a refusal or failure with ``error=_error`` (-> ``state.queue``,
  the outbox, and the web page); the values the device acknowledged and read back come
  back as a poll's do, through ``_on_update``; a ``/get`` is read, then published with
  ``read=state.again`` (its state, changed or not);
- a management request: ``_route`` -> ``_request`` -> ``_answer`` -> ``_respond`` (->
  ``state.queue``); a reload: ``Management(on_reload=_reloaded)`` -> ``state.reloaded``;
  a ``mapping: sunspec`` device's mapping, built or rebuilt by ``management.sunspec``
  (bridge/sunspec_devices.py, run with the engine) -> ``Management.swap_mapping`` -> the
  same ``_reloaded``;
- a new config (the web page after it wrote the file, SIGHUP after it read it again):
  ``apply_config`` -> bridge/reconfigure.py, which starts, stops and restarts through the
  engine, the dispatcher (``between_commands``) and ``state.removed``/``state.reloaded``;
- the MQTT side: ``run_with_reconnect(session=_session, on_state=_mqtt_is)``; a session's
  publishing tasks are ``state.run``, ``state.refresh``, ``state.home_assistant_returns``
  and ``_health_reports``.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import logging
import time
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from bridge import __version__
from bridge.carry_over import carry_over
from bridge.config import LoadedConfig, MetricsConfig, load_config
from bridge.core.commands import check_size, error_document
from bridge.core.discovery import (
    Origin,
    Publish,
)
from bridge.core.health_report import HealthReporter, Snapshot
from bridge.core.instance import Instance, instance_of, taken_message
from bridge.core.management_request import response
from bridge.core.state import compact
from bridge.core.topics import Topics
from bridge.discovery_publisher import DiscoveryPublisher
from bridge.dispatcher import RETAINED, Dispatcher
from bridge.errors import ConfigError, ValueRejectedError, first_of
from bridge.management import Management
from bridge.modbus.engine import Engine
from bridge.modbus.poller import DeviceUpdate
from bridge.mqtt import (
    BaseTopicTakenError,
    Message,
    MqttClient,
    MqttError,
    run_with_reconnect,
)
from bridge.mqtt.reconnect import STANDBY_RETRY
from bridge.reconfigure import apply_config
from bridge.standby import check_alone
from bridge.state_publisher import StatePublisher
from bridge.subscriptions import Subscriptions, Wanted
from bridge.web import WebFeed, serve_web

if TYPE_CHECKING:
    from bridge.gateway import Gateway

log = logging.getLogger(__name__)
MAX_REQUESTS = 8  # management requests running at a time; more are answered "busy"


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
        self.feed = WebFeed()  # what the web page watches: value changes, refusals
        self.instance = Instance.new(time.time())
        # the callbacks, wired here and nowhere else (module docstring: the wiring)
        self.engine = Engine(loaded, self._on_update)
        self.discovery = DiscoveryPublisher(loaded, self.engine, self.topics, self.origin)
        self.management = Management(
            loaded,
            self.engine,
            on_reload=self._reloaded,
            mqtt_state=lambda: self.mqtt_state,
            instance=self.instance,
        )
        self.state = StatePublisher(
            self.engine,
            self.topics,
            self.mqtt,
            self.discovery,
            info=self.management.info,
            spawn=self._spawn,
        )
        self.dispatcher = Dispatcher(
            self.engine,
            self.mqtt.command_expiry,
            spawn=self._spawn,
            error=self._error,
            read=self.state.again,  # a /get: its state, changed or not
        )
        self.gateway = _gateway(loaded, self.engine, self.dispatcher)  # other Modbus masters
        self._requests = 0  # management requests running
        self._group: asyncio.TaskGroup | None = None
        self._health = HealthReporter()  # rates since the previous report
        # "online" while connected, "offline" between, "standby" while another bridge
        # serves the base topic
        self.mqtt_state = "connecting"
        self._rival: Instance | None = None  # a bridge that came up beside this one
        self._engine: asyncio.Task[None] | None = None
        # every subscription at QoS 0: the session is clean, so QoS 1 on the way to the
        # bridge would add only a redelivery (a command twice is worse than once lost)
        # and, on NATS, a JetStream consumer per subscription, which a cluster creates
        # slowly after a node failure while the connection's other packets wait
        # (docs/brokers.md, "On a cluster")
        self.subscriptions = Subscriptions(self._wanted(), 0)
        self._carry_over = True  # read what was left retained: a start, or after standby
        # requests beyond the management API, by command (the demo's "demo/fault")
        self.extra_requests: dict[str, Callable[[bytes], Awaitable[str]]] = {}

    # --- running ----------------------------------------------------------------------

    async def run(self) -> None:
        """Run until cancelled."""
        metrics = _metrics(self.loaded.config.bridge.metrics, self.engine.snapshot)
        web = serve_web(self.loaded.config.bridge.web, self)
        async with metrics, web, asyncio.TaskGroup() as group:
            self._group = group
            self._engine = group.create_task(self.engine.run(), name="engine")
            if self.gateway is not None:
                group.create_task(self.gateway.run(), name="gateway")
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
            Wanted(
                "commands",
                commands,
                "commands and requests do not reach the bridge",
                live_only=True,
                level=logging.ERROR,
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
        if state == "standby":
            self._carry_over = True  # the other bridge published meanwhile
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
        what was left retained is read back (at a start or after standing by: bridge/
        carry_over.py), commands are served, the state goes out, then ``online``, discovery
        and what publishes changes. A command that came before that waits in the
        connection's queue (or goes with it, standing by)."""
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
                if self._carry_over:  # within a run the bridge knows what it published
                    await carry_over(client, self.topics, self.engine, self.state)
                    self._carry_over = False
                self._polling()
                # from here on no command waits for the broker's acknowledgements: on a
                # cluster electing its leaders those took seconds, long enough for the
                # commands that came meanwhile to expire (bridge/dispatcher.py)
                serving = group.create_task(self._serve(client))
                # values, devices and info in one burst before ``online``: one round trip,
                # and on a broker that stores each retained message before it passes it on
                # (NATS), nothing of ``online``'s waits sits ahead of the values
                await self.state.everything(client, with_info=True)
                await client.announce()
                # discovery (its stale-config sweep at the first session only: it is a
                # retained read, seconds on a cluster) beside the commands, then what
                # publishes changes
                group.create_task(self._discovery_then_publishers(client, group))
                await serving
        except ExceptionGroup as failed:  # the MQTT error, so the reconnect loop sees it
            raise first_of(failed, MqttError) or failed from None
        finally:
            self.subscriptions.reset()  # nothing is held between sessions

    async def _serve(self, client: MqttClient) -> None:
        """Handle every message of the session; a rival's ``bridge/info`` ends it."""
        async for message in client.messages():
            self._handle(message)
            if self._rival is not None:
                raise BaseTopicTakenError(
                    taken_message(self.mqtt.base_topic, self._rival, STANDBY_RETRY)
                )

    async def _discovery_then_publishers(
        self, client: MqttClient, group: asyncio.TaskGroup
    ) -> None:
        """Discovery first (a change published before it would publish it a second
        time), then the tasks that publish changes, refreshes, republishes and health."""
        await self.discovery.publish(client, clear_stale=not self.discovery.swept)
        for work in (
            self.state.run,
            self.state.refresh,
            self.state.home_assistant_returns,
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
                "dropped": self.state.dropped,
            }
            report["process"] = {"tasks": len(asyncio.all_tasks()), "outbox": self.state.queued}
            if self.gateway is not None:
                report["gateway"] = self.gateway.health()
            await client.publish(self.topics.bridge_health, compact(report), retain=True)
            await asyncio.sleep(interval)

    # --- a poll ---------------------------------------------------------------------

    def _on_update(self, update: DeviceUpdate) -> None:
        """The engine's report of a poll that changed values: to the broker
        (bridge/state_publisher.py) and to the web page."""
        self.state.changed(update)
        self.feed.changed(update.device_id, update.changed)

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
                self.state.home_assistant_online()
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
            self.state.info_again()

    def _spawn(self, work: Any, failed: Callable[[str], None] | None = None) -> None:
        """Run a command's or request's work in the bridge's TaskGroup; whatever it raises
        is logged (and reported through ``failed``), never taken for the bridge's end. Once
        the bridge is stopping it is not started (a publish acknowledged during the stop
        asked for one: the stop ended with a RuntimeError)."""
        if self._group is None:
            raise RuntimeError("the bridge is not running")
        guarded = _guarded(work, failed)
        try:
            self._group.create_task(guarded)
        except RuntimeError:  # the bridge is stopping: its TaskGroup takes no new task
            guarded.close()
            if asyncio.iscoroutine(work):
                work.close()
            log.debug("the bridge is stopping: work not started")

    async def apply_config(self, new: LoadedConfig) -> dict[str, Any]:
        """Apply a new config while running: only what changed is started, stopped or
        restarted; what needs a restart is refused whole (bridge/reconfigure.py)."""
        return await apply_config(self, new)

    def hangup(self) -> None:
        """SIGHUP (``systemctl reload``, a closed terminal): read the config file again and
        apply what changed (``apply_config``; a file that does not load, or a change that
        needs a restart, is logged and changes nothing), then the mapping files, as
        ``bridge/request/mapping/reload`` with no devices does, and go on running."""
        log.info("SIGHUP: reading the config file and the mapping files again")
        if self._group is not None:
            self._spawn(self._reload_all())

    async def _reload_all(self) -> None:
        path = self.loaded.path
        if path.is_file():  # not the demo's config, built in memory
            try:
                new = await asyncio.to_thread(load_config, path)
            except ConfigError as exc:
                log.error("SIGHUP: the config file is not applied, nothing changed: %s", exc)
            else:
                answer = await self.apply_config(new)
                if answer["status"] == "ok":
                    log.info("SIGHUP: config changes: %s", answer["description"])
        await self._reload_mappings()

    async def _reload_mappings(self) -> None:
        answer = json.loads(await self.management.handle("mapping/reload", b"{}"))
        if answer["status"] == "ok":
            log.info("SIGHUP: mappings changed: %s", answer["data"]["changed"] or "none")
        else:
            log.error("SIGHUP: mappings not reloaded: %s", answer["error"])

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
        self.state.queue(Publish(self.topics.bridge_response(command), answer, retain=False))

    async def _reloaded(self, device_ids: list[str]) -> None:
        log.info("mappings reloaded for %s", ", ".join(device_ids))
        self.state.reloaded(device_ids)

    def _error(self, device_id: str, key: str | None, value: object, error: str) -> None:
        payload = error_document(key, value, error)
        log.info("%s refused: %s", device_id[:100], payload)
        self.state.queue(Publish(self.topics.error(device_id), payload, retain=False))
        self.feed.refused_command(device_id, payload)


def _gateway(loaded: LoadedConfig, engine: Engine, dispatcher: Dispatcher) -> Gateway | None:
    """The Modbus TCP server for other masters, if enabled (pymodbus' server is imported
    only then: a bridge without it starts as fast as before)."""
    if not loaded.config.bridge.gateway.enabled:
        return None
    from bridge.gateway import Gateway  # noqa: PLC0415

    return Gateway(loaded, engine, dispatcher)


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
