"""The config file: MQTT connection, buses, devices. ``load_config`` validates it whole.

    model.py    the pydantic models of the file and load_config()
    checks.py   checks beyond the fields, as ``path: message`` rows

The names below are the package's public face; import them from ``bridge.config``.
"""

from bridge.config.model import (
    MIN_TOKEN,
    Bus,
    Config,
    DeviceConfig,
    FilePath,
    LoadedConfig,
    ManagementConfig,
    MetricsConfig,
    MqttConfig,
    PollConfig,
    ProtocolOverride,
    SerialBus,
    SerialLine,
    TcpBus,
    TlsConfig,
    WebConfig,
    config_schema,
    is_register_number,
    load_config,
    load_config_data,
    load_device_mapping,
    secret_of,
)

__all__ = [
    "MIN_TOKEN",
    "Bus",
    "Config",
    "DeviceConfig",
    "FilePath",
    "LoadedConfig",
    "ManagementConfig",
    "MetricsConfig",
    "MqttConfig",
    "PollConfig",
    "ProtocolOverride",
    "SerialBus",
    "SerialLine",
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
