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
Helpers shared by the detector and the tracker: image checks, segment geometry, kernels.

Segments are ``(u1, v1, u2, v2)`` in pixels (``u`` column, ``v`` row, pixel centres at
integer coordinates).
"""
from functools import lru_cache
from typing import Tuple

import cv2
import numpy as np


def has_ximgproc() -> bool:
    """Return True when this OpenCV has the contrib module ximgproc (backends fld, edlines)."""
    return hasattr(cv2, 'ximgproc')


def check_gray(gray: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``gray`` is a (H, W) uint8 image."""
    if gray.ndim != 2 or gray.dtype != np.uint8:
        raise ValueError(f'expected a (H, W) uint8 gray image, got {gray.dtype} {gray.shape}')


def segment_lengths(segments: np.ndarray) -> np.ndarray:
    """Return the lengths (M,) in pixels of segments ``(M, 4)``."""
    s = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    return np.hypot(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1])


def angle_pairs(theta: np.ndarray, width: np.ndarray, period: float
                ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the index pairs ``(i, j)``, ``i != j``, with ``|theta_j - theta_i| <= width_i``.

    ``theta`` (M,) angles in ``[0, period)`` (compared periodically), ``width`` (M,) half-window
    per segment (rad, at most ``period / 2``). Sort + ``searchsorted`` on the angles tripled
    over three periods, so the cost follows the number of candidate pairs rather than M^2.
    """
    m = theta.size
    order = np.argsort(theta)
    a = theta[order]
    ext = np.concatenate([a - period, a, a + period])
    ext_idx = np.concatenate([order, order, order])
    lo = np.searchsorted(ext, theta - width, 'left')
    hi = np.searchsorted(ext, theta + width, 'right')
    cnt = hi - lo
    i = np.repeat(np.arange(m), cnt)
    starts = np.repeat(lo - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt)
    j = ext_idx[starts + np.arange(i.size)]
    keep = i != j
    return i[keep], j[keep]


@lru_cache(maxsize=4)
def square_kernel(size: int) -> np.ndarray:
    """Return the rectangular structuring element ``size`` x ``size`` (cached per size)."""
    return cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))
