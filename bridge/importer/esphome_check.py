"""An ESPHome node checked by ESPHome's own config validation, when ESPHome is installed.

The import does not decide for ESPHome what ESPHome accepts: ``check_node`` runs ``esphome
config FILE`` (the ``esphome`` found on PATH, or the executable ``MODBUS_BRIDGE_ESPHOME``
names) apart from the bridge, bounded in time and output, and each part it refuses becomes
a note in ESPHome's own words at the file and line of the entity and key. A note of the
import's own at the same key gives way to ESPHome's. ESPHome stops at the first component
it refuses, so one run shows the first refusal; the note says so.

The run sees the node's folder through links in a temporary folder (ESPHome leaves its
build folder there, not beside the user's file). A node whose folder has no
``secrets.yaml`` gets one there with a placeholder for each ``!secret`` it names (a key's
a base64 key, others a short text): ESPHome needs the values to read the file. Proxies
that refuse every connection keep ESPHome off the network (a remote package is refused,
not fetched). Without ESPHome the import works as before and says once that the node was
not checked.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.importer.result import Import, Note
from bridge.importer.source import Node, Where

ESPHOME_ENV = "MODBUS_BRIDGE_ESPHOME"
TIMEOUT = 120.0  # seconds for one `esphome config`
MAX_OUTPUT = 256_000  # characters of its output read
MAX_LINKED = 2_000  # entries of the node's folder linked for the run
PLATFORMS = ("sensor", "binary_sensor", "switch", "number", "select", "text_sensor")
_NO_NETWORK = "http://127.0.0.1:9"  # the discard port: every connection refused
_HEADER = re.compile(r"^(\S.*?): \[source (.+?):(\d+)\]$")
_KEY = re.compile(r"^\s*([\w-]+):\s*(.*)$")
_SECRET = re.compile(r"!secret\s+([\w.-]+)")
_KEY_PLACEHOLDER = "MDEyMzQ1Njc4OWFiY2RlZjAxMjM0NTY3ODlhYmNkZWY="  # 32 bytes, base64
_TEXT_PLACEHOLDER = "placeholder1"
_NOT_CHECKED = (
    "ESPHome is not installed here: the node was not checked by ESPHome's own validation "
    f"(pip install esphome, or set {ESPHOME_ENV} to its executable)"
)


@dataclass(frozen=True, slots=True)
class Refusal:
    """One part ESPHome refused: its path (``sensor.modbus_controller``), the file and line
    of the item, ESPHome's message and the key it is about, when ESPHome shows it."""

    path: str
    file: str
    line: int
    message: str
    key: str | None = None


def esphome_command() -> list[str] | None:
    """How to run ESPHome here, or None when it is not installed."""
    given = os.environ.get(ESPHOME_ENV)
    if given:
        return [given] if shutil.which(given) else None
    found = shutil.which("esphome")
    return [found] if found else None


def check_node(path: Path, data: Any, result: Import) -> None:
    """Run ESPHome's validation of ``path`` and note what it refuses (or that it did not
    run) in ``result``; ``data`` is the node as the import read it."""
    command = esphome_command()
    if command is None:
        result.note(Where(result.source, 1), "esphome config", _NOT_CHECKED, partly=True)
        return
    try:
        text = run_config(command, path)
    except (OSError, subprocess.SubprocessError) as exc:
        reason = f"ESPHome did not run ({exc}): the node was not checked"
        result.note(Where(result.source, 1), "esphome config", reason, partly=True)
        return
    refusals = parse_report(text)
    for index, refusal in enumerate(refusals):
        _note(refusal, data, result, first=index == 0)


