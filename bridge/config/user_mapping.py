"""A device's user mapping: the override file the page writes, and where it lives.

A device's override is ``<bridge.state_dir>/mappings/<device id>.yaml`` (the folder the
bridge writes what it learns of devices in; relative to the config file). It says
``extends: <the device's mapping>`` and holds the entities added on the page
(bridge/core/override.py has what an override may say). When it exists, the loader
takes it as the device's mapping (``load_device_mapping``); a shipped mapping is never
written. An override that extends another mapping than the device's config names is an
error naming both, never taken silently.

``entity_added`` edits the file's text as the config file is edited (bridge/config/
document.py), so a user's comments and key order stay; ``write_atomic`` replaces it with
a temp file and a rename.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.config.document import Document
from bridge.config.loading import override_path
from bridge.config.model import DeviceConfig
from bridge.core.mapping import (
    Mapping,
    builtin_mapping_names,
    check_mapping_text,
    load_mapping,
    resolve_mapping_path,
)
from bridge.core.override import EXTENDS
from bridge.core.yaml_source import parse_yaml
from bridge.errors import MappingError

HEADER = (
    "The entities added to this device on the bridge's page (the mapping it extends is "
    "never edited).\nChecked as any mapping file: docs/mappings.md, Overrides."
)


def entity_added(text: str | None, base: str, key: str, fields: dict[str, Any]) -> str:
    """The override's text with entity ``key`` added (a new file extending ``base`` when
    ``text`` is None); ValueError when the text is not an override's mapping. Edited as
    the config file is (bridge/config/document.py): the user's comments and order kept."""
    if text is None:
        header = "".join(f"# {line}\n" for line in HEADER.splitlines())
        plain = f"{EXTENDS}: {base}\n"
        quoted = parse_yaml(plain, "the override file") != {EXTENDS: base}
        text = header + (f"{EXTENDS}: {json.dumps(base)}\n" if quoted else plain)
    document = Document.parse(text, "the override file")
    root = document.root
    if not isinstance(root.get(EXTENDS), str):
        raise ValueError("the override file has no extends: at its top")
    expected = parse_yaml(text, "the override file")
    entities = root.get("entities")
    if entities is None:
        root["entities"] = document.node({key: fields})
        expected["entities"] = {key: fields}
    elif isinstance(entities, dict):
        entities[key] = document.node(fields)
        expected["entities"][key] = fields
    else:
        raise ValueError("the override file's entities are not a mapping")
    return document.render(expected, "the override file")


@dataclass(frozen=True, slots=True)
class Proposed:
    """A device's override with one entity more, checked by the mapping loader: ``text``
    to write at ``path`` (where ``before`` stood; None: no file yet), loading as ``mapping``."""

    path: Path
    before: str | None
    text: str
    mapping: Mapping


def propose(
    device: DeviceConfig, config_dir: Path, state_dir: Path, key: str, fields: dict[str, Any]
) -> Proposed:
    """The device's override with entity ``key`` added; MappingError naming the override
    file with every problem the loader finds (a key the mapping has, a guard, an overlap)."""
    if device.is_sunspec:
        raise MappingError(device.id, ["mapping: a SunSpec device's mapping is built, not edited"])
    base = resolve_mapping_path(device.mapping, config_dir)
    path = override_path(state_dir, device.id)
    if device.mapping in builtin_mapping_names():
        ref = device.mapping
    elif base.resolve() == path.resolve():
        ref = ""  # the device names its override already: the file says what it extends
    else:
        ref = str(base.resolve())
    try:
        before = path.read_text(encoding="utf-8") if path.is_file() else None
    except OSError as exc:
        raise MappingError(str(path), [f"cannot read it: {exc.strerror}"]) from None
    now = (
        check_mapping_text(before, str(path)).mapping if before is not None else load_mapping(base)
    )
    if now is not None and key in now.entities:
        raise MappingError(str(path), [f"entities.{key}: the mapping has this entity already"])
    try:
        text = entity_added(before, ref, key, fields)
    except ValueError as exc:
        raise MappingError(str(path), [str(exc)]) from None
    report = check_mapping_text(text, str(path))
    if report.mapping is None:
        raise MappingError(str(path), list(report.errors))
    return Proposed(path, before, text, report.mapping)


def write_atomic(path: Path, text: str) -> None:
    """Replace ``path`` by ``text`` at once: a temp file beside it, synced, renamed."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as file:
            file.write(text)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temp, path)
    except BaseException:
        Path(temp).unlink(missing_ok=True)
        raise


def restore(path: Path, text: str | None) -> None:
    """Put the override back as it was (``None``: there was none)."""
    if text is None:
        path.unlink(missing_ok=True)
    else:
        write_atomic(path, text)
