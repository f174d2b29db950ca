"""Names the importers give: mapping keys, ids, and the entity ids Home Assistant made."""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Collection

_NOT_SLUG = re.compile(r"[^a-z0-9]+")


def ha_slug(text: str) -> str:
    """Home Assistant's ``slugify`` for ASCII-transliterable names: lowercase, every run
    of other characters one ``_`` (``"Power L1 (W)"`` -> ``power_l1_w``); the id Home
    Assistant gave an entity named so (``unknown`` for a name with nothing left)."""
    ascii_text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode()
    return _NOT_SLUG.sub("_", ascii_text.lower()).strip("_") or "unknown"


def unique_key(name: str, taken: Collection[str]) -> str:
    """A mapping key for ``name``: a slug starting with a letter, ``_2``, ``_3``... when
    taken already."""
    base = ha_slug(name)
    if not base[0].isalpha():
        base = f"e_{base}"
    key, n = base, 2
    while key in taken:
        key, n = f"{base}_{n}", n + 1
    return key


def identifier(text: str) -> str:
    """A config id (bus, device): lowercase letters, digits, ``_``; never ``bridge``."""
    slug = ha_slug(text)
    return f"{slug}_1" if slug == "bridge" else slug
