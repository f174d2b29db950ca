"""One Home Assistant modbus entity (sensor, binary sensor, switch) as mapping entities.

Each function answers the mapping entities (``Draft``) made from one YAML item, and
notes the keys it did not convert. Read Home Assistant's own code for the meaning of a
key (``homeassistant/components/modbus``): a sensor's value is ``raw * scale + offset``,
``nan_value`` is a raw value meaning unknown, ``slave_count``/``virtual_count`` add
entities named ``<name> <n>`` at the next addresses, a binary sensor on a register is
its bit 0, a switch writes ``command_on``/``command_off`` and reads its state only with
``verify``.
"""

from __future__ import annotations

import math
import re

from bridge.importer.draft import Draft
from bridge.importer.naming import ha_slug
from bridge.importer.result import Import
from bridge.importer.source import Node

DEFAULT_SCAN_INTERVAL = 15  # seconds, Home Assistant's
BASE_KEYS = frozenset({"name", "address", "slave", "device_address", "scan_interval", "unique_id"})
BASE_KEYS |= {"lazy_error_count"}  # the device's offline threshold (ha_modbus)
MAX_VERIFY_DELAY = 60  # seconds: the mapping's bound of verify_delay
_TYPES = {  # data_type -> (mapping type, registers)
    "int16": ("s16", 1),
    "uint16": ("u16", 1),
    "int32": ("s32", 2),
    "uint32": ("u32", 2),
    "float32": ("f32", 2),
    "float16": ("f16", 1),
    "int64": ("s64", 4),
    "uint64": ("u64", 4),
    "float64": ("f64", 4),
}
_STRUCT = {"h": ("s16", 1), "H": ("u16", 1), "i": ("s32", 2), "l": ("s32", 2)}
_STRUCT |= {"I": ("u32", 2), "L": ("u32", 2), "f": ("f32", 2), "e": ("f16", 1)}
_STRUCT |= {"q": ("s64", 4), "Q": ("u64", 4), "d": ("f64", 4)}
_STRUCTURE = re.compile(r"^([<>!]?)([hHiIlLfeqQd])$")
_FLOATS = ("f16", "f32", "f64")
_TEXT = re.compile(r"^[<>!=@]?(\d+)s$")  # one text of n bytes: byte order means nothing
_WRITE_TYPES = {  # write_type -> (table, function code)
    "holding": ("holding", 6),
    "holdings": ("holding", 16),
    "coil": ("coil", 5),
    "coils": ("coil", 15),
}
_READ_TABLES = {
    "holding": "holding",
    "holdings": "holding",
    "input": "input",
    "coil": "coil",
    "coils": "coil",
    "discrete_input": "discrete",
}


def base_draft(node: Node, result: Import, kind: str) -> Draft | None:
    """The name, address and scan interval every entity has; None (noted) when unusable."""
    name, address = node.get("name"), node.get("address")
    if not isinstance(name, str) or not name.strip():
        result.note(node.where, kind, "no name: the entity is not converted")
        return None
    if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 0xFFFF:
        result.note(node.at("address"), f"{name}.address", "not an address 0..65535")
        return None
    interval = node.get("scan_interval", DEFAULT_SCAN_INTERVAL)
    if isinstance(interval, bool) or not isinstance(interval, int) or interval < 0:
        result.note(node.at("scan_interval"), f"{name}.scan_interval", "not seconds: 15 s kept")
        interval = DEFAULT_SCAN_INTERVAL
    draft = Draft(name.strip(), {"name": name.strip(), "address": address}, interval, node)
    draft.ha["entity_id"] = ha_slug(name)
    if isinstance(node.get("unique_id"), str | int):
        draft.fields["note"] = f"Home Assistant modbus unique_id {node['unique_id']}"
    return draft


