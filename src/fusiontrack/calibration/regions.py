"""Candidate laser regions of image boxes (seed 000 Eq. 1; ALGORITHMS.md A6), generalised to any camera placement.

Every angle is an *azimuth seen from the camera centre*: the world-frame horizontal bearing of a viewing ray,
counter-clockwise from world x. All pixels on the image of one vertical line share one azimuth, and turning
the camera by ``b`` about the vertical through its centre adds exactly ``b`` to every azimuth whatever its
pitch. For the paper's camera and laser "arranged vertically" (one vertical axis) a region is A6's beam
interval ``[θ(u_r) - m, θ(u_l) + m]``, shifted by the bias.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fusiontrack.geometry import PinholeCamera, wrap_angle

__all__ = ["CandidateRegions", "candidate_regions", "pixel_azimuths", "points_in_regions", "regions_overlap"]


def pixel_azimuths(camera: PinholeCamera, uv_px: Any) -> np.ndarray:
    """World azimuth of the viewing ray of each pixel, seen from the camera centre.

    Parameters
    ----------
    camera : PinholeCamera
    uv_px : (n, 2) float
        Distorted pixels.

    Returns
    -------
    (n,) float64
        Radians in ``(-pi, pi]``, counter-clockwise from world x; NaN for a non-finite pixel or a vertical ray.
    """
    xy = camera.undistort_pixels(uv_px, normalized=True)
    rays = np.column_stack([xy, np.ones(len(xy))]) @ camera.world2cam[:3, :3]  # optical -> world directions
    with np.errstate(invalid="ignore"):
        az = np.arctan2(rays[:, 1], rays[:, 0])
    az[np.hypot(rays[:, 0], rays[:, 1]) < 1e-12] = np.nan
    return az


@dataclass(frozen=True, slots=True, eq=False)
class CandidateRegions:
    """Candidate regions of ``n`` image boxes (ALGORITHMS.md A6), as azimuth intervals from the camera.

    Attributes
    ----------
    centre_rad : (n,) float64
        ``θ_c``: azimuth of the box centre (or of the given centre point), bias included.
    lo_rad, hi_rad : (n,) float64
        Interval ``[lo, hi]`` (counter-clockwise from ``lo``): the box corners' azimuths plus the margin.
    half_width_rad : (n,) float64
        ``h_θ = (hi - lo) / 2``.
    distance_m : (n,) float64
        Horizontal distance from the camera centre to the floor point under the box's bottom-centre (invariant
        under the yaw bias); NaN when that ray misses the floor.
    """

    centre_rad: np.ndarray
    lo_rad: np.ndarray
    hi_rad: np.ndarray
    half_width_rad: np.ndarray
    distance_m: np.ndarray

    def __len__(self) -> int:
        return int(self.centre_rad.size)


def validate_boxes(boxes_px: Any) -> np.ndarray:
    b = np.asarray(boxes_px, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 4:
        raise ValueError(f"boxes_px: expected an array of shape (n, 4) (u_min, v_min, u_max, v_max), got {b.shape}")
    if not np.all(np.isfinite(b)) or np.any(b[:, 2] <= b[:, 0]) or np.any(b[:, 3] <= b[:, 1]):
        raise ValueError("boxes_px: every box must be finite with u_max > u_min and v_max > v_min")
    return b


def candidate_regions(boxes_px: Any, camera: PinholeCamera, bias_rad: float = 0.0,
                      margin_rad: float = math.radians(1.0), floor_z_m: float = 0.0,
                      centres_px: Any = None) -> CandidateRegions:
    """Azimuth interval of each box as seen through ``camera`` turned by ``bias_rad`` (ALGORITHMS.md A6, Eq. 1).

    A6: region ``[θ(u_r) - m, θ(u_l) + m]``, centre ``θ((u_l + u_r) / 2)``; ``θ`` here is the exact azimuth of
    a pixel's ray (the atan form, with distortion), taken over the four corners because a pitched camera sees
    a wider azimuth range at the bottom of a box than at its top.

    Parameters
    ----------
    boxes_px : (n, 4) float
        ``(u_min, v_min, u_max, v_max)`` of the blobs, pixels.
    camera : PinholeCamera
        The calibrated (uncorrected) camera.
    bias_rad : float
        Current bias ``b``.
    margin_rad : float
        ``m`` (A6: 1 degree), >= 0.
    floor_z_m : float
        Height of the floor for :attr:`CandidateRegions.distance_m`.
    centres_px : (n, 2) float, optional
        The image point whose azimuth is ``θ_c`` (default: the box centre). A blob's pixel centroid is better:
        seen from above, a person's image is wider at the head than at the feet and leans away from the image
        centre, which moves the box centre off the person's axis (by ~2 px for a camera 7 m up), while the
        centroid of a silhouette symmetric about the axis stays on it. NaN rows fall back to the box centre.

    Returns
    -------
    CandidateRegions
    """
    b = validate_boxes(boxes_px)
    if not (math.isfinite(margin_rad) and 0 <= margin_rad < math.pi / 2):
        raise ValueError(f"margin_rad: expected a finite margin in [0, pi/2), got {margin_rad}")
    if not math.isfinite(bias_rad):
        raise ValueError(f"bias_rad: expected a finite angle, got {bias_rad}")
    u0, v0, u1, v1 = b.T
    uc, vc = (u0 + u1) / 2, (v0 + v1) / 2
    if centres_px is not None:
        cen = np.asarray(centres_px, dtype=np.float64)
        if cen.shape != (b.shape[0], 2):
            raise ValueError(f"centres_px: expected shape ({b.shape[0]}, 2) (one point per box), got {cen.shape}")
        has = np.all(np.isfinite(cen), axis=1)
        uc, vc = np.where(has, cen[:, 0], uc), np.where(has, cen[:, 1], vc)
    pix = np.stack([np.column_stack(p) for p in ((u0, v0), (u1, v0), (u0, v1), (u1, v1), (uc, vc))], axis=1)
    az = pixel_azimuths(camera, pix.reshape(-1, 2)).reshape(-1, 5) + bias_rad
    centre = wrap_angle(az[:, 4])
    rel = wrap_angle(az[:, :4] - centre[:, None])
    lo = wrap_angle(centre + rel.min(axis=1) - margin_rad)
    hi = wrap_angle(centre + rel.max(axis=1) + margin_rad)
    half = (rel.max(axis=1) - rel.min(axis=1)) / 2 + margin_rad
    feet = camera.backproject_to_floor(np.column_stack([uc, v1]), floor_z_m)
    dist = np.hypot(feet[:, 0] - camera.position_m[0], feet[:, 1] - camera.position_m[1])
    return CandidateRegions(centre, lo, hi, half, dist)


def points_in_regions(azimuth_rad: Any, distance_m: Any, regions: CandidateRegions,
                      range_gate_m: float | None = None) -> np.ndarray:
    """Which points (laser beams) lie in which candidate region.

    Parameters
    ----------
    azimuth_rad, distance_m : (n_points,) float
        Azimuth and horizontal distance of each point seen from the camera centre (NaN = invalid point).
    regions : CandidateRegions
    range_gate_m : float, optional
        Also require ``|distance - regions.distance_m| <= range_gate_m`` where the region's distance is known
        (an extension of A6 for an elevated camera, whose box bottom fixes the distance).

    Returns
    -------
    (n_regions, n_points) bool
    """
    az = np.asarray(azimuth_rad, dtype=np.float64).reshape(-1)
    d = np.asarray(distance_m, dtype=np.float64).reshape(-1)
    if az.shape != d.shape:
        raise ValueError(f"distance_m: expected {az.shape[0]} values (one per azimuth), got {d.shape[0]}")
    width = np.mod(regions.hi_rad - regions.lo_rad, 2 * np.pi)
    with np.errstate(invalid="ignore"):
        inside = np.mod(az[None, :] - regions.lo_rad[:, None], 2 * np.pi) <= width[:, None]
        if range_gate_m is not None:
            known = np.isfinite(regions.distance_m)[:, None]
            near = np.abs(d[None, :] - regions.distance_m[:, None]) <= range_gate_m
            inside &= near | ~known
    return inside & np.isfinite(az)[None, :]


def regions_overlap(regions: CandidateRegions) -> np.ndarray:
    """``(n, n) bool``: regions ``i`` and ``j != i`` share some azimuth (the diagonal is False)."""
    lo = regions.lo_rad
    width = np.mod(regions.hi_rad - lo, 2 * np.pi)
    starts_inside = np.mod(lo[None, :] - lo[:, None], 2 * np.pi) <= width[:, None]  # [i, j]: lo_j in region i
    out = starts_inside | starts_inside.T
    np.fill_diagonal(out, False)
    return out
