"""MQTT topic names of the contract in DESIGN.md, and parsing of command topics. Pure.

<base>/bridge/state              online/offline (retained, also the LWT)
<base>/bridge/devices            JSON list of devices (retained)
<base>/bridge/info               version, config without secrets, schemas, mappings (retained)
<base>/bridge/health             per bus and per device counters (periodic)
<base>/bridge/discovery          JSON list of the discovery topics published (retained)
<base>/bridge/request/<cmd>      management request: JSON with an optional transaction
<base>/bridge/response/<cmd>     {status, data, error, transaction}
<base>/<device>                  JSON of every value by key (retained)
<base>/<device>/<key>            the plain value (retained)
<base>/<device>/availability     online/offline (retained)
<base>/<device>/set              JSON {key: value} command
<base>/<device>/<key>/set        plain value command
<base>/<device>/get              read now: empty or JSON {key: ""}
<base>/<device>/error            JSON {key, value, error} (not retained)
<prefix>/status                  Home Assistant's birth/will: online/offline
<prefix>/device/<device>/config  device-based discovery (retained)
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

RESERVED_DEVICE_IDS = frozenset({"bridge"})


class Action(StrEnum):
    SET = "set"
    GET = "get"


@dataclass(frozen=True, slots=True)
class CommandTopic:
    """What a command topic addresses: a device, maybe one key, and set or get."""

    device_id: str
    key: str | None
    action: Action


@dataclass(frozen=True, slots=True)
class Topics:
    base: str
    discovery_prefix: str = "homeassistant"

    @property
    def bridge_state(self) -> str:
        return f"{self.base}/bridge/state"

    @property
    def bridge_devices(self) -> str:
        return f"{self.base}/bridge/devices"

    @property
    def bridge_info(self) -> str:
        return f"{self.base}/bridge/info"

    @property
    def bridge_health(self) -> str:
        return f"{self.base}/bridge/health"

    @property
    def bridge_discovery(self) -> str:
        """The discovery topics this bridge published (to empty them once gone)."""
        return f"{self.base}/bridge/discovery"

    @property
    def bridge_requests(self) -> str:
        """Subscription filter for every management request."""
        return f"{self.base}/bridge/request/#"

    def bridge_request(self, command: str) -> str:
        return f"{self.base}/bridge/request/{command}"

    def bridge_response(self, command: str) -> str:
        return f"{self.base}/bridge/response/{command}"

    def parse_request(self, topic: str) -> str | None:
        """The management command of a request topic (``device/read``), else None."""
        prefix = f"{self.base}/bridge/request/"
        if not topic.startswith(prefix) or topic == prefix:
            return None
        return topic[len(prefix) :]

    @property
    def ha_status(self) -> str:
        return f"{self.discovery_prefix}/status"

    def device(self, device_id: str) -> str:
        return f"{self.base}/{device_id}"

    def value(self, device_id: str, key: str) -> str:
        return f"{self.base}/{device_id}/{key}"

    def availability(self, device_id: str) -> str:
        return f"{self.base}/{device_id}/availability"

    def set(self, device_id: str, key: str | None = None) -> str:
        return f"{self.base}/{device_id}/{key}/set" if key else f"{self.base}/{device_id}/set"

    def get(self, device_id: str) -> str:
        return f"{self.base}/{device_id}/get"

    def error(self, device_id: str) -> str:
        return f"{self.base}/{device_id}/error"

    def event(self, device_id: str) -> str:
        """Alarms raised and cleared, one JSON message per transition (not retained)."""
        return f"{self.base}/{device_id}/event"

    def device_config(self, device_id: str) -> str:
        return f"{self.discovery_prefix}/device/{device_id}/config"

    def entity_config(self, component: str, device_id: str, key: str) -> str:
        return f"{self.discovery_prefix}/{component}/{device_id}/{key}/config"

    def command_filters(self) -> tuple[str, ...]:
        """Subscriptions for every command topic (live messages only: see DESIGN.md)."""
        base = self.base
        return (f"{base}/+/set", f"{base}/+/+/set", f"{base}/+/get")

    def parse_command(self, topic: str) -> CommandTopic | None:
        """The command a topic carries, or None for any other topic."""
        prefix = f"{self.base}/"
        if not topic.startswith(prefix):
            return None
        parts = topic[len(prefix) :].split("/")
        if len(parts) == 2 and parts[1] in (Action.SET, Action.GET):
            device_id, key, action = parts[0], None, Action(parts[1])
        elif len(parts) == 3 and parts[2] == Action.SET:
            device_id, key, action = parts[0], parts[1], Action.SET
        else:
            return None
        if not device_id or device_id in RESERVED_DEVICE_IDS or key == "":
            return None
        return CommandTopic(device_id, key, action)
