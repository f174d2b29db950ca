"""The mapping library as the page searches it: every shipped mapping (the seeds and
``mappings/library/<category>/``) with its manufacturer, model, category and the other
names people search it by; a query matches a mapping when each of its words is in one
of those (case-blind). The query is at most ``MAX_QUERY`` characters and ``MAX_WORDS``
words, the answer at most ``MAX_RESULTS`` mappings (``total`` says how many matched).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping as AnyMapping
from typing import Any

from bridge.core.mapping import Mapping, shipped_library

MAX_QUERY = 100
MAX_WORDS = 8
MAX_RESULTS = 50


class QueryError(ValueError):
    """A query the library is not searched for (too long, too many words)."""


def library_row(name: str, mapping: Mapping) -> dict[str, Any]:
    library = mapping.library
    return {
        "mapping": name,
        "manufacturer": mapping.manufacturer,
        "model": mapping.model,
        "category": library.category.value if library is not None else "",
        "aliases": list(library.aliases) if library is not None else [],
        "transports": list(mapping.protocol.transports),
        "options": {
            name: {"description": o.description, "choices": list(o.choices), "default": o.default}
            for name, o in mapping.options.items()
        },
    }


@functools.cache
def shipped_rows() -> tuple[dict[str, Any], ...]:
    """Every shipped mapping's row, built once (loading the library takes a while: call it
    off the event loop the first time)."""
    return rows_of(shipped_library())


def rows_of(library: AnyMapping[str, Mapping]) -> tuple[dict[str, Any], ...]:
    rows = (library_row(name, mapping) for name, mapping in library.items())
    return tuple(sorted(rows, key=lambda r: (r["manufacturer"].lower(), r["model"].lower())))


def search(rows: tuple[dict[str, Any], ...], query: str) -> dict[str, Any]:
    """The rows whose words hold every word of ``query``; QueryError for a query too long."""
    if len(query) > MAX_QUERY:
        raise QueryError(f"q: at most {MAX_QUERY} characters")
    words = query.lower().split()
    if len(words) > MAX_WORDS:
        raise QueryError(f"q: at most {MAX_WORDS} words")
    found = [row for row in rows if all(word in _haystack(row) for word in words)]
    return {"query": query, "total": len(found), "mappings": found[:MAX_RESULTS]}


def _haystack(row: dict[str, Any]) -> str:
    parts = (row["mapping"], row["manufacturer"], row["model"], row["category"], *row["aliases"])
    return " ".join(parts).lower()
