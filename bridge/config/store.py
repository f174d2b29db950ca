"""The config file as the web page edits it: one change at a time, validated as ``check``
validates, written atomically with a backup, never over a file changed on disk.

    store = ConfigStore.open(path)          # reads the file (ConfigError if unreadable)
    store.public_view() -> dict             # the file's data, secrets as SECRET_MARK
    store.preview(change) -> LoadedConfig   # the config the change gives; nothing written
    store.apply(change) -> Applied          # written: Applied(loaded, summary)
    store.refresh()                         # read the file again (after a conflict)
    ConfigStore.read_only(loaded, reason)   # a config that is no file: edits refused

Changes (bridge/config/edits.py): ``AddDevice``, ``EditDevice``, ``RemoveDevice``,
``AddBus``; ``parse_change(json_data)`` reads one. Errors (bridge/errors.py), all
``ConfigEditError(message, field)`` with nothing written: ``ConfigConflictError`` (the
file changed on disk; ``diff`` from what was read to what is there, secrets hidden),
``ConfigReadOnlyError``, ``ConfigWriteError`` (the disk refused; the file is as it was).

Applying: the change is made to the user's YAML (comments, key order, quoting and blank
lines kept: bridge/config/document.py), the text read back with ``load_config_data`` as
``check`` reads it, then written: a temp file in the same folder, fsync, the previous
version kept as ``<name>.1`` (``.1`` newest, ``BACKUPS`` kept), ``os.replace``; the file's
mode (and owner, as root) kept. A file given as a symbolic link is written where it
leads. Methods are blocking and thread-safe (one lock): async callers run them with
``asyncio.to_thread``. The summary names the change and each value it changed, secrets
hidden: fit for the log.
"""

from __future__ import annotations

import difflib
import hashlib
import os
import stat
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge.config.document import Document
from bridge.config.edits import AddBus, AddDevice, EditDevice, RemoveDevice, describe, make_change
from bridge.config.loading import LoadedConfig, load_config_data
from bridge.config.redaction import change_rows, public_data, redact_text
from bridge.core.yaml_source import parse_yaml
from bridge.errors import (
    ConfigConflictError,
    ConfigEditError,
    ConfigError,
    ConfigReadOnlyError,
    ConfigWriteError,
)

BACKUPS = 5  # previous versions kept: <name>.1 (newest) .. <name>.5
MAX_FILE_BYTES = 4 * 1024 * 1024  # a config file larger than this is not edited

AnyChange = AddDevice | EditDevice | RemoveDevice | AddBus


@dataclass(frozen=True, slots=True)
class Applied:
    """A change written: the config as the bridge now loads it, and what changed."""

    loaded: LoadedConfig
    summary: str


@dataclass(frozen=True, slots=True)
class _Read:
    """The file as the store read it."""

    raw: bytes
    text: str  # with "\n" line ends
    newline: str
    data: Any  # as the loader parses it


