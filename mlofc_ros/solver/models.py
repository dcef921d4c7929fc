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
Per-body rotation models: residual costs of every track and (weighted) least-squares fits.

Two residuals exist side by side:

* ``weighted=False``: the paper's algebraic residual, the distance of each row ``y`` to the
  body's hyperplane ``u = [c ; 1]``: ``|y . u|^2 / |u|^2`` summed over a track's rows.
* ``weighted=True``: the Mahalanobis (Sampson) cost ``r^T S^-1 r`` with ``S`` the residual
  covariance propagated from 1 px endpoint noise (short lines weigh less). Divided by the true
  endpoint variance it is chi-square with ``2 * pairs`` degrees of freedom.
"""
from dataclasses import dataclass, field
from typing import Optional, Tuple

import numpy as np

from .lines import LineFlows


@dataclass
class TrackStats:
    """
    Per-track normal equations: the cost of a track under any ``c`` is a quadratic form.

    ``cost(c) = c^T A c - 2 g . c + k`` with ``A = sum M^T M``, ``g = sum M^T b``,
    ``k = sum b^T b`` over the track's frame pairs, with ``M, b`` whitened per track (weighted)
    or raw. Evaluating thousands of hypotheses, or refitting
    bodies, then costs O(N) 3x3 operations instead of O(pairs) covariance propagations.
    """

    A: np.ndarray       # (N, 3, 3)
    g: np.ndarray       # (N, 3)
    k: np.ndarray       # (N,)
    usable: np.ndarray  # (N,) bool: the track has at least one frame pair
    weighted: bool
    stacked: Optional[np.ndarray] = None   # (N, 12) [A, g], see fit_stats
    # fit_stats results by labelling: K-subspaces, the final pass and the covariances refit
    # the same labels in a row (the arrays are never modified, only copies handed out)
    fits: dict = field(default_factory=dict, repr=False, compare=False)


def track_stats(flows: LineFlows, weighted: bool = True) -> TrackStats:
    """
    Accumulate :class:`TrackStats` of every track (vectorised over pairs).

    Cached on ``flows``: the robust solve, its final pass and the covariances all need them.
    """
    key = ('stats', bool(weighted))
    if key not in flows.cache:
        flows.cache[key] = _track_stats(flows, weighted)
    return flows.cache[key]


def _track_stats(flows: LineFlows, weighted: bool) -> TrackStats:
    if weighted:
        # the 4x4 Gram matrix of every track's whitened rows holds A, g and k at once
        rows = flows.track_rows
        gram = np.matmul(rows.transpose(0, 2, 1), rows)
        return TrackStats(gram[:, :3, :3], -gram[:, :3, 3], gram[:, 3, 3],
                          flows.pairs_per_track() > 0, True)
    M, b = flows.M, flows.b
    n, pt = flows.n_tracks, flows.pair_track
    A = sum_by_track(np.einsum('pji,pjk->pik', M, M), pt, n)
    g = sum_by_track(np.einsum('pji,pj->pi', M, b), pt, n)
    k = sum_by_track(np.sum(b * b, axis=1), pt, n)
    return TrackStats(A, g, k, flows.pairs_per_track() > 0, weighted)


def quad_costs(stats: TrackStats, c: np.ndarray) -> np.ndarray:
    """
    Costs ``(N, H)`` of every track under every Cayley vector ``c (H, 3)`` (nan: unusable).

    Unweighted costs are divided by ``1 + |c|^2`` (distance to the hyperplane ``[c ; 1]``).
    """
    c = np.atleast_2d(c)
    # c^T A c for all (track, hypothesis) pairs as one (N, 9) x (9, H) product
    outer = (c[:, :, None] * c[:, None, :]).reshape(c.shape[0], 9)
    # the same operations in the same order as ``A c c - 2 g c + k``, in place (no temporaries
    # of (N, H))
    out = stats.A.reshape(-1, 9) @ outer.T
    out -= 2.0 * (stats.g @ c.T)
    out += stats.k[:, None]
    np.maximum(out, 0.0, out=out)
    if not stats.weighted:
        out /= 1.0 + np.sum(c * c, axis=1)[None, :]
    out[~stats.usable] = np.nan
    return out


def fit_stats(stats: TrackStats, labels: np.ndarray, n: int) -> Tuple[np.ndarray, np.ndarray]:
    """Least-squares ``c (n, 3)`` per body from its tracks' statistics; information (n, 3, 3)."""
    labels = np.asarray(labels)
    key = (n, labels.dtype.str, labels.tobytes())
    hit = stats.fits.get(key)
    if hit is None:
        if len(stats.fits) >= FIT_MEMO:
            stats.fits.clear()       # the repeats come in a row: a few entries are enough
        hit = stats.fits[key] = _fit_stats(stats, labels, n)
    return hit[0].copy(), hit[1].copy()


