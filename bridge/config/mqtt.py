"""The ``mqtt`` section of the config file: the broker (or brokers) and how to log in,
TLS, topic prefixes, what a device publishes. Credentials given in a URL
(``mqtt://user:pass@host``) move to their fields, so no log line ever shows them.
"""

from __future__ import annotations

import re
from typing import Any, Literal, Self
from urllib.parse import unquote, urlsplit

from pydantic import Field, SecretStr, field_validator, model_validator

from bridge.config.field import FilePath, Strict, one_source, secret_of
from bridge.core.duration import Duration

_TOPIC_FORBIDDEN = re.compile(r"[#+\x00]")
MAX_PREFIX_BYTES = 1024  # base_topic, discovery_prefix: room left for device, entity, suffix


def _without_credentials(url: str) -> tuple[str, str | None, str | None]:
    """The URL without ``user:password@``, and the user and password it gave (decoded)."""
    parts = urlsplit(url)
    user, password, port = parts.username, parts.password, parts.port
    if user is None:
        return url, None, None
    host = parts.hostname or ""
    netloc = (f"[{host}]" if ":" in host else host) + (f":{port}" if port else "")
    decoded = unquote(password) if password is not None else None
    return parts._replace(netloc=netloc).geturl(), unquote(user), decoded


MAX_BROKERS = 16  # broker URLs in mqtt.url


class TlsConfig(Strict):
    """TLS for mqtts://: CA bundle, optional client certificate, or no verification."""

    ca: FilePath | None = None
    cert: FilePath | None = None
    key: FilePath | None = None
    insecure: bool = Field(False, description="skip certificate verification (testing only)")


