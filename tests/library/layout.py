"""What the library's tests ask of a mapping's index entry."""

from __future__ import annotations

from bridge.core.library import Category
from bridge.core.mapping import Mapping

# Kinds of device with no status word or alarm register: a meter only measures.
WITHOUT_STATUS = frozenset({Category.METER})


def has_no_status(mapping: Mapping) -> bool:
    """True for a mapping of a kind that has no status word (and so no ``status``)."""
    return (
        mapping.status is None
        and mapping.library is not None
        and mapping.library.category in WITHOUT_STATUS
    )
