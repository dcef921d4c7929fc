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
Our robust method: several initialisations, noise-weighted K-subspaces, outlier rejection.

Candidates (all refined by Mahalanobis-weighted K-subspaces):

1. the noise-whitened algebraic (GPCA) solution,
2. the paper's algebraic solution (not from previous labels: a stream's warm solve that did not
   hold, the automatic count's trials),
3. sequential MSAC on minimal samples of two tracks, half of them spatially local (tracks near
   each other in the image tend to share a body, as in NAPSAC / Progressive-X),

and the candidate with the lowest truncated total cost wins. Tracks whose best cost exceeds the
chi-square 99.99% bound at the estimated endpoint noise get ``-1`` and move no body.

Early accept (K >= 4 frames): the first candidate alone is returned when it is clearly right --
its noise matches that of the tracks fitted one by one, nearly every track fits its body about as
well as alone, and the bodies are told apart (:data:`EARLY_RATIO`); the other starts (MSAC
costs more than everything else together) are then skipped.
"""
from typing import NamedTuple, Optional, Tuple

import numpy as np

from .gpca import algebraic_normals
from .ksubspaces import assign, ksubspaces, total_cost
from .lines import first_midpoints, LineFlows
from .models import (chi2_quantile, fit_bodies, median, normal_ridge, quad_costs,
                     solve_normal_equations, track_costs, track_stats, TrackStats)
from .result import Diagnostics, noted
from .spatial import smooth_labels, spatial_neighbours

#: A warm start is accepted alone when it leaves at least this share of the tracks as inliers
#: (tracker noise is heavier-tailed than Gaussian: 78-88% measured on rendered windows).
WARM_INLIERS = 0.75

#: Outlier level: a track is rejected when its cost exceeds this chi-square quantile (99.99%:
#: tracker noise is heavier-tailed than Gaussian; 99.9% left ~7% of rendered segments -1).
OUTLIER_P = 0.9999


class Segmentation(NamedTuple):
    """A rotation-only segmentation: what the solves of this module return."""

    #: (N,) body of every track, -1 unassigned.
    labels: np.ndarray
    #: (n, 3) Cayley vector of every body.
    cayley: np.ndarray
    #: (N, n) exact weighted cost of every track under every body.
    costs: np.ndarray
    #: Noise level, winning start, scores.
    diagnostics: Diagnostics


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


def column_quantile(x: np.ndarray, q: float) -> np.ndarray:
    """
    Return ``np.quantile(x, q, axis=0)`` (method 'linear') of ``x (R, H)`` without nan.

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
    """
    Labels from fitting one body at a time to the tracks not yet explained; noise (px).

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
        kth = column_quantile(per_dof, q)
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
                        init_labels: Optional[np.ndarray] = None,
                        warm_inliers: float = WARM_INLIERS,
                        warm_competes: bool = True) -> Segmentation:
    """
    Best of several initialisations, weighted K-subspaces, outliers rejected.

    ``init_labels`` (N,): the previous window's labels (``-1`` unknown). Their final pass is
    returned alone when it leaves at least ``warm_inliers`` of the usable tracks inliers;
    otherwise the other starts are searched and, with ``warm_competes``, it competes with them
    (scored like them).
    The diagnostics hold ``inlier_share`` and ``warm_rejected`` (a search ran past the warm
    start's final pass).
    """
    stats = track_stats(flows, weighted=True)
    dof = 2.0 * flows.pairs_per_track()
    refined = []
    warm, tried = None, False
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
            tried = True
            out = _final_pass(flows, tracks, init, c, dof, sigma, 'previous', {})
            lab = out.labels
            counts = np.bincount(lab[lab >= 0], minlength=n)
            share = float(np.mean(lab[stats.usable] >= 0)) if stats.usable.any() else 0.0
            if np.all(counts >= 2) and share >= warm_inliers:
                return out._replace(diagnostics=noted(out.diagnostics, inlier_share=share))
            if np.all(counts >= 2):
                warm = out
        # still a candidate, refined like the others
        refined.append(('previous',) + ksubspaces(stats, n, init, trim_dof=dof))
    starts = []
    if n == 1:
        starts.append(('all', np.where(stats.usable, 0, -1)))
    else:
        # from the previous labels (a stream, the automatic count's trials) without the
        # paper's unweighted GPCA (by QR: a fifth of a search of five bodies): bench count's
        # scheduled stream, largest frame 5.6-6.6x -> 4.2-4.8x its median, the counts the
        # same; Hopkins155 right count 57 / 38 -> 57 / 37% (docs/design/node.md)
        for name in (('gpca-weighted',) if init_labels is not None
                     else ('gpca-weighted', 'gpca')):
            # the unweighted rows only when the early accept did not return
            rows = flows.whitened_rows if name == 'gpca-weighted' else flows.rows
            try:
                # the weighted start by the Gram matrix (a start for K-subspaces: ~1e-8 at
                # zero noise is ample); the paper's unweighted GPCA as published (QR)
                u = algebraic_normals(rows.reshape(-1, 4), n, gram=name == 'gpca-weighted')
            except np.linalg.LinAlgError:
                continue
            if np.all(np.isfinite(u)):
                starts.append((name, assign(quad_costs(stats, u[:, :3]))))
            if name == 'gpca-weighted' and starts and not refined and sigma is None:
                # early accept: the first start alone when it is clearly right (2-4x cheaper
                # than all starts); otherwise it is refined once and joins the others
                first = (name,) + ksubspaces(stats, n, starts.pop()[1], trim_dof=dof)
                out = _early_accept(flows, tracks, stats, first, dof)
                if out is not None:
                    return out
                refined.append(first)
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
    names = [r[0] for r in refined]
    best = int(np.argmin(scores))
    name, lab, c, _ = refined[best]
    costs = exact[best]
    if warm is not None and warm_competes:
        # the warm start's own final pass competes too, scored at the same noise level: on
        # real scenes that the rotation model explains only in part it had been rejected for
        # fewer than warm_inliers inliers, and the search's winner then explained still fewer
        w_score = total_cost(warm.costs, warm.labels, cap)
        names.append('previous-pass')
        scores.append(w_score)
        if w_score < scores[best]:
            name, lab, c, costs = 'previous-pass', warm.labels, warm.cayley, warm.costs
    out = _final_pass(flows, tracks, lab, c, dof, sigma, name, dict(zip(names, scores)), costs)
    share = float(np.mean(out.labels[stats.usable] >= 0)) if stats.usable.any() else 0.0
    return out._replace(diagnostics=noted(out.diagnostics, inlier_share=share,
                                          warm_rejected=tried))


def free_residuals(stats: TrackStats, dof: np.ndarray) -> np.ndarray:
    """
    Least-squares cost ``(N,)`` of every track fitted ALONE (its own rotation); nan if none.

    Chi-square with about ``dof - FREE_DOF`` degrees of freedom (times the noise variance)
    whatever body the track belongs to: no segmentation is needed. nan where
    ``dof < FREE_DOF + 2`` (K = 2: one frame pair fits exactly) and for unusable tracks.
    """
    out = np.full(dof.shape[0], np.nan)
    rows = ((dof >= FREE_DOF + 2.0) & stats.usable).nonzero()[0]
    if rows.size:
        # k - g^T A^-1 g by the LDL^T factors of every (ridged, symmetric positive definite)
        # A written out: ~20 calls on (N,) arrays instead of one LAPACK solve per track
        a = stats.A[rows].reshape(-1, 9).T                   # a[3 i + j] = A_ij, (9, N)
        g = stats.g[rows].T                                  # (3, N)
        ridge = normal_ridge(a[0] + a[4] + a[8])
        d1 = a[0] + ridge
        l21, l31 = a[3] / d1, a[6] / d1
        d2 = a[4] + ridge - l21 * a[3]
        l32 = (a[7] - l31 * a[3]) / d2
        d3 = a[8] + ridge - l31 * a[6] - l32 * l32 * d2
        y2 = g[1] - l21 * g[0]
        y3 = g[2] - l31 * g[0] - l32 * y2
        fit = g[0] * g[0] / d1 + y2 * y2 / d2 + y3 * y3 / d3
        out[rows] = np.maximum(stats.k[rows] - fit, 0.0)
    return out


#: Parameters a track's own fit absorbs in :func:`free_residuals` (three; the last one weakly:
#: a line does not see the rotation about its own interpretation-plane normal).
FREE_DOF = 3.0

#: Early accept of the first start (gpca-weighted + K-subspaces), all three must hold, with
#: ``s0`` the noise of the tracks fitted alone (:func:`free_residuals`), which a right
#: grouping must match; measured on 3 x 15 synthetic scenes per accuracy section at K = 5, 8
#: (no accepted start worse than the full search) and on Hopkins155 at K = 5 (where the
#: bodies translate and often rotate alike: 3% of the calls pass; 4 of 310 windows changed,
#: all for the better):
#: 1. its noise estimate is at most EARLY_RATIO x ``s0`` (good starts: median 0.99, 90% 1.03);
EARLY_RATIO = 1.2
#: 2. at least this share of the tracks cost at most the chi-square(3) 99.99% bound at ``s0``
#:    more under their best body than alone (a merged or split body leaves ~1/3 of them above;
#:    with 15% outlier tracks 0.85 passes);
EARLY_SHARE = 0.8
#: 3. at least this share of the tracks cost more than that bound more under their second
#:    body than under their best (the bodies are told apart: where they rotate alike, a
#:    consistent but wrong grouping exists, as on Hopkins155 two-motion sequences; right
#:    synthetic starts: 1% quantile 0.955).
EARLY_SEPARATED = 0.95


def early_stats(stats: TrackStats, exact: np.ndarray, labels: np.ndarray, dof: np.ndarray,
                sigma: Optional[float] = None) -> Optional[Tuple[float, float, float]]:
    """
    Compute the early-accept statistics of a refined start (None: no reference noise).

    ``exact (N, n)``: exact costs under the start's bodies; ``labels (N,)`` its labels;
    ``sigma``: their :func:`noise_sigma` when already computed. Returns (noise ratio to the
    tracks fitted alone, share fitting their body nearly as well as alone, share with a clearly
    worse second body); see :data:`EARLY_RATIO`.
    """
    free = free_residuals(stats, dof)
    ok = np.isfinite(free) & np.isfinite(exact).all(axis=1)
    if np.count_nonzero(ok) < 8 or exact.shape[1] < 2:
        return None
    free = free[ok]
    s0 = max(median(free / chi2_quantile(0.5, dof[ok] - FREE_DOF)), 1e-24)
    if sigma is None:
        sigma = noise_sigma(exact, labels, dof)
    bound = float(chi2_quantile(OUTLIER_P, 3.0)) * s0
    part = np.partition(exact[ok], 1, axis=1)             # best and second-best body
    fits = np.count_nonzero(part[:, 0] - free <= bound)
    separated = np.count_nonzero(part[:, 1] - part[:, 0] > bound)
    m = free.shape[0]
    return sigma / float(np.sqrt(s0)), fits / m, separated / m


def _early_accept(flows: LineFlows, tracks: np.ndarray, stats: TrackStats, first: tuple,
                  dof: np.ndarray) -> Optional[Segmentation]:
    """
    Return the final pass of the refined first start when it is clearly right, else None.

    ``first``: ``(name, labels (N,), c (n, 3), quadratic costs (N, n))`` from K-subspaces.
    """
    name, lab, c, _ = first
    exact = track_costs(flows, c, weighted=True)
    sigma = noise_sigma(exact, lab, dof)           # the final pass's noise level as well
    test = early_stats(stats, exact, lab, dof, sigma)
    if test is None or not (test[0] <= EARLY_RATIO and test[1] >= EARLY_SHARE
                            and test[2] >= EARLY_SEPARATED):
        return None
    out = _final_pass(flows, tracks, lab, c, dof, sigma, name, {}, exact)
    if np.all(np.bincount(out.labels[out.labels >= 0], minlength=c.shape[0]) >= 2):
        return out._replace(diagnostics=noted(out.diagnostics, early_accept=True))
    return None


def _final_pass(flows: LineFlows, tracks: np.ndarray, lab: np.ndarray, c: np.ndarray,
                dof: np.ndarray, sigma: Optional[float], name: str, scores: dict,
                costs: Optional[np.ndarray] = None) -> Segmentation:
    """
    Exact costs, noise, outlier rejection, spatial smoothing, refit: outliers move no body.

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
    return Segmentation(lab, c, costs, Diagnostics(sigma_px=sigma, candidate=name,
                                                   candidate_costs=scores,
                                                   potts_coupling=coupling))
