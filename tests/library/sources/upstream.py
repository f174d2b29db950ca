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
