"""What the sections of the config file share: a strict, frozen base model; the files a
config names, taken from the config file's folder; secrets from one of three sources (the
value, a file, an environment variable), read when needed and never logged.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, SecretStr, ValidationInfo


class Strict(BaseModel):
    """A config section: frozen, and an unknown key is an error."""

    model_config = ConfigDict(frozen=True, extra="forbid")


def _from_config_folder(path: Path, info: ValidationInfo) -> Path:
    """A relative path is taken from the config file's folder (``context["base"]``), as
    mapping paths are: a service's working directory is often ``/``."""
    base = info.context.get("base") if isinstance(info.context, dict) else None
    return path if base is None or path.is_absolute() else base / path


def one_source(name: str, *given: object) -> None:
    """At most one of ``<name>``, ``<name>_file``, ``<name>_env`` is given."""
    if sum(value is not None for value in given) > 1:
        raise ValueError(f"give one of {name}, {name}_file, {name}_env")


FilePath = Annotated[Path, AfterValidator(_from_config_folder)]
"""A file a config names (a secret, a certificate); relative to the config file."""


def secret_of(value: SecretStr | None, file: Path | None, env: str | None) -> str | None:
    """A secret from whichever source is configured: given, a file (stripped), or an
    environment variable (None while it is unset); read now, never logged. OSError if the
    file cannot be read."""
    if value is not None:
        return value.get_secret_value()
    if file is not None:
        return file.read_text(encoding="utf-8").strip()
    if env is not None:
        return os.environ.get(env)
    return None


def is_register_number(text: str | None) -> bool:
    """A password a device's unlock register takes: ASCII digits, 0..65535 ("12³" is none)."""
    return text is not None and text.isascii() and text.isdigit() and int(text) <= 0xFFFF