class ConfigStore:
    """The config file, read once, edited one change at a time (see the module)."""

    def __init__(
        self, path: Path, read: _Read | None, loaded: LoadedConfig | None = None, reason: str = ""
    ) -> None:
        self.path = path
        self._read = read
        self._loaded = loaded
        self._reason = reason
        self._lock = threading.Lock()

    @classmethod
    def open(cls, path: Path) -> ConfigStore:
        """The store of the config file at ``path``; ConfigError if it cannot be read."""
        return cls(path, _read_file(path))

    @classmethod
    def read_only(cls, loaded: LoadedConfig, reason: str) -> ConfigStore:
        """A store of a config that is no file the bridge may write (``reason`` says what
        it is: "the add-on's options"); views work, edits raise ConfigReadOnlyError."""
        return cls(loaded.path, None, loaded, reason)

    @property
    def writable(self) -> bool:
        return self._read is not None

    def public_view(self) -> dict[str, Any]:
        """The config's data as in the file, every secret shown as SECRET_MARK."""
        with self._lock:
            if self._read is not None:
                data = self._read.data
            else:
                assert self._loaded is not None  # one of the two is given
                data = self._loaded.config.model_dump(mode="json", exclude_defaults=True)
            view: dict[str, Any] = public_data(data)
            return view

    def refresh(self) -> None:
        """Read the file again (what a page shows after a conflict); ConfigError if it
        cannot be read."""
        with self._lock:
            if self._read is not None:
                self._read = _read_file(self.path)

    def preview(self, change: AnyChange) -> LoadedConfig:
        """The config ``change`` gives, validated as ``check`` does; nothing written."""
        with self._lock:
            return self._planned(change)[1]

    def apply(self, change: AnyChange) -> Applied:
        """Make ``change`` to the file: validated, then written atomically with a backup."""
        with self._lock:
            text, loaded, read = self._planned(change)
            loaded_data = parse_yaml(text, str(self.path))
            rows = change_rows(read.data, loaded_data, _renamed(change))
            if text != read.text:
                raw = text.replace("\n", read.newline).encode("utf-8")
                _write(_target(self.path), read.raw, raw)
                self._read = _Read(raw, text, read.newline, loaded_data)
            summary = "\n".join([f"{self.path}: {describe(change)}", *(f"  {r}" for r in rows)])
            return Applied(loaded, summary if rows else f"{summary} (no value changed)")

    def _planned(self, change: AnyChange) -> tuple[str, LoadedConfig, _Read]:
        read = self._read
        if read is None:
            raise ConfigReadOnlyError(
                f"the config is {self._reason}, not a file the page may write; change it there"
            )
        source = str(self.path)
        expected = _unshared(read.data)  # an anchor's uses are copies: only one changes
        make_change(expected, change, lambda value, _: _unshared(value))
        try:
            document = Document.parse(read.text, source)
            make_change(document.root, change, document.node)
            text = document.render(expected, source)
        except ValueError as exc:  # RenderError, or YAML ruamel reads otherwise than PyYAML
            raise ConfigEditError(str(exc)) from None
        try:
            loaded = load_config_data(parse_yaml(text, source), self.path)
        except ConfigError as exc:
            field, sep, message = exc.issues[0].partition(": ")
            if not sep:
                field, message = "", exc.issues[0]
            raise ConfigEditError(message, field, exc.issues) from None
        return text, loaded, read


def _unshared(data: Any) -> Any:
    """A copy of plain data in which no dict or list is in two places (YAML aliases)."""
    if isinstance(data, dict):
        return {key: _unshared(value) for key, value in data.items()}
    if isinstance(data, list):
        return [_unshared(item) for item in data]
    return data


def _renamed(change: AnyChange) -> tuple[str, str] | None:
    """A device's old and new id if ``change`` renames one."""
    new = change.set.get("id") if isinstance(change, EditDevice) else None
    return (change.id, new) if isinstance(change, EditDevice) and isinstance(new, str) else None


def _read_file(path: Path) -> _Read:
    try:
        with path.open("rb") as file:
            raw = file.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(str(path), [f"cannot read {path.absolute()}: {exc.strerror}"]) from None
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError(str(path), [f"larger than {MAX_FILE_BYTES} bytes: not edited here"])
    try:
        decoded = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(str(path), ["not UTF-8 text"]) from None
    newline = "\r\n" if "\r\n" in decoded else "\n"
    text = decoded.replace("\r\n", "\n")
    try:
        data = parse_yaml(text, str(path))
    except ValueError as exc:
        raise ConfigError(str(path), [str(exc)]) from None
    if not isinstance(data, dict):
        raise ConfigError(str(path), ["the file must hold a mapping with mqtt, buses, devices"])
    return _Read(raw, text, newline, data)


def _target(path: Path) -> Path:
    """Where writing ``path`` goes: a symbolic link's target (the link stays a link)."""
    return Path(os.path.realpath(path))


