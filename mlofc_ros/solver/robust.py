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
"""Our robust method: several initialisations, noise-weighted K-subspaces, outlier rejection.

Candidates (all refined by Mahalanobis-weighted K-subspaces):

1. the noise-whitened algebraic (GPCA) solution,
2. the paper's algebraic solution,
3. sequential MSAC on minimal samples of two tracks, half of them spatially local (tracks near
   each other in the image tend to share a body, as in NAPSAC / Progressive-X),

and the candidate with the lowest truncated total cost wins. Tracks whose best cost exceeds the
chi-square 99.99% bound at the estimated endpoint noise get ``-1`` and move no body.
"""
from typing import Optional, Tuple

import numpy as np

from .gpca import algebraic_normals
from .ksubspaces import assign, ksubspaces, total_cost
from .lines import first_midpoints, LineFlows
from .models import (chi2_quantile, fit_bodies, median, quad_costs, solve_normal_equations,
                     track_costs, track_stats, TrackStats)
from .spatial import smooth_labels, spatial_neighbours

#: A warm start is accepted alone when it leaves at least this share of the tracks as inliers
#: (tracker noise is heavier-tailed than Gaussian: 78-88% measured on rendered windows).
WARM_INLIERS = 0.75

#: Outlier level: a track is rejected when its cost exceeds this chi-square quantile (99.99%:
#: tracker noise is heavier-tailed than Gaussian; 99.9% left ~7% of rendered segments -1).
OUTLIER_P = 0.9999


def noise_sigma(costs: np.ndarray, labels: np.ndarray, dof: np.ndarray,
                floor: float = 1e-6) -> float:
    """Robust endpoint noise (px) from the costs of the labelled tracks (median of chi-square)."""
    rows = (labels >= 0).nonzero()[0]
    if not rows.size:
        return 1.0
    best = costs[rows, labels[rows]] / chi2_quantile(0.5, dof[rows])
    return float(max(np.sqrt(median(best)), floor))


def _sample_pairs(rng: np.random.Generator, pool: np.ndarray, mid: np.ndarray,
                  n_samples: int, neighbours: int = 6) -> np.ndarray:
    """``(H, 2)`` track index pairs from ``pool``: half global, half spatially local."""
    first = rng.choice(pool, size=n_samples)
    second = rng.choice(pool, size=n_samples)
    local = np.arange(n_samples) % 2 == 0
    if pool.size > 2 and np.any(local):
        # the same values as np.linalg.norm over the last axis, without its slow length-2
        # reduction
        dx = mid[first[local], 0, None] - mid[None, pool, 0]
        dy = mid[first[local], 1, None] - mid[None, pool, 1]
        d = np.sqrt(dx * dx + dy * dy)
        k = min(neighbours, pool.size - 1)
        near = np.argpartition(d, k, axis=1)[:, 1:k + 1]               # skip itself
        second[local] = pool[near[np.arange(near.shape[0]), rng.integers(0, k, near.shape[0])]]
    same = first == second
    second[same] = pool[(np.searchsorted(pool, first[same]) + 1) % pool.size]
    return np.stack([first, second], axis=1)


def _column_quantile(x: np.ndarray, q: float) -> np.ndarray:
    """``np.quantile(x, q, axis=0)`` (method 'linear') of ``x (R, H)`` without nan, ``(H,)``.

    The same order statistics and interpolation as numpy, from one partition at the lower rank
    (numpy's quantile moves axes and partitions at extra ranks: 5x slower here).
    """
    v = (x.shape[0] - 1) * q
    lo = int(np.floor(v))
    part = np.partition(x, lo, axis=0)
    a = part[lo]
    # the next order statistic is the least value above rank lo: a partition at both ranks
    # costs 2.5x the one at lo (measured), this reduction a tenth of it
    b = part[lo + 1:].min(axis=0) if lo + 1 < x.shape[0] else a
    t = v - lo
    diff = b - a
    return b - diff * (1.0 - t) if t >= 0.5 else a + diff * t


def sequential_msac(stats: TrackStats, tracks: np.ndarray, n: int, dof: np.ndarray,
                    rng: np.random.Generator, n_samples: int = 200
                    ) -> Tuple[np.ndarray, float]:
    """Labels from fitting one body at a time to the tracks not yet explained; noise (px).

    Scale-free: a hypothesis is scored by a low quantile of its per-degree-of-freedom costs
    over the remaining tracks (least k-th order statistic, k = half the expected share of the
    largest remaining body), so no noise level is needed up front; the noise is then estimated
    from the first, largest body and sets the chi-square inlier bound.
    """
    mid = first_midpoints(tracks)
    labels = np.full(stats.A.shape[0], -1, dtype=np.int64)
    pool = np.flatnonzero(stats.usable)
    sigma2 = None
    for body in range(n):
        if pool.size < 2:
            break
        # the last body too is a hypothesis search: what is left also holds the outliers
        pairs = _sample_pairs(rng, pool, mid, n_samples)
        hyp = solve_normal_equations(stats.A[pairs[:, 0]] + stats.A[pairs[:, 1]],
                                     stats.g[pairs[:, 0]] + stats.g[pairs[:, 1]])
        costs = quad_costs(stats, hyp)[pool]                          # (|pool|, H)
        per_dof = costs / np.maximum(dof[pool, None], 1.0)
        q = 0.5 / (n - body)
        kth = _column_quantile(per_dof, q)
        best = int(np.argmin(kth))
        if sigma2 is None:
            # inliers of the best body: per-dof chi-square, median ~ chi2_median(d) / d
            d = float(np.median(dof[pool]))
            sigma2 = max(float(kth[best]) * d / float(chi2_quantile(0.5, d)), 1e-12)
        inside = costs[:, best] < chi2_quantile(OUTLIER_P, dof[pool]) * sigma2
        labels[pool[inside]] = body
        pool = pool[~inside]
    return labels, float(np.sqrt(sigma2)) if sigma2 is not None else 1.0


