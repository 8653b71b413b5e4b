"""Errors raised at fusiontrack's public edges.

Every error a user can cause (a missing file, a corrupt bag, an unknown topic, a bad config value)
is a :class:`FusiontrackError` subclass whose message names the file, topic or field and what was
expected. The CLI prints the message on one line and exits non-zero; library callers can catch the
base class. The original exception, when there is one, is kept as ``__cause__``.
"""

from __future__ import annotations


class FusiontrackError(Exception):
    """Base class of every error fusiontrack raises on purpose."""


class RecordingError(FusiontrackError):
    """A recording (bag, MCAP, video, CSV) cannot be opened, read or written."""


class TopicError(RecordingError):
    """A topic that was asked for is not in the recording."""


class MessageTypeError(RecordingError):
    """A message type is unknown, or known but not convertible into fusiontrack's types."""


class ConfigError(FusiontrackError):
    """A configuration value (pipeline file, CLI option, function argument) is invalid."""


class CalibrationError(FusiontrackError):
    """A calibration cannot be computed from the given data (too few or degenerate points)."""
