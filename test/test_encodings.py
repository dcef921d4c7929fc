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
"""Image decoding: every encoding from synthetic arrays, step padding, byte order, errors."""
import array
import time
import types

import cv2
from mlofc_ros.image import (
    gray_to_image_fields,
    image_msg_to_gray,
    image_to_gray,
    SUPPORTED_ENCODINGS,
    WRITABLE_ENCODINGS,
)
import numpy as np
import pytest

H, W = 24, 34
RNG = np.random.default_rng(1234)
GRAY = RNG.integers(0, 256, (H, W), dtype=np.uint8)
BGR = RNG.integers(0, 256, (H, W, 3), dtype=np.uint8)
ALL_NAMES = sorted(SUPPORTED_ENCODINGS)


def raw_fields(pixels, encoding, is_bigendian=False, pad=0):
    """
    Build Image fields by hand from ``(H, W)`` / ``(H, W, C)`` wire-layout pixels.

    Independent of the library: numpy byte order + explicit zero padding per row.
    """
    pixels = np.asarray(pixels)
    h, w = pixels.shape[:2]
    order = '>' if is_bigendian else '<'
    wire = pixels.astype(pixels.dtype.newbyteorder(order)) if pixels.itemsize > 1 else pixels
    rows = np.ascontiguousarray(wire).reshape(h, -1).view(np.uint8)
    rows = np.concatenate([rows, np.full((h, pad), 0xAB, np.uint8)], axis=1)  # junk padding
    return {'height': h, 'width': w, 'encoding': encoding, 'step': rows.shape[1],
            'is_bigendian': int(is_bigendian), 'data': rows.tobytes()}


def decode(fields, **kw):
    return image_to_gray(fields['height'], fields['width'], fields['encoding'], fields['step'],
                         fields['is_bigendian'], fields['data'], **kw)


def bgr2gray(bgr):
    return cv2.cvtColor(np.ascontiguousarray(bgr), cv2.COLOR_BGR2GRAY)


def test_table_covers_required_encodings():
    required = {'mono8', 'mono16', '8UC1', '16UC1', '32FC1', 'bgr8', 'rgb8', 'bgra8', 'rgba8',
                'bgr16', 'rgb16', 'bayer_rggb8', 'bayer_bggr8', 'bayer_gbrg8', 'bayer_grbg8',
                'uyvy', 'yuv422', 'yuyv', 'yuv422_yuy2'}
    assert required <= set(SUPPORTED_ENCODINGS)
    assert SUPPORTED_ENCODINGS['yuv422'] is SUPPORTED_ENCODINGS['uyvy']
    assert SUPPORTED_ENCODINGS['yuv422_yuy2'] is SUPPORTED_ENCODINGS['yuyv']


@pytest.mark.parametrize('pad', [0, 5])
@pytest.mark.parametrize('encoding', ['mono8', '8UC1'])
def test_mono8(encoding, pad):
    out = decode(raw_fields(GRAY, encoding, pad=pad))
    assert out.dtype == np.uint8 and out.flags.c_contiguous
    np.testing.assert_array_equal(out, GRAY)


@pytest.mark.parametrize('pad', [0, 3])  # odd padding -> unaligned 16-bit rows
@pytest.mark.parametrize('big', [False, True])
@pytest.mark.parametrize('encoding', ['mono16', '16UC1'])
def test_mono16_shifts_and_honours_byte_order(encoding, big, pad):
    raw = RNG.integers(0, 65536, (H, W), dtype=np.uint16)
    out = decode(raw_fields(raw, encoding, big, pad))
    np.testing.assert_array_equal(out, (raw >> 8).astype(np.uint8))
    # the same bytes read with the other byte order give a different image
    other = raw_fields(raw, encoding, big, pad)
    other['is_bigendian'] = int(not big)
    assert not np.array_equal(decode(other), out)


