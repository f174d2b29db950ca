"""One ESPHome ``platform: modbus_controller`` item as mapping entities.

``register_type`` is the table (``read`` = input registers), ``value_type`` the type and
word order (``_R``: low word first; of a QWORD, the four words reversed), ``bitmask`` a
bit field (shifted down to its lowest bit, as ESPHome does), the ``multiply``/``offset``
filters scale and offset, in their order; ``lambda``, ``write_lambda``,
``custom_command`` and every other filter are reported, never guessed. The entity asks
Home Assistant for the id ESPHome's entity had: ``<node>_<name>``.
"""

from __future__ import annotations

from bridge.importer.draft import Draft
from bridge.importer.naming import ha_slug
from bridge.importer.result import Import
from bridge.importer.source import Node

_TABLES = {"holding": "holding", "read": "input", "coil": "coil", "discrete_input": "discrete"}
_TYPES = {  # value_type -> (type, word order)
    "U_WORD": ("u16", "big"),
    "S_WORD": ("s16", "big"),
    "U_DWORD": ("u32", "big"),
    "S_DWORD": ("s32", "big"),
    "U_DWORD_R": ("u32", "little"),
    "S_DWORD_R": ("s32", "little"),
    "FP32": ("f32", "big"),
    "FP32_R": ("f32", "little"),
    "U_QWORD": ("u64", "big"),
    "S_QWORD": ("s64", "big"),
    "U_QWORD_R": ("u64", "little"),  # the four words in reverse
    "S_QWORD_R": ("s64", "little"),
}
_KEPT = {"platform", "modbus_controller_id", "id", "name", "address", "register_type"}
_KEPT |= {"value_type", "bitmask", "skip_updates", "unit_of_measurement", "device_class"}
_KEPT |= {"state_class", "accuracy_decimals", "filters", "icon", "entity_category"}
_KEPT |= {"register_count", "response_size", "force_new_range", "min_value", "max_value"}
_KEPT |= {"step", "multiply", "optionsmap", "use_write_multiple", "raw_encode"}
_PLANNING = ("force_new_range", "register_count", "response_size")
_CODE = ("lambda", "write_lambda", "custom_command")


def convert(platform: str, item: Node, result: Import, node_name: str) -> list[Draft]:
    """The entity of one item, or none (noted)."""
    name, address = item.get("name"), item.get("address")
    code = [key for key in _CODE if key in item]
    if code:
        shown = name if isinstance(name, str) else platform
        reason = f"its value comes from code on the ESP ({', '.join(code)}): not converted"
        result.note(item.at(code[0]), f"{shown}.{code[0]}", reason)
        return []
    if not isinstance(name, str) or not isinstance(address, int) or not 0 <= address <= 0xFFFF:
        result.note(item.where, platform, "needs a name and an address 0..65535")
        return []
    for key in item:
        if key not in _KEPT:
            result.note(item.at(key), f"{name}.{key}", "an ESPHome option the bridge has not")
    for key in _PLANNING:
        if key in item and platform != "text_sensor":
            reason = "the bridge plans its reads itself (padding and ranges not kept)"
            result.note(item.at(key), f"{name}.{key}", reason, partly=True)
    default = "holding" if platform in ("number", "select") else None
    table = _TABLES.get(str(item.get("register_type", default)))
    if table is None:
        result.note(item.at("register_type"), f"{name}.register_type", "not a table")
        return []
    draft = Draft(name, {"name": name, "address": address, "table": table}, 0, item)
    draft.ha["entity_id"] = f"{ha_slug(node_name)}_{ha_slug(name)}"
    for key in ("device_class", "state_class", "icon"):
        if isinstance(item.get(key), str):
            draft.ha[key] = item[key]
    skip = item.get("skip_updates", 0)
    if isinstance(skip, int) and skip > 0:
        draft.scan_interval = skip
        draft.fields["skip_updates"] = skip
    if not _shape(platform, draft, result):
        return []
    return [draft]


