"""The page's "add as entity": a raw register of a device becomes an entity of its mapping.

    POST api/entity/preview   {device, key, name, address, type, ..., words?} -> the value
                              as Home Assistant would show it (``words``: the registers
                              the commissioning read gave; without them, or too few for
                              the type, read once as ``device/read`` reads)
    POST api/entity/add       the same -> the device's override file written, the device's
                              mapping reloaded: {path, mapping, key, changed}

The proposal is bounded (bridge/core/entity_proposal.py) and checked by the mapping
loader through the device's override (bridge/config/user_mapping.py): a key the mapping
has, a guarded register of the base, an overlap are refused with the loader's rows, and
nothing is written. A shipped mapping is never edited. The entity is read-only: the page
cannot make a register writable. An add writes the file atomically and asks
``mapping/reload`` for that device; a reload that fails puts the file back as it was.
Each request is one log line: who, which device and key, and what came of it.
"""

from __future__ import annotations

import asyncio
import json
import logging
from http import HTTPStatus
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from bridge.config.user_mapping import Proposed, propose, restore, write_atomic
from bridge.core.entity_proposal import EntityProposal, entity_fields, preview
from bridge.core.mapping import format_validation_errors
from bridge.errors import MappingError
from bridge.web.http import Request, Response
from bridge.web.parts import BridgeParts

ROUTES = frozenset({"/api/entity/preview", "/api/entity/add"})
MAX_ROWS = 10  # problems answered at most (each names its field)
ROW_LIMIT = 300  # characters of one problem (a 60 kB field name is not echoed)
_JSON = "application/json"

log = logging.getLogger(__name__)


class RefusedError(Exception):
    """A request answered with ``status`` and ``rows``; nothing was written."""

    def __init__(self, status: HTTPStatus, rows: list[str]) -> None:
        super().__init__("; ".join(rows))
        self.status = status
        self.rows = [_one_line(row, ROW_LIMIT) for row in rows[:MAX_ROWS]]


class EntityRoutes:
    """Preview and add; one add at a time (the override is read, edited and replaced)."""

    def __init__(self, bridge: BridgeParts) -> None:
        self.bridge = bridge
        self._adding = asyncio.Lock()

    async def handle(self, request: Request) -> Response:
        action = request.path.removeprefix("/api/entity/")
        who = request.peer
        try:
            proposal = _proposal(request.body)
            if action == "add":
                async with self._adding:
                    data = await self._add(proposal)
            else:
                data = await self._preview(proposal)
        except RefusedError as refused:
            said = _one_line(str(refused))
            log.warning("entity %s from %s refused (%d): %s", action, who, refused.status, said)
            return _answer(refused.status, {"status": "error", "errors": refused.rows})
        what = data["entity"] if action == "preview" else data
        said = _one_line(f"{proposal.device}.{proposal.key} {json.dumps(what, default=str)}")
        log.info("entity %s from %s: %s", action, who, said)
        return _answer(HTTPStatus.OK, {"status": "ok", "data": data})

    async def _proposed(self, proposal: EntityProposal) -> Proposed:
        poller = self.bridge.engine.devices.get(proposal.device)
        if poller is None:
            raise RefusedError(HTTPStatus.NOT_FOUND, [f"device: no device {proposal.device!r}"])
        loaded = self.bridge.loaded
        folder = loaded.path.parent
        state_dir = folder / loaded.config.bridge.state_dir
        fields = entity_fields(proposal, poller.mapping.protocol.addressing)
        try:
            return await asyncio.to_thread(
                propose, poller.device, folder, state_dir, proposal.key, fields
            )
        except MappingError as exc:
            raise RefusedError(HTTPStatus.UNPROCESSABLE_ENTITY, list(exc.issues)) from None

    async def _preview(self, proposal: EntityProposal) -> dict[str, Any]:
        proposed = await self._proposed(proposal)
        count = proposed.mapping.points()[proposal.key].count
        words = proposal.words
        if words is None or len(words) < count:  # not read yet, or not all of it
            words = await self._read(proposal, count)
        try:
            shown = preview(proposed.mapping, proposal.key, words)
        except ValueError as exc:
            raise RefusedError(HTTPStatus.UNPROCESSABLE_ENTITY, [str(exc)]) from None
        return shown | {"words": list(words), "entity": _entity_of(proposed, proposal.key)}

    async def _read(self, proposal: EntityProposal, count: int) -> tuple[int, ...]:
        """The registers (or bits) of the proposal, read once as ``device/read`` reads."""
        body: dict[str, object] = {"device": proposal.device, "table": proposal.table}
        body |= {"address": proposal.address, "count": count}
        answer = json.loads(
            await self.bridge.management.handle("device/read", json.dumps(body).encode())
        )
        if answer["status"] != "ok":
            raise RefusedError(HTTPStatus.BAD_GATEWAY, [f"read: {answer['error']}"])
        data = answer["data"]
        return tuple(data["registers"] if "registers" in data else data["bits"])

    async def _add(self, proposal: EntityProposal) -> dict[str, Any]:
        proposed = await self._proposed(proposal)
        await asyncio.to_thread(write_atomic, proposed.path, proposed.text)
        body = json.dumps({"devices": [proposal.device]})
        answer = json.loads(await self.bridge.management.handle("mapping/reload", body.encode()))
        if answer["status"] != "ok":
            await asyncio.to_thread(restore, proposed.path, proposed.before)
            raise RefusedError(HTTPStatus.UNPROCESSABLE_ENTITY, [f"reload: {answer['error']}"])
        return {
            "entity": _entity_of(proposed, proposal.key),
            "path": str(proposed.path),
            "mapping": str(_shown_path(proposed.path, self.bridge.loaded.path.parent)),
            "key": proposal.key,
            "changed": answer["data"]["changed"],
        }


def _proposal(body: bytes) -> EntityProposal:
    try:
        data = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        raise RefusedError(HTTPStatus.BAD_REQUEST, ["send a JSON object"]) from None
    if not isinstance(data, dict):
        raise RefusedError(HTTPStatus.BAD_REQUEST, ["send a JSON object"])
    try:
        return EntityProposal.model_validate(data)
    except ValidationError as exc:
        raise RefusedError(HTTPStatus.BAD_REQUEST, list(format_validation_errors(exc))) from None


def _entity_of(proposed: Proposed, key: str) -> dict[str, Any]:
    """The entity as the override file holds it (what an add writes)."""
    entity = proposed.mapping.entities[key]
    return entity.model_dump(mode="json", exclude_defaults=True)


def _shown_path(path: Path, folder: Path) -> Path:
    """The override as a device's ``mapping:`` would name it: relative to the config."""
    try:
        return path.relative_to(folder)
    except ValueError:
        return path


def _one_line(text: str, limit: int = 500) -> str:
    """``text`` on one line, control characters escaped, cut at ``limit``."""
    flat = text.encode("unicode_escape").decode("ascii")
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


def _answer(status: HTTPStatus, document: dict[str, Any]) -> Response:
    return Response(status, json.dumps(document, default=str).encode("utf-8"), _JSON)
