"""Every independent source definition, by library device name.

Sources (``SourceDefinition.source``): mbmd (volkszaehler/mbmd), evcc (evcc-io/evcc; most
of its meter templates delegate to mbmd and are transcribed from mbmd's producer they
name), openems (OpenEMS/openems), tasmota (arendst/Tasmota's energy drivers), openwb
(openWB/core), victron (victronenergy/dbus-modbus-client) and community:<owner>/<repo>
for a smaller community project. Each definition lists only
what that source reads, under the library's entity keys; a register a source reads under
another meaning (OpenEMS's "consumption" energy) gets the key of that meaning, so
``disagreements()`` shows it. Units are those of raw * scale as the source computes it.
"""

from __future__ import annotations

from tests.library.source import SourceDefinition
from tests.library.sources import (
    abb,
    carlo_gavazzi,
    chint,
    deye,
    eastron,
    eastron_sdm_modbus,
    goodwe,
    orno,
    solax,
)

_MODULES = (eastron, eastron_sdm_modbus, abb, carlo_gavazzi, chint, orno, deye, solax, goodwe)

SOURCES: dict[str, tuple[SourceDefinition, ...]] = {}
for _module in _MODULES:
    for _device, _definitions in _module.DEFINITIONS.items():
        SOURCES[_device] = SOURCES.get(_device, ()) + _definitions
