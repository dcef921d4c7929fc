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
"""Straight line segment detection on gray images, with collinear-fragment merging.

Segments are ``(u1, v1, u2, v2)`` in pixels of the input image (``u`` column, ``v`` row, pixel
centres at integer coordinates). Every segment returned by :class:`LineDetector` is *oriented*:
walking from ``(u1, v1)`` to ``(u2, v2)``, the brighter side is on the left in the image (which,
with ``v`` pointing down, is the side of ``(dv, -du)``). Orientation lets the tracker tell apart
the two edges of a thin bar.
"""
from typing import Callable, Optional, Tuple, Union

import cv2
import numpy as np

#: Backends understood by :class:`LineDetector` (``fld``/``edlines`` need opencv-contrib).
BACKENDS = ('lsd', 'lsd_resize', 'fld', 'edlines')

Backend = Union[str, Callable[[np.ndarray], np.ndarray]]


def segment_lengths(segments: np.ndarray) -> np.ndarray:
    """Return the lengths (M,) in pixels of segments ``(M, 4)``."""
    s = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    return np.hypot(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1])


def orient_by_polarity(gray: np.ndarray, segments: np.ndarray, offset: float = 1.5,
                       ts=(0.25, 0.5, 0.75)) -> np.ndarray:
    """Flip segments so that the brighter side is on the left (side of ``(dv, -du)``).

    ``gray`` (H, W) uint8; ``segments`` (M, 4) px. Intensities are read (nearest pixel) at
    ``offset`` px either side of the points at fractions ``ts`` along each segment. Returns a
    new (M, 4) array of the input dtype.
    """
    seg = np.asarray(segments)
    if seg.shape[0] == 0:
        return seg.copy()
    s = seg.astype(np.float32, copy=False)
    h, w = gray.shape[:2]
    d = s[:, 2:] - s[:, :2]
    n = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-6)
    nrm = np.stack([d[:, 1], -d[:, 0]], axis=1) / n[:, None] * offset   # left normal
    t = np.asarray(ts, dtype=np.float32)
    pts = s[:, None, :2] + t[None, :, None] * d[:, None, :]            # (M, T, 2)
    left = pts + nrm[:, None, :]
    right = pts - nrm[:, None, :]
    lu = np.clip(np.rint(left[..., 0]), 0, w - 1).astype(np.intp)
    lv = np.clip(np.rint(left[..., 1]), 0, h - 1).astype(np.intp)
    ru = np.clip(np.rint(right[..., 0]), 0, w - 1).astype(np.intp)
    rv = np.clip(np.rint(right[..., 1]), 0, h - 1).astype(np.intp)
    g = gray.astype(np.int32, copy=False) if gray.dtype != np.uint8 else gray
    diff = (g[lv, lu].astype(np.int32) - g[rv, ru].astype(np.int32)).sum(axis=1)
    out = seg.copy()
    flip = diff < 0
    out[flip] = seg[flip][:, [2, 3, 0, 1]]
    return out