#: Labellings whose fits :func:`fit_stats` keeps (long K-subspaces runs would otherwise hold
#: one N-label key per iteration until the solve ends).
FIT_MEMO = 8


def _fit_stats(stats: TrackStats, labels: np.ndarray, n: int) -> Tuple[np.ndarray, np.ndarray]:
    use = (labels >= 0) & stats.usable
    # one weighted bincount over the 12 entries (A, g) of every track: it adds in track order
    # like np.add.at (the same sums), several times faster. The tracks not used go to the bins
    # of an extra body, dropped after: the others add up the same, without copying them out
    bins = (np.where(use, labels, n)[:, None] * 12 + _ENTRIES).ravel()
    sums = np.bincount(bins, weights=_stacked(stats).ravel(), minlength=12 * (n + 1))
    sums = sums[:12 * n].reshape(n, 12)
    info, rhs = sums[:, :9].reshape(n, 3, 3), sums[:, 9:]
    return solve_normal_equations(info, rhs), info


#: Entry offsets 0..11 of a track's ``A`` and ``g`` in :func:`_stacked` (made once, not per fit).
_ENTRIES = np.arange(12)


def _stacked(stats: TrackStats) -> np.ndarray:
    """``(N, 12)``: every track's ``A`` (row-major) and ``g`` side by side (computed once)."""
    if stats.stacked is None:
        stats.stacked = np.concatenate([stats.A.reshape(-1, 9), stats.g], axis=1)
    return stats.stacked


def sum_by_track(values: np.ndarray, pair_track: np.ndarray, n_tracks: int) -> np.ndarray:
    """
    Sum per-pair ``values (P, ...)`` into ``(n_tracks, ...)``; pairs are sorted by track.

    ``np.add.reduceat`` over the runs of equal track index: several times faster than
    ``np.add.at``, which matters because it runs on every cost evaluation.
    """
    out = np.zeros((n_tracks,) + values.shape[1:])
    if values.shape[0] == 0:
        return out
    starts = np.flatnonzero(np.r_[True, pair_track[1:] != pair_track[:-1]])
    out[pair_track[starts]] = np.add.reduceat(values, starts, axis=0)
    return out


def pair_costs(flows: LineFlows, c: np.ndarray) -> np.ndarray:
    """
    Algebraic (unweighted) cost ``(P, n)`` of every frame pair under every body.

    The distance of the pair's rows to the hyperplane ``[c ; 1]`` (the module docstring); the
    weighted costs are per track (:func:`track_costs`), since whitening couples a track's pairs.
    """
    c = np.atleast_2d(np.asarray(c, dtype=float))
    r = np.einsum('pjk,nk->pnj', flows.M, c) - flows.b[:, None, :]
    return np.sum(r * r, axis=2) / (1.0 + np.sum(c * c, axis=1))[None, :]