def unknown_keys(node: Node, known: frozenset[str], result: Import, name: str) -> None:
    """Note every key of ``node`` that no converter reads."""
    for key in node:
        if key not in known:
            result.note(node.at(key), f"{name}.{key}", "a key the import does not know")


def sensor(node: Node, result: Import) -> list[Draft]:
    """A register sensor, and its ``slave_count``/``virtual_count`` copies."""
    draft = base_draft(node, result, "sensor")
    if draft is None:
        return []
    known = BASE_KEYS | {"input_type", "data_type", "count", "structure", "swap", "scale"}
    known |= {"offset", "precision", "unit_of_measurement", "device_class", "state_class"}
    known |= {"slave_count", "virtual_count", "nan_value", "min_value", "max_value"}
    known |= {"zero_suppress"}
    unknown_keys(node, known, result, draft.name)
    table = node.get("input_type", "holding")
    if table not in ("holding", "input"):
        result.note(node.at("input_type"), f"{draft.name}.input_type", f"{table!r} is not a table")
        return []
    draft.fields["table"] = table
    shape = _shape(draft, result)
    if shape is None:
        return []
    if not _numbers(draft, result, shape[0]):
        return []
    for key in ("device_class", "state_class"):
        if isinstance(node.get(key), str):
            draft.ha[key] = node[key]
    if not _shaping(draft, result, shape[0]):
        return []
    for key in ("slave_count", "virtual_count"):
        if key in node and node.get("data_type") in ("custom", "string"):
            reason = f"not with data_type {node['data_type']} (Home Assistant refuses it)"
            result.note(node.at(key), f"{draft.name}.{key}", reason)
            return []
    return _copies(draft, result, shape[1])


def _shaping(draft: Draft, result: Import, kind: str) -> bool:
    """``min_value``/``max_value`` as the reading's ``clamp`` and ``zero_suppress`` (Home
    Assistant applies them after scale and offset, in this order); False (noted) when one
    is not a number. A text sensor has neither."""
    node, name = draft.node, draft.name
    found: dict[str, float] = {}
    for key in ("min_value", "max_value", "zero_suppress"):
        if key not in node:
            continue
        value = _real(node[key])
        if value is None or kind == "ascii" or (key == "zero_suppress" and value < 0):
            result.note(
                node.at(key), f"{name}.{key}", f"{node[key]!r}: not a number to show within"
            )
            return False
        found[key] = value
    clamp = {end: found[f"{end}_value"] for end in ("min", "max") if f"{end}_value" in found}
    if clamp:
        draft.fields["clamp"] = clamp
    if "zero_suppress" in found:
        draft.fields["zero_suppress"] = found["zero_suppress"]
    return True


