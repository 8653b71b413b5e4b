"""Write a calibrated sensor pose into a pipeline file, keeping everything else as it was.

The pipeline file (:mod:`fusiontrack.config`) gives each sensor's pose as ``pose = { x = ..., y = ..., z = ...,
roll_deg = ..., pitch_deg = ..., yaw_deg = ... }`` in its ``[sensors.<name>]`` table (a ``[sensors.<name>.pose]``
sub-table or dotted ``pose.x = ...`` keys are also understood). Only the pose is rewritten: other keys, other
sections, comments and blank lines are kept byte for byte, and the result is validated before it is written.
"""

from __future__ import annotations

import logging
import math
import os
import re
import tempfile
import tomllib
from pathlib import Path

from fusiontrack.config import PipelineConfig, Pose, parse_config
from fusiontrack.errors import ConfigError

__all__ = ["format_pose", "update_pipeline_pose", "write_pose_to_pipeline"]

log = logging.getLogger(__name__)

_HEADER = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_POSE_FIELDS = ("x", "y", "z", "roll_deg", "pitch_deg", "yaw_deg")


def _number(v: float) -> str:
    if not math.isfinite(v):
        raise ConfigError(f"pose: every value must be finite, got {v}")
    text = f"{v:.6f}".rstrip("0")
    text = text + "0" if text.endswith(".") else text
    return "0.0" if text in ("-0.0", "0.0") else text  # µm / µdeg: far below any calibration's accuracy


def format_pose(pose: Pose) -> str:
    """``{ x = 1.0, y = ..., yaw_deg = ... }``: a pose as a TOML inline table (6 decimals)."""
    return "{ " + ", ".join(f"{k} = {_number(getattr(pose, k))}" for k in _POSE_FIELDS) + " }"


def _key_path(header: str) -> tuple[str, ...]:
    """``sensors."camera 0"`` -> ``("sensors", "camera 0")`` (bare and quoted keys)."""
    parts = re.findall(r'"((?:[^"\\]|\\.)*)"|\'([^\']*)\'|([A-Za-z0-9_-]+)', header)
    return tuple(a or b or c for a, b, c in parts)


