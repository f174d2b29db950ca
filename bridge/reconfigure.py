"""A new config applied to the running bridge: only what changed is started, stopped or
restarted; every other bus and device keeps polling, its state and counters untouched.

``await bridge.apply_config(new)`` (``new`` as ``bridge.config.load_config`` or
``load_config_data`` returns it, so validated as ``check`` validates) is what the web page
calls after the config store wrote the file, and SIGHUP after it read the file again. It
answers a dict:

- ``{"status": "ok", "changes": {...}, "description": "devices added: well"}``: applied;
  ``changes`` holds the non-empty parts of the diff by name (``added``, ``removed``,
  ``enabled``, ``disabled``, ``restarted``, ``buses_added``, ``buses_removed``,
  ``buses_restarted``); an empty ``changes`` changed nothing running;
- ``{"status": "refused", "error": "...", "restart": [...]}``: nothing changed, because
  part of it needs a restart: a setting of the ``mqtt`` or ``bridge`` sections (web,
  gateway, metrics, ...), each named in ``restart`` (``mqtt.base_topic``, ``bridge.web``).

The diff (bridge/core/config_diff.py) is found and checked whole before anything
changes. Then, one config (or mapping reload) at a time:

1. devices no longer polled (removed, or ``enabled: false``): each once its command
   running ends (a write of several registers is never cut in half; the commands after it
   are answered "no such device"), its polling stopped, its discovery configs and retained
   topics emptied (bridge/state_publisher.py ``removed``: as the demo empties its own at
   Ctrl-C);
2. buses added: their scheduler started; buses changed: their devices' polling and their
   scheduler stopped, the port closed, a new scheduler started;
3. devices changed (name, unit, intervals, ``allow_dangerous_writes``, mapping, protocol
   overrides, bus), or on a restarted bus: their poller started afresh between two
   commands, as a mapping reload does (``Engine.replace_mapping``: the guard and the
   counters' published values carry over);
4. devices added or enabled: a poller each; a device polled before under the same id in
   this run keeps its guard (a guard only grows: a register a mapping guarded stays
   guarded; ``allow_dangerous_writes`` is the only switch);
5. a ``mapping: sunspec`` device's walks (bridge/sunspec_devices.py) are stopped before
   it is stopped or restarted, and started again once it is started or restarted: its
   chain checked against its cache, or walked and built, as at a start;
6. buses no device uses any more: stopped;
7. the config is the new one for management, the web page and the gateway's routes, and
   info, discovery and state are published again (``StatePublisher.reloaded``).
"""

from __future__ import annotations

import contextlib
import logging
from typing import TYPE_CHECKING, Any, Protocol

from bridge.config import LoadedConfig, MqttConfig
from bridge.config.model import ManagementConfig
from bridge.core.config_diff import ConfigDiff, ConfigView, DeviceView, diff_configs
from bridge.core.topics import Topics
from bridge.discovery_publisher import DiscoveryPublisher
from bridge.dispatcher import Dispatcher
from bridge.management import Management
from bridge.modbus.engine import Engine
from bridge.state_publisher import StatePublisher

if TYPE_CHECKING:
    from bridge.gateway import Gateway

log = logging.getLogger(__name__)
SUNSPEC_BUILT = "sunspec"  # a SunSpec device's mapping is built at run time: not compared


class Bridge(Protocol):
    """The parts of the running bridge (bridge/app.py) a new config changes."""

    loaded: LoadedConfig
    mqtt: MqttConfig
    topics: Topics
    engine: Engine
    discovery: DiscoveryPublisher
    management: Management
    state: StatePublisher
    dispatcher: Dispatcher
    gateway: Gateway | None


def view_of(loaded: LoadedConfig) -> ConfigView:
    """What the diff compares of a loaded config."""
    config = loaded.config
    settings: dict[str, object] = {
        f"mqtt.{name}": getattr(config.mqtt, name) for name in MqttConfig.model_fields
    }
    settings |= {
        f"bridge.{name}": getattr(config.bridge, name) for name in ManagementConfig.model_fields
    }
    devices = {
        d.id: DeviceView(
            bus=d.bus,
            enabled=d.enabled,
            settings=d,
            mapping=SUNSPEC_BUILT if d.is_sunspec else loaded.mappings.get(d.id),
        )
        for d in config.devices
    }
    return ConfigView(settings=settings, buses={b.id: b for b in config.buses}, devices=devices)


