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
Segment orientation by contrast polarity and merging of collinear fragments.

Every segment the detector returns is *oriented*: walking from ``(u1, v1)`` to ``(u2, v2)``,
the brighter side is on the left in the image (which, with ``v`` pointing down, is the side of
``(dv, -du)``). Orientation lets the tracker tell apart the two edges of a thin bar.
"""
from typing import Sequence

from mlofc_ros.segments.common import angle_pairs, segment_lengths
import numpy as np


def orient_by_polarity(gray: np.ndarray, segments: np.ndarray, offset: float = 1.5,
                       ts: Sequence[float] = (0.25, 0.5, 0.75)) -> np.ndarray:
    """
    Flip segments so that the brighter side is on the left (side of ``(dv, -du)``).

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
    """
    Return the connected-component labels (m,) of the undirected graph with edges ``(i[k], j[k])``.

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


def merge_collinear(segments: np.ndarray, angle_deg: float = 2.0, offset_px: float = 1.5,
                    gap_px: float = 10.0, oriented: bool = False) -> np.ndarray:
    """
    Merge collinear fragments of the same line into single segments.

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
    i, j = angle_pairs(theta, width, period)
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


def rows_not_in(seg: np.ndarray, base: np.ndarray, tol: float = 1e-3) -> np.ndarray:
    """
    Return the mask (M,) of the segments ``seg`` (M, 4) px that are no row of ``base`` (B, 4).

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


def covers_any(seg: np.ndarray, base: np.ndarray, angle_deg: float = 2.0,
               offset_px: float = 2.0) -> np.ndarray:
    """
    Return the mask (M,) of segments ``seg`` (M, 4) px on which a ``base`` centre lies.

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
