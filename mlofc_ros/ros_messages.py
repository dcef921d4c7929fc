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
Build and parse the ROS messages of mlofc_ros (needs the message packages, not rclpy).

- ``~/segments``: ``sensor_msgs/PointCloud2``, one point per line segment of the newest frame,
  with the layout of :data:`mlofc_ros.messages.segments.SEGMENT_FIELDS` (x, y, z the viewing
  ray through the segment's midpoint at unit depth, x1, y1, x2, y2 pixels as seen in the image,
  track_id, label (-1 unassigned), residual), little-endian, ``height = 1``.
- ``~/body_<i>/twist``: ``geometry_msgs/TwistWithCovarianceStamped``; ``angular`` is the body's
  angular velocity relative to the camera in rad/s, camera optical frame (x right, y down,
  z forward; ``header.frame_id`` is the image's frame). The rotation-only model does not measure
  translation: ``linear`` is 0 with variance :data:`LINEAR_UNKNOWN_VARIANCE` on its diagonal
  (robot_localization and friends read a huge variance as "ignore"). Angular covariance comes
  from the fit, converted to (rad/s)^2; undetermined entries are ``inf`` (the node does not publish
  a twist for an undetermined body, see :func:`twist_msg`).
- ``~/debug_image``: ``sensor_msgs/Image`` ``bgr8``.
- ``camera_info``: :func:`camera_model_from_info` turns ``sensor_msgs/CameraInfo`` into a
  :class:`~mlofc_ros.camera.CameraModel` of the image as published (binning and ROI applied).
"""
import math
from typing import Optional, Tuple

from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistWithCovarianceStamped
from mlofc_ros.camera import CameraModel
from mlofc_ros.messages.images import bgr8_fields
from mlofc_ros.messages.segments import (segment_cloud_fields, SEGMENT_FIELDS,
                                         SEGMENT_POINT_STEP, unpack_segments)
import numpy as np
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField
from std_msgs.msg import Header

#: Variance ((m/s)^2) on the diagonal of the linear part of every twist covariance: the
#: rotation-only model does not observe translation, so it is marked as unknown.
LINEAR_UNKNOWN_VARIANCE = 1.0e9

#: Bytes per point of ``~/segments``.
POINT_STEP = SEGMENT_POINT_STEP


def stamp_to_seconds(stamp: Time) -> float:
    """Return a ``builtin_interfaces/Time`` as float seconds."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def segment_fields() -> list:
    """``PointField`` list of ``~/segments`` (from ``SEGMENT_FIELDS``)."""
    return [PointField(name=name, offset=int(offset), datatype=int(datatype), count=int(count))
            for name, offset, datatype, count in SEGMENT_FIELDS]


def segments_msg(header: Header, segments: np.ndarray, track_ids: np.ndarray,
                 labels: np.ndarray, residuals: np.ndarray,
                 rays: Optional[np.ndarray] = None) -> PointCloud2:
    """
    Build the ``~/segments`` cloud: one point per segment, in the given order.

    Parameters
    ----------
    header : std_msgs/Header
        The input image's header (stamp and camera optical frame id).
    segments : (M, 4) float
        ``x1, y1, x2, y2`` endpoints in pixels, as seen in the (distorted) image.
    track_ids : (M,) uint32
        Persistent track id of every segment.
    labels : (M,) int
        Stable body id of every segment, -1 unassigned.
    residuals : (M,) float
        Residual of every segment under its body in pixels (NaN when not solved).
    rays : (M, 3) float or None
        ``x y z``: the viewing ray through every segment's midpoint at unit depth
        (:attr:`mlofc_ros.pipeline.FrameResult.rays`); None or NaN rows = not known.

    The cloud is ``is_dense`` when every ray is known (NaN residual = not solved).

    """
    f = segment_cloud_fields(segments, track_ids, labels, residuals, rays)
    msg = PointCloud2()
    msg.header = header
    msg.height = int(f['height'])
    msg.width = int(f['width'])
    msg.fields = segment_fields()
    msg.is_bigendian = bool(f['is_bigendian'])
    msg.point_step = int(f['point_step'])
    msg.row_step = int(f['row_step'])
    msg.data = bytes(f['data'])
    msg.is_dense = bool(f['is_dense'])
    return msg


def parse_segments_msg(msg: PointCloud2) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Parse a ``~/segments`` cloud into ``(segments (M,4), track_ids, labels, residuals)``.

    Raises ``ValueError`` when the field layout is not the one of ``SEGMENT_FIELDS``.
    :func:`parse_segment_rays` reads the ``x y z`` rays.
    """
    out = _unpack_segments_msg(msg)
    segs = np.stack([out[k] for k in ('x1', 'y1', 'x2', 'y2')], axis=-1)
    return segs, out['track_id'], out['label'], out['residual']


def parse_segment_rays(msg: PointCloud2) -> np.ndarray:
    """Return the ``(M, 3)`` float32 ``x y z`` rays of a ``~/segments`` cloud (NaN = unknown)."""
    out = _unpack_segments_msg(msg)
    return np.stack([out[k] for k in ('x', 'y', 'z')], axis=-1)


def _unpack_segments_msg(msg: PointCloud2) -> np.ndarray:
    got = [(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    want = [(n, int(o), int(d), int(c)) for n, o, d, c in SEGMENT_FIELDS]
    if got != want:
        raise ValueError(f'~/segments field layout {got} differs from SEGMENT_FIELDS {want}')
    if msg.is_bigendian:
        raise ValueError('~/segments cloud is big-endian; expected little-endian')
    if msg.point_step != POINT_STEP:
        raise ValueError(f'~/segments point_step is {msg.point_step}, expected {POINT_STEP}')
    return unpack_segments(msg.data)


def twist_msg(header: Header, angular_velocity: np.ndarray,
              angular_covariance: np.ndarray) -> TwistWithCovarianceStamped:
    """
    Build a body twist.

    Parameters
    ----------
    header : std_msgs/Header
        The input image's header; the twist is in its (camera optical) frame.
    angular_velocity : (3,) float
        Rotation vector rate of the body relative to the camera, rad/s, camera optical frame.
    angular_covariance : (3, 3) float
        Its covariance in (rad/s)^2. Non-finite entries mark it undetermined: the angular
        diagonal becomes ``inf`` and the off-diagonal terms 0; a non-finite angular velocity
        becomes 0 with an ``inf`` variance.

    The linear part is 0 with :data:`LINEAR_UNKNOWN_VARIANCE` on its diagonal.

    """
    w = np.asarray(angular_velocity, dtype=float).reshape(3)
    c = np.asarray(angular_covariance, dtype=float).reshape(3, 3)
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(w))):
        bad = ~np.isfinite(w) | ~np.isfinite(np.diag(c))
        c = np.diag(np.where(bad, math.inf, np.nan_to_num(np.diag(c))))
        w = np.where(np.isfinite(w), w, 0.0)
    cov = np.zeros((6, 6))
    cov[:3, :3] = np.eye(3) * LINEAR_UNKNOWN_VARIANCE
    cov[3:, 3:] = c
    msg = TwistWithCovarianceStamped()
    msg.header = header
    msg.twist.twist.angular.x = float(w[0])
    msg.twist.twist.angular.y = float(w[1])
    msg.twist.twist.angular.z = float(w[2])
    msg.twist.covariance = [float(x) for x in cov.ravel()]
    return msg


def parse_twist_msg(msg: TwistWithCovarianceStamped) -> Tuple[np.ndarray, np.ndarray]:
    """Return ``(angular (3,) rad/s, angular covariance (3, 3) (rad/s)^2)`` of a body twist."""
    a = msg.twist.twist.angular
    cov = np.asarray(msg.twist.covariance, dtype=float).reshape(6, 6)
    return np.array([a.x, a.y, a.z]), cov[3:, 3:].copy()


def debug_image_msg(header: Header, bgr: np.ndarray) -> Image:
    """Build a ``bgr8`` ``sensor_msgs/Image`` from an ``(H, W, 3) uint8`` BGR array."""
    fields = bgr8_fields(bgr)
    msg = Image()
    msg.header = header
    for key, value in fields.items():
        setattr(msg, key, value)
    return msg


def camera_model_from_info(msg: CameraInfo) -> CameraModel:
    """
    Return the :class:`CameraModel` of the images that go with ``msg``.

    ``k``, ``d`` and ``distortion_model`` come from the message; binning and a region of interest
    (REP 104) are folded into the intrinsics so the model applies to the published image pixels.
    Raises ``ValueError`` naming the problem (all-zero or non-finite K, wrong D length, unknown
    distortion model).
    """
    cam = CameraModel.from_camera_info(list(msg.k), list(msg.d), msg.distortion_model)
    bx = int(msg.binning_x) or 1
    by = int(msg.binning_y) or 1
    roi = msg.roi
    ox, oy = int(roi.x_offset), int(roi.y_offset)
    if bx == 1 and by == 1 and ox == 0 and oy == 0:
        return cam
    return CameraModel((cam.fx) / bx, (cam.fy) / by, (cam.cx - ox) / bx, (cam.cy - oy) / by,
                       cam.d, cam.distortion_model)


def camera_info_size(msg: CameraInfo) -> Optional[Tuple[int, int]]:
    """Image size ``(width, height)`` the calibration expects (binning/ROI applied), or None."""
    w, h = int(msg.width), int(msg.height)
    if msg.roi.width and msg.roi.height:
        w, h = int(msg.roi.width), int(msg.roi.height)
    if not (w and h):
        return None
    return w // (int(msg.binning_x) or 1), h // (int(msg.binning_y) or 1)
