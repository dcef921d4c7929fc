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
"""Segment cloud packing (also via real sensor_msgs serialization), image fields, debug view."""
from mlofc_ros.image import image_to_gray
from mlofc_ros.messages import (
    bgr8_fields,
    draw_debug,
    label_color,
    MAX_TEXT_SEGMENTS,
    pack_segments,
    POINTFIELD_NUMPY_TYPES,
    segment_cloud_fields,
    SEGMENT_DTYPE,
    SEGMENT_FIELDS,
    SEGMENT_POINT_STEP,
    unpack_segments,
)
import numpy as np
import pytest

RNG = np.random.default_rng(7)


def random_segments(m):
    segs = RNG.uniform(-10.0, 650.0, (m, 4)).astype(np.float32)
    ids = RNG.integers(0, 2 ** 32, m, dtype=np.uint64)
    labels = RNG.integers(-1, 6, m)
    residuals = RNG.uniform(0.0, 3.0, m).astype(np.float32)
    return segs, ids, labels, residuals


def test_layout_is_the_documented_one():
    # x y z first: what RViz and Foxglove take for a point's position
    assert [f[0] for f in SEGMENT_FIELDS] == ['x', 'y', 'z', 'x1', 'y1', 'x2', 'y2', 'track_id',
                                              'label', 'residual']
    assert [f[2] for f in SEGMENT_FIELDS] == [7, 7, 7, 7, 7, 7, 7, 6, 5, 7]
    assert [f[1] for f in SEGMENT_FIELDS[:3]] == [0, 4, 8]
    assert all(f[3] == 1 for f in SEGMENT_FIELDS)
    assert SEGMENT_POINT_STEP == SEGMENT_DTYPE.itemsize == 40
    for name, offset, code, _ in SEGMENT_FIELDS:
        dt, off = SEGMENT_DTYPE.fields[name]
        assert off == offset
        assert dt == np.dtype('<' + POINTFIELD_NUMPY_TYPES[code])
        assert dt.byteorder in '<|' or (dt.byteorder == '=' and np.little_endian)
    # fields are packed back to back, in order, with no gaps
    ends = [off + np.dtype(POINTFIELD_NUMPY_TYPES[c]).itemsize for _, off, c, _ in SEGMENT_FIELDS]
    assert [f[1] for f in SEGMENT_FIELDS[1:]] == ends[:-1] and ends[-1] == 40


def test_pack_unpack_round_trip():
    segs, ids, labels, residuals = random_segments(257)
    rays = RNG.normal(size=(257, 3)).astype(np.float32)
    data = pack_segments(segs, ids, labels, residuals, rays)
    assert isinstance(data, bytes) and len(data) == 257 * 40
    rec = unpack_segments(data)
    assert rec.dtype == SEGMENT_DTYPE and rec.shape == (257,)
    np.testing.assert_array_equal(np.stack([rec[k] for k in 'xyz'], 1), rays)
    np.testing.assert_array_equal(np.stack([rec[k] for k in ('x1', 'y1', 'x2', 'y2')], 1), segs)
    np.testing.assert_array_equal(rec['track_id'], ids)
    np.testing.assert_array_equal(rec['label'], labels)
    np.testing.assert_array_equal(rec['residual'], residuals)
    rec['label'][0] = 99   # writable copy
    assert unpack_segments(bytearray(data))['label'][0] == labels[0]


def test_layout_bytes_by_offset():
    data = pack_segments([[1.5, -2.0, 3.25, 4.0]], [0xDEADBEEF], [-1], [0.125],
                         [[0.25, -0.5, 1.0]])
    assert np.frombuffer(data, '<f4', 3, 0).tolist() == [0.25, -0.5, 1.0]
    assert np.frombuffer(data, '<f4', 4, 12).tolist() == [1.5, -2.0, 3.25, 4.0]
    assert data[28:32] == bytes.fromhex('efbeadde')          # little-endian uint32
    assert np.frombuffer(data, '<i4', 1, 32)[0] == -1
    assert np.frombuffer(data, '<f4', 1, 36)[0] == 0.125
    # no rays given: NaN (a point a viewer leaves out)
    assert np.all(np.isnan(np.frombuffer(pack_segments([[1, 2, 3, 4]], [0], [0], [0]),
                                         '<f4', 3, 0)))


