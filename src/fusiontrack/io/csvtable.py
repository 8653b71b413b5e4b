"""Numeric CSV tables with errors that name the file, line and column (shared by the CSV readers)."""

from __future__ import annotations

import logging
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import RecordingError

log = logging.getLogger(__name__)

MAX_BAD_ROW_SHARE = 0.01
"""``skip_bad_rows`` drops bad rows only while they are at most this share of the rows (or a single row)."""


@dataclass(frozen=True, slots=True)
class NumericTable:
    """A parsed numeric CSV file.

    Attributes
    ----------
    values : (n_rows, n_cols) float64
        Every column as float.
    ints : dict of column index -> (n_rows,) int64
        The columns asked for as exact integers (e.g. nanosecond stamps beyond 2**53).
    line_numbers : (n_rows,) int64
        The 1-based line of the file each row came from (for later error messages).
    header : list of str or None
        The header fields (stripped) when ``header=True``.
    skipped_lines : tuple of int
        The 1-based lines dropped as bad (``skip_bad_rows``).
    """

    values: np.ndarray
    ints: dict[int, np.ndarray]
    line_numbers: np.ndarray
    header: list[str] | None
    skipped_lines: tuple[int, ...] = ()

    def __len__(self) -> int:
        return int(self.values.shape[0])


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")  # (a byte-order mark, as some Windows tools write, is dropped)
    except FileNotFoundError as err:
        raise RecordingError(f"{path}: no such file (expected {what})") from err
    except IsADirectoryError as err:
        raise RecordingError(f"{path}: is a folder (expected {what})") from err
    except UnicodeDecodeError as err:
        raise RecordingError(f"{path}: not a UTF-8 text file (expected {what})") from err
    except OSError as err:
        raise RecordingError(f"{path}: cannot be read ({err.strerror or err}; expected {what})") from err


def _row_problem(lineno: int, line: str, expected: int, int_cols: Sequence[int], what: str) -> str | None:
    """What is wrong with one row (``"line N: ..."``), or ``None`` when it is ``expected`` numbers."""
    fields = line.split(",")
    if len(fields) != expected:
        return (f"line {lineno}: expected {expected} comma-separated values ({what}), "
                f"got {len(fields)}: {line.strip()[:80]!r}")
    for col, text in enumerate(fields):
        try:
            if "_" in text or not text.isascii():  # Python's int / float take "9_8" and other scripts' digits;
                raise ValueError  # numpy's parser does not
            int(text) if col in int_cols else float(text)
        except ValueError:
            kind = "an integer" if col in int_cols else "a number"
            return f"line {lineno}, column {col + 1}: expected {kind} ({what}), got {text.strip()[:40]!r}"
    return None


_EMPTY_FIELD = re.compile(r"(^|,)[ \t]*(?=,|$)")