def _connected_labels(m: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Connected-component labels (m,) of the undirected graph with edges ``(i[k], j[k])``.

    Min-label propagation along the edge list with pointer jumping (vectorised; a few
    iterations for merge graphs). Labels are the smallest member index of each component.
    """
    labels = np.arange(m)
    while True:
        new = labels.copy()
        np.minimum.at(new, i, labels[j])
        np.minimum.at(new, j, labels[i])
        new = new[new]                      # pointer jumping shortens long chains
        if np.array_equal(new, labels):
            return labels
        labels = new


def _angle_pairs(theta: np.ndarray, width: np.ndarray, period: float
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j)``, ``i != j``, with ``|theta_j - theta_i| <= width_i`` (periodic).

    ``theta`` (M,) angles in ``[0, period)``, ``width`` (M,) half-window per segment (rad, at
    most ``period / 2``). Sort + ``searchsorted`` on the angles tripled over three periods, so the
    cost follows the number of candidate pairs rather than M^2.
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


def merge_collinear(segments: np.ndarray, angle_deg: float = 2.0, offset_px: float = 1.5,
                    gap_px: float = 10.0, oriented: bool = False) -> np.ndarray:
    """Merge collinear fragments of the same line into single segments.

    Two segments ``(M, 4)`` px join when their directions differ by less than ``angle_deg``
    (or ``atan(offset_px / shorter length)`` when larger, capped at 20 deg: short fragments
    have noisy angles, and the endpoint test below bounds the angle anyway), every endpoint of
    each lies within ``offset_px`` of the other's infinite line, and the gap between their
    extents along the line is below ``gap_px`` (overlap allowed). Directions are compared as
    oriented when ``oriented``, else modulo 180 deg, so that pieces of one line whose contrast
    polarity flips (e.g. where stripes cross it) still join. Joined groups (transitively) are
    replaced by the total-least-squares line through the length-weighted segments, spanning the
    extreme endpoint projections and oriented like the length-weighted majority of its members;
    a group whose endpoints stray more than ``offset_px`` from that fit is left unmerged.
    Returns (K, 4) float32, K <= M, in the order of each output's first member.
    """
    s = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    m = s.shape[0]
    if m < 2:
        return s.astype(np.float32)
    x1, y1, x2, y2 = s.T                                      # 1-D columns index fastest
    dx, dy = x2 - x1, y2 - y1
    length = np.maximum(np.hypot(dx, dy), 1e-9)
    ux, uy = dx / length, dy / length                         # unit directions
    cx, cy = 0.5 * (x1 + x2), 0.5 * (y1 + y2)
    period = 2.0 * np.pi if oriented else np.pi
    theta = np.mod(np.arctan2(uy, ux), period)
    width = np.minimum(np.maximum(np.deg2rad(angle_deg), np.arctan2(offset_px, length)),
                       np.deg2rad(20.0))
    i, j = _angle_pairs(theta, width, period)
    # cheap spatial gate first: centres no further apart than half lengths + gap
    ok = np.hypot(cx[j] - cx[i], cy[j] - cy[i]) <= 0.5 * (length[i] + length[j]) + gap_px
    i, j = i[ok], j[ok]
    # exact angle test with the shorter segment's tolerance
    cosang = ux[i] * ux[j] + uy[i] * uy[j]
    if not oriented:
        cosang = np.abs(cosang)
    ok = cosang >= np.cos(np.maximum(width[i], width[j]))
    i, j = i[ok], j[ok]
    if i.size == 0:
        return s.astype(np.float32)
    # perpendicular distances (normal (-uy, ux)) of j's endpoints to line i and vice versa
    nxi, nyi, nxj, nyj = -uy[i], ux[i], -uy[j], ux[j]
    off_ij = np.maximum(np.abs((x1[j] - cx[i]) * nxi + (y1[j] - cy[i]) * nyi),
                        np.abs((x2[j] - cx[i]) * nxi + (y2[j] - cy[i]) * nyi))
    off_ji = np.maximum(np.abs((x1[i] - cx[j]) * nxj + (y1[i] - cy[j]) * nyj),
                        np.abs((x2[i] - cx[j]) * nxj + (y2[i] - cy[j]) * nyj))
    # gap between the extents along line i
    ti = 0.5 * length[i]
    a = (x1[j] - cx[i]) * ux[i] + (y1[j] - cy[i]) * uy[i]
    b = (x2[j] - cx[i]) * ux[i] + (y2[j] - cy[i]) * uy[i]
    gap = np.maximum(np.minimum(a, b) - ti, -ti - np.maximum(a, b))
    keep = (off_ij <= offset_px) & (off_ji <= offset_px) & (gap <= gap_px)
    if not keep.any():
        return s.astype(np.float32)
    labels = _connected_labels(m, i[keep], j[keep])
    uniq, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
    if counts.max() == 1:
        return s.astype(np.float32)
    return _fit_groups(s, inv, len(uniq), counts, offset_px).astype(np.float32)


def _fit_groups(s: np.ndarray, inv: np.ndarray, k: int, counts: np.ndarray,
                offset_px: float) -> np.ndarray:
    """Replace each multi-member group of segments (M, 4) by its TLS segment (see merge)."""
    p1, p2 = s[:, :2], s[:, 2:]
    d = p2 - p1
    w = np.hypot(d[:, 0], d[:, 1])
    # second moments of a uniform segment: mean c, covariance d d^T / 12
    c = 0.5 * (p1 + p2)
    W = np.bincount(inv, w, k)
    cx = np.bincount(inv, w * c[:, 0], k) / W
    cy = np.bincount(inv, w * c[:, 1], k) / W
    dx, dy = c[:, 0] - cx[inv], c[:, 1] - cy[inv]
    sxx = np.bincount(inv, w * (dx * dx + d[:, 0] ** 2 / 12.0), k)
    sxy = np.bincount(inv, w * (dx * dy + d[:, 0] * d[:, 1] / 12.0), k)
    syy = np.bincount(inv, w * (dy * dy + d[:, 1] ** 2 / 12.0), k)
    theta = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    ux, uy = np.cos(theta), np.sin(theta)
    # orientation of the length-weighted majority: sum of the members' signed projections
    proj = d[:, 0] * ux[inv] + d[:, 1] * uy[inv]
    flip = np.bincount(inv, proj, k) < 0
    ux, uy = np.where(flip, -ux, ux), np.where(flip, -uy, uy)
    pts = np.concatenate([p1, p2])                       # (2M, 2)
    g = np.concatenate([inv, inv])
    t = (pts[:, 0] - cx[g]) * ux[g] + (pts[:, 1] - cy[g]) * uy[g]
    r = np.abs(-(pts[:, 0] - cx[g]) * uy[g] + (pts[:, 1] - cy[g]) * ux[g])
    tmin = np.full(k, np.inf)
    tmax = np.full(k, -np.inf)
    rmax = np.zeros(k)
    np.minimum.at(tmin, g, t)
    np.maximum.at(tmax, g, t)
    np.maximum.at(rmax, g, r)
    merged = np.stack([cx + tmin * ux, cy + tmin * uy, cx + tmax * ux, cy + tmax * uy], axis=1)
    good = (counts > 1) & (rmax <= offset_px)
    # output: good merged groups (one row each) + all members of other groups
    first = np.full(k, s.shape[0])
    np.minimum.at(first, inv, np.arange(s.shape[0]))
    single = ~good[inv]
    rows = np.concatenate([s[single], merged[good]])
    order = np.argsort(np.concatenate([np.nonzero(single)[0], first[good]]), kind='stable')
    return rows[order]


class LineDetector:
    """Line segment detector with a choice of backend, collinear merging and a length floor.

    ``backend``:

    * ``'lsd'`` -- ``cv2.createLineSegmentDetector`` with its own Gaussian sub-sampling
      ``scale`` (the LSD paper's anti-aliased scale; 0.8 is OpenCV's default).
    * ``'lsd_resize'`` -- ``cv2.resize`` (INTER_AREA) by ``scale``, then LSD at scale 1.
    * ``'fld'`` / ``'edlines'`` -- ``cv2.ximgproc`` FastLineDetector / EdgeDrawing on the
      image resized by ``scale`` (need opencv-contrib).
    * a callable ``gray (H, W) uint8 -> (M, 4)`` segments px, used as is (``scale`` ignored).

    Segments shorter than ``min_length`` px (full-resolution pixels) are dropped after merging.
    """

    def __init__(self, min_length: float = 20.0, scale: float = 1.0, backend: Backend = 'lsd',
                 merge: bool = True, merge_angle_deg: float = 2.0, merge_offset_px: float = 2.0,
                 merge_gap_px: float = 15.0, merge_oriented: bool = False, orient: bool = True,
                 refine: bool = True) -> None:
        if not min_length >= 0:
            raise ValueError(f'min_length must be >= 0, got {min_length}')
        if not 0.0 < scale <= 1.0:
            raise ValueError(f'scale must be in (0, 1], got {scale}')
        if not callable(backend) and backend not in BACKENDS:
            raise ValueError(f'unknown backend {backend!r}; expected one of {BACKENDS} '
                             'or a callable')
        self.min_length = float(min_length)
        self.scale = float(scale)
        self.backend = backend
        self.merge = bool(merge)
        self.merge_angle_deg = float(merge_angle_deg)
        self.merge_offset_px = float(merge_offset_px)
        self.merge_gap_px = float(merge_gap_px)
        self.merge_oriented = bool(merge_oriented) and bool(orient)
        self.orient = bool(orient)
        self._impl = self._make_backend(backend, refine)

    def _make_backend(self, backend: Backend,
                      refine: bool) -> Callable[[np.ndarray], Optional[np.ndarray]]:
        ref = cv2.LSD_REFINE_STD if refine else cv2.LSD_REFINE_NONE
        if callable(backend):
            return backend
        if backend == 'lsd':
            lsd = cv2.createLineSegmentDetector(ref, self.scale)
            # OpenCV's LSD reports scaled coordinates shifted by -(1/scale - 1)/2 px (measured
            # on ideal step edges: -0.125 px at 0.8, -0.5 px at 0.5); put them on pixel centres
            shift = np.float32(0.5 * (1.0 / self.scale - 1.0))

            def run_lsd(g: np.ndarray) -> Optional[np.ndarray]:
                out = lsd.detect(g)[0]
                return None if out is None else out.reshape(-1, 4) + shift
            return run_lsd
        if backend in ('fld', 'edlines'):
            if not hasattr(cv2, 'ximgproc'):
                raise ValueError(f'backend {backend!r} needs opencv-contrib (cv2.ximgproc)')
        if backend == 'lsd_resize':
            det = cv2.createLineSegmentDetector(ref, 1.0)
            run = (lambda g: det.detect(g)[0])
        elif backend == 'fld':
            fld = cv2.ximgproc.createFastLineDetector(
                max(int(self.min_length * self.scale * 0.5), 5))
            run = fld.detect
        else:
            ed = cv2.ximgproc.createEdgeDrawing()
            p = cv2.ximgproc.EdgeDrawing.Params()
            p.MinLineLength = max(int(self.min_length * self.scale * 0.5), 5)
            ed.setParams(p)

            def run(g: np.ndarray) -> Optional[np.ndarray]:
                ed.detectEdges(g)
                return ed.detectLines()
        if self.scale == 1.0:
            return run
        f = self.scale

        def scaled(g: np.ndarray) -> Optional[np.ndarray]:
            small = cv2.resize(g, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)
            out = run(small)
            if out is None or len(out) == 0:
                return out
            # pixel centres: u_full = (u_small + 0.5) / f - 0.5
            return (np.asarray(out, dtype=np.float32).reshape(-1, 4) + 0.5) / f - 0.5
        return scaled

    def detect(self, gray: np.ndarray) -> np.ndarray:
        """Detect segments in ``gray`` (H, W) uint8; return (M, 4) float32 ``(u1, v1, u2, v2)``.

        Segments are oriented (brighter side on the left, see the module docstring) when
        ``orient``, collinear fragments merged when ``merge``, and at least ``min_length`` px
        long. Raises ``ValueError`` for a non-2D or non-uint8 image.
        """
        if gray.ndim != 2 or gray.dtype != np.uint8:
            raise ValueError(f'expected a (H, W) uint8 gray image, got {gray.dtype} '
                             f'{gray.shape}')
        raw = self._impl(gray)
        if raw is None or len(raw) == 0:
            return np.zeros((0, 4), np.float32)
        seg = np.asarray(raw, dtype=np.float32).reshape(-1, 4)
        # drop fragments too short to matter even after merging (cheap pre-filter)
        seg = seg[segment_lengths(seg) >= min(4.0, self.min_length)]
        if self.orient:
            seg = orient_by_polarity(gray, seg)
        if self.merge and seg.shape[0] > 1:
            seg = merge_collinear(seg, self.merge_angle_deg, self.merge_offset_px,
                                  self.merge_gap_px, oriented=self.merge_oriented)
        return np.ascontiguousarray(seg[segment_lengths(seg) >= self.min_length],
                                    dtype=np.float32)
