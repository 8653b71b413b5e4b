"""Step length as a straight-line function of step duration, per person (ALGORITHMS.md C3).

Seed 002, section 2.1.2: "the test subject was instructed to walk with different step lengths ...
A program was used to fit the data points with a straight line. The equation of this straight line
was the time-length formula for the test subject." So ``L = a·Δt + b``, fitted per person by ordinary
least squares, and clipped to ``[0.2, 1.2]`` m (C3, RECON).

Two ways to train (:func:`fit_step_model`):

* per-step lengths ``(Δt_i, L_i)``: OLS on the pairs (the paper's procedure);
* the total length of one or more walks (what a user can measure: "I walked this 30 m corridor"):
  each walk gives one equation ``a·ΣΔt + b·n = D``. Two or more walks at different paces determine
  ``a`` and ``b`` by least squares; a single walk (or walks at one pace) only fixes the scale, so the
  default line's shape is kept and scaled to match (logged).

A model is a frozen record that round-trips through JSON (:meth:`StepLengthModel.to_json`,
:meth:`StepLengthModel.save`, :func:`load_step_model`).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from .steps import DEFAULT_FIRST_DURATION_S

__all__ = ["DEFAULT_STEP_MODEL", "StepLengthModel", "fit_step_model", "load_step_model"]

log = logging.getLogger(__name__)

_FORMAT = "fusiontrack.step_length_model/1"


@dataclass(frozen=True, slots=True)
class StepLengthModel:
    """``L = slope_mps · Δt + intercept_m``, clipped to ``[min_length_m, max_length_m]`` (ALGORITHMS.md C3).

    Attributes
    ----------
    slope_mps : float
        ``a``, m per s of step duration. Default 0.9 (C3 placeholder, not from the paper).
    intercept_m : float
        ``b``, m. Default 0.2.
    min_length_m, max_length_m : float
        Clip range of a step length (C3: 0.2 and 1.2 m).
    typical_duration_s : float
        Median training step duration; the duration of the first step of a walk (C2).
    subject : str
        Who the model belongs to.
    n_train : int
        Training steps (0 for the default).
    rms_m : float
        RMS residual of the fit per step (``NaN`` when unknown, e.g. fitted from totals only).
    """

    slope_mps: float = 0.9
    intercept_m: float = 0.2
    min_length_m: float = 0.2
    max_length_m: float = 1.2
    typical_duration_s: float = DEFAULT_FIRST_DURATION_S
    subject: str = "default"
    n_train: int = 0
    rms_m: float = float("nan")

    def __post_init__(self) -> None:
        for name in ("slope_mps", "intercept_m", "min_length_m", "max_length_m", "typical_duration_s"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not np.isfinite(value):
                raise ValueError(f"{name}: expected a finite number, got {value!r}")
        if not 0 <= self.min_length_m < self.max_length_m:
            raise ValueError(f"min_length_m, max_length_m: expected 0 <= min < max, got {self.min_length_m}, "
                             f"{self.max_length_m}")
        if self.typical_duration_s <= 0:
            raise ValueError(f"typical_duration_s: expected > 0, got {self.typical_duration_s}")
        if not isinstance(self.n_train, int) or self.n_train < 0:
            raise ValueError(f"n_train: expected an integer >= 0, got {self.n_train!r}")

    @property
    def rms_text(self) -> str:
        """``rms_m`` for people: ``"rms 0.041 m"``, or why there is none (``rms_m`` is ``NaN``)."""
        if np.isfinite(self.rms_m):
            return f"rms {self.rms_m:.3f} m"
        if self.n_train == 0:
            return "rms unknown: not fitted to anybody's steps"
        return "rms unknown: fitted from each walk's total length, so the error of single steps is not measured"

    def length(self, duration_s: Any) -> np.ndarray:
        """Step lengths, m, for step durations ``duration_s`` (any shape, s); clipped."""
        d = np.asarray(duration_s, dtype=np.float64)
        if not np.all(np.isfinite(d)) or np.any(d < 0):
            raise ValueError("duration_s: expected finite durations >= 0")
        return np.clip(self.slope_mps * d + self.intercept_m, self.min_length_m, self.max_length_m)

    # ---- serialisation ---------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["rms_m"] = None if not np.isfinite(self.rms_m) else self.rms_m  # JSON has no NaN
        return {"format": _FORMAT, **d}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> StepLengthModel:
        if not isinstance(data, dict):
            raise ValueError(f"step model: expected a JSON object, got {type(data).__name__}")
        fmt = data.get("format", _FORMAT)
        if fmt != _FORMAT:
            raise ValueError(f"step model format: expected {_FORMAT!r}, got {fmt!r}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known - {"format"})
        if unknown:
            raise ValueError(f"step model: unknown field(s) {unknown}; expected some of {sorted(known)}")
        kw = {k: v for k, v in data.items() if k in known}
        if kw.get("rms_m", 0.0) is None:
            kw["rms_m"] = float("nan")
        return cls(**kw)

    @classmethod
    def from_json(cls, text: str) -> StepLengthModel:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as err:
            raise ValueError(f"step model: not valid JSON ({err})") from err
        return cls.from_dict(data)

    def save(self, path: str | Path) -> Path:
        """Write the model as JSON to ``path``; returns the path."""
        path = Path(path)
        path.write_text(self.to_json() + "\n", encoding="utf-8")
        return path


DEFAULT_STEP_MODEL = StepLengthModel()
"""The model used when none is fitted (ALGORITHMS.md C3 placeholder a = 0.9 m/s, b = 0.2 m)."""


def load_step_model(path: str | Path) -> StepLengthModel:
    """Read a model written by :meth:`StepLengthModel.save`.

    Raises
    ------
    ValueError
        The file is missing, not JSON or not a step model (the path is named).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ValueError(f"{path}: cannot read the step model ({err.strerror or err})") from err
    try:
        return StepLengthModel.from_json(text)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: {err}") from err


