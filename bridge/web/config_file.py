"""The config file as the page changes it: written by the config store
(bridge/config/store.py), then applied to the running bridge. The one writer of the file
while the bridge runs: every page change goes through ``WebApp.config_file``.

``ConfigFile(bridge).change(*changes)`` (``AddBus`` then ``AddDevice`` on it, or one
edit) runs, holding one lock (two page changes never interleave: a change written first
and applied last would undo the other in the running bridge):

1. the store (``bridge.loaded.path``; a config that is no file, the demo's, gets a
   read-only store), opened when the page starts serving (``open``) so that a change made
   to the file by hand after it is shown as a diff; then, until the file on disk loads as
   the config the bridge runs, every change is refused saying what the file holds that the
   bridge does not run (apply it first: SIGHUP or a restart; or undo it), so the page only
   ever applies its own change;
2. ``store.apply(change)`` for each change in turn: validated as ``check`` does, written
   atomically with a backup, comments kept;
3. ``bridge.apply_config(loaded)`` once, with the config of the last change written: only
   what changed starts, stops or restarts. Should a later change be refused, the ones
   written before it are applied all the same (the file and the bridge never part) and
   the refusal says what was written.

A page change never touches what needs a restart (the ``mqtt`` and ``bridge`` sections);
were it refused all the same, the answer says the file is written and the bridge needs a
restart. Refusals are ``ConfigChangeError(status, message)``: 400 for a value the config
refuses (naming its field), 403 for a read-only config, 409 for a file changed on disk
since it was read (``diff`` from what was read to what is there; the store reads the file
again) or one the bridge does not run, 500 for a disk that refused the write (the file
as it was). Blocking calls run in a thread.
"""

from __future__ import annotations

import asyncio
import contextlib
from dataclasses import dataclass
from http import HTTPStatus
from typing import TYPE_CHECKING, Any

from bridge.config import LoadedConfig, load_config
from bridge.config.store import AnyChange, Applied, ConfigStore
from bridge.core.config_diff import diff_configs
from bridge.errors import (
    ConfigConflictError,
    ConfigEditError,
    ConfigError,
    ConfigReadOnlyError,
    ConfigWriteError,
)
from bridge.reconfigure import view_of
from bridge.web.parts import BridgeState

if TYPE_CHECKING:
    from pathlib import Path


class ConfigChangeError(Exception):
    """A change refused: ``status`` and one line saying why; ``diff`` for a conflict."""

    def __init__(self, status: HTTPStatus, message: str, diff: str = "") -> None:
        super().__init__(message)
        self.status = status
        self.diff = diff


@dataclass(frozen=True, slots=True)
class Changed:
    """A change written and applied: the store's summary (no secrets) and what the
    running bridge did (``apply_config``'s answer)."""

    summaries: tuple[str, ...]  # one per change
    applied: dict[str, Any]

    @property
    def summary(self) -> str:
        return "\n".join(self.summaries)

    @property
    def line(self) -> str:
        """The summary on one line, for the log."""
        return "; ".join(part.strip() for part in self.summary.splitlines())


class ConfigFile:
    """The running bridge's config file, changed one change at a time (see the module)."""

    def __init__(self, bridge: BridgeState) -> None:
        self.bridge = bridge
        self.lock = asyncio.Lock()
        self._store: ConfigStore | None = None
        self._in_step = False  # the file on disk was seen to load as the running config

    async def open(self) -> None:
        """Read the file now (the page starts serving): a later change on disk is a
        conflict, shown as a diff."""
        with contextlib.suppress(ConfigChangeError):
            if (await self.store()).writable:
                await self._check_in_step()

    async def store(self) -> ConfigStore:
        """The store, opened at the first call: read-only, saying why, for a config that
        is no file or a file that cannot be read."""
        if self._store is None:
            self._store = await asyncio.to_thread(_open, self.bridge.loaded)
        return self._store

    async def change(self, *changes: AnyChange) -> Changed:
        """Write ``changes`` and apply them (see the module); ConfigChangeError if refused."""
        async with self.lock:
            store = await self.store()
            if not self._in_step and store.writable:
                await self._check_in_step()
            written: list[Applied] = []
            try:
                for change in changes:
                    written.append(await self._write(store, change))
            except ConfigChangeError as exc:
                if not written:
                    raise
                await self._run(written)
                said = "; ".join(w.summary.splitlines()[0] for w in written)
                raise ConfigChangeError(
                    exc.status, f"{exc} (written and applied: {said})"
                ) from None
            return Changed(tuple(w.summary for w in written), await self._run(written))

    async def _write(self, store: ConfigStore, change: AnyChange) -> Applied:
        try:
            return await _apply(store, change)
        except ConfigConflictError as exc:
            await asyncio.to_thread(store.refresh)
            self._in_step = False
            raise ConfigChangeError(HTTPStatus.CONFLICT, exc.message, exc.diff) from None

    async def _run(self, written: list[Applied]) -> dict[str, Any]:
        """The config of the last change written, applied to the running bridge."""
        answer = await self.bridge.apply_config(written[-1].loaded)
        if answer.get("status") != "ok":
            message = f"written, not applied: {answer.get('error')}; restart the bridge"
            raise ConfigChangeError(HTTPStatus.INTERNAL_SERVER_ERROR, message)
        return answer

    async def _check_in_step(self) -> None:
        """ConfigChangeError (409) unless the file on disk loads as the running config."""
        running = self.bridge.loaded
        try:
            on_disk = await asyncio.to_thread(load_config, running.path)
        except ConfigError as exc:
            message = f"the config file does not load now, nothing written: {exc}"
            raise ConfigChangeError(HTTPStatus.CONFLICT, message) from None
        if on_disk.config != running.config:
            held = diff_configs(view_of(running), view_of(on_disk)).describe()
            message = (
                f"the config file holds changes the bridge does not run ({held}): apply them "
                "first (SIGHUP or a restart) or undo them; nothing written"
            )
            raise ConfigChangeError(HTTPStatus.CONFLICT, message)
        self._in_step = True


async def _apply(store: ConfigStore, change: AnyChange) -> Applied:
    """``store.apply`` in a thread, its refusals as ConfigChangeError; a conflict raised
    as it is (the caller looks at the file again)."""
    try:
        return await asyncio.to_thread(store.apply, change)
    except ConfigConflictError:
        raise
    except ConfigReadOnlyError as exc:
        raise ConfigChangeError(HTTPStatus.FORBIDDEN, exc.message) from None
    except ConfigWriteError as exc:
        raise ConfigChangeError(HTTPStatus.INTERNAL_SERVER_ERROR, exc.message) from None
    except ConfigEditError as exc:
        where = f"{exc.field}: " if exc.field else ""
        raise ConfigChangeError(HTTPStatus.BAD_REQUEST, where + exc.message) from None


def _open(loaded: LoadedConfig) -> ConfigStore:
    path: Path = loaded.path
    if not path.is_file():
        return ConfigStore.read_only(loaded, f"built without a file ({path.name} is not there)")
    try:
        return ConfigStore.open(path)
    except ConfigError as exc:
        return ConfigStore.read_only(loaded, f"a file the page cannot read ({exc.issues[0]})")
