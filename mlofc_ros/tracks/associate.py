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
Association of detections with tracks, fusion of the claimed fragments, births and duplicates.

Each detection joins the track (carried, or predicted when carrying failed) with the lowest
normalised cost among those passing the gates (angle, distance of its endpoints to the track's
line, overlap along the line). A track may absorb several collinear fragments, fused by a
length-weighted TLS fit. Detections left unclaimed get a second chance with wider gates
(mutual best match with an unmatched track only), then start new tracks; a track lying on the
same line as an older one is dropped as a duplicate.
"""
from typing import NamedTuple, Tuple

from mlofc_ros.segments.common import angle_pairs
from mlofc_ros.tracks.edges import tls_by_group
import numpy as np

#: Association gates: angle between lines (deg), distance of the detection's endpoints to the
#: track's line (px), overlap along the line over the shorter segment's length.
ANGLE_DEG = 3.0
DISTANCE_PX = 2.0
MIN_OVERLAP = 0.3
#: Detections left unclaimed get a second, mutual-best association to the unmatched tracks
#: with gates widened by this factor, so a track drifted slightly off its edge keeps its id
#: (3 rather than 2: fewer id switches on the rendered sequences, longer lives on the real
#: ones, bench frontend).
RESCUE_GATE = 3.0
#: After the first frame, two unclaimed detections within ANGLE_DEG, overlapping along the
#: line (>= 0.3 of the shorter) and with centres at most this far apart across it (px) are not
#: born: the converging stripes of a face turning into view, whose tracks would collapse onto
#: each other and switch ids (measured: own_centre id switches 1.22 -> 0.96 %, bench
#: frontend); they are born once the edges part.
BIRTH_CLEAR_PX = 3.0


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
    """Return the pairs ``(i, j)`` of segments (M, 4) within ``angle_deg`` (mod 180) and lines."""
    x1, y1, x2, y2 = seg.T
    length = np.maximum(np.hypot(x2 - x1, y2 - y1), 1e-9)
    ux, uy = (x2 - x1) / length, (y2 - y1) / length
    theta = np.mod(np.arctan2(uy, ux), np.pi)
    i, j = angle_pairs(theta, np.full(seg.shape[0], np.deg2rad(angle_deg)), np.pi)
    lines = _Lines(x1, y1, x2, y2, length, ux, uy, 0.5 * (x1 + x2), 0.5 * (y1 + y2))
    return i, j, lines


def _overlap(g: _Lines, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Return the overlap of segments ``p`` with ``q`` along q's lines, over the shorter length."""
    a = (g.x1[p] - g.cx[q]) * g.ux[q] + (g.y1[p] - g.cy[q]) * g.uy[q]
    b = (g.x2[p] - g.cx[q]) * g.ux[q] + (g.y2[p] - g.cy[q]) * g.uy[q]
    lo = np.maximum(np.minimum(a, b), -0.5 * g.length[q])
    hi = np.minimum(np.maximum(a, b), 0.5 * g.length[q])
    return (hi - lo) / np.minimum(g.length[p], g.length[q])


