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
Lines cut into pieces by crossing edges, found from the gradient pixels segments leave over.

Edges crossed by other edges at short intervals (cross-hatched patterns: tiles, grids,
shelving; in the rendered scenes, faces striped in two directions) come out of LSD in pieces
too small for it to report: LSD grows a line's support region over connected pixels whose
gradient is aligned with it, a crossing edge's pixels are not, and regions under ~15 pixels are
dropped as not meaningful. :func:`bridge_crossings` finds such lines from the gradient pixels
the reported segments leave unexplained, joining their pieces across gaps where a reported
segment crosses.
"""
from functools import lru_cache
from typing import NamedTuple, Optional, Tuple

import cv2
from mlofc_ros.segments.common import square_kernel
import numpy as np

#: Hough angle bins over 180 deg (3 deg each).
HOUGH_BINS = 60
#: Direction groups (15 deg each) that decide whether a gradient pixel is explained by a
#: reported segment (same group or a neighbour).
_GROUPS = 12
#: Pixels of one line closer than this (px along it) always belong to one run.
_JOIN_PX = 3.0


@lru_cache(maxsize=1)
def _group_luts() -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the lookup tables (256,) uint8 ``fold`` and ``resid``.

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


class _Pixels(NamedTuple):
    """Candidate pixels: columns, rows (P,) intp, normal angles mod pi (P,), gradients (P,)."""

    xs: np.ndarray
    ys: np.ndarray
    theta: np.ndarray
    weight: np.ndarray


class _Lines(NamedTuple):
    """Hough peak lines ``x nx + y ny = rho`` (C,) and the pixels on them, sorted along each."""

    nx: np.ndarray
    ny: np.ndarray
    rho: np.ndarray
    c: np.ndarray       # (Q,) line of each pixel
    px: np.ndarray      # (Q,) pixel x, y, gradient weight and position along its line
    py: np.ndarray
    pw: np.ndarray
    t: np.ndarray


def bridge_crossings(gray: np.ndarray, segments: np.ndarray, min_length: float = 20.0,
                     gap_px: float = 12.0, min_cross_deg: float = 30.0,
                     min_gradient: float = 4.0, min_votes: int = 20, min_density: float = 0.5,
                     near_px: int = 8, scratch: Optional[dict] = None) -> np.ndarray:
    """
    Find lines whose edge pixels are interrupted where reported segments cross them.

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
    pix = _candidate_pixels(gray, seg, min_gradient, near_px, _Buffers(scratch, gray.shape[:2]))
    if pix is None or pix.xs.size < min_votes:
        return empty
    lines = _hough_lines(pix, gray.shape[:2], min_votes)
    if lines is None:
        return empty
    span = _key_span(gray.shape[:2])
    same = lines.c[1:] == lines.c[:-1]
    gap = lines.t[1:] - lines.t[:-1]
    crossed = _crossed_gaps(lines, seg, same, gap, gap_px, min_cross_deg, span)
    join = same & ((gap <= _JOIN_PX) | crossed)
    start = np.ones(lines.c.size, bool)
    start[1:] = ~join
    run = np.cumsum(start) - 1
    first = np.nonzero(start)[0]
    count = np.diff(np.append(first, lines.c.size))
    extent = np.maximum.reduceat(lines.t, first) - lines.t[first] + 1.0
    bridged = np.bincount(run[1:][crossed & join], minlength=first.size)
    good = (bridged >= 1) & (extent >= min_length) & (count >= min_density * extent)
    if not good.any():
        return empty
    sel = good[run]
    return _fit_runs(np.cumsum(good)[run[sel]] - 1, int(good.sum()), lines.px[sel],
                     lines.py[sel], lines.pw[sel])


