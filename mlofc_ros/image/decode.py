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
Decode ``sensor_msgs/Image`` payloads to 8-bit grayscale, without ROS (numpy + OpenCV).

The one table :data:`SUPPORTED_ENCODINGS` describes every encoding understood here; decoding
(:func:`image_to_gray`) and encoding (:func:`gray_to_image_fields`) both read it.

Conventions follow ``cv_bridge``: ``step`` is the row length in bytes (rows may be padded),
``is_bigendian`` gives the byte order of multi-byte channels, 16-bit data goes to 8 bits by
dropping the low byte (``>> 8``; cv_bridge scales by 1/256), Bayer and YUV 4:2:2 are converted by
OpenCV. Every malformed input raises :class:`ValueError` naming the problem; sizes are checked
before anything large is allocated, so a forged header cannot make the decoder allocate memory.
"""
from dataclasses import dataclass
import numbers
import types
from typing import Any, Dict, Mapping, Optional

import cv2
import numpy as np

#: How the channels of an encoding become one gray channel.
KIND_MONO = 'mono'        # one integer channel, shifted down to 8 bits
KIND_FLOAT = 'float'      # one float channel, finite min-max stretched to 0..255
KIND_COLOR = 'color'      # 3 or 4 channels, cv2.cvtColor(code)
KIND_BAYER = 'bayer'      # one 8-bit mosaic channel, cv2.cvtColor(Bayer code)
KIND_YUV422 = 'yuv422'    # two bytes per pixel, cv2.cvtColor(YUV2GRAY code)


@dataclass(frozen=True)
class EncodingInfo:
    """
    Memory layout of one ``sensor_msgs/Image`` encoding and how it becomes gray.

    Attributes
    ----------
    name : str
        Canonical ROS encoding name (an alias such as ``yuv422`` maps to ``uyvy``'s entry).
    channels : int
        Channels per pixel as laid out in memory (YUV 4:2:2: 2 bytes per pixel -> 2 channels).
    bytes_per_channel : int
        Bytes of one channel value (1, 2 or 4).
    dtype : str
        numpy kind+size of one channel without byte order, e.g. ``'u1'``, ``'u2'``, ``'f4'``.
    kind : str
        One of ``KIND_MONO``, ``KIND_FLOAT``, ``KIND_COLOR``, ``KIND_BAYER``, ``KIND_YUV422``.
    cv2_code : int or None
        ``cv2.COLOR_*`` code converting the native-order array to gray, ``None`` if not needed.

    """

    name: str
    channels: int
    bytes_per_channel: int
    dtype: str
    kind: str
    cv2_code: Optional[int] = None

    @property
    def bytes_per_pixel(self) -> int:
        """Bytes of one pixel, ``channels * bytes_per_channel``."""
        return self.channels * self.bytes_per_channel

    def numpy_dtype(self, is_bigendian: bool = False) -> np.dtype:
        """Return the channel dtype with the wire byte order (1-byte types have none)."""
        if self.bytes_per_channel == 1:
            return np.dtype(self.dtype)
        return np.dtype(('>' if is_bigendian else '<') + self.dtype)


def _table() -> Mapping[str, EncodingInfo]:
    e = EncodingInfo
    rows = [
        e('mono8', 1, 1, 'u1', KIND_MONO),
        e('8UC1', 1, 1, 'u1', KIND_MONO),
        e('mono16', 1, 2, 'u2', KIND_MONO),
        e('16UC1', 1, 2, 'u2', KIND_MONO),
        e('32FC1', 1, 4, 'f4', KIND_FLOAT),
        e('bgr8', 3, 1, 'u1', KIND_COLOR, cv2.COLOR_BGR2GRAY),
        e('rgb8', 3, 1, 'u1', KIND_COLOR, cv2.COLOR_RGB2GRAY),
        e('bgra8', 4, 1, 'u1', KIND_COLOR, cv2.COLOR_BGRA2GRAY),
        e('rgba8', 4, 1, 'u1', KIND_COLOR, cv2.COLOR_RGBA2GRAY),
        e('bgr16', 3, 2, 'u2', KIND_COLOR, cv2.COLOR_BGR2GRAY),
        e('rgb16', 3, 2, 'u2', KIND_COLOR, cv2.COLOR_RGB2GRAY),
        # ROS names the 2x2 cell from the top-left pixel; OpenCV's classic names (BayerBG...)
        # are shifted by one pixel, so ROS rggb == COLOR_BayerBG2GRAY (cv_bridge's table).
        # test_encodings checks each one against a hand-made mosaic.
        e('bayer_rggb8', 1, 1, 'u1', KIND_BAYER, cv2.COLOR_BayerBG2GRAY),
        e('bayer_bggr8', 1, 1, 'u1', KIND_BAYER, cv2.COLOR_BayerRG2GRAY),
        e('bayer_gbrg8', 1, 1, 'u1', KIND_BAYER, cv2.COLOR_BayerGR2GRAY),
        e('bayer_grbg8', 1, 1, 'u1', KIND_BAYER, cv2.COLOR_BayerGB2GRAY),
        e('uyvy', 2, 1, 'u1', KIND_YUV422, cv2.COLOR_YUV2GRAY_UYVY),
        e('yuyv', 2, 1, 'u1', KIND_YUV422, cv2.COLOR_YUV2GRAY_YUY2),
    ]
    table: Dict[str, EncodingInfo] = {r.name: r for r in rows}
    # sensor_msgs/image_encodings.hpp: YUV422 = "yuv422" (UYVY), YUV422_YUY2 = "yuv422_yuy2"
    table['yuv422'] = table['uyvy']
    table['yuv422_yuy2'] = table['yuyv']
    return types.MappingProxyType(table)


#: Every encoding :func:`image_to_gray` accepts (aliases included) -> its :class:`EncodingInfo`.
SUPPORTED_ENCODINGS: Mapping[str, EncodingInfo] = _table()

#: Encodings :func:`gray_to_image_fields` can produce.
WRITABLE_ENCODINGS = tuple(
    name for name, info in SUPPORTED_ENCODINGS.items() if info.kind in (
        KIND_MONO, KIND_FLOAT, KIND_COLOR))


def encoding_info(encoding: Any) -> EncodingInfo:
    """Return the table entry of ``encoding``; ``ValueError`` listing supported ones if absent."""
    info = SUPPORTED_ENCODINGS.get(encoding) if isinstance(encoding, str) else None
    if info is None:
        raise ValueError('unsupported image encoding %r; supported: %s'
                         % (encoding, ', '.join(sorted(SUPPORTED_ENCODINGS))))
    return info


def _as_int(value: Any, what: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise ValueError('image %s must be an integer, got %r' % (what, value))
    return int(value)


def byte_length(data: Any) -> int:
    """
    Return the number of bytes in a message ``data`` field without copying it.

    ``data`` may be ``bytes``, ``bytearray``, ``memoryview``, ``array.array`` (any item size
    counts its bytes), a ``uint8`` numpy array or a list/tuple of byte values (one per element).
    """
    if isinstance(data, np.ndarray):
        if data.dtype != np.uint8:
            raise ValueError('image data array must be uint8, got %s' % data.dtype)
        return int(data.size)
    if isinstance(data, (list, tuple)):
        return len(data)
    if isinstance(data, str):
        raise ValueError('image data must be bytes-like, got str')
    try:
        return memoryview(data).nbytes
    except TypeError:
        raise ValueError('image data must be bytes-like, a uint8 array or a list of byte '
                         'values, got %s' % type(data).__name__) from None


def as_byte_array(data: Any) -> np.ndarray:
    """
    View (or, for lists, convert) a message ``data`` field as a flat ``(N,)`` uint8 array.

    Bytes-like objects and uint8 arrays are viewed without copying (the result may be
    read-only); list values must be integers in 0..255. Raises ``ValueError`` otherwise.
    """
    if isinstance(data, np.ndarray):
        byte_length(data)
        return data.reshape(-1)
    if isinstance(data, (list, tuple)):
        if not data:
            return np.zeros(0, np.uint8)
        try:
            arr = np.asarray(data)
        except (ValueError, TypeError, OverflowError) as exc:
            raise ValueError('image data list is not a flat list of byte values: %s' % exc) \
                from None
        if arr.ndim != 1 or arr.dtype.kind not in 'iu' or arr.min() < 0 or arr.max() > 255:
            raise ValueError('image data list must hold integers in 0..255')
        return arr.astype(np.uint8)
    byte_length(data)
    try:
        return np.frombuffer(memoryview(data).cast('B'), dtype=np.uint8)
    except (TypeError, ValueError) as exc:  # e.g. a non-contiguous buffer
        raise ValueError('image data buffer is not usable: %s' % exc) from None


def _to_gray(pixels: np.ndarray, info: EncodingInfo) -> np.ndarray:
    """Convert native-order ``(H, W, C)`` pixels of ``info``'s layout to ``(H, W)`` uint8."""
    if info.kind == KIND_MONO:
        plane = pixels[:, :, 0]
        if info.bytes_per_channel == 2:
            return np.ascontiguousarray(plane >> 8, dtype=np.uint8)
        return np.ascontiguousarray(plane, dtype=np.uint8)
    if info.kind == KIND_FLOAT:
        return _stretch_float(pixels[:, :, 0])
    if info.kind == KIND_BAYER:
        src = np.ascontiguousarray(pixels[:, :, 0])
    else:
        src = np.ascontiguousarray(pixels)
    try:
        gray = cv2.cvtColor(src, info.cv2_code)
    except cv2.error as exc:  # should not happen after the checks; never let it escape
        raise ValueError('OpenCV could not convert %s image of shape %s: %s'
                         % (info.name, src.shape, str(exc).strip().splitlines()[-1])) from None
    if gray.dtype == np.uint16:
        gray = (gray >> 8).astype(np.uint8)
    return np.ascontiguousarray(gray)


def _stretch_float(plane: np.ndarray) -> np.ndarray:
    """Min-max stretch the finite values of a float plane to 0..255; NaN/inf become 0."""
    finite = np.isfinite(plane)
    if not finite.any():
        raise ValueError('32FC1 image has no finite pixels (all NaN/inf); cannot scale it')
    values = plane[finite].astype(np.float64)
    lo = float(values.min())
    span = float(values.max()) - lo   # float64: no overflow even for +-3.4e38
    out = np.zeros(plane.shape, np.uint8)
    if span > 0:
        out[finite] = np.rint((values - lo) * (255.0 / span)).astype(np.uint8)
    return out


def image_to_gray(height: Any, width: Any, encoding: Any, step: Any, is_bigendian: Any,
                  data: Any, max_pixels: Optional[int] = None) -> np.ndarray:
    """
    Decode a ``sensor_msgs/Image`` payload to an 8-bit grayscale image.

    Parameters
    ----------
    height, width : int
        Image size in pixels (rows, columns), both > 0.
    encoding : str
        A key of :data:`SUPPORTED_ENCODINGS`.
    step : int
        Bytes per row, ``>= width * bytes_per_pixel`` (the rest of a row is padding).
    is_bigendian : int or bool
        Byte order of 16-bit and float channels (ignored for 8-bit encodings).
    data : bytes-like, uint8 array or list of byte values
        Exactly ``height * step`` bytes.
    max_pixels : int, optional
        Reject images with more than this many pixels (checked before any allocation).

    Returns
    -------
    (H, W) uint8, C-contiguous
        Gray levels: 16-bit channels ``>> 8``; ``32FC1`` min-max stretched over its finite
        pixels (NaN/inf -> 0, a constant image -> 0); colour, Bayer and YUV 4:2:2 through
        ``cv2.cvtColor`` (ITU-R BT.601 luma weights).

    Raises
    ------
    ValueError
        Unsupported encoding, non-positive or non-integer sizes, ``step`` too short, ``data``
        of the wrong length or type, more than ``max_pixels`` pixels, a ``32FC1`` image with no
        finite pixel.

    """
    info = encoding_info(encoding)
    height = _as_int(height, 'height')
    width = _as_int(width, 'width')
    step = _as_int(step, 'step')
    if height <= 0 or width <= 0:
        raise ValueError('image size must be positive, got %dx%d (width x height)'
                         % (width, height))
    if max_pixels is not None:
        max_pixels = _as_int(max_pixels, 'max_pixels')
        if width * height > max_pixels:
            raise ValueError('image %dx%d has %d pixels, more than max_pixels=%d'
                             % (width, height, width * height, max_pixels))
    row_bytes = width * info.bytes_per_pixel
    if step < row_bytes:
        raise ValueError('image step %d is shorter than a %s row of %d pixels (%d bytes)'
                         % (step, info.name, width, row_bytes))
    nbytes = byte_length(data)
    if nbytes != height * step:
        raise ValueError('image data has %d bytes, expected height*step = %d*%d = %d'
                         % (nbytes, height, step, height * step))
    buf = as_byte_array(data)
    dtype = info.numpy_dtype(bool(is_bigendian))
    # strided view (no copy) of the pixels, skipping row padding; may be unaligned
    pixels = np.ndarray((height, width, info.channels), dtype=dtype, buffer=buf,
                        strides=(step, info.bytes_per_pixel, info.bytes_per_channel))
    if info.bytes_per_channel > 1:
        pixels = pixels.astype(dtype.newbyteorder('='))   # aligned, native-order copy
    return _to_gray(pixels, info)


def image_msg_to_gray(msg: Any, max_pixels: Optional[int] = None) -> np.ndarray:
    """
    Decode a ``sensor_msgs/Image`` (or any object with its fields) with :func:`image_to_gray`.

    Returns ``(H, W)`` uint8; raises ``ValueError`` for malformed messages, including ones
    missing a field.
    """
    try:
        fields = (msg.height, msg.width, msg.encoding, msg.step, msg.is_bigendian, msg.data)
    except AttributeError as exc:
        raise ValueError('not an image message: %s' % exc) from None
    return image_to_gray(*fields, max_pixels=max_pixels)


def gray_to_image_fields(gray_or_bgr: np.ndarray, encoding: str = 'mono8', *,
                         is_bigendian: bool = False, row_padding: int = 0) -> Dict[str, Any]:
    """
    Build the fields of a ``sensor_msgs/Image`` holding ``gray_or_bgr`` (inverse of decode).

    Parameters
    ----------
    gray_or_bgr : (H, W) or (H, W, 3) array
        uint8 gray or BGR image. It is converted to ``encoding``: gray is replicated to colour
        channels, BGR goes to gray with ``cv2.COLOR_BGR2GRAY``, 8-bit values become 16-bit as
        ``v * 257`` (so ``>> 8`` gives ``v`` back) and float as ``float32(v)``. A uint16 array
        for a 16-bit encoding or a float32 array for ``32FC1`` is written unchanged. For 4
        channel encodings alpha is 255.
    encoding : str
        One of :data:`WRITABLE_ENCODINGS` (mono8, 8UC1, mono16, 16UC1, 32FC1, bgr8, rgb8,
        bgra8, rgba8, bgr16, rgb16).
    is_bigendian : bool
        Byte order of 16-bit and float channels.
    row_padding : int
        Extra bytes (zeros) at the end of every row, ``step = width * bytes_per_pixel + pad``.

    Returns
    -------
    dict
        ``height, width, encoding, step, is_bigendian`` (0/1) and ``data`` (bytes).

    """
    info = encoding_info(encoding)
    if info.kind not in (KIND_MONO, KIND_FLOAT, KIND_COLOR):
        raise ValueError('gray_to_image_fields cannot write %s; writable: %s'
                         % (encoding, ', '.join(WRITABLE_ENCODINGS)))
    img = np.asarray(gray_or_bgr)
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3) or img.size == 0:
        raise ValueError('expected a non-empty (H, W) gray or (H, W, 3) BGR image, got shape %s'
                         % (img.shape,))
    row_padding = _as_int(row_padding, 'row_padding')
    if row_padding < 0:
        raise ValueError('row_padding must be >= 0, got %d' % row_padding)
    raw_dtype = np.dtype(info.dtype)
    if img.dtype != np.uint8 and img.dtype != raw_dtype:
        raise ValueError('%s image must be uint8 (or %s), got %s'
                         % (encoding, raw_dtype, img.dtype))
    # channel layout first (in the input dtype), then depth
    if info.channels == 1:
        if img.ndim == 3:
            img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_BGR2GRAY)
        img = img[:, :, None]
    else:
        bgr = img if img.ndim == 3 else np.repeat(img[:, :, None], 3, axis=2)
        if encoding.startswith('rgb'):
            bgr = bgr[:, :, ::-1]
        if info.channels == 4:
            alpha = 255 if bgr.dtype == np.uint8 else np.iinfo(bgr.dtype).max
            bgr = np.concatenate([bgr, np.full(bgr.shape[:2] + (1,), alpha, bgr.dtype)], axis=2)
        img = bgr
    if img.dtype == np.uint8 and raw_dtype == np.uint16:
        img = img.astype(np.uint16) * np.uint16(257)
    elif img.dtype == np.uint8 and raw_dtype == np.float32:
        img = img.astype(np.float32)
    height, width = img.shape[:2]
    wire = img.astype(info.numpy_dtype(bool(is_bigendian)))
    rows = wire.reshape(height, -1).view(np.uint8)
    if row_padding:
        rows = np.concatenate([rows, np.zeros((height, row_padding), np.uint8)], axis=1)
    return {
        'height': int(height),
        'width': int(width),
        'encoding': encoding,
        'step': int(rows.shape[1]),
        'is_bigendian': int(bool(is_bigendian)),
        'data': rows.tobytes(),
    }
