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
"""Debug overlay: segments coloured by body, track ids, and a legend of body angular velocities."""
from typing import Any, Optional, Tuple

import cv2
import numpy as np

#: Distinct BGR colours; body ``k`` is drawn with ``BODY_PALETTE[k % len(BODY_PALETTE)]``.
BODY_PALETTE: Tuple[Tuple[int, int, int], ...] = (
    (48, 48, 255),     # red
    (80, 220, 60),     # green
    (255, 128, 32),    # blue
    (0, 215, 255),     # yellow
    (255, 64, 255),    # magenta
    (255, 255, 0),     # cyan
    (0, 140, 255),     # orange
    (180, 105, 255),   # pink
    (128, 0, 128),     # purple
    (160, 255, 160),   # light green
    (0, 100, 180),     # brown
    (200, 200, 255),   # rose
)

#: Colour of unassigned (label ``-1``) segments.
UNASSIGNED_COLOR: Tuple[int, int, int] = (150, 150, 150)

#: Track ids are written next to segments only when there are at most this many.
MAX_TEXT_SEGMENTS = 300

_SHIFT = 4                      # fixed-point fractional bits for sub-pixel cv2 drawing
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def label_color(label: int) -> Tuple[int, int, int]:
    """Return the BGR colour of a body label (``< 0``: :data:`UNASSIGNED_COLOR`)."""
    label = int(label)
    return UNASSIGNED_COLOR if label < 0 else BODY_PALETTE[label % len(BODY_PALETTE)]


def _column(values: Any, m: int, name: str) -> np.ndarray:
    arr = np.asarray(values)
    if arr.shape != (m,) or (m and arr.dtype.kind not in 'iufb'):
        raise ValueError('%s must be a numeric (%d,) array, got %s %s'
                         % (name, m, arr.dtype, arr.shape))
    return arr


def draw_debug(gray: np.ndarray, segments: Any, labels: Any, track_ids: Any,
               angular_velocities_rad_s: Any, valid: Optional[Any] = None) -> np.ndarray:
    """
    Draw the segmentation of one frame over its gray image.

    Parameters
    ----------
    gray : (H, W) uint8
        The frame (an ``(H, W, 3)`` uint8 BGR image is accepted too).
    segments : (M, 4) float
        Segment endpoints ``(x1, y1, x2, y2)`` in pixels; non-finite rows are skipped.
    labels : (M,) int
        Body index per segment, ``-1`` = unassigned (drawn grey).
    track_ids : (M,) int
        Track id per segment, written at the segment midpoint when ``M <= MAX_TEXT_SEGMENTS``.
    angular_velocities_rad_s : (n, 3) float
        Angular velocity of each body (rad/s, camera optical frame); one legend line per body
        with ``|omega|`` and its components in deg/s.
    valid : (n,) bool, optional
        Whether each body's estimate is trustworthy; invalid bodies are marked in the legend.

    Returns
    -------
    (H, W, 3) uint8
        BGR overlay (a new array).

    """
    img = np.asarray(gray)
    if img.dtype != np.uint8 or not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)) \
            or img.size == 0:
        raise ValueError('gray must be a non-empty (H, W) uint8 image, got %s %s'
                         % (img.dtype, img.shape))
    seg = np.asarray(segments, dtype=np.float64)
    if seg.ndim != 2 or seg.shape[1] != 4:
        raise ValueError('segments must have shape (M, 4), got %s' % (seg.shape,))
    m = seg.shape[0]
    lab = _column(labels, m, 'labels').astype(np.int64)
    ids = _column(track_ids, m, 'track_ids')
    omega = np.asarray(angular_velocities_rad_s, dtype=np.float64)
    if omega.size == 0:
        omega = omega.reshape(0, 3)
    if omega.ndim != 2 or omega.shape[1] != 3:
        raise ValueError('angular_velocities_rad_s must have shape (n, 3), got %s'
                         % (omega.shape,))
    n = omega.shape[0]
    ok = np.ones(n, bool) if valid is None else _column(valid, n, 'valid').astype(bool)

    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
    h, w = out.shape[:2]
    thickness = max(1, int(round(min(h, w) / 400.0)))

    # lines: one cv2.polylines call per label, in fixed point, skipping non-finite rows and
    # clipping far-away endpoints into int32 range (cv2 clips to the image itself)
    good = np.all(np.isfinite(seg), axis=1)
    limit = 4.0 * max(h, w)
    fixed = np.clip(np.where(good[:, None], seg, 0.0), -limit, limit) * (1 << _SHIFT)
    pts = np.round(fixed).astype(np.int32).reshape(-1, 2, 2)
    for label in np.unique(lab[good]):
        sel = pts[good & (lab == label)]
        cv2.polylines(out, list(sel), False, label_color(label), thickness, cv2.LINE_AA, _SHIFT)

    if 0 < m <= MAX_TEXT_SEGMENTS:
        mid = (seg[:, :2] + seg[:, 2:]) / 2.0
        for k in np.flatnonzero(good):
            u, v = int(mid[k, 0]) + 2, int(mid[k, 1]) - 2
            if 0 <= u < w and 0 <= v < h:
                cv2.putText(out, str(int(ids[k])), (u, v), _FONT, 0.3, label_color(lab[k]), 1,
                            cv2.LINE_AA)

    # legend: one line per body, on a dark band for contrast
    deg = np.degrees(omega)
    norm = np.linalg.norm(deg, axis=1)
    line_h = 14
    for i in range(n):
        if np.all(np.isfinite(deg[i])):
            text = 'body %d: |w| %.1f deg/s (%+.1f, %+.1f, %+.1f)' % (i, norm[i], *deg[i])
        else:
            text = 'body %d: w unknown' % i
        if not ok[i]:
            text += ' [invalid]'
        y = 4 + line_h * (i + 1)
        (tw, th), base = cv2.getTextSize(text, _FONT, 0.4, 1)
        cv2.rectangle(out, (2, y - th - 2), (6 + tw, y + base), (0, 0, 0), cv2.FILLED)
        color = label_color(i) if ok[i] else UNASSIGNED_COLOR
        cv2.putText(out, text, (4, y), _FONT, 0.4, color, 1, cv2.LINE_AA)
    return out
