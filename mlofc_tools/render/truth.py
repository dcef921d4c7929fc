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
Visible portions of projected 3D edges, from a face-id buffer.

An edge is sampled every :data:`STEP_PX` pixels along its projection (after clipping it to
the rasterised canvas); a sample is visible when the face-id buffer, read
:data:`SIDE_PX` pixels to either side of the edge, shows one of the faces the edge bounds
(so an edge is hidden by anything drawn over it, and a back face's edges are never seen).
The longest run of visible samples is the reported segment.
"""
from typing import Optional, Sequence, Tuple

from mlofc_tools.render.geometry import clip_segments_to_rect, distort_pixels
import numpy as np

#: Sample spacing along an edge, px (occlusion ends are accurate to about this).
STEP_PX = 1.0
#: Distance of the face-id probes from the edge, px.
SIDE_PX = 1.5
#: A run that stops within this many samples of the clipped edge end is extended to it
#: (the probes next to a face corner can miss the face).
SNAP_SAMPLES = 3
#: Shortest reported visible segment, px.
MIN_LENGTH_PX = 2.0


def visible_segments(p1: np.ndarray, p2: np.ndarray, faces: np.ndarray, id_buffer: np.ndarray,
                     origin: Tuple[int, int], image_size: Tuple[int, int],
                     K: Optional[np.ndarray] = None,
                     dist: Optional[Sequence[float]] = None
                     ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Longest visible run of every projected edge.

    Parameters
    ----------
    p1, p2
        (N, 2) float64 projected (undistorted pinhole) endpoints, px.
    faces
        (N, 2) int global face ids the edge bounds (-1 for none).
    id_buffer
        (Hc, Wc) int32 face id of every canvas pixel (-1 empty); canvas pixel
        ``(i, j)`` is image pixel ``(u0 + j, v0 + i)``.
    origin
        ``(u0, v0)`` of the canvas in image pixels.
    image_size
        ``(width, height)`` of the output image.
    K, dist
        with plumb_bob ``dist``, a sample is also required to land inside the
        distorted output image.

    Returns ``(segments (N, 4) px, visible_fraction (N,), ok (N,) bool)``; rows with ``ok``
    False have no visible run of at least :data:`MIN_LENGTH_PX`.

    """
    n = len(p1)
    seg = np.zeros((n, 4))
    frac = np.zeros(n)
    ok = np.zeros(n, dtype=bool)
    if n == 0:
        return seg, frac, ok
    u0, v0 = origin
    hc, wc = id_buffer.shape
    width, height = image_size
    if dist is None:
        lo = (max(u0, 0), max(v0, 0))
        hi = (min(u0 + wc, width) - 1.0, min(v0 + hc, height) - 1.0)
    else:
        lo = (float(u0), float(v0))
        hi = (u0 + wc - 1.0, v0 + hc - 1.0)
    t0, t1, inside = clip_segments_to_rect(p1, p2, lo, hi)
    full_len = np.linalg.norm(p2 - p1, axis=1)
    clip_len = (t1 - t0) * full_len
    idx = np.nonzero(inside & (clip_len >= MIN_LENGTH_PX))[0]
    if len(idx) == 0:
        return seg, frac, ok
    d = p2[idx] - p1[idx]
    a = p1[idx] + t0[idx, None] * d
    b = p1[idx] + t1[idx, None] * d
    ab = b - a
    cnt = np.ceil(clip_len[idx] / STEP_PX).astype(np.int64) + 1
    start = np.concatenate([[0], np.cumsum(cnt)])
    owner = np.repeat(np.arange(len(idx)), cnt)
    k = np.arange(start[-1]) - start[owner]
    s = k / (cnt - 1.0)[owner]
    # sample points in canvas pixels (+0.5 so that truncation rounds to the nearest pixel)
    q = (a - [u0 - 0.5, v0 - 0.5])[owner] + s[:, None] * ab[owner]
    side = SIDE_PX * np.stack([-ab[:, 1], ab[:, 0]], axis=1) / np.linalg.norm(ab, axis=1)[:, None]
    side = side[owner]
    f1 = faces[idx, 0][owner]
    f2 = np.where(faces[idx, 1] >= 0, faces[idx, 1], -2)[owner]
    vis = np.zeros(len(q), dtype=bool)
    for pr in (q + side, q - side):
        col = np.clip(pr[:, 0], 0, wc - 1).astype(np.int64)
        row = np.clip(pr[:, 1], 0, hc - 1).astype(np.int64)
        fid = id_buffer[row, col]
        vis |= (fid == f1) | (fid == f2)
    if dist is not None:
        qd = distort_pixels(q + [u0 - 0.5, v0 - 0.5], K, dist)
        vis &= ((qd[:, 0] >= 0) & (qd[:, 0] <= width - 1)
                & (qd[:, 1] >= 0) & (qd[:, 1] <= height - 1))
    # runs of visible samples, in sample order (and so grouped by edge)
    first = k == 0
    prev_vis = np.concatenate([[False], vis[:-1]]) & ~first
    next_vis = np.concatenate([vis[1:], [False]]) & ~np.concatenate([first[1:], [True]])
    run_first = np.nonzero(vis & ~prev_vis)[0]
    run_last = np.nonzero(vis & ~next_vis)[0]
    if len(run_first) == 0:
        return seg, frac, ok
    run_len = run_last - run_first + 1
    run_owner = owner[run_first]
    # longest run per edge: sort by (owner, -length) and take the first of each owner
    order = np.lexsort((-run_len, run_owner))
    best = order[np.concatenate([[True], run_owner[order][1:] != run_owner[order][:-1]])]
    e = run_owner[best]
    k_a = k[run_first[best]]
    k_b = k_a + run_len[best] - 1
    last = cnt[e] - 1
    k_a = np.where(k_a <= SNAP_SAMPLES, 0, k_a)
    k_b = np.where(k_b >= last - SNAP_SAMPLES, last, k_b)
    sa = k_a / last
    sb = k_b / last
    pa = np.clip(a[e] + sa[:, None] * ab[e], lo, hi)     # clip: rounding only
    pb = np.clip(a[e] + sb[:, None] * ab[e], lo, hi)
    length = np.linalg.norm(pb - pa, axis=1)
    good = length >= MIN_LENGTH_PX
    rows = idx[e[good]]
    seg[rows] = np.concatenate([pa, pb], axis=1)[good]
    n_vis = np.bincount(owner[vis], minlength=len(idx))
    frac_all = n_vis / cnt * clip_len[idx] / np.maximum(full_len[idx], 1e-12)
    frac[rows] = np.minimum(1.0, frac_all[e[good]])
    ok[rows] = True
    return seg, frac, ok
