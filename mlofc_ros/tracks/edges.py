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
Lines located on image edges: the search along a line's normals, and growth along it.

:func:`refine_lines` re-locates predicted lines on the image edges (a 1D search for the
gradient maximum along the line's normal at a few samples, then a robust total-least-squares
fit): only the position *across* the line is measured, which is all a line has (endpoints need
not correspond; along an edge image motion is ill-posed anyway). :func:`grow_lines` extends
lines along themselves while the edge continues beyond their ends.
"""
from functools import lru_cache
from typing import Optional, Tuple, Union

import cv2
import numpy as np


def tls_by_group(px: np.ndarray, py: np.ndarray, w: np.ndarray, g: np.ndarray, k: int,
                 sxx0: Optional[np.ndarray] = None, sxy0: Optional[np.ndarray] = None,
                 syy0: Optional[np.ndarray] = None
                 ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Fit a weighted TLS line per group: centroid (k, 2), direction (k, 2), weight sum (k,).

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


def tls_rows(x: np.ndarray, y: np.ndarray, w: np.ndarray
             ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit a weighted TLS line per row of (n, P) points: centroid x, y and direction ux, uy."""
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
    """
    Return the medians of the ``valid`` entries of both halves of each row of (n, S).

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
    """
    Find the sub-pixel edge offsets along the normals: (offset (T, S) px, found (T, S)).

    ``image`` (H, W) float32; ``pts`` (2, T, S) px: x and y of ``S`` points on each of ``T``
    lines; ``nrm`` (2, T) the unit normal of each line (coordinate-major arrays: one numpy
    call handles x and y).
    The intensity is sampled at integer offsets ``-radius - 1 .. radius + 1`` along the
    normal; the nearest local maximum of the central-difference gradient magnitude (at least
    ``min_gradient`` grey levels per 2 px and ``min_relative`` of the strongest in the window;
    ties: the stronger), refined by a parabola, is the edge. ``signed`` (T,) bool: only the
    gradient getting darker along +normal counts on those lines; ``prefer_polarity`` px: a
    peak of the other polarity counts as that much further away (see :func:`refine_lines`).
    A point outside the image finds nothing (the border's pixels, replicated outward, would
    show an edge that crosses the border wherever it is predicted to slide).
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
    h, w = image.shape[:2]
    px, py = pts.reshape(2, n)
    if n and (px.min() < 0 or px.max() > w - 1 or py.min() < 0 or py.max() > h - 1):
        valid &= (px >= 0) & (px <= w - 1) & (py >= 0) & (py <= h - 1)
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
    """
    Re-locate lines on the image edges found along their normals (moving-edges search).

    ``image`` (H, W) float32 gray, ``seg`` (T, 4) px predicted segments. At ``n_samples``
    points along each segment the intensity is sampled at integer offsets ``-radius - 1 ..
    radius + 1`` px along the normal; the nearest local maximum of the central-difference
    gradient magnitude (at least ``min_gradient`` grey levels per 2 px and ``min_relative``
    of the strongest in the window), refined to sub-pixel by a parabola, is the edge point.
    ``signed`` (bool, or (T,) bool): count only the gradient of the segment's polarity
    (brighter side on the left, see :mod:`mlofc_ros.segments.merge`), so that the opposite
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
    cx, cy, fx, fy = tls_rows(ex, ey, w)
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
    """
    Extend segments along their own line while the image edge continues beyond their ends.

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
    # a sample outside the image finds nothing (:func:`_normal_search`)
    off, found = _normal_search(image, pts.reshape(2, t_n, -1), u.T[::-1] * _ROT90, radius,
                                min_gradient, min_relative)
    ok = (found & (np.abs(off) <= tol_px)).reshape(t_n, 2, n_steps)
    # consecutive supported samples from the end outwards
    run = np.where(ok.all(axis=2), n_steps, np.argmin(ok, axis=2))           # (T, 2)
    grown = step * run
    out = np.concatenate([s[:, :2] - grown[:, :1] * u, s[:, 2:] + grown[:, 1:] * u], axis=1)
    return out, grown