def read_numeric_table(
    path: str | Path,
    *,
    n_cols: int | None = None,
    int_cols: Sequence[int] = (),
    header: bool = False,
    comment: str = "#",
    what: str = "a numeric CSV file",
    skip_bad_rows: bool = False,
    empty_as_nan: bool = False,
) -> NumericTable:
    """Read a comma-separated file of numbers, with errors that name the file and line.

    Parameters
    ----------
    path : str or Path
    n_cols : int, optional
        Required number of columns; by default every row must have as many as the first.
    int_cols : sequence of int
        0-based columns to parse also as exact ``int64`` (they must hold integers).
    header : bool
        The first non-blank, non-comment line is a header of names, returned in ``header``.
    comment : str
        Lines starting with this (after leading blanks) are skipped, as are blank lines.
    what : str
        What the file should be, for error messages (e.g. ``"t_ns, ax, ay, az"``).
    empty_as_nan : bool
        Read an empty field (``1.0,,2.0``) as NaN instead of refusing its row.
    skip_bad_rows : bool
        For a sensor log, where a row cut short (the recorder stopped mid-write) or garbled must not cost the
        rest: rows with the wrong number of values, or a value that is not a number, are dropped with a
        warning (their lines are in ``skipped_lines``) as long as they are few, at most one row or
        :data:`MAX_BAD_ROW_SHARE` of the rows; more than that means the file is not ``what``: an error.

    Returns
    -------
    NumericTable

    Raises
    ------
    RecordingError
        Missing or unreadable file, no data rows, wrong column count or a value that is not a number (beyond
        the few rows ``skip_bad_rows`` drops).
    """
    path = Path(path)
    text = _read_text(path, what)
    rows = [(i, line) for i, line in enumerate(text.splitlines(), start=1)
            if line.strip() and not line.lstrip().startswith(comment)]
    if rows and "\t" in rows[0][1] and "," not in rows[0][1]:
        raise RecordingError(f"{path}, line {rows[0][0]}: tab-separated values; expected comma-separated ({what})")
    # a comma ending every line (some exporters write one) closes the last value; it opens no empty column (unless
    # the header names one more: an empty last column, e.g. a sensor that gave nothing)
    data = rows[1 if header else 0:]
    if data and all(line.rstrip().endswith(",") for _, line in data) and not (
            header and len(rows[0][1].rstrip().removesuffix(",").split(",")) == len(data[0][1].split(","))):
        rows = [(i, line.rstrip().removesuffix(",")) for i, line in rows]
    if empty_as_nan:  # an empty field is a value the sensor did not give: NaN (the caller's rules decide)
        first = 1 if header else 0
        rows = rows[:first] + [(i, _EMPTY_FIELD.sub(r"\1nan", line)) for i, line in rows[first:]]
    names: list[str] | None = None
    if header:
        if not rows:
            raise RecordingError(f"{path}: empty file (expected a header line and rows of {what})")
        names = [name.strip() for name in rows[0][1].split(",")]
        if len(names) > 1 and not names[-1]:  # (the header alone ending in a comma)
            names = names[:-1]
        rows = rows[1:]
        if n_cols is None:
            n_cols = len(names)
    if not rows:
        raise RecordingError(f"{path}: no data rows (expected {what})")
    skipped: list[int] = []
    try:
        values, ints = _parse(rows, n_cols, int_cols)
    except ValueError as err:
        expected = n_cols if n_cols is not None else len(rows[0][1].split(","))
        problems = [(lineno, _row_problem(lineno, line, expected, int_cols, what)) for lineno, line in rows]
        bad = [(lineno, why) for lineno, why in problems if why is not None]
        if not bad:
            raise RecordingError(f"{path}: cannot be parsed as {what}: {err}") from err
        if not skip_bad_rows or len(bad) > max(1, int(MAX_BAD_ROW_SHARE * len(rows))) or len(bad) == len(rows):
            more = f" ({len(bad)} of {len(rows)} rows are bad)" if len(bad) > 1 else ""
            raise RecordingError(f"{path}, {bad[0][1]}{more}") from err
        skipped = [lineno for lineno, _ in bad]
        drop = set(skipped)
        rows = [(lineno, line) for lineno, line in rows if lineno not in drop]
        try:
            values, ints = _parse(rows, n_cols, int_cols)
        except ValueError as again:  # (numpy refused what the row-by-row check let through)
            raise RecordingError(f"{path}: cannot be parsed as {what}: {again}") from again
        shown = ", ".join(str(lineno) for lineno in skipped[:5]) + (", ..." if len(skipped) > 5 else "")
        log.warning("%s: skipped %d bad row(s) of %d (line %s); the first: %s", path, len(bad),
                    len(rows) + len(bad), shown, bad[0][1])
    line_numbers = np.array([i for i, _ in rows], dtype=np.int64)
    return NumericTable(values=values, ints=ints, line_numbers=line_numbers, header=names,
                        skipped_lines=tuple(skipped))


def _parse(rows: Sequence[tuple[int, str]], n_cols: int | None,
           int_cols: Sequence[int]) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """``np.loadtxt`` of the rows' text: all columns as float, ``int_cols`` also as exact int64 (ValueError on a bad
    row, to be located by :func:`_row_problem`)."""
    lines = [line for _, line in rows]
    values = np.loadtxt(lines, delimiter=",", dtype=np.float64, ndmin=2, comments=None)
    if n_cols is not None and values.shape[1] != n_cols:
        raise ValueError(f"{values.shape[1]} columns instead of {n_cols}")
    ints = {c: np.loadtxt(lines, delimiter=",", dtype=np.int64, usecols=c, ndmin=1, comments=None)
            for c in int_cols}
    return values, ints