def _real(value: object) -> float | None:
    """A finite number, as Home Assistant coerces it (a number, or text of one)."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        return None
    try:
        number = float(value)
    except ValueError:
        return None
    return number if math.isfinite(number) else None


def _shape(draft: Draft, result: Import) -> tuple[str, int] | None:
    """The mapping type and register count from data_type/count/structure/swap."""
    node, name = draft.node, draft.name
    data_type = node.get("data_type", "int16")
    swap = node.get("swap", "none")
    if data_type == "string":
        count = node.get("count")
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= 125:
            result.note(node.at("count"), f"{name}.count", "a string needs count 1..125")
            return None
        kind, size = "ascii", count
        draft.fields["count"] = count
    elif data_type == "custom":
        found = _custom(node, result, name)
        if found is None:
            return None
        kind, size, reverse = found
        swap = reverse or swap
        if kind == "ascii":
            draft.fields["count"] = size
    elif data_type in _TYPES:
        kind, size = _TYPES[data_type]
    else:
        result.note(
            node.at("data_type"),
            f"{name}.data_type",
            f"{data_type!r}: the mapping types are 16, 32 and 64-bit integers, floats and text",
        )
        return None
    draft.fields["type"] = kind
    return (kind, size) if _swap(draft, result, size, swap) else None


def _custom(node: Node, result: Import, name: str) -> tuple[str, int, str | None] | None:
    """A ``custom`` structure of one value; with ``<``, its swap (every byte reversed). One
    ``<n>s`` (n bytes, even) is text, as Home Assistant decodes it."""
    structure = node.get("structure")
    text = _TEXT.match(structure) if isinstance(structure, str) else None
    if text is not None and int(text.group(1)) % 2 == 0 and 2 <= int(text.group(1)) <= 250:
        size = int(text.group(1)) // 2
        if node.get("count", size) != size:
            result.note(node.at("count"), f"{name}.count", f"{structure!r} is {size} register(s)")
            return None
        return "ascii", size, None
    match = _STRUCTURE.match(structure) if isinstance(structure, str) else None
    if match is None:
        result.note(
            node.at("structure"),
            f"{name}.structure",
            f"{structure!r}: only one integer or float ('>h', '>i', '>q', '>e', '>f', '>d'...)",
        )
        return None
    order, letter = match.groups()
    kind, size = _STRUCT[letter]
    if node.get("count", size) != size:
        result.note(node.at("count"), f"{name}.count", f"{structure!r} is {size} register(s)")
        return None
    reversed_bytes = "word_byte" if size > 1 else "byte"
    return kind, size, reversed_bytes if order == "<" else None


def _swap(draft: Draft, result: Import, size: int, swap: object) -> bool:
    if swap in ("byte", "word_byte"):
        draft.fields["byte_order"] = "little"
    if swap in ("word", "word_byte"):
        if size not in (2, 4) or draft.fields["type"] == "ascii":
            result.note(draft.node.at("swap"), f"{draft.name}.swap", "word swap of one number")
            return False
        draft.fields["word_order"] = "little"
    if swap not in ("none", "byte", "word", "word_byte"):
        result.note(draft.node.at("swap"), f"{draft.name}.swap", f"{swap!r} is not a swap")
        return False
    return True


def _numbers(draft: Draft, result: Import, kind: str) -> bool:
    """scale, offset, precision, unit and nan_value; False (noted) when unusable."""
    node, name = draft.node, draft.name
    scale, offset = node.get("scale", 1), node.get("offset", 0)
    for key, value in (("scale", scale), ("offset", offset)):
        if isinstance(value, bool) or not isinstance(value, int | float):
            result.note(node.at(key), f"{name}.{key}", f"{value!r} is not a number")
            return False
    if scale == 0:
        result.note(node.at("scale"), f"{name}.scale", "0 makes every reading 0")
        return False
    text = kind == "ascii"
    if (scale, offset) != (1, 0) and not text:
        draft.fields |= {"scale": float(scale), "offset": float(offset)}
    precision = node.get("precision")
    if isinstance(precision, int) and not isinstance(precision, bool) and not text:
        draft.fields["precision"] = min(max(precision, 0), 6)
        if precision > 6:
            result.note(node.at("precision"), f"{name}.precision", "6 decimals kept", partly=True)
    unit = node.get("unit_of_measurement")
    if isinstance(unit, str) and not text:
        draft.fields["unit"] = unit
    elif unit is not None:
        result.note(node.at("unit_of_measurement"), f"{name}.unit_of_measurement", "not a number")
    if "nan_value" in node:
        return _nan_value(draft, result, kind)
    return True


def _nan_value(draft: Draft, result: Import, kind: str) -> bool:
    """Home Assistant's nan_value (an integer, or a hex text) as a sentinel raw value."""
    node, name = draft.node, draft.name
    value = node["nan_value"]
    if isinstance(value, str):
        try:
            value = int(value, 16) if value.lower().startswith("0x") else int(value)
        except ValueError:
            value = None
    if kind in (*_FLOATS, "ascii") or isinstance(value, bool) or not isinstance(value, int):
        result.note(node.at("nan_value"), f"{name}.nan_value", "kept for integer registers only")
        return True
    bits = {"s32": 32, "u32": 32, "s64": 64, "u64": 64}.get(kind, 16)
    if not -(1 << (bits - 1)) <= value < (1 << bits):
        result.note(node.at("nan_value"), f"{name}.nan_value", f"does not fit {bits} bits")
        return True
    draft.fields["sentinels"] = {value & ((1 << bits) - 1): "nan_value"}
    return True


