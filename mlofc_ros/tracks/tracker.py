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
"""Line tracking with persistent ids: lines carried frame to frame, refreshed by detection.

Per frame, vectorised over tracks and detections (no Python loop per line):

1. *Carry*. A track with a velocity is predicted by it (the last displacement of both
   endpoints, turned by the line's smoothed turn rate) and re-located on the image edges by
   :func:`refine_lines`: a 1D search for the gradient maximum along the line's normal at a
   few samples, then a robust total-least-squares fit.
   Only the position *across* the line is measured, which is all a line has (endpoints need
   not correspond; along an edge image motion is ill-posed anyway). New tracks, and tracks
   whose prediction finds too little edge support, are carried by pyramidal Lucas-Kanade
   (``cv2.calcOpticalFlowPyrLK``) on ``n_points`` points, a TLS line fit to them (one outlier
   may be dropped, turns above ``max_turn_deg`` rejected; along the line only points with
   2D texture count) and the same edge refinement; a new track whose KLT fit is rejected
   is still carried when the refinement of that fit finds its edge. A carried line then
   grows along itself while the edge continues beyond its ends (:func:`grow_lines`), so a
   track born on a fragment reaches the whole edge before the next detection.
2. *Detect* on every ``detect_every``-th frame with a
   :class:`~mlofc_ros.segments.detect.LineDetector`.
3. *Associate*: each detection joins the track (carried, or predicted when carrying failed)
   with the lowest normalised cost among those passing the gates (angle, distance of its
   endpoints to the track's line, overlap along the line). A track may absorb several
   collinear fragments, fused by a length-weighted TLS fit. Detections left unclaimed get a
   second chance with wider gates (mutual best match with an unmatched track only), then start
   new tracks; a track lying on the same line as an older one is dropped as a duplicate.
4. A track neither carried nor detected coasts on its velocity (not reported) and retires
   after ``max_misses`` such frames.

Segments are ``(u1, v1, u2, v2)`` px in the input image. A track keeps the orientation it was
born with (the detector's: brighter side on the left).
"""
from functools import lru_cache
import math
from typing import Dict, NamedTuple, Optional, Tuple, Union

import cv2
import numpy as np

from mlofc_ros.segments.common import angle_pairs, check_gray, square_kernel
from mlofc_ros.segments.detect import LineDetector


