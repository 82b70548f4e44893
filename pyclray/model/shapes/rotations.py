"""Rotations by axis and angle, shared by the shapes placed so (a box's, a mesh's): the keys'
checks, the matrix (Rodrigues' formula) and its inverse."""
from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError, norm3, number, vector3


def axis_angle(axis, angle) -> tuple:
    """The keys axis (optional, non-zero) and angle (degrees, 0 without an axis), checked: a box's
    and a mesh's rotation."""
    if axis is not None:
        axis = vector3("axis", axis)
        if norm3(axis) == 0:
            raise SceneError("expected a non-zero rotation axis, got [0, 0, 0]", key="axis")
    angle = number("angle", angle)
    if axis is None and angle != 0:
        raise SceneError("expected an axis to rotate about (key 'axis') with a non-zero angle", key="angle")
    return axis, angle


def rotation(axis, angle_degrees) -> np.ndarray:
    """world_from_box (columns: the box's axes in world space), Rodrigues' formula in float64;
    the identity, exactly, without an axis or at angle 0."""
    if axis is None or angle_degrees == 0:
        return np.eye(3)
    k = np.asarray(axis, np.float64) / norm3(axis)
    theta = math.radians(angle_degrees)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) * math.cos(theta) + math.sin(theta) * cross + (1 - math.cos(theta)) * np.outer(k, k)


def rotation_axis_angle(R: np.ndarray):
    """(axis, degrees) of a rotation matrix (the inverse of rotation), via its quaternion (Shepperd's
    method: the largest of the four squared components is taken first, so no division is near
    zero); (None, 0) for none."""
    trace = np.trace(R)
    squares = [trace, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(squares))
    if k == 0:
        w = math.sqrt(1 + trace) / 2
        x, y, z = (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        q = np.zeros(3)
        q[i] = math.sqrt(max(0.0, 1 + R[i, i] - R[j, j] - R[m, m])) / 2
        q[j] = (R[j, i] + R[i, j]) / (4 * q[i])
        q[m] = (R[m, i] + R[i, m]) / (4 * q[i])
        w = (R[m, j] - R[j, m]) / (4 * q[i])
        x, y, z = q
    vector = np.array([x, y, z]) * (1 if w >= 0 else -1)
    length = np.linalg.norm(vector)
    if length == 0:
        return None, 0.0
    return tuple(vector / length), math.degrees(2 * math.atan2(length, abs(w)))
