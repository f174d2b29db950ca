"""An MQTT broker inside the process, for the zero-setup demo (amqtt, the ``demo`` extra).

``embedded_broker(host, port)`` serves MQTT 3.1.1 on loopback for the duration of the
block and yields its URL. amqtt does not answer an MQTT 5 CONNECT at all (no CONNACK
with "unsupported protocol version" to fall back on), so clients of it must be set to
3.1.1. Only this module imports amqtt.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator

from bridge.errors import BridgeError

PROTOCOL = "3.1.1"


class BrokerUnavailableError(BridgeError):
    """The embedded broker cannot run (extra not installed, port taken)."""


@contextlib.asynccontextmanager
async def embedded_broker(host: str, port: int) -> AsyncIterator[str]:
    """Run an anonymous broker on ``host:port``; yield ``mqtt://host:port``."""
    try:
        from amqtt.broker import Broker  # noqa: PLC0415 - optional extra, loaded on demand
        from amqtt.errors import BrokerError  # noqa: PLC0415
    except ImportError:
        raise BrokerUnavailableError(
            "no MQTT broker answers and the embedded one needs the demo extra: "
            "pip install 'modbus-mqtt-bridge[demo]' (make demo does it)"
        ) from None
    for name in ("amqtt", "transitions"):
        logging.getLogger(name).setLevel(logging.CRITICAL)  # it would flood the demo
    broker = Broker(
        {
            "listeners": {"default": {"type": "tcp", "bind": f"{host}:{port}"}},
            "plugins": {
                "amqtt.plugins.authentication.AnonymousAuthPlugin": {"allow_anonymous": True}
            },
        }
    )
    try:
        await broker.start()
    except BrokerError as exc:  # amqtt wraps socket errors in it
        raise BrokerUnavailableError(f"cannot start the embedded broker: {exc}") from None
    try:
        yield f"mqtt://{host}:{port}"
    finally:
        await broker.shutdown()
