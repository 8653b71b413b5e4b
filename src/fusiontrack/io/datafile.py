"""Reading the small TOML and JSON files users and the package keep (rules, road geometry, models).

One place for the errors a user can cause: a missing file, an unreadable one, bad syntax; each names the file
and what it was meant to be.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from ..errors import ConfigError

__all__ = ["read_json", "read_toml"]


def _text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError as err:
        raise ConfigError(f"{what} file not found: {path}") from err
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the {what} file: {err.strerror or err}") from err


def read_toml(path: str | Path, what: str) -> dict[str, Any]:
    """The parsed TOML of ``path`` (``what``: e.g. ``"rules"``, named in errors)."""
    path = Path(path)
    try:
        return tomllib.loads(_text(path, what))
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from err


def read_json(path: str | Path, what: str) -> Any:
    """The parsed JSON of ``path`` (``what`` named in errors)."""
    path = Path(path)
    try:
        return json.loads(_text(path, what))
    except json.JSONDecodeError as err:
        raise ConfigError(f"{path}: not JSON: {err}") from err
