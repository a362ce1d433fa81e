"""Unit quaternions (w, x, y, z), batched over leading axes: the rotation part of the in-hand
manipulation tasks' goals. A quaternion and its negative are the same rotation here."""

from __future__ import annotations

import numpy as np


def multiply(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """The Hamilton product ``first * second`` (the rotation ``second`` then ``first``)."""
    w0, x0, y0, z0 = np.moveaxis(np.asarray(first, dtype=np.float64), -1, 0)
    w1, x1, y1, z1 = np.moveaxis(np.asarray(second, dtype=np.float64), -1, 0)
    return np.stack(
        [
            w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1,
            w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
            w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1,
            w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1,
        ],
        axis=-1,
    )


def conjugate(quaternion: np.ndarray) -> np.ndarray:
    """The inverse rotation of a unit quaternion."""
    return np.asarray(quaternion, dtype=np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def normalized(quaternion: np.ndarray) -> np.ndarray:
    """Scaled to unit length (the identity where the length is zero)."""
    quaternion = np.asarray(quaternion, dtype=np.float64)
    norm = np.linalg.norm(quaternion, axis=-1, keepdims=True)
    identity = np.zeros_like(quaternion)
    identity[..., 0] = 1.0
    return np.where(norm > 1e-12, quaternion / np.maximum(norm, 1e-12), identity)


def rotation_vector(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(..., 3) the rotation from ``start`` to ``end`` as axis times angle (radians, in
    [0, pi]), in ``start``'s frame: the tangent vector of the shortest way between them."""
    relative = multiply(conjugate(normalized(start)), normalized(end))
    relative = np.where(relative[..., :1] < 0.0, -relative, relative)  # the shorter way round
    sine = np.linalg.norm(relative[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(sine, relative[..., :1])
    with np.errstate(divide="ignore", invalid="ignore"):
        per_sine = np.where(sine > 1e-12, angle / sine, 2.0)
    return relative[..., 1:] * per_sine


def angle_between(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """The angle (radians, in [0, pi]) of the rotation taking ``first`` to ``second``."""
    return np.linalg.norm(rotation_vector(first, second), axis=-1)


def from_rotation_vector(vector: np.ndarray) -> np.ndarray:
    """The unit quaternion of a rotation given as axis times angle (radians)."""
    vector = np.asarray(vector, dtype=np.float64)
    angle = np.linalg.norm(vector, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        half_sine = np.where(angle > 1e-12, np.sin(angle / 2.0) / angle, 0.5)
    return np.concatenate([np.cos(angle / 2.0), vector * half_sine], axis=-1)


def random_rotations(rng: np.random.Generator, count: int, max_angle: float) -> np.ndarray:
    """(count, 4) rotations about uniformly random axes by angles uniform in [0, max_angle]."""
    axis = rng.standard_normal((count, 3))
    axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
    angle = rng.uniform(0.0, max_angle, size=(count, 1))
    return from_rotation_vector(axis * angle)


def rotation_placement(
    start: np.ndarray, subgoals: np.ndarray, goal: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where rotation sub-goals lie on the way from the start's rotation to the goal's.

    ``start`` and ``goal`` (B, 4), ``subgoals`` (B, K, 4). In the tangent space at the start
    (rotations as axis times angle from it), returns ``progress`` (B, K), the projection of
    each sub-goal onto the start-to-goal rotation as a fraction of it (0 start, 1 goal), and
    ``off_line`` (B, K), its distance from that line in radians. NaN where the goal's rotation
    is the start's.
    """
    to_goal = rotation_vector(start, goal)  # (B, 3)
    to_subgoal = rotation_vector(start[:, None], subgoals)  # (B, K, 3)
    length_sq = np.sum(to_goal * to_goal, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        progress = np.einsum("bkg,bg->bk", to_subgoal, to_goal) / length_sq[:, None]
    off_line = np.linalg.norm(to_subgoal - progress[..., None] * to_goal[:, None], axis=-1)
    undefined = length_sq <= 1e-12
    progress[undefined] = np.nan
    off_line[undefined] = np.nan
    return progress, off_line