def associate(trk: np.ndarray, det: np.ndarray, loose: np.ndarray, confirmed: np.ndarray
              ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the best track index (or -1) for each detection and which were absorbed, (D,) each.

    ``trk`` (T, 4) and ``det`` (D, 4) px; ``loose`` (T,) doubles the gates of those tracks.

    Absorbed: the detections rescued by a track ``confirmed`` (T,) on the image edges.
    """
    t_n, d_n = trk.shape[0], det.shape[0]
    absorbed = np.zeros(d_n, bool)
    if t_n == 0 or d_n == 0:
        return np.full(d_n, -1, np.intp), absorbed
    cost = _cost(trk, det, np.where(loose, 2.0, 1.0))
    best = np.argmin(cost, axis=0)
    owner = np.where(np.isfinite(cost[best, np.arange(d_n)]), best, -1)
    # second chance, mutual best only: a track that drifted a little off its edge
    # takes the detection back instead of a new id being born on the edge
    taken = np.zeros(t_n, bool)
    taken[owner[owner >= 0]] = True
    ft = np.flatnonzero(~taken)          # = setdiff1d, without its sorting
    fd = np.nonzero(owner < 0)[0]
    if ft.size and fd.size:
        # RESCUE_GATE replaces (does not multiply) the x2 of uncarried tracks: wider
        # gates let detections of other edges in
        c2 = _cost(trk[ft], det[fd], np.full(ft.size, RESCUE_GATE))
        bt = np.argmin(c2, axis=0)
        bd = np.argmin(c2, axis=1)
        ok = np.isfinite(c2[bt, np.arange(fd.size)]) & (bd[bt] == np.arange(fd.size))
        owner[fd[ok]] = ft[bt[ok]]
        # a track whose carry the edge search confirmed is on its edge: the detection
        # so rescued is a neighbouring edge's, absorbed (not born) but not fused
        absorbed[fd[ok]] = confirmed[ft[bt[ok]]]
    return owner, absorbed


def _cost(trk: np.ndarray, det: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Return the association cost (T, D), inf outside the gates ``scale`` (T,) widens."""
    t_n, d_n = trk.shape[0], det.shape[0]
    tx1, ty1, tx2, ty2 = trk.T
    dx1, dy1, dx2, dy2 = det.T
    tl = np.maximum(np.hypot(tx2 - tx1, ty2 - ty1), 1e-9)
    tux, tuy = (tx2 - tx1) / tl, (ty2 - ty1) / tl
    dl = np.maximum(np.hypot(dx2 - dx1, dy2 - dy1), 1e-9)
    dux, duy = (dx2 - dx1) / dl, (dy2 - dy1) / dl
    tcx, tcy = 0.5 * (tx1 + tx2), 0.5 * (ty1 + ty2)
    dist_thr = DISTANCE_PX * scale
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
    ang_thr = np.maximum(np.deg2rad(ANGLE_DEG) * sc,
                         np.arctan2(thr, np.minimum(ti, dl[j])))
    gate = cosang >= np.cos(ang_thr)
    # overlap along the track line, over the shorter length
    a1 = rx1.ravel()[pair] * tux[i] + ry1.ravel()[pair] * tuy[i]
    a2 = rx2.ravel()[pair] * tux[i] + ry2.ravel()[pair] * tuy[i]
    half = 0.5 * ti
    lo = np.maximum(np.minimum(a1, a2), -half)
    hi = np.minimum(np.maximum(a1, a2), half)
    overlap = (hi - lo) / np.minimum(ti, dl[j])
    gate &= overlap >= MIN_OVERLAP
    ang = np.arccos(np.minimum(cosang, 1.0))
    cost = np.full((t_n, d_n), np.inf)
    cost.ravel()[pair[gate]] = (dist.ravel()[pair] / thr + ang / ang_thr
                                - 0.5 * np.minimum(overlap, 1.0))[gate]
    return cost


def fuse(det: np.ndarray, owner: np.ndarray, t_n: int, ref: np.ndarray) -> np.ndarray:
    """
    Fuse the detections (D, 4) claimed by each track into one segment per track.

    ``owner`` (D,) holds track indices in ``[0, t_n)``; ``ref`` (t_n, 4) the tracks' current
    segments, whose orientation is kept. Returns (t_n, 4): the length-weighted TLS line of
    the claimed detections spanning their extreme endpoint projections (rows of tracks
    without detections are meaningless).
    """
    p1, p2 = det[:, :2], det[:, 2:]
    d = p2 - p1
    w = np.hypot(d[:, 0], d[:, 1])
    mid = 0.5 * (p1 + p2)
    c, u, _ = tls_by_group(mid[:, 0], mid[:, 1], w, owner, t_n,
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


def crowded(born: np.ndarray) -> np.ndarray:
    """
    Return the mask (B,) of segments ``born`` (B, 4) with a close, parallel, overlapping one.

    A neighbour is another segment within :data:`ANGLE_DEG`, overlapping at least 0.3 of the
    shorter one along the first's line, whose centre lies between 0.25 px (a duplicate
    fragment of the same line is no neighbour) and :data:`BIRTH_CLEAR_PX` across that line.
    """
    out = np.zeros(born.shape[0], bool)
    if born.shape[0] < 2:
        return out
    i, j, g = _parallel_pairs(born, ANGLE_DEG)
    off = np.abs((g.cx[j] - g.cx[i]) * g.uy[i] - (g.cy[j] - g.cy[i]) * g.ux[i])
    over = _overlap(g, j, i)
    hit = (off > 0.25) & (off <= BIRTH_CLEAR_PX) & (over >= 0.3)
    out[i[hit]] = True
    return out


def duplicates(seg: np.ndarray, age: np.ndarray) -> np.ndarray:
    """Return the mask (T,) of tracks on the same line as an older (or as old, longer) one."""
    dup = np.zeros(seg.shape[0], bool)
    if seg.shape[0] < 2:
        return dup
    i, j, g = _parallel_pairs(seg, ANGLE_DEG)
    length = g.length
    # i is the younger one (smaller age; same age: shorter, or as long and later index):
    # tracks born together are told apart by the line they hold, not by their order
    keep = (age[i] < age[j]) | ((age[i] == age[j]) & (
        (length[i] < length[j]) | ((length[i] == length[j]) & (i > j))))
    i, j = i[keep], j[keep]
    off = np.maximum(np.abs((g.x1[i] - g.cx[j]) * g.uy[j] - (g.y1[i] - g.cy[j]) * g.ux[j]),
                     np.abs((g.x2[i] - g.cx[j]) * g.uy[j] - (g.y2[i] - g.cy[j]) * g.ux[j]))
    hit = (off <= 0.5 * DISTANCE_PX) & (_overlap(g, i, j) >= 0.5)
    dup[i[hit]] = True
    return dup
