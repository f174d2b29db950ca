"""The wheel carries every package of ``bridge``: setuptools' list in pyproject.toml is
explicit, so a new package left out of it is missing from the image and the add-on."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_package_of_bridge_is_in_the_wheel() -> None:
    listed = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    found = {
        ".".join(init.parent.relative_to(ROOT).parts)
        for init in (ROOT / "bridge").rglob("__init__.py")
    }
    assert found - listed == set(), f"packages missing from pyproject.toml: {found - listed}"


def test_every_shipped_mapping_is_package_data() -> None:
    """The seeds and mappings/library/<category>/*.yaml ship inside the wheel (the Docker
    image and the add-on install the wheel): each file matches a package-data pattern."""
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"
    ]["bridge.mappings"]
    files = sorted((ROOT / "mappings").rglob("*.yaml"))
    for path in files:
        relative = path.relative_to(ROOT / "mappings")
        assert any(
            relative.match(glob) and len(relative.parts) == len(Path(glob).parts) for glob in globs
        ), relative


def test_every_library_folder_is_a_listed_package() -> None:
    """setuptools takes a folder of data under a package for a package of its own: each
    mappings/library/<category>/ is listed (as bridge.mappings.library.<category>), or the
    wheel build warns that it "would be ignored"."""
    listed = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    folders = {path.parent for path in (ROOT / "mappings").rglob("*.yaml")}
    folders |= {parent for folder in folders for parent in folder.parents}
    for folder in folders:
        if folder.is_relative_to(ROOT / "mappings"):
            parts = folder.relative_to(ROOT / "mappings").parts
            assert ".".join(("bridge", "mappings", *parts)) in listed, folder