def _shape(platform: str, draft: Draft, result: Import) -> bool:
    item, fields = draft.node, draft.fields
    bits = fields["table"] in ("coil", "discrete")
    if platform == "text_sensor":
        return _text(draft, result)
    if not bits and platform not in {"binary_sensor", "switch"}:
        found = _TYPES.get(str(item.get("value_type", "U_WORD")))
        if found is None:
            result.note(
                item.at("value_type"),
                f"{draft.name}.value_type",
                f"{item.get('value_type')}: no mapping type",
            )
            return False
        fields["type"] = found[0]
        if found[1] == "little":
            fields["word_order"] = "little"
    if not bits and not _bitmask(draft, result, platform in ("binary_sensor", "switch")):
        return False
    if platform in ("switch", "number", "select"):
        if fields["table"] in ("input", "discrete"):
            result.note(item.at("register_type"), draft.name, "a read-only table is not written")
            return False
        fields["access"] = "rw"
        if item.get("use_write_multiple"):
            fields["write_function"] = 15 if bits else 16
    if platform == "switch":
        draft.ha["component"] = "switch"
    if platform == "select":
        return _options(draft, result)
    if platform == "number":
        _limits(draft, result)
    if platform in ("sensor", "number"):
        return _filters(draft, result)
    return True


def _bitmask(draft: Draft, result: Import, boolean: bool) -> bool:
    """ESPHome's ``bitmask``: the masked value shifted down to its lowest bit."""
    item = draft.node
    mask = item.get("bitmask", 1 if boolean else 0xFFFF)
    if not isinstance(mask, int) or mask <= 0:
        result.note(item.at("bitmask"), f"{draft.name}.bitmask", "not a mask")
        return False
    if mask == 0xFFFF and not boolean:
        return True
    low = (mask & -mask).bit_length() - 1
    width = (mask >> low).bit_length()
    if mask >> low != (1 << width) - 1 or low + width > 16:
        result.note(item.at("bitmask"), f"{draft.name}.bitmask", "not one run of bits of a word")
        return False
    draft.fields.pop("type", None)
    draft.fields |= {"bit": low} | ({"width": width} if width > 1 else {})
    if boolean and width > 1:
        draft.fields["on_when"] = {"min": 1}
    return True


def _text(draft: Draft, result: Import) -> bool:
    item = draft.node
    encoding = item.get("raw_encode", "NONE")
    if encoding != "NONE":
        result.note(item.at("raw_encode"), f"{draft.name}.raw_encode", f"{encoding}: text only")
        return False
    size = item.get("response_size") or 2 * int(item.get("register_count", 1) or 1)
    draft.fields |= {"type": "ascii", "count": max(1, min(125, (int(size) + 1) // 2))}
    return True


def _options(draft: Draft, result: Import) -> bool:
    options = draft.node.get("optionsmap")
    if not isinstance(options, dict) or not options:
        result.note(draft.node.at("optionsmap"), f"{draft.name}.optionsmap", "no options")
        return False
    draft.fields["enum"] = {int(value): str(label) for label, value in options.items()}
    return True


def _limits(draft: Draft, result: Import) -> None:
    item = draft.node
    for key, field in (("min_value", "min"), ("max_value", "max"), ("step", "step")):
        if isinstance(item.get(key), int | float):
            draft.fields[field] = item[key]
    multiply = item.get("multiply")
    if isinstance(multiply, int | float) and multiply:
        draft.fields["scale"] = 1 / multiply
    elif multiply is not None:
        result.note(item.at("multiply"), f"{draft.name}.multiply", "not a number")


def _filters(draft: Draft, result: Import) -> bool:
    """``multiply`` and ``offset`` filters, applied in order, as scale and offset."""
    item = draft.node
    scale, offset = float(draft.fields.get("scale", 1.0)), 0.0
    for entry in item.get("filters") or []:
        name = next(iter(entry), "?") if isinstance(entry, dict) else str(entry)
        value = entry.get(name) if isinstance(entry, dict) else None
        if name in ("multiply", "offset") and isinstance(value, int | float):
            scale, offset = (
                (scale * value, offset * value) if name == "multiply" else (scale, offset + value)
            )
        else:
            where = entry.where if isinstance(entry, Node) else item.at("filters")
            result.note(where, f"{draft.name}.filters.{name}", "a filter the bridge does not run")
    if (scale, offset) != (1.0, 0.0):
        draft.fields |= {"scale": scale, "offset": offset}
    decimals = item.get("accuracy_decimals")
    if isinstance(decimals, int) and 0 <= decimals <= 6:
        draft.ha["display_precision"] = decimals  # ESPHome publishes the value unrounded
    unit = item.get("unit_of_measurement")
    if isinstance(unit, str):
        draft.fields["unit"] = unit
    return True
