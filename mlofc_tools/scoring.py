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
Score algorithm output against ground truth: body labels, angular velocities, line tracks.

Library tests and benchmarks share these; nothing here imports the benchmarks.
"""
from collections import defaultdict
import itertools
import math
from typing import Dict, List, Optional, Sequence, Set, Tuple

import numpy as np


def best_permutation(pred: np.ndarray, truth: np.ndarray, n_bodies: int
                     ) -> Tuple[Tuple[int, ...], int]:
    """
    Relabelling of predicted body ids that agrees best with the truth.

    Parameters
    ----------
    pred : (N,) int
        Predicted body ids, ``-1`` = unassigned (always counted wrong).
    truth : (N,) int
        True body ids ``0 .. n_bodies-1``.
    n_bodies : int
        Number of bodies (predicted ids ``>= n_bodies`` are counted wrong).

    Returns
    -------
    perm : tuple of n_bodies ints
        ``perm[p]`` is the true body matched to predicted body ``p``.
    errors : int
        Misclassified lines under ``perm``.

    """
    pred = np.asarray(pred, dtype=np.int64)
    truth = np.asarray(truth, dtype=np.int64)
    valid = (pred >= 0) & (pred < n_bodies)
    conf = np.zeros((n_bodies, n_bodies), dtype=np.int64)  # conf[p, t]
    np.add.at(conf, (pred[valid], truth[valid]), 1)
    best, best_hits = tuple(range(n_bodies)), -1
    for perm in itertools.permutations(range(n_bodies)):
        hits = int(conf[np.arange(n_bodies), perm].sum())
        if hits > best_hits:
            best, best_hits = perm, hits
    return best, int(pred.shape[0] - best_hits)


def misclassification(pred: np.ndarray, truth: np.ndarray, n_bodies: int) -> float:
    """Fraction of misclassified lines (0..1), minimised over relabellings; ``-1`` is wrong."""
    _, errors = best_permutation(pred, truth, n_bodies)
    return errors / max(int(np.asarray(truth).shape[0]), 1)


def misclassification_any(pred: np.ndarray, truth: np.ndarray) -> float:
    """
    Fraction of misclassified lines (0..1) when the number of bodies itself was estimated.

    ``pred (N,)``: any body ids (``-1`` unassigned, always wrong); ``truth (N,)``: true ids.
    Predicted and true bodies are matched one to one to agree on the most lines; lines of a
    predicted body left unmatched (more bodies found than there are) are wrong.
    """
    pred = np.asarray(pred, dtype=np.int64)
    ok = pred >= 0
    # both numbered 0.. so that best_permutation matches them over the larger count
    found, compact = np.unique(pred[ok], return_inverse=True)
    numbered = np.full(pred.shape, -1, dtype=np.int64)
    numbered[ok] = compact
    bodies, true = np.unique(np.asarray(truth, dtype=np.int64), return_inverse=True)
    _, errors = best_permutation(numbered, true, max(len(found), len(bodies)))
    return errors / max(len(pred), 1)


def motion_errors(est: np.ndarray, truth: np.ndarray, perm: Sequence[int]
                  ) -> Tuple[float, float]:
    """
    Angular-velocity errors after matching bodies with ``perm``.

    Parameters
    ----------
    est
        (n, 3) estimated rotation vectors (rad/frame), row ``p`` = predicted body ``p``.
    truth
        (n, 3) true rotation vectors (rad/frame).
    perm
        ``perm[p]`` is the true body of predicted body ``p`` (:func:`best_permutation`).

    Returns
    -------
    relative : float
        Mean of ``|w_est - w_true| / |w_true|`` over the bodies that rotate (``|w_true| > 0``);
        NaN when none does.
    absolute_deg : float
        Mean of ``|w_est - w_true|`` over all bodies, in degrees per frame.

    """
    est = np.asarray(est, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    matched = truth[list(perm)]
    err = np.linalg.norm(est - matched, axis=1)
    norm = np.linalg.norm(matched, axis=1)
    rot = norm > 0
    rel = float(np.mean(err[rot] / norm[rot])) if np.any(rot) else math.nan
    return rel, float(np.degrees(err.mean()))


def match_to_truth(seg: np.ndarray, gt: np.ndarray, angle_deg: float = 3.0,
                   dist_px: float = 2.0, min_overlap: float = 0.5,
                   visible_fraction: Optional[np.ndarray] = None
                   ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Assign every segment (M, 4) px to the ground-truth segment (L, 4) px it lies on.

    A segment lies on a GT segment when their (unoriented) directions differ by less than
    ``angle_deg``, at least ``min_overlap`` of the segment's length projects inside the GT
    segment, and both endpoints of the overlapping part are within ``dist_px`` of the GT line.
    With ``visible_fraction`` (L,), GT segments of partly hidden edges (fraction < 0.95; the
    GT segment is only the longest visible part) are extended along their line by 4 lengths
    each way, so that a segment on another visible part of the same 3D edge still counts.
    Returns ``(gt_index (M,) intp, -1 when none; line_error (M,) px, the mean distance of the
    overlapping part's endpoints to the GT line; endpoint_error (M,) px, the mean distance of
    each segment endpoint to the nearer GT endpoint)``; errors are NaN for unmatched segments.
    """
    m, n = seg.shape[0], gt.shape[0]
    idx = np.full(m, -1, np.intp)
    line_err = np.full(m, np.nan)
    end_err = np.full(m, np.nan)
    if m == 0 or n == 0:
        return idx, line_err, end_err
    s = seg.astype(np.float64)
    g = gt.astype(np.float64).copy()
    if visible_fraction is not None:
        # partly hidden edges: any visible part of the 3D edge counts, i.e. its whole line
        # within the image (the GT segment is only the longest visible part)
        vf = np.asarray(visible_fraction, dtype=np.float64)
        ext = np.where(vf < 0.95, 4.0, 0.0)[:, None] * (g[:, 2:] - g[:, :2])
        g = np.concatenate([g[:, :2] - ext, g[:, 2:] + ext], axis=1)
    gd = g[:, 2:] - g[:, :2]
    gl = np.maximum(np.hypot(gd[:, 0], gd[:, 1]), 1e-9)
    gu = gd / gl[:, None]
    gn = np.stack([-gu[:, 1], gu[:, 0]], 1)
    sd = s[:, 2:] - s[:, :2]
    sl = np.maximum(np.hypot(sd[:, 0], sd[:, 1]), 1e-9)
    su = sd / sl[:, None]
    cos = np.abs(su @ gu.T)                                            # (M, L)
    r1 = s[:, None, :2] - g[None, :, :2]
    r2 = s[:, None, 2:] - g[None, :, :2]
    t1 = np.einsum('mlk,lk->ml', r1, gu)
    t2 = np.einsum('mlk,lk->ml', r2, gu)
    d1 = np.einsum('mlk,lk->ml', r1, gn)
    d2 = np.einsum('mlk,lk->ml', r2, gn)
    lo = np.clip(np.minimum(t1, t2), 0, gl[None, :])
    hi = np.clip(np.maximum(t1, t2), 0, gl[None, :])
    span = np.maximum(np.abs(t2 - t1), 1e-9)
    overlap = (hi - lo) / span
    # distances at the overlap ends, by linear interpolation of the signed distance
    da = d1 + (d2 - d1) * (lo - t1) / np.where(t2 != t1, t2 - t1, 1.0)
    db = d1 + (d2 - d1) * (hi - t1) / np.where(t2 != t1, t2 - t1, 1.0)
    dist = 0.5 * (np.abs(da) + np.abs(db))
    ok = (cos >= np.cos(np.deg2rad(angle_deg))) & (overlap >= min_overlap) \
        & (np.maximum(np.abs(da), np.abs(db)) <= dist_px)
    cost = np.where(ok, dist, np.inf)
    best = np.argmin(cost, axis=1)
    hit = np.isfinite(cost[np.arange(m), best])
    idx[hit] = best[hit]
    line_err[hit] = dist[np.arange(m), best][hit]
    gb = gt[best].astype(np.float64)
    e = np.minimum(np.hypot(*(s[:, :2] - gb[:, :2]).T), np.hypot(*(s[:, :2] - gb[:, 2:]).T)) \
        + np.minimum(np.hypot(*(s[:, 2:] - gb[:, :2]).T), np.hypot(*(s[:, 2:] - gb[:, 2:]).T))
    end_err[hit] = 0.5 * e[hit]
    return idx, line_err, end_err


