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
When and where the line detector runs: detection on demand, on the whole image or in regions.

After a detection whose unclaimed segments (new edges) number at most :data:`QUIET_BIRTHS` of
the live tracks per ``detect_every`` frames, the interval doubles, up to ``detect_every_max``
frames; a detection that finds more brings it back to ``detect_every``. Past ``detect_every``
frames the detector also runs at once when more than :data:`DETECT_ON_LOSS` of the tracks were
not carried in a frame, or when the edge pixels no track explains grew by more than
:data:`NEW_EDGE_PX` since the last detection (a 0.2 ms check at 640x480). A static camera
watching a few moving objects then pays for the detector rarely (measured: every ~8th frame
instead of every 3rd on camera_centre, front-end CPU -30 %, bench frontend); where faces keep
turning into view it stays near every 3rd. The first ``detect_every_max`` frames run at the
base rate: the track set is being built (a longer first interval changed the solver's first
cold search: 1.4 -> 14.5 % wrong on own3+bg, bench spinning).

With ``detect_regions``, in a quiet scene after the first ``detect_every_max`` frames the
detector runs only in boxes around the edges no carried track explains and the predicted lines
of the tracks not carried, unless they cover more than :data:`REGION_MAX_AREA` of the image;
the first detection after ``detect_every_max`` frames sees the whole image. Cropping busy
scenes too cost tracked-5 and endpoint accuracy (measured: endpoint errors +31-37 % instead of
+10-12 %, bench frontend).
"""
import math
from typing import Optional, Tuple

import cv2
from mlofc_ros.segments.common import square_kernel
from mlofc_ros.tracks.config import TrackerConfig
from mlofc_ros.tracks.frames import Frames, KLT_SCALE
import numpy as np

#: A detection finding at most this share of the live tracks as new segments (per
#: ``detect_every`` frames) is quiet: the interval doubles.
QUIET_BIRTHS = 0.03
#: Past the base interval, detect at once when more than this share of the tracks was lost.
DETECT_ON_LOSS = 0.05
#: Past the base interval, detect at once when this many more edge pixels of the reduced
#: image (at 640x480, ~30-50 px of new edge; scaled with the image diagonal) lie farther than
#: ~2 px from every track than right after the last detection.
NEW_EDGE_PX = 100
#: Regions: tiles (px), margin around what is new (px), largest share of the image cropped.
REGION_TILE_PX = 40
REGION_MARGIN_PX = 12.0
REGION_MAX_AREA = 0.5


class DetectionSchedule:
    """The detection interval and the counters that decide when the detector runs next."""

    def __init__(self, config: TrackerConfig) -> None:
        self.config = config
        self.reset()

    def reset(self) -> None:
        """Start again at the base rate."""
        self.since_detect = 0                # frames since the detector last ran
        self.since_full = 0                  # frames since it last saw the whole image
        self.interval = self.config.detect_every      # current interval (on demand)
        self.uncovered_after = 0             # uncovered edge pixels after the last detection

    @property
    def _top(self) -> int:
        return max(self.config.detect_every_max, self.config.detect_every)

    def due(self, frames: Frames, seg: np.ndarray, carried: np.ndarray) -> bool:
        """Count a frame; return whether the detector runs in it (tracks ``seg``, ``carried``)."""
        self.since_detect += 1
        self.since_full += 1
        base = self.config.detect_every
        t_n = seg.shape[0]
        interval = min(max(self.interval, base), self._top)
        if t_n == 0 or self.since_detect >= interval:
            return True
        if self.since_detect < base:
            return False
        # past the base interval: detect as soon as something new shows (tracks lost, or
        # edges that no track explains)
        if t_n - np.count_nonzero(carried) > DETECT_ON_LOSS * t_n:
            return True
        # NEW_EDGE_PX is for 640x480; edge pixel counts grow with the image's linear size
        scale = math.hypot(*frames.shape) / 800.0
        return uncovered_edges(frames, seg) > self.uncovered_after + NEW_EDGE_PX * scale

    def boxes(self, frames: Frames, frame: int, seg: np.ndarray, carried: np.ndarray
              ) -> Tuple[Optional[np.ndarray], float]:
        """
        Return where to detect in frame number ``frame``: ``(boxes or None, image share)``.

        The boxes are (B, 4) ``(u0, v0, u1, v1)`` px.

        None (the whole image) unless regions are on, the scene is quiet, the track set is
        built and the whole image was seen within the last ``detect_every_max`` frames.
        """
        top = self._top
        quiet = self.interval > self.config.detect_every
        if (self.config.detect_regions and seg.shape[0] > 0 and quiet and frame >= top
                and self.since_full < top):
            boxes, area = _regions(frames, seg, carried)
        else:
            boxes, area = None, 1.0
        if boxes is None:
            self.since_full = 0
        return boxes, area

    def after_detect(self, frame: int, unclaimed: int, alive: int) -> None:
        """Set the next interval from the ``unclaimed`` (new) segments of a detection."""
        base = self.config.detect_every
        top = self._top
        # new segments per base interval: a longer wait has more to find
        rate = unclaimed * base / max(self.since_detect, 1)
        self.since_detect = 0
        # the first `top` frames build the track set: the base rate there (and the solver's
        # first windows see every birth); a quiet scene doubles the wait, anything new brings
        # it back to the base rate
        quiet = frame >= top and rate <= QUIET_BIRTHS * alive
        self.interval = min(2 * max(self.interval, base), top) if quiet else base

    def after_births(self, frames: Frames, seg: np.ndarray) -> None:
        """Note what the tracks ``seg`` leave unexplained right after a detection."""
        if self.interval > self.config.detect_every:
            # the reference of the checks that run only while the interval is longer than
            # the base one
            self.uncovered_after = uncovered_edges(frames, seg)


def uncovered_edges(frames: Frames, seg: np.ndarray) -> int:
    """Count the edge pixels of the reduced current frame farther than ~2 px from ``seg``."""
    if seg.shape[0] == 0:
        return 0
    edges = frames.edges()
    pts = np.round(seg.reshape(-1, 2, 2) * KLT_SCALE).astype(np.int32)
    cv2.polylines(edges, list(pts), False, 0, 5)      # erase what the tracks explain
    return cv2.countNonZero(edges)


def _regions(frames: Frames, seg: np.ndarray, carried: np.ndarray
             ) -> Tuple[Optional[np.ndarray], float]:
    """
    Return the boxes ``(B, 4)`` (u0, v0, u1, v1) px to detect in and their image share.

    The edge pixels of the current frame (as in :func:`uncovered_edges`) that no carried track
    of ``seg`` explains, plus the predicted lines of the tracks not carried (to be found
    again), grown by :data:`REGION_MARGIN_PX`, on a grid of :data:`REGION_TILE_PX` tiles; each
    8-connected group of tiles is one box. ``(None, 1.0)`` (the whole image) when they cover
    more than :data:`REGION_MAX_AREA` of the image (a crop would save little).
    """
    mask = frames.edges()
    pts = np.round(seg.reshape(-1, 2, 2) * KLT_SCALE).astype(np.int32)
    if carried.any():
        cv2.polylines(mask, list(pts[carried]), False, 0, 5)
    if not carried.all():
        cv2.polylines(mask, list(pts[~carried]), False, 255, 5)
    r = int(round(REGION_MARGIN_PX * KLT_SCALE))
    if r > 0:
        mask = cv2.dilate(mask, square_kernel(2 * r + 1))
    h, w = frames.shape
    ts = max(int(round(REGION_TILE_PX * KLT_SCALE)), 1)   # reduced-image pixels
    nty, ntx = -(-mask.shape[0] // ts), -(-mask.shape[1] // ts)
    grid = np.zeros((nty * ts, ntx * ts), np.uint8)
    grid[:mask.shape[0], :mask.shape[1]] = mask
    on = grid.reshape(nty, ts, ntx, ts).max(axis=(1, 3))
    _, _, stats, _ = cv2.connectedComponentsWithStats(on, connectivity=8)
    st = stats[1:]                                        # label 0 is the background
    # tile edges back in image pixels (reduced-image pixel i covers [i / s, (i + 1) / s))
    lo = np.floor(st[:, :2] * ts / KLT_SCALE).astype(np.int64)
    hi = np.ceil((st[:, :2] + st[:, 2:4]) * ts / KLT_SCALE).astype(np.int64)
    boxes = np.stack([lo[:, 0], lo[:, 1], np.minimum(hi[:, 0], w),
                      np.minimum(hi[:, 1], h)], axis=1)
    boxes = boxes[(boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])]
    area = float(np.sum((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]))) / (h * w)
    return (None, 1.0) if area > REGION_MAX_AREA else (boxes, area)
