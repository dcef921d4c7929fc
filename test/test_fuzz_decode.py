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
"""Fuzz image_to_gray: any header and payload gives an (H, W) uint8 image or a ValueError."""
import array

from hypothesis import given
from hypothesis import HealthCheck, settings, strategies as st
from mlofc_ros.image import image_to_gray, SUPPORTED_ENCODINGS
import numpy as np

ENCODINGS = sorted(SUPPORTED_ENCODINGS)
BOGUS = ['', 'jpeg', 'MONO8', 'mono', 'bgr', 'bayer_rggb16', 'yuv420', '32FC3', '8UC3',
         'mono8 ', 'nv12']
FUZZ = settings(deadline=None, database=None, print_blob=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def wrap(data: bytes, container: str):
    """Return ``data`` in one of the containers a message's ``data`` field can be."""
    if container == 'bytearray':
        return bytearray(data)
    if container == 'array':
        return array.array('B', data)
    if container == 'list':
        return list(data)
    if container == 'ndarray':
        return np.frombuffer(data, np.uint8)
    return data


def check(height, width, encoding, step, is_bigendian, data, max_pixels):
    """Decode; return the image, or the ValueError's message. Any other exception propagates."""
    try:
        out = image_to_gray(height, width, encoding, step, is_bigendian, data,
                            max_pixels=max_pixels)
    except ValueError as exc:
        return str(exc)
    assert isinstance(out, np.ndarray)
    assert out.dtype == np.uint8 and out.shape == (height, width) and out.flags.c_contiguous
    return out


CONTAINERS = ['bytes', 'bytearray', 'array', 'list', 'ndarray']
STEP_ERRORS = [0] * 10 + [-3, -2, -1, 1, 2, 3]
LENGTH_ERRORS = [0] * 12 + [-2, -1, 1, 5]


def near_valid_case(encoding: str, bits: int):
    """
    Small header that is right or off by a little, with a payload of about the right size.

    Every choice is a bit field of ``bits`` (so hypothesis makes only two draws per example,
    keeping its per-example cost low, and shrinks towards small headers); the payload
    bytes come from a numpy generator seeded with ``bits``.
    """
    def field(shift, size):
        return (bits >> shift) & ((1 << size) - 1)

    def size(shift):   # 0 (invalid) with probability 1/16, else 1..6
        return 0 if field(shift, 4) == 0 else 1 + field(shift, 4) % 6

    height, width, pad = size(0), size(4), field(8, 3) % 5
    step_error, length_error = STEP_ERRORS[field(11, 4)], LENGTH_ERRORS[field(15, 4)]
    container = CONTAINERS[field(19, 3) % 5]
    is_bigendian = [0, 1, 2, True, False][field(22, 3) % 5]
    max_pixels = None if field(25, 6) > 40 else field(25, 6)   # None or 0..40
    info = SUPPORTED_ENCODINGS.get(encoding)
    bpp = info.bytes_per_pixel if info else 1 + field(31, 2)
    step = width * bpp + pad + step_error
    nbytes = max(0, height * step + length_error)
    rng = np.random.default_rng(bits)
    if encoding == '32FC1' and field(33, 1):   # plain finite floats as well as random bits
        data = rng.normal(size=nbytes // 4).astype('<f4').tobytes()
        data += bytes(nbytes - len(data))
    else:
        data = rng.bytes(nbytes)
    return height, width, encoding, step, is_bigendian, wrap(data, container), max_pixels


@settings(FUZZ, max_examples=8000)
@given(st.sampled_from(ENCODINGS + BOGUS[:4]), st.integers(0, 2 ** 40 - 1))
def test_fuzz_near_valid_headers(encoding, bits):
    case = near_valid_case(encoding, bits)
    height, width, _, step, _, data, max_pixels = case
    result = check(*case)
    info = SUPPORTED_ENCODINGS.get(encoding)
    valid = (info is not None and height > 0 and width > 0
             and (max_pixels is None or height * width <= max_pixels)
             and step >= width * info.bytes_per_pixel and len(data) == height * step)
    if valid and isinstance(result, str):
        # the only content-dependent failure
        assert encoding == '32FC1' and 'no finite pixels' in result, result
    if not valid:
        assert isinstance(result, str)


# Cheap strategies (sampled_from of prepared values) keep hypothesis' per-example cost low.
ODD_VALUES = [None, 1.5, 4.0, float('nan'), float('inf'), -0.0, '4', '', b'\x04', True, False,
              np.int64(4), np.uint8(3), np.float32(2.0), [], [4], {}, object(), 3 + 0j]
EDGE_INTS = [20000, 2 ** 31 - 1, 2 ** 31, 2 ** 32 + 1, 10 ** 18, -(2 ** 63), 2 ** 64, -1, 0]
ANY_INT = st.one_of(st.integers(-3, 8), st.sampled_from(EDGE_INTS),
                    st.integers(-2 ** 70, 2 ** 70), st.sampled_from(ODD_VALUES))
ANY_DATA = st.one_of(st.binary(max_size=96), st.lists(st.integers(-5, 300), max_size=40),
                     st.sampled_from(ODD_VALUES + [
                         np.zeros(8, np.float32), np.zeros((2, 4), np.uint8),
                         np.zeros(16, np.uint8)[::2], array.array('H', [1, 2, 3, 4]),
                         memoryview(bytes(8)), 'abcdefgh', list(range(8)), (1, 2), [b'a']]))


@settings(FUZZ, max_examples=2000)
@given(height=ANY_INT, width=ANY_INT, step=ANY_INT,
       encoding=st.one_of(st.sampled_from(ENCODINGS + BOGUS + ODD_VALUES), st.text(max_size=8)),
       is_bigendian=st.sampled_from([0, 1, 2, 255, -1, True, False, None, 'yes']),
       data=ANY_DATA, max_pixels=st.one_of(st.none(), ANY_INT))
def test_fuzz_arbitrary_inputs(height, width, encoding, step, is_bigendian, data, max_pixels):
    check(height, width, encoding, step, is_bigendian, data, max_pixels)
