"""What the page's routes read from the running bridge: ``BridgeParts`` (its config, its
engine and management: what adding a device and an entity need) and ``BridgeState``
(everything the page shows and changes, bridge/web/server.py)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

from bridge.config import LoadedConfig
from bridge.core.topics import Topics
from bridge.management import Management
from bridge.modbus.engine import Engine
from bridge.web.live import WebFeed

if TYPE_CHECKING:
    from bridge.gateway import Gateway


class BridgeParts(Protocol):
    """The config, engine and management of the running bridge."""

    @property
    def loaded(self) -> LoadedConfig: ...
    @property
    def engine(self) -> Engine: ...
    @property
    def management(self) -> Management: ...


class BridgeState(BridgeParts, Protocol):
    """What the page reads from the running bridge, and the live apply of a config."""

    @property
    def topics(self) -> Topics: ...
    @property
    def feed(self) -> WebFeed: ...
    @property
    def gateway(self) -> Gateway | None: ...
    @property
    def mqtt_state(self) -> str: ...
    @property
    def mqtt_subscriptions(self) -> dict[str, str]: ...
    async def apply_config(self, new: LoadedConfig) -> dict[str, Any]: ...