def run_config(command: list[str], path: Path) -> str:
    """``esphome config`` of ``path`` in a folder of its own; its output, bounded."""
    with tempfile.TemporaryDirectory(prefix="bridge-esphome-") as folder:
        node = _mirror(path.resolve(), Path(folder))
        env = os.environ | dict.fromkeys(("HTTP_PROXY", "HTTPS_PROXY"), _NO_NETWORK)
        env |= {"http_proxy": _NO_NETWORK, "https_proxy": _NO_NETWORK, "NO_COLOR": "1"}
        completed = subprocess.run(  # noqa: S603 - our own argument list, no shell
            [*command, "config", node.name],
            capture_output=True,
            text=True,
            errors="replace",
            timeout=TIMEOUT,
            cwd=folder,
            env=env,
            stdin=subprocess.DEVNULL,
            check=False,
        )
    return (completed.stdout or "")[:MAX_OUTPUT] + (completed.stderr or "")[:MAX_OUTPUT]


def _mirror(path: Path, folder: Path) -> Path:
    """Links to ``path``'s folder entries in ``folder`` (a secrets.yaml of placeholders
    when there is none); the node's place there."""
    entries = sorted(path.parent.iterdir())[:MAX_LINKED]
    for entry in entries:
        (folder / entry.name).symlink_to(entry)
    if not (path.parent / "secrets.yaml").exists():
        text = path.read_text(encoding="utf-8", errors="replace")
        names = sorted(set(_SECRET.findall(text)))
        (folder / "secrets.yaml").write_text(
            "".join(f"{name}: {_placeholder(name)}\n" for name in names), encoding="utf-8"
        )
    return folder / path.name


def _placeholder(name: str) -> str:
    return _KEY_PLACEHOLDER if "key" in name.lower() else _TEXT_PLACEHOLDER


def parse_report(text: str) -> list[Refusal]:
    """The refusals of an ``esphome config`` output (none when it passed): each block
    ``path: [source file:line]`` with its messages (a message follows a blank line of the
    block; the key it is about, when the next line names it), and the lines of a refusal
    of the whole node."""
    lines = text.splitlines()
    if "Failed config" not in lines:
        return []
    refusals: list[Refusal] = []
    header: tuple[str, str, int] | None = None
    body = lines[lines.index("Failed config") + 1 :]
    for index, line in enumerate(body):
        found = _HEADER.match(line)
        if found is not None:
            header = (found[1], found[2], int(found[3]))
        elif header is None and line.strip() and not line.startswith(("INFO", "WARNING")):
            refusals.append(Refusal("", "", 0, line.strip()))
        elif header is not None and line.strip() and index and not body[index - 1].strip():
            following = body[index + 1] if index + 1 < len(body) else ""
            refusals.append(Refusal(*header, line.strip(), _key_of(line, following)))
    return refusals


def _key_of(message: str, following: str) -> str | None:
    """The key on the line after a message, when the message is about it (names the key
    or its value)."""
    found = _KEY.match(following)
    if found is None:
        return None
    key, value = found[1], found[2].strip()
    return key if key in message or (value and value in message) else None


def _note(refusal: Refusal, data: Any, result: Import, *, first: bool) -> None:
    """One refusal as a note at its entity and key (replacing the import's own note
    there), or at the node."""
    platform = refusal.path.split(".")[0]
    own_file = Path(refusal.file).name == Path(result.source).name
    item = _item_at(data, platform, refusal.line) if platform in PLATFORMS and own_file else None
    reason = f"ESPHome refuses it: {refusal.message}"
    if first:
        reason += " (ESPHome stops at its first refusal: fix it and import again)"
    if item is None:
        where = Where(Path(refusal.file).name or result.source, max(refusal.line, 1))
        key = f"{refusal.path}.{refusal.key}" if refusal.key else refusal.path or "esphome"
        result.note(where, key, reason)
        return
    name = str(item.get("name", platform))
    key = f"{name}.{refusal.key}" if refusal.key else name
    where = item.at(refusal.key) if refusal.key else item.where
    result.notes[:] = [n for n in result.notes if not _same_place(n, where, key)]
    result.note(where, key, reason)


def _same_place(note: Note, where: Where, key: str) -> bool:
    return note.where == where and note.key == key


def _item_at(data: Any, platform: str, line: int) -> Node | None:
    """The item of ``platform`` written at ``line`` of the node's own file."""
    items = data.get(platform) if isinstance(data, Node) else None
    for item in items if isinstance(items, list) else []:
        if isinstance(item, Node) and item.where.line == line:
            return item
    return None
