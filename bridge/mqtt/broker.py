"""An MQTT broker inside the process, for the zero-setup demo (amqtt, the ``demo`` extra).

``embedded_broker(host, port)`` serves MQTT 3.1.1 on loopback for the duration of the
block and yields its URL. amqtt does not answer an MQTT 5 CONNECT at all (no CONNACK
with "unsupported protocol version" to fall back on), so clients of it must be set to
3.1.1. Only this module imports amqtt.

Two faults of amqtt 0.12 (the newest) are worked around here, in our use of it:

* A QoS 0 PUBLISH followed at once by DISCONNECT (``mosquitto_pub`` without ``-q``) was
  lost: the connection's reader hands each packet to a task of its own and, at the end
  of the stream, cancels the tasks that have not run yet, the PUBLISH's among them. When
  the three arrive together (the broker was busy, e.g. sending retained messages), the
  message never reached anyone. Here a QoS 0 PUBLISH is queued for delivery as it is
  read (QoS 1 and 2 are acknowledged, so their clients wait and were never lost).
* On connecting, every client got the retained messages matching any subscription of
  any client (the broker's whole list, not the client's own): each ``mosquitto_sub``
  received the bridge's discovery configs, whatever it subscribed to. Here the retained
  messages of a subscription go only to the session that holds it.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

from bridge.errors import BridgeError

PROTOCOL = "3.1.1"


class BrokerUnavailableError(BridgeError):
    """The embedded broker cannot run (extra not installed, port taken)."""


@contextlib.asynccontextmanager
async def embedded_broker(host: str, port: int) -> AsyncIterator[str]:
    """Run an anonymous broker on ``host:port``; yield ``mqtt://host:port``."""
    try:
        from amqtt.errors import BrokerError  # noqa: PLC0415 - optional extra, loaded on demand
    except ImportError:
        raise BrokerUnavailableError(
            "no MQTT broker answers and the embedded one needs the demo extra: "
            "pip install 'modbus-mqtt-bridge[demo]' (make demo does it)"
        ) from None
    for name in ("amqtt", "transitions"):
        logging.getLogger(name).setLevel(logging.CRITICAL)  # it would flood the demo
    broker = _broker_class()(
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


def _broker_class() -> type[Any]:
    """amqtt's Broker with the two faults of the module docstring worked around."""
    from amqtt.broker import Broker  # noqa: PLC0415 - optional extra, loaded on demand

    class DemoBroker(Broker):  # type: ignore[misc] # amqtt has no type information
        async def _handle_client_session(self, *args: Any) -> None:
            _, _, _, handler, *_ = args  # reader, writer, session, handler, server, listener
            handler.handle_publish = _queue_qos0_at_once(handler)
            await super()._handle_client_session(*args)

        async def _publish_retained_messages_for_subscription(
            self, subscription: tuple[str, int], session: Any
        ) -> None:
            holders = self.subscriptions.get(subscription[0], ())
            if any(holder is session for holder, _ in holders):
                await super()._publish_retained_messages_for_subscription(subscription, session)

    return DemoBroker


def _queue_qos0_at_once(handler: Any) -> Callable[[Any], Awaitable[None]]:
    """``handler.handle_publish`` that queues a QoS 0 message for delivery when called (the
    reader calls it as it reads the packet, and may cancel what it returns unstarted)."""
    from amqtt.session import IncomingApplicationMessage  # noqa: PLC0415

    original: Callable[[Any], Awaitable[None]] = handler.handle_publish

    def handle_publish(packet: Any) -> Awaitable[None]:
        session = handler.session
        if packet.qos or packet.dup_flag or session is None or packet.topic_name is None:
            return original(packet)  # the library's own flow (and its refusals)
        message = IncomingApplicationMessage(
            None, packet.topic_name, 0, packet.data or b"", packet.retain_flag
        )
        message.publish_packet = packet
        session.delivered_message_queue.put_nowait(message)
        return _done()

    return handle_publish


async def _done() -> None:
    """Nothing left to do."""
