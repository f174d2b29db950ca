"""The config file as a YAML document that keeps the user's layout: comments, key order,
quoting, blank lines. The only module that imports ruamel.yaml (pinned to one minor).

An edit changes ``Document.root`` (ruamel's dict and list types, edited like plain ones;
new values go through ``Document.node``). ``render`` then writes the user's text with that
change only: ruamel dumps the document before and after the edit, and the lines the edit
changed are merged into the user's own text (a three-way merge), so whatever ruamel would
lay out otherwise (a flow mapping over two lines, its inner comments, odd spacing) stays as
the user wrote it outside the edit. The result must read back, with the loader's own
``parse_yaml`` (YAML 1.1, PyYAML), as the expected data, else ``render`` refuses it.
"""

from __future__ import annotations

import io
import itertools
from typing import Any

import yaml
from ruamel.yaml import YAML
from ruamel.yaml.comments import CommentedMap, CommentedSeq
from ruamel.yaml.error import YAMLError
from ruamel.yaml.scalarstring import DoubleQuotedScalarString

from bridge.config.lines import above_blank_lines, changed_lines, merge_lines
from bridge.core.yaml_source import parse_yaml

_INDENTS = tuple(
    (mapping, sequence, offset)
    for mapping, sequence, offset in itertools.product((2, 4), (2, 4), (0, 2))
    if offset < sequence
)
_RESOLVER = yaml.resolver.Resolver()
_STR = "tag:yaml.org,2002:str"


def _guessed_indent(lines: list[str]) -> tuple[int, int, int]:
    """The indentation the user's lines suggest: (mapping, sequence, dash offset)."""
    mapping = next((_indent(line) for line in lines if _indent(line) and _content(line)), 2)
    dashes = [_indent(line) for line in lines if line.lstrip().startswith("- ")]
    offset = min(dashes, default=0)
    return (
        (mapping if mapping in (2, 4) else 2, offset + 2, offset) if offset in (0, 2) else (2, 4, 2)
    )


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def _content(line: str) -> bool:
    stripped = line.strip()
    return bool(stripped) and not stripped.startswith(("#", "- "))


def _read_as(text: str) -> str:
    """The tag PyYAML (YAML 1.1) reads the plain scalar ``text`` as."""
    tag: str = _RESOLVER.resolve(yaml.ScalarNode, text, (True, False))  # type: ignore[no-untyped-call]
    return tag


class RenderError(ValueError):
    """The edited document cannot be written so that it reads back as intended."""


def _yaml(indent: tuple[int, int, int]) -> YAML:
    handler = YAML(typ="rt")
    handler.preserve_quotes = True
    handler.width = 4096  # never fold a long line the user wrote on one
    handler.indent(mapping=indent[0], sequence=indent[1], offset=indent[2])
    return handler


def _dump(handler: YAML, root: Any) -> str:
    out = io.StringIO()
    handler.dump(root, out)
    return out.getvalue()


class Document:
    """A config file's YAML, editable in place; ``text`` is the user's (``\\n`` lines)."""

    def __init__(
        self, text: str, root: Any, indent: tuple[int, int, int], handler: YAML, base: str
    ) -> None:
        self.text = text
        self.root = root
        self.indent = indent  # (mapping, sequence, dash offset) ruamel writes
        self._handler = handler
        self._base = base  # ruamel's dump of the unedited document

    @classmethod
    def parse(cls, text: str, source: str, indent: tuple[int, int, int] | None = None) -> Document:
        """The document of ``text``; ValueError naming ``source`` if it is no YAML mapping.
        The indentation ruamel writes is ``indent``, else the one that reproduces most of
        the user's lines (the one a previous parse of the same text found)."""
        try:
            parse_yaml(text, source)  # the loader's reading (duplicate keys refused)
            best: tuple[int, Document] | None = None
            lines = text.splitlines()
            guess = _guessed_indent(lines)
            candidates = [indent] if indent else sorted(_INDENTS, key=lambda c: c != guess)
            for candidate in candidates:
                handler = _yaml(candidate)
                root = handler.load(text)
                if not isinstance(root, CommentedMap):
                    raise ValueError(f"{source}: the file must hold a mapping")
                base = _dump(handler, root)
                changed = changed_lines(lines, base.splitlines())
                if best is None or changed < best[0]:
                    best = (changed, cls(text, root, candidate, handler, base))
                if changed == 0:
                    break
        except YAMLError as exc:
            raise ValueError(f"{source}: invalid YAML: {exc}") from None
        assert best is not None  # _INDENTS is not empty
        return best[1]

    def node(self, value: Any, like: Any = None) -> Any:
        """``value`` (plain data) as a node of this document: strings the loader would read
        as something else (``on``, ``0755``, ``12:30``) quoted; a mapping in flow style when
        ``like`` (its sibling) is one."""
        if isinstance(value, dict):
            result = CommentedMap((self.node(k), self.node(v)) for k, v in value.items())
            if getattr(getattr(like, "fa", None), "flow_style", lambda: False)():
                result.fa.set_flow_style()
            return result
        if isinstance(value, list):
            return CommentedSeq(self.node(item) for item in value)
        if isinstance(value, str) and _read_as(value) != _STR:
            return DoubleQuotedScalarString(value)
        return value

    def render(self, expected: Any, source: str) -> str:
        """The user's text with the edit made to ``root``; RenderError unless it reads back
        (with the loader's parser) as ``expected``."""
        edited = _dump(self._handler, self.root)
        user, base = self.text.splitlines(keepends=True), self._base.splitlines(keepends=True)
        lines = edited.splitlines(keepends=True)
        candidates = (
            "".join(merge_lines(user, base, above_blank_lines(base, lines))),
            "".join(merge_lines(user, base, lines)),
            edited,  # the whole dump if no merge keeps the data
        )
        for text in candidates:
            try:
                if parse_yaml(text, source) == expected:
                    return text
            except ValueError:
                continue
        raise RenderError(
            f"{source}: the edit cannot be written so that it reads back as made (a part the "
            "file shares through a YAML anchor, &name, would change wherever it is used); "
            "edit that part of the file by hand"
        )
