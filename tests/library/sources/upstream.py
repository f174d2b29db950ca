"""The upstream snapshots the manufacturer modules transcribe, and what they share."""

from __future__ import annotations

from tests.library.source import SourcePoint

MBMD = "volkszaehler/mbmd@fb8f9c22f1210740ac89064fb55610613bba3f78"
EVCC = "evcc-io/evcc@b29b49e3056ead3c99ff1f4711b2bb17083114b0"

EVCC_PINS_MBMD = (
    "evcc's go.mod pins volkszaehler/mbmd at 96221ccf34be, which is not in the stored "
    "snapshot; the registers evcc reads are transcribed from mbmd at fb8f9c22"
)
EVCC_PV = "with usage pv evcc negates power (and phase values) and swaps import/export"
EVCC_NAN = "evcc's mbmd meter reports a NaN reading as 0"

# what evcc's mbmd-based three-phase templates read: power, energy, return energy, phases
EVCC_3P = (
    "power",
    "energy_import",
    "energy_export",
    "current_l1",
    "current_l2",
    "current_l3",
    "power_l1",
    "power_l2",
    "power_l3",
    "voltage_l1",
    "voltage_l2",
    "voltage_l3",
)


def pick(points: tuple[SourcePoint, ...], keys: tuple[str, ...]) -> tuple[SourcePoint, ...]:
    """The points with these keys, in the order of keys (KeyError if one is missing)."""
    by_key = {p.key: p for p in points}
    return tuple(by_key[k] for k in keys)


OPENEMS = "OpenEMS/openems@0e4ea8881f78f46b6a7cd05ce570c35de334c113"
OPENEMS_CONVENTION = (
    "OpenEMS converts into its own channel units (mV, mA, W, var, mHz, Wh) and counts "
    "'production' energy while its active power is positive and 'consumption' while it is "
    "negative; invert (a config flag, default off) flips both; keys here assume it is off"
)

TASMOTA_STYLE = (
    "Tasmota's driver sends one 2-register read per value in a cycle (float32 high word "
    "first); only what the default build reads is listed"
)


def tasmota_ref(commit: str, file: str) -> str:
    """The ref of one Tasmota energy driver file at one commit."""
    return f"arendst/Tasmota@{commit}:tasmota/tasmota_xnrg_energy/{file}"


OPENWB = "openWB/core@3039a21010759129b7dd182df0e7e183fed28baa"

VICTRON = "victronenergy/dbus-modbus-client@fe12d8c9c30fab4310e16c10bbec0ced4ca9926f"
VICTRON_STYLE = (
    "Victron's dbus-modbus-client reads holding registers (function 3), packing nearby "
    "registers into block reads"
)
