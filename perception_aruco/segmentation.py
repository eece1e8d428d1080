"""Bottle segmentation by colour class with depth (stands in for the paper's YOLO segmentation, Sect. 5: its
weights cannot be downloaded here; the paper's bottles were told apart by colour, as ours are).

1. Every pixel with a depth return is back-projected into the robot base frame (camera pose from the marker).
2. Workspace gate: only points inside a shelf compartment (above a board, inside the side and back panels,
   under the board above, off the marker plates where the scenario puts them and where they are seen) can belong
   to a bottle; boards, arm, floor, markers drop out.
3. Colour class: a pixel p (RGB, 0..255) belongs to the class c whose reference colour a_c explains it best under
   a shading gain s in [gain_min, gain_max]:  residual_c(p) = || p - s* a_c ||,  s* = clip(p.a_c / |a_c|^2).
   Colours that are not scalar multiples of each other (orange / brown, yellow / olive) are told apart by their
   chromaticity; scalar multiples (black / white / gray) by their brightness range. Pixels with no class within
   `max_residual` are left unassigned, and so are ambiguous pixels: the best class must explain the pixel clearly
   better than the second best (residual ratio <= `max_ratio`); an ambiguous pixel is never given the nearest,
   possibly wrong, class. A saturated channel (>= `clip_level`) is a lower bound: a residual only where the
   class predicts less, the gain fitted on the other channels (over-exposed orange, red clipped, is not yellow).
   The colour image is median-filtered first (3x3, 5x5 when the noise measured on the marker's white exceeds
   `wide_median_noise`: sensor noise; edges stay sharp), and deconvolved when the marker's edges show blur
   (`deblur`).
4. Colour constancy: before classifying, the image is normalised by the marker's own white and black (its plate
   is a known neutral: a warm or cool white balance, or an exposure change, is undone), see `plate_levels`.
5. Each class mask is eroded by `erode_px` (anti-aliased silhouette pixels; not below `erode_min_focal`) without
   growing depth holes: a pixel without depth does not erode its neighbours.
No rclpy here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike

from relocation_common.scenario import Marker, Scenario

from .aruco import ImageFormatError, marker_in_base
from .objects.params import value

UNASSIGNED = -1
NOISE_KERNEL = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)


@dataclass(frozen=True)
class SegmentationParams:
    """Colour classes and the workspace gate (module docstring)."""

    gain_min: float = field(default_factory=value("gain_min"))  # darkest shading of a colour (its shadowed side)
    gain_max: float = field(default_factory=value("gain_max"))  # brightest (lit side, before saturation)
    max_residual: float = field(default_factory=value("max_residual"))  # RGB: farther from every class: unassigned
    wall_margin: float = 0.004   # m kept off the boards and panels by the workspace gate
    marker_margin: float = 0.01  # m around the marker plate excluded from the gate
    erode_px: int = 1            # erosion of each class mask (drops anti-aliased silhouette pixels)
    median_px: int = 3           # median filter of the colour image before classifying (sensor noise); 0: none
    max_ratio: float = 0.7       # best / second-best residual above this: ambiguous, unassigned
    white_level: float = 195.0   # the marker plate's white is scaled to this (0..255; the renderer's at 0.6-0.7 m)
    min_gain: float = 0.5        # bounds of the colour normalisation's per-channel gain
    max_gain: float = 2.5
    wide_median_noise: float = 14.0  # colour noise (sigma on the marker's white, 0..255) above which the median is 5x5
    erode_min_focal: float = 400.0   # px: at a shorter focal length (a lower resolution) the masks are not eroded
    sharp_blur: float = 0.65         # px: the blur `plate_levels` measures on a sharp frame (anti-aliasing)
    deblur_min: float = 1.0          # px: blur beyond the sharp frame's above which the colour image is deconvolved
    clip_level: int = 254            # a channel at or above this is saturated (`classify_colours`)
    clipped_gain: float = 2.0        # the shading gain of a pixel with a saturated channel may reach gain_max x this

    def for_frame(self, focal: float, levels: PlateLevels | None) -> SegmentationParams:
        """These parameters adapted to one frame: the median filter widened to 5x5 when the colour noise measured on
        the marker's white (`plate_levels`) exceeds `wide_median_noise` (sigma 20 lost the dark bottles' pixels);
        no erosion when the focal length (px) is below `erode_min_focal` (at 480x360 and less the 1-pixel
        anti-aliased fringe is a large part of a bottle partly hidden; the fit's inlier test and flying-pixel filter
        drop the fringe's mixed pixels)."""
        noisy = levels is not None and levels.noise > self.wide_median_noise and self.median_px > 1
        return replace(self, median_px=max(self.median_px, 5) if noisy else self.median_px,
                       erode_px=self.erode_px if focal >= self.erode_min_focal else 0)


def check_images(rgb: ArrayLike, depth: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Colour HxWx3 uint8 and depth HxW (float metres) of the same size; ImageFormatError otherwise."""
    rgb, depth = np.asarray(rgb), np.asarray(depth)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ImageFormatError(f"colour image must be HxWx3 uint8 (rgb8), got shape {rgb.shape} {rgb.dtype}")
    if depth.ndim != 2 or not np.issubdtype(depth.dtype, np.floating):
        raise ImageFormatError(f"depth image must be HxW float metres, got shape {depth.shape} {depth.dtype}")
    if rgb.shape[:2] != depth.shape:
        raise ImageFormatError(f"colour {rgb.shape[1]}x{rgb.shape[0]} and depth {depth.shape[1]}x{depth.shape[0]} "
                               "differ in size (the depth must be registered to the colour image)")
    return rgb, depth


def backproject_image(depth: np.ndarray, K: np.ndarray, T_base_camera: np.ndarray) -> np.ndarray:
    """HxWx3 points in the base frame (NaN where depth is 0 or not finite). Depth is planar z (RealSense)."""
    h, w = depth.shape
    z = depth.astype(np.float32)
    z = np.where(np.isfinite(z) & (z > 0), z, np.float32(np.nan))
    x = ((np.arange(w, dtype=np.float32) - np.float32(K[0, 2])) / np.float32(K[0, 0]))[None, :] * z
    y = ((np.arange(h, dtype=np.float32) - np.float32(K[1, 2])) / np.float32(K[1, 1]))[:, None] * z
    r, t = np.asarray(T_base_camera, np.float32)[:3, :3], np.asarray(T_base_camera, np.float32)[:3, 3]
    out = np.empty((h, w, 3), np.float32)
    for k in range(3):
        out[..., k] = r[k, 0] * x + r[k, 1] * y + r[k, 2] * z + t[k]
    return out


def on_marker_plates(points: np.ndarray, markers: Sequence[Marker], margin: float) -> np.ndarray:
    """Bool per point (... x 3, base frame, NaN allowed): on one of the markers' plates (within `margin`)."""
    return on_plates(points, [(marker_in_base(m), m.size) for m in markers], margin)


def on_plates(points: np.ndarray, plates: Sequence[tuple[np.ndarray, float]], margin: float) -> np.ndarray:
    """Bool per point (... x 3, NaN allowed): on one of the plates, given as (T_frame_marker 4x4 in the points'
    frame, marker size), within `margin` of its edge and 2 cm of its face."""
    out = np.zeros(points.shape[:-1], bool)
    with np.errstate(invalid="ignore"):
        for t, size in plates:
            local = (points - np.asarray(t[:3, 3], np.float32)) @ np.asarray(t[:3, :3], np.float32)
            half = size * 0.75 + margin  # the plate carries a white margin of a quarter side
            out |= (np.abs(local[..., 0]) < half) & (np.abs(local[..., 1]) < half) & (np.abs(local[..., 2]) < 0.02)
    return out


def workspace_mask(points: np.ndarray, scenario: Scenario, margin: float, marker_margin: float) -> np.ndarray:
    """HxW bool: the point is inside the top or bottom shelf compartment and not on a marker plate."""
    s = scenario.shelf
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    with np.errstate(invalid="ignore"):
        inside = (x > s.x_front - 0.02) & (x < s.x_back - margin) & (y > s.y_min + margin) & (y < s.y_max - margin)
        top = (z > s.top_z + margin) & (z < s.ceiling_z - margin)
        bottom = (z > s.bottom_z + margin) & (z < s.top_z - s.board_thickness - margin)
        mask = inside & (top | bottom)
    mask[mask] = ~on_marker_plates(points[mask], scenario.markers, marker_margin)
    return mask


def colour_residuals(rgb_pixels: np.ndarray, refs: np.ndarray, params: SegmentationParams,
                     clipped: np.ndarray | None = None) -> np.ndarray:
    """N x C: the distance of each of N pixels (N x 3, 0..255) to each of C reference colours shaded by the best
    gain in [gain_min, gain_max] (|p - s* a_c|). `clipped` (N x 3 bool): channels the camera saturated; their value
    is a lower bound (a residual only where the class predicts less), the shading gain is fitted on the other
    channels and may reach `gain_max` x `clipped_gain` (the pixel was brighter than the camera's range: over-exposed
    orange is not yellow)."""
    p = rgb_pixels.astype(np.float32)
    a = refs.astype(np.float32)
    s = np.clip(p @ a.T / np.maximum(np.sum(a * a, axis=1), 1e-6), params.gain_min, params.gain_max)  # N x C
    res = np.linalg.norm(p[:, None, :] - s[..., None] * a[None, :, :], axis=2)             # N x C
    sat = np.nonzero(clipped.any(axis=1))[0] if clipped is not None else np.zeros(0, int)
    if clipped is not None and len(sat):  # the few saturated pixels: censored channels
        q, c = p[sat], clipped[sat]
        u = (~c).astype(np.float32)
        num, den = (q * u) @ a.T, u @ (a * a).T
        top = params.gain_max * params.clipped_gain
        s = np.clip(np.where(den > 0, num / np.maximum(den, 1e-6), top), params.gain_min, top)
        diff = q[:, None, :] - s[..., None] * a[None, :, :]
        res[sat] = np.linalg.norm(np.where(c[:, None, :], np.maximum(diff, 0.0), diff), axis=2)
    return res


def classify_colours(rgb_pixels: np.ndarray, refs: np.ndarray, params: SegmentationParams,
                     clipped: np.ndarray | None = None) -> np.ndarray:
    """Class index per pixel (N,) for N x 3 pixels and C x 3 reference colours (0..255); UNASSIGNED if none fits
    within `max_residual` or the best is not clearly better than the second best (`max_ratio`); `clipped` as in
    `colour_residuals`."""
    res = colour_residuals(rgb_pixels, refs, params, clipped)
    rows = np.arange(len(res))
    best = np.argmin(res, axis=1)
    first = res[rows, best].copy()
    bad = first > params.max_residual
    if res.shape[1] > 1:
        res[rows, best] = np.inf
        bad |= first > params.max_ratio * res.min(axis=1)
    best[bad] = UNASSIGNED
    return best


@dataclass(frozen=True)
class PlateLevels:
    """The marker plate as seen: its white and black (RGB, 0..255), the colour noise on its white (robust sigma,
    0..255), which sets the median filter's size (`SegmentationParams.for_frame`), and the blur of its edges (sigma of
    a Gaussian, px), which `deblur` undoes."""

    white: np.ndarray
    black: np.ndarray
    noise: float
    blur: float = 0.0


def plate_levels(rgb: np.ndarray, corners: np.ndarray) -> PlateLevels | None:
    """The marker plate's white (its margin and bits) and black (its square), the noise on the white and the blur
    of the edges, or None when the plate is too small or has no contrast. The two groups are split at the middle
    of the plate's grey levels."""
    h, w = rgb.shape[:2]
    centre = corners.mean(0)
    quad = np.round(centre + 1.3 * (corners - centre)).astype(np.int32)
    c0, r0 = np.maximum(quad.min(0) - 2, 0)
    c1, r1 = np.minimum(quad.max(0) + 3, (w, h))
    crop = rgb[r0:r1, c0:c1].astype(np.float32)
    mask = np.zeros(crop.shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, quad - (c0, r0), 1)
    px = crop[mask > 0]
    if len(px) < 50:
        return None
    g = px.mean(1)
    lo, hi = np.percentile(g, 5), np.percentile(g, 95)
    if hi - lo < 30:
        return None
    mid = (lo + hi) / 2
    # noise: the response of the 3x3 Laplacian-difference kernel (std 6 sigma on flat Gaussian noise; Immerkaer
    # 1996) on the white pixels whose 3x3 neighbourhood is all white (edges and shading gradients left out)
    flat = cv2.erode(((crop.mean(2) > mid) & (mask > 0)).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    resp = cv2.filter2D(crop, -1, NOISE_KERNEL)[flat]
    noise = 1.4826 * float(np.median(np.abs(resp))) / 6.0 if resp.size else 0.0
    white, black = np.median(px[g > mid], axis=0), np.median(px[g <= mid], axis=0)
    # blur: a step of height H blurred by a Gaussian of sigma has the steepest slope H / (sqrt(2 pi) sigma)
    gray = crop.mean(2)
    slope = np.hypot(cv2.Sobel(gray, cv2.CV_32F, 1, 0), cv2.Sobel(gray, cv2.CV_32F, 0, 1))[mask > 0] / 8.0
    blur = float(np.mean(white - black)) / (math.sqrt(2 * math.pi) * max(float(np.percentile(slope, 99)), 1e-6))
    return PlateLevels(white, black, noise, blur)


def deblur(rgb: np.ndarray, levels: PlateLevels | None, params: SegmentationParams) -> np.ndarray:
    """The colour image deconvolved (Wiener filter, Gaussian kernel) by the blur measured on the marker's edges
    beyond a sharp frame's, when that exceeds `deblur_min` (defocus, a slow shutter; at sigma 2 px the edge pixels of
    small bottles mixed into other classes); the noise-to-signal term from the noise measured on the marker."""
    if levels is None or levels.blur ** 2 - params.sharp_blur ** 2 <= params.deblur_min ** 2:
        return rgb
    sigma = math.sqrt(levels.blur ** 2 - params.sharp_blur ** 2)
    h, w = rgb.shape[:2]
    f2 = np.fft.fftfreq(h)[:, None] ** 2 + np.fft.rfftfreq(w)[None, :] ** 2
    kernel = np.exp(-2 * math.pi ** 2 * sigma ** 2 * f2)
    gain = kernel / (kernel ** 2 + max(1e-3, (levels.noise / 50.0) ** 2))
    out = np.empty(rgb.shape, np.float32)
    for c in range(3):
        out[..., c] = np.fft.irfft2(np.fft.rfft2(rgb[..., c].astype(np.float32)) * gain, s=(h, w))
    return np.clip(out, 0, 255).astype(np.uint8)


def normalise_colours(pixels: np.ndarray, levels: PlateLevels | None, params: SegmentationParams) -> np.ndarray:
    """Pixels (N x 3) with the plate's black subtracted and its white scaled to `white_level` per channel."""
    if levels is None:
        return pixels
    gain = np.clip(params.white_level / np.maximum(levels.white - levels.black, 1.0), params.min_gain, params.max_gain)
    return np.clip((pixels.astype(np.float32) - levels.black) * gain, 0, 255)


@dataclass(frozen=True)
class Segmentation:
    """labels: HxW int, index into `classes` (scenario object ids) or UNASSIGNED; points: HxWx3 base frame."""

    labels: np.ndarray
    points: np.ndarray
    classes: tuple[str, ...]

    def mask(self, object_id: str) -> np.ndarray:
        """HxW bool: the pixels of this object's colour class."""
        return self.labels == self.classes.index(object_id)


def segment(rgb: ArrayLike, depth: ArrayLike, K: ArrayLike, T_base_camera: ArrayLike, scenario: Scenario,
            params: SegmentationParams = SegmentationParams(), levels: PlateLevels | None = None) -> Segmentation:
    """Per-pixel bottle class of a registered RGB-D frame (see the module docstring)."""
    rgb, depth = check_images(rgb, depth)
    points = backproject_image(depth, np.asarray(K, float), np.asarray(T_base_camera, float))
    return segment_points(rgb, points, scenario, params, levels)


def segment_points(rgb: np.ndarray, points: np.ndarray, scenario: Scenario,
                   params: SegmentationParams = SegmentationParams(), levels: PlateLevels | None = None,
                   exclude: np.ndarray | None = None) -> Segmentation:
    """`segment` on base-frame points already computed (HxWx3, NaN without depth); `levels`: the marker plate
    (`plate_levels`) for the colour normalisation (None: none); `exclude`: HxW bool, pixels never classified (the
    plates of the markers as seen, wherever the scenario puts them)."""
    gate = workspace_mask(points, scenario, params.wall_margin, params.marker_margin)
    if exclude is not None:
        gate &= ~exclude
    if params.median_px > 1:
        rgb = cv2.medianBlur(np.ascontiguousarray(rgb), params.median_px)
    classes = tuple(b.id for b in scenario.objects)
    refs = np.array([b.rgb for b in scenario.objects]) * 255.0
    labels = np.full(points.shape[:2], UNASSIGNED, np.int32)
    px = rgb[gate]
    labels[gate] = classify_colours(normalise_colours(px, levels, params), refs, params, px >= params.clip_level)
    if params.erode_px > 0:
        kernel = np.ones((2 * params.erode_px + 1,) * 2, np.uint8)
        no_depth = ~np.isfinite(points[..., 2])
        for k in range(len(classes)):
            m = labels == k
            if m.any():
                # a pixel without depth is neutral: it neither erodes its neighbours nor is kept itself
                labels[m & (cv2.erode((m | no_depth).astype(np.uint8), kernel) == 0)] = UNASSIGNED
    return Segmentation(labels, points, classes)