def _candidate_pixels(gray: np.ndarray, seg: np.ndarray, min_gradient: float, near_px: int,
                      buf: _Buffers) -> Optional[_Pixels]:
    """
    Return the gradient pixels near the segments ``seg`` (M, 4) that none of them explains.

    Whole-image uint8 operations (cheap) rather than per-pixel numpy: the direction group of
    every pixel, then explained or not from its group and the segment label under it.
    """
    d = seg[:, 2:] - seg[:, :2]
    # each segment's normal direction group, drawn 3 px wide as label group + 1
    sgrp = np.minimum((np.mod(np.arctan2(d[:, 0], -d[:, 1]), np.pi) * (_GROUPS / np.pi))
                      .astype(np.intp), _GROUPS - 1)
    pts = np.rint(seg.reshape(-1, 2, 2)).astype(np.int32)
    label = buf('label', np.uint8)
    label[...] = 0
    order = np.argsort(sgrp, kind='stable')
    bounds = np.searchsorted(sgrp[order], np.arange(_GROUPS + 1))
    for g in np.nonzero(np.diff(bounds))[0]:        # one call per direction group (<= 12)
        cv2.polylines(label, list(pts[order[bounds[g]:bounds[g + 1]]]), False, int(g) + 1, 3)
    near = cv2.dilate(cv2.compare(label, 0, cv2.CMP_GT, dst=buf('u8a', np.uint8)),
                      square_kernel(2 * near_px - 1), dst=buf('near', np.uint8))
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, dst=buf('gx', np.float32), ksize=3)
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, dst=buf('gy', np.float32), ksize=3)
    mag = cv2.magnitude(gx, gy, magnitude=buf('mag', np.float32))
    phase = cv2.phase(gx, gy, angle=buf('phase', np.float32))   # rad in [0, 2 pi)
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
    if nz is None:
        return None
    xs, ys = nz.reshape(-1, 2).T.astype(np.intp)
    return _Pixels(xs, ys, np.mod(phase[ys, xs].astype(np.float64), np.pi),
                   mag[ys, xs].astype(np.float64))


def _key_span(shape: Tuple[int, int]) -> float:
    """Return the span of one line's positions in the combined sort key (line * span + t)."""
    return 4.0 * (int(np.ceil(np.hypot(*shape))) + 2)


def _hough_lines(pix: _Pixels, shape: Tuple[int, int], min_votes: int) -> Optional[_Lines]:
    """
    Return the Hough peaks of the pixels ``pix`` and their pixels sorted along each, or None.

    Each pixel votes at its own normal angle +-1 bin; the peaks are local maxima over +-1 bin
    and +-2 px with at least ``min_votes``; a pixel belongs to the peaks within 1 px of its
    vote (the peak's own cell wins a tie) whose line passes within 1.5 px of it.
    """
    h, w = shape
    nb = HOUGH_BINS
    bins = np.mod(np.minimum((pix.theta * (nb / np.pi)).astype(np.intp), nb - 1)[:, None]
                  + np.arange(-1, 2), nb)                        # (P, 3)
    centre = (np.arange(nb) + 0.5) * (np.pi / nb)
    cos_b, sin_b = np.cos(centre), np.sin(centre)
    rmax = int(np.ceil(np.hypot(h, w))) + 2
    nr = 2 * rmax + 1
    cell = bins * nr + rmax + np.rint(pix.xs[:, None] * cos_b[bins]
                                      + pix.ys[:, None] * sin_b[bins]).astype(np.intp)
    acc = np.bincount(cell.ravel(), minlength=nb * nr).reshape(nb, nr).astype(np.float32)
    acc[:, 1:-1] += acc[:, :-2] + acc[:, 2:]        # integer pixels: a line spreads over 3 px
    # local maxima over +-1 bin and +-2 px; the angle wraps at 180 deg where rho changes sign
    pad = np.concatenate([acc[-1:, ::-1], acc, acc[:1, ::-1]])
    top = cv2.dilate(pad, np.ones((3, 5), np.uint8))[1:-1]
    pb, pr = np.nonzero((acc >= min_votes) & (acc >= top))
    if pb.size == 0:
        return None
    owner = np.full(nb * nr, -1, np.intp)
    for dr in (1, -1, 0):                           # the peak's own cell written last: it wins
        owner[pb * nr + pr + dr] = np.arange(pb.size)
    c3 = owner[cell]
    c3[:, 1] = np.where(c3[:, 1] == c3[:, 0], -1, c3[:, 1])
    c3[:, 2] = np.where((c3[:, 2] == c3[:, 0]) | (c3[:, 2] == c3[:, 1]), -1, c3[:, 2])
    k, col = np.nonzero(c3 >= 0)
    c = c3[k, col]
    nx, ny, rho = cos_b[pb], sin_b[pb], (pr - rmax).astype(np.float64)
    px, py, pw = pix.xs[k].astype(np.float64), pix.ys[k].astype(np.float64), pix.weight[k]
    keep = np.abs(px * nx[c] + py * ny[c] - rho[c]) <= 1.5
    c, px, py, pw = c[keep], px[keep], py[keep], pw[keep]
    if c.size == 0:
        return None
    t = py * nx[c] - px * ny[c]                                  # position along the line
    # by line, then along it: one sort of a combined key (|t| < rmax, so lines do not mix),
    # the order of lexsort((t, c)) at a fraction of its cost; no two pixels of one line share
    # a t (the bins' angles have irrational slopes), so the unstable sort has no ties to break
    o = np.argsort(c * _key_span(shape) + t)
    return _Lines(nx, ny, rho, c[o], px[o], py[o], pw[o], t[o])


