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
"""
Map pixels of the distorted camera image to the undistorted pinhole image with the same K.

Straight 3D lines image as straight lines only in the undistorted image, so the solver takes
segments after :func:`undistort_segments`. The output image uses the camera's own intrinsics as
its projection (``P = K``): an undistorted pixel ``(u, v)`` is ``K @ (x, y, 1)`` for the
normalised ray ``(x, y, 1)`` in the camera optical frame (x right, y down, z forward).
"""
from typing import Optional, Tuple

import cv2
from mlofc_ros.camera import CameraModel
import numpy as np

#: Default iteration criteria: tighter than OpenCV's default (5 iterations), so the result
#: reprojects through ``cv2.projectPoints`` to well under 1e-3 px for usual lenses.
CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)

Criteria = Optional[Tuple[int, int, float]]


def _undistort_points_iter(src: np.ndarray, K: np.ndarray, d: np.ndarray,  # noqa: N803
                           criteria: Criteria) -> np.ndarray:
    """
    Run ``cv2.undistortPoints`` with termination criteria on any OpenCV the package supports.

    OpenCV 4.x (4.6 is Ubuntu 24.04's) has them in ``undistortPointsIter``; 5.x dropped that
    function for a ``criteria`` keyword of ``undistortPoints``.
    """
    if hasattr(cv2, 'undistortPointsIter'):
        return cv2.undistortPointsIter(src, K, d, None, K, criteria)
    return cv2.undistortPoints(src, K, d, R=None, P=K, criteria=criteria)


def undistort_points(points: np.ndarray, camera: CameraModel,
                     criteria: Criteria = CRITERIA) -> np.ndarray:
    """
    Undistort pixel points (N, 2) ``(u, v)`` of ``camera``; return (N, 2) float64 px.

    Output pixels are in the undistorted pinhole image with the same ``K``. Models:
    ``plumb_bob`` (5 coefficients) and ``rational_polynomial`` (8, or 5) via
    ``cv2.undistortPoints``; ``equidistant`` (4) via ``cv2.fisheye.undistortPoints``. No
    distortion returns the points unchanged (as float64). ``criteria`` is the cv2 termination
    criteria of the iterative inversion (``None``: OpenCV's default).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f'points must be (N, 2), got {pts.shape}')
    if not camera.has_distortion or pts.shape[0] == 0:
        return pts.copy()
    K = camera.K
    d = np.asarray(camera.d, dtype=np.float64)
    src = pts.reshape(-1, 1, 2)
    model = camera.distortion_model
    if model == 'equidistant':
        if criteria is None:
            out = cv2.fisheye.undistortPoints(src, K, d, R=np.eye(3), P=K)
        else:
            out = cv2.fisheye.undistortPoints(src, K, d, R=np.eye(3), P=K, criteria=criteria)
    elif model in ('plumb_bob', 'rational_polynomial'):
        if criteria is None:
            out = cv2.undistortPoints(src, K, d, R=None, P=K)
        else:
            out = _undistort_points_iter(src, K, d, criteria)
    else:   # CameraModel validates models; keep a clear message for duck-typed cameras
        raise ValueError(f'unsupported distortion model {model!r}')
    return out.reshape(-1, 2).astype(np.float64)


def undistort_segments(segments: np.ndarray, camera: CameraModel,
                       criteria: Criteria = CRITERIA) -> np.ndarray:
    """
    Undistort both endpoints of segments (M, 4) ``(u1, v1, u2, v2)`` px; return (M, 4) f64.

    See :func:`undistort_points` for the models and the output image (``P = K``). Identity
    (a float64 copy) when the camera has no distortion.
    """
    seg = np.asarray(segments, dtype=np.float64)
    if seg.ndim != 2 or seg.shape[1] != 4:
        raise ValueError(f'segments must be (M, 4), got {seg.shape}')
    return undistort_points(seg.reshape(-1, 2), camera, criteria).reshape(-1, 4)