def _as_walks(durations_s: Any) -> list[np.ndarray]:
    if isinstance(durations_s, np.ndarray) and durations_s.ndim == 1:
        walks = [durations_s]
    elif isinstance(durations_s, Sequence) and durations_s and all(np.ndim(w) == 1 for w in durations_s):
        walks = list(durations_s)
    else:
        walks = [durations_s]
    out = []
    for i, w in enumerate(walks):
        arr = np.asarray(w, dtype=np.float64)
        if arr.ndim != 1 or arr.size == 0:
            raise ValueError(f"durations_s: walk {i}: expected a non-empty (k,) array of step durations, "
                             f"got shape {arr.shape}")
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            raise ValueError(f"durations_s: walk {i}: expected finite durations > 0 s")
        out.append(arr)
    return out


def fit_step_model(durations_s: Any, lengths_m: Any = None, *, total_length_m: Any = None,
                   subject: str = "default", prior: StepLengthModel = DEFAULT_STEP_MODEL,
                   min_spread_s: float = 0.03) -> StepLengthModel:
    """Fit ``L = a·Δt + b`` for one person (ALGORITHMS.md C3).

    Give either per-step ``lengths_m`` or the ``total_length_m`` of each walk.

    Parameters
    ----------
    durations_s : (k,) float, or a sequence of (k_w,) arrays (one per walk)
        Step durations, s (e.g. :attr:`Steps.duration_s` of :func:`detect_steps`).
    lengths_m : (k,) float, optional
        Length of every step, m (one walk only): OLS on ``(Δt_i, L_i)``.
    total_length_m : float or (n_walks,) float, optional
        Distance walked in each walk, m.
    subject : str
        Stored in the model.
    prior : StepLengthModel
        Clip range, and the line whose shape is kept when the walks cannot separate ``a`` from ``b``.
    min_spread_s : float
        Walks (or steps) whose mean durations spread less than this cannot separate slope and
        intercept; then only the scale of ``prior`` is fitted.

    Returns
    -------
    StepLengthModel

    Raises
    ------
    ValueError
        Inconsistent or missing inputs (the parameter is named).
    """
    if (lengths_m is None) == (total_length_m is None):
        raise ValueError("lengths_m, total_length_m: give exactly one of them")
    walks = _as_walks(durations_s)
    all_d = np.concatenate(walks)
    typical = float(np.median(all_d))
    if lengths_m is not None:
        if len(walks) != 1:
            raise ValueError("lengths_m: per-step lengths go with one (k,) array of durations, not several walks")
        d = walks[0]
        L = np.asarray(lengths_m, dtype=np.float64)
        if L.shape != d.shape:
            raise ValueError(f"lengths_m: expected shape {d.shape} to match durations_s, got {L.shape}")
        if not np.all(np.isfinite(L)) or np.any(L <= 0):
            raise ValueError("lengths_m: expected finite lengths > 0 m")
        if d.size >= 2 and np.ptp(d) >= min_spread_s:
            A = np.stack([d, np.ones_like(d)], axis=1)
            (a, b), *_ = np.linalg.lstsq(A, L, rcond=None)
        else:
            s = float(L.sum() / np.sum(prior.slope_mps * d + prior.intercept_m))
            a, b = s * prior.slope_mps, s * prior.intercept_m
            log.info("step durations spread %.3f s < %.3f s: only the scale of the prior line is fitted",
                     float(np.ptp(d)), min_spread_s)
        rms = float(np.sqrt(np.mean((a * d + b - L) ** 2)))
        n = int(d.size)
    else:
        D = np.atleast_1d(np.asarray(total_length_m, dtype=np.float64))
        if D.shape != (len(walks),):
            raise ValueError(f"total_length_m: expected {len(walks)} value(s), one per walk, got shape {D.shape}")
        if not np.all(np.isfinite(D)) or np.any(D <= 0):
            raise ValueError("total_length_m: expected finite distances > 0 m")
        sum_d = np.array([w.sum() for w in walks])
        count = np.array([float(w.size) for w in walks])
        mean_d = sum_d / count
        if len(walks) >= 2 and np.ptp(mean_d) >= min_spread_s:
            # one equation per walk, a·ΣΔt + b·n = D, each weighted by 1/n so every step counts alike
            A = np.stack([sum_d, count], axis=1) / count[:, None]
            (a, b), *_ = np.linalg.lstsq(A, D / count, rcond=None)
        else:
            s = float(D.sum() / np.sum(prior.slope_mps * sum_d + prior.intercept_m * count))
            a, b = s * prior.slope_mps, s * prior.intercept_m
            log.info("%d walk(s) at one pace (mean step durations spread %.3f s): only the scale of the prior "
                     "line is fitted (x%.3f)", len(walks), float(np.ptp(mean_d)), s)
        rms = float("nan")
        n = int(all_d.size)
    model = StepLengthModel(float(a), float(b), prior.min_length_m, prior.max_length_m, typical, subject, n, rms)
    lengths = model.length(all_d)
    clipped = np.count_nonzero((lengths <= prior.min_length_m) | (lengths >= prior.max_length_m))
    if clipped:
        log.warning("fitted step model L = %.3f·Δt + %.3f clips %d of %d training steps to [%.1f, %.1f] m",
                    a, b, clipped, all_d.size, prior.min_length_m, prior.max_length_m)
    return model
