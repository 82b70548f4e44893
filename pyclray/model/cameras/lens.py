"""The lenses of OpenCV's camera models, in float64: their forward maps (a direction in the camera's
frame to the normalized image coordinates K^-1 [u, v, 1]) and their inverses per pixel, solved to
float64's precision, with the pixels each lens cannot reach.

- Radial-tangential (OpenCV's ``projectPoints``; Brown-Conrady with the rational radial term):
  x = X / Z, r^2 = |x|^2, x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
  + tangential (2 p1 x y + p2 (r^2 + 2 x^2), p1 (r^2 + 2 y^2) + 2 p2 x y).
- Fisheye (OpenCV's ``fisheye::projectPoints``, Kannala-Brandt): theta the angle off the optical
  axis, theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), x_d = theta_d x / r.

Where a lens folds over (its radial map stops growing: two directions land on one pixel), the
directions beyond the fold are not its field: the pixels only they would reach are misses, never a
wrong ray. The fold is the first radius where the radial map's derivative is not positive (or the
rational term's denominator is not), found on a fine grid and refined by bisection."""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .base import RayTable

# The radial maps are scanned for their fold up to this radius (normalized image coordinates, about
# 89.9 degrees off the axis for a pinhole) or angle (a fisheye's, pi)
PINHOLE_SCAN_REACH = 1e3
# How many samples of the scan (geometric from PINHOLE_SCAN_FROM): a fold between two samples is
# found by the sign of the derivative at the next, then refined by bisection to float64
SCAN_SAMPLES = 20_000
PINHOLE_SCAN_FROM = 1e-4
# A pixel's solution is kept where the forward model maps it back to the pixel within this
# (relative to 1 + |x_d|): Newton's last step is then far below 1e-4 pixels for any focal length a
# float32 ray can resolve
SOLVED = 1e-12
BISECTIONS = 64  # halvings of a bracket in [0, 1e3] to float64's resolution: the most steps a solve takes
NEWTON_STEPS = 8  # the full (tangential) model's steps from the radial solution: quadratic convergence
# Solved tables kept by value (intrinsics, coefficients, size): a moving camera's frames and a
# handle's views of one lens share theirs; a 1024x768 table is 19 MB
TABLES_KEPT = 4


def radial_pinhole(coefficients, r2):
    """(factor, d factor / d r^2) of the radial-tangential model's radial term at r^2."""
    k1, k2, p1, p2, k3, k4, k5, k6 = coefficients
    numerator = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    denominator = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    d_numerator = k1 + r2 * (2 * k2 + r2 * 3 * k3)
    d_denominator = k4 + r2 * (2 * k5 + r2 * 3 * k6)
    return numerator / denominator, (d_numerator * denominator - numerator * d_denominator) / denominator**2, denominator