def unresolvable_edges(gt: np.ndarray, angle_deg: float = 3.0, dist_px: float = 2.0,
                       min_overlap: float = 0.5) -> np.ndarray:
    """
    Mask (L,) of GT segments (L, 4) px that the image cannot separate from another one.

    Edge ``i`` is unresolvable when some other GT segment ``j`` is within ``angle_deg`` of it,
    overlaps at least ``min_overlap`` of ``i``'s length along ``i``'s line, and lies within
    ``dist_px`` of that line at both ends of the common part: the same tolerances by which
    :func:`match_to_truth` puts a segment on an edge, so a track on either could be matched to
    both (in the rendered sequences: stripes and box edges converging as a face turns
    edge-on).
    """
    n = gt.shape[0]
    if n < 2:
        return np.zeros(n, bool)
    g = gt.astype(np.float64)
    d = g[:, 2:] - g[:, :2]
    gl = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    u = d / gl[:, None]
    nrm = np.stack([-u[:, 1], u[:, 0]], 1)
    cos = np.abs(u @ u.T)                                              # (i, j)
    r1 = g[None, :, :2] - g[:, None, :2]                               # j's ends rel. to i
    r2 = g[None, :, 2:] - g[:, None, :2]
    t1 = np.einsum('ijk,ik->ij', r1, u)
    t2 = np.einsum('ijk,ik->ij', r2, u)
    d1 = np.einsum('ijk,ik->ij', r1, nrm)
    d2 = np.einsum('ijk,ik->ij', r2, nrm)
    lo = np.clip(np.minimum(t1, t2), 0, gl[:, None])
    hi = np.clip(np.maximum(t1, t2), 0, gl[:, None])
    den = np.where(t2 != t1, t2 - t1, 1.0)
    da = d1 + (d2 - d1) * (lo - t1) / den
    db = d1 + (d2 - d1) * (hi - t1) / den
    close = (cos >= np.cos(np.deg2rad(angle_deg))) & (hi - lo >= min_overlap * gl[:, None]) \
        & (np.maximum(np.abs(da), np.abs(db)) <= dist_px)
    np.fill_diagonal(close, False)
    return close.any(axis=1)