@pytest.mark.parametrize('pad', [0, 2])
@pytest.mark.parametrize('big', [False, True])
def test_32fc1_min_max_and_non_finite(big, pad):
    depth = RNG.uniform(0.5, 7.5, (H, W)).astype(np.float32)
    depth[0, 0], depth[-1, -1] = 0.5, 7.5
    depth[2, 3], depth[4, 5], depth[6, 7] = np.nan, np.inf, -np.inf
    out = decode(raw_fields(depth, '32FC1', big, pad))
    expected = np.rint((depth.astype(np.float64) - 0.5) * 255.0 / 7.0)
    finite = np.isfinite(depth)
    np.testing.assert_array_equal(out[finite], expected[finite].astype(np.uint8))
    assert out[2, 3] == out[4, 5] == out[6, 7] == 0
    assert out.min() == 0 and out.max() == 255


def test_32fc1_constant_and_extreme_ranges():
    const = np.full((3, 4), 2.0, np.float32)
    np.testing.assert_array_equal(decode(raw_fields(const, '32FC1')), 0)
    extreme = np.array([[-3.4e38, 3.4e38]], np.float32)   # max - min overflows float32
    np.testing.assert_array_equal(decode(raw_fields(extreme, '32FC1')), [[0, 255]])


@pytest.mark.parametrize('pad', [0, 7])
@pytest.mark.parametrize('encoding', ['bgr8', 'rgb8', 'bgra8', 'rgba8'])
def test_colour8(encoding, pad):
    wire = BGR[:, :, ::-1] if encoding.startswith('rgb') else BGR
    if encoding.endswith('a8'):
        wire = np.concatenate([wire, RNG.integers(0, 256, (H, W, 1), dtype=np.uint8)], axis=2)
    out = decode(raw_fields(wire, encoding, pad=pad))
    np.testing.assert_array_equal(out, bgr2gray(BGR))


