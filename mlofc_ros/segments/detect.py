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
Straight line segment detection on gray images: a backend, then orientation, merging, bridging.

Segments are ``(u1, v1, u2, v2)`` in pixels of the input image (``u`` column, ``v`` row, pixel
centres at integer coordinates). Every segment returned by :class:`LineDetector` is oriented
(brighter side on the left, see :mod:`mlofc_ros.segments.merge`).
"""
from typing import Tuple

from mlofc_ros.segments.backends import Backend, BACKENDS, make_backend
from mlofc_ros.segments.bridge import bridge_crossings
from mlofc_ros.segments.common import check_gray, has_ximgproc, segment_lengths
from mlofc_ros.segments.merge import covers_any, merge_collinear, orient_by_polarity, rows_not_in
import numpy as np

__all__ = ['BACKENDS', 'bridge_crossings', 'check_gray', 'has_ximgproc', 'LineDetector',
           'merge_collinear', 'orient_by_polarity', 'segment_lengths']

#: Collinear merging: largest angle (deg), endpoint offset from the other's line (px) and gap
#: along the line (px) between two fragments of one line. Directions are compared modulo
#: 180 deg, so that pieces of one line whose contrast polarity flips (e.g. where stripes cross
#: it) still join.
MERGE_ANGLE_DEG = 2.0
MERGE_OFFSET_PX = 2.0
MERGE_GAP_PX = 15.0
#: Longest gap (px) :func:`bridge_crossings` bridges where a segment crosses a line.
BRIDGE_GAP_PX = 12.0


class LineDetector:
    """
    Line segment detector with a choice of backend, collinear merging and a length floor.

    ``backend``:

    * ``'lsd'``: ``cv2.createLineSegmentDetector`` with its own Gaussian sub-sampling
      ``scale`` (the LSD paper's anti-aliased scale; 0.8 is OpenCV's default).
    * ``'lsd_resize'`` (the default, at ``scale`` 0.8): ``cv2.resize`` (INTER_AREA) by
      ``scale``, then LSD at scale 1. The area average takes out most of the sensor noise, in
      which LSD at full resolution spends much of its time, while edges a few px apart stay
      apart. In the tracker it tracks as many edges as full-resolution LSD for 20-28 % less
      front-end CPU per frame, with line errors ~10 % larger (measured: tracked-5 0.937 /
      0.931 vs 0.937 / 0.932 on render seeds 0-3 / 4-9, bench frontend); 0.9 and 0.7 were
      both worse, 0.5 lost 2 points and LSD's own sub-sampling at 0.8 (``'lsd'``) 1 point.
    * ``'fld'`` / ``'edlines'``: ``cv2.ximgproc`` FastLineDetector / EdgeDrawing on the image
      resized by ``scale`` (need opencv-contrib). FLD at scale 1 with ``bridge`` tracks as
      many edges as the default for a third less front-end CPU per frame, with line errors
      ~30 % and endpoint errors 40-110 % larger (bench frontend); without ``bridge`` it misses
      5 points of the edges.
    * a callable ``gray (H, W) uint8 -> (M, 4)`` segments px, used as is (``scale`` ignored).

    Segments shorter than ``min_length`` px (full-resolution pixels) are dropped after merging.

    ``bridge``: add the lines that :func:`bridge_crossings` finds where the backend's segments
    cross them (the segments of at least ``min_length`` px are the crossings). ~4 ms more CPU
    per 640x480 detection frame; the real sequences gain 0-7 segments per frame.
    ``bridge_join``: merge the bridged lines with the reported segments they continue (beyond
    a crossing), which lifts the detector's recall of edges on faces striped in two directions
    (measured: 0.904 -> 0.945 on rendered frames). Off (the default), a bridged line is added
    only where no reported segment's centre lies on it, so reported segments keep their
    extent: in the tracker the joined extents cost id switches (measured: 0.98 vs 0.87 % on
    own_centre seed 4, bench frontend).

    ``lsd_bins``: the number of gradient-norm bins in which LSD orders its seed pixels
    (OpenCV's ``n_bins``, 1024 there and here; backends ``lsd`` and ``lsd_resize``). On a
    noisy image that sort is most of LSD's time: 32 bins take LSD on the image resized by 0.8
    from ~11 to ~6.7 ms (640x480, noise sigma 2) with the same segments to within a few, but
    tracked the spinning boxes of bench spinning 1-1.3 points worse, so the default stays 1024.
    """

    def __init__(self, min_length: float = 20.0, scale: float = 0.8,
                 backend: Backend = 'lsd_resize', bridge: bool = True,
                 bridge_join: bool = False, lsd_bins: int = 1024) -> None:
        if not min_length >= 0:
            raise ValueError(f'min_length must be >= 0, got {min_length}')
        if not 0.0 < scale <= 1.0:
            raise ValueError(f'scale must be in (0, 1], got {scale}')
        if int(lsd_bins) < 1:
            raise ValueError(f'lsd_bins must be >= 1, got {lsd_bins}')
        self.min_length = float(min_length)
        self.scale = float(scale)
        self.backend = backend
        self.bridge = bool(bridge)
        self.bridge_join = bool(bridge_join)
        self.lsd_bins = int(lsd_bins)
        self._scratch: dict = {}                 # bridge_crossings' reused image buffers
        self._region_scratch: dict = {}          # the same for detect_regions' crops
        self._raw = make_backend(backend, self.scale, self.min_length, self.lsd_bins)

    def detect(self, gray: np.ndarray) -> np.ndarray:
        """
        Detect segments in ``gray`` (H, W) uint8; return (M, 4) float32 ``(u1, v1, u2, v2)``.

        Segments are oriented (brighter side on the left), collinear fragments merged, lines
        cut up by crossings added when ``bridge``, and at least ``min_length`` px long. Raises
        ``ValueError`` for a non-2D or non-uint8 image.
        """
        check_gray(gray)
        raw = self._raw(gray)
        if raw is None or len(raw) == 0:
            return np.zeros((0, 4), np.float32)
        seg = np.asarray(raw, dtype=np.float32).reshape(-1, 4)
        # drop fragments too short to matter even after merging (cheap pre-filter)
        seg = seg[segment_lengths(seg) >= min(4.0, self.min_length)]
        seg = orient_by_polarity(gray, seg)
        if seg.shape[0] > 1:
            seg = _merge(seg)
        seg = seg[segment_lengths(seg) >= self.min_length]
        if self.bridge and seg.shape[0] > 0:
            seg = self._add_bridged(gray, seg)
        return np.ascontiguousarray(seg, dtype=np.float32)

    def _add_bridged(self, gray: np.ndarray, seg: np.ndarray) -> np.ndarray:
        """Return ``seg`` with the lines :func:`bridge_crossings` finds across them."""
        extra = bridge_crossings(gray, seg, self.min_length, BRIDGE_GAP_PX,
                                 scratch=self._scratch)
        if extra.shape[0] == 0:
            return seg
        extra = orient_by_polarity(gray, extra)
        # an added line may continue a reported one beyond a crossing: join them
        both = _merge(np.concatenate([seg, extra.astype(seg.dtype)]))
        # a bridged line's fitted extent may fall a hair short of its pixel span
        both = both[segment_lengths(both) >= self.min_length]
        if self.bridge_join:
            return both
        # only lines the backend missed altogether: a reported segment joined with bridged
        # pieces stays as reported (see the class docstring)
        new = rows_not_in(both, seg)
        new[new] = ~covers_any(both[new], seg)
        return np.concatenate([seg, both[new]])

    def detect_regions(self, gray: np.ndarray, boxes: np.ndarray, clip_px: float = 2.0
                       ) -> Tuple[np.ndarray, np.ndarray]:
        """
        Detect in rectangles of ``gray`` only: ``(segments (M, 4) float32, clipped (M,))``.

        ``boxes (B, 4)`` int ``(u0, v0, u1, v1)`` px, end-exclusive, inside the image. Each box
        goes through :meth:`detect` on its own and its segments are shifted back into the
        image's pixels. ``clipped`` marks segments with an endpoint within ``clip_px`` of a
        box side that is not an image border: such a segment may be the part of a longer line
        that the crop cut off, so its extent is not the line's. A segment crossing from one
        box into another comes out as one piece per box. LSD costs about what it costs on an
        image of the boxes' total area; orientation, merging and bridging add ~0.4 ms per box
        (640x480 real frames), so many small boxes save little.
        """
        check_gray(gray)
        b = np.asarray(boxes, dtype=np.int64).reshape(-1, 4)
        h, w = gray.shape
        if b.size and (b[:, 0].min() < 0 or b[:, 1].min() < 0 or b[:, 2].max() > w
                       or b[:, 3].max() > h or np.any(b[:, 2] <= b[:, 0])
                       or np.any(b[:, 3] <= b[:, 1])):
            raise ValueError(f'boxes must be non-empty (u0, v0, u1, v1) inside {w}x{h}, '
                             f'got {b.tolist()}')
        # the crops have other shapes than whole frames: their buffers apart from the frames'
        scratch, self._scratch = self._scratch, self._region_scratch
        segs, cuts = [np.zeros((0, 4), np.float32)], [np.zeros(0, bool)]
        try:
            for u0, v0, u1, v1 in b:                     # a few regions, not lines
                seg = self.detect(np.ascontiguousarray(gray[v0:v1, u0:u1]))
                seg[:, 0::2] += u0
                seg[:, 1::2] += v0
                u, v = seg[:, 0::2].astype(np.float64), seg[:, 1::2].astype(np.float64)
                # pixel centres of the box run from u0 to u1 - 1; image borders cut nothing
                cut = (((u0 > 0) & (u < u0 + clip_px)) | ((u1 < w) & (u > u1 - 1 - clip_px))
                       | ((v0 > 0) & (v < v0 + clip_px)) | ((v1 < h) & (v > v1 - 1 - clip_px)))
                segs.append(seg)
                cuts.append(cut.any(axis=1))
        finally:
            self._region_scratch, self._scratch = self._scratch, scratch
        return np.ascontiguousarray(np.concatenate(segs), dtype=np.float32), np.concatenate(cuts)


def _merge(seg: np.ndarray) -> np.ndarray:
    """Merge the collinear fragments of ``seg`` (M, 4) with the detector's tolerances."""
    return merge_collinear(seg, MERGE_ANGLE_DEG, MERGE_OFFSET_PX, MERGE_GAP_PX, oriented=False)
