"""The rigid map of a liver into the population's frame (liverreg.rigid): a known turn, mirror
and shift of a lopsided point cloud is found back exactly; a declared frame is its axis map;
Kabsch's solution is the least-squares rotation."""

import math

import numpy as np
import pytest

from liverreg.rigid import FRAMES, RigidFit, kabsch, orient


def lopsided(n: int = 900, seed: int = 0) -> np.ndarray:
    """Points on an ellipsoid (60 x 40 x 25 mm) with a bump in one octant: no symmetry, so
    one orthogonal map lays it onto itself and no other."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    bump = 1.0 + 0.5 * np.exp(-8.0 * np.sum((u - [0.6, 0.6, 0.5]) ** 2, axis=1))
    return u * bump[:, None] * [60.0, 40.0, 25.0]


def turn(axis, degrees) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = math.radians(degrees)
    return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K


def test_kabsch_is_the_least_squares_rotation():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(50, 3))
    R0, t0 = turn([1, 2, 3], 70.0), np.array([5.0, -2.0, 1.0])
    R, t = kabsch(A, A @ R0.T + t0)
    np.testing.assert_allclose(R, R0, atol=1e-12)
    np.testing.assert_allclose(t, t0, atol=1e-12)
    # a mirror image is never returned: the best proper rotation instead
    R, _ = kabsch(A, A * [-1.0, 1.0, 1.0])
    assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("mirror", [False, True])
def test_a_turned_mirrored_shifted_liver_is_mapped_back_exactly(mirror):
    Y = lopsided()
    # the liver's frame: the population's turned by 140 degrees (and mirrored), shifted
    Q_true = turn([0.3, -1.0, 0.5], 140.0) @ (np.diag([-1.0, 1.0, 1.0]) if mirror else np.eye(3))
    t_true = np.array([120.0, -35.0, 80.0])
    X = (Y - t_true) @ Q_true  # so that Y = X Q_true^T + t_true
    fit = orient(X[::-1], Y)   # any order of the points
    assert fit.mirrored == mirror
    np.testing.assert_allclose(fit.Q, Q_true, atol=1e-6)
    np.testing.assert_allclose(fit.t, t_true, atol=1e-4)
    assert fit.distance < 1e-6
    assert fit.candidates == 3 + 48


def test_a_liver_in_the_population_frame_stays_and_declared_frames_are_their_axis_maps():
    Y = lopsided()
    fit = orient(Y + [3.0, 0.0, 0.0], Y)
    np.testing.assert_allclose(fit.Q, np.eye(3), atol=1e-6)
    assert fit.describe() == "the population frame turned by 0 degrees"
    # an LPS liver (x toward the patient's left): x flipped, the centroids matched, no fit
    X = Y * [-1.0, 1.0, 1.0] + [50.0, 60.0, 70.0]
    fit = orient(X, Y, frame="LPS")
    np.testing.assert_array_equal(fit.Q, FRAMES["LPS"])
    np.testing.assert_allclose(X @ fit.Q.T + fit.t, Y, atol=1e-9)
    assert fit.candidates == 1 and fit.mirrored
    with pytest.raises(ValueError, match="frame: expected 'auto' or one of population, LPS"):
        orient(X, Y, frame="XYZ")


def test_the_nearest_frame_and_its_angle():
    fit = RigidFit(Q=turn([0, 0, 1], 30.0) @ FRAMES["RAS"], t=np.zeros(3), distance=0.0,
                   candidates=1)
    name, deg = fit.nearest_frame()
    assert name == "RAS" and deg == pytest.approx(30.0)