def _tls_by_group(px: np.ndarray, py: np.ndarray, w: np.ndarray, g: np.ndarray, k: int,
                  sxx0: Optional[np.ndarray] = None, sxy0: Optional[np.ndarray] = None,
                  syy0: Optional[np.ndarray] = None
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted TLS line per group: centroid (k, 2), unit direction (k, 2), weight sum (k,).

    Points ``(px, py)`` px with weights ``w`` belong to groups ``g`` in ``[0, k)``. Optional
    per-point second moments (``sxx0`` ...) add the spread of a segment around its midpoint.
    """
    W = np.bincount(g, w, k)
    Ws = np.where(W > 0, W, 1.0)
    cx = np.bincount(g, w * px, k) / Ws
    cy = np.bincount(g, w * py, k) / Ws
    dx, dy = px - cx[g], py - cy[g]
    a, b, c = dx * dx, dx * dy, dy * dy
    if sxx0 is not None:
        a, b, c = a + sxx0, b + sxy0, c + syy0
    sxx = np.bincount(g, w * a, k)
    sxy = np.bincount(g, w * b, k)
    syy = np.bincount(g, w * c, k)
    theta = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    return np.stack([cx, cy], 1), np.stack([np.cos(theta), np.sin(theta)], 1), W


def _tls_rows(x: np.ndarray, y: np.ndarray, w: np.ndarray
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Weighted TLS line per row of (n, P) points: centroid x, y (n,), direction ux, uy (n,)."""
    W = np.maximum(w.sum(1), 1e-12)
    cx = (w * x).sum(1) / W
    cy = (w * y).sum(1) / W
    dx, dy = x - cx[:, None], y - cy[:, None]
    sxx = (w * dx * dx).sum(1)
    sxy = (w * dx * dy).sum(1)
    syy = (w * dy * dy).sum(1)
    theta = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    return cx, cy, np.cos(theta), np.sin(theta)


def _half_medians(off: np.ndarray, valid: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Median of the ``valid`` entries of the first and the second half of each row of (n, S).

    Returns ``(m1 (n,), m2 (n,))``, NaN where a half has no valid entry. For an odd ``S`` the
    first half (``S // 2`` entries) is padded with an invalid one; both halves are sorted in
    one call (each ``np.sort`` costs mostly fixed overhead at these sizes).
    """
    n, s_n = off.shape
    half = s_n // 2
    vals = np.where(valid, off, np.inf)
    if s_n % 2 == 0:
        v = vals.reshape(n, 2, half)
    else:
        v = np.full((n, 2, half + 1), np.inf)
        v[:, 0, :half] = vals[:, :half]
        v[:, 1] = vals[:, half:]
    v = np.sort(v, axis=2).reshape(2 * n, -1)                                  # (2n, S/2)
    # the offsets of found edges are finite, the others inf
    cnt = np.isfinite(v).sum(axis=1)
    rows = np.arange(2 * n)
    lo = v[rows, np.maximum((cnt - 1) // 2, 0)]
    hi = v[rows, np.maximum(cnt // 2, 0)]
    med = np.where(cnt > 0, 0.5 * (lo + hi), np.nan).reshape(n, 2)
    return med[:, 0], med[:, 1]


_REMAP_COLS = 16384


def _normal_search(image: np.ndarray, pts: np.ndarray, nrm: np.ndarray, radius: int,
                   min_gradient: float, min_relative: float,
                   signed: Optional[np.ndarray] = None, prefer_polarity: float = 0.0
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """Sub-pixel edge offset along the normal at points (T, S): (offset (T, S) px, found (T, S)).

    ``image`` (H, W) float32; ``pts`` (2, T, S) px: x and y of ``S`` points on each of ``T``
    lines; ``nrm`` (2, T) the unit normal of each line (coordinate-major arrays: one numpy
    call handles x and y).
    The intensity is sampled at integer offsets ``-radius - 1 .. radius + 1`` along the
    normal; the nearest local maximum of the central-difference gradient magnitude (at least
    ``min_gradient`` grey levels per 2 px and ``min_relative`` of the strongest in the window;
    ties: the stronger), refined by a parabola, is the edge. ``signed`` (T,) bool: only the
    gradient getting darker along +normal counts on those lines; ``prefer_polarity`` px: a
    peak of the other polarity counts as that much further away (see :func:`refine_lines`).
    """
    t_n, s_n = pts.shape[1:]
    n = t_n * s_n
    offs = np.arange(-radius - 1, radius + 2, dtype=np.float64)                 # (O,)
    o_n = offs.size
    # offset-major layout (O, N): the per-sample reductions below then run across rows
    # (long inner loops instead of one short row per sample), and remap gets O long rows
    # (about half the time of N rows of O pixels); the products offset x normal are per line
    m = (pts.reshape(2, 1, t_n, s_n)
         + (offs[:, None] * nrm[:, None, :])[..., None]).astype(np.float32).reshape(2, o_n, n)
    mx, my = m                                                                  # (O, N)
    val = np.empty((o_n, n), np.float32)
    for c in range(0, n, _REMAP_COLS):       # remap takes < SHRT_MAX columns
        val[:, c:c + _REMAP_COLS] = cv2.remap(image, mx[:, c:c + _REMAP_COLS],
                                              my[:, c:c + _REMAP_COLS], cv2.INTER_LINEAR,
                                              borderMode=cv2.BORDER_REPLICATE)
    g = val[2:] - val[:-2]                                                      # (K, N)
    # +normal is the right-hand side: the segment's own polarity (brighter on the left)
    # gets darker along it, g < 0
    other = g > 0 if prefer_polarity > 0 else None
    if signed is None:
        g = np.abs(g)
    else:
        g = np.where(np.repeat(signed, s_n), np.maximum(-g, 0.0), np.abs(g))
    kk = 2 * radius + 1
    thr = np.maximum(min_gradient, min_relative * g.max(axis=0))
    peak = g >= thr
    peak[1:] &= g[1:] >= g[:-1]
    peak[:-1] &= g[:-1] >= g[1:]
    # score: distance from the prediction, ties to the stronger, inf off the peaks
    # (dtype=: the mixed float64 - float32 loop is slower than an explicit float64 one;
    # where= arguments and np.copyto are slower than an added array and np.putmask)
    score = np.subtract(np.abs(np.arange(-radius, radius + 1.0))[:, None], 1e-4 * g,
                        dtype=np.float64)
    if other is not None:
        score += prefer_polarity * other
    np.putmask(score, ~peak, np.inf)
    j = np.argmin(score, axis=0)
    valid = np.isfinite(score.min(axis=0))
    # flat indices into g; the neighbours at j = 0 / kk - 1 are clipped (not used there)
    gf = g.ravel()
    at = j * n + np.arange(n)
    g0 = gf.take(at)
    gm = gf.take(at - n, mode='clip')
    gq = gf.take(at + n, mode='clip')
    den = gm - 2.0 * g0 + gq
    inner = (j > 0) & (j < kk - 1) & (den < 0)
    delta = np.where(inner, 0.5 * (gm - gq) / np.where(inner, den, -1.0), 0.0)
    # np.minimum / np.maximum: np.clip's Python wrapper costs more than the work here
    off = (j - radius) + np.minimum(np.maximum(delta, -0.5), 0.5)
    return off.reshape(t_n, s_n), valid.reshape(t_n, s_n)


_ROT90 = np.array([[-1.0], [1.0]])       # (x, y) -> (-y, x) as ``v[::-1] * _ROT90``


@lru_cache(maxsize=8)
def _sample_grid(n_samples: int) -> Tuple[np.ndarray, float, float]:
    """Sample positions ``t`` (S,) along a segment and the mean ``t`` of each half."""
    t = (np.arange(n_samples) + 0.5) / n_samples
    t.flags.writeable = False
    half = n_samples // 2
    return t, float(t[:half].mean()), float(t[half:].mean())


def refine_lines(image: np.ndarray, seg: np.ndarray, n_samples: int = 12, radius: int = 3,
                 min_gradient: float = 8.0, inlier_px: float = 0.5, min_relative: float = 0.3,
                 signed: Optional[Union[bool, np.ndarray]] = None,
                 prefer_polarity: float = 0.0
                 ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Re-locate lines on the image edges found along their normals (moving-edges search).

    ``image`` (H, W) float32 gray, ``seg`` (T, 4) px predicted segments. At ``n_samples``
    points along each segment the intensity is sampled at integer offsets ``-radius - 1 ..
    radius + 1`` px along the normal; the nearest local maximum of the central-difference
    gradient magnitude (at least ``min_gradient`` grey levels per 2 px and ``min_relative``
    of the strongest in the window), refined to sub-pixel by a parabola, is the edge point.
    ``signed`` (bool, or (T,) bool): count only the gradient of the segment's polarity
    (brighter side on the left, see :mod:`mlofc_ros.segments.detect`), so that the opposite
    edges of neighbouring stripes are not candidates; ``None`` = unsigned.
    ``prefer_polarity`` (px): an unsigned search still, but a peak of the opposite polarity
    counts as that much further from the prediction (so the edge's own polarity wins over a
    neighbour's, while an edge whose polarity flips along its length keeps its samples).
    Each line is the TLS fit to the edge points within ``inlier_px`` of a robust start (the
    line through the median offsets of the two halves of the samples), refitted once without
    points further than ``inlier_px``.
    Returns ``(segments (T, 4) float64, the predicted extent on the refitted line;
    support (T,) share of samples that are inliers; residual (T,) px RMS of the inliers)``.
    """
    t_n = seg.shape[0]
    if t_n == 0:
        return seg.copy(), np.zeros(0), np.zeros(0)
    x1, y1, x2, y2 = seg.T
    # coordinate-major (2, T, ...) arrays: one numpy call for x and y
    d = seg.T[2:] - seg.T[:2]                                                   # (2, T)
    length = np.maximum(np.hypot(d[0], d[1]), 1e-9)
    u = d / length
    nrm = u[::-1] * _ROT90                                                      # (-uy, ux)
    t, t1, t2 = _sample_grid(n_samples)                                         # (S,)
    pts = seg.T[:2, :, None] + t * d[:, :, None]                                # (2, T, S)
    sg = None
    if signed is not None:
        sg = np.broadcast_to(np.asarray(signed, bool), (t_n,))
    off, valid = _normal_search(image, pts, nrm, radius, min_gradient, min_relative, sg,
                                prefer_polarity)
    ex, ey = pts + off * nrm[:, :, None]
    # robust start: the line through the median offsets of the two halves (resists a
    # neighbouring edge caught by up to half of the samples of each half)
    m1, m2 = _half_medians(off, valid)
    m1 = np.where(np.isfinite(m1), m1, m2)
    m2 = np.where(np.isfinite(m2), m2, m1)
    guess = m1[:, None] + (m2 - m1)[:, None] * (t[None, :] - t1) / (t2 - t1)
    w = (valid & (np.abs(off - guess) <= inlier_px)).astype(np.float64)
    cx, cy, fx, fy = _tls_rows(ex, ey, w)
    r = np.abs((ex - cx[:, None]) * fy[:, None] - (ey - cy[:, None]) * fx[:, None])
    w = w * (r <= inlier_px)
    w_sum = w.sum(1)
    support = w_sum / n_samples                       # = w.mean(1), without its overhead
    rms = np.sqrt((w * r * r).sum(1) / np.maximum(w_sum, 1.0))
    flip = fx * u[0] + fy * u[1] < 0
    fx, fy = np.where(flip, -fx, fx), np.where(flip, -fy, fy)
    ta = (x1 - cx) * fx + (y1 - cy) * fy
    tb = (x2 - cx) * fx + (y2 - cy) * fy
    out = np.empty((t_n, 4))
    out[:, 0], out[:, 1] = cx + ta * fx, cy + ta * fy
    out[:, 2], out[:, 3] = cx + tb * fx, cy + tb * fy
    return out, support, rms


def grow_lines(image: np.ndarray, seg: np.ndarray, step: float = 2.0, n_steps: int = 4,
               radius: int = 2, min_gradient: float = 8.0, tol_px: float = 0.75,
               min_relative: float = 0.3) -> Tuple[np.ndarray, np.ndarray]:
    """Extend segments along their own line while the image edge continues beyond their ends.

    ``image`` (H, W) float32 gray, ``seg`` (T, 4) px. Beyond each endpoint, at ``step``,
    ``2 step`` ... ``n_steps step`` px along the line, the gradient maximum along the normal is
    searched as in :func:`refine_lines` (unsigned, within ``radius`` px); the end moves out to
    the last of the consecutive samples whose edge lies within ``tol_px`` of the line (and
    inside the image). Returns ``(segments (T, 4) float64, grown (T, 2) px added at the
    first / second end)``.
    """
    t_n = seg.shape[0]
    if t_n == 0:
        return seg.astype(np.float64), np.zeros((0, 2))
    h, w = image.shape[:2]
    s = seg.astype(np.float64)
    d = s[:, 2:] - s[:, :2]
    length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    u = d / length[:, None]                                                    # (T, 2)
    dist = step * (np.arange(n_steps) + 1.0)                                   # (K,)
    # (2 coords, T, 2 ends, K): samples beyond the first end (backwards) and the second
    # (forwards)
    base = s.T.reshape(2, 2, t_n).transpose(1, 2, 0)                           # (2, T, 2)
    sgn = np.array([-1.0, 1.0])
    pts = base[..., None] + (sgn[:, None] * dist)[None, None] * u.T[:, :, None, None]
    off, found = _normal_search(image, pts.reshape(2, t_n, -1), u.T[::-1] * _ROT90, radius,
                                min_gradient, min_relative)
    ok = (found & (np.abs(off) <= tol_px)).reshape(t_n, 2, n_steps)
    ok &= (pts[0] >= 0) & (pts[0] <= w - 1) & (pts[1] >= 0) & (pts[1] <= h - 1)
    # consecutive supported samples from the end outwards
    run = np.where(ok.all(axis=2), n_steps, np.argmin(ok, axis=2))           # (T, 2)
    grown = step * run
    out = np.concatenate([s[:, :2] - grown[:, :1] * u, s[:, 2:] + grown[:, 1:] * u], axis=1)
    return out, grown


def _remap_velocity(old: np.ndarray, vel: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Move endpoint displacements (T, 4) px of segments ``old`` (T, 4) to the ends of ``new``.

    ``new`` lies on (about) the same lines with the same orientation but another extent; the
    displacement is taken as affine in the position along the line (exact for an affine image
    motion), so the far end of a grown line moves as the line's extrapolated motion says.
    """
    d = old[:, 2:] - old[:, :2]
    l2 = np.maximum(np.einsum('ij,ij->i', d, d), 1e-9)
    s1 = np.einsum('ij,ij->i', new[:, :2] - old[:, :2], d) / l2
    s2 = np.einsum('ij,ij->i', new[:, 2:] - old[:, :2], d) / l2
    va, dv = vel[:, :2], vel[:, 2:] - vel[:, :2]
    return np.concatenate([va + s1[:, None] * dv, va + s2[:, None] * dv], axis=1)


class _Lines(NamedTuple):
    """Endpoints, lengths, unit directions and centres of segments (M, 4) px, each (M,)."""

    x1: np.ndarray
    y1: np.ndarray
    x2: np.ndarray
    y2: np.ndarray
    length: np.ndarray
    ux: np.ndarray
    uy: np.ndarray
    cx: np.ndarray
    cy: np.ndarray


def _parallel_pairs(seg: np.ndarray, angle_deg: float
                    ) -> Tuple[np.ndarray, np.ndarray, _Lines]:
    """Index pairs ``(i, j)`` of segments (M, 4) within ``angle_deg`` (mod 180) and their lines."""
    x1, y1, x2, y2 = seg.T
    length = np.maximum(np.hypot(x2 - x1, y2 - y1), 1e-9)
    ux, uy = (x2 - x1) / length, (y2 - y1) / length
    theta = np.mod(np.arctan2(uy, ux), np.pi)
    i, j = angle_pairs(theta, np.full(seg.shape[0], np.deg2rad(angle_deg)), np.pi)
    lines = _Lines(x1, y1, x2, y2, length, ux, uy, 0.5 * (x1 + x2), 0.5 * (y1 + y2))
    return i, j, lines


def _overlap(g: _Lines, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Overlap of segments ``p`` with segments ``q`` along q's lines, over the shorter length."""
    a = (g.x1[p] - g.cx[q]) * g.ux[q] + (g.y1[p] - g.cy[q]) * g.uy[q]
    b = (g.x2[p] - g.cx[q]) * g.ux[q] + (g.y2[p] - g.cy[q]) * g.uy[q]
    lo = np.maximum(np.minimum(a, b), -0.5 * g.length[q])
    hi = np.minimum(np.maximum(a, b), 0.5 * g.length[q])
    return (hi - lo) / np.minimum(g.length[p], g.length[q])


class LineTracker:
    """Track line segments over a gray image stream with persistent ``uint32`` ids.

    Parameters (pixels are input-image pixels):

    * ``detector``: a :class:`LineDetector` (default: its defaults, LSD on the image resized
      by 0.8, with ``min_length``).
    * ``min_length``: shortest segment reported or born, px. Edges crossed by stripes (whose
      contrast flips along them) often come out of LSD in pieces shorter than 20 px only;
      10 (those pieces born, then grown, see ``grow_steps``) gave +1.2 / +2.4 / +0.4 points
      of tracked-5 on the rendered seeds 0,1 / 2,3 / 4,5 but more id switches on seeds 0,1
      (0.53 -> 0.63 %) and short tracks jumping between GT edges at junctions.
    * ``max_misses``: consecutive frames a track may be neither carried nor detected.
    * ``detect_every``: run the detector on every n-th frame (KLT carries tracks between).
      3 rather than 4: edges of faces turning into view are born a frame earlier (rendered
      own_centre s1 tracked-5 0.897 -> 0.911, but id switches 0.79 -> 1.22 %, brought back
      below 1 % by ``birth_clear_px``, the duplicate rule and the rescue rule below: 0.912,
      0.85 %); the median frame is still one without detection (+0.1-0.2 ms CPU), the mean
      frame costs ~+20 %; real-sequence median lifetimes are shorter (more short births:
      hamburg_taxi 32 -> 19-25 frames, visp_cube 52 -> 50).
    * ``detect_every_max``: detection on demand. After a detection whose unclaimed segments
      (new edges) number at most ``quiet_births`` of the live tracks per ``detect_every``
      frames, the interval doubles, up to ``detect_every_max`` frames; a detection that finds
      more brings it back to ``detect_every``. Past ``detect_every`` frames the detector also
      runs at once when more than ``detect_on_loss`` of the tracks were not carried in a frame
      or when the edge pixels no track explains (``|Sobel x| + |Sobel y|`` of the KLT image
      above ``edge_threshold`` grey levels, farther than ~2 px from every track) grew by more
      than ``new_edge_px`` (KLT-image pixels at 640x480, ~30-50 px of new edge there; scaled
      with the image diagonal) since the last detection (a 0.2 ms check at 640x480). A static
      camera watching a few moving objects then pays for the detector rarely: on the
      rendered camera_centre sequences every ~8th frame instead of every 3rd (front-end CPU
      -30%); where faces keep turning into view (own_centre) it stays near every 3rd.
      The first ``detect_every_max`` frames run at the base rate (the track set is being
      built; with ``general`` a longer first interval changed the first cold search: 300
      frames own3+bg s1 1.4 -> 14.5% wrong). ``detect_every_max`` <= ``detect_every``: a
      fixed rate. Cost, rendered seeds 0-3 / 4-9: tracked-5 0.937 / 0.931 -> 0.930 / 0.930,
      id switches 0.53 / 0.52 -> 0.56 / 0.53 %.
    * ``detect_regions``: in a quiet scene (the detection interval has grown past
      ``detect_every``) after the first ``detect_every_max`` frames, the detector runs only on
      boxes around the edges no carried track explains and the predicted lines of the tracks
      not carried (:meth:`_regions`: grown by ``region_margin_px``, on ``region_tile_px``
      tiles, one box per 8-connected group), unless they cover more than
      ``region_max_area`` of the image; the first detection after ``detect_every_max`` frames
      sees the whole image. A detection that a box side cuts (``clipped`` of
      :meth:`LineDetector.detect_regions`) claims its track without replacing its extent, or
      is born. Off by default. Rendered seeds 0-3 / 4-9, tracked-5 / id switches pooled:
      0.930 / 0.56 % and 0.930 / 0.53 % -> 0.929 / 0.56 % and 0.929 / 0.51 %, endpoint errors
      3.65 / 3.67 -> 4.08 / 4.05 px; cropping busy scenes too (own_centre: detections at the
      base rate) cost 0.925-0.926 and 4.8-5.0 px. The textured real sequences fall back to the
      whole image (visp_cube's boxes cover 90-100 % of it on 40 px tiles; on 10 px tiles 33-50 %,
      but then 10-15 boxes, ~0.4 ms each outside LSD, saved about nothing).
    * ``n_points``: KLT points per track; ``klt_win``: LK window, px of the LK image, which is
      the input resized by ``klt_scale``; ``klt_levels`` / ``klt_levels_predicted``: pyramid
      levels without / with a velocity prediction.
    * ``residual_px``: max distance of a KLT point to the re-fitted line; ``max_turn_deg``:
      largest rotation of a line between frames.
    * ``refine``, ``refine_samples``, ``refine_radius``, ``refine_min_gradient``,
      ``refine_inlier_px``, ``refine_min_relative``: the edge search of
      :func:`refine_lines`; ``min_support``: share of its samples that must agree;
      ``refine_polarity``: search for edges of the track's polarity only (the unsigned search
      is the fallback for tracks that find too little support so); off by default: on the
      rendered sequences it gained 0-1.7 points of tracked-5 for ~1.5 ms CPU per frame.
      ``refine_prefer_polarity`` (px): the cheap form used by default, in the single unsigned
      search a peak of the opposite polarity counts as this much further from the
      prediction (a neighbouring stripe's edge loses a tie; 0 = off).
    * ``grow_steps`` / ``grow_step_px``: a carried line is extended by up to ``grow_steps``
      samples ``grow_step_px`` apart beyond each end while the edge continues there
      (:func:`grow_lines`; 0 = off). Detections refresh the extent; there is no shrinking
      between them (shrinking to the supported samples cost tracked-5 on every sequence).
    * ``turn_smoothing``: weight in [0, 1] of the last frame's turn of a line in its smoothed
      turn rate, by which its displacement is rotated for the next prediction (0 = constant
      image velocity).
    * ``klt_min_eig``: LK points whose window's smaller gradient eigenvalue is below this
      (OpenCV's ``OPTFLOW_LK_GET_MIN_EIGENVALS`` units) do not measure along-line motion.
    * ``predict``: ``'velocity'`` (default) or ``'klt'`` (KLT-carry every track, slower).
    * ``angle_deg`` / ``distance_px`` / ``min_overlap``: association gates (angle between
      lines, distance of detection endpoints to the track's line, overlap along the line over
      the shorter segment's length). ``rescue_gate``: detections left unclaimed get a second,
      mutual-best association to the unmatched tracks with gates widened by this factor
      (for carried and uncarried tracks alike; 1 = off), so a track drifted slightly off its
      edge keeps its id (3 rather than 2: fewer id switches on the rendered sequences, longer
      lives on the real ones). A track whose carry the edge search confirmed this frame keeps
      its line when it rescues a detection (the detection is absorbed, not born): such
      tracks took detections of a parallel edge 3-6 px away when their own edge went
      undetected (own_centre s1 id switches 0.89 -> 0.85 %; excluding them from the rescue
      instead gave more births next to them and visp_cube median lifetime 50 -> 30).
    * ``birth_clear_px``: after the first frame, two unclaimed detections within
      ``angle_deg`` of each other, overlapping along the line (>= 0.3 of the shorter) and
      with centres at most this far apart across it are not born (0 = off). Such pairs
      are the converging stripes of a face turning into view: the tracks born on them
      collapse onto each other and switch ids (own_centre s1 with ``detect_every`` 3: id
      switches 1.22 -> 0.96 %); they are born once the edges part. Tracks lying on the same
      line (duplicates) keep the older, and of two as old the longer (was the lower index;
      own_centre s0 / s1 switches 0.98 / 0.96 -> 0.94 / 0.89 %).
    * ``remap_velocity``: a carried track's velocity is the displacement of its carried
      endpoints; when growth or a detection then gives the track another extent, the
      displacements are moved to the new endpoints (affine along the line) rather than applied
      to them unchanged, which on a turning line mispredicted a track whose extent a detection
      had cut from 80 to 32 px by 8 deg in the next frame. Rendered seeds 0-5, tracked-5:
      own_centre s1 / s2 / s4 0.912 / 0.925 / 0.892 -> 0.922 / 0.934 / 0.905, camera_centre
      +0-0.4 points, own_centre s5 0.950 -> 0.946; id switches own_centre s0 0.89 -> 0.98 %,
      s1 / s4 0.85 / 0.88 -> 0.67 / 0.77 %.
    """

    def __init__(self, detector: Optional[LineDetector] = None, min_length: float = 20.0,
                 max_misses: int = 2, detect_every: int = 3, n_points: int = 4,
                 klt_win: int = 9, klt_levels: int = 3, klt_levels_predicted: int = 1,
                 klt_scale: float = 0.5,
                 residual_px: float = 0.75, angle_deg: float = 3.0, distance_px: float = 2.0,
                 min_overlap: float = 0.3, refine: bool = True, refine_samples: int = 12,
                 refine_radius: int = 3, refine_min_gradient: float = 8.0,
                 refine_inlier_px: float = 0.5, refine_min_relative: float = 0.3,
                 min_support: float = 0.4, predict: str = 'velocity', max_turn_deg: float = 12.0,
                 max_tracks: int = 2000, refine_polarity: bool = False,
                 turn_smoothing: float = 0.5, rescue_gate: float = 3.0,
                 klt_min_eig: float = 1e-2, refine_prefer_polarity: float = 1.0,
                 grow_steps: int = 2, grow_step_px: float = 2.0,
                 birth_clear_px: float = 3.0, remap_velocity: bool = True,
                 detect_every_max: int = 12, quiet_births: float = 0.03,
                 detect_on_loss: float = 0.05, new_edge_px: int = 100,
                 edge_threshold: float = 40.0, detect_regions: bool = False,
                 region_tile_px: int = 40, region_margin_px: float = 12.0,
                 region_max_area: float = 0.5) -> None:
        if int(detect_every) < 1:
            raise ValueError(f'detect_every must be >= 1, got {detect_every}')
        if int(detect_every_max) < 1:
            raise ValueError(f'detect_every_max must be >= 1, got {detect_every_max}')
        if not min(quiet_births, detect_on_loss, new_edge_px, edge_threshold) >= 0:
            raise ValueError('quiet_births, detect_on_loss, new_edge_px and edge_threshold '
                             f'must be >= 0, got {quiet_births}, {detect_on_loss}, '
                             f'{new_edge_px} and {edge_threshold}')
        if int(region_tile_px) < 8 or not region_margin_px >= 0 or not 0 < region_max_area <= 1:
            raise ValueError('region_tile_px must be >= 8, region_margin_px >= 0 and '
                             f'region_max_area in (0, 1], got {region_tile_px}, '
                             f'{region_margin_px} and {region_max_area}')
        self.detect_regions = bool(detect_regions)
        self.region_tile_px = int(region_tile_px)
        self.region_margin_px = float(region_margin_px)
        self.region_max_area = float(region_max_area)
        if int(n_points) < 3:
            raise ValueError(f'n_points must be >= 3, got {n_points}')
        if not min_length >= 0:
            raise ValueError(f'min_length must be >= 0, got {min_length}')
        self.detector = detector if detector is not None else LineDetector(
            min_length=min_length)
        self.min_length = float(min_length)
        self.max_misses = int(max_misses)
        self.detect_every = int(detect_every)
        self.detect_every_max = int(detect_every_max)
        self.quiet_births = float(quiet_births)
        self.detect_on_loss = float(detect_on_loss)
        self.new_edge_px = int(new_edge_px)
        self.edge_threshold = float(edge_threshold)
        self.n_points = int(n_points)
        self.klt_win = int(klt_win)
        self.klt_levels = int(klt_levels)
        self.klt_levels_predicted = int(klt_levels_predicted)
        if not 0.0 < klt_scale <= 1.0:
            raise ValueError(f'klt_scale must be in (0, 1], got {klt_scale}')
        self.klt_scale = float(klt_scale)
        self.residual_px = float(residual_px)
        self.angle_deg = float(angle_deg)
        self.distance_px = float(distance_px)
        self.min_overlap = float(min_overlap)
        self.max_tracks = int(max_tracks)
        self.refine = bool(refine)
        self.refine_samples = int(refine_samples)
        self.refine_radius = int(refine_radius)
        self.min_support = float(min_support)
        if predict not in ('velocity', 'klt'):
            raise ValueError(f"predict must be 'velocity' or 'klt', got {predict!r}")
        self.predict = predict
        self.max_turn_deg = float(max_turn_deg)
        self.refine_polarity = bool(refine_polarity)
        if not 0.0 <= turn_smoothing <= 1.0:
            raise ValueError(f'turn_smoothing must be in [0, 1], got {turn_smoothing}')
        self.turn_smoothing = float(turn_smoothing)
        self.rescue_gate = float(rescue_gate)
        self.klt_min_eig = float(klt_min_eig)
        self.refine_min_gradient = float(refine_min_gradient)
        self.refine_inlier_px = float(refine_inlier_px)
        self.refine_min_relative = float(refine_min_relative)
        self.refine_prefer_polarity = float(refine_prefer_polarity)
        if int(grow_steps) < 0 or not grow_step_px > 0:
            raise ValueError(f'grow_steps must be >= 0 and grow_step_px > 0, got {grow_steps} '
                             f'and {grow_step_px}')
        self.grow_steps = int(grow_steps)
        self.grow_step_px = float(grow_step_px)
        if not birth_clear_px >= 0:
            raise ValueError(f'birth_clear_px must be >= 0, got {birth_clear_px}')
        self.birth_clear_px = float(birth_clear_px)
        self.remap_velocity = bool(remap_velocity)
        self._t = (np.arange(self.n_points) + 0.5) / self.n_points      # (P,) along segment
        self.reset()

    def reset(self) -> None:
        """Drop every track and the previous image; ids restart from 0."""
        self._ids = np.zeros(0, np.uint32)
        self._seg = np.zeros((0, 4))
        self._vel = np.zeros((0, 4))          # per-frame displacement of both endpoints, px
        self._has_vel = np.zeros(0, bool)
        self._misses = np.zeros(0, np.int32)
        self._omega = np.zeros(0)             # smoothed turn per frame, rad
        self._age = np.zeros(0, np.int32)
        self._confirmed = np.zeros(0, bool)   # this frame: carried and found on the image edges
        self._absorbed = np.zeros(0, bool)    # this frame's detections a confirmed track rescued
        self._next_id = 0
        self._prev: Optional[np.ndarray] = None
        self._cur: Optional[np.ndarray] = None
        self._small_prev: Optional[np.ndarray] = None
        self._small_cur: Optional[np.ndarray] = None
        self._edges_cur: Optional[np.ndarray] = None       # this frame's :meth:`_edges`
        self._shape: Optional[Tuple[int, int]] = None
        self._frame = 0
        self._since_detect = 0                # frames since the detector last ran
        self._interval = self.detect_every    # current detection interval (on demand)
        self._uncovered_after = 0             # uncovered edge pixels after the last detection
        self._since_full = 0                  # frames since the detector last saw the whole image
        #: seconds spent in the last :meth:`update` per stage (``detect``, ``track``),
        #: ``detected`` = 1.0 when the detector ran in it and ``detected_area`` the share of
        #: the image it ran on (1.0 whole, less with ``detect_regions``, 0.0 not at all)
        self.last_timing: Dict[str, float] = {'detect': 0.0, 'track': 0.0, 'detected': 0.0,
                                              'detected_area': 0.0}

    @property
    def n_tracks(self) -> int:
        """Number of live tracks (reported or coasting)."""
        return int(self._ids.size)

    # ------------------------------------------------------------------ carry (KLT)
    def _small(self, which: str) -> np.ndarray:
        """Return the previous (``'prev'``) or current (``'cur'``) image at ``klt_scale``."""
        key = '_small_' + which
        img = getattr(self, key)
        if img is None:
            full = self._prev if which == 'prev' else self._cur
            img = cv2.resize(full, None, fx=self.klt_scale, fy=self.klt_scale,
                             interpolation=cv2.INTER_AREA)
            setattr(self, key, img)
        return img

    def _lk(self, gray: np.ndarray, p0: np.ndarray, init: Optional[np.ndarray],
            levels: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """LK from the previous frame: points (n, 2) float32 -> (new (n, 2), status, eig).

        ``status`` (n,) bool; ``eig`` (n,) the minimum eigenvalue of each window's gradient
        matrix (OpenCV's normalisation).

        Runs on the images resized by ``klt_scale`` (pixel centres mapped exactly); the edge
        refinement restores full-resolution accuracy afterwards.
        """
        if p0.shape[0] == 0:
            return p0.copy(), np.zeros(0, bool), np.zeros(0, np.float32)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 10, 0.03)
        win = (self.klt_win, self.klt_win)
        f = self.klt_scale
        if f != 1.0:
            prev, cur = self._small('prev'), self._small('cur')
            p0 = ((p0 + 0.5) * f - 0.5).astype(np.float32)
            init = None if init is None else ((init + 0.5) * f - 0.5).astype(np.float32)
        else:
            prev, cur = self._prev, gray
        flags = cv2.OPTFLOW_LK_GET_MIN_EIGENVALS
        if init is None:
            p1, st, eig = cv2.calcOpticalFlowPyrLK(prev, cur, p0, None, winSize=win,
                                                   maxLevel=levels, criteria=crit, flags=flags)
        else:
            p1, st, eig = cv2.calcOpticalFlowPyrLK(
                prev, cur, p0, init.copy(), winSize=win, maxLevel=levels, criteria=crit,
                flags=flags | cv2.OPTFLOW_USE_INITIAL_FLOW)
        p1 = p1.reshape(-1, 2)
        if f != 1.0:
            p1 = (p1 + 0.5) / f - 0.5
        return p1, st.reshape(-1).astype(bool), eig.reshape(-1)

    def _fit(self, seg: np.ndarray, p0: np.ndarray, p1: np.ndarray, valid: np.ndarray,
             tex: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Re-fit lines to carried points.

        ``seg`` (n, 4) previous segments, ``p0``/``p1`` (n, P, 2) points before/after, ``valid``
        (n, P). Returns ``(new segments (n, 4), ok (n,), velocity (n, 4))``: the TLS line of
        the points (at most one outlier dropped), spanning the old endpoints projected onto it
        and slid by the points' mean displacement along it (only the points with ``tex`` (n, P)
        > 0 when given, no slide when none has); ``ok`` also requires the line to turn by at
        most ``max_turn_deg``.
        """
        h, w = self._shape
        x, y = p1[..., 0].astype(np.float64), p1[..., 1].astype(np.float64)
        inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
        wt = (valid & inside).astype(np.float64)
        cx, cy, ux, uy = _tls_rows(x, y, wt)
        r = np.abs((x - cx[:, None]) * uy[:, None] - (y - cy[:, None]) * ux[:, None]) * wt
        worst = np.argmax(r, axis=1)
        bad = r[np.arange(r.shape[0]), worst] > self.residual_px
        wt[bad, worst[bad]] = 0.0
        cx, cy, ux, uy = _tls_rows(x, y, wt)
        r = np.abs((x - cx[:, None]) * uy[:, None] - (y - cy[:, None]) * ux[:, None]) * wt
        ok = (wt.sum(1) >= self.n_points - 1) & (r.max(1) <= self.residual_px)
        # keep the old orientation; a line turning faster than max_turn_deg is lost
        d = seg[:, 2:] - seg[:, :2]
        dl = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        cos_turn = (ux * d[:, 0] + uy * d[:, 1]) / dl
        ok &= np.abs(cos_turn) >= np.cos(np.deg2rad(self.max_turn_deg))
        flip = cos_turn < 0
        ux, uy = np.where(flip, -ux, ux), np.where(flip, -uy, uy)
        # extent: old endpoints projected on the new line, slid by the mean along-line
        # displacement of the points
        disp = (p1 - p0).astype(np.float64)
        along = disp[..., 0] * ux[:, None] + disp[..., 1] * uy[:, None]
        if tex is not None:
            wa = wt * tex
            slide = (wa * along).sum(1) / np.maximum(wa.sum(1), 1e-9)
        else:
            slide = (wt * along).sum(1) / np.maximum(wt.sum(1), 1.0)
        ta = (seg[:, 0] - cx) * ux + (seg[:, 1] - cy) * uy + slide
        tb = (seg[:, 2] - cx) * ux + (seg[:, 3] - cy) * uy + slide
        new = np.stack([cx + ta * ux, cy + ta * uy, cx + tb * ux, cy + tb * uy], axis=1)
        return new, ok, new - seg

    def _refine(self, image: np.ndarray, seg: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Moving-edges refinement of segments (n, 4): (refined (n, 4), ok (n,))."""
        if not self.refine:
            return seg, np.ones(seg.shape[0], bool)
        ref, support, _ = refine_lines(image, seg, self.refine_samples, self.refine_radius,
                                       self.refine_min_gradient, self.refine_inlier_px,
                                       self.refine_min_relative,
                                       True if self.refine_polarity else None,
                                       self.refine_prefer_polarity)
        ok = support >= self.min_support
        # edges whose polarity flips along them (stripes crossing a box edge) may find too
        # few samples of one sign: those get the unsigned search
        if self.refine_polarity and not ok.all():
            bad = np.nonzero(~ok)[0]
            r2, s2, _ = refine_lines(image, seg[bad], self.refine_samples, self.refine_radius,
                                     self.refine_min_gradient, self.refine_inlier_px,
                                     self.refine_min_relative, None,
                                     self.refine_prefer_polarity)
            ref[bad] = r2
            ok[bad] = s2 >= self.min_support
        return ref, ok

    def _klt(self, gray: np.ndarray, sel: np.ndarray, init: bool
             ) -> Tuple[np.ndarray, np.ndarray]:
        """KLT-carry tracks ``sel``: (segments (n, 4), ok (n,)).

        With ``init`` the constant-velocity prediction seeds LK and ``klt_levels_predicted``
        levels are used, else the full ``klt_levels`` pyramid from zero motion.
        """
        s = self._seg[sel]
        t = self._t[None, :, None]
        p0 = (s[:, None, :2] + t * (s[:, None, 2:] - s[:, None, :2])).astype(np.float32)
        q0 = p0.reshape(-1, 2)
        if init:
            v = self._vel[sel]
            flow = v[:, None, :2] + t * (v[:, None, 2:] - v[:, None, :2])
            q1, st, eig = self._lk(gray, q0, (q0 + flow.reshape(-1, 2)).astype(np.float32),
                                   self.klt_levels_predicted)
        else:
            q1, st, eig = self._lk(gray, q0, None, self.klt_levels)
        # along a line, LK only measures motion where its window has texture across the
        # line's direction too (stripe crossings, corners); elsewhere (parallel stripes) the
        # along-line part is the aperture problem's arbitrary answer
        tex = None
        if self.klt_min_eig > 0:
            tex = (eig >= self.klt_min_eig).reshape(sel.size, -1).astype(np.float64)
        seg, ok, _ = self._fit(s, p0, q1.reshape(sel.size, -1, 2), st.reshape(sel.size, -1),
                               tex)
        return seg, ok

    def _carry(self, gray: np.ndarray, image: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Carry every live track into the new frame: (segments (T, 4), ok (T,)).

        ``predict='velocity'``: tracks with a velocity are predicted by it and refined on the
        image edges; ``predict='klt'``: they are KLT-carried from the prediction first. Tracks
        without a velocity, or whose first attempt fails, are KLT-carried with the full
        pyramid (tracks without a velocity also pass when the KLT fit fails but its edge
        refinement succeeds). Failed tracks get their constant-velocity prediction and
        ``ok = False``. ``image`` is ``gray`` as float32 (for the edge search).
        """
        t_n = self._seg.shape[0]
        new = self._seg + self._vel
        ok = np.zeros(t_n, bool)
        self._confirmed = np.zeros(t_n, bool)
        if t_n == 0 or self._prev is None:
            return new, ok
        sel = np.nonzero(self._has_vel)[0]
        if sel.size:
            if self.predict == 'klt':
                seg1, ok1 = self._klt(gray, sel, True)
                seg1 = np.where(ok1[:, None], seg1, new[sel])
            else:
                seg1 = new[sel]
            seg1, ok2 = self._refine(image, seg1)
            ok1 = ok2 if self.predict != 'klt' else ok1 & ok2
            new[sel[ok1]] = seg1[ok1]
            ok[sel[ok1]] = True
            self._confirmed[sel[ok1]] = ok2[ok1]
        sel = np.nonzero(~ok)[0]
        if sel.size:
            seg2, ok2 = self._klt(gray, sel, False)
            ref2, ok3 = self._refine(image, seg2)
            # a good KLT fit stands on its own where the edge search finds too little support
            seg2 = np.where(ok3[:, None], ref2, seg2)
            # a new track whose KLT fit fails (residual, turn) but whose refined line finds
            # its edge is kept: coasting, it would die before the next detection
            ok2 = ok2 | (ok3 & ~self._has_vel[sel])
            new[sel[ok2]] = seg2[ok2]
            ok[sel[ok2]] = True
            self._confirmed[sel[ok2 & ok3]] = True
        return new, ok

    def _turn(self, vel: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """Rotate endpoint displacements (T, 4) by angles ``phi`` (T,) rad."""
        c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
        vx, vy = vel[:, 0::2], vel[:, 1::2]
        out = np.empty_like(vel)
        out[:, 0::2] = c * vx - s * vy
        out[:, 1::2] = s * vx + c * vy
        return out

    # ------------------------------------------------------------------ association
    def _associate(self, trk: np.ndarray, det: np.ndarray, loose: np.ndarray) -> np.ndarray:
        """Best track index (or -1) for each detection (D,); ``loose`` (T,) widens gates x2.

        Sets ``_absorbed`` (D,): detections rescued by a track confirmed on the image edges.
        """
        t_n, d_n = trk.shape[0], det.shape[0]
        self._absorbed = np.zeros(d_n, bool)
        if t_n == 0 or d_n == 0:
            return np.full(d_n, -1, np.intp)
        cost = self._cost(trk, det, np.where(loose, 2.0, 1.0))
        best = np.argmin(cost, axis=0)
        owner = np.where(np.isfinite(cost[best, np.arange(d_n)]), best, -1)
        if self.rescue_gate > 1.0:
            # second chance, mutual best only: a track that drifted a little off its edge
            # takes the detection back instead of a new id being born on the edge
            taken = np.zeros(t_n, bool)
            taken[owner[owner >= 0]] = True
            ft = np.flatnonzero(~taken)          # = setdiff1d, without its sorting
            fd = np.nonzero(owner < 0)[0]
            if ft.size and fd.size:
                # rescue_gate replaces (does not multiply) the x2 of uncarried tracks: wider
                # gates let detections of other edges in
                c2 = self._cost(trk[ft], det[fd], np.full(ft.size, self.rescue_gate))
                bt = np.argmin(c2, axis=0)
                bd = np.argmin(c2, axis=1)
                ok = np.isfinite(c2[bt, np.arange(fd.size)]) & (bd[bt] == np.arange(fd.size))
                owner[fd[ok]] = ft[bt[ok]]
                # a track whose carry the edge search confirmed is on its edge: the detection
                # so rescued is a neighbouring edge's, absorbed (not born) but not fused
                self._absorbed[fd[ok]] = self._confirmed[ft[bt[ok]]]
        return owner

    def _cost(self, trk: np.ndarray, det: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """Association cost (T, D), inf outside the gates; ``scale`` (T,) widens the gates."""
        t_n, d_n = trk.shape[0], det.shape[0]
        tx1, ty1, tx2, ty2 = trk.T
        dx1, dy1, dx2, dy2 = det.T
        tl = np.maximum(np.hypot(tx2 - tx1, ty2 - ty1), 1e-9)
        tux, tuy = (tx2 - tx1) / tl, (ty2 - ty1) / tl
        dl = np.maximum(np.hypot(dx2 - dx1, dy2 - dy1), 1e-9)
        dux, duy = (dx2 - dx1) / dl, (dy2 - dy1) / dl
        tcx, tcy = 0.5 * (tx1 + tx2), 0.5 * (ty1 + ty2)
        dist_thr = self.distance_px * scale
        # distances of the detection endpoints to the track line, on every pair: the cheap
        # gate that leaves few pairs; the other gates and the cost (arctan2, cos, arccos)
        # are evaluated on those pairs only
        rx1 = dx1[None, :] - tcx[:, None]
        ry1 = dy1[None, :] - tcy[:, None]
        rx2 = dx2[None, :] - tcx[:, None]
        ry2 = dy2[None, :] - tcy[:, None]
        dist = np.maximum(np.abs(rx1 * tuy[:, None] - ry1 * tux[:, None]),
                          np.abs(rx2 * tuy[:, None] - ry2 * tux[:, None]))
        pair = np.flatnonzero(dist <= dist_thr[:, None])
        i, j = pair // d_n, pair % d_n
        thr, sc, ti = dist_thr[i], scale[i], tl[i]
        cosang = np.abs(tux[i] * dux[j] + tuy[i] * duy[j])
        ang_thr = np.maximum(np.deg2rad(self.angle_deg) * sc,
                             np.arctan2(thr, np.minimum(ti, dl[j])))
        gate = cosang >= np.cos(ang_thr)
        # overlap along the track line, over the shorter length
        a1 = rx1.ravel()[pair] * tux[i] + ry1.ravel()[pair] * tuy[i]
        a2 = rx2.ravel()[pair] * tux[i] + ry2.ravel()[pair] * tuy[i]
        half = 0.5 * ti
        lo = np.maximum(np.minimum(a1, a2), -half)
        hi = np.minimum(np.maximum(a1, a2), half)
        overlap = (hi - lo) / np.minimum(ti, dl[j])
        gate &= overlap >= self.min_overlap
        ang = np.arccos(np.minimum(cosang, 1.0))
        cost = np.full((t_n, d_n), np.inf)
        cost.ravel()[pair[gate]] = (dist.ravel()[pair] / thr + ang / ang_thr
                                    - 0.5 * np.minimum(overlap, 1.0))[gate]
        return cost

    @staticmethod
    def _fuse(det: np.ndarray, owner: np.ndarray, t_n: int, ref: np.ndarray) -> np.ndarray:
        """Fuse the detections (D, 4) claimed by each track into one segment per track.

        ``owner`` (D,) holds track indices in ``[0, t_n)``; ``ref`` (t_n, 4) the tracks' current
        segments, whose orientation is kept. Returns (t_n, 4): the length-weighted TLS line of
        the claimed detections spanning their extreme endpoint projections (rows of tracks
        without detections are meaningless).
        """
        p1, p2 = det[:, :2], det[:, 2:]
        d = p2 - p1
        w = np.hypot(d[:, 0], d[:, 1])
        mid = 0.5 * (p1 + p2)
        c, u, _ = _tls_by_group(mid[:, 0], mid[:, 1], w, owner, t_n,
                                d[:, 0] ** 2 / 12.0, d[:, 0] * d[:, 1] / 12.0,
                                d[:, 1] ** 2 / 12.0)
        rd = ref[:, 2:] - ref[:, :2]
        flip = np.einsum('ij,ij->i', u, rd) < 0
        u[flip] *= -1
        pts = np.concatenate([p1, p2])
        g = np.concatenate([owner, owner])
        tt = np.einsum('ij,ij->i', pts - c[g], u[g])
        tmin = np.full(t_n, np.inf)
        tmax = np.full(t_n, -np.inf)
        np.minimum.at(tmin, g, tt)
        np.maximum.at(tmax, g, tt)
        tmin[~np.isfinite(tmin)] = 0.0
        tmax[~np.isfinite(tmax)] = 0.0
        return np.concatenate([c + tmin[:, None] * u, c + tmax[:, None] * u], axis=1)

    def _crowded(self, born: np.ndarray) -> np.ndarray:
        """Mask (B,) of segments ``born`` (B, 4) with a parallel, overlapping close neighbour.

        A neighbour is another segment within ``angle_deg``, overlapping at least 0.3 of the
        shorter one along the first's line, whose centre lies between 0.25 px (a duplicate
        fragment of the same line is no neighbour) and ``birth_clear_px`` across that line.
        """
        out = np.zeros(born.shape[0], bool)
        if born.shape[0] < 2:
            return out
        i, j, g = _parallel_pairs(born, self.angle_deg)
        off = np.abs((g.cx[j] - g.cx[i]) * g.uy[i] - (g.cy[j] - g.cy[i]) * g.ux[i])
        over = _overlap(g, j, i)
        hit = (off > 0.25) & (off <= self.birth_clear_px) & (over >= 0.3)
        out[i[hit]] = True
        return out

    def _duplicates(self, seg: np.ndarray, age: np.ndarray) -> np.ndarray:
        """Mask (T,) of tracks lying on the same line as an older (or as old, longer) track."""
        dup = np.zeros(seg.shape[0], bool)
        if seg.shape[0] < 2:
            return dup
        i, j, g = _parallel_pairs(seg, self.angle_deg)
        length = g.length
        # i is the younger one (smaller age; same age: shorter, or as long and later index):
        # tracks born together are told apart by the line they hold, not by their order
        keep = (age[i] < age[j]) | ((age[i] == age[j]) & (
            (length[i] < length[j]) | ((length[i] == length[j]) & (i > j))))
        i, j = i[keep], j[keep]
        off = np.maximum(np.abs((g.x1[i] - g.cx[j]) * g.uy[j] - (g.y1[i] - g.cy[j]) * g.ux[j]),
                         np.abs((g.x2[i] - g.cx[j]) * g.uy[j] - (g.y2[i] - g.cy[j]) * g.ux[j]))
        hit = (off <= 0.5 * self.distance_px) & (_overlap(g, i, j) >= 0.5)
        dup[i[hit]] = True
        return dup

    # ------------------------------------------------------------------ detection schedule
    def _edges(self) -> np.ndarray:
        """Return the edge mask (uint8 0 / 255) of the current image at ``klt_scale``.

        255 where ``|Sobel x| + |Sobel y|`` exceeds ``edge_threshold`` grey levels.
        """
        if self._edges_cur is None:      # once per frame: the checks and the regions share it
            small = self._small('cur')
            mag = cv2.add(cv2.convertScaleAbs(cv2.Sobel(small, cv2.CV_16S, 1, 0)),
                          cv2.convertScaleAbs(cv2.Sobel(small, cv2.CV_16S, 0, 1)))
            self._edges_cur = cv2.compare(mag, self.edge_threshold, cv2.CMP_GT)
        return self._edges_cur.copy()    # callers draw on it

    def _uncovered_edges(self, seg: np.ndarray) -> int:
        """Edge pixels of the current image (at ``klt_scale``) farther than ~2 px from ``seg``."""
        if seg.shape[0] == 0:
            return 0
        edges = self._edges()
        pts = np.round(seg.reshape(-1, 2, 2) * self.klt_scale).astype(np.int32)
        cv2.polylines(edges, list(pts), False, 0, 5)      # erase what the tracks explain
        return cv2.countNonZero(edges)

    def _regions(self, seg: np.ndarray, carried: np.ndarray
                 ) -> Tuple[Optional[np.ndarray], float]:
        """Return the boxes ``(B, 4)`` (u0, v0, u1, v1) px to detect in and their image share.

        The edge pixels of the current image (as in :meth:`_uncovered_edges`) that no carried
        track of ``seg`` explains, plus the predicted lines of the tracks not carried (to be
        found again), grown by ``region_margin_px``, on a grid of ``region_tile_px`` tiles;
        each 8-connected group of tiles is one box. ``(None, 1.0)`` (the whole image) when
        they cover more than ``region_max_area`` of the image (a crop would save little).
        """
        mask = self._edges()
        pts = np.round(seg.reshape(-1, 2, 2) * self.klt_scale).astype(np.int32)
        if carried.any():
            cv2.polylines(mask, list(pts[carried]), False, 0, 5)
        if not carried.all():
            cv2.polylines(mask, list(pts[~carried]), False, 255, 5)
        r = int(round(self.region_margin_px * self.klt_scale))
        if r > 0:
            mask = cv2.dilate(mask, square_kernel(2 * r + 1))
        h, w = self._shape
        ts = max(int(round(self.region_tile_px * self.klt_scale)), 1)   # KLT-image pixels
        nty, ntx = -(-mask.shape[0] // ts), -(-mask.shape[1] // ts)
        grid = np.zeros((nty * ts, ntx * ts), np.uint8)
        grid[:mask.shape[0], :mask.shape[1]] = mask
        on = grid.reshape(nty, ts, ntx, ts).max(axis=(1, 3))
        _, _, stats, _ = cv2.connectedComponentsWithStats(on, connectivity=8)
        st = stats[1:]                                        # label 0 is the background
        # tile edges back in image pixels (KLT-image pixel i covers [i / s, (i + 1) / s))
        lo = np.floor(st[:, :2] * ts / self.klt_scale).astype(np.int64)
        hi = np.ceil((st[:, :2] + st[:, 2:4]) * ts / self.klt_scale).astype(np.int64)
        boxes = np.stack([lo[:, 0], lo[:, 1], np.minimum(hi[:, 0], w),
                          np.minimum(hi[:, 1], h)], axis=1)
        boxes = boxes[(boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])]
        area = float(np.sum((boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]))) / (h * w)
        return (None, 1.0) if area > self.region_max_area else (boxes, area)

    def _detect_now(self, t_n: int, uncarried: int, seg: np.ndarray) -> bool:
        """Whether the detector runs now: ``t_n`` tracks at ``seg``, ``uncarried`` of them lost."""
        self._since_detect += 1
        self._since_full += 1
        base = self.detect_every
        interval = min(max(self._interval, base), max(self.detect_every_max, base))
        if t_n == 0 or self._since_detect >= interval:
            return True
        if self._since_detect < base:
            return False
        # past the base interval: detect as soon as something new shows (tracks lost, or
        # edges that no track explains)
        if uncarried > self.detect_on_loss * t_n:
            return True
        # new_edge_px is for 640x480; edge pixel counts grow with the image's linear size
        scale = math.hypot(*self._shape) / 800.0
        return self._uncovered_edges(seg) > self._uncovered_after + self.new_edge_px * scale

    def _after_detect(self, unclaimed: int, alive: int) -> None:
        """Set the next detection interval from a detection's ``unclaimed`` (new) segments."""
        base, top = self.detect_every, max(self.detect_every_max, self.detect_every)
        # new segments per base interval: a longer wait has more to find
        rate = unclaimed * base / max(self._since_detect, 1)
        self._since_detect = 0
        # the first `top` frames build the track set: the base rate there (and the solver's
        # first windows see every birth)
        quiet = self._frame >= top and rate <= self.quiet_births * alive
        # a quiet scene doubles the wait, anything new brings it back to the base rate
        self._interval = min(2 * max(self._interval, base), top) if quiet else base

    # ------------------------------------------------------------------ main entry
    def update(self, gray: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Process one frame ``gray`` (H, W) uint8.

        Returns ``(track_ids (M,) uint32, segments (M, 4) float32)`` px of the tracks observed
        in this frame (carried by KLT or matched to a detection), sorted by id. Raises
        ``ValueError`` on a non-uint8/non-2D image or a change of image size (call
        :meth:`reset` first).
        """
        check_gray(gray)
        if self._shape is not None and gray.shape != self._shape:
            raise ValueError(f'image size changed from {self._shape} to {gray.shape}; '
                             'reset() the tracker first')
        tick = cv2.getTickCount
        t0 = tick()
        self._shape = gray.shape
        self._cur, self._small_cur, self._edges_cur = gray, None, None
        image = gray.astype(np.float32)
        seg, carried = self._carry(gray, image)
        t_n = seg.shape[0]
        vel = np.where(carried[:, None], seg - self._seg, self._vel)
        omega = self._omega
        if self.turn_smoothing > 0:
            # constant turn rate: a line's displacement turns with it (a rotating body, or
            # a camera rolling), so the along-line motion stays along the line
            d0 = self._seg[:, 2:] - self._seg[:, :2]
            d1 = seg[:, 2:] - seg[:, :2]
            phi = np.arctan2(d0[:, 0] * d1[:, 1] - d0[:, 1] * d1[:, 0],
                             d0[:, 0] * d1[:, 0] + d0[:, 1] * d1[:, 1])
            lim = np.deg2rad(self.max_turn_deg)
            b = self.turn_smoothing
            omega = np.where(carried, (1 - b) * omega + b * np.clip(phi, -lim, lim), omega)
            vel = np.where(carried[:, None], self._turn(vel, omega), vel)
        seg_carried = seg.copy()
        if self.grow_steps > 0 and carried.any():
            # after the velocity: growth is new extent, not motion to extrapolate
            idx = np.nonzero(carried)[0]
            seg[idx], _ = grow_lines(image, seg[idx], self.grow_step_px, self.grow_steps,
                                     min(self.refine_radius, 2), self.refine_min_gradient,
                                     1.5 * self.refine_inlier_px, self.refine_min_relative)
        run_detect = self._detect_now(t_n, int(t_n - np.count_nonzero(carried)), seg)
        t1 = tick()
        det, clipped, area = np.zeros((0, 4), np.float32), None, 0.0
        if run_detect:
            top = max(self.detect_every_max, self.detect_every)
            # only where something is new, in a quiet scene (the interval has grown) once the
            # track set is built; the whole image while the scene is busy (cropped, the
            # extents of a busy scene went stale: endpoint errors +31-37% instead of +10-12%)
            # and at the first detection after detect_every_max frames (it refreshes every
            # track's extent; a detection of its own then, one frame after a crop, counted
            # its few births as a busy scene's and brought back the base rate)
            quiet = self._interval > self.detect_every
            boxes, area = (self._regions(seg, carried) if self.detect_regions and t_n > 0
                           and quiet and self._frame >= top and self._since_full < top
                           else (None, 1.0))
            if boxes is None:
                det = self.detector.detect(gray)
                self._since_full = 0
            else:
                det, clipped = self.detector.detect_regions(gray, boxes)
        t2 = tick()
        det = det.astype(np.float64)
        owner = self._associate(seg, det, ~carried)
        claimed = owner >= 0
        fuse = claimed & ~self._absorbed
        if clipped is not None:
            # a crop's cut of a longer tracked line would shorten the track to the crop
            fuse &= ~clipped
        matched = np.zeros(t_n, bool)
        if fuse.any():
            own = owner[fuse]
            matched[own] = True
            fused = self._fuse(det[fuse], own, t_n, seg)
            # tracks seen only by the detector: velocity from the previous segment
            lost = matched & ~carried
            old = self._seg
            new_vel = fused - old
            vel[lost] = np.where(self._has_vel[lost, None], new_vel[lost], 0.0)
            seg[matched] = fused[matched]
        if self.remap_velocity and carried.any():
            # the carried endpoints' displacements belong to those points: moved to the grown
            # or fused endpoints along the line (affine in the position along it)
            idx = np.nonzero(carried)[0]
            vel[idx] = _remap_velocity(seg_carried[idx], vel[idx], seg[idx])
        observed = carried | matched
        misses = np.where(observed, 0, self._misses + 1)
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        alive = (misses <= self.max_misses) & (length >= 0.5 * self.min_length)
        has_vel = (self._has_vel | carried) & alive
        if run_detect and alive.sum() > 1:
            idx = np.nonzero(alive)[0]
            alive[idx[self._duplicates(seg[idx], self._age[idx])]] = False
        # births from unclaimed detections
        born = det[~claimed]
        if run_detect:
            self._after_detect(born.shape[0], int(alive.sum()))
        if self.birth_clear_px > 0 and self._frame > 0 and born.shape[0] > 1:
            # parallel births within a few px: converging stripes, born once they part
            born = born[~self._crowded(born)]
        born = born[:max(self.max_tracks - int(alive.sum()), 0)]
        nb = born.shape[0]
        new_ids = (self._next_id + np.arange(nb)).astype(np.uint32)
        self._next_id += nb
        report = np.concatenate([(observed & (length >= self.min_length))[alive],
                                 np.ones(nb, bool)])
        self._ids = np.concatenate([self._ids[alive], new_ids])
        self._seg = np.concatenate([seg[alive], born])
        self._vel = np.concatenate([vel[alive], np.zeros((nb, 4))])
        self._has_vel = np.concatenate([has_vel[alive], np.zeros(nb, bool)])
        self._misses = np.concatenate([misses[alive], np.zeros(nb, np.int32)]).astype(np.int32)
        self._omega = np.concatenate([omega[alive], np.zeros(nb)])
        self._age = np.concatenate([self._age[alive] + 1, np.zeros(nb, np.int32)])
        if run_detect and self._interval > self.detect_every:
            # what no track explains right after a detection: the reference of the checks
            # that run only while the interval is longer than the base one
            self._uncovered_after = self._uncovered_edges(self._seg)
        self._prev = gray.copy()
        self._small_prev = self._small_cur
        self._cur = self._small_cur = self._edges_cur = None
        self._frame += 1
        out_ids, out_seg = self._ids[report], self._seg[report]
        order = np.argsort(out_ids, kind='stable')
        t3 = tick()
        f = cv2.getTickFrequency()
        self.last_timing = {'detect': (t2 - t1) / f, 'track': ((t1 - t0) + (t3 - t2)) / f,
                            'detected': float(run_detect), 'detected_area': area}
        return out_ids[order], out_seg[order].astype(np.float32)
