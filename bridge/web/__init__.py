"""The web page for the people at the cabinet (``bridge.web``, off by default).

Devices and their values live, bus health, refused commands, commissioning (scan, raw
read and write through bridge/management.py) and the loaded config, served by the bridge
itself on its own event loop: a few static files shipped in the wheel (no build step, no
framework, no CDN) over a JSON and Server-Sent-Events API (bridge/web/server.py).

``serve_web(settings, bridge)`` is an async context manager: with ``settings.enabled`` it
listens on ``settings.host:settings.port`` for the duration of the block, and stops
listening (ending open event streams) when the block ends. An address that cannot be
bound raises OSError naming it before anything else starts. With the page off, nothing
of it is imported but ``WebFeed``, which the bridge feeds either way (it costs nothing
while nobody watches).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator
from typing import TYPE_CHECKING

from bridge.config import WebConfig
from bridge.web.live import WebFeed

if TYPE_CHECKING:
    from bridge.web.parts import BridgeState

__all__ = ["WebFeed", "serve_web"]
log = logging.getLogger(__name__)


@contextlib.asynccontextmanager
async def serve_web(settings: WebConfig, bridge: BridgeState) -> AsyncIterator[None]:
    """Serve the page for the duration of the block when ``settings.enabled``."""
    if not settings.enabled:
        yield
        return
    from bridge.web.access import Access  # noqa: PLC0415 - only when on
    from bridge.web.http import listening  # noqa: PLC0415
    from bridge.web.server import WebApp, load_static  # noqa: PLC0415

    app = WebApp(bridge, Access.of(settings), load_static())
    await app.config_file.open()  # as the bridge read it: a later change on disk is seen
    async with listening(app.handle, settings.host, settings.port, "web page"):
        log.info("web page on %s", page_url(settings))
        yield


def page_url(settings: WebConfig) -> str:
    """Where a browser on this machine (or, for 0.0.0.0, on the network) opens the page."""
    host = settings.host
    if host in ("0.0.0.0", "::", ""):  # noqa: S104 - naming the wildcard, not binding it
        host = "127.0.0.1"
    elif ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{settings.port}/"
