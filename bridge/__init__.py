"""modbus-mqtt-bridge: Modbus RTU/TCP field devices to MQTT and Home Assistant."""

__version__ = "0.1.0"