def test_empty_and_float_labels():
    assert pack_segments(np.zeros((0, 4)), [], [], []) == b''
    assert unpack_segments(b'').shape == (0,)
    rec = unpack_segments(pack_segments(np.ones((2, 4)), np.array([1.0, 2.0]),
                                        np.array([-1.0, 3.0]), [np.nan, 1.0]))
    assert rec['label'].tolist() == [-1, 3] and np.isnan(rec['residual'][0])


@pytest.mark.parametrize('args,match', [
    ((np.zeros((3, 3)), [0] * 3, [0] * 3, [0] * 3), 'shape \\(M, 4\\)'),
    ((np.zeros(4), [0], [0], [0]), 'shape \\(M, 4\\)'),
    ((np.zeros((3, 4)), [0] * 2, [0] * 3, [0] * 3), 'track_ids must have shape'),
    ((np.zeros((3, 4)), [0] * 3, [0] * 4, [0] * 3), 'labels must have shape'),
    ((np.zeros((3, 4)), [0] * 3, [0] * 3, [0] * 2), 'residuals must have shape'),
    ((np.zeros((1, 4)), [-1], [0], [0]), 'track_ids must lie'),
    ((np.zeros((1, 4)), [2 ** 32], [0], [0]), 'track_ids must lie'),
    ((np.zeros((1, 4)), [0], [-2], [0]), 'labels must lie'),
    ((np.zeros((1, 4)), [0], [0.5], [0]), 'labels must hold integers'),
    ((np.full((1, 4), np.nan), [0], [0], [0]), 'finite'),
    ((np.array([['a'] * 4]), [0], [0], [0]), 'numeric'),
    ((np.zeros((2, 4)), [0] * 2, [0] * 2, [0] * 2, np.zeros((2, 2))), 'rays must have shape'),
    ((np.zeros((1, 4)), [0], [0], [0], [['a'] * 3]), 'rays must be numeric'),
])
def test_pack_rejects_bad_input(args, match):
    with pytest.raises(ValueError, match=match):
        pack_segments(*args)


def test_unpack_rejects_partial_points():
    with pytest.raises(ValueError, match='multiple of point_step'):
        unpack_segments(bytes(41))


def test_segment_cloud_fields():
    rays = np.ones((5, 3))
    f = segment_cloud_fields(*random_segments(5), rays)
    assert (f['height'], f['width'], f['point_step'], f['row_step']) == (1, 5, 40, 200)
    assert f['is_dense'] is True and f['is_bigendian'] is False and len(f['data']) == 200
    assert f['fields'] == SEGMENT_FIELDS
    # a ray not known (NaN) makes the cloud not dense, as it is without rays
    rays[2] = np.nan
    assert segment_cloud_fields(*random_segments(5), rays)['is_dense'] is False
    assert segment_cloud_fields(*random_segments(5))['is_dense'] is False


@pytest.mark.ros
def test_real_pointcloud2_serialization_round_trip():
    serialization = pytest.importorskip('rclpy.serialization')
    msgs = pytest.importorskip('sensor_msgs.msg')
    segs, ids, labels, residuals = random_segments(40)
    f = segment_cloud_fields(segs, ids, labels, residuals)
    fields = [msgs.PointField(name=n, offset=o, datatype=d, count=c) for n, o, d, c in f['fields']]
    assert [p.datatype for p in fields[6:9]] == [
        msgs.PointField.FLOAT32, msgs.PointField.UINT32, msgs.PointField.INT32]
    cloud = msgs.PointCloud2(height=f['height'], width=f['width'], fields=fields,
                             is_bigendian=f['is_bigendian'], point_step=f['point_step'],
                             row_step=f['row_step'], data=f['data'], is_dense=f['is_dense'])
    cloud.header.frame_id = 'camera_optical'
    wire = serialization.serialize_message(cloud)
    back = serialization.deserialize_message(wire, msgs.PointCloud2)
    assert back.header.frame_id == 'camera_optical' and back.width == 40
    assert [(p.name, p.offset, p.datatype, p.count) for p in back.fields] == list(SEGMENT_FIELDS)
    rec = unpack_segments(back.data)   # array.array('B') from rclpy
    np.testing.assert_array_equal(rec['x2'], segs[:, 2])
    np.testing.assert_array_equal(rec['track_id'], ids)
    np.testing.assert_array_equal(rec['label'], labels)
    np.testing.assert_array_equal(rec['residual'], residuals)
    # the layout a generic consumer would build from the PointFields
    generic = np.dtype({'names': [p.name for p in back.fields],
                        'formats': ['<' + POINTFIELD_NUMPY_TYPES[p.datatype]
                                    for p in back.fields],
                        'offsets': [p.offset for p in back.fields],
                        'itemsize': back.point_step})
    np.testing.assert_array_equal(np.frombuffer(bytes(back.data), generic)['label'], labels)


