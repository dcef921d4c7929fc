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

Edges crossed by other edges at short intervals (cross-hatched patterns: tiles, grids,
shelving; in the rendered scenes, faces striped in two directions) come out of LSD in pieces
too small for it to report: LSD grows a line's support region over connected pixels whose
gradient is aligned with it, a crossing edge's pixels are not, and regions under ~15 pixels are
dropped as not meaningful. :func:`bridge_crossings` finds such lines from the gradient pixels
the reported segments leave unexplained, joining their pieces across gaps where a reported
segment crosses.
"""
from functools import lru_cache
from typing import Callable, Optional, Tuple, Union

import cv2
import numpy as np

#: Backends understood by :class:`LineDetector` (``fld``/``edlines`` need opencv-contrib).
BACKENDS = ('lsd', 'lsd_resize', 'fld', 'edlines')

Backend = Union[str, Callable[[np.ndarray], np.ndarray]]


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


#: Hough angle bins over 180 deg (3 deg) and the coarser direction groups (15 deg) that decide
#: whether a gradient pixel is explained by a reported segment (same group or a neighbour).
_HOUGH_BINS = 60
_GROUPS = 12


@lru_cache(maxsize=1)
def _group_luts() -> Tuple[np.ndarray, np.ndarray]:
    """Lookup tables (256,) uint8 for :func:`bridge_crossings`.

    ``fold``: an angle index in units of ``180 / _GROUPS`` deg over 360 deg -> its group mod
    180 deg. ``resid``: key ``group * (_GROUPS + 1) + label`` (label 0 = no segment, else a
    segment's group + 1) -> 255 where the pixel is *not* explained (no segment there, or one
    more than a group away in direction), else 0.
    """
    k = np.arange(256)
    fold = (k % _GROUPS).astype(np.uint8)
    grp, lab = k // (_GROUPS + 1), k % (_GROUPS + 1)
    dg = np.mod(grp - (lab - 1), _GROUPS)
    explained = (lab > 0) & ((dg <= 1) | (dg >= _GROUPS - 1))
    return fold, np.where(explained | (grp >= _GROUPS), 0, 255).astype(np.uint8)


@lru_cache(maxsize=4)
def _square(size: int) -> np.ndarray:
    """Rectangular structuring element ``size`` x ``size`` (cached: built per call otherwise)."""
    return cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))


class _Buffers:
    """Whole-image arrays of one shape, kept in a caller's dict and reused between calls."""

    def __init__(self, scratch: Optional[dict], shape: Tuple[int, int]) -> None:
        self.store = scratch if scratch is not None else {}
        self.shape = shape

    def __call__(self, name: str, dtype: type) -> np.ndarray:
        a = self.store.get(name)
        if a is None or a.shape != self.shape or a.dtype != dtype:
            a = self.store[name] = np.empty(self.shape, dtype)
        return a