class MqttConfig(Strict):
    url: str | list[str] = "mqtt://127.0.0.1:1883"
    url_order: Literal["in_order", "random"] = Field(
        "in_order",
        description="with several broker URLs: the next one after a failure, or a random one",
    )
    base_topic: str = "modbus"
    discovery_prefix: str = "homeassistant"
    discovery: Literal["device", "entity", "off"] = Field(
        "device", description="device-based discovery, per-entity (older HA), or none"
    )
    client_id: str | None = None
    username: str | None = None
    password: SecretStr | None = None
    password_file: FilePath | None = None
    password_env: str | None = None
    tls: TlsConfig | None = None
    version: Literal["5", "3.1.1"] = Field("5", description="MQTT 5, falls back to 3.1.1")
    keepalive: Duration = Field(60.0, ge=1, le=65535, description="MQTT keepalive, 1..65535 s")
    qos: Literal[0, 1, 2] = 1
    output: Literal["json", "values", "both"] = Field(
        "json",
        description=(
            "what a device publishes: its JSON document (<base>/<device>, what Home "
            "Assistant and the Node-RED example read), a plain topic per value "
            "(<base>/<device>/<key>), or both (about 1 + changed values messages per poll); "
            "values alone needs discovery: off"
        ),
    )
    state_refresh: Duration = Field(300.0, gt=0, description="republish every value this often")
    command_expiry: Duration = Field(5.0, gt=0, description="drop commands not executed in time")

    @model_validator(mode="before")
    @classmethod
    def _credentials_from_url(cls, data: Any) -> Any:
        """``mqtt://user:pass@host`` logs in as user with pass; the URL keeps only the
        host, so no log line, error or ``bridge/info`` ever shows the password."""
        url = data.get("url") if isinstance(data, dict) else None
        urls: list[Any] = url if isinstance(url, list) else [url]
        texts = [u for u in urls if isinstance(u, str)]
        if len(texts) != len(urls) or not any("@" in u for u in texts):
            return data
        try:
            found = [_without_credentials(u) for u in texts]
        except ValueError:
            return data  # _check_url names the problem
        logins = {(user, password) for _, user, password in found if user is not None}
        if not logins:
            return data
        if len(logins) > 1 or any(user is None for _, user, _ in found):
            raise ValueError("url: the brokers of a list take the same user and password")
        ((user, password),) = logins
        if data.get("username") is not None or (
            password is not None
            and any(data.get(k) is not None for k in ("password", "password_file", "password_env"))
        ):
            raise ValueError(
                "url: give the user and password in the URL or in their fields, not both"
            )
        bare = [u for u, _, _ in found]
        moved = {**data, "url": bare if isinstance(url, list) else bare[0], "username": user}
        if password is not None:
            moved["password"] = password
        return moved

    @field_validator("url")
    @classmethod
    def _check_url(cls, url: str | list[str]) -> str | list[str]:
        urls = url if isinstance(url, list) else [url]
        if not 1 <= len(urls) <= MAX_BROKERS:
            raise ValueError(f"give 1 to {MAX_BROKERS} broker URLs")
        for each in urls:
            parts = urlsplit(each)
            if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
                which = f"{each!r}: " if isinstance(url, list) else ""
                raise ValueError(f"{which}use mqtt://host[:port] or mqtts://host[:port]")
        if len({urlsplit(u).scheme for u in urls}) > 1:
            raise ValueError("the brokers of a list all use mqtt:// or all mqtts://")
        return url

    @field_validator("base_topic", "discovery_prefix")
    @classmethod
    def _check_topic(cls, topic: str) -> str:
        if not topic or topic.startswith("/") or topic.endswith("/"):
            raise ValueError("a topic prefix is non-empty and has no leading or trailing '/'")
        if _TOPIC_FORBIDDEN.search(topic):
            raise ValueError("a topic prefix cannot contain '#', '+' or NUL")
        if topic.startswith("$"):
            raise ValueError("topics starting with '$' belong to the broker ($SYS); drop the '$'")
        if len(topic.encode("utf-8")) > MAX_PREFIX_BYTES:
            raise ValueError(f"a topic prefix is at most {MAX_PREFIX_BYTES} bytes")
        return topic

    @model_validator(mode="after")
    def _prefixes_apart(self) -> Self:
        base, prefix = self.base_topic, self.discovery_prefix
        if base == prefix or base.startswith(prefix + "/") or prefix.startswith(base + "/"):
            raise ValueError(
                "discovery_prefix and base_topic must not be equal or nested: the bridge's "
                "commands and Home Assistant's discovery would share topics"
            )
        return self

    @model_validator(mode="after")
    def _discovery_reads_json(self) -> Self:
        if self.output == "values" and self.discovery != "off":
            raise ValueError(
                "output: values publishes no device JSON, which Home Assistant's discovered "
                "entities read; use output: json or both, or discovery: off"
            )
        return self

    @model_validator(mode="after")
    def _tls_needs_mqtts(self) -> Self:
        if self.tls is not None and urlsplit(self.broker_url).scheme != "mqtts":
            raise ValueError("tls: settings apply to mqtts:// URLs; use mqtts://host[:port]")
        return self

    @model_validator(mode="after")
    def _one_password_source(self) -> Self:
        one_source("password", self.password, self.password_file, self.password_env)
        return self

    @property
    def urls(self) -> list[str]:
        """Every broker, in the configured order (one unless ``url`` is a list)."""
        return list(self.url) if isinstance(self.url, list) else [self.url]

    @property
    def broker_url(self) -> str:
        """The broker of this connection: the first (the MQTT client connects to a copy
        of the config that names only the node it tries)."""
        return self.urls[0]

    @property
    def host(self) -> str:
        return urlsplit(self.broker_url).hostname or "127.0.0.1"

    @property
    def port(self) -> int:
        parts = urlsplit(self.broker_url)
        return parts.port or (8883 if parts.scheme == "mqtts" else 1883)

    def password_value(self) -> str | None:
        """The password from whichever source is configured (read now, never logged)."""
        return secret_of(self.password, self.password_file, self.password_env)
