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
The previous and the current frame, and the reduced copies that carrying and scheduling read.

KLT runs on the images resized by :data:`KLT_SCALE` (the edge refinement restores
full-resolution accuracy afterwards); the edge mask that detection on demand checks is taken
from the same reduced image, once per frame.
"""
from typing import Optional, Tuple

import cv2
import numpy as np

#: Scale of the images KLT and the edge checks run on (area average).
KLT_SCALE = 0.5
#: An edge pixel of the reduced image has ``|Sobel x| + |Sobel y|`` above this (grey levels).
EDGE_THRESHOLD = 40


class Frames:
    """The frame being processed, the one before it, and their cached reduced copies."""

    def __init__(self) -> None:
        self.prev: Optional[np.ndarray] = None
        self.cur: Optional[np.ndarray] = None
        self.shape: Optional[Tuple[int, int]] = None
        self._small_prev: Optional[np.ndarray] = None
        self._small_cur: Optional[np.ndarray] = None
        self._edges_cur: Optional[np.ndarray] = None

    def begin(self, gray: np.ndarray) -> None:
        """Start processing frame ``gray`` (H, W) uint8."""
        self.shape = gray.shape
        self.cur, self._small_cur, self._edges_cur = gray, None, None

    def end(self) -> None:
        """Make the current frame the previous one."""
        self.prev = self.cur.copy()
        self._small_prev = self._small_cur
        self.cur = self._small_cur = self._edges_cur = None

    def small(self, which: str) -> np.ndarray:
        """Return the previous (``'prev'``) or current (``'cur'``) frame at :data:`KLT_SCALE`."""
        key = '_small_' + which
        img = getattr(self, key)
        if img is None:
            full = self.prev if which == 'prev' else self.cur
            img = cv2.resize(full, None, fx=KLT_SCALE, fy=KLT_SCALE,
                             interpolation=cv2.INTER_AREA)
            setattr(self, key, img)
        return img

    def edges(self) -> np.ndarray:
        """Return a copy of the current frame's edge mask (uint8 0 / 255) at :data:`KLT_SCALE`."""
        if self._edges_cur is None:      # once per frame: the checks and the regions share it
            small = self.small('cur')
            mag = cv2.add(cv2.convertScaleAbs(cv2.Sobel(small, cv2.CV_16S, 1, 0)),
                          cv2.convertScaleAbs(cv2.Sobel(small, cv2.CV_16S, 0, 1)))
            self._edges_cur = cv2.compare(mag, EDGE_THRESHOLD, cv2.CMP_GT)
        return self._edges_cur.copy()    # callers draw on it