def _write(path: Path, expected: bytes, new: bytes) -> None:
    """``new`` in place of ``path`` if it still holds ``expected``: ConfigConflictError
    otherwise; ConfigWriteError if the disk refuses (the file as it was, no temp left)."""
    try:
        with path.open("rb") as file:
            on_disk = file.read(MAX_FILE_BYTES + 1)
        info = path.stat()
    except OSError as exc:
        raise ConfigWriteError(f"cannot read {path} again: {exc.strerror}") from None
    if hashlib.sha256(on_disk).digest() != hashlib.sha256(expected).digest():
        raise ConfigConflictError(str(path), conflict_diff(expected, on_disk, path.name))
    try:
        temp = _temp_copy(path, new, info)
    except OSError as exc:
        raise ConfigWriteError(f"cannot write beside {path}: {exc.strerror}") from None
    try:
        _rotate_backups(path, expected, info)
        os.replace(temp, path)
        _sync_folder(path.parent)
    except OSError as exc:
        raise ConfigWriteError(f"cannot replace {path}: {exc.strerror}") from None
    finally:
        temp.unlink(missing_ok=True)


def _temp_copy(path: Path, content: bytes, info: os.stat_result) -> Path:
    """``content`` in a new file beside ``path``, with its mode (and owner, as root), on
    disk (fsync) before anything is renamed."""
    handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    temp = Path(name)
    try:
        with os.fdopen(handle, "wb") as file:
            file.write(content)
            os.fchmod(file.fileno(), stat.S_IMODE(info.st_mode))
            if os.geteuid() == 0:
                os.fchown(file.fileno(), info.st_uid, info.st_gid)
            file.flush()
            os.fsync(file.fileno())
    except OSError:
        temp.unlink(missing_ok=True)
        raise
    return temp


def _rotate_backups(path: Path, previous: bytes, info: os.stat_result) -> None:
    """``<name>.1`` .. ``<name>.BACKUPS`` move one up (the oldest dropped) and the previous
    version becomes ``<name>.1``, with the file's mode (a backup holds its secrets too)."""
    for number in range(BACKUPS - 1, 0, -1):
        older = path.with_name(f"{path.name}.{number}")
        if older.exists():
            os.replace(older, path.with_name(f"{path.name}.{number + 1}"))
    temp = _temp_copy(path, previous, info)
    try:
        os.replace(temp, path.with_name(f"{path.name}.1"))
    finally:
        temp.unlink(missing_ok=True)


def _sync_folder(folder: Path) -> None:
    """The renames on disk too (a folder's entries are its data)."""
    handle = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(handle)
    finally:
        os.close(handle)


def conflict_diff(read: bytes, on_disk: bytes, name: str) -> str:
    """A unified diff from what was read to what is on disk, secrets hidden: the lines are
    compared as they are (a changed password shows as a changed line), then shown hidden."""
    before = read.decode("utf-8", "replace").splitlines(keepends=True)
    after = on_disk.decode("utf-8", "replace").splitlines(keepends=True)
    shown_before = redact_text("".join(before)).splitlines(keepends=True)
    shown_after = redact_text("".join(after)).splitlines(keepends=True)
    lines = [f"--- {name} (read)\n", f"+++ {name} (on disk)\n"]
    matcher = difflib.SequenceMatcher(None, before, after, autojunk=False)
    for group in matcher.get_grouped_opcodes(3):
        first, last = group[0], group[-1]
        lines.append(
            f"@@ -{first[1] + 1},{last[2] - first[1]} +{first[3] + 1},{last[4] - first[3]} @@\n"
        )
        for tag, i1, i2, j1, j2 in group:
            if tag == "equal":
                lines += [f" {line}" for line in shown_before[i1:i2]]
                continue
            lines += [f"-{line}" for line in shown_before[i1:i2]]
            lines += [f"+{line}" for line in shown_after[j1:j2]]
    return "".join(line if line.endswith("\n") else line + "\n" for line in lines)
