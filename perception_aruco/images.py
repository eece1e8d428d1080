"""sensor_msgs/Image fields -> numpy (no rclpy, no cv_bridge: it is not on PyPI).

Colour: rgb8 (the driver's, RealSense default) or bgr8. Depth: 32FC1 (metres) or 16UC1 / mono16 (millimetres, the
RealSense driver's default), returned as float32 metres with 0 = no return. Anything else: ImageFormatError.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .aruco import ImageFormatError

COLOR_ENCODINGS = ("rgb8", "bgr8")
DEPTH_ENCODINGS = ("32FC1", "16UC1", "mono16")


def _array(encoding: str, height: int, width: int, step: int, data: Any, dtype: Any, channels: int,
           is_bigendian: bool = False) -> np.ndarray:
    dt = np.dtype(dtype).newbyteorder(">" if is_bigendian else "<")
    row = width * channels * dt.itemsize
    if height <= 0 or width <= 0:
        raise ImageFormatError(f"{encoding} image of size {width}x{height}")
    if step < row:
        raise ImageFormatError(f"{encoding} image: step {step} < {row} bytes per row")
    try:
        buf = np.frombuffer(data, np.uint8)
    except TypeError:
        buf = np.asarray(data, np.uint8).reshape(-1)
    if buf.size != step * height:
        raise ImageFormatError(f"{encoding} image {width}x{height}: {buf.size} data bytes, expected {step * height}")
    rows = buf.reshape(height, step)[:, :row]
    out = np.ascontiguousarray(rows).view(dt).reshape((height, width, channels) if channels > 1 else (height, width))
    return out.astype(dt.newbyteorder("="), copy=False)


def decode_color(encoding: str, height: int, width: int, step: int, data: Any,
                 is_bigendian: bool = False) -> np.ndarray:
    """HxWx3 uint8 RGB."""
    if encoding not in COLOR_ENCODINGS:
        raise ImageFormatError(f"colour image encoding {encoding!r} not supported (use {', '.join(COLOR_ENCODINGS)})")
    img = _array(encoding, height, width, step, data, np.uint8, 3)
    return img[:, :, ::-1].copy() if encoding == "bgr8" else img


def decode_depth(encoding: str, height: int, width: int, step: int, data: Any,
                 is_bigendian: bool = False) -> np.ndarray:
    """HxW float32 metres (0 = no return; NaN/Inf of a float image also become 0)."""
    if encoding == "32FC1":
        d = _array(encoding, height, width, step, data, np.float32, 1, is_bigendian).astype(np.float32)
        d[~np.isfinite(d) | (d < 0)] = 0.0
        return d
    if encoding in ("16UC1", "mono16"):
        return _array(encoding, height, width, step, data, np.uint16, 1, is_bigendian).astype(np.float32) / 1000.0
    raise ImageFormatError(f"depth image encoding {encoding!r} not supported (use {', '.join(DEPTH_ENCODINGS)})")


def encode_color(rgb: np.ndarray) -> tuple[str, int, int, int, bytes]:
    """(encoding, height, width, step, data) of an rgb8 image (for the debug image and tests)."""
    rgb = np.ascontiguousarray(rgb, np.uint8)
    h, w = rgb.shape[:2]
    return "rgb8", h, w, 3 * w, rgb.tobytes()


def encode_depth(depth_m: np.ndarray, encoding: str = "32FC1") -> tuple[str, int, int, int, bytes]:
    """(encoding, height, width, step, data) of a depth image in metres: 32FC1 metres or 16UC1 millimetres."""
    depth_m = np.asarray(depth_m, np.float32)
    h, w = depth_m.shape
    if encoding == "32FC1":
        return encoding, h, w, 4 * w, np.ascontiguousarray(depth_m).tobytes()
    if encoding == "16UC1":
        mm = np.clip(np.round(depth_m * 1000.0), 0, 65535).astype(np.uint16)
        return encoding, h, w, 2 * w, mm.tobytes()
    raise ImageFormatError(f"cannot encode depth as {encoding!r}")