def track_costs(flows: LineFlows, c: np.ndarray, weighted: bool = True) -> np.ndarray:
    """
    Cost ``(N, n)`` of every track under every body: sum over its frame pairs.

    Tracks with no frame pair get ``nan``.
    """
    if weighted:
        # one product over every track's whitened rows (zero where a pair is missing), as a
        # single (N 2 (K-1), 4) x (4, n) matrix product: the same dot products as the batched
        # (N, 2 (K-1), 4) @ (4, n) (one BLAS call instead of N), 2-3x faster
        c = np.atleast_2d(np.asarray(c, dtype=float))
        u = np.empty((c.shape[0], 4))
        u[:, :3] = c
        u[:, 3] = 1.0
        rows = flows.track_rows
        r = (rows.reshape(-1, 4) @ u.T).reshape(rows.shape[:2] + (c.shape[0],))
        out = np.einsum('ndh,ndh->nh', r, r)
    else:
        out = sum_by_track(pair_costs(flows, c), flows.pair_track, flows.n_tracks)
    out[_empty_tracks(flows)] = np.nan
    return out


def _empty_tracks(flows: LineFlows) -> np.ndarray:
    """Return the tracks without a frame pair (cached on ``flows``: every cost needs them)."""
    out = flows.cache.get('empty')
    if out is None:
        out = flows.cache['empty'] = (flows.pairs_per_track() == 0).nonzero()[0]
    return out


def fit_bodies(flows: LineFlows, track_labels: np.ndarray, n: int, weighted: bool = True
               ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Least-squares Cayley vector ``(n, 3)`` of every body from the tracks labelled with it.

    Returns the Cayley vectors (zeros for a body without data) and the information matrices
    ``(n, 3, 3)`` (``sum M^T W M``, for 1 px noise when weighted): the covariance of ``c`` is
    ``sigma^2 info^-1``.
    """
    return fit_stats(track_stats(flows, weighted), np.asarray(track_labels), n)


def solve_normal_equations(info: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """
    Solve ``info c = rhs`` per body.

    A relative ridge keeps rank-deficient (and empty) bodies finite: a single line does not see
    the rotation about its own normal.
    """
    ridge = normal_ridge(info.trace(axis1=-2, axis2=-1))[..., None, None] * _EYE3
    return np.linalg.solve(info + ridge, rhs[..., None])[..., 0]


def normal_ridge(trace: np.ndarray) -> np.ndarray:
    """
    Ridge ``(...)`` added to the diagonal of 3x3 normal equations with the given traces.

    1e-9 of the mean eigenvalue (positive even for an empty system): what every solve of
    :func:`solve_normal_equations` and :func:`.robust.free_residuals` adds.
    """
    return 1e-9 * np.maximum(trace / 3.0, 1e-300)


def row_min(a: np.ndarray) -> np.ndarray:
    """
    Minimum ``(N,)`` of every row of a narrow ``(N, n)`` array (``n >= 1``, no nan).

    Taken column by column: the same values as ``a.min(axis=1)``, several times faster along
    the few bodies' short axis.
    """
    out = a[:, 0]
    for b in range(1, a.shape[1]):                        # bodies, not tracks
        out = np.minimum(out, a[:, b])
    return out


_EYE3 = np.eye(3)
_EYE3.setflags(write=False)


def median(x: np.ndarray) -> float:
    """
    ``np.median`` of a 1-D array without nan, from one partition (same value, less overhead).

    It runs in every K-subspaces iteration, where np.median's generic machinery cost more
    than the median itself.
    """
    m = x.shape[0]
    h = m // 2
    if m % 2:
        return float(np.partition(x, h)[h])
    part = np.partition(x, [h - 1, h])
    return float((part[h - 1] + part[h]) / 2.0)


#: Standard normal quantiles for the chi-square levels used here (no scipy at runtime).
_Z = {0.5: 0.0, 0.9: 1.2815516, 0.95: 1.6448536, 0.99: 2.3263479, 0.999: 3.0902323,
      0.9999: 3.7190165}


def chi2_quantile(p: float, dof) -> np.ndarray:
    """Wilson-Hilferty approximation of the chi-square quantile for ``p`` in ``_Z``."""
    k = np.maximum(np.asarray(dof, dtype=float), 1.0)
    h = 2.0 / (9.0 * k)
    # every z here is >= 0 and h <= 2/9, so the base is > 0 (a clip at 0 would change nothing)
    # and z = 0 adds nothing: the same values with fewer array operations
    base = 1.0 - h
    if _Z[p]:
        base += _Z[p] * np.sqrt(h)
    return k * base ** 3
