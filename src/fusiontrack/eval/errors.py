"""Errors of the evaluation subpackage."""

from __future__ import annotations

from ..errors import FusiontrackError


class EvaluationError(FusiontrackError, ValueError):
    """The inputs of an evaluation are invalid (an id twice in one frame, frames out of range, a bad threshold).

    A :class:`ValueError` as well, so argument checks can be caught the usual way; a
    :class:`~fusiontrack.errors.FusiontrackError`, so the CLI reports it on one line.
    """
