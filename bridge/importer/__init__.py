"""Importers: another tool's Modbus configuration turned into a bridge config and mappings.

``source`` reads the YAML (bounded, with the file and line of every key, ``!secret`` and
``!include`` resolved inside the file's folder); ``ha_modbus`` converts Home Assistant's
``modbus:`` hubs, ``esphome`` an ESPHome node's ``modbus_controller``; both answer an
``Import`` (``result``): the config, one mapping per device, and a ``Note`` for every key
that was not converted, with its file, line and reason. Nothing here writes a file or
touches a bus: the command line (``bridge.cli.importer``) writes what the import answers.
"""