def refusal(diff: ConfigDiff) -> list[str]:
    """What of the diff needs a restart (nothing changes when anything does)."""
    return list(diff.restart)


async def apply_config(bridge: Bridge, new: LoadedConfig) -> dict[str, Any]:
    """Apply ``new`` to the running bridge (see the module docstring)."""
    async with bridge.management.reloading:
        old = bridge.loaded
        diff = diff_configs(view_of(old), view_of(new))
        restart = refusal(diff)
        if restart:
            error = "nothing changed: these need a restart of the bridge: " + ", ".join(restart)
            log.error("config not applied: %s", error)
            return {"status": "refused", "error": error, "restart": restart}
        merged = LoadedConfig(path=new.path, config=new.config, mappings=dict(new.mappings))
        for d in new.config.devices:  # a built SunSpec mapping stays as built
            if d.is_sunspec and d.id in old.mappings:
                merged.mappings[d.id] = old.mappings[d.id]
        await _apply(bridge, diff, merged)
        _install(bridge, merged)
        if not diff.empty:
            bridge.state.reloaded(list(diff.started + diff.restarted))
        log.info("config applied: %s", diff.describe())
        return {"status": "ok", "changes": diff.summary(), "description": diff.describe()}


async def _apply(bridge: Bridge, diff: ConfigDiff, new: LoadedConfig) -> None:
    engine = bridge.engine
    devices = {d.id: d for d in new.config.devices}
    buses = {b.id: b for b in new.config.buses}
    for device_id in diff.stopped + diff.restarted:  # no walk under a poller that changes
        await bridge.management.sunspec.stop(device_id)
    for device_id in diff.stopped:
        await _stop(bridge, device_id)
    for bus_id in diff.buses_added:
        engine.add_bus(buses[bus_id])
    restarted = set(diff.restarted)
    for bus_id in diff.buses_restarted:
        on_bus = sorted(d for d in restarted if engine.devices[d].device.bus == bus_id)
        async with contextlib.AsyncExitStack() as held:
            for device_id in on_bus:
                await held.enter_async_context(bridge.dispatcher.between_commands(device_id))
            await engine.restart_bus(buses[bus_id])
            for device_id in on_bus:
                await engine.replace_mapping(device_id, new.mappings[device_id], devices[device_id])
        restarted -= set(on_bus)
    for device_id in sorted(restarted):
        async with bridge.dispatcher.between_commands(device_id):
            await engine.replace_mapping(device_id, new.mappings[device_id], devices[device_id])
    for device_id in diff.started:
        engine.add_device(devices[device_id], new.mappings[device_id])
        bridge.state.restored(device_id)
    for device_id in diff.started + diff.restarted:
        if devices[device_id].is_sunspec:  # its chain walked (again) as at a start
            bridge.management.sunspec.start(device_id)
    for bus_id in diff.buses_removed:
        await engine.remove_bus(bus_id)


async def _stop(bridge: Bridge, device_id: str) -> None:
    """A device no longer polled, between two of its commands; its topics emptied."""
    async with bridge.dispatcher.between_commands(device_id):
        poller = await bridge.engine.remove_device(device_id)
    topics = bridge.topics
    listed: list[str] = []
    if bridge.mqtt.discovery != "off":
        listed += [m.topic for m in bridge.discovery.discovery_for(poller)]
    bridge.discovery.forget(device_id)
    listed += [topics.device(device_id), topics.availability(device_id)]
    if bridge.mqtt.output != "json":
        listed += [topics.value(device_id, key) for key in sorted(poller.state.published)]
    bridge.state.removed(device_id, listed)


def _install(bridge: Bridge, new: LoadedConfig) -> None:
    """The new config for everything that reads it while the bridge runs."""
    bridge.loaded = new
    bridge.management.loaded = new
    bridge.management.sunspec.loaded = new
    if bridge.gateway is not None:
        from bridge.gateway import routes_of  # noqa: PLC0415 (loaded only with the gateway)

        bridge.gateway.loaded = new
        bridge.gateway.routes = routes_of(new)
