"""Config data and text with their secrets hidden, for views, logs and conflict diffs.

A secret is the value of a key in ``SECRET_KEYS`` (``password``, ``token``, and the
``*_file`` and ``*_env`` that say where one is) at any level, and the password of a broker
URL (``mqtt://user:pass@host``). Each is shown as ``SECRET_MARK``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from typing import Any

from bridge.config.edits import SECRET_KEYS, SECRET_MARK

_URL_PASSWORD = re.compile(r"(://[^/\s:@]*:)[^@/\s]*@")
_KEYS = "|".join(sorted(SECRET_KEYS, key=len, reverse=True))
_KEY = rf"['\"]?(?:{_KEYS})['\"]?\s*:"
_QUOTED = r"\"(?:[^\"\\\n]|\\.)*\"?|'(?:[^'\n]|'')*'?"  # a quote not closed runs to the end
_BLOCK_KEY = re.compile(rf"^(\s*(?:-\s+)?)({_KEY})(?=\s|$)[ \t]*({_QUOTED}|.*?)(\s+#.*)?$")
_FLOW_KEY = re.compile(rf"([{{,]\s*{_KEY}[ \t]+)({_QUOTED}|[^,}}\]\n]*?)(?=\s*[,}}\]]|\s+#|\s*$)")
MAX_ROWS = 40  # rows of a change summary; more are counted


def public_data(data: Any) -> Any:
    """``data`` (plain config data) with every secret replaced by SECRET_MARK, and values
    JSON has no type for (a YAML date) as text."""
    if isinstance(data, dict):
        return {
            key: SECRET_MARK if key in SECRET_KEYS and value is not None else public_data(value)
            for key, value in data.items()
        }
    if isinstance(data, list):
        return [public_data(item) for item in data]
    if isinstance(data, str):
        return _URL_PASSWORD.sub(rf"\g<1>{SECRET_MARK}@", data)
    return data if data is None or isinstance(data, bool | int | float) else str(data)


def redact_text(text: str) -> str:
    """Config text with secret values replaced, line by line (the lines stay the lines):
    ``key: value`` (quoted or plain, a comment after it kept), the lines that continue it
    (a block scalar, a multi-line string), ``{key: value}`` in a flow mapping, and the
    password of a URL."""
    lines = []
    column: int | None = None  # lines indented past it continue a secret's value
    for line in text.splitlines(keepends=True):
        body, end = line.rstrip("\r\n"), line[len(line.rstrip("\r\n")) :]
        indent = len(body) - len(body.lstrip(" "))
        if column is not None and (not body.strip() or indent > column):
            lines.append((" " * indent + SECRET_MARK if body.strip() else body) + end)
            continue
        column = None
        block = _BLOCK_KEY.match(body)
        if block is not None:
            column = len(block.group(1))
            value, comment = block.group(3), block.group(4) or ""
            shown = value if not value or value[0] in "|>" else SECRET_MARK
            body = f"{block.group(1)}{block.group(2)} {shown}".rstrip() + comment
        body = _FLOW_KEY.sub(rf"\g<1>{SECRET_MARK}", body)
        lines.append(_URL_PASSWORD.sub(rf"\g<1>{SECRET_MARK}@", body) + end)
    return "".join(lines)


def change_rows(before: Any, after: Any, renamed: tuple[str, str] | None = None) -> list[str]:
    """``path: old -> new`` for each value that differs (secrets hidden: a new one shows as
    changed; list entries with an ``id`` named by it; an entry gone in one row), at most
    MAX_ROWS of them. ``renamed``: a device's old and new id, compared under the new one."""
    old, new = _flat(before, renamed), _flat(after)
    shown_old = {p: v[:200] for p, v in _flat(public_data(before), renamed).items()}
    shown_new = {p: v[:200] for p, v in _flat(public_data(after)).items()}
    gone = {_entry(p) for p in old} - {_entry(p) for p in new}
    rows = [f"{entry}: (removed)" for entry in sorted(gone)]
    for path in list(old) + [p for p in new if p not in old]:
        if _entry(path) in gone or old.get(path) == new.get(path):
            continue
        if path not in new:
            rows.append(f"{path}: {shown_old[path]} -> (removed)")
        elif path not in old:
            rows.append(f"{path}: {shown_new[path]}")
        elif shown_old[path] == shown_new[path]:
            rows.append(f"{path}: {shown_new[path]} (changed)")
        else:
            rows.append(f"{path}: {shown_old[path]} -> {shown_new[path]}")
    if len(rows) > MAX_ROWS:
        rows = [*rows[:MAX_ROWS], f"... {len(rows) - MAX_ROWS} more"]
    return rows


def _entry(path: str) -> str:
    """The list entry a flat path is in (``devices.pump``), or the path's section."""
    return ".".join(path.split(".")[:2])


def _flat(data: Any, renamed: tuple[str, str] | None = None) -> dict[str, str]:
    """``data`` as ``path: value`` rows (``renamed``: a device's paths under its new id)."""
    flat = _paths(data)
    if renamed is None:
        return flat
    was, now = (f"devices.{name}." for name in renamed)
    return {(now + p[len(was) :] if p.startswith(was) else p): v for p, v in flat.items()}


def _paths(data: Any, path: str = "") -> dict[str, str]:
    items: Iterable[tuple[Any, Any]]
    if isinstance(data, dict) and data:
        items = data.items()
    elif isinstance(data, list) and data:
        items = ((_entry_name(item, i), item) for i, item in enumerate(data))
    else:
        return {path: json.dumps(data, default=str, ensure_ascii=False)}
    flat: dict[str, str] = {}
    for key, value in items:
        flat.update(_paths(value, f"{path}.{key}" if path else str(key)))
    return flat


def _entry_name(item: Any, index: int) -> str:
    name = item.get("id") if isinstance(item, dict) else None
    return name if isinstance(name, str) and name else str(index)
