# Copyright 2026 The mlofc_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.
"""undistort_points / undistort_segments against OpenCV for every distortion model."""
import cv2
from mlofc_ros.camera import CameraModel
from mlofc_ros.tracks.undistort import undistort_points, undistort_segments
import numpy as np
import pytest

CAMERAS = [
    CameraModel(520.0, 515.0, 322.0, 241.0, (-0.28, 0.09, 0.001, -0.0005, -0.01), 'plumb_bob'),
    CameraModel(520.0, 515.0, 322.0, 241.0,
                (-0.3, 0.1, 0.001, -0.001, 0.01, 0.05, 0.01, 0.02), 'rational_polynomial'),
    CameraModel(520.0, 515.0, 322.0, 241.0, (-0.3, 0.1, 0.001, -0.001, 0.01),
                'rational_polynomial'),
]
FISHEYE = CameraModel(300.0, 300.0, 320.0, 240.0, (-0.02, 0.005, -0.001, 0.0002),
                      'equidistant')


def _points(n=200, seed=0):
    return np.random.default_rng(seed).uniform([5, 5], [635, 475], (n, 2))


@pytest.mark.parametrize('cam', CAMERAS, ids=['plumb_bob', 'rational8', 'rational5'])
def test_matches_cv2_undistort_points(cam):
    pts = _points()
    ref = cv2.undistortPoints(pts.reshape(-1, 1, 2), cam.K, np.asarray(cam.d),
                              P=cam.K).reshape(-1, 2)
    np.testing.assert_allclose(undistort_points(pts, cam, criteria=None), ref, atol=1e-9)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)
    if hasattr(cv2, 'undistortPointsIter'):      # OpenCV 4 (Ubuntu 24.04: 4.6)
        ref = cv2.undistortPointsIter(pts.reshape(-1, 1, 2), cam.K, np.asarray(cam.d), None,
                                      cam.K, crit).reshape(-1, 2)
    else:                                           # OpenCV 5: a keyword of undistortPoints
        ref = cv2.undistortPoints(pts.reshape(-1, 1, 2), cam.K, np.asarray(cam.d), P=cam.K,
                                  criteria=crit).reshape(-1, 2)
    und = undistort_points(pts, cam)
    np.testing.assert_allclose(und, ref, atol=1e-9)
    # and it is the inverse of the projection
    rays = np.c_[(und - [cam.cx, cam.cy]) / [cam.fx, cam.fy], np.ones(len(und))]
    back = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), cam.K,
                             np.asarray(cam.d))[0].reshape(-1, 2)
    np.testing.assert_allclose(back, pts, atol=1e-6)


def test_equidistant_matches_cv2_fisheye():
    pts = _points()
    cam = FISHEYE
    d = np.asarray(cam.d)
    ref = cv2.fisheye.undistortPoints(pts.reshape(-1, 1, 2), cam.K, d, R=np.eye(3),
                                      P=cam.K).reshape(-1, 2)
    np.testing.assert_allclose(undistort_points(pts, cam, criteria=None), ref, atol=1e-9)
    und = undistort_points(pts, cam)
    rays = np.c_[(und - [cam.cx, cam.cy]) / [cam.fx, cam.fy], np.ones(len(und))]
    back = cv2.fisheye.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K,
                                     d)[0].reshape(-1, 2)
    np.testing.assert_allclose(back, pts, atol=1e-6)


def test_segments_are_endpoint_pairs():
    cam = CAMERAS[0]
    seg = _points(60).reshape(-1, 4)
    out = undistort_segments(seg, cam)
    assert out.shape == seg.shape and out.dtype == np.float64
    np.testing.assert_allclose(out.reshape(-1, 2), undistort_points(seg.reshape(-1, 2), cam))
    assert undistort_segments(np.zeros((0, 4)), cam).shape == (0, 4)


def test_straightens_lines():
    # project a straight 3D line through the lens, undistort: collinear again
    cam = CAMERAS[0]
    t = np.linspace(0, 1, 20)[:, None]
    xyz = np.array([-0.5, -0.3, 1.0]) + t * np.array([1.0, 0.5, 0.2])
    dist = cv2.projectPoints(xyz, np.zeros(3), np.zeros(3), cam.K,
                             np.asarray(cam.d))[0].reshape(-1, 2)
    und = undistort_points(dist, cam)
    c = und - und.mean(0)
    s = np.linalg.svd(c, compute_uv=False)
    assert s[1] / s[0] < 1e-6
    c = dist - dist.mean(0)
    s = np.linalg.svd(c, compute_uv=False)
    assert s[1] / s[0] > 1e-3                       # (it was curved before)


def test_identity_without_distortion():
    pts = _points(10)
    for cam in (CameraModel(500, 500, 320, 240), CameraModel(500, 500, 320, 240, (0.0,) * 5)):
        out = undistort_points(pts, cam)
        np.testing.assert_array_equal(out, pts)
        assert out is not pts
        seg = pts.reshape(-1, 4).astype(np.float32)
        np.testing.assert_array_equal(undistort_segments(seg, cam), seg.astype(np.float64))


def test_bad_shapes_raise():
    cam = CAMERAS[0]
    with pytest.raises(ValueError):
        undistort_points(np.zeros((3, 3)), cam)
    with pytest.raises(ValueError):
        undistort_segments(np.zeros((3, 2)), cam)
