"""The shape fits' fast forms against the formulas they replace (docs/bench/perception.md, "Speed"), on generated
points: the lying cylinder's axis search over all directions at once (primitives._search_rms) against one
cross-section fit per direction (primitives._cross_section), the circle's Gauss-Newton (localize._gauss_newton)
against its matrix form; the lying cylinder's rms floor (primitives.lying_rms_floor) under every lying fit; the box
fitted on its faces under the realistic camera's noise and flying pixels (docs/perception.md, "Objects")."""
from __future__ import annotations

import math

import numpy as np
import pytest

from perception_aruco.localize import FitError, _gauss_newton
from perception_aruco.objects.model import BOX
from perception_aruco.objects.params import ObjectParams
from perception_aruco.objects.primitives import (
    _cross_section,
    _search_rms,
    _section_start,
    box,
    fit_primitive,
    lying_cylinder,
    lying_rms_floor,
    lying_start,
)


def lying_points(rng: np.random.Generator, radius: float, length: float, yaw: float, noise: float,
                 cap: bool) -> np.ndarray:
    """The half of a lying cylinder's surface facing +x and up (x, y, z above the board), one end cap if `cap`."""
    u = rng.uniform(-length / 2, length / 2, 600)
    phi = rng.uniform(-0.3, math.pi + 0.3, 600)        # around the axis, from the camera's side over the top
    across, up = radius * np.cos(phi), radius + radius * np.sin(phi)
    pts = [np.c_[u, across, up]]
    if cap:
        rho, ang = radius * np.sqrt(rng.uniform(0, 1, 200)), rng.uniform(0, 2 * math.pi, 200)
        pts.append(np.c_[np.full(200, length / 2), rho * np.cos(ang), radius + rho * np.sin(ang)])
    p = np.concatenate(pts)
    c, s = math.cos(yaw), math.sin(yaw)
    xy = p[:, :2] @ np.array([[c, s], [-s, c]]) + (0.6, 0.1)
    return np.c_[xy, p[:, 2]] + rng.normal(0, noise, (len(p), 3))


@pytest.mark.parametrize("seed", range(6))
def test_the_axis_search_at_once_gives_each_directions_cross_section_rms(seed):
    rng = np.random.default_rng(seed)
    pts = lying_points(rng, rng.uniform(0.02, 0.04), rng.uniform(0.1, 0.2), rng.uniform(-math.pi, math.pi),
                       [0.0005, 0.002, 0.005][seed % 3], cap=seed % 2 == 1)
    xy, z, view = pts[:, :2], pts[:, 2], np.array([0.8, 0.0, -0.4])
    mean, r0 = xy.mean(axis=0), max(float(np.percentile(z, 99)) / 2, 0.015)
    dirs = np.array([[math.cos(a), math.sin(a)] for a in np.radians(np.arange(0, 180, 10))])
    s, sc0 = _section_start(xy, mean, np.c_[-dirs[:, 1], dirs[:, 0]], r0, view)
    at_once = _search_rms(dirs @ (xy - mean).T, s, z, sc0, np.full(len(dirs), r0), 6)
    one_by_one = []
    for axis in dirs:   # as the search ran before: one _cross_section per direction
        normal = np.array([-axis[1], axis[0]])
        sk = (xy - mean) @ normal
        start = float(np.median(sk)) + r0 * math.copysign(1.0, float(normal @ view[:2]) or 1.0)
        one_by_one.append(_cross_section((xy - mean) @ axis, sk, z, start, r0, 6)[2])
    assert np.allclose(at_once, one_by_one, rtol=1e-9, atol=1e-12)
    assert int(np.argmin(at_once)) == int(np.argmin(one_by_one))


def gauss_newton_matrix_form(pts: np.ndarray, centre: np.ndarray, radius: float | None,
                             iterations: int) -> tuple[np.ndarray, float]:
    """The circle's Gauss-Newton as it was written: the Jacobian built with np.c_, distances by np.linalg.norm."""
    r = 0.0 if radius is None else radius
    x = np.r_[centre, r] if radius is None else centre.copy()
    for _ in range(iterations):
        d = pts - x[:2]
        dist = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        res = dist - (x[2] if radius is None else r)
        jac = -d / dist[:, None]
        if radius is None:
            jac = np.c_[jac, -np.ones(len(pts))]
        step = np.linalg.solve(jac.T @ jac, -jac.T @ res)
        x = x + step
        if np.linalg.norm(step) < 1e-7:
            break
    return x[:2], float(x[2]) if radius is None else r


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("fitted", [True, False])
def test_the_circle_gauss_newton_is_its_matrix_form_to_the_last_bit(seed, fitted):
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.02, 0.05)
    ang = rng.uniform(-1.2, 1.2, 300) + rng.uniform(0, 2 * math.pi)   # the arc a camera sees
    pts = np.c_[0.5 + r * np.cos(ang), 0.1 + r * np.sin(ang)] + rng.normal(0, 0.001, (300, 2))
    start = np.array([0.5, 0.1]) + rng.normal(0, 0.01, 2)
    radius = None if fitted else r
    got, want = _gauss_newton(pts, start, radius, 20), gauss_newton_matrix_form(pts, start, radius, 20)
    assert np.array_equal(got[0], want[0]) and got[1] == want[1]


