"""What a real RGB-D camera does to the renderer's perfect images (no ROS, seeded): the `camera_model` of the driver
(`ideal`: images as rendered; `realsense_d435`: the effects below at a D435's typical magnitudes) and the
perturbations of the perception robustness benchmark (scripts/bench_perception_robustness.py).

Depth (planar z, metres, 0 = no return):
- noise growing with distance squared: sigma(z) = sigma_ref * (z / z_ref)^2 (a stereo camera's depth error grows as
  z^2 / (focal length x baseline); a D435 gives about 2 mm at 0.75 m in its high-accuracy preset);
- holes: pixels without a return, in small clumps (texture-less or dark surfaces), and along depth edges (the
  stereo shadow: one camera sees what the other does not);
- flying pixels: on a depth edge, a pixel at a depth between the near and the far surface.
Colour (RGB uint8): white balance (per-channel gains, warm = more red, less blue), exposure (one gain, clipped
at 255), noise (Gaussian, per channel) and blur; motion blur of what moves during the exposure (`exposure_s`: the
colour image is the mean of sub-frames rendered over the exposure, jaco2_sim_driver.camera.CameraRenderer; the
depth stream's short global-shutter exposure is not blurred).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike

CAMERA_MODELS = ("ideal", "realsense_d435")


def depth_noise(depth: np.ndarray, sigma_ref: float, rng: np.random.Generator, z_ref: float = 0.75) -> np.ndarray:
    """Depth with Gaussian noise of sigma_ref * (z / z_ref)^2 (m) on every valid pixel."""
    z = depth.astype(np.float32)
    valid = z > 0
    noisy = z + rng.standard_normal(z.shape).astype(np.float32) * np.float32(sigma_ref) * (z / z_ref) ** 2
    return np.where(valid, np.maximum(noisy, 1e-3), 0.0).astype(np.float32)


def depth_holes(depth: np.ndarray, fraction: float, rng: np.random.Generator, clump_px: int = 3) -> np.ndarray:
    """Depth with about `fraction` of the pixels set to 0 (no return), in clumps of about clump_px pixels."""
    h, w = depth.shape
    hh, ww = max(1, h // clump_px), max(1, w // clump_px)
    small = rng.random((hh, ww)) < fraction
    holes = cv2.resize(small.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    return np.where(holes, 0.0, depth).astype(np.float32)


def depth_edges(depth: np.ndarray, jump: float = 0.02) -> np.ndarray:
    """HxW bool: a pixel whose 4-neighbour is more than `jump` (m) farther (the far side of a depth edge)."""
    z = np.where(depth > 0, depth, np.inf).astype(np.float32)
    near = cv2.erode(z, np.ones((3, 3), np.uint8))   # min over the 3x3 neighbourhood
    with np.errstate(invalid="ignore"):
        return np.isfinite(z) & (z - near > jump)


def edge_holes_and_flying_pixels(depth: np.ndarray, rng: np.random.Generator, hole_prob: float = 0.5,
                                 flying_prob: float = 0.2) -> np.ndarray:
    """On the far side of depth edges: a hole with hole_prob, else a flying pixel (between near and far) with
    flying_prob."""
    z = depth.astype(np.float32).copy()
    edges = depth_edges(z)
    near = cv2.erode(np.where(z > 0, z, np.inf).astype(np.float32), np.ones((3, 3), np.uint8))
    u = rng.random(z.shape)
    hole = edges & (u < hole_prob)
    fly = edges & ~hole & (u < hole_prob + flying_prob)
    mix = rng.random(z.shape).astype(np.float32)
    z[fly] = near[fly] + mix[fly] * (z[fly] - near[fly])
    z[hole] = 0.0
    return z


def white_balance(rgb: np.ndarray, gains: ArrayLike) -> np.ndarray:
    """Per-channel gains (r, g, b), clipped to 0..255."""
    return np.clip(rgb.astype(np.float32) * np.asarray(gains, np.float32), 0, 255).astype(np.uint8)


def warm(level: float) -> tuple[float, float, float]:
    """White-balance gains of a warm cast (level 0.1 = +10 % red, -10 % blue); negative level: cool."""
    return (1.0 + level, 1.0, 1.0 - level)


def exposure(rgb: np.ndarray, gain: float) -> np.ndarray:
    """Brightness x gain, saturating at 255."""
    return white_balance(rgb, (gain, gain, gain))


def colour_noise(rgb: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian noise of sigma (0..255 units) on every channel."""
    return np.clip(rgb.astype(np.float32) + rng.standard_normal(rgb.shape).astype(np.float32) * sigma, 0,
                   255).astype(np.uint8)


def blur(rgb: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian blur of sigma_px pixels (defocus, or motion while the arm moves)."""
    return cv2.GaussianBlur(rgb, (0, 0), sigma_px) if sigma_px > 0 else rgb


@dataclass(frozen=True)
class SensorModel:
    """A camera's imperfections; `apply(rgb, depth)` returns the images it would give. Drift: the white balance and
    exposure wander (random walk of `drift_sigma` per frame, bounded by `drift_max`), as an auto white balance does."""

    depth_sigma: float = 0.0       # m at z_ref
    z_ref: float = 0.75
    hole_fraction: float = 0.0
    edge_holes: bool = False
    colour_sigma: float = 0.0
    drift_sigma: float = 0.0
    drift_max: float = 0.0
    blur_px: float = 0.0
    exposure_s: float = 0.0        # colour exposure time: motion blur while the arm moves (CameraRenderer)

    @classmethod
    def named(cls, name: str) -> SensorModel:
        """`ideal` (no effect) or `realsense_d435` (magnitudes of a D435 at 0.5-1 m, high-accuracy preset)."""
        if name == "ideal":
            return cls()
        if name == "realsense_d435":
            return cls(depth_sigma=0.002, hole_fraction=0.01, edge_holes=True, colour_sigma=3.0, drift_sigma=0.01,
                       drift_max=0.05, blur_px=0.5, exposure_s=0.02)  # auto exposure indoors: 10-33 ms
        raise ValueError(f"camera_model must be one of {', '.join(CAMERA_MODELS)}, got {name!r}")


class SensorSimulator:
    """Applies a SensorModel frame after frame (the drift state lives here); seeded."""

    def __init__(self, model: SensorModel, seed: int = 0):
        self.model = model
        self.rng = np.random.default_rng(seed)
        self.wb = 0.0      # warm (+) / cool (-) cast
        self.gain = 1.0    # exposure

    def apply(self, rgb: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rgb, depth) as the modelled camera gives them."""
        m, rng = self.model, self.rng
        if m == SensorModel():
            return rgb, depth
        if m.drift_sigma > 0:
            self.wb = float(np.clip(self.wb + rng.normal(0, m.drift_sigma), -m.drift_max, m.drift_max))
            self.gain = float(np.clip(self.gain + rng.normal(0, m.drift_sigma), 1 - m.drift_max, 1 + m.drift_max))
            rgb = white_balance(rgb, np.asarray(warm(self.wb)) * self.gain)
        rgb = blur(rgb, m.blur_px)
        if m.colour_sigma > 0:
            rgb = colour_noise(rgb, m.colour_sigma, rng)
        if m.edge_holes:
            depth = edge_holes_and_flying_pixels(depth, rng)
        if m.depth_sigma > 0:
            depth = depth_noise(depth, m.depth_sigma, rng, m.z_ref)
        if m.hole_fraction > 0:
            depth = depth_holes(depth, m.hole_fraction, rng)
        return rgb, depth
