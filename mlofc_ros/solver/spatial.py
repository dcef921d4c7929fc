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
Spatial coherence: lines near each other in the image tend to share a body.

Real rigid bodies are compact in the image, so a track's image neighbours are evidence for its
label, which matters where the rotation-only model is only approximately right (bodies that
also translate). :func:`smooth_labels` adds a Potts term (a penalty per neighbour with another
label) to the per-track costs and minimises it by iterated conditional modes. The coupling is
estimated from the labelling itself: when labels are spatially mixed (the paper's synthetic
scenes of intermixed random lines) it is zero and nothing changes.
"""
from typing import Tuple

import numpy as np

from .models import median, row_min

#: Potts weight per disagreeing neighbour, as a share of the median inlier cost, at full
#: coherence (measured on Hopkins155 line tracks: 0.25-1 gain 1-5 points, 2 starts to lose).
POTTS_WEIGHT = 0.5
#: Neighbours per track.
NEIGHBOURS = 6


#: Up to this many points the neighbours are exact (brute force, one (N, N) distance matrix).
EXACT_MAX = 600


def _morton(q: np.ndarray) -> np.ndarray:
    """Z-order codes ``(N,)`` of non-negative integer coordinates ``q (N, 2)`` < 2**16."""
    v = q.astype(np.uint64)
    for shift, mask in ((8, 0x00FF00FF), (4, 0x0F0F0F0F), (2, 0x33333333), (1, 0x55555555)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v[:, 0] | (v[:, 1] << np.uint64(1))


def spatial_neighbours(points: np.ndarray, k: int = NEIGHBOURS, window: int = 16
                       ) -> np.ndarray:
    """
    ``k`` nearest neighbours ``(N, k)`` of ``points (N, 2)`` (px), never the point itself.

    Exact up to :data:`EXACT_MAX` points. Beyond, approximate and linear in N: the candidates
    are the ``window`` points on either side along two shifted Z-order curves (recall of the
    true 6 nearest ~0.97 on uniform and clustered points); a smoothness prior needs near
    neighbours, not exactly the nearest ones. Deterministic. ``-1`` pads when N <= k.
    """
    pts = np.asarray(points, dtype=np.float64)
    n = pts.shape[0]
    k = min(k, n - 1)
    if k <= 0:
        return np.full((n, 0), -1, dtype=np.int64)
    if n <= EXACT_MAX:
        d = pts @ (-2.0 * pts.T)
        # x^2 + y^2: the sums np.sum(pts * pts, axis=1) makes, without its length-2 reduction
        sq = pts * pts
        sq = sq[:, 0] + sq[:, 1]
        d += sq[:, None]
        d += sq
        flat = d.reshape(-1)                # a view: masks by flat index, one call each
        flat[::n + 1] = np.inf
        # k argmins, each masking the one found: several times faster than argpartition
        # along rows for k << N (written as contiguous rows of a (k, N) array)
        out = np.empty((k, n), dtype=np.int64)
        starts = np.arange(0, n * n, n)
        for j in range(k):
            col = d.argmin(axis=1)
            out[j] = col
            col += starts
            flat[col] = np.inf
        return out.T.copy()
    lo = pts.min(axis=0)
    q = (pts - lo) * (32767.0 / max(float(np.ptp(pts, axis=0).max()), 1e-9))
    offs = np.r_[-window:0, 1:window + 1]
    # int32 indices and in-place arithmetic: at N ~ 1000 the (N, 4 window) temporaries, not
    # the arithmetic, cost the time
    cs = np.empty((n, 2 * offs.size), dtype=np.int32)
    for i, shift in enumerate((0.0, 32767.0 / 3.0)):   # a second, shifted curve: the seams
        order = np.argsort(_morton(q + shift), kind='stable').astype(np.int32)
        rank = np.empty(n, dtype=np.int64)
        rank[order] = np.arange(n)
        pos = rank[:, None] + offs
        np.clip(pos, 0, n - 1, out=pos)
        np.take(order, pos, out=cs[:, i * offs.size:(i + 1) * offs.size])
    # the candidates sorted per track, so that one found twice (on both curves, or clipped at
    # an end of a curve) counts once. Sorting the indices themselves (not argsort and gathers)
    # and measuring the distances after gives the same arrays several times faster: every
    # repeat of a candidate has the same distance
    cs.sort(axis=1)
    # squared distances dx^2 + dy^2, the same sums as np.sum over the last axis of the
    # (N, C, 2) differences, without that length-2 reduction (20x slower)
    x, y = pts[:, 0].copy(), pts[:, 1].copy()
    ds = x[cs]
    ds -= x[:, None]
    ds *= ds
    dy = y[cs]
    dy -= y[:, None]
    dy *= dy
    ds += dy
    np.copyto(ds, np.inf, where=cs == np.arange(n)[:, None])
    np.copyto(ds[:, 1:], np.inf, where=cs[:, 1:] == cs[:, :-1])
    near = np.argpartition(ds, k - 1, axis=1)[:, :k]
    return np.take_along_axis(cs, near, axis=1).astype(np.int64)


def label_coherence(labels: np.ndarray, neighbours: np.ndarray) -> float:
    """Spatial coherence in [0, 1]: neighbour agreement above chance (0 = mixed, 1 = regions)."""
    a = labels[:, None]
    b = np.where(neighbours >= 0, labels[np.maximum(neighbours, 0)], -1)
    both = (a >= 0) & (b >= 0)
    pairs = np.count_nonzero(both)
    if pairs == 0:
        return 0.0
    counts = np.bincount(labels[labels >= 0])
    return _coherence(np.count_nonzero((a == b) & both), pairs, counts)


def _coherence(agree: int, pairs: int, counts: np.ndarray) -> float:
    """
    :func:`label_coherence` from the numbers of agreeing and of labelled neighbour pairs.

    ``counts``: tracks per label (trailing zeros allowed).
    """
    agree = agree / pairs
    chance = float(counts @ counts) / float(counts.sum()) ** 2
    if chance >= 1.0:
        return 0.0
    return min(max((agree - chance) / (1.0 - chance), 0.0), 1.0)


def smooth_labels(costs: np.ndarray, labels: np.ndarray, neighbours: np.ndarray,
                  weight: float = POTTS_WEIGHT, sweeps: int = 5) -> Tuple[np.ndarray, float]:
    """
    Relabel the labelled tracks by costs plus a Potts term over image neighbours.

    Parameters
    ----------
    costs : (N, n) float
        Per-track cost under every body (nan: unusable).
    labels : (N,) int
        Current labels; ``-1`` (outliers, unusable) stay ``-1`` and vote for nobody.
    neighbours : (N, k) int
        From :func:`spatial_neighbours` (``-1`` pads).
    weight : float
        Penalty per disagreeing neighbour as a share of the median best cost of the labelled
        tracks, at full coherence (scaled by :func:`label_coherence`).
    sweeps : int
        Most passes over the tracks (each relabels every track given its neighbours).

    Returns
    -------
    labels : (N,) int64
        The smoothed labels.
    coupling : float
        The penalty per disagreeing neighbour that was used (cost units; 0 = unchanged).

    """
    lab = np.array(labels, dtype=np.int64)                           # a copy
    keep = lab >= 0
    n = costs.shape[1]
    n_keep = np.count_nonzero(keep)
    if n < 2 or neighbours.shape[1] == 0 or n_keep < 2:
        return lab, 0.0
    data = np.where(np.isfinite(costs), costs, np.inf)
    best = row_min(data)                                  # no nan here
    scale = median(best[keep])
    # every track's neighbours counted by label in one bincount: bin 0 = unlabelled (or a pad),
    # bin 1 + b = label b. The same integers as comparing every neighbour with every body, in
    # a few calls instead of (N, k, n) temporaries reduced over a middle axis
    size, k = neighbours.shape
    width = max(n, int(lab.max()) + 1) + 1
    offsets = np.arange(0, size * width, width)
    codes = np.zeros(size + 1, dtype=np.int64)         # a -1 pad reads the last entry: bin 0

    def tally(cur: np.ndarray) -> np.ndarray:
        np.add(cur, 1, out=codes[:size])
        idx = codes[neighbours]
        idx += offsets[:, None]
        return np.bincount(idx.ravel(), minlength=size * width)

    cnt = tally(np.maximum(lab, -1))
    # label_coherence's counts: labelled neighbours of the labelled tracks, and those among
    # them with the track's own label
    rows = keep.nonzero()[0]
    first = offsets[rows]
    pairs = k * n_keep - int(cnt[first].sum())
    if pairs == 0:
        return lab, 0.0
    agree = int(cnt[first + codes[rows]].sum())
    coupling = weight * _coherence(agree, pairs, np.bincount(codes[rows])) * scale
    if not coupling > 0.0:
        return lab, 0.0
    drop = (~keep).nonzero()[0]
    for sweep in range(sweeps):
        if sweep:
            cnt = tally(lab)
        cnt = cnt.reshape(size, width)
        # labelled neighbours with another label: (present - votes) of every body
        new = (data + coupling * ((k - cnt[:, :1]) - cnt[:, 1:n + 1])).argmin(axis=1)
        new[drop] = -1
        if (new == lab).all():
            break
        lab = new
    return lab, coupling


#: Two tracks are in one region of the image (:func:`largest_region`) when their midpoints are
#: within this many times the tracks' mean spacing (:func:`track_spacing`): a box's lines are
#: about one spacing apart, two boxes or a box and the wall behind it several.
REGION_REACH = 1.5


def track_spacing(points: np.ndarray) -> float:
    """
    Return the mean spacing (px) of points ``(N, 2)``: ``sqrt(area / N)`` of their bounding box.

    ``N >= 1``; at least 1 px^2 of area.
    """
    pts = np.asarray(points, dtype=float)
    extent = pts.max(axis=0) - pts.min(axis=0)
    return float(np.sqrt(max(float(extent[0] * extent[1]), 1.0) / pts.shape[0]))


def largest_region(points: np.ndarray, spacing: float, reach: float = REGION_REACH
                   ) -> np.ndarray:
    """
    Return the largest region ``(N,)`` bool of points ``(N, 2)`` (px): a connected component.

    Two points are linked when within ``reach * spacing`` px (single linkage); the component
    with the most points is returned (the first such when several tie). All True when the
    points form one region.
    """
    pts = np.asarray(points, dtype=float)
    d2 = np.sum((pts[:, None, :] - pts[None, :, :]) ** 2, axis=-1)
    near = d2 <= (reach * spacing) ** 2
    # every point takes the smallest label among its neighbours, then its label's label
    # (pointer jumping: steps grow with the log of a component's diameter, not the diameter)
    # until none changes: each component ends labelled by its smallest index
    comp = np.arange(pts.shape[0])
    while True:
        nxt = np.min(np.where(near, comp[None, :], pts.shape[0]), axis=1)
        nxt = nxt[nxt]
        if np.array_equal(nxt, comp):
            break
        comp = nxt
    sizes = np.bincount(comp, minlength=pts.shape[0])
    return comp == int(np.argmax(sizes))