def _copies(draft: Draft, result: Import, size: int) -> list[Draft]:
    """The entity and its ``slave_count``/``virtual_count`` copies at the next addresses."""
    node = draft.node
    key = "virtual_count" if "virtual_count" in node else "slave_count"
    count = node.get(key, 0)
    if isinstance(count, bool) or not isinstance(count, int) or not 0 <= count <= 1000:
        result.note(node.at(key), f"{draft.name}.{key}", "not a count 0..1000: no copies")
        count = 0
    drafts = [draft]
    for n in range(1, count + 1):
        address = draft.fields["address"] + n * size
        if address + size - 1 > 0xFFFF:
            result.note(node.at(key), f"{draft.name} {n}", "beyond address 65535")
            break
        name = f"{draft.name} {n}"
        fields = draft.fields | {"name": name, "address": address}
        if "note" in fields:
            fields["note"] = f"{fields['note']}_{n}"
        copy = Draft(name, fields, draft.scan_interval, node, dict(draft.ha))
        copy.ha["entity_id"] = ha_slug(name)
        drafts.append(copy)
    return drafts


def binary_sensor(node: Node, result: Import) -> list[Draft]:
    """A coil, discrete input, or bit 0 of a register; and its copies."""
    draft = base_draft(node, result, "binary_sensor")
    if draft is None:
        return []
    known = BASE_KEYS | {"input_type", "device_class", "slave_count", "virtual_count"}
    unknown_keys(node, known, result, draft.name)
    table = _READ_TABLES.get(str(node.get("input_type", "coil")))
    if table is None or node.get("input_type") in ("holdings", "coils"):
        result.note(node.at("input_type"), f"{draft.name}.input_type", "not a table")
        return []
    draft.fields["table"] = table
    if table in ("holding", "input"):
        draft.fields["bit"] = 0  # Home Assistant: the register's lowest bit
    if isinstance(node.get("device_class"), str):
        draft.ha["device_class"] = node["device_class"]
    return _copies(draft, result, 1)


def switch(node: Node, result: Import, kind: str = "switch") -> list[Draft]:
    """A switch (a fan or light as a switch): writes command_on/off, reads with verify."""
    draft = base_draft(node, result, kind)
    if draft is None:
        return []
    known = BASE_KEYS | {"write_type", "command_on", "command_off", "verify", "device_class"}
    unknown_keys(node, known, result, draft.name)
    write = _WRITE_TYPES.get(str(node.get("write_type", "holding")))
    if write is None:
        result.note(node.at("write_type"), f"{draft.name}.write_type", "not a write type")
        return []
    table, function = write
    draft.fields |= {"table": table, "type": "bool", "write_function": function}
    if table == "coil":
        del draft.fields["type"]
    draft.ha["component"] = "switch"
    if isinstance(node.get("device_class"), str):
        draft.ha["device_class"] = node["device_class"]
    commands = _commands(draft, result, table)
    if commands is None or not _verify(draft, result, table):
        return []
    return [draft] if _words(draft, result, table, commands) else []


def _commands(draft: Draft, result: Import, table: str) -> tuple[int, int] | None:
    """``command_on``/``command_off`` (16-bit words, different); None (noted) otherwise.
    On a coil, Home Assistant writes ON for any non-zero command: 0 must be off."""
    node, name = draft.node, draft.name
    words = []
    for key, default in (("command_on", 1), ("command_off", 0)):
        value = _word(node.get(key, default))
        if value is None:
            result.note(node.at(key), f"{name}.{key}", "not a word 0..65535: not converted")
            return None
        words.append(value)
    on, off = words
    if on == off or (table == "coil" and (on == 0 or off != 0)):
        result.note(
            node.at("command_on"),
            f"{name}.command_on",
            f"{on}/{off} do not tell on from off on a {table}: not converted",
        )
        return None
    return on, off