def score_tracks(frames_ids: Sequence[np.ndarray], frames_seg: Sequence[np.ndarray],
                 truth: Sequence[object], min_gt_length: float = 30.0, window: int = 5,
                 use_distorted: bool = False) -> Dict[str, float]:
    """
    Score track output against rendered ground truth.

    ``frames_ids[f]`` (M_f,) and ``frames_seg[f]`` (M_f, 4) px are the tracker output of frame
    ``f``; ``truth[f]`` a ``FrameTruth``. GT edges count when at least ``min_gt_length`` px
    long. Returns a dict:

    * ``tracked_5``: share of (GT edge, ``window`` consecutive frames with the edge present)
      pairs in which one track id lies on the edge in all ``window`` frames;
    * ``recall``: share of (GT edge, frame) pairs with some track on the edge;
    * ``id_switch_pct``: GT side, % of frames (with the edge matched before and now) where
      none of the edge's current tracks carries its previous id (MOT-style switches);
    * ``id_jump_pct``: track side, % of a track's consecutive matched frames where it moved
      to a different GT edge (a track mixing two 3D lines); ``cross_body_jump_pct``: the
      same for moves to an edge of another body (the harmful kind for motion segmentation);
    * ``line_err_px`` / ``endpoint_err_px``: median errors of the matched track segments;
    * ``precision``: share of reported segments lying on some GT edge (any length);
    * ``tracked_5_resolvable`` / ``id_switch_pct_resolvable``: the same as ``tracked_5`` /
      ``id_switch_pct`` counting only windows / transitions in which the edge is resolvable in
      every frame (see :func:`unresolvable_edges`); ``unresolvable_window_pct``: % of the
      ``tracked_5`` windows so left out;
    * ``id_switch_pct_in_view``: ``id_switch_pct`` over the transitions (``transitions_in_view``)
      where the edge stayed in view in between (long enough in every frame since it was last
      matched): the switches left when re-acquisitions of an edge that went out of view (a
      face turning away and back) are not counted; no tracker re-identifies those.
    """
    m = _match_frames(frames_ids, frames_seg, truth, min_gt_length, use_distorted)
    c: Dict[str, int] = defaultdict(int)
    for e, fr in m.present.items():
        _count_windows(c, e, fr, m, window)
        _count_switches(c, e, set(fr), m)
    _count_jumps(c, m)
    return _track_scores(c, m)


class _Matched:
    """Per-frame matches of track segments to GT edges (see :func:`_match_frames`)."""

    def __init__(self) -> None:
        self.present: Dict[int, List[int]] = defaultdict(list)  # edge -> frames present (long)
        self.unres: List[Set[int]] = []                         # frame -> unresolvable edges
        self.on_edge: List[Dict[int, Set[int]]] = []            # frame -> edge -> track ids
        self.track_edges: Dict[int, List[int]] = defaultdict(list)
        self.edge_body: Dict[int, int] = {}
        self.line_errs: List[float] = []
        self.end_errs: List[float] = []
        self.n_rep = 0
        self.n_hit = 0