def bridge_crossings(gray: np.ndarray, segments: np.ndarray, min_length: float = 20.0,
                     gap_px: float = 12.0, min_cross_deg: float = 30.0,
                     min_gradient: float = 4.0, min_votes: int = 20, min_density: float = 0.5,
                     near_px: int = 8, scratch: Optional[dict] = None) -> np.ndarray:
    """Find lines whose edge pixels are interrupted where reported segments cross them.

    ``gray`` (H, W) uint8; ``segments`` (M, 4) px, the lines already found (e.g. LSD's). Returns
    (K, 4) float32 px of further lines, unoriented.

    Candidate pixels have a normalised Sobel gradient of at least ``min_gradient`` grey levels
    per px, lie within ``near_px`` of a segment and are not explained by one (no segment of
    about their edge direction, within 15-30 deg, passes within 1 px). Each votes in a Hough
    accumulator at its own normal angle (+-1 bin of 3 deg), so that pixels of one line vote
    together even where crossings cut it into pieces; peaks of at least ``min_votes`` collect
    the pixels within 1.5 px of their line. Along each line, pixels more than 3 px apart stay
    joined only when a segment crosses the line in between (at ``min_cross_deg`` or more, or
    ends on it) and they are at most ``gap_px`` apart. A resulting run becomes a line (the
    gradient-weighted TLS fit of its pixels) when it bridges at least one crossing, spans at
    least ``min_length`` px and has at least ``min_density`` pixels per px of length (the
    gradient ridge is 2-3 px wide, so 0.5 is about a quarter of the length supported):
    lines LSD could find on its own are not this function's business, and gaps without a
    crossing are not bridged, which keeps chance alignments in clutter out.

    ``scratch``: a dict the caller keeps between calls (e.g. one per detector), in which the
    whole-image intermediates (~6 MB at 640x480) are kept and reused. Allocated afresh on every
    call, their pages are faulted in anew each time (glibc returns large freed blocks to the
    system): about 1400 page faults per call, about half of this function's CPU time in a loop
    over 640x480 detection frames.
    """
    empty = np.zeros((0, 4), np.float32)
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    if seg.shape[0] == 0:
        return empty
    h, w = gray.shape[:2]
    d = seg[:, 2:] - seg[:, :2]
    # each segment's normal direction group, drawn 3 px wide as label group + 1
    sgrp = np.minimum((np.mod(np.arctan2(d[:, 0], -d[:, 1]), np.pi) * (_GROUPS / np.pi))
                      .astype(np.intp), _GROUPS - 1)
    pts = np.rint(seg.reshape(-1, 2, 2)).astype(np.int32)
    buf = _Buffers(scratch, (h, w))
    label = buf('label', np.uint8)
    label[...] = 0
    order = np.argsort(sgrp, kind='stable')
    bounds = np.searchsorted(sgrp[order], np.arange(_GROUPS + 1))
    for g in np.nonzero(np.diff(bounds))[0]:        # one call per direction group (<= 12)
        cv2.polylines(label, list(pts[order[bounds[g]:bounds[g + 1]]]), False, int(g) + 1, 3)
    near = cv2.dilate(cv2.compare(label, 0, cv2.CMP_GT, dst=buf('u8a', np.uint8)),
                      _square(2 * near_px - 1), dst=buf('near', np.uint8))
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, dst=buf('gx', np.float32), ksize=3)
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, dst=buf('gy', np.float32), ksize=3)
    mag = cv2.magnitude(gx, gy, magnitude=buf('mag', np.float32))
    phase = cv2.phase(gx, gy, angle=buf('phase', np.float32))   # rad in [0, 2 pi)
    # whole-image uint8 ops (cheap) rather than per-pixel numpy: group of every pixel, then
    # explained or not from its group and the label under it
    fold, resid = _group_luts()
    u8a, u8b = buf('u8a', np.uint8), buf('u8b', np.uint8)
    grp = cv2.LUT(cv2.convertScaleAbs(phase, dst=u8a, alpha=_GROUPS / np.pi, beta=-0.5), fold,
                  dst=u8b)
    cand = cv2.LUT(cv2.scaleAdd(grp, float(_GROUPS + 1), label, dst=u8a), resid, dst=u8b)
    # near is 0 / 255, so a plain AND masks (a masked op would leave the reused dst unset)
    cand = cv2.bitwise_and(cand, near, dst=u8b)
    cand = cv2.bitwise_and(cand, cv2.compare(mag, 8.0 * min_gradient, cv2.CMP_GE, dst=u8a),
                           dst=u8b)
    nz = cv2.findNonZero(cand)
    if nz is None or len(nz) < min_votes:
        return empty
    xs, ys = nz.reshape(-1, 2).T.astype(np.intp)
    theta = np.mod(phase[ys, xs].astype(np.float64), np.pi)    # normal angle mod 180 deg
    wgt = mag[ys, xs].astype(np.float64)
    nb = _HOUGH_BINS
    bins = np.mod(np.minimum((theta * (nb / np.pi)).astype(np.intp), nb - 1)[:, None]
                  + np.arange(-1, 2), nb)                        # (P, 3)
    centre = (np.arange(nb) + 0.5) * (np.pi / nb)
    cos_b, sin_b = np.cos(centre), np.sin(centre)
    rmax = int(np.ceil(np.hypot(h, w))) + 2
    nr = 2 * rmax + 1
    cell = bins * nr + rmax + np.rint(xs[:, None] * cos_b[bins]
                                      + ys[:, None] * sin_b[bins]).astype(np.intp)
    acc = np.bincount(cell.ravel(), minlength=nb * nr).reshape(nb, nr).astype(np.float32)
    acc[:, 1:-1] += acc[:, :-2] + acc[:, 2:]        # integer pixels: a line spreads over 3 px
    # local maxima over +-1 bin and +-2 px; the angle wraps at 180 deg where rho changes sign
    pad = np.concatenate([acc[-1:, ::-1], acc, acc[:1, ::-1]])
    top = cv2.dilate(pad, np.ones((3, 5), np.uint8))[1:-1]
    pb, pr = np.nonzero((acc >= min_votes) & (acc >= top))
    if pb.size == 0:
        return empty
    n_c = pb.size
    # pixels voting within 1 px of a peak belong to it (the peak's own cell wins a tie)
    owner = np.full(nb * nr, -1, np.intp)
    for dr in (1, -1, 0):
        owner[pb * nr + pr + dr] = np.arange(n_c)
    c3 = owner[cell]
    c3[:, 1] = np.where(c3[:, 1] == c3[:, 0], -1, c3[:, 1])
    c3[:, 2] = np.where((c3[:, 2] == c3[:, 0]) | (c3[:, 2] == c3[:, 1]), -1, c3[:, 2])
    pix, col = np.nonzero(c3 >= 0)
    c = c3[pix, col]
    nx, ny, rho = cos_b[pb], sin_b[pb], (pr - rmax).astype(np.float64)
    px, py, pw = xs[pix].astype(np.float64), ys[pix].astype(np.float64), wgt[pix]
    keep = np.abs(px * nx[c] + py * ny[c] - rho[c]) <= 1.5
    c, px, py, pw = c[keep], px[keep], py[keep], pw[keep]
    if c.size == 0:
        return empty
    t = py * nx[c] - px * ny[c]                                  # position along the line
    # by line, then along it: one sort of a combined key (|t| < rmax, so lines do not mix),
    # the order of lexsort((t, c)) at a fraction of its cost; no two pixels of one line share
    # a t (the bins' angles have irrational slopes), so the unstable sort has no ties to break
    span = 4.0 * rmax
    o = np.argsort(c * span + t)
    c, px, py, pw, t = c[o], px[o], py[o], pw[o], t[o]
    same = c[1:] == c[:-1]
    gap = t[1:] - t[:-1]
    crossed = np.zeros(gap.size, bool)
    gi = np.nonzero(same & (gap > 3.0) & (gap <= gap_px))[0]
    if gi.size:
        # where segments cross the candidate lines (or end within 2 px of them), as
        # positions along each line, sorted per line; a gap is bridged when one lies in it
        # only the lines with such a gap: the others ask for no crossing
        lines = c[gi]                              # c is sorted: the first of each run
        lines = lines[np.append(True, lines[1:] != lines[:-1])]
        cj, sj = np.divmod(np.arange(lines.size * seg.shape[0]), seg.shape[0])
        cj = lines[cj]
        da = seg[sj, 0] * nx[cj] + seg[sj, 1] * ny[cj] - rho[cj]
        db = seg[sj, 2] * nx[cj] + seg[sj, 3] * ny[cj] - rho[cj]
        length = np.maximum(np.hypot(d[sj, 0], d[sj, 1]), 1e-9)
        f = da / np.where(da != db, da - db, 1.0)               # crossing point along sj
        hit = ((np.abs(da - db) >= np.sin(np.deg2rad(min_cross_deg)) * length)
               & (f >= -2.0 / length) & (f <= 1.0 + 2.0 / length))
        cj, sj, f = cj[hit], sj[hit], f[hit]
        tx = ((seg[sj, 1] + f * d[sj, 1]) * nx[cj] - (seg[sj, 0] + f * d[sj, 0]) * ny[cj])
        key = np.sort(cj * span + tx)
        lo = np.searchsorted(key, c[gi] * span + t[gi] - 1.0, 'left')
        hi = np.searchsorted(key, c[gi] * span + t[gi + 1] + 1.0, 'right')
        crossed[gi] = hi > lo
    join = same & ((gap <= 3.0) | crossed)
    start = np.ones(c.size, bool)
    start[1:] = ~join
    run = np.cumsum(start) - 1
    first = np.nonzero(start)[0]
    count = np.diff(np.append(first, c.size))
    extent = np.maximum.reduceat(t, first) - t[first] + 1.0
    bridged = np.bincount(run[1:][crossed & join], minlength=first.size)
    good = (bridged >= 1) & (extent >= min_length) & (count >= min_density * extent)
    if not good.any():
        return empty
    sel = good[run]
    r = np.cumsum(good)[run[sel]] - 1
    k = int(good.sum())
    px, py, pw = px[sel], py[sel], pw[sel]
    sw = np.bincount(r, pw, k)
    cx = np.bincount(r, pw * px, k) / sw
    cy = np.bincount(r, pw * py, k) / sw
    dx, dy = px - cx[r], py - cy[r]
    ang = 0.5 * np.arctan2(2.0 * np.bincount(r, pw * dx * dy, k),
                           np.bincount(r, pw * (dx * dx - dy * dy), k))
    ux, uy = np.cos(ang), np.sin(ang)
    tt = dx * ux[r] + dy * uy[r]
    tmin = np.full(k, np.inf)
    tmax = np.full(k, -np.inf)
    np.minimum.at(tmin, r, tt)
    np.maximum.at(tmax, r, tt)
    return np.stack([cx + tmin * ux, cy + tmin * uy, cx + tmax * ux, cy + tmax * uy],
                    axis=1).astype(np.float32)