def _word(value: object) -> int | None:
    if isinstance(value, str) and value.strip().isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
        return None
    return value


def _verify(draft: Draft, result: Import, table: str) -> bool:
    """``verify``: the state read back (same table only); none: a write-only switch."""
    node, name = draft.node, draft.name
    if "verify" not in node:
        draft.fields |= {"access": "w", "verify": False}
        return True
    verify = node["verify"] if isinstance(node["verify"], dict) else {}
    where = node.at("verify")
    read_table = _READ_TABLES.get(str(verify.get("input_type", table)), "?")
    if read_table != table:
        result.note(
            where,
            f"{name}.verify.input_type",
            f"the state is read from another table ({read_table}): a write-only switch",
            partly=True,
        )
        draft.fields |= {"access": "w", "verify": False}
        return True
    draft.fields["access"] = "rw"
    address = verify.get("address", draft.fields["address"])
    if isinstance(address, int) and address != draft.fields["address"]:
        draft.fields |= {"write_address": draft.fields["address"], "address": address}
    _verify_delay(draft, result, verify.get("delay"))
    return True


def _verify_delay(draft: Draft, result: Import, delay: object) -> None:
    """``verify``'s ``delay``: the read back that many seconds after a write."""
    if not delay:
        return
    where, key = draft.node.at("verify"), f"{draft.name}.verify.delay"
    if isinstance(delay, bool) or not isinstance(delay, int | float) or delay < 0:
        result.note(where, key, f"{delay!r} is not seconds: read back at once", partly=True)
    elif delay > MAX_VERIFY_DELAY:
        reason = f"{delay} s: read back after {MAX_VERIFY_DELAY} s, the bridge's longest wait"
        result.note(where, key, reason, partly=True)
        draft.fields["verify_delay"] = MAX_VERIFY_DELAY
    else:
        draft.fields["verify_delay"] = delay


def _words(draft: Draft, result: Import, table: str, commands: tuple[int, int]) -> bool:
    """A register switch's words: ``command_on``/``command_off`` written, ``verify``'s
    ``state_on``/``state_off`` (a word or a list; by default the commands) read, so that a
    word in neither reads unknown, not on (Home Assistant keeps its last state and logs
    it); none for a write-only switch writing 1 and 0. A word in both lists reads on, as in
    Home Assistant (it looks in state_on first). False (noted) when a state is no word."""
    node, name = draft.node, draft.name
    if table != "holding":
        return True
    verify = node.get("verify") if draft.fields["access"] == "rw" else None
    states = (None, None)
    if isinstance(verify, dict):
        states = (verify.get("state_on"), verify.get("state_off"))
    read: list[list[int]] = []
    for key, given, command in zip(("state_on", "state_off"), states, commands, strict=True):
        listed = [command] if given is None else given if isinstance(given, list) else [given]
        words = [_word(w) for w in listed]
        if not words or any(w is None for w in words):
            result.note(node.at("verify"), f"{name}.verify.{key}", "not words: not converted")
            return False
        read.append([w for w in words if w is not None])
    read_on, read_off = read[0], [w for w in read[1] if w not in read[0]]
    if commands == (1, 0) and draft.fields["access"] == "w":
        return True  # a write-only switch writes 1 and 0 without words
    chosen: dict[str, object] = {"write_on": commands[0], "write_off": commands[1]}
    if read_on != [commands[0]]:
        chosen["read_on"] = read_on
    if read_off != [commands[1]]:
        chosen["read_off"] = read_off
    draft.fields["words"] = chosen
    return True