def robust_segmentation(flows: LineFlows, tracks: np.ndarray, n: int,
                        rng: np.random.Generator, sigma: Optional[float] = None,
                        init_labels: Optional[np.ndarray] = None
                        ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Best of several initialisations, weighted K-subspaces, outliers rejected.

    Returns labels ``(N,)``, Cayley vectors ``(n, 3)``, exact costs ``(N, n)`` and diagnostics.
    """
    stats = track_stats(flows, weighted=True)
    dof = 2.0 * flows.pairs_per_track()
    refined = []
    if init_labels is not None:
        # warm start (the previous window's labels): when they still explain the window, the
        # other starts are skipped -- the common case in a stream, and 3-5x cheaper
        init = np.asarray(init_labels, dtype=np.int64)
        held = np.bincount(init[(init >= 0) & stats.usable], minlength=n)
        # a body the previous window did not hold (a merge there) must be searched for
        if np.all(held >= 2):
            # straight to the final pass from the previous labels: they already are its fixed
            # point in the last window (outliers, spatial prior), where K-subspaces (trimmed,
            # no prior) would first drift away from them (rendered sequences: more -1, more
            # label changes, 1.5-2x the iterations)
            c, _ = fit_bodies(flows, init, n)
            out = _final_pass(flows, tracks, init, c, dof, sigma, 'previous', {})
            lab = out[0]
            counts = np.bincount(lab[lab >= 0], minlength=n)
            if np.all(counts >= 2) and np.mean(lab[stats.usable] >= 0) >= WARM_INLIERS:
                return out
        # still a candidate, refined like the others
        refined.append(('previous',) + ksubspaces(stats, n, init, trim_dof=dof))
    starts = []
    if n == 1:
        starts.append(('all', np.where(stats.usable, 0, -1)))
    else:
        for name, rows in (('gpca-weighted', flows.whitened_rows.reshape(-1, 4)),
                           ('gpca', flows.rows.reshape(-1, 4))):
            try:
                u = algebraic_normals(rows, n)
            except np.linalg.LinAlgError:
                continue
            if np.all(np.isfinite(u)):
                starts.append((name, assign(quad_costs(stats, u[:, :3]))))
    if n > 1:
        starts.append(('msac', sequential_msac(stats, tracks, n, dof, rng)[0]))
    # trimmed: gross outliers (mis-tracks) are excluded from every fit from the start
    refined += [(name,) + ksubspaces(stats, n, lab, trim_dof=dof) for name, lab in starts]
    # exact residuals (not the quadratic form) so that zero noise gives zero, not rounding: one
    # evaluation for every candidate's bodies at once
    exact = np.split(track_costs(flows, np.concatenate([r[2] for r in refined]), weighted=True),
                     len(refined), axis=1)
    if sigma is None:
        # the best-fitting candidate gives the smallest (least inflated) estimate
        sigma = min(noise_sigma(e, r[1], dof) for r, e in zip(refined, exact))
    cap = chi2_quantile(OUTLIER_P, dof) * sigma ** 2
    scores = [total_cost(costs, lab, cap) for _, lab, _, costs in refined]
    best = int(np.argmin(scores))
    name, lab, c, _ = refined[best]
    return _final_pass(flows, tracks, lab, c, dof, sigma, name,
                       dict(zip([r[0] for r in refined], scores)), exact[best])


def _final_pass(flows: LineFlows, tracks: np.ndarray, lab: np.ndarray, c: np.ndarray,
                dof: np.ndarray, sigma: Optional[float], name: str, scores: dict,
                costs: Optional[np.ndarray] = None
                ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Exact costs, noise, outlier rejection, spatial smoothing, refit: outliers move no body.

    ``costs (N, n)``: the exact costs under ``c`` when already known.
    """
    n = c.shape[0]
    if costs is None:
        costs = track_costs(flows, c, weighted=True)
    if sigma is None:
        sigma = noise_sigma(costs, lab, dof)
    cap = chi2_quantile(OUTLIER_P, dof) * sigma ** 2
    neighbours = spatial_neighbours(first_midpoints(tracks))
    coupling = 0.0
    for _ in range(3):
        # outliers are decided by the costs alone; the neighbours only choose among bodies
        new, coupling = smooth_labels(costs, assign(costs, cap), neighbours)
        c_new, _ = fit_bodies(flows, new, n)
        same = bool((new == lab).all())
        if not (same and np.array_equal(c_new, c)):
            # (a converged K-subspaces start refits to the very same c: costs are unchanged)
            costs = track_costs(flows, c_new, weighted=True)
        c = c_new
        if same:
            break
        lab = new
    info = {'sigma_px': sigma, 'candidate': name, 'candidate_costs': scores,
            'potts_coupling': coupling}
    return lab, c, costs, info
