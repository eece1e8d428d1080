"""camera_info and image sizes checked before perception uses them (ROS-free).

A calibration perception cannot use is refused with the reason and the frame dropped: the camera matrix K
(sensor_msgs/CameraInfo.k, row-major 3x3, OpenCV's intrinsics: fx 0 cx / 0 fy cy / 0 0 1) must be finite with
positive focal lengths and the principal point inside the image, and be for the size of the images (a NaN or
all-zero K made OpenCV's pose solver raise "Eigenvalues did not converge" and ended the node). An image larger than
`max_image_pixels` is refused before it is decoded or kept (a 4K frame took the node from 204 MiB to 1.9 GiB).
"""
from __future__ import annotations

import math
from typing import Sequence


def image_problem(width: int, height: int, max_pixels: int, what: str = "image") -> str | None:
    """Why an image of width x height cannot be used, or None."""
    if width <= 0 or height <= 0:
        return f"{what} is {width}x{height}: empty"
    if width * height > max_pixels:
        return (f"{what} is {width}x{height} = {width * height} pixels > max_image_pixels ({max_pixels}): "
                "set the camera to a smaller resolution (or raise max_image_pixels)")
    return None


def camera_info_problem(k: Sequence[float], info_size: tuple[int, int], image_size: tuple[int, int]) -> str | None:
    """Why camera_info (its K and width x height) cannot be used with images of image_size (width, height), or
    None."""
    if len(k) != 9 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in k):
        return f"camera_info K is not 9 finite numbers: {list(k)}"
    fx, fy, cx, cy = k[0], k[4], k[2], k[5]
    if not (fx > 0 and fy > 0):
        return f"camera_info K has focal lengths fx={fx:g}, fy={fy:g}: both must be > 0 (is the camera calibrated?)"
    if tuple(k[6:]) != (0, 0, 1) or k[3] != 0:
        return f"camera_info K's last row must be 0 0 1 and K[1][0] 0 (a pinhole camera matrix), got {list(k)}"
    w, h = info_size
    if (w, h) != tuple(image_size):
        return f"camera_info is for {w}x{h}, the images are {image_size[0]}x{image_size[1]}"
    if not (0 <= cx < w and 0 <= cy < h):
        return f"camera_info K's principal point ({cx:g}, {cy:g}) is outside the {w}x{h} image"
    return None
