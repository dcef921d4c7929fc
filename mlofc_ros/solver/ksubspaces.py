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
"""K-subspaces ("K-means" in the paper): alternate per-body fits and per-track assignment."""
from typing import Optional, Tuple

import numpy as np

from .models import chi2_quantile, fit_stats, median, quad_costs, row_min, TrackStats


def assign(costs: np.ndarray, threshold: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Label ``(N,)`` every track with the argmin of ``costs (N, n)``.

    ``-1`` for unusable tracks (nan) and above ``threshold (N,)`` when given (outliers).
    """
    if costs.shape[1] == 0:
        return np.full(costs.shape[0], -1, dtype=np.int64)
    ok = np.isfinite(costs).all(axis=1)
    labels = np.where(ok[:, None], costs, 0.0).argmin(axis=1)
    out = ~ok
    if threshold is not None:
        out |= costs[np.arange(costs.shape[0]), labels] > threshold
    labels[out] = -1
    return labels


def reseed_empty(labels: np.ndarray, costs: np.ndarray, n: int, min_tracks: int) -> np.ndarray:
    """Give a body that lost its tracks the worst-explained tracks, so no body dies out."""
    counts = np.bincount(labels[labels >= 0], minlength=n)
    if np.all(counts >= min_tracks):
        return labels
    labels = labels.copy()
    best = np.min(np.where(np.isfinite(costs), costs, -np.inf), axis=1)
    order = np.argsort(-best)
    taken = 0
    for body in np.flatnonzero(counts < min_tracks):           # at most n bodies
        pick = order[taken:taken + min_tracks]
        labels[pick] = body
        taken += min_tracks
    return labels


def ksubspaces(stats: TrackStats, n: int, labels: np.ndarray, max_iter: int = 100,
               threshold: Optional[np.ndarray] = None, min_tracks: int = 2,
               trim_dof: Optional[np.ndarray] = None, trim_p: float = 0.9999
               ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Refine a labelling until it stops changing.

    Parameters
    ----------
    stats : TrackStats
        Per-track normal equations, weighted (ours) or not (the paper's K-means).
    n : int
        Number of bodies.
    labels : (N,) int
        Initial labels (``-1`` = unused).
    max_iter : int
        Most refinement rounds (a labelling that cycles is stopped earlier).
    threshold : (N,), optional
        Per-track outlier threshold on the cost: tracks above it get ``-1`` and do not move
        any body.
    min_tracks : int
        Fewest tracks a body keeps: an emptier body is reseeded with the worst-explained
        tracks, so no body dies out.
    trim_dof : (N,), optional
        Degrees of freedom of every track's cost: when given (and no ``threshold``), every
        iteration re-estimates the noise from the median cost and excludes the tracks above the
        ``trim_p`` chi-square bound from the next fit, so gross outliers never pull a body.
    trim_p : float
        Chi-square probability of the trimming bound.

    Returns
    -------
    labels : (N,), c : (n, 3) Cayley vectors, costs : (N, n).

    """
    labels = np.asarray(labels, dtype=np.int64).copy()
    # the chi-square quantiles of the trimming depend on the dof only: computed once
    trim_q = None if trim_dof is None else (chi2_quantile(0.5, trim_dof),
                                            chi2_quantile(trim_p, trim_dof))

    def step(lab: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        c, _ = fit_stats(stats, lab, n)
        costs = quad_costs(stats, c)
        bound = threshold
        if bound is None and trim_dof is not None:
            bound = trim_bound(costs, trim_dof, trim_p, quantiles=trim_q)
        new = assign(costs, bound)
        if threshold is None:
            new = reseed_empty(new, costs, n, min_tracks)
        return c, costs, new

    history, seen = [labels], {labels.tobytes(): 0}
    c = costs = None
    for it in range(max_iter):
        c, costs, new = step(labels)
        if np.array_equal(new, labels):
            break
        j = seen.get(new.tobytes())
        if j is not None:
            # labels seen before: a cycle (trimming can flip borderline tracks back and forth).
            # Each step depends on the labels only, so the remaining iterations would go round
            # it: jump to where max_iter iterations end (the same result, without the laps)
            period = it + 1 - j
            c, costs, _ = step(history[j + (max_iter - 1 - j) % period])
            return history[j + (max_iter - j) % period].copy(), c, costs
        seen[new.tobytes()] = it + 1
        history.append(new)
        labels = new
    return labels, c, costs


def trim_bound(costs: np.ndarray, dof: np.ndarray, p: float = 0.9999,
               floor: float = 1e-8, quantiles: Optional[Tuple[np.ndarray, np.ndarray]] = None
               ) -> np.ndarray:
    """
    Per-track chi-square bound ``(N,)`` at the noise estimated from the median best cost.

    ``quantiles``: ``(chi2_quantile(0.5, dof), chi2_quantile(p, dof))`` when already computed.
    """
    ok = np.isfinite(costs).all(axis=1) & (dof > 0)
    q50, qp = quantiles if quantiles is not None else (chi2_quantile(0.5, dof),
                                                       chi2_quantile(p, dof))
    if ok.all() and costs.shape[1]:
        best = row_min(costs) / q50                       # the usual case, without gathers
    elif ok.any():
        best = np.min(costs[ok], axis=1) / q50[ok]
    else:
        return np.full(costs.shape[0], np.inf)
    return qp * max(median(best), floor)


def total_cost(costs: np.ndarray, labels: np.ndarray, cap: Optional[np.ndarray] = None) -> float:
    """Sum of each track's cost under its label, capped at ``cap`` (outliers pay the cap)."""
    ok = labels >= 0
    best = np.full(costs.shape[0], np.nan)
    best[ok] = costs[np.flatnonzero(ok), labels[ok]]
    usable = np.isfinite(costs).all(axis=1)
    if cap is None:
        return float(np.nansum(best[usable]))
    best = np.where(ok, best, np.inf)
    return float(np.sum(np.minimum(best, cap)[usable]))
