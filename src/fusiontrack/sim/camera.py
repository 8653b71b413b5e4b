"""Camera simulator: colour (and RGB-D depth) images of the static world and the agents, with ground truth.

Rendering model (issue 3):

* Everything is drawn into an ideal pinhole *canvas* with the camera's ``fx, fy``; without lens distortion
  the canvas is the image, with distortion it has margins and is remapped once per frame into the distorted
  image through maps precomputed with OpenCV, so pixels agree with :meth:`PinholeCamera.project`.
* Occlusion is a z-buffer of exact per-pixel depth along the optical axis. The static scene (textured floor,
  roads, walls, pillars, boxes, backdrop) is rendered once with its depth. Each agent is a list of planar
  convex polygons (legs, torso box, arms, neck, head; car body and cabin faces; bicycle frame lines), drawn
  far-to-near with ``cv2.fillConvexPoly`` into a small image of its own bounding box, which records which
  part covers each pixel; the part's plane then gives that pixel's depth, z-tested against the frame.
* A frame is then lit: the illumination gain in force (``CameraSpec.illumination``) and a per-camera white
  balance multiply the whole image, and Gaussian sensor noise of ``noise_sigma`` grey levels is added
  (quantised to whole grey levels through a 256-entry quantile table, ~10x faster than drawing normals).
* Ground shadows are multiplicative (factor :data:`SHADOW_GAIN`, blurred edge) on floor pixels, cast away
  from the fixed light :data:`LIGHT_DIR_WORLD`; they are never labelled as the agent (ALGORITHMS.md A3).

Calibration sign convention: the image is rendered from :attr:`CameraSim.true_camera`; the user believes
:attr:`CameraSim.calibrated_camera` = ``true_camera.with_yaw_offset(-yaw_bias_rad)``. Equivalently the real
camera is turned by ``+yaw_bias_rad`` (counter-clockwise seen from above) relative to its believed
calibration, so a point on the true optical axis appears ``fx * tan(yaw_bias_rad)`` px *left* of the centre
when projected with the calibration (for a level camera).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, NamedTuple

import cv2
import numpy as np
from scipy.special import ndtri

from fusiontrack.geometry import PinholeCamera
from fusiontrack.sim.model import (
    KIND_BICYCLE,
    KIND_CAR,
    PATTERN_CHECKS,
    PATTERN_HSTRIPES,
    PATTERN_VSTRIPES,
    AgentSnapshot,
    CameraSpec,
    StaticWorld,
    rect_corners,
)
from fusiontrack.types import CameraInfo

__all__ = ["LIGHT_DIR_WORLD", "SHADOW_GAIN", "CameraSim", "RenderOutput"]

_EL, _AZ = np.deg2rad(62.0), 1.1
LIGHT_DIR_WORLD = np.array([np.cos(_EL) * np.cos(_AZ), np.cos(_EL) * np.sin(_AZ), np.sin(_EL)])
"""Unit vector towards the (distant) light, world frame; shadows fall along ``-LIGHT_DIR_WORLD``."""
SHADOW_GAIN = 0.6
"""Brightness of a ground shadow relative to the lit floor (inside A3's shadow band 0.40-0.95)."""
_SHADOW_DIR = -LIGHT_DIR_WORLD[:2] / np.linalg.norm(LIGHT_DIR_WORLD[:2])
_SHADOW_PER_M = 1.0 / np.tan(_EL)  # shadow length per metre of height
_Z_NEAR_M, _FLOOR_FAR_M = 0.05, 150.0
_AMBIENT, _DIFFUSE = 0.62, 0.38
_SKIN = np.array([[150, 180, 230], [120, 160, 210], [95, 130, 180], [70, 100, 150], [50, 70, 110]], np.float64)
_HAIR = np.array([[25, 25, 30], [30, 50, 80], [90, 160, 200], [150, 150, 150]], np.float64)
_DARK = np.array([35.0, 35.0, 38.0])
_WINDOW = np.array([75.0, 58.0, 45.0])
_UP = np.array([0.0, 0.0, 1.0])
_DISC = np.linspace(0, 2 * np.pi, 14, endpoint=False)[:, None]
_HAIR_ARC = np.linspace(np.arcsin(0.3), np.pi - np.arcsin(0.3), 8)[:, None]  # the head above 0.3 of its radius
_Q = ndtri((np.arange(256) + 0.5) / 256)  # standard normal quantiles of the 256 byte values
_GAUSS16 = ndtri((np.arange(65536) + 0.5) / 65536).astype(np.float32)


@dataclass(frozen=True, slots=True, eq=False)
class RenderOutput:
    """One rendered frame and its ground truth.

    Attributes
    ----------
    bgr : (H, W, 3) uint8
    labels : (H, W) uint16 or None
        Agent id + 1 where that agent is visible, 0 elsewhere (only when ``CameraSpec.labels``).
    depth_m : (H, W) float32 or None
        Depth along the optical axis plus noise; NaN out of ``depth_range_m`` or on nothing (``CameraSpec.depth``).
    boxes_px : (n, 4) float64
        ``(u_min, v_min, u_max, v_max)`` of each snapshot agent in the true camera, not clipped to the image:
        the tight box of the rendered body (people) or of the projected cuboid (vehicles); NaN when behind.
    visibility : (n,) float64
        Visible fraction of the agent's unoccluded silhouette (0 off-image or behind the camera).
    """

    bgr: np.ndarray
    labels: np.ndarray | None
    depth_m: np.ndarray | None
    boxes_px: np.ndarray
    visibility: np.ndarray


class _Part(NamedTuple):
    """A planar convex polygon ``verts`` (k, 3) m of an agent, counter-clockwise seen from outside if ``cull``.

    ``overlay`` (m, k', 3): polygons in the same plane drawn over it in ``overlay_colour`` (stripes, hair,
    windows). ``lines`` = (polylines [(m, 3)], width_m): thick lines drawn instead, ``verts`` giving their plane.
    """

    verts: np.ndarray
    colour: np.ndarray
    cull: bool = False
    overlay: np.ndarray | None = None
    overlay_colour: np.ndarray | None = None
    lines: tuple | None = None


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _clip_near(pc: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman clip of a polygon (k, 3) in camera coordinates to ``z >= Z_NEAR``."""
    if pc[:, 2].min() >= _Z_NEAR_M:
        return pc
    out = []
    for a, b in zip(pc, np.roll(pc, -1, axis=0), strict=True):
        if a[2] >= _Z_NEAR_M:
            out.append(a)
        if (a[2] >= _Z_NEAR_M) != (b[2] >= _Z_NEAR_M):
            out.append(a + (b - a) * (_Z_NEAR_M - a[2]) / (b[2] - a[2]))
    return np.array(out).reshape(-1, 3)


def _prism(foot: np.ndarray, z0: float, z1: float) -> np.ndarray:
    """Side quads of a vertical prism over a counter-clockwise footprint (k, 2): (k, 4, 3), outward facing."""
    k = len(foot)
    lo = np.column_stack([foot, np.full(k, z0)])
    hi = np.column_stack([foot, np.full(k, z1)])
    j = np.roll(np.arange(k), -1)
    return np.stack([lo, lo[j], hi[j], hi], axis=1)


def _top(foot: np.ndarray, z: float) -> np.ndarray:
    return np.column_stack([foot, np.full(len(foot), z)])


@lru_cache(maxsize=256)
def _pattern_cells(pattern: int, width: float, height: float) -> np.ndarray:
    """Rectangles ``(m, 4, 2)`` in ``(s, t)`` (units of the pattern period) of a face's second colour."""
    ns, nt = int(np.ceil(width)), int(np.ceil(height))
    i, j = np.meshgrid(np.arange(ns), np.arange(nt), indexing="ij")
    odd = {PATTERN_HSTRIPES: j % 2 == 1, PATTERN_VSTRIPES: i % 2 == 1, PATTERN_CHECKS: (i + j) % 2 == 1}[pattern]
    s0, t0 = i[odd].astype(float), j[odd].astype(float)
    s1, t1 = np.minimum(s0 + 1, width), np.minimum(t0 + 1, height)
    return np.stack([np.stack([s0, t0], -1), np.stack([s1, t0], -1), np.stack([s1, t1], -1),
                     np.stack([s0, t1], -1)], axis=1).reshape(-1, 4, 2)


def _sample(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear, wrapping lookup of a square texture at texel coordinates ``u, v`` (N,)."""
    n = tex.shape[0]
    i0, j0 = np.floor(v).astype(np.int64), np.floor(u).astype(np.int64)
    fv, fu = v - i0, u - j0
    i0, j0 = i0 % n, j0 % n
    i1, j1 = (i0 + 1) % n, (j0 + 1) % n
    return ((tex[i0, j0] * (1 - fu) + tex[i0, j1] * fu) * (1 - fv) + (tex[i1, j0] * (1 - fu) + tex[i1, j1] * fu) * fv)


def _lambert(n_w: np.ndarray) -> np.ndarray:
    """Brightness factor of surfaces with world normals ``n_w`` (..., 3) under the fixed light."""
    return _AMBIENT + _DIFFUSE * np.maximum(0.0, n_w @ LIGHT_DIR_WORLD)



class CameraSim:
    """Renders one camera of a simulation (issue 3): colour image, optional depth and labels, boxes, visibility.

    Parameters
    ----------
    spec : CameraSpec
        Pose, intrinsics, distortion, noise, illumination schedule and outputs of the camera.
    world : StaticWorld
        Static scene; its floor/backdrop texture comes from ``world.floor_seed`` (same for every camera).
    rng : numpy.random.Generator | int | None
        Draws this camera's white balance (a few percent per channel).
    """

    def __init__(self, spec: CameraSpec, world: StaticWorld, rng: np.random.Generator | int | None = None) -> None:
        rng = np.random.default_rng(rng)
        self.spec, self.world = spec, world
        self.true_camera = PinholeCamera.from_pose(
            spec.position_m, spec.yaw_rad, spec.pitch_rad, spec.roll_rad, fx=spec.fx, fy=spec.fy,
            width=spec.width, height=spec.height, cx=spec.cx, cy=spec.cy, dist=spec.dist or None)
        self.calibrated_camera = self.true_camera.with_yaw_offset(-spec.yaw_bias_rad)
        cam = self.true_camera
        self._R, self._t, self._C = cam.world2cam[:3, :3], cam.world2cam[:3, 3], cam.position_m
        K, W, H = cam.K, spec.width, spec.height
        self._in_image: np.ndarray | None = None
        self._maps: tuple[np.ndarray, np.ndarray] | None = None
        mx0 = my0 = 0
        Wc, Hc = W, H
        if np.any(cam.dist != 0):  # ideal canvas with margins, remapped into the distorted image each frame
            grid = np.stack(np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64)), -1)
            xy = cam.undistort_pixels(grid.reshape(-1, 2), normalized=True).reshape(H, W, 2)
            ux, uy = K[0, 0] * xy[..., 0] + K[0, 2], K[1, 1] * xy[..., 1] + K[1, 2]
            mx0 = int(np.clip(np.ceil(-np.nanmin(ux)) + 2, 0, W // 2))
            my0 = int(np.clip(np.ceil(-np.nanmin(uy)) + 2, 0, H // 2))
            Wc = W + mx0 + int(np.clip(np.ceil(np.nanmax(ux) - W) + 3, 0, W // 2))
            Hc = H + my0 + int(np.clip(np.ceil(np.nanmax(uy) - H) + 3, 0, H // 2))
            self._maps = (np.nan_to_num(ux + mx0, nan=-1).astype(np.float32),
                          np.nan_to_num(uy + my0, nan=-1).astype(np.float32))
        self._f = np.array([K[0, 0], K[1, 1]])
        self._c = np.array([K[0, 2] + mx0, K[1, 2] + my0])
        self._Wc, self._Hc = Wc, Hc
        self._xn = ((np.arange(Wc) - self._c[0]) / self._f[0]).astype(np.float32)  # normalised x of each column
        self._yn = ((np.arange(Hc) - self._c[1]) / self._f[1]).astype(np.float32)
        if self._maps is not None:  # canvas pixels that land inside the distorted image (for visibility)
            canvas = np.stack(np.meshgrid(self._xn, self._yn), -1).reshape(-1, 2).astype(np.float64)
            uv = cam.project((np.column_stack([canvas, np.ones(len(canvas))]) - self._t) @ self._R)
            with np.errstate(invalid="ignore"):
                self._in_image = ((uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5)
                                  & (uv[:, 1] < H - 0.5)).reshape(Hc, Wc)
        self._wb = rng.uniform(0.97, 1.03, 3)
        noise = np.round(spec.noise_sigma * _Q)
        self._noise_pos = np.clip(noise, 0, 255).astype(np.uint8)
        self._noise_neg = np.clip(-noise, 0, 255).astype(np.uint8)
        self._render_static()

    # ---- public API ------------------------------------------------------------------------------

    @property
    def background_bgr(self) -> np.ndarray:
        """The empty scene as the camera sees it (white balance included), gain 1, no noise: ``(H, W, 3) uint8``."""
        return self._expose(self._to_image(self._static_bgr, cv2.INTER_LINEAR), 1.0, None)

    def camera_info(self, t_ns: int) -> CameraInfo:
        """Intrinsics (the same for the true and the believed camera), ``frame_id = spec.name``."""
        d = self.true_camera.dist
        D = np.pad(d, (0, 5 - d.size)) if d.size <= 5 else d
        return CameraInfo(t_ns, self.spec.name, self.spec.name, self.spec.width, self.spec.height,
                          self.true_camera.K, D, "rational_polynomial" if d.size > 5 else "plumb_bob")

    def gain(self, t_s: float) -> float:
        """Illumination gain in force at true time ``t_s`` (s): the last scheduled value, 1 before the first."""
        g = 1.0
        for t0, value in sorted(self.spec.illumination):
            if t_s >= t0:
                g = float(value)
        return g

    def render(self, t_s: float, snapshot: AgentSnapshot, rng: np.random.Generator | int | None = None
               ) -> RenderOutput:
        """Render the agents of ``snapshot`` as the true camera sees them at true time ``t_s``.

        Parameters
        ----------
        t_s : float
            True time (s): selects the illumination gain (and turns bicycle cranks).
        snapshot : AgentSnapshot
            The agents present; ``ids`` must be below 65535 (labels are ``id + 1`` in uint16).
        rng : numpy.random.Generator | int | None
            Draws the image noise, then the depth noise.

        Returns
        -------
        RenderOutput
            Image, optional labels and depth, and per agent (in snapshot order) its box and visibility.
        """
        rng = np.random.default_rng(rng)
        n = len(snapshot)
        if self.spec.labels and n and int(np.max(snapshot.ids)) >= 65535:
            raise ValueError(f"camera {self.spec.name!r}: agent ids must be < 65535 for uint16 labels, got "
                             f"{int(np.max(snapshot.ids))}")
        zbuf, cbuf = self._static_depth.copy(), self._static_bgr.copy()
        lbuf = np.zeros((self._Hc, self._Wc), np.uint16)
        if self.spec.shadows and n:
            self._draw_shadows(cbuf, snapshot)
        area, visibility, verts, rois = np.zeros(n), np.zeros(n), [np.zeros((0, 3))] * n, [None] * n
        for k, parts in enumerate(self._all_parts(snapshot, t_s)):
            area[k], rois[k], verts[k] = self._draw_agent(parts, k + 1, zbuf, cbuf, lbuf)
        for k, roi in enumerate(rois):  # what is left of each agent once everything is drawn
            if roi is not None and area[k] > 0:
                vis = lbuf[roi] == k + 1
                if self._in_image is not None:
                    vis &= self._in_image[roi]
                visibility[k] = min(1.0, np.count_nonzero(vis) / area[k])
        bgr = self._expose(self._to_image(cbuf, cv2.INTER_LINEAR), self.gain(t_s), rng)
        labels = None
        if self.spec.labels:
            lut = np.concatenate([[0], np.asarray(snapshot.ids, np.int64) + 1]).astype(np.uint16)
            labels = np.take(lut, self._to_image(lbuf, cv2.INTER_NEAREST))
        depth = None
        if self.spec.depth:
            z = self._to_image(zbuf, cv2.INTER_NEAREST)
            lo, hi = self.spec.depth_range_m
            u16 = rng.bit_generator.random_raw((z.size + 3) // 4).view(np.uint16)[:z.size].reshape(z.shape)
            noise = np.take(_GAUSS16, u16) * np.float32(self.spec.depth_noise_m)  # Gaussian by its 65536 quantiles
            depth = np.where((z >= lo) & (z <= hi), z + noise, np.float32(np.nan))
        return RenderOutput(bgr, labels, depth, self._boxes(snapshot, verts), visibility)

    # ---- frame composition -----------------------------------------------------------------------

    def _to_image(self, canvas: np.ndarray, interp: int) -> np.ndarray:
        if self._maps is None:
            return canvas.copy()
        border = float("inf") if canvas.dtype == np.float32 else 0
        return cv2.remap(canvas, *self._maps, interp, borderMode=cv2.BORDER_CONSTANT, borderValue=border)

    def _expose(self, bgr: np.ndarray, gain: float, rng: np.random.Generator | None) -> np.ndarray:
        """Illumination gain and white balance, then sensor noise (none when ``rng`` is None)."""
        g = gain * self._wb
        lit = cv2.multiply(bgr, (float(g[0]), float(g[1]), float(g[2]), 0.0))
        if self.spec.noise_sigma <= 0 or rng is None:
            return lit
        size = lit.size
        # random bytes straight from the bit generator (3x faster than Generator.integers); saturating add,
        # then subtract = clip(lit + noise)
        b = rng.bit_generator.random_raw((size + 7) // 8).view(np.uint8)[:size].reshape(lit.shape)
        return cv2.subtract(cv2.add(lit, cv2.LUT(b, self._noise_pos)), cv2.LUT(b, self._noise_neg))

    def _project(self, pc: np.ndarray) -> np.ndarray:
        """Camera-frame points (n, 3), z > 0, to ideal canvas pixels (n, 2)."""
        return pc[:, :2] / pc[:, 2:3] * self._f + self._c

    # ---- agents ----------------------------------------------------------------------------------

    def _draw_agent(self, parts: list[_Part], label: int, zbuf: np.ndarray, cbuf: np.ndarray, lbuf: np.ndarray
                    ) -> tuple[float, tuple[slice, slice] | None, np.ndarray]:
        """Rasterise one agent: parts far-to-near in its own box, then z-tested into the frame buffers.

        Returns the unoccluded silhouette area (px, off-canvas parts included), the canvas ROI it was drawn
        into (None if outside) and the camera-frame vertices of its parts (for its box).
        """
        pc, spans = self._gather(parts)
        if pc is None:
            return 0.0, None, np.zeros((0, 3))
        idx = [i for i, sp in enumerate(spans) if sp is not None]
        s0 = np.array([spans[i][0][0] for i in idx])
        a0, e1, e2 = pc[s0], pc[s0 + 1] - pc[s0], pc[s0 + 2] - pc[s0]
        # a point in the middle of each (symmetric, convex) polygon: halfway to its opposite vertex
        centroid = 0.5 * (a0 + pc[s0 + np.array([(spans[i][0][1] - spans[i][0][0]) // 2 for i in idx])])
        n = e1[:, [1, 2, 0]] * e2[:, [2, 0, 1]] - e1[:, [2, 0, 1]] * e2[:, [1, 2, 0]]  # cross product
        n /= np.maximum(np.sqrt((n * n).sum(1)), 1e-12)[:, None]
        facing = (n * a0).sum(1) < 0
        n[~facing] *= -1  # towards the camera
        cen_dir = centroid / np.sqrt((centroid * centroid).sum(1))[:, None]
        edge_on = np.abs((n * cen_dir).sum(1)) < 0.08
        n[edge_on] = -cen_dir[edge_on]  # plane depth is ill-conditioned: use a plane facing the camera
        shade = _lambert(n @ self._R)[:, None]
        uv = self._project(pc)
        thick = [max(1, round(self._f[0] * parts[i].lines[1] / centroid[m, 2])) if parts[i].lines else 0
                 for m, i in enumerate(idx)]
        pad = max(thick)
        lo, hi = (np.floor(uv.min(0)) - pad).astype(int), (np.ceil(uv.max(0)) + pad + 1).astype(int)
        area = None
        if np.prod(hi - lo) > 2 * self._Wc * self._Hc:  # e.g. right in front of the camera: measure the
            area = self._coarse_area(parts, idx, facing, spans, uv, thick, lo, hi)  # silhouette coarsely and
            lo, hi = np.maximum(lo, 0), np.minimum(hi, (self._Wc, self._Hc))  # draw only the canvas part
        if np.any(hi <= lo):
            return (area or 0.0), None, pc
        # inverse depth is affine in the pixel over a plane: 1/z = a u + b v + c (u, v local to this agent's box)
        inv_d = 1.0 / (n * centroid).sum(1)
        a, b = n[:, 0] * inv_d / self._f[0], n[:, 1] * inv_d / self._f[1]
        c = (n[:, 2] * inv_d + a * (lo[0] - self._c[0]) + b * (lo[1] - self._c[1]))
        planes = np.column_stack([a, b, c]).tolist()
        fixed = np.round((uv - lo) * 16).astype(np.int32)
        col = np.zeros((hi[1] - lo[1], hi[0] - lo[0], 3), np.uint8)
        plane_img = np.zeros(col.shape, np.float32)
        covered = np.zeros(col.shape[:2], np.uint8)
        base = np.array([parts[i].colour for i in idx])
        alt = np.array([base[m] if parts[i].overlay is None else parts[i].overlay_colour for m, i in enumerate(idx)])
        colours = np.clip(np.hstack([base, alt]) * shade, 0, 255).astype(int).tolist()
        for m in np.argsort(-centroid[:, 2], kind="stable").tolist():  # painter's order inside the agent
            i = idx[m]
            if parts[i].cull and not facing[m]:
                continue
            (p0, p1), ov, lns = spans[i]
            if lns:
                pts = [fixed[q0:q1] for q0, q1 in lns]
                for img, value in ((col, colours[m][:3]), (plane_img, planes[m]), (covered, 1)):
                    cv2.polylines(img, pts, False, value, thick[m], cv2.LINE_8, 4)
                continue
            for img, value in ((col, colours[m][:3]), (plane_img, planes[m]), (covered, 1)):
                cv2.fillConvexPoly(img, fixed[p0:p1], value, cv2.LINE_8, 4)
            if ov is not None:  # pattern cells, hair, windows: same plane, drawn over the part
                cv2.fillPoly(col, fixed[ov[0]:ov[1]].reshape(ov[2], -1, 2), colours[m][3:], cv2.LINE_8, 4)
        area = float(cv2.countNonZero(covered)) if area is None else area
        x0, y0 = max(lo[0], 0), max(lo[1], 0)
        x1, y1 = min(hi[0], self._Wc), min(hi[1], self._Hc)
        if area == 0 or x1 <= x0 or y1 <= y0:
            return area, None, pc
        local = (slice(y0 - lo[1], y1 - lo[1]), slice(x0 - lo[0], x1 - lo[0]))
        pl = plane_img[local]
        inv = (pl[..., 0] * np.arange(x0 - lo[0], x1 - lo[0], dtype=np.float32)
               + pl[..., 1] * np.arange(y0 - lo[1], y1 - lo[1], dtype=np.float32)[:, None] + pl[..., 2])
        roi = (slice(y0, y1), slice(x0, x1))
        with np.errstate(divide="ignore"):
            depth = 1.0 / inv
        sel = ((depth < zbuf[roi]) & (covered[local] != 0) & (inv > 0)).view(np.uint8)
        cv2.copyTo(depth, sel, zbuf[roi])  # in place: the ROI views are written by OpenCV
        cv2.copyTo(col[local], sel, cbuf[roi])
        np.copyto(lbuf[roi], label, where=sel.view(bool))
        return area, roi, pc

    def _coarse_area(self, parts: list[_Part], idx: list[int], facing: np.ndarray, spans: list, uv: np.ndarray,
                     thick: list[int], lo: np.ndarray, hi: np.ndarray) -> float:
        """Silhouette area (px) of an agent whose box ``lo, hi`` is huge, rasterised at a reduced scale."""
        scale = float(np.sqrt(self._Wc * self._Hc / np.prod(hi - lo)))
        mask = np.zeros((int((hi[1] - lo[1]) * scale) + 2, int((hi[0] - lo[0]) * scale) + 2), np.uint8)
        fixed = np.round((uv - lo) * scale * 16).astype(np.int32)
        for m, i in enumerate(idx):
            if parts[i].cull and not facing[m]:
                continue
            (p0, p1), _, lns = spans[i]
            if lns:
                cv2.polylines(mask, [fixed[q0:q1] for q0, q1 in lns], False, 1, max(1, round(thick[m] * scale)),
                              cv2.LINE_8, 4)
            else:
                cv2.fillConvexPoly(mask, fixed[p0:p1], 1, cv2.LINE_8, 4)
        return cv2.countNonZero(mask) / scale**2

    def _gather(self, parts: list[_Part]) -> tuple[np.ndarray | None, list]:
        """Camera-frame vertices (N, 3) of every polygon of ``parts``, clipped to the near plane, and per part
        ``((start, stop) of its polygon, (start, stop, count) of its overlay or None, [(start, stop)] lines)``
        (None for a part entirely behind the near plane; overlays and lines crossing it are dropped)."""
        arrays, spans, off = [], [], 0
        for p in parts:
            arrays.append(p.verts)
            span, off = (off, off + len(p.verts)), off + len(p.verts)
            ov_span = None
            if p.overlay is not None:
                m = p.overlay.shape[0] * p.overlay.shape[1]
                arrays.append(p.overlay.reshape(m, 3))
                ov_span, off = (off, off + m, p.overlay.shape[0]), off + m
            line_spans = []
            for q in p.lines[0] if p.lines else ():
                arrays.append(q)
                line_spans.append((off, off + len(q)))
                off += len(q)
            spans.append((span, ov_span, line_spans))
        pc = np.vstack(arrays) @ self._R.T + self._t
        if pc[:, 2].min() >= _Z_NEAR_M:
            return pc, spans
        out, clipped, off = [], [], 0  # slow path: the agent reaches behind the near plane
        for (p0, p1), ov, lns in spans:
            poly = _clip_near(pc[p0:p1])
            lines = [pc[q0:q1] for q0, q1 in lns if pc[q0:q1, 2].min() >= _Z_NEAR_M]
            if len(poly) < 3 or (lns and not lines):
                clipped.append(None)
                continue
            out.append(poly)
            span, off = (off, off + len(poly)), off + len(poly)
            ov_span = None
            if ov is not None and pc[ov[0]:ov[1], 2].min() >= _Z_NEAR_M:
                out.append(pc[ov[0]:ov[1]])
                ov_span, off = (off, off + ov[1] - ov[0], ov[2]), off + ov[1] - ov[0]
            line_spans = []
            for q in lines:
                out.append(q)
                line_spans.append((off, off + len(q)))
                off += len(q)
            clipped.append((span, ov_span, line_spans))
        return (np.vstack(out) if out else None), clipped

    def _boxes(self, snap: AgentSnapshot, verts: list[np.ndarray]) -> np.ndarray:
        """Tight boxes of the rendered bodies (people) or the cuboids (vehicles), distorted pixels (n, 4)."""
        pcs = list(verts)
        for k in np.flatnonzero(np.isin(snap.kinds, (KIND_CAR, KIND_BICYCLE))):
            foot = rect_corners(snap.position_m[k], snap.size_m[k, 0], snap.size_m[k, 1], snap.heading_rad[k])[0]
            faces = _prism(foot, 0.0, snap.size_m[k, 2]) @ self._R.T + self._t
            pcs[k] = faces.reshape(-1, 3)
            if pcs[k][:, 2].min() < _Z_NEAR_M:
                pcs[k] = np.vstack([_clip_near(f) for f in faces])
        sizes = np.array([len(p) for p in pcs], np.int64)
        boxes = np.full((len(snap), 4), np.nan)
        has = np.flatnonzero(sizes)
        if has.size:
            uv = self.true_camera.project((np.vstack(pcs) - self._t) @ self._R)
            starts = (np.cumsum(sizes) - sizes)[has]
            boxes[has] = np.hstack([np.minimum.reduceat(uv, starts), np.maximum.reduceat(uv, starts)])
        return boxes

    def _all_parts(self, snap: AgentSnapshot, t_s: float) -> list[list[_Part]]:
        """The drawable parts of every agent of ``snap`` (people vectorised over the snapshot)."""
        n = len(snap)
        yaw = snap.heading_rad.astype(np.float64)
        fwd = np.column_stack([np.cos(yaw), np.sin(yaw), np.zeros(n)])
        lft = np.column_stack([-np.sin(yaw), np.cos(yaw), np.zeros(n)])
        base = np.column_stack([snap.position_m, np.zeros(n)])
        h = snap.size_m[:, 2].astype(np.float64)
        upper, lower = snap.upper_bgr.astype(np.float64), snap.lower_bgr.astype(np.float64)
        out: list[list[_Part]] = [[] for _ in range(n)]
        people = np.flatnonzero((snap.kinds != KIND_CAR) & (snap.kinds != KIND_BICYCLE))
        if people.size:
            b, f, lf, hp = base[people], fwd[people], lft[people], h[people]
            pm = np.array([1.0, -1.0])[None, :, None]  # left, right
            feet = np.concatenate([snap.feet_m[people], np.zeros((people.size, 2, 1))], axis=2)
            bad = ~np.all(np.isfinite(feet), axis=(1, 2))
            feet[bad] = b[bad][:, None] + pm * 0.09 * lf[bad][:, None]
            swing = -0.6 * np.einsum("nfj,nj->nf", feet - b[:, None], f)  # each arm swings against its own leg
            hands = (b[:, None] + pm * (0.115 * hp)[:, None, None] * lf[:, None] + swing[..., None] * f[:, None]
                     + (0.44 * hp)[:, None, None] * _UP)
            bodies = self._bodies(b, f, lf, hp, feet, hands, 0.47 * hp, 0.81 * hp, upper[people], lower[people],
                                  snap.pattern[people], snap.ids[people], np.ones(people.size))
            for k, parts in zip(people, bodies, strict=True):
                out[k] = parts
        for k in np.flatnonzero(snap.kinds == KIND_CAR):
            out[k] = self._car_parts(snap.position_m[k], float(yaw[k]), *snap.size_m[k], upper[k])
        for k in np.flatnonzero(snap.kinds == KIND_BICYCLE):
            out[k] = self._bicycle_parts(snap, k, t_s, base[k], fwd[k], lft[k], upper[k], lower[k])
        return out

    def _bicycle_parts(self, snap: AgentSnapshot, k: int, t_s: float, base: np.ndarray, fwd: np.ndarray,
                       lft: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> list[_Part]:
        """A thin dark frame (wheels, tubes) with a rider pedalling, fitted into the agent's size."""
        L, W, h = (float(v) for v in snap.size_m[k])
        r = min(0.34, L / 4, 0.2 * h)
        a = L / 2 - r
        crank = float(np.hypot(*snap.velocity_mps[k])) * t_s / (2.5 * r)
        bb = base + r * 0.85 * _UP - 0.05 * fwd
        pedals = np.array([bb + s * 0.1 * lft + 0.17 * (np.cos(c) * fwd + np.sin(c) * _UP)
                           for s, c in ((1, crank), (-1, crank + np.pi))])
        ws = min(1.0, 0.45 * W / (0.129 * h))  # keep the rider inside the agent's width
        hands = np.array([base + (a - 0.18) * fwd + s * 0.2 * ws * lft + 0.56 * h * _UP for s in (1, -1)])
        (body,) = self._bodies((base - 0.2 * fwd)[None], fwd[None], lft[None], np.array([h]), pedals[None],
                               hands[None], np.array([0.52 * h]), np.array([0.8 * h]), upper[None], lower[None],
                               snap.pattern[k:k + 1], snap.ids[k:k + 1], np.array([ws]))
        seat, head = base - 0.22 * fwd + 0.5 * h * _UP, base + (a - 0.12) * fwd + 0.55 * h * _UP
        rear, front = base - a * fwd + r * _UP, base + a * fwd + r * _UP
        ring = np.vstack([_DISC, _DISC[:1]])
        wheels = [c + r * (np.cos(ring) * fwd + np.sin(ring) * _UP) for c in (rear, front)]
        frame = [np.array([rear, bb, seat, rear]), np.array([seat, head, bb]), np.array([head, front])]
        e = self._across_view(base[None] + 0.5 * h * _UP, lft[None])[0]  # frame depth: a plane facing the camera
        plane = base + np.array([-e, e, e + _UP, -e + _UP]) * 0.5
        return [*body, _Part(plane, _DARK, lines=([*wheels, *frame], 0.035))]

    def _across_view(self, p: np.ndarray, fallback: np.ndarray) -> np.ndarray:
        """Horizontal unit vectors (n, 3) across the lines of sight to points ``p`` (n, 3)."""
        e = np.column_stack([p[:, 1] - self._C[1], self._C[0] - p[:, 0], np.zeros(len(p))])
        norm = np.hypot(e[:, 0], e[:, 1])[:, None]
        return np.where(norm > 1e-6, e / np.maximum(norm, 1e-12), fallback)

    def _bodies(self, base: np.ndarray, fwd: np.ndarray, lft: np.ndarray, h: np.ndarray, feet: np.ndarray,
                hands: np.ndarray, hip_z: np.ndarray, shoulder_z: np.ndarray, upper: np.ndarray, lower: np.ndarray,
                pattern: np.ndarray, ids: np.ndarray, ws: np.ndarray) -> list[list[_Part]]:
        """People (or riders), vectorised over n: legs from ``feet`` (n, 2, 3) to the hips, a torso box
        0.19h x 0.12h (0.33 x 0.21 m at h = 1.75 m) above ``base`` (n, 3), arms to ``hands`` (n, 2, 3), neck, head.

        ``feet`` and ``hands`` are ordered (left, right); shoulders are ~0.45 m wide at 1.75 m; ``ws`` (n,)
        scales widths. Legs, arms, neck and head are camera-facing billboards; the torso is a culled box
        carrying the clothing pattern (ALGORITHMS.md B12-B13 need texture to learn from).
        """
        H = h[:, None, None]
        e = self._across_view(base + 0.5 * h[:, None] * _UP, lft)[:, None, :]  # (n, 1, 3)
        side = np.array([1.0, -1.0])[None, :, None] * (H * ws[:, None, None]) * lft[:, None, :]
        hips = base[:, None] + 0.05 * side + hip_z[:, None, None] * _UP
        sh = base[:, None] + 0.105 * side + (shoulder_z - 0.03 * h)[:, None, None] * _UP
        legs = np.stack([feet - 0.03 * H * e, feet + 0.03 * H * e, hips + 0.043 * H * e, hips - 0.043 * H * e], 2)
        arms = np.stack([sh - 0.026 * H * e, sh + 0.026 * H * e, hands + 0.02 * H * e, hands - 0.02 * H * e], 2)
        local = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])[None] * np.stack(
            [0.06 * h, 0.095 * h * ws], -1)[:, None, :]  # torso footprint: rear-right, front-right, ...
        foot = base[:, None, :2] + local[..., :1] * fwd[:, None, :2] + local[..., 1:] * lft[:, None, :2]
        z0 = hip_z - 0.02 * h
        lo = np.concatenate([foot, np.broadcast_to(z0[:, None, None], (*foot.shape[:2], 1))], 2)
        hi = np.concatenate([foot, np.broadcast_to(shoulder_z[:, None, None], (*foot.shape[:2], 1))], 2)
        j = [1, 2, 3, 0]
        sides = np.stack([lo, lo[:, j], hi[:, j], hi], 2)  # (n, 4 faces, 4, 3), outward
        rv, rh = (0.065 * h)[:, None], (0.055 * h)[:, None]
        centre = base + (shoulder_z + 0.19 * h)[:, None] * _UP - rv * _UP
        neck = base + (shoulder_z - 0.01 * h)[:, None] * _UP
        e2 = e[:, 0] * (0.028 * h)[:, None]
        necks = np.stack([neck - e2, neck + e2, centre + e2, centre - e2], 1)
        v = centre - self._C  # the head: an ellipse facing the camera, hair on its upper part
        es = self._across_view(centre, lft)
        et = np.cross(es, v)
        et /= np.linalg.norm(et, axis=1, keepdims=True) * np.where(et[:, 2:] >= 0, 1.0, -1.0)
        disc = centre[:, None] + (rh * np.cos(_DISC.T))[..., None] * es[:, None] + (rv * np.sin(_DISC.T))[..., None] \
            * et[:, None]
        cap = centre[:, None] + (rh * np.cos(_HAIR_ARC.T))[..., None] * es[:, None] \
            + (rv * np.sin(_HAIR_ARC.T))[..., None] * et[:, None]
        lum = upper @ np.array([0.114, 0.587, 0.299])
        alt = np.where(lum[:, None] > 100, upper * 0.5, upper + 0.55 * (255.0 - upper))  # pattern's second colour
        ids = np.asarray(ids, np.int64)
        skin, hair = _SKIN[ids * 7919 % len(_SKIN)], _HAIR[ids * 104729 % len(_HAIR)]
        out = []
        for k in range(len(h)):
            parts = [_Part(legs[k, 0], lower[k]), _Part(legs[k, 1], lower[k])]
            p = 0.057 * h[k]
            for f in sides[k]:
                ov = None
                if pattern[k] in (PATTERN_HSTRIPES, PATTERN_VSTRIPES, PATTERN_CHECKS):
                    e_s = f[1] - f[0]
                    width = np.hypot(e_s[0], e_s[1])
                    cells = _pattern_cells(int(pattern[k]), round(width / p, 3), round((f[2, 2] - f[0, 2]) / p, 3))
                    ov = f[0] + (p / width) * cells[..., :1] * e_s + p * cells[..., 1:] * _UP
                parts.append(_Part(f, upper[k], True, ov, alt[k]))
            parts += [_Part(hi[k], upper[k], True), _Part(arms[k, 0], upper[k]), _Part(arms[k, 1], upper[k]),
                      _Part(necks[k], skin[k]), _Part(disc[k], skin[k], False, cap[k][None], hair[k])]
            out.append(parts)
        return out

    def _car_parts(self, pos: np.ndarray, yaw: float, L: float, W: float, h: float, paint: np.ndarray
                   ) -> list[_Part]:
        """Lower body with a dark sill band and a cabin with dark windows, as back-face-culled boxes."""
        parts = []
        for z0, z1, foot, band in ((0.0, 0.5 * h, rect_corners(pos, L, W, yaw)[0], (0.0, 0.18)),
                                   (0.5 * h, h, rect_corners(pos - 0.05 * L * np.array([np.cos(yaw), np.sin(yaw)]),
                                                             0.5 * L, 0.88 * W, yaw)[0], None)):
            for f in _prism(foot, z0, z1):
                e_s = f[1] - f[0]
                width = np.hypot(e_s[0], e_s[1])
                e_s = e_s / width
                if band is None:  # window: inset from the cabin side's edges
                    s0, s1, t0, t1 = 0.08, width - 0.08, z0 + 0.05, z1 - 0.07
                else:
                    s0, s1, t0, t1 = 0.0, width, band[0], band[1]
                ov = np.array([f[0] + s * e_s + (t - f[0, 2]) * _UP for s, t in ((s0, t0), (s1, t0), (s1, t1),
                                                                                  (s0, t1))])
                parts.append(_Part(f, paint, True, ov[None], _WINDOW if band is None else _DARK))
            parts.append(_Part(_top(foot, z1), paint, True))
        return parts

    def _draw_shadows(self, cbuf: np.ndarray, snap: AgentSnapshot) -> None:
        """Darken the floor under and behind every agent (soft multiplicative shadows, ALGORITHMS.md A3)."""
        h = snap.size_m[:, 2]
        length = h * _SHADOW_PER_M
        half_w = np.where(snap.kinds == KIND_BICYCLE, 0.3, 0.2)
        perp = np.array([-_SHADOW_DIR[1], _SHADOW_DIR[0]])
        centre = snap.position_m + 0.45 * length[:, None] * _SHADOW_DIR
        ellipses = (centre[:, None, :] + ((0.45 * length + 0.12)[:, None, None] * np.cos(_DISC)[None]) * _SHADOW_DIR
                    + (half_w[:, None, None] * np.sin(_DISC)[None]) * perp)
        polys = list(ellipses)
        for k in np.flatnonzero(snap.kinds == KIND_CAR):
            foot = rect_corners(snap.position_m[k], snap.size_m[k, 0] * 1.02, snap.size_m[k, 1] * 1.02,
                                snap.heading_rad[k])[0]
            hull = cv2.convexHull(np.vstack([foot, foot + 0.6 * length[k] * _SHADOW_DIR]).astype(np.float32))
            polys[k] = hull.reshape(-1, 2).astype(np.float64)
        # penumbra: the outer polygon half dark, the inner 70 % fully dark, then a 1-px blur (soft at any scale)
        polys += [q.mean(0) + 0.7 * (q - q.mean(0)) for q in polys]
        cams = [_clip_near(np.column_stack([q, np.zeros(len(q))]) @ self._R.T + self._t) for q in polys]
        uvs = [(self._project(q), 150 if j < len(snap) else 255) for j, q in enumerate(cams) if len(q) >= 3]
        if not uvs:
            return
        allv = np.vstack([uv for uv, _ in uvs])
        x0, y0 = (max(int(v) - 4, 0) for v in np.floor(allv.min(0)))
        x1, y1 = (min(int(v) + 5, m) for v, m in zip(np.ceil(allv.max(0)), (self._Wc, self._Hc), strict=True))
        if x1 <= x0 or y1 <= y0:
            return
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        for uv, value in uvs:
            cv2.fillConvexPoly(mask, np.round((uv - (x0, y0)) * 16).astype(np.int32), value, cv2.LINE_8, 4)
        soft = cv2.multiply(cv2.GaussianBlur(mask, (0, 0), 1.0), self._static_floor[y0:y1, x0:x1])
        factor = cv2.convertScaleAbs(soft, alpha=-(1.0 - SHADOW_GAIN), beta=255.0)  # 255 * (1 - (1 - g) soft)
        cv2.multiply(cbuf[y0:y1, x0:x1], cv2.merge([factor] * 3), cbuf[y0:y1, x0:x1], scale=1 / 255)

    # ---- static scene (rendered once) --------------------------------------------------------------

    def _render_static(self) -> None:
        """Backdrop, floor (tiles and noise from ``world.floor_seed``), roads, walls, pillars and boxes, with
        their depth along the optical axis and a mask of the pixels that show the floor; done once."""
        w = self.world
        fr = np.random.default_rng(w.floor_seed)
        tex = [cv2.GaussianBlur(np.tile(fr.standard_normal((256, 256)).astype(np.float32), (3, 3)), (0, 0), s)
               [256:512, 256:512] for s in (0.8, 3.0)]  # tiled, so the blurred texture wraps seamlessly
        tex = [t / t.std() for t in tex]
        tile, base = fr.uniform(0.5, 0.8), fr.uniform([140, 150, 155], [170, 178, 188])
        tile_var = fr.normal(0.0, 0.05, (32, 32))
        wall_c, wood_c = fr.uniform([175, 185, 190], [205, 210, 215]), fr.uniform([50, 85, 120], [70, 105, 150])
        Hc, Wc = self._Hc, self._Wc
        xn, yn = np.meshgrid(self._xn, self._yn)
        dirw = np.stack([xn, yn, np.ones_like(xn)], -1) @ self._R  # world direction of each pixel's ray (z = 1)
        elev = dirw[..., 2] / np.linalg.norm(dirw, axis=-1)
        k = np.clip(elev * 3.0, 0, 1)[..., None]
        col = (1 - k) * np.array([205.0, 200.0, 195.0]) + k * np.array([225.0, 190.0, 150.0])
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -self._C[2] / dirw[..., 2]
        floor = (s > 0) & (s < _FLOOR_FAR_M)
        depth = np.where(floor, s, np.inf)
        X, Y, sf = self._C[0] + s[floor] * dirw[..., 0][floor], self._C[1] + s[floor] * dirw[..., 1][floor], s[floor]
        fp = sf / self._f[0] / np.maximum(np.abs(elev[floor]), 0.05)  # ground footprint of a pixel (m)
        n1, n2 = _sample(tex[0], X / 0.05, Y / 0.05), _sample(tex[1], X / 0.5, Y / 0.5)
        fc = base * (1 + tile_var[np.floor(X / tile).astype(int) % 32, np.floor(Y / tile).astype(int) % 32])[:, None]
        fc *= (1 + 0.05 * n1 + 0.06 * n2)[:, None]
        gx, gy = np.abs((X / tile + 0.5) % 1 - 0.5) * tile, np.abs((Y / tile + 0.5) % 1 - 0.5) * tile

        def line(c: np.ndarray, dist: np.ndarray, width: float, colour: Any, where: Any = True) -> None:
            on = (dist < np.maximum(width, fp) / 2) & where
            a = np.minimum(1.0, width / fp[on])[:, None]
            colour = np.asarray(colour, np.float64)
            c[on] = (1 - a) * c[on] + a * (colour[on] if colour.ndim == 2 else colour)

        line(fc, np.minimum(gx, gy), 0.012, fc * 0.7)
        for x0, y0, x1, y1, rw in w.roads:
            u = _unit(np.array([x1 - x0, y1 - y0]))
            along, d = (X - x0) * u[0] + (Y - y0) * u[1], -(X - x0) * u[1] + (Y - y0) * u[0]
            on = (along > -rw / 2) & (along < np.hypot(x1 - x0, y1 - y0) + rw / 2) & (np.abs(d) <= rw / 2)
            asphalt = np.array([88.0, 88.0, 92.0])[None] * (1 + 0.08 * n1 + 0.05 * n2)[:, None]
            fc[on] = asphalt[on]
            line(fc, np.abs(d), 0.15, (90, 200, 230), on)
            line(fc, np.abs(np.abs(d) - (rw / 2 - 0.25)), 0.15, (225, 225, 225), on)
            for m in range(1, int(rw / 2 / w.lane_width_m) + 1):
                if m * w.lane_width_m < rw / 2 - 0.5:
                    line(fc, np.abs(np.abs(d) - m * w.lane_width_m), 0.15, (225, 225, 225), on & (along % 9 < 3))
        haze = (1 - np.exp(-sf / 80.0))[:, None]
        col[floor] = (1 - haze) * fc * _lambert(_UP) / 0.95 + haze * np.array([205.0, 200.0, 195.0])

        def static(verts: np.ndarray, shade: Any, two_sided: bool = False) -> None:
            pc = _clip_near(verts @ self._R.T + self._t)
            if len(pc) < 3:
                return
            n_c = _unit(np.cross(pc, np.roll(pc, -1, axis=0)).sum(0))  # Newell normal, outward
            if n_c @ pc[0] > 0:  # back face
                if not two_sided:
                    return
                n_c = -n_c
            uv = self._project(pc)
            x0, y0 = np.maximum(np.floor(uv.min(0)).astype(int), 0)
            x1, y1 = np.minimum(np.ceil(uv.max(0)).astype(int) + 1, (Wc, Hc))
            if x1 <= x0 or y1 <= y0:
                return
            mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
            cv2.fillConvexPoly(mask, np.round((uv - (x0, y0)) * 16).astype(np.int32), 1, cv2.LINE_8, 4)
            ys, xs = np.nonzero(mask)
            xr, yr = self._xn[x0 + xs].astype(np.float64), self._yn[y0 + ys].astype(np.float64)
            with np.errstate(divide="ignore", invalid="ignore"):
                dz = (n_c @ pc[0]) / (n_c[0] * xr + n_c[1] * yr + n_c[2])
            ok = (dz > 0) & (dz < depth[y0 + ys, x0 + xs])
            ys, xs, dz = ys[ok], xs[ok], dz[ok]
            depth[y0 + ys, x0 + xs] = dz
            floor[y0 + ys, x0 + xs] = False
            world = (np.column_stack([dz * xr[ok], dz * yr[ok], dz]) - self._t) @ self._R
            col[y0 + ys, x0 + xs] = shade(world) * _lambert(n_c @ self._R)

        hw = w.wall_height_m
        for (x0, y0), (x1, y1) in w.walls:
            d = _unit(np.array([x1 - x0, y1 - y0, 0.0]))

            def wall(P: np.ndarray, x0: float = x0, y0: float = y0, d: np.ndarray = d) -> np.ndarray:
                s = (P[:, 0] - x0) * d[0] + (P[:, 1] - y0) * d[1]
                c = wall_c * (1 + 0.04 * _sample(tex[1], s / 0.1, P[:, 2] / 0.1))[:, None]
                seam = (np.abs((s / 1.2 + 0.5) % 1 - 0.5) < 0.01) | (P[:, 2] < 0.12)
                return np.where(seam[:, None], c * 0.75, c)

            static(np.array([[x0, y0, 0], [x1, y1, 0], [x1, y1, hw], [x0, y0, hw]], np.float64), wall, True)
        for px, py, pr in w.pillars:
            ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
            foot = np.column_stack([px + pr * np.cos(ang), py + pr * np.sin(ang)])
            for face in [*_prism(foot, 0.0, w.pillar_height_m), _top(foot, w.pillar_height_m)]:
                static(face, lambda P: np.array([150.0, 152.0, 155.0]) * (
                    1 + 0.05 * _sample(tex[0], (P[:, 0] + P[:, 1]) / 0.05, P[:, 2] / 0.05))[:, None])
        for corners, height in zip(w.box_corners(), w.boxes[:, 5], strict=True):
            for face in [*_prism(corners, 0.0, height), _top(corners, height)]:
                static(face, lambda P: wood_c * (1 + 0.08 * _sample(tex[0], P[:, 0] / 0.05, P[:, 1] / 0.3
                                                                    + P[:, 2] / 0.05))[:, None])
        self._static_bgr = np.clip(col, 0, 255).astype(np.uint8)
        self._static_depth = depth.astype(np.float32)
        self._static_floor = floor.astype(np.uint8)  # 1 where the floor is what the pixel shows
        for arr in (self._static_bgr, self._static_depth, self._static_floor):
            arr.setflags(write=False)
