"""What changes between the running config and a new one, and what that takes to apply.

``diff_configs(old, new)`` compares two ``ConfigView``s (built by the edge from a loaded
config: bridge/reconfigure.py) and answers a ``ConfigDiff``: the settings that only a
restart applies (``restart``: the MQTT, web and gateway settings), the buses to start,
stop and restart, and the devices to start, stop and restart. A device is polled when it
is configured and enabled; one that stops being polled is ``removed`` (gone from the
config) or ``disabled`` (kept there), one that starts is ``added`` or ``enabled``. A
polled device whose settings or mapping changed, or whose bus is restarted, is
``restarted``; an id change is the old id removed and the new one added. Values are
compared with ``==`` only: the core knows no config model.
"""

from __future__ import annotations

from collections.abc import Iterable
from collections.abc import Mapping as Lookup
from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class DeviceView:
    """One configured device as the diff sees it: its bus, whether it is polled, and what
    its poller is built from (its settings and its mapping, compared whole)."""

    bus: str
    enabled: bool
    settings: object
    mapping: object


@dataclass(frozen=True, slots=True)
class ConfigView:
    """A config as the diff sees it: the restart-only settings by dotted name
    (``mqtt.url``, ``bridge.web``), the buses by id and the devices by id."""

    settings: Lookup[str, object] = field(default_factory=dict)
    buses: Lookup[str, object] = field(default_factory=dict)
    devices: Lookup[str, DeviceView] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class ConfigDiff:
    """What applying a new config takes; every tuple sorted."""

    restart: tuple[str, ...] = ()  # settings only a restart applies
    buses_added: tuple[str, ...] = ()
    buses_removed: tuple[str, ...] = ()
    buses_restarted: tuple[str, ...] = ()
    added: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()
    enabled: tuple[str, ...] = ()
    disabled: tuple[str, ...] = ()
    restarted: tuple[str, ...] = ()

    @property
    def stopped(self) -> tuple[str, ...]:
        """Devices no longer polled (removed or disabled): their retained topics cleared."""
        return tuple(sorted(self.removed + self.disabled))

    @property
    def started(self) -> tuple[str, ...]:
        """Devices polled from now on that were not (added or enabled)."""
        return tuple(sorted(self.added + self.enabled))

    @property
    def empty(self) -> bool:
        """Nothing to apply and nothing refused."""
        return not any(getattr(self, name) for name in self.__slots__)

    def summary(self) -> dict[str, list[str]]:
        """The non-empty parts by name (for the log and the answer)."""
        parts = {name: list(getattr(self, name)) for name in self.__slots__}
        return {name: ids for name, ids in parts.items() if ids}

    def describe(self) -> str:
        """One line: ``devices added: a, b; buses restarted: rs485`` (or ``nothing``)."""
        words = {
            "restart": "needs a restart",
            "buses_added": "buses added",
            "buses_removed": "buses removed",
            "buses_restarted": "buses restarted",
            "added": "devices added",
            "removed": "devices removed",
            "enabled": "devices enabled",
            "disabled": "devices disabled",
            "restarted": "devices restarted",
        }
        parts = [f"{words[name]}: {', '.join(ids)}" for name, ids in self.summary().items()]
        return "; ".join(parts) or "nothing"


def diff_configs(old: ConfigView, new: ConfigView) -> ConfigDiff:
    """What turns the running ``old`` into ``new`` (see the module docstring)."""
    bus_ids = old.buses.keys() | new.buses.keys()
    buses_restarted = _ids(
        b for b in bus_ids if b in old.buses and b in new.buses and old.buses[b] != new.buses[b]
    )
    polled_before = {d for d, view in old.devices.items() if view.enabled}
    polled_now = {d for d, view in new.devices.items() if view.enabled}
    restarted = _ids(
        d
        for d in polled_before & polled_now
        if _device_changed(old.devices[d], new.devices[d]) or new.devices[d].bus in buses_restarted
    )
    return ConfigDiff(
        restart=_ids(
            name
            for name in old.settings.keys() | new.settings.keys()
            if old.settings.get(name, _ABSENT) != new.settings.get(name, _ABSENT)
        ),
        buses_added=_ids(new.buses.keys() - old.buses.keys()),
        buses_removed=_ids(old.buses.keys() - new.buses.keys()),
        buses_restarted=buses_restarted,
        added=_ids(d for d in polled_now - polled_before if d not in old.devices),
        removed=_ids(d for d in polled_before - polled_now if d not in new.devices),
        enabled=_ids(d for d in polled_now - polled_before if d in old.devices),
        disabled=_ids(d for d in polled_before - polled_now if d in new.devices),
        restarted=restarted,
    )


_ABSENT = object()  # a setting one side does not have


def _device_changed(old: DeviceView, new: DeviceView) -> bool:
    return (old.bus, old.settings, old.mapping) != (new.bus, new.settings, new.mapping)


def _ids(ids: Iterable[str]) -> tuple[str, ...]:
    return tuple(sorted(ids))
