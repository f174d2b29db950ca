"""The command-line faces of the bridge: ``modbus-mqtt-bridge COMMAND`` and its helpers.

    console.py       main(): the parser, check | schema | mappings, and run (the bridge)
    simulate.py      simulate: simulated devices built from mappings
    commission.py    scan | read | write: commissioning a bus without the bridge
    identify.py      identify: what answers at a unit (SunSpec marker, mapping fingerprints)
    bus_spec.py      a bus named on the command line (tcp://..., rtu:///dev/...)
    demo.py          demo: the seed devices simulated and bridged, shown live
    demo_view.py     what the demo shows (a rich table or plain lines)
    demo_control.py  the demo's own request: trip a simulated device
    demo_broker.py   the demo's broker when none answers (mosquitto or the embedded one)
    config_doc.py    schema --markdown: docs/config.md from the config models
    lifecycle.py     logging set-up and clean stops for long-running commands

The faces import the runtime (``bridge.app``, ``bridge.config``, ``bridge.modbus``...),
never the reverse (an import-linter contract in pyproject.toml holds it).
"""

from bridge.cli.console import main

__all__ = ["main"]
