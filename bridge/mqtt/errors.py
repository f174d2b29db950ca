"""The MQTT branch of the exception tree (under ``bridge.errors.BridgeError``).

    BridgeError
    └── MqttError                   talking to the broker did not succeed
        ├── MqttConnectError        no session was established: the broker is unreachable,
        │   │                       the TLS handshake or certificate check failed, or the
        │   │                       broker refused the CONNECT (bad user name or password,
        │   │                       not authorised, protocol); ``code`` is the MQTT 5 CONNACK
        │   │                       reason code when the broker answered (3.1.1 codes are
        │   │                       translated: 4 -> 134), else None; ``refused``: the
        │   │                       code refuses this client's login (LOGIN_REFUSED), not
        │   │                       a passing state of the broker (busy, unavailable, quota)
        │   └── MqttUnansweredError the broker took the connection but sent no CONNACK in
        │                           time (or closed it): amqtt does so for MQTT 5
        ├── MqttDisconnectedError   an established session was lost (socket closed, keepalive
        │                           expired, broker restarted) or an operation on it timed out
        ├── MqttRefusedError        the broker answered a SUBSCRIBE with a failure code (an
        │   │                       ACL); the session itself is fine
        │   └── MqttUnackedError    ...or did not answer it in time (a cluster creating its
        │                           consumers); the session itself is fine
        ├── BaseTopicTakenError     another bridge serves the same base topic: this one left
        │                           the broker without a word (no will) and stands by
        └── MqttPublishError        one message cannot be published (a topic MQTT does not
                                    allow, a payload beyond 256 MB); the session is fine

``run_with_reconnect`` retries after MqttConnectError and MqttDisconnectedError (bare or
inside an ExceptionGroup from the session's TaskGroup), and after BaseTopicTakenError
every ``STANDBY_RETRY`` seconds; every other error propagates.
"""

from __future__ import annotations

from bridge.errors import BridgeError

# CONNACK reason codes refusing the login or the client: 0x85 client identifier not valid,
# 0x86 bad user name or password, 0x87 not authorised, 0x8A banned, 0x8C bad authentication
# method (paho translates the 3.1.1 return codes 2, 4 and 5 to 0x85, 0x86 and 0x87)
LOGIN_REFUSED = frozenset({0x85, 0x86, 0x87, 0x8A, 0x8C})


class MqttError(BridgeError):
    """Talking to the MQTT broker did not succeed."""


class MqttConnectError(MqttError):
    """No MQTT session could be established (unreachable, TLS, refused CONNACK)."""

    def __init__(self, message: str, code: int | None = None) -> None:
        self.code = code
        super().__init__(message)

    @property
    def refused(self) -> bool:
        """The broker refused this client's login; retrying soon will not change that."""
        return self.code in LOGIN_REFUSED


class MqttUnansweredError(MqttConnectError):
    """The connection was made and CONNECT sent, but no CONNACK came (a broker that
    ignores or drops a CONNECT of a protocol version it does not speak)."""


class MqttDisconnectedError(MqttError):
    """An established MQTT session was lost or an operation on it timed out."""


class MqttRefusedError(MqttError):
    """The broker refused a subscription (typically an ACL)."""


class MqttPublishError(MqttError):
    """One message cannot be published (invalid topic, payload too large); nothing sent."""


class BaseTopicTakenError(MqttError):
    """Another bridge serves this base topic; the message says which and what to do."""


class MqttUnackedError(MqttRefusedError):
    """The broker did not acknowledge a subscription in time; the session is fine."""