@pytest.mark.ros
def test_real_image_serialization_round_trip():
    serialization = pytest.importorskip('rclpy.serialization')
    msgs = pytest.importorskip('sensor_msgs.msg')
    bgr = RNG.integers(0, 256, (12, 17, 3), dtype=np.uint8)
    msg = msgs.Image(**bgr8_fields(bgr))
    back = serialization.deserialize_message(serialization.serialize_message(msg), msgs.Image)
    assert (back.height, back.width, back.encoding, back.step) == (12, 17, 'bgr8', 51)
    np.testing.assert_array_equal(np.frombuffer(bytes(back.data), np.uint8).reshape(12, 17, 3),
                                  bgr)


def test_bgr8_fields():
    bgr = RNG.integers(0, 256, (5, 6, 3), dtype=np.uint8)
    f = bgr8_fields(bgr)
    assert f == {'height': 5, 'width': 6, 'encoding': 'bgr8', 'step': 18, 'is_bigendian': 0,
                 'data': bgr.tobytes()}
    assert image_to_gray(**f).shape == (5, 6)
    for bad in [bgr[:, :, 0], bgr.astype(np.float32), np.zeros((0, 3, 3), np.uint8)]:
        with pytest.raises(ValueError, match='bgr8 image'):
            bgr8_fields(bad)


@pytest.mark.parametrize('m', [0, 1, 50, MAX_TEXT_SEGMENTS + 1])
def test_draw_debug_shape(m):
    gray = RNG.integers(0, 256, (120, 160), dtype=np.uint8)
    before = gray.copy()
    segs, ids, labels, _ = random_segments(m)
    if m:
        segs[0] = np.nan                   # skipped, no warning or error
    omega = RNG.normal(0, 0.5, (3, 3))
    out = draw_debug(gray, segs, labels, ids, omega, np.array([True, False, True]))
    assert out.shape == (120, 160, 3) and out.dtype == np.uint8
    out2 = draw_debug(gray, segs, labels, ids, omega)
    assert out2.shape == (120, 160, 3)
    np.testing.assert_array_equal(gray, before)   # drawn on a copy


def test_draw_debug_colours_by_label():
    gray = np.zeros((60, 80), np.uint8)
    for label in [-1, 0, 1, 2]:
        out = draw_debug(gray, [[10.0, 40.0, 70.0, 40.0]], [label], [3], np.zeros((0, 3)))
        column = out[35:46, 20].astype(int)          # across the line, away from the id text
        brightest = column[column.sum(axis=1).argmax()]
        colour = np.array(label_color(label))
        alpha = brightest.max() / colour.max()       # anti-aliasing over black dims the line
        assert alpha > 0.8 and np.abs(brightest - alpha * colour).max() <= 3, (label, brightest)
    assert len({label_color(k) for k in range(-1, 12)}) == 13


def test_draw_debug_rejects_bad_shapes():
    gray = np.zeros((10, 10), np.uint8)
    with pytest.raises(ValueError, match='segments'):
        draw_debug(gray, np.zeros((2, 3)), [0, 0], [0, 0], np.zeros((1, 3)))
    with pytest.raises(ValueError, match='labels'):
        draw_debug(gray, np.zeros((2, 4)), [0], [0, 0], np.zeros((1, 3)))
    with pytest.raises(ValueError, match='angular_velocities'):
        draw_debug(gray, np.zeros((2, 4)), [0, 0], [0, 0], np.zeros((1, 2)))
    with pytest.raises(ValueError, match='valid'):
        draw_debug(gray, np.zeros((2, 4)), [0, 0], [0, 0], np.zeros((1, 3)), [True, False])
    with pytest.raises(ValueError, match='gray'):
        draw_debug(gray.astype(np.float32), np.zeros((2, 4)), [0, 0], [0, 0], np.zeros((1, 3)))
