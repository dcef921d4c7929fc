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
"""Sliding window of the last few frames of line tracks, as the solver consumes them."""
from typing import Tuple

import numpy as np


class TrackWindow:
    """
    Ring buffer of the last ``size`` frames of ``(track_ids, segments)``.

    Each :meth:`push` stores one frame (ids sorted, in preallocated arrays that grow by doubling
    when a frame has more tracks than ever before); :meth:`tracks` lays the window out as one
    row per track id and one column per frame, oldest first, newest last. Everything is
    vectorised (``np.unique`` / ``np.searchsorted``), no per-track Python work.
    """

    def __init__(self, size: int = 5, capacity: int = 256) -> None:
        if int(size) < 1:
            raise ValueError(f'window size must be >= 1, got {size}')
        self.size = int(size)
        cap = max(int(capacity), 1)
        self._ids = np.zeros((self.size, cap), np.uint32)
        self._seg = np.zeros((self.size, cap, 4), np.float64)
        self._count = np.zeros(self.size, np.intp)
        self._head = 0          # slot the next push writes
        self._fill = 0

    @property
    def fill(self) -> int:
        """Return the number of frames held (0 .. size)."""
        return self._fill

    def reset(self) -> None:
        """Forget every frame (keeps the allocated buffers)."""
        self._count[:] = 0
        self._head = 0
        self._fill = 0

    def _grow(self, m: int) -> None:
        cap = self._ids.shape[1]
        while cap < m:
            cap *= 2
        ids = np.zeros((self.size, cap), np.uint32)
        seg = np.zeros((self.size, cap, 4), np.float64)
        old = self._ids.shape[1]
        ids[:, :old] = self._ids
        seg[:, :old] = self._seg
        self._ids, self._seg = ids, seg

    def push(self, track_ids: np.ndarray, segments: np.ndarray) -> None:
        """
        Append one frame: ``track_ids`` (M,) unsigned ints, ``segments`` (M, 4) px.

        The oldest frame drops out once ``size`` frames are held. Raises ``ValueError`` on
        mismatched lengths, a wrong segment shape, or a repeated id within the frame.
        """
        ids = np.asarray(track_ids).reshape(-1)
        seg = np.asarray(segments, dtype=np.float64)
        if seg.size == 0 and ids.size == 0:
            seg = seg.reshape(0, 4)
        if seg.ndim != 2 or seg.shape[1] != 4:
            raise ValueError(f'segments must be (M, 4), got {seg.shape}')
        if seg.shape[0] != ids.size:
            raise ValueError(f'{ids.size} track ids but {seg.shape[0]} segments')
        if ids.size and ids.dtype.kind not in 'ui':
            raise ValueError(f'track ids must be integers, got {ids.dtype}')
        if ids.size and ids.dtype.kind == 'i' and ids.min() < 0:
            raise ValueError('track ids must be non-negative')
        m = ids.size
        order = np.argsort(ids, kind='stable')
        ids = ids[order].astype(np.uint32)
        if m > 1 and np.any(ids[1:] == ids[:-1]):
            raise ValueError('track ids repeat within one frame')
        if m > self._ids.shape[1]:
            self._grow(m)
        h = self._head
        self._ids[h, :m] = ids
        self._seg[h, :m] = seg[order]
        self._count[h] = m
        self._head = (h + 1) % self.size
        self._fill = min(self._fill + 1, self.size)

    def _slots(self) -> np.ndarray:
        """Ring slots of the held frames, oldest first (fill,)."""
        return (self._head - self._fill + np.arange(self._fill)) % self.size

    def tracks(self, min_frames: int = 2) -> Tuple[np.ndarray, np.ndarray]:
        """
        Lay out the window: ``(ids (N,) uint32, window (N, K, 4) float64)``.

        ``K`` is :attr:`fill`, column ``K - 1`` is the newest frame; rows are sorted by id and
        hold only tracks present in at least ``min_frames`` of the K frames. Entries of frames
        where a track is missing are NaN. Segments are ``(u1, v1, u2, v2)`` px as pushed.
        """
        k = self._fill
        if k == 0:
            return np.zeros(0, np.uint32), np.zeros((0, 0, 4), np.float64)
        slots = self._slots()
        counts = self._count[slots]
        all_ids = np.concatenate([self._ids[s, :c] for s, c in zip(slots, counts)])
        uniq, present = np.unique(all_ids, return_counts=True)
        keep = present >= int(min_frames)
        ids = uniq[keep]
        out = np.full((ids.size, k, 4), np.nan)
        if ids.size == 0:
            return ids, out
        for col, (s, c) in enumerate(zip(slots, counts)):   # one step per frame, not per track
            fid = self._ids[s, :c]
            row = np.searchsorted(ids, fid)
            row_c = np.minimum(row, ids.size - 1)
            hit = ids[row_c] == fid
            out[row_c[hit], col] = self._seg[s, :c][hit]
        return ids, out
