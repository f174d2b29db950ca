"""The built mapping of a ``mapping: sunspec`` device, kept in the bridge's state folder.

``<state_dir>/sunspec/<device id>.yaml`` is ``BuiltMapping.yaml()`` (a mapping file
``load_mapping`` reads) and ``<device id>.json`` what it was built from: the chain's
``signature`` (the marker's base and each model's id, address and length) and the
``setting`` (the bases tried, the read limit, the bridge's version). ``load`` gives the
cached mapping only when its setting is the device's now (another base, read limit or
bridge version builds afresh); a walk whose signature differs from the cached one (a
firmware update) rebuilds. Both files are written whole (a temporary file renamed), the
JSON last, so a stop mid-write leaves no cache that looks valid. ``pending`` is the
mapping of a device not walked yet: no entity, so nothing is polled or discovered.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge import __version__
from bridge.core.mapping import Mapping, Source, load_mapping
from bridge.core.protocol import Protocol
from bridge.errors import MappingError
from bridge.sunspec.mapping import BuiltMapping
from bridge.sunspec.walk import BASES, Chain

log = logging.getLogger(__name__)
FOLDER = "sunspec"  # under the state folder
MAX_SIDECAR = 1024 * 1024  # bytes of the signature file: a chain of 100 models is 3 kB

Signature = dict[str, Any]


@dataclass(frozen=True, slots=True)
class Cached:
    """A device's cached mapping and the chain signature it was built from."""

    mapping: Mapping
    signature: Signature


def signature(chain: Chain) -> Signature:
    """What a changed chain changes: the base and each model's id, address and length."""
    return {"base": chain.base, "models": [[m.id, m.address, m.length] for m in chain.models]}


def setting(bases: Sequence[int] | None, read_limit: int) -> dict[str, Any]:
    """What the mapping was built with besides the chain."""
    return {"bases": list(bases or BASES), "read_limit": read_limit, "bridge": __version__}


def paths(state_dir: Path, device_id: str) -> tuple[Path, Path]:
    """The mapping file and the signature file of a device."""
    folder = state_dir / FOLDER
    return folder / f"{device_id}.yaml", folder / f"{device_id}.json"


def load(
    state_dir: Path, device_id: str, bases: Sequence[int] | None, read_limit: int
) -> Cached | None:
    """The cached mapping, if there is one built with this setting and it loads; a cache
    that does not load is logged and ignored (the device is walked)."""
    mapping_file, sidecar = paths(state_dir, device_id)
    if not sidecar.is_file():
        return None
    try:
        if sidecar.stat().st_size > MAX_SIDECAR:
            raise ValueError(f"over {MAX_SIDECAR} bytes")
        record = json.loads(sidecar.read_text(encoding="utf-8"))
        if not isinstance(record, dict) or record.get("setting") != setting(bases, read_limit):
            return None
        chain = record["signature"]
        if not isinstance(chain, dict):
            raise ValueError("no signature")
        return Cached(load_mapping(mapping_file), chain)
    except (OSError, ValueError, KeyError, MappingError) as exc:
        log.warning("%s: the cached SunSpec mapping is not usable (%s); walking it", device_id, exc)
        return None


def store(
    state_dir: Path,
    device_id: str,
    chain: Chain,
    built: BuiltMapping,
    *,
    bases: Sequence[int] | None,
    read_limit: int,
) -> None:
    """Write the device's mapping and signature (OSError if the folder is not writable)."""
    mapping_file, sidecar = paths(state_dir, device_id)
    mapping_file.parent.mkdir(parents=True, exist_ok=True)
    record = {"signature": signature(chain), "setting": setting(bases, read_limit)}
    sidecar.unlink(missing_ok=True)  # no signature beside a half-written mapping
    _write(mapping_file, built.yaml())
    _write(sidecar, json.dumps(record, indent=1) + "\n")


def _write(path: Path, text: str) -> None:
    temporary = path.with_name(f".{path.name}.tmp")
    temporary.write_text(text, encoding="utf-8")
    os.replace(temporary, path)


def pending() -> Mapping:
    """The mapping of a SunSpec device before its first walk: no entity (a model not
    validated: a mapping file needs one)."""
    return Mapping.model_construct(
        manufacturer="SunSpec",
        model="device not walked yet",
        description="a mapping: sunspec device before its model chain is walked",
        source=Source(title="SunSpec information models"),
        protocol=Protocol(),
        options={},
        status=None,
        entities={},
    )
