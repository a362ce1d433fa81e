"""Quaternion helpers, checked against Gymnasium-Robotics' own rotations and the Hand task's
distance."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium_robotics.utils import rotations as reference

from dtd.agents.rotations import (
    angle_between,
    from_rotation_vector,
    multiply,
    random_rotations,
    rotation_placement,
    rotation_vector,
)


def unit_quaternions(rng: np.random.Generator, count: int) -> np.ndarray:
    quaternions = rng.standard_normal((count, 4))
    return quaternions / np.linalg.norm(quaternions, axis=-1, keepdims=True)


def test_product_and_angle_agree_with_gymnasium_robotics():
    rng = np.random.default_rng(0)
    first, second = unit_quaternions(rng, 50), unit_quaternions(rng, 50)
    assert np.allclose(multiply(first, second), reference.quat_mul(first, second))
    # The task's angle, 2 arccos(w) of the difference, counts q and -q apart; ours takes the
    # shorter way, so it is the task's where that is at most pi.
    difference = reference.quat_mul(first, reference.quat_conjugate(second))
    task_angle = 2 * np.arccos(np.clip(np.abs(difference[:, 0]), -1, 1))
    assert np.allclose(angle_between(second, first), task_angle, atol=1e-6)
    assert np.allclose(angle_between(first, -first), 0.0, atol=1e-6)


def test_rotation_vectors_round_trip_and_batch_over_leading_axes():
    rng = np.random.default_rng(1)
    start, end = unit_quaternions(rng, 12).reshape(3, 4, 4), unit_quaternions(rng, 12).reshape(3, 4, 4)
    vector = rotation_vector(start, end)
    assert vector.shape == (3, 4, 3) and np.all(np.linalg.norm(vector, axis=-1) <= np.pi + 1e-9)
    rebuilt = multiply(start, from_rotation_vector(vector))
    assert np.allclose(np.abs(np.sum(rebuilt * end, axis=-1)), 1.0)  # the same rotation, up to sign
    assert np.allclose(rotation_vector(start, start), 0.0)


@pytest.mark.parametrize("max_angle", [0.1, 1.0, np.pi])
def test_random_rotations_are_unit_and_bounded_in_angle(max_angle):
    turns = random_rotations(np.random.default_rng(2), 5000, max_angle)
    angles = angle_between(np.array([1.0, 0, 0, 0]), turns)
    assert np.allclose(np.linalg.norm(turns, axis=-1), 1.0)
    assert angles.max() <= max_angle + 1e-9 and angles.max() > 0.95 * max_angle
    assert abs(angles.mean() - max_angle / 2) < 0.05 * max_angle


def test_rotation_placement_is_progress_along_the_start_to_goal_turn():
    start = np.array([[1.0, 0, 0, 0]])
    goal = from_rotation_vector(np.array([[0, 0, 1.2]]))
    halfway = from_rotation_vector(np.array([0, 0, 0.6]))
    aside = from_rotation_vector(np.array([0.3, 0, 0.6]))
    progress, off_line = rotation_placement(start, np.stack([[halfway, aside, goal[0]]]), goal)
    assert np.allclose(progress, [[0.5, 0.5, 1.0]])
    assert np.allclose(off_line, [[0.0, 0.3, 0.0]])
    progress, off_line = rotation_placement(start, start[:, None], start)
    assert np.isnan(progress).all() and np.isnan(off_line).all()