@pytest.mark.parametrize('pad', [0, 1])
@pytest.mark.parametrize('big', [False, True])
@pytest.mark.parametrize('encoding', ['bgr16', 'rgb16'])
def test_colour16(encoding, big, pad):
    bgr16 = RNG.integers(0, 65536, (H, W, 3), dtype=np.uint16)
    wire = bgr16[:, :, ::-1] if encoding == 'rgb16' else bgr16
    out = decode(raw_fields(wire, encoding, big, pad))
    expected = cv2.cvtColor(bgr16, cv2.COLOR_BGR2GRAY) >> 8
    assert np.abs(out.astype(int) - expected).max() <= 1
    # and 8-bit content scaled by 257 comes back exactly like bgr8
    out8 = decode(raw_fields((wire.astype(np.uint32) // 257).astype(np.uint16) * 257,
                             encoding, big, pad))
    ref8 = bgr2gray((bgr16 // 257).astype(np.uint8))
    assert np.abs(out8.astype(int) - ref8).max() <= 1


def smooth_bgr(h, w):
    """Smooth colour image with very different R, G, B so a wrong Bayer pattern shows."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    b = 40 + 30 * np.sin(x / 9.0)
    g = 120 + 60 * np.sin(y / 11.0 + 1.0)
    r = 200 + 40 * np.cos((x + y) / 13.0)
    return np.stack([b, g, r], axis=2).clip(0, 255).astype(np.uint8)


def mosaic(bgr, pattern):
    """Sample ``bgr`` through a Bayer filter named the ROS way (2x2 cell from the top-left)."""
    channel = {'b': 0, 'g': 1, 'r': 2}
    out = np.zeros(bgr.shape[:2], np.uint8)
    for colour, (dy, dx) in zip(pattern, [(0, 0), (0, 1), (1, 0), (1, 1)]):
        out[dy::2, dx::2] = bgr[dy::2, dx::2, channel[colour]]
    return out


PATTERNS = ['rggb', 'bggr', 'gbrg', 'grbg']


@pytest.mark.parametrize('pad', [0, 4])
@pytest.mark.parametrize('pattern', PATTERNS)
def test_bayer_matches_colour_gray(pattern, pad):
    bgr = smooth_bgr(48, 64)
    ref = bgr2gray(bgr).astype(int)[4:-4, 4:-4]
    raw = mosaic(bgr, pattern)
    errors = {}
    for decoded_as in PATTERNS:
        out = decode(raw_fields(raw, 'bayer_%s8' % decoded_as, pad=pad))
        assert out.shape == (48, 64) and out.dtype == np.uint8
        errors[decoded_as] = np.abs(out.astype(int)[4:-4, 4:-4] - ref).max()
    assert errors[pattern] <= 3, errors
    # every other pattern is clearly wrong, so the table's mapping is the right one
    assert all(e > 20 for p, e in errors.items() if p != pattern), errors


@pytest.mark.parametrize('pad', [0, 6])
@pytest.mark.parametrize('encoding,y_first', [('uyvy', False), ('yuv422', False),
                                              ('yuyv', True), ('yuv422_yuy2', True)])
def test_yuv422_gives_luma(encoding, y_first, pad):
    chroma = RNG.integers(0, 256, (H, W), dtype=np.uint8)   # U, V alternate per pixel
    pair = [GRAY, chroma] if y_first else [chroma, GRAY]
    wire = np.stack(pair, axis=2)                           # (H, W, 2): 2 bytes per pixel
    out = decode(raw_fields(wire, encoding, pad=pad))
    np.testing.assert_array_equal(out, GRAY)


@pytest.mark.parametrize('encoding', WRITABLE_ENCODINGS)
@pytest.mark.parametrize('big', [False, True])
def test_gray_to_image_fields_round_trip(encoding, big):
    gray = GRAY.copy()
    gray[0, 0], gray[0, 1] = 0, 255          # so 32FC1's min-max stretch is the identity
    f = gray_to_image_fields(gray, encoding, is_bigendian=big, row_padding=3)
    assert f['encoding'] == encoding and (f['height'], f['width']) == (H, W)
    info = SUPPORTED_ENCODINGS[encoding]
    assert f['step'] == W * info.bytes_per_pixel + 3 and len(f['data']) == H * f['step']
    np.testing.assert_array_equal(decode(f), gray)
    expected = bgr2gray(BGR).astype(np.float64)   # BGR input is stored as its gray
    if encoding == '32FC1':
        expected = np.rint((expected - expected.min()) * 255 / np.ptp(expected))
    out = decode(gray_to_image_fields(BGR, encoding, is_bigendian=big))
    assert np.abs(out - expected).max() <= 1


def test_gray_to_image_fields_raw_high_depth():
    raw = RNG.integers(0, 65536, (H, W), dtype=np.uint16)
    f = gray_to_image_fields(raw, 'mono16', is_bigendian=True)
    assert f['data'] == raw.astype('>u2').tobytes()
    depth = RNG.uniform(0, 5, (H, W)).astype(np.float32)
    assert gray_to_image_fields(depth, '32FC1')['data'] == depth.astype('<f4').tobytes()
    with pytest.raises(ValueError, match='cannot write'):
        gray_to_image_fields(GRAY, 'bayer_rggb8')
    with pytest.raises(ValueError, match='uint8'):
        gray_to_image_fields(GRAY.astype(np.int32), 'mono8')


@pytest.mark.parametrize('kind', ['bytes', 'bytearray', 'array', 'list', 'ndarray', 'memview'])
def test_data_containers_and_msg(kind):
    f = raw_fields(GRAY, 'mono8', pad=2)
    data = {'bytes': f['data'], 'bytearray': bytearray(f['data']),
            'array': array.array('B', f['data']), 'list': list(f['data']),
            'ndarray': np.frombuffer(f['data'], np.uint8),
            'memview': memoryview(f['data'])}[kind]
    msg = types.SimpleNamespace(**dict(f, data=data))
    np.testing.assert_array_equal(image_msg_to_gray(msg), GRAY)


@pytest.mark.ros
def test_real_sensor_msgs_image():
    msg_mod = pytest.importorskip('sensor_msgs.msg')
    f = raw_fields(RNG.integers(0, 65536, (H, W), dtype=np.uint16), 'mono16', True, 2)
    msg = msg_mod.Image(**f)
    assert isinstance(msg.data, array.array)
    np.testing.assert_array_equal(image_msg_to_gray(msg), decode(f))


def check_error(match, *args, **kw):
    with pytest.raises(ValueError, match=match):
        image_to_gray(*args, **kw)


def test_unsupported_encoding_lists_supported():
    data = bytes(12)
    for bad in ['jpeg', 'MONO8', '', None, b'mono8', 'bayer_rggb16']:
        with pytest.raises(ValueError, match='unsupported image encoding') as err:
            image_to_gray(3, 4, bad, 4, 0, data)
        assert 'mono8' in str(err.value) and 'yuv422_yuy2' in str(err.value)


def test_wrong_length():
    check_error('expected height\\*step', 3, 4, 'mono8', 4, 0, bytes(11))
    check_error('expected height\\*step', 3, 4, 'mono8', 4, 0, bytes(13))
    check_error('expected height\\*step', 3, 4, 'bgr8', 12, 0, [0] * 35)


def test_short_step():
    check_error('step 3 is shorter', 3, 4, 'mono8', 3, 0, bytes(9))
    check_error('step 7 is shorter', 3, 4, 'mono16', 7, 0, bytes(21))
    check_error('step 11 is shorter', 3, 4, 'bgr8', 11, 0, bytes(33))
    check_error('step -4 is shorter', 3, 4, 'mono8', -4, 0, b'')


@pytest.mark.parametrize('h,w', [(0, 0), (0, 4), (4, 0), (-1, 4)])
def test_empty_or_negative_size(h, w):
    check_error('size must be positive', h, w, 'mono8', max(w, 0), 0, b'')


def test_non_integer_header_fields():
    check_error('height must be an integer', 2.0, 2, 'mono8', 2, 0, bytes(4))
    check_error('step must be an integer', 2, 2, 'mono8', '2', 0, bytes(4))
    check_error('bytes-like', 2, 2, 'mono8', 2, 0, 'abcd')
    check_error('bytes-like', 2, 2, 'mono8', 2, 0, 1234)
    check_error('0..255', 2, 2, 'mono8', 2, 0, [0, 1, 2, 256])
    check_error('0..255', 2, 2, 'mono8', 2, 0, [0, 1, 2, -1])
    check_error('uint8', 2, 2, 'mono8', 2, 0, np.zeros(4, np.float32))
    with pytest.raises(ValueError, match='not an image message'):
        image_msg_to_gray(object())


def test_huge_header_fails_fast_without_allocating():
    t0 = time.perf_counter()
    check_error('more than max_pixels', 20000, 20000, 'bgr8', 60000, 0, bytes(16),
                max_pixels=4096 * 4096)
    check_error('expected height\\*step', 20000, 20000, 'bgr8', 60000, 0, bytes(16))
    check_error('expected height\\*step', 20000, 20000, '32FC1', 80000, 0, [1] * 16)
    check_error('expected height\\*step', 10 ** 12, 10 ** 12, 'mono8', 10 ** 12, 0, b'')
    assert time.perf_counter() - t0 < 0.05


def test_max_pixels_boundary():
    assert image_to_gray(4, 4, 'mono8', 4, 0, bytes(16), max_pixels=16).shape == (4, 4)
    check_error('more than max_pixels', 4, 4, 'mono8', 4, 0, bytes(16), max_pixels=15)


def test_32fc1_without_finite_pixels():
    for fill in [np.nan, np.inf, -np.inf]:
        f = raw_fields(np.full((3, 5), fill, np.float32), '32FC1')
        with pytest.raises(ValueError, match='no finite pixels'):
            decode(f)


@pytest.mark.parametrize('encoding', ALL_NAMES)
def test_every_encoding_decodes_tiny_images(encoding):
    info = SUPPORTED_ENCODINGS[encoding]
    for h, w in [(1, 1), (1, 3), (3, 1), (2, 2), (5, 7)]:
        nbytes = h * w * info.bytes_per_pixel
        data = RNG.integers(0, 256, nbytes, dtype=np.uint8).tobytes()
        if info.kind == 'float':
            data = np.ones(h * w, np.float32).tobytes()
        out = image_to_gray(h, w, encoding, w * info.bytes_per_pixel, 0, data)
        assert out.shape == (h, w) and out.dtype == np.uint8 and out.flags.c_contiguous
