"""The config file: MQTT connection, buses, devices. ``load_config`` validates it whole.

    field.py    what the sections share: the strict base, files a config names, secrets
    mqtt.py     the ``mqtt`` section: brokers, login, TLS, topic prefixes, output
    model.py    buses, devices, the ``bridge`` section, and ``Config`` with its invariants
    checks.py   checks beyond the model: files, variables, topic sizes; the error rows
    loading.py  load_config(): the file, its mappings, every problem reported at once

The file as the web page edits it (import these from their modules: ruamel.yaml loads
only for an edit):

    lines.py      lines of text compared (Myers) and merged three ways
    document.py   the YAML that keeps the user's comments and layout (ruamel.yaml)
    edits.py      the changes (AddDevice, EditDevice, RemoveDevice, AddBus), bounded
    redaction.py  config data and text with secrets hidden
    store.py      ConfigStore: one change validated as ``check`` does, written atomically

Each imports only the ones listed before it (an import-linter contract in pyproject.toml):
the checks read the model, the model never reads the checks. The names below are the
package's public face; import them from ``bridge.config``.
"""

from bridge.config.field import FilePath, is_register_number, secret_of
from bridge.config.loading import (
    LoadedConfig,
    load_config,
    load_config_data,
    load_device_mapping,
)
from bridge.config.model import (
    MIN_TOKEN,
    Bus,
    Config,
    DeviceConfig,
    GatewayConfig,
    GatewayUnit,
    ManagementConfig,
    MetricsConfig,
    PollConfig,
    ProtocolOverride,
    SerialBus,
    SerialLine,
    SunSpecConfig,
    TcpBus,
    WebConfig,
    config_schema,
)
from bridge.config.mqtt import MqttConfig, TlsConfig

__all__ = [
    "MIN_TOKEN",
    "Bus",
    "Config",
    "DeviceConfig",
    "FilePath",
    "GatewayConfig",
    "GatewayUnit",
    "LoadedConfig",
    "ManagementConfig",
    "MetricsConfig",
    "MqttConfig",
    "PollConfig",
    "ProtocolOverride",
    "SerialBus",
    "SerialLine",
    "SunSpecConfig",
    "TcpBus",
    "TlsConfig",
    "WebConfig",
    "config_schema",
    "is_register_number",
    "load_config",
    "load_config_data",
    "load_device_mapping",
    "secret_of",
]