def _quoted(name: str) -> str:
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def update_pipeline_pose(text: str, sensor: str, pose: Pose, *, kind: str | None = None, topic: str | None = None,
                         comment: str = "", source: str = "<pipeline>") -> str:
    """The pipeline file ``text`` with the pose of ``sensor`` replaced by ``pose``.

    Parameters
    ----------
    text : str
        A pipeline file (TOML).
    sensor : str
        The sensor's name (its ``[sensors.<name>]`` table).
    pose : Pose
    kind, topic : str, optional
        Needed only when the file has no table for ``sensor`` yet: a new ``[sensors.<name>]`` table is added.
    comment : str
        Put after the pose as a TOML comment (e.g. how it was calibrated).
    source : str
        The file's name, for error messages.

    Returns
    -------
    str
        The new text; every other line unchanged.

    Raises
    ------
    ConfigError
        ``text`` or the result is not a valid pipeline file, or the sensor is missing and ``kind``/``topic``
        are not given.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{source}: not valid TOML: {err}") from err
    parse_config(data, source)
    if "\n" in comment or "\r" in comment:
        raise ConfigError("comment: expected a single line")
    lines = text.splitlines(keepends=True)
    newline = "\r\n" if lines and lines[0].endswith("\r\n") else "\n"
    tail = f"  # {comment}" if comment else ""
    pose_line = f"pose = {format_pose(pose)}{tail}{newline}"
    headers = [(i, _key_path(m.group(1))) for i, line in enumerate(lines) if (m := _HEADER.match(line))]
    ends = {i: (headers[j + 1][0] if j + 1 < len(headers) else len(lines)) for j, (i, _) in enumerate(headers)}
    table = next((i for i, path in headers if path == ("sensors", sensor)), None)
    sub = next((i for i, path in headers if path == ("sensors", sensor, "pose")), None)
    if sub is not None:  # [sensors.<name>.pose] sub-table: rewrite its keys
        body = [f"{k} = {_number(getattr(pose, k))}{newline}" for k in _POSE_FIELDS]
        keep = [ln for ln in lines[sub + 1:ends[sub]] if not re.match(r"^\s*[A-Za-z_\"']", ln)]
        out = lines[:sub + 1] + ([f"# {comment}{newline}"] if comment else []) + body + keep + lines[ends[sub]:]
    elif table is not None:
        end = ends[table]
        pose_re = re.compile(r"^\s*pose\s*(=|\.)")
        hits = [i for i in range(table + 1, end) if pose_re.match(lines[i])]
        if hits:
            first = hits[0]
            indent = re.match(r"^\s*", lines[first]).group(0)
            out = lines[:first] + [indent + pose_line] + [ln for i, ln in enumerate(lines[first + 1:end], first + 1)
                                                         if i not in hits] + lines[end:]
        else:
            last = max([i for i in range(table, end) if lines[i].strip() and not lines[i].lstrip().startswith("#")])
            prefix = lines[:last + 1]
            if not prefix[-1].endswith(("\n", "\r")):
                prefix[-1] += newline
            out = [*prefix, pose_line, *lines[last + 1:]]
    else:
        if sensor in data.get("sensors", {}):
            raise ConfigError(f"{source}: sensor {sensor!r} is written inline; give it its own "
                              f"[sensors.{_quoted(sensor)}] table to have its pose rewritten")
        if kind is None or topic is None:
            raise ConfigError(f"{source}: no [sensors.{_quoted(sensor)}] table; give the sensor's kind and topic to "
                              "add one")
        block = [f"{newline}[sensors.{_quoted(sensor)}]{newline}", f'kind = "{kind}"{newline}',
                 f'topic = "{topic}"{newline}', pose_line]
        out = [*lines]
        if out and not out[-1].endswith(("\n", "\r")):
            out[-1] += newline
        out += block
    new_text = "".join(out)
    try:
        new = parse_config(tomllib.loads(new_text), f"{source} (with the new pose of {sensor!r})")
    except tomllib.TOMLDecodeError as err:  # pragma: no cover - the edit keeps TOML valid
        raise ConfigError(f"{source}: the edited pipeline file is not valid TOML: {err}") from err
    got = new.sensors[sensor].pose
    if any(abs(getattr(got, k) - getattr(pose, k)) > 1e-6 for k in _POSE_FIELDS):
        raise ConfigError(f"{source}: the pose of {sensor!r} could not be rewritten in place (got {got})")
    return new_text


def _umask() -> int:
    """The process's umask, read without setting it (os.umask sets it, a race for threads), 0o022 if unknown."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return 0o022


def write_pose_to_pipeline(path: str | Path, sensor: str, pose: Pose, *, kind: str | None = None,
                           topic: str | None = None, comment: str = "", create: bool = False) -> PipelineConfig:
    """Rewrite the pose of ``sensor`` in the pipeline file ``path`` (atomically) and return the new configuration.

    ``create=True`` starts a new file when ``path`` does not exist (``kind`` and ``topic`` are then needed).
    See :func:`update_pipeline_pose`.

    Raises
    ------
    ConfigError
        Unreadable or invalid file, missing sensor without ``kind``/``topic``.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as err:
        if not create:
            raise ConfigError(f"pipeline file not found: {path}") from err
        text = ""
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the pipeline file: {err.strerror}") from err
    new_text = update_pipeline_pose(text, sensor, pose, kind=kind, topic=topic, comment=comment, source=str(path))
    target = path.resolve() if path.is_symlink() else path  # a linked file is rewritten, the link kept
    # the new file keeps the old one's permissions (mkstemp makes it 0600); a new file gets the umask's
    mode = target.stat().st_mode & 0o7777 if target.exists() else 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(prefix=target.name + ".", suffix=".tmp",
                               dir=target.parent if target.parent.exists() else None)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(new_text)
        os.chmod(tmp, mode)
        os.replace(tmp, target)
    except OSError as err:
        Path(tmp).unlink(missing_ok=True)
        raise ConfigError(f"{path}: cannot write the pipeline file: {err.strerror}") from err
    log.info("%s: pose of %s set to %s", path, sensor, format_pose(pose))
    return parse_config(tomllib.loads(new_text), str(path))