def _match_frames(frames_ids: Sequence[np.ndarray], frames_seg: Sequence[np.ndarray],
                  truth: Sequence[object], min_gt_length: float, use_distorted: bool
                  ) -> _Matched:
    """Match every frame's segments to its GT edges; collect what the scores count."""
    m = _Matched()
    for f, (ids, seg, tr) in enumerate(zip(frames_ids, frames_seg, truth)):
        gt = tr.segments_distorted if use_distorted else tr.segments
        glen = np.hypot(gt[:, 2] - gt[:, 0], gt[:, 3] - gt[:, 1])
        gi, le, ee = match_to_truth(seg, gt, visible_fraction=tr.visible_fraction)
        m.n_rep += len(ids)
        m.n_hit += int((gi >= 0).sum())
        long_ = glen >= min_gt_length
        m.unres.append(set(tr.edge_ids[unresolvable_edges(gt)].tolist()))
        for e in tr.edge_ids[long_]:
            m.present[int(e)].append(f)
        m.edge_body.update(zip(tr.edge_ids.tolist(), tr.body_ids.tolist()))
        d: Dict[int, Set[int]] = defaultdict(set)
        for tid, j in zip(ids[gi >= 0], gi[gi >= 0]):
            eid = int(tr.edge_ids[j])
            d[eid].add(int(tid))
            m.track_edges[int(tid)].append(eid)
        m.on_edge.append(d)
        sel = (gi >= 0)
        sel[sel] = long_[gi[sel]]
        m.line_errs.extend(le[sel].tolist())
        m.end_errs.extend(ee[sel].tolist())
    return m


def _count_windows(c: Dict[str, int], e: int, fr: List[int], m: _Matched, window: int
                   ) -> None:
    """Count edge ``e``'s recall frames and its ``window``-frame runs held by one track."""
    fr_set = set(fr)
    for f in fr:
        c['rec_tot'] += 1
        c['rec'] += bool(m.on_edge[f].get(e))
        if all((f + k) in fr_set for k in range(window)):
            c['tot5'] += 1
            held = set(m.on_edge[f].get(e, set()))
            for k in range(1, window):
                held &= m.on_edge[f + k].get(e, set())
            c['ok5'] += bool(held)
            if not any(e in m.unres[f + k] for k in range(window)):
                c['tot5r'] += 1
                c['ok5r'] += bool(held)


def _count_switches(c: Dict[str, int], e: int, fr_set: Set[int], m: _Matched) -> None:
    """Count edge ``e``'s transitions between matched frames and the id switches among them."""
    prev: Optional[Set[int]] = None
    pf = -1
    for f in range(len(m.on_edge)):
        cur = m.on_edge[f].get(e)
        if not cur:
            continue
        if prev:
            switched = not (prev & cur)
            c['sw_tot'] += 1
            c['sw'] += switched
            if e not in m.unres[pf] and e not in m.unres[f]:
                c['sw_totr'] += 1
                c['swr'] += switched
            if all(g in fr_set for g in range(pf + 1, f)):
                c['sw_totv'] += 1
                c['swv'] += switched
        prev, pf = cur, f


def _count_jumps(c: Dict[str, int], m: _Matched) -> None:
    """Count the tracks' moves to another GT edge, and to an edge of another body."""
    for seq in m.track_edges.values():
        a = np.asarray(seq)
        c['jump_tot'] += max(a.size - 1, 0)
        c['jumps'] += int(np.count_nonzero(a[1:] != a[:-1]))
        b = np.asarray([m.edge_body[e] for e in seq])
        c['cross'] += int(np.count_nonzero(b[1:] != b[:-1]))


def _track_scores(c: Dict[str, int], m: _Matched) -> Dict[str, float]:
    """Turn the counts into the scores :func:`score_tracks` returns (NaN without a count)."""
    nan = float('nan')

    def ratio(num: float, den: int, scale: float = 1.0) -> float:
        return scale * num / den if den else nan

    return {
        'tracked_5': ratio(c['ok5'], c['tot5']),
        'windows': c['tot5'],
        'recall': ratio(c['rec'], c['rec_tot']),
        'id_switch_pct': ratio(c['sw'], c['sw_tot'], 100.0),
        'transitions': c['sw_tot'],
        'id_jump_pct': ratio(c['jumps'], c['jump_tot'], 100.0),
        'cross_body_jump_pct': ratio(c['cross'], c['jump_tot'], 100.0),
        'line_err_px': float(np.median(m.line_errs)) if m.line_errs else nan,
        'endpoint_err_px': float(np.median(m.end_errs)) if m.end_errs else nan,
        'precision': ratio(m.n_hit, m.n_rep),
        'tracked_5_resolvable': ratio(c['ok5r'], c['tot5r']),
        'id_switch_pct_resolvable': ratio(c['swr'], c['sw_totr'], 100.0),
        'unresolvable_window_pct': ratio(c['tot5'] - c['tot5r'], c['tot5'], 100.0),
        'id_switch_pct_in_view': ratio(c['swv'], c['sw_totv'], 100.0),
        'transitions_in_view': c['sw_totv'],
    }
