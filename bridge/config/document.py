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

import difflib
import io
import itertools
from collections.abc import Sequence
from typing import Any

import yaml
from ruamel.yaml import YAML
from ruamel.yaml.comments import CommentedMap, CommentedSeq
from ruamel.yaml.error import YAMLError
from ruamel.yaml.scalarstring import DoubleQuotedScalarString

from bridge.core.yaml_source import parse_yaml

_INDENTS = tuple(
    (mapping, sequence, offset)
    for mapping, sequence, offset in itertools.product((2, 4), (2, 4), (0, 2))
    if offset < sequence
)
_RESOLVER = yaml.resolver.Resolver()
_STR = "tag:yaml.org,2002:str"


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

    def __init__(self, text: str, root: Any, handler: YAML, base: str) -> None:
        self.text = text
        self.root = root
        self._handler = handler
        self._base = base  # ruamel's dump of the unedited document

    @classmethod
    def parse(cls, text: str, source: str) -> Document:
        """The document of ``text``; ValueError naming ``source`` if it is no YAML mapping.
        The indentation ruamel writes is the one that reproduces most of the user's lines."""
        try:
            parse_yaml(text, source)  # the loader's reading (duplicate keys refused)
            best: tuple[int, Document] | None = None
            for indent in _INDENTS:
                handler = _yaml(indent)
                root = handler.load(text)
                if not isinstance(root, CommentedMap):
                    raise ValueError(f"{source}: the file must hold a mapping")
                base = _dump(handler, root)
                changed = _changed_lines(text, base)
                if best is None or changed < best[0]:
                    best = (changed, cls(text, handler.load(text), handler, base))
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


def above_blank_lines(base: list[str], edited: list[str]) -> list[str]:
    """``edited`` with each block of added lines moved up above the blank and comment lines
    before it: ruamel writes a new key or entry after the blank line and comments that close
    the one before, which belong to what follows."""
    result: list[str] = []
    matcher = difflib.SequenceMatcher(None, base, edited, autojunk=False)
    for tag, _, _, j1, j2 in matcher.get_opcodes():
        if tag != "insert":
            result += edited[j1:j2]
            continue
        keep = len(result)
        while keep > 0 and (not result[keep - 1].strip() or result[keep - 1].lstrip()[0] == "#"):
            keep -= 1
        result[keep:keep] = edited[j1:j2]
    return result


def _changed_lines(text: str, other: str) -> int:
    matcher = difflib.SequenceMatcher(None, text.splitlines(), other.splitlines(), autojunk=False)
    return sum(
        max(i2 - i1, j2 - j1) for tag, i1, i2, j1, j2 in matcher.get_opcodes() if tag != "equal"
    )


def merge_lines(user: list[str], base: list[str], edited: list[str]) -> list[str]:
    """The changes from ``base`` to ``edited`` made to ``user`` (``base`` in the user's
    layout). Where a change meets lines the user laid out otherwise, the edited lines of
    that stretch win."""
    user_hunks = _hunks(base, user)
    edit_ops = difflib.SequenceMatcher(None, base, edited, autojunk=False).get_opcodes()
    edit_hunks = [(i1, i2, edited[j1:j2], 1) for tag, i1, i2, j1, j2 in edit_ops if tag != "equal"]
    result: list[str] = []
    position = 0
    for start, end, lines, members in _clusters(sorted(user_hunks + edit_hunks)):
        result += base[position:start]
        if members > 1:  # both changed this stretch: the edit's version of it
            result += edited[_mapped(edit_ops, start) : _mapped(edit_ops, end)]
        else:
            result += lines
        position = end
    return result + base[position:]


def _hunks(base: list[str], other: list[str]) -> list[tuple[int, int, list[str], int]]:
    matcher = difflib.SequenceMatcher(None, base, other, autojunk=False)
    return [
        (i1, i2, other[j1:j2], 0) for tag, i1, i2, j1, j2 in matcher.get_opcodes() if tag != "equal"
    ]


def _clusters(
    hunks: list[tuple[int, int, list[str], int]],
) -> list[tuple[int, int, list[str], int]]:
    """Hunks (sorted) grouped where they touch the same base lines: (start, end, the lines
    of a lone hunk, how many hunks)."""
    clusters: list[tuple[int, int, list[str], int]] = []
    for start, end, lines, _ in hunks:
        if clusters:
            c_start, c_end, c_lines, count = clusters[-1]
            inserts = start == end and c_start == c_end == start
            if start < c_end or (start == end and c_start < start < c_end) or inserts:
                clusters[-1] = (c_start, max(c_end, end), c_lines, count + 1)
                continue
        clusters.append((start, end, lines, 1))
    return clusters


def _mapped(ops: Sequence[tuple[str, int, int, int, int]], position: int) -> int:
    """The line of the edited text at ``position`` of the base (a hunk's edge)."""
    for tag, i1, i2, j1, j2 in ops:
        if i1 <= position <= i2:
            if tag == "equal":
                return j1 + position - i1
            return j1 if position == i1 else j2
    return sum(j2 - j1 for _, _, _, j1, j2 in ops)
