"""Bounded YAML reading for importers: every mapping remembers the file and line of its
keys, Home Assistant's tags are resolved or kept as ``Unresolved`` for the report.

A file to import is input from outside (a community package of hundreds of registers, a
file someone sent): it is read with a safe loader, its size, the depth and number of
``!include`` files and the folder they may come from are bounded, and a tag the importer
does not resolve (``!env_var``, ``!include_dir_*``, ``!input``) becomes an ``Unresolved``
value that the converters report where it is used, never a guess.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bridge.core.yaml_source import _StrictLoader

MAX_FILE_BYTES = 2_000_000  # one YAML file
MAX_FILES = 64  # the file and everything it includes
MAX_INCLUDE_DEPTH = 5


class SourceError(ValueError):
    """A file that cannot be read or parsed at all (the message names file and line)."""


@dataclass(frozen=True, slots=True)
class Where:
    """A place in a source file (line 1-based)."""

    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"


class Node(dict[Any, Any]):
    """A YAML mapping that knows where it and each of its keys were written."""

    where: Where
    places: dict[Any, Where]

    def at(self, key: object) -> Where:
        """Where ``key`` was written (the mapping's own place if it was not)."""
        return self.places.get(key, self.where)


@dataclass(frozen=True, slots=True)
class Unresolved:
    """A tagged value the importer does not resolve, and why."""

    tag: str
    value: str
    where: Where
    reason: str


@dataclass(slots=True)
class _Budget:
    """What one import may still read, shared by the file and its includes."""

    root: Path
    files: int = 0
    secrets: dict[str, Any] | None = None
    secrets_file: Path | None = None
    problems: list[Unresolved] = field(default_factory=list)


def load_source(path: Path, root: Path | None = None) -> Any:
    """Parse ``path`` (and the files it ``!include``s, inside ``root``, default its folder)
    into plain values with ``Node`` mappings. Raise SourceError if it cannot be read."""
    budget = _Budget(root=(root or path.parent).resolve())
    return _load(path.resolve(), budget, 0)


def _load(path: Path, budget: _Budget, depth: int) -> Any:
    budget.files += 1
    if budget.files > MAX_FILES:
        raise SourceError(f"{path}: more than {MAX_FILES} files included")
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise SourceError(f"{path}: {size} bytes, more than {MAX_FILE_BYTES}")
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SourceError(f"cannot read {path}: {exc}") from exc
    loader = _Loader(text)
    loader.path, loader.budget, loader.depth = path, budget, depth
    try:
        return loader.get_single_data()
    except yaml.YAMLError as exc:
        raise SourceError(f"{path}: invalid YAML: {exc}") from exc
    finally:
        loader.dispose()


class _Loader(_StrictLoader):
    """The strict safe loader, with positions and Home Assistant's tags."""

    path: Path
    budget: _Budget
    depth: int

    def where(self, node: yaml.Node) -> Where:
        return Where(_shown(self.path, self.budget.root), node.start_mark.line + 1)


def _shown(path: Path, root: Path) -> str:
    try:
        return str(path.relative_to(root))
    except ValueError:
        return str(path)


def _mapping(loader: _Loader, node: yaml.MappingNode) -> Node:
    plain = _StrictLoader.yaml_constructors[yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG]
    data = Node(plain(loader, node))
    data.where = loader.where(node)
    data.places = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=True)
        if isinstance(key, str | int):
            data.places[key] = loader.where(key_node)
    return data


def _include(loader: _Loader, node: yaml.Node) -> Any:
    name = str(loader.construct_scalar(node))
    where = loader.where(node)
    target = (loader.path.parent / name).resolve()
    if not target.is_relative_to(loader.budget.root):
        return Unresolved("!include", name, where, f"outside {loader.budget.root}: not read")
    if loader.depth + 1 > MAX_INCLUDE_DEPTH:
        return Unresolved("!include", name, where, f"more than {MAX_INCLUDE_DEPTH} levels deep")
    if not target.is_file():
        return Unresolved("!include", name, where, f"no file {target}")
    return _load(target, loader.budget, loader.depth + 1)


def _secret(loader: _Loader, node: yaml.Node) -> Any:
    name = str(loader.construct_scalar(node))
    where = loader.where(node)
    budget = loader.budget
    if budget.secrets is None:
        budget.secrets_file = budget.root / "secrets.yaml"
        found = _load(budget.secrets_file, budget, 1) if budget.secrets_file.is_file() else {}
        budget.secrets = found if isinstance(found, dict) else {}
    if name not in budget.secrets:
        return Unresolved("!secret", name, where, f"not in {budget.secrets_file}")
    return budget.secrets[name]


def _other(loader: _Loader, suffix: str, node: yaml.Node) -> Unresolved:
    value = loader.construct_scalar(node) if isinstance(node, yaml.ScalarNode) else "..."
    return Unresolved(
        f"!{suffix}", str(value), loader.where(node), "tag not resolved by the import"
    )


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)
_Loader.add_constructor("!include", _include)
_Loader.add_constructor("!secret", _secret)
_Loader.add_multi_constructor("!", _other)