def _rows_not_in(seg: np.ndarray, base: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """Mask (M,) of the segments ``seg`` (M, 4) px that are no row of ``base`` (B, 4) px.

    Rows count as equal within ``tol`` px per coordinate (merging passes a segment without
    partners through unchanged, up to its float32 conversion).
    """
    if base.shape[0] == 0 or seg.shape[0] == 0:
        return np.ones(seg.shape[0], bool)
    # candidates by the first coordinate only (sorted), then all four: the dense (M, B, 4)
    # comparison cost ~0.8 ms per 640x480 detection frame, this ~0.07 ms
    order = np.argsort(base[:, 0], kind='stable')
    b0 = base[order, 0]
    lo = np.searchsorted(b0, seg[:, 0] - tol, 'left')
    cnt = np.searchsorted(b0, seg[:, 0] + tol, 'right') - lo
    i = np.repeat(np.arange(seg.shape[0]), cnt)
    k = lo[i] + np.arange(i.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    same = np.abs(seg[i] - base[order[k]]).max(axis=1) <= tol
    out = np.ones(seg.shape[0], bool)
    out[i[same]] = False
    return out


def _covers_any(seg: np.ndarray, base: np.ndarray, angle_deg: float = 2.0,
                offset_px: float = 2.0) -> np.ndarray:
    """Mask (M,) of segments ``seg`` (M, 4) px on which the centre of a ``base`` (B, 4) lies.

    A base segment's centre lies on a segment when it is within ``offset_px`` of the segment's
    line, projects inside its extent, and the two directions differ by at most ``angle_deg``.
    """
    if base.shape[0] == 0 or seg.shape[0] == 0:
        return np.zeros(seg.shape[0], bool)
    s = seg.astype(np.float64)
    b = base.astype(np.float64)
    length = np.maximum(segment_lengths(s), 1e-9)
    u = (s[:, 2:] - s[:, :2]) / length[:, None]                                 # (M, 2)
    bu = (b[:, 2:] - b[:, :2]) / np.maximum(segment_lengths(b), 1e-9)[:, None]  # (B, 2)
    r = 0.5 * (b[None, :, :2] + b[None, :, 2:]) - s[:, None, :2]                # (M, B, 2)
    t = r[..., 0] * u[:, 0:1] + r[..., 1] * u[:, 1:2]
    off = np.abs(r[..., 0] * u[:, 1:2] - r[..., 1] * u[:, 0:1])
    hit = ((np.abs(u @ bu.T) >= np.cos(np.deg2rad(angle_deg))) & (off <= offset_px)
           & (t >= 0.0) & (t <= length[:, None]))
    return hit.any(axis=1)


class LineDetector:
    """Line segment detector with a choice of backend, collinear merging and a length floor.

    ``backend``:

    * ``'lsd'`` -- ``cv2.createLineSegmentDetector`` with its own Gaussian sub-sampling
      ``scale`` (the LSD paper's anti-aliased scale; 0.8 is OpenCV's default).
    * ``'lsd_resize'`` (the default, at ``scale`` 0.8) -- ``cv2.resize`` (INTER_AREA) by
      ``scale``, then LSD at scale 1. The area average takes out most of the sensor noise,
      in which LSD at full resolution spends much of its time, while edges a few px apart
      stay apart: on the rendered 640x480 sequences (render seeds 0-9, every 3rd frame in
      the tracker) it tracks as many edges as full-resolution LSD (tracked-5 0.937 / 0.931
      on seeds 0-3 / 4-9 vs 0.937 / 0.932, id switches 0.53 / 0.52 % vs 0.52 / 0.51 %) for
      20-28 % less front-end CPU per frame (mean), with line errors ~10 % larger (0.05-0.09
      px). 0.9 and 0.7 were both worse (0.933 / 0.927 on seeds 0-3), 0.5 lost 2 points, and
      LSD's own Gaussian sub-sampling at 0.8 (``'lsd'``) lost 1 point.
    * ``'fld'`` / ``'edlines'`` -- ``cv2.ximgproc`` FastLineDetector / EdgeDrawing on the
      image resized by ``scale`` (need opencv-contrib). FLD at scale 1 with ``bridge``, in the
      tracker: as many edges tracked as the default (tracked-5 / id switches, render seeds
      0-3 / 4-9: 0.930 / 0.52 % and 0.937 / 0.48 % vs 0.937 / 0.53 % and 0.931 / 0.52 %),
      a third less front-end CPU per frame (mean), line errors ~30 % and endpoint errors
      40-110 % larger. Without ``bridge`` it misses 5 points of the edges.
    * a callable ``gray (H, W) uint8 -> (M, 4)`` segments px, used as is (``scale`` ignored).

    Segments shorter than ``min_length`` px (full-resolution pixels) are dropped after merging.

    ``bridge``: add the lines that :func:`bridge_crossings` finds where the backend's segments
    cross them (gaps up to ``bridge_gap_px``; the segments of at least ``min_length`` px are the
    crossings; short fragments are dropped first). ~4 ms more CPU per 640x480 detection frame
    (LSD on the image resized by 0.8: ~15 ms); the real sequences gain 0-7 segments per frame.
    ``bridge_join``: the bridged lines are merged with the reported segments they continue
    (beyond a crossing), which lifted the detector's recall on the rendered seeds 0-3 (every
    3rd frame) of stripe edges on faces striped in two directions from 0.904 to 0.945 and of
    box edges from 0.930 to 0.966 (precision 0.991 -> 0.990). Off (the default), a bridged
    line is added only where no reported segment's centre lies on it (after the merge), so
    only the lines the backend missed altogether are added and reported ones keep their
    extent: in the tracker the joined extents, longer by the bridged pieces beyond a
    crossing, cost own_centre id switches (tracked-5 / switches, rendered seeds 0-5 with
    joining vs without: own_centre s4 0.909 / 0.98 % vs 0.909 / 0.87 %, s5 0.938 / 0.59 % vs
    0.943 / 0.43 %), while the missed lines are what camera_centre s3 needs (0.946 vs 0.947;
    no bridge: 0.894). On by default since the tracker meets the issue #3 goal on 11 of the 12
    rendered sequences with it, 10 without (see ``docs/design.md``).

    ``lsd_bins``: the number of gradient-norm bins in which LSD orders its seed pixels
    (OpenCV's ``n_bins``, 1024 there and here; backends ``lsd`` and ``lsd_resize``). LSD
    sorts every pixel by its bin, and on a noisy image that sort is most of its time: 32 bins
    take LSD on the image resized by 0.8 from ~11 to ~6.7 ms (640x480, noise sigma 2; a flat
    image: 3.2 ms) with the same segments to within a few. In the tracker (session 17,
    rendered 640x480, render seeds 0-3 / 4-9, tracked-5 / id switches pooled) 32 bins gave
    0.930 / 0.58 % and 0.930 / 0.57 % against 0.930 / 0.56 % and 0.930 / 0.54 % (13 instead
    of 15 of the 20 sequences meeting issue #3 alone; 16 bins: 0.929 / 0.54 %, 0.932 /
    0.57 %), the whole pipeline's mean frame 0.50-0.56x LSD alone against 0.53-0.54x (150
    frames; the gain is within the machine's noise), and the spinning boxes (issue #6,
    `general`, 30 frames) 1-1.3 points more wrong on average over six seeds (own2+bg 5.7 vs
    4.4 %, own3+bg 7.4 vs 6.2 %; 16 bins was worse on five of five own3+bg seeds). So the
    default stays 1024.
    """

    def __init__(self, min_length: float = 20.0, scale: float = 0.8,
                 backend: Backend = 'lsd_resize',
                 merge: bool = True, merge_angle_deg: float = 2.0, merge_offset_px: float = 2.0,
                 merge_gap_px: float = 15.0, merge_oriented: bool = False, orient: bool = True,
                 refine: bool = True, bridge: bool = True, bridge_gap_px: float = 12.0,
                 bridge_join: bool = False, lsd_bins: int = 1024) -> None:
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
        self.bridge = bool(bridge)
        if not bridge_gap_px > 3.0:
            raise ValueError(f'bridge_gap_px must be > 3, got {bridge_gap_px}')
        self.bridge_gap_px = float(bridge_gap_px)
        self.bridge_join = bool(bridge_join)
        if int(lsd_bins) < 1:
            raise ValueError(f'lsd_bins must be >= 1, got {lsd_bins}')
        self.lsd_bins = int(lsd_bins)
        self._scratch: dict = {}                 # bridge_crossings' reused image buffers
        self._region_scratch: dict = {}          # the same for detect_regions' crops
        self._impl = self._make_backend(backend, refine)

    def _make_backend(self, backend: Backend,
                      refine: bool) -> Callable[[np.ndarray], Optional[np.ndarray]]:
        ref = cv2.LSD_REFINE_STD if refine else cv2.LSD_REFINE_NONE
        if callable(backend):
            return backend
        # OpenCV's defaults after refine and scale: sigma_scale, quant, ang_th, log_eps,
        # density_th; then n_bins, the number of gradient-norm bins LSD sorts pixels into
        lsd_args = (0.6, 2.0, 22.5, 0.0, 0.7, self.lsd_bins)
        if backend == 'lsd':
            lsd = cv2.createLineSegmentDetector(ref, self.scale, *lsd_args)
            # OpenCV's LSD reports scaled coordinates shifted by -(1/scale - 1)/2 px (measured
            # on ideal step edges: -0.125 px at 0.8, -0.5 px at 0.5); put them on pixel centres
            shift = np.float32(0.5 * (1.0 / self.scale - 1.0))

            def run_lsd(g: np.ndarray) -> Optional[np.ndarray]:
                out = lsd.detect(g)[0]
                return None if out is None else out.reshape(-1, 4) + shift
            return run_lsd
        if backend in ('fld', 'edlines'):
            if not has_ximgproc():
                raise ValueError(f'backend {backend!r} needs opencv-contrib (cv2.ximgproc)')
        if backend == 'lsd_resize':
            det = cv2.createLineSegmentDetector(ref, 1.0, *lsd_args)
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
        ``orient``, collinear fragments merged when ``merge``, lines cut up by crossings added
        when ``bridge``, and at least ``min_length`` px long. Raises ``ValueError`` for a
        non-2D or non-uint8 image.
        """
        check_gray(gray)
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
        seg = seg[segment_lengths(seg) >= self.min_length]
        if self.bridge and seg.shape[0] > 0:
            extra = bridge_crossings(gray, seg, self.min_length, self.bridge_gap_px,
                                     scratch=self._scratch)
            if extra.shape[0] > 0:
                if self.orient:
                    extra = orient_by_polarity(gray, extra)
                both = np.concatenate([seg, extra.astype(seg.dtype)])
                # an added line may continue a reported one beyond a crossing: join them
                if self.merge:
                    both = merge_collinear(both, self.merge_angle_deg, self.merge_offset_px,
                                           self.merge_gap_px, oriented=self.merge_oriented)
                # a bridged line's fitted extent may fall a hair short of its pixel span
                both = both[segment_lengths(both) >= self.min_length]
                if self.bridge_join:
                    seg = both
                else:
                    # only lines the backend missed altogether: a reported segment joined
                    # with bridged pieces stays as reported (see the class docstring)
                    new = _rows_not_in(both, seg)
                    new[new] = ~_covers_any(both[new], seg)
                    seg = np.concatenate([seg, both[new]])
        return np.ascontiguousarray(seg, dtype=np.float32)

    def detect_regions(self, gray: np.ndarray, boxes: np.ndarray, clip_px: float = 2.0
                       ) -> Tuple[np.ndarray, np.ndarray]:
        """Detect in rectangles of ``gray`` only: ``(segments (M, 4) float32, clipped (M,))``.

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
