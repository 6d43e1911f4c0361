"""A known warp made by projecting a 3-D motion (:func:`myoface.analysis.knownwarp.
projected_warp`): each point moves as a pinhole camera sees its vertex move, depth included."""

import numpy as np
import pytest

from myoface.analysis.camera import HeadPose, PinholeCamera
from myoface.analysis.knownwarp import projected_warp
from myoface.errors import MyofaceValueError


@pytest.fixture
def scene():
    cam = PinholeCamera.for_image(640, 360, 40.0)
    pose = HeadPose.from_euler(2.0, 3.0, 1.0, (-20.0, -15.0, -430.0))
    rng = np.random.default_rng(3)
    shape0 = rng.uniform(-40, 40, (30, 3)) * np.array([1.0, 1.2, 0.4])
    pts = cam.project(pose.apply(shape0))
    return cam, pose, shape0, pts


def test_points_move_as_their_projection(scene):
    cam, pose, s0, pts = scene
    s1 = s0.copy()
    s1[:5] += [1.5, 2.0, -3.5]  # up, out and back
    w = projected_warp(pts, s0, s1, cam, pose)
    np.testing.assert_allclose(w.moved(pts), cam.project(pose.apply(s1)), atol=1e-6)
    np.testing.assert_allclose(w.moved(pts[5:]), pts[5:], atol=1e-9)


def test_depth_alone_moves_an_off_axis_point(scene):
    """A flat field (x, y only) would not move a point that only moves back; a camera does,
    toward the image's centre, more the farther off axis the point is."""
    cam, _, s0, _ = scene
    pose = HeadPose.from_euler(0.0, 0.0, 0.0, (-20.0, -15.0, -430.0))  # facing the camera
    pts = cam.project(pose.apply(s0))
    s1 = s0.copy()
    s1[:, 2] -= 4.0
    d = projected_warp(pts, s0, s1, cam, pose).shifts
    off = pts - [cam.cx, cam.cy]
    inward = -(d * off).sum(1) / np.linalg.norm(off, axis=1)
    assert (inward > 0).all()
    far = np.linalg.norm(off, axis=1) > np.median(np.linalg.norm(off, axis=1))
    assert np.linalg.norm(d[far], axis=1).mean() > np.linalg.norm(d[~far], axis=1).mean()


def test_sizes_checked(scene):
    cam, pose, s0, pts = scene
    with pytest.raises(MyofaceValueError):
        projected_warp(pts[:-1], s0, s0, cam, pose)
