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

from .lines import LineFlows
from .models import fit_bodies, track_costs


def assign(costs: np.ndarray, threshold: Optional[np.ndarray] = None) -> np.ndarray:
    """Labels ``(N,)`` = argmin of ``costs (N, n)``; ``-1`` for unusable tracks (nan) and above
    ``threshold (N,)`` when given (outliers)."""
    ok = np.isfinite(costs).all(axis=1)
    labels = np.full(costs.shape[0], -1, dtype=np.int64)
    if costs.shape[1] == 0:
        return labels
    labels[ok] = np.argmin(costs[ok], axis=1)
    if threshold is not None:
        best = np.where(ok, np.min(np.where(ok[:, None], costs, 0.0), axis=1), np.inf)
        labels[best > threshold] = -1
    return labels


def _reseed_empty(labels: np.ndarray, costs: np.ndarray, n: int, min_tracks: int) -> np.ndarray:
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


def ksubspaces(flows: LineFlows, n: int, labels: np.ndarray, weighted: bool,
               max_iter: int = 100, c0: Optional[np.ndarray] = None,
               threshold: Optional[np.ndarray] = None,
               min_tracks: int = 2) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Refine a labelling until it stops changing.

    Parameters
    ----------
    flows : LineFlows
    n : int
        Number of bodies.
    labels : (N,) int
        Initial labels (``-1`` = unused).
    weighted : bool
        Mahalanobis costs and fits (ours) or the paper's algebraic ones.
    threshold : (N,), optional
        Per-track outlier threshold on the cost: tracks above it get ``-1`` and do not move
        any body.

    Returns
    -------
    labels : (N,), c : (n, 3) Cayley vectors, costs : (N, n).
    """
    labels = np.asarray(labels, dtype=np.int64).copy()
    c = c0
    costs = None
    for _ in range(max_iter):
        c, _ = fit_bodies(flows, labels, n, weighted=weighted, c0=c)
        costs = track_costs(flows, c, weighted)
        new = assign(costs, threshold)
        new = _reseed_empty(new, costs, n, min_tracks)
        if np.array_equal(new, labels):
            break
        labels = new
    return labels, c, costs


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
