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
Field layout and packing of the node's ``~/segments`` ``sensor_msgs/PointCloud2`` (no ROS).

One point per line segment, ``height = 1``, little-endian, ``point_step = 40``::

    offset  name      type     unit / meaning
    0       x         FLOAT32  viewing ray through the segment's midpoint at unit depth
    4       y         FLOAT32    (camera optical frame: x right, y down, z forward; undistorted;
    8       z         FLOAT32    z = 1), NaN when the focal length is not known yet
    12      x1        FLOAT32  first endpoint u (px)
    16      y1        FLOAT32  first endpoint v (px)
    20      x2        FLOAT32  second endpoint u (px)
    24      y2        FLOAT32  second endpoint v (px)
    28      track_id  UINT32   id of the line track the segment belongs to
    32      label     INT32    body index, -1 = unassigned
    36      residual  FLOAT32  RMS residual of the track under its body (px-equivalent)

``x y z`` come first so that RViz and Foxglove draw the cloud as points (in the image's frame,
one unit in front of the camera) without being told which fields hold a position.

:data:`SEGMENT_FIELDS` is the single definition; :data:`SEGMENT_DTYPE` and everything else
derive from it. The node copies ``SEGMENT_FIELDS`` into ``sensor_msgs/PointField`` messages.
"""
from typing import Any, Dict, Tuple

from mlofc_ros.image.decode import as_byte_array
import numpy as np

#: ``sensor_msgs/PointField`` datatype codes.
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)

#: PointField datatype code -> numpy type (without byte order).
POINTFIELD_NUMPY_TYPES = {
    INT8: 'i1', UINT8: 'u1', INT16: 'i2', UINT16: 'u2',
    INT32: 'i4', UINT32: 'u4', FLOAT32: 'f4', FLOAT64: 'f8',
}

#: ``(name, offset in bytes, PointField datatype code, count)`` of every segment field.
SEGMENT_FIELDS: Tuple[Tuple[str, int, int, int], ...] = (
    ('x', 0, FLOAT32, 1),
    ('y', 4, FLOAT32, 1),
    ('z', 8, FLOAT32, 1),
    ('x1', 12, FLOAT32, 1),
    ('y1', 16, FLOAT32, 1),
    ('x2', 20, FLOAT32, 1),
    ('y2', 24, FLOAT32, 1),
    ('track_id', 28, UINT32, 1),
    ('label', 32, INT32, 1),
    ('residual', 36, FLOAT32, 1),
)

#: Bytes per point (``PointCloud2.point_step``).
SEGMENT_POINT_STEP = 40

#: Structured little-endian numpy dtype of one point, built from :data:`SEGMENT_FIELDS`.
SEGMENT_DTYPE = np.dtype({
    'names': [f[0] for f in SEGMENT_FIELDS],
    'formats': ['<' + POINTFIELD_NUMPY_TYPES[f[2]] for f in SEGMENT_FIELDS],
    'offsets': [f[1] for f in SEGMENT_FIELDS],
    'itemsize': SEGMENT_POINT_STEP,
})

_UINT32_MAX = 2 ** 32 - 1
_INT32_MAX = 2 ** 31 - 1


def _integer_column(values: Any, m: int, name: str, lo: int, hi: int) -> np.ndarray:
    """Validate an ``(M,)`` integer-valued column in ``[lo, hi]``; return it as int64."""
    arr = np.asarray(values)
    if arr.shape != (m,):
        raise ValueError('%s must have shape (%d,), got %s' % (name, m, arr.shape))
    if m == 0:
        return np.zeros(0, np.int64)
    if arr.dtype.kind in 'iub':
        ints = arr.astype(np.int64) if arr.dtype != np.uint64 or arr.max() <= hi else None
    elif arr.dtype.kind == 'f' and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
        ints = arr.astype(np.float64)
    else:
        raise ValueError('%s must hold integers, got dtype %s' % (name, arr.dtype))
    if ints is None or ints.min() < lo or ints.max() > hi:
        raise ValueError('%s must lie in [%d, %d], got range [%s, %s]'
                         % (name, lo, hi, arr.min(), arr.max()))
    return ints.astype(np.int64)


def pack_segments(segments: Any, track_ids: Any, labels: Any, residuals: Any,
                  rays: Any = None) -> bytes:
    """
    Pack segments into ``PointCloud2.data`` bytes laid out as :data:`SEGMENT_FIELDS`.

    Parameters
    ----------
    segments : (M, 4) float
        Endpoints ``(x1, y1, x2, y2)`` in pixels, finite.
    track_ids : (M,) int
        Track ids, ``0 <= id < 2**32``.
    labels : (M,) int
        Body index per segment, ``-1`` = unassigned (``-1 <= label < 2**31``).
    residuals : (M,) float
        Residual per segment (px-equivalent); NaN allowed for "not computed".
    rays : (M, 3) float or None
        ``x y z`` of every segment: its viewing ray at unit depth (see the module doc); NaN
        allowed (not known yet); None = all NaN.

    Returns
    -------
    bytes
        ``M * SEGMENT_POINT_STEP`` bytes (``b''`` for ``M = 0``).

    """
    seg = np.asarray(segments)
    if seg.ndim != 2 or seg.shape[1] != 4:
        raise ValueError('segments must have shape (M, 4), got %s' % (seg.shape,))
    if seg.dtype.kind not in 'iuf':
        raise ValueError('segments must be numeric, got dtype %s' % seg.dtype)
    m = seg.shape[0]
    seg = seg.astype(np.float64)
    if not np.all(np.isfinite(seg)):
        raise ValueError('segments must be finite (the segment cloud is dense)')
    ids = _integer_column(track_ids, m, 'track_ids', 0, _UINT32_MAX)
    lab = _integer_column(labels, m, 'labels', -1, _INT32_MAX)
    res = np.asarray(residuals)
    if res.shape != (m,):
        raise ValueError('residuals must have shape (%d,), got %s' % (m, res.shape))
    if m and res.dtype.kind not in 'iuf':
        raise ValueError('residuals must be numeric, got dtype %s' % res.dtype)
    xyz = np.full((m, 3), np.nan) if rays is None else np.asarray(rays)
    if xyz.shape != (m, 3):
        raise ValueError('rays must have shape (%d, 3), got %s' % (m, xyz.shape))
    if m and xyz.dtype.kind not in 'iuf':
        raise ValueError('rays must be numeric, got dtype %s' % xyz.dtype)
    out = np.empty(m, SEGMENT_DTYPE)
    for k, name in enumerate(('x', 'y', 'z')):
        out[name] = xyz[:, k]
    for k, name in enumerate(('x1', 'y1', 'x2', 'y2')):
        out[name] = seg[:, k]
    out['track_id'] = ids
    out['label'] = lab
    out['residual'] = res
    return out.tobytes()


def unpack_segments(data: Any) -> np.ndarray:
    """
    Unpack ``PointCloud2.data`` (bytes-like or list of byte values) into ``(M,)`` records.

    Returns a writable structured array of dtype :data:`SEGMENT_DTYPE` (fields ``x, y, z``
    (the ray), ``x1, y1, x2, y2`` px, ``track_id``, ``label``, ``residual``). Raises
    ``ValueError`` if the length is not a multiple of :data:`SEGMENT_POINT_STEP`.
    """
    buf = as_byte_array(data)
    if buf.size % SEGMENT_POINT_STEP:
        raise ValueError('segment cloud data has %d bytes, not a multiple of point_step %d'
                         % (buf.size, SEGMENT_POINT_STEP))
    return np.frombuffer(np.ascontiguousarray(buf).tobytes(), SEGMENT_DTYPE).copy()


def segment_cloud_fields(segments: Any, track_ids: Any, labels: Any,
                         residuals: Any, rays: Any = None) -> Dict[str, Any]:
    """
    Return every ``sensor_msgs/PointCloud2`` field but ``header`` for the given segments.

    ``fields`` is :data:`SEGMENT_FIELDS` (the caller turns the tuples into ``PointField``);
    ``height = 1``, ``width = M``, ``is_bigendian = False``, ``point_step = 40``,
    ``row_step = 40 * M``, ``data`` from :func:`pack_segments`, and ``is_dense`` True when
    every ray is finite (a point with NaN ``x y z`` is invalid to a point-cloud viewer).
    """
    data = pack_segments(segments, track_ids, labels, residuals, rays)
    m = len(data) // SEGMENT_POINT_STEP
    dense = rays is not None and bool(np.all(np.isfinite(np.asarray(rays, dtype=np.float64))))
    return {
        'height': 1,
        'width': m,
        'fields': SEGMENT_FIELDS,
        'is_bigendian': False,
        'point_step': SEGMENT_POINT_STEP,
        'row_step': SEGMENT_POINT_STEP * m,
        'data': data,
        'is_dense': dense or m == 0,
    }
