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

__all__ = ["json_text", "read_json", "read_toml"]


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


def _finite(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if obj == obj and obj not in (float("inf"), float("-inf")) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if hasattr(obj, "item") and getattr(obj, "ndim", None) == 0:  # numpy scalars
        return _finite(obj.item())
    return obj


def json_text(obj: Any, indent: int | None = 2, default: Any = float) -> str:
    """Strict JSON of a summary or metrics mapping: NaN and infinities (a recall with nothing to recall, an unknown
    rate) as ``null`` (``json.dumps`` writes ``NaN``, which no other JSON reader accepts), numpy scalars as numbers."""
    return json.dumps(_finite(obj), indent=indent, allow_nan=False, default=default)