def distort_pinhole(coefficients, x, y):
    """(x_d, y_d) of undistorted normalized coordinates (OpenCV's projectPoints, without K)."""
    k1, k2, p1, p2, k3, k4, k5, k6 = coefficients
    r2 = x * x + y * y
    factor, _, _ = radial_pinhole(coefficients, r2)
    return (x * factor + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * factor + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def _pinhole_jacobian(coefficients, x, y):
    k1, k2, p1, p2, k3, k4, k5, k6 = coefficients
    r2 = x * x + y * y
    factor, d_factor, _ = radial_pinhole(coefficients, r2)
    # d r2 / dx = 2 x
    dxx = factor + x * d_factor * 2 * x + 2 * p1 * y + p2 * 6 * x
    dxy = x * d_factor * 2 * y + 2 * p1 * x + p2 * 2 * y
    dyx = y * d_factor * 2 * x + p1 * 2 * x + 2 * p2 * y
    dyy = factor + y * d_factor * 2 * y + p1 * 6 * y + 2 * p2 * x
    return dxx, dxy, dyx, dyy


def pinhole_fold(coefficients) -> float:
    """The undistorted radius where the radial term's map r -> r factor(r^2) first stops growing
    (or its denominator reaches 0): the lens's field ends there; inf where it never does."""
    def slope(r):
        factor, d_factor, denominator = radial_pinhole(coefficients, r * r)
        return np.where(denominator > 0, factor + 2 * r * r * d_factor, -1.0)  # d (r factor) / dr

    return _first_fold(slope, np.geomspace(PINHOLE_SCAN_FROM, PINHOLE_SCAN_REACH, SCAN_SAMPLES))


def _first_fold(slope, grid) -> float:
    grid = np.concatenate([[0.0], grid])
    bad = np.nonzero(slope(grid) <= 0)[0]
    if not len(bad):
        return math.inf
    lo, hi = float(grid[bad[0] - 1]), float(grid[bad[0]])
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        if slope(np.array(mid)) <= 0:
            hi = mid
        else:
            lo = mid
    return lo


def _radial_inverse(forward, slope, target, reach):
    """r in [0, reach] with forward(r) = target (forward increasing there: one solution), per
    element, to float64's precision: Newton's steps kept inside the bracket [lo, hi] that each
    evaluation narrows (a step leaving it bisects instead), each element until its step is down to
    its last bits (the elements still moving are iterated alone); nan where target > forward(reach),
    beyond the field."""
    top = reach if math.isfinite(reach) else PINHOLE_SCAN_REACH
    shape = np.shape(target)
    target = np.ravel(target)
    reachable = target <= forward(np.full_like(target, top))
    out = np.full(target.shape, np.nan)
    active = np.nonzero(reachable)[0]
    goal = target[active]
    lo, hi = np.zeros_like(goal), np.full_like(goal, top)
    r = np.clip(goal, 0.0, top)
    for _ in range(BISECTIONS):
        f = forward(r) - goal
        hi = np.where(f > 0, r, hi)
        lo = np.where(f <= 0, r, lo)
        with np.errstate(invalid="ignore", divide="ignore"):
            step = r - f / slope(r)
        # (closed: at the root the step stays at r, which is one end of the bracket)
        new = np.where((step >= lo) & (step <= hi), step, 0.5 * (lo + hi))
        moving = np.abs(new - r) > 4 * np.finfo(np.float64).eps * np.abs(new)
        out[active[~moving]] = new[~moving]
        active, goal, lo, hi, r = active[moving], goal[moving], lo[moving], hi[moving], new[moving]
        if not len(active):
            break
    out[active] = r
    return out.reshape(shape)


def undistort_pinhole(coefficients, xd, yd):
    """(x, y, valid): the undistorted normalized coordinates whose projection is (xd, yd), float64,
    per element; valid False where the lens cannot reach (xd, yd) within its field (before its fold)
    or Newton does not land on it."""
    fold = pinhole_fold(coefficients)
    rd = np.hypot(xd, yd)

    def forward(r):
        factor, _, _ = radial_pinhole(coefficients, r * r)
        return r * factor

    def slope(r):
        factor, d_factor, _ = radial_pinhole(coefficients, r * r)
        return factor + 2 * r * r * d_factor

    # the radial term alone first (monotonic up to the fold: one solution), then the full model's Newton
    r = _radial_inverse(forward, slope, rd, fold)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(rd > 0, r / np.where(rd > 0, rd, 1.0), 1.0)
    x, y = xd * scale, yd * scale
    x, y = np.nan_to_num(x), np.nan_to_num(y)
    tangential = coefficients[2] != 0 or coefficients[3] != 0
    for _ in range(NEWTON_STEPS if tangential else 1):  # (radial alone: solved already, one step checks)
        fx, fy = distort_pinhole(coefficients, x, y)
        dxx, dxy, dyx, dyy = _pinhole_jacobian(coefficients, x, y)
        det = dxx * dyy - dxy * dyx
        with np.errstate(invalid="ignore", divide="ignore"):
            step_x = (dyy * (fx - xd) - dxy * (fy - yd)) / det
            step_y = (dxx * (fy - yd) - dyx * (fx - xd)) / det
        x, y = x - np.nan_to_num(step_x), y - np.nan_to_num(step_y)
    fx, fy = distort_pinhole(coefficients, x, y)
    dxx, dxy, dyx, dyy = _pinhole_jacobian(coefficients, x, y)
    residual = np.hypot(fx - xd, fy - yd)
    valid = (np.isfinite(r) & (residual <= SOLVED * (1 + rd)) & (np.hypot(x, y) < fold)
             & (dxx * dyy - dxy * dyx > 0))
    return x, y, valid


def fisheye_theta_d(coefficients, theta):
    k1, k2, k3, k4 = coefficients
    t2 = theta * theta
    return theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))