@pytest.mark.parametrize("seed", range(6))
def test_no_lying_fit_of_a_tall_standing_bottle_is_below_its_rms_floor(seed):
    """lying_rms_floor bounds every lying fit's rms from below (fit_primitive leaves the lying fit out on it): the
    principal-axis fit and the searched one, on the visible side of a standing bottle taller than 2 radius_max."""
    params = ObjectParams.configured()
    rng = np.random.default_rng(seed)
    r, h = rng.uniform(0.02, 0.04), 2 * params.radius_max + rng.uniform(0.01, 0.05)
    phi, z = rng.uniform(-1.3, 1.3, 1500) + math.pi, rng.uniform(0, h, 1500)   # the side facing the camera (-x)
    pts = np.c_[0.6 + r * np.cos(phi), 0.1 + r * np.sin(phi), z] + rng.normal(0, 0.001, (1500, 3))
    view = np.array([0.6, 0.0, -0.5])
    floor = lying_rms_floor(pts, 0.0, params)
    start = lying_start(pts, 0.0, view, params)
    assert floor > 0.003 and start.fit[2] >= floor
    try:
        searched = lying_cylinder(pts, 0.0, view, params, 0.0, start).rms   # bound 0: the search always runs
    except FitError:
        return   # out of its bounds: no lying fit either
    assert searched >= floor


def box_points(rng: np.random.Generator, centre: np.ndarray, size: tuple[float, float, float], yaw: float,
               camera: np.ndarray, sigma: float, flying: float) -> np.ndarray:
    """The faces of a box on the board (z 0) a camera at `camera` sees (the top and the sides facing it), each point
    moved along its ray by Gaussian noise of `sigma` (a stereo camera's depth error), and a `flying` fraction of
    them, taken within 5 mm of a face's edge, pushed 5-15 mm back along their rays (flying pixels between an edge and
    what lies behind it)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])
    half = np.array(size) / 2
    faces = [(np.array([0.0, 0.0, 1.0]), 2)] + [(np.r_[sg * rot[:, k], 0.0], k) for k in (0, 1) for sg in (-1, 1)]
    pts, edge = [], []
    for normal, k in faces:
        mid = np.r_[centre, size[2] / 2] + normal * (half[k] if k < 2 else size[2] / 2)
        if normal @ (camera - mid) <= 0:
            continue   # facing away: hidden
        area = np.prod([size[i] for i in range(3) if i != k])
        n = int(area / 4e-6)   # a point per 2 x 2 mm
        loc = rng.uniform(-1, 1, (n, 3)) * half
        loc[:, k] = np.sign(normal @ np.r_[rot[:, k], 0.0] if k < 2 else 1.0) * half[k]
        free = [i for i in range(3) if i != k]
        edge.append(np.any(np.abs(half[free] - np.abs(loc[:, free])) < 0.005, axis=1))
        pts.append(np.c_[loc[:, :2] @ rot.T + centre, loc[:, 2] + size[2] / 2])
    p, at_edge = np.concatenate(pts), np.concatenate(edge)
    ray = (p - camera) / np.linalg.norm(p - camera, axis=1)[:, None]
    p = p + ray * rng.normal(0, sigma, (len(p), 1))
    fly = rng.choice(np.flatnonzero(at_edge), int(flying * len(p)), replace=False)
    p[fly] += ray[fly] * rng.uniform(0.005, 0.015, (len(fly), 1))
    return p


@pytest.mark.parametrize("seed", range(6))
def test_a_box_under_depth_noise_and_flying_pixels_is_fitted_on_its_faces(seed):
    """A box seen by the realistic camera (depth noise 2 mm along the rays, 5 % flying pixels at its edges): the fit
    (primitives.box, and fit_primitive's choice) is that box within 10 mm, its rms within the fit bound. The hull's
    rectangle (cv2.minAreaRect of all points, the fit before) reaches the flying pixels: a rectangle tens of mm too
    large, its rms over the bound."""
    params = ObjectParams.configured()
    rng = np.random.default_rng([seed, 36])
    size = (rng.uniform(0.05, 0.12), rng.uniform(0.05, 0.12), rng.uniform(0.08, 0.2))
    centre, yaw = np.array([rng.uniform(0.7, 0.9), rng.uniform(-0.2, 0.2)]), rng.uniform(-math.pi, math.pi)
    camera = np.array([0.0, -0.35, 0.55])
    sigma = 0.002
    pts = box_points(rng, centre, size, yaw, camera, sigma, 0.01)
    top = float(np.percentile(pts[:, 2], 99.5))
    bound = max(params.fit_rms, params.fit_noise * sigma)
    fitted = box(pts, 0.0, top, camera, params, params.fit_noise * sigma)
    assert math.dist((fitted.x, fitted.y), centre) < 0.010
    assert np.allclose(sorted(fitted.size[:2]), sorted(size[:2]), atol=0.010)
    assert fitted.rms <= bound
    side = pts[pts[:, 2] < top - 0.006, :2]
    best = fit_primitive(pts, side, np.ones(len(side), bool), top, top - 0.006, 0.0, camera, params, sigma,
                         2.5 * sigma)
    assert best.shape == BOX and not best.conservative
    assert math.dist((best.x, best.y), centre) < 0.010