def _crossed_gaps(lines: _Lines, seg: np.ndarray, same: np.ndarray, gap: np.ndarray,
                  gap_px: float, min_cross_deg: float, span: float) -> np.ndarray:
    """
    Return the mask of the gaps between consecutive pixels that a segment of ``seg`` crosses.

    Only gaps within one line (``same``), longer than the always-joined spacing and at most
    ``gap_px`` long are considered. A segment crosses a line where it meets it at
    ``min_cross_deg`` or more (or ends within 2 px of it); the crossing points, as positions
    along each line, are sorted once and looked up per gap.
    """
    c, t = lines.c, lines.t
    crossed = np.zeros(gap.size, bool)
    gi = np.nonzero(same & (gap > _JOIN_PX) & (gap <= gap_px))[0]
    if gi.size == 0:
        return crossed
    # only the lines with such a gap: the others ask for no crossing
    ids = c[gi]                                   # c is sorted: the first of each run
    ids = ids[np.append(True, ids[1:] != ids[:-1])]
    cj, sj = np.divmod(np.arange(ids.size * seg.shape[0]), seg.shape[0])
    cj = ids[cj]
    nx, ny, rho = lines.nx[cj], lines.ny[cj], lines.rho[cj]
    d = seg[:, 2:] - seg[:, :2]
    da = seg[sj, 0] * nx + seg[sj, 1] * ny - rho
    db = seg[sj, 2] * nx + seg[sj, 3] * ny - rho
    length = np.maximum(np.hypot(d[sj, 0], d[sj, 1]), 1e-9)
    f = da / np.where(da != db, da - db, 1.0)               # crossing point along sj
    hit = ((np.abs(da - db) >= np.sin(np.deg2rad(min_cross_deg)) * length)
           & (f >= -2.0 / length) & (f <= 1.0 + 2.0 / length))
    cj, sj, f = cj[hit], sj[hit], f[hit]
    tx = ((seg[sj, 1] + f * d[sj, 1]) * lines.nx[cj] - (seg[sj, 0] + f * d[sj, 0]) * lines.ny[cj])
    key = np.sort(cj * span + tx)
    lo = np.searchsorted(key, c[gi] * span + t[gi] - 1.0, 'left')
    hi = np.searchsorted(key, c[gi] * span + t[gi + 1] + 1.0, 'right')
    crossed[gi] = hi > lo
    return crossed


def _fit_runs(r: np.ndarray, k: int, px: np.ndarray, py: np.ndarray, pw: np.ndarray
              ) -> np.ndarray:
    """Return the gradient-weighted TLS segments (k, 4) float32 of pixels in runs ``r``."""
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