def fisheye_fold(coefficients) -> float:
    """The angle off the axis where theta_d(theta) first stops growing; inf where it grows up to pi."""
    k1, k2, k3, k4 = coefficients

    def slope(theta):
        t2 = theta * theta
        return 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))

    return _first_fold(slope, np.linspace(0.0, math.pi, SCAN_SAMPLES)[1:])


def undistort_fisheye(coefficients, xd, yd, max_theta):
    """(unit directions (..., 3) in OpenCV's camera axes, valid): the directions whose fisheye
    projection is (xd, yd); valid False beyond max_theta (the field limit, the fold or pi)."""
    reach = min(max_theta, fisheye_fold(coefficients), math.pi)
    rd = np.hypot(xd, yd)
    k1, k2, k3, k4 = coefficients

    def slope(theta):
        t2 = theta * theta
        return 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))

    theta = _radial_inverse(lambda t: fisheye_theta_d(coefficients, t), slope, rd, reach)
    valid = np.isfinite(theta) & (theta <= reach)
    theta = np.nan_to_num(theta)
    sine = np.sin(theta)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.where(rd > 0, xd / np.where(rd > 0, rd, 1.0), 0.0)
        uy = np.where(rd > 0, yd / np.where(rd > 0, rd, 1.0), 0.0)
    return np.stack([sine * ux, sine * uy, np.cos(theta)], axis=-1), valid


def _pixel_coordinates(intrinsics, width: int, height: int):
    """(x_d, y_d): each pixel centre's K^-1 [i, j, 1] (OpenCV's convention), (height, width) float64."""
    fx, fy, cx, cy = intrinsics
    xd = (np.arange(width, dtype=np.float64) - cx) / fx
    yd = (np.arange(height, dtype=np.float64) - cy) / fy
    return np.broadcast_to(xd[None, :], (height, width)), np.broadcast_to(yd[:, None], (height, width))




@lru_cache(maxsize=TABLES_KEPT)
def pinhole_table(intrinsics: tuple, coefficients: tuple, width: int, height: int):
    """The RayTable of a perspective camera with OpenCV's distortion: each pixel's unit direction in
    the camera's space (u left, v up, w forward: OpenCV's x and y negated), float64, and whether
    the lens reaches the pixel (elsewhere the pinhole's ray, a miss)."""
    xd, yd = _pixel_coordinates(intrinsics, width, height)
    x, y, valid = undistort_pinhole(coefficients, xd, yd)
    x, y = np.where(valid, x, xd), np.where(valid, y, yd)
    d = np.stack([-x, -y, np.ones_like(x)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return RayTable(d, valid)


@lru_cache(maxsize=TABLES_KEPT)
def fisheye_table(intrinsics: tuple, coefficients: tuple, max_theta: float, width: int, height: int):
    """The RayTable of OpenCV's fisheye camera, as pinhole_table's (misses: the axis)."""
    xd, yd = _pixel_coordinates(intrinsics, width, height)
    d, valid = undistort_fisheye(coefficients, xd, yd, max_theta)
    d = np.where(valid[..., None], d, [0.0, 0.0, 1.0]) * [-1.0, -1.0, 1.0]
    return RayTable(d, valid)
