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
chi-square 99.9% bound at the estimated endpoint noise get ``-1`` and move no body.
"""
from typing import Optional, Tuple

import numpy as np

from .gpca import algebraic_normals
from .ksubspaces import assign, ksubspaces, total_cost
from .lines import inv2, LineFlows, residual_covariance
from .models import chi2_quantile, solve_normal_equations, track_costs

#: Outlier level: a track is rejected when its cost exceeds this chi-square quantile.
OUTLIER_P = 0.999


def whitened_rows(flows: LineFlows) -> np.ndarray:
    """Rows ``(2P, 4)`` multiplied by ``S^-1/2`` so every residual has unit variance (1 px)."""
    s = residual_covariance(flows, np.zeros((1, 3)))[:, 0]          # (P, 2, 2)
    val, vec = np.linalg.eigh(s)
    inv_sqrt = vec @ (np.swapaxes(vec, 1, 2) / np.sqrt(np.maximum(val, 1e-300))[..., None])
    return (inv_sqrt @ flows.rows).reshape(-1, 4)


def noise_sigma(costs: np.ndarray, labels: np.ndarray, dof: np.ndarray,
                floor: float = 1e-6) -> float:
    """Robust endpoint noise (px) from the costs of the labelled tracks (median of chi-square)."""
    ok = labels >= 0
    if not np.any(ok):
        return 1.0
    best = costs[np.flatnonzero(ok), labels[ok]] / chi2_quantile(0.5, dof[ok])
    return float(max(np.sqrt(np.median(best)), floor))


def _midpoints(tracks: np.ndarray) -> np.ndarray:
    """First present segment midpoint of every track ``(N, 2)`` (px)."""
    ok = np.isfinite(tracks[..., 0])
    first = np.argmax(ok, axis=1)
    seg = tracks[np.arange(tracks.shape[0]), first]
    return 0.5 * (seg[:, :2] + seg[:, 2:])


def _sample_pairs(rng: np.random.Generator, pool: np.ndarray, mid: np.ndarray,
                  n_samples: int, neighbours: int = 6) -> np.ndarray:
    """``(H, 2)`` track index pairs from ``pool``: half global, half spatially local."""
    first = rng.choice(pool, size=n_samples)
    second = rng.choice(pool, size=n_samples)
    local = np.arange(n_samples) % 2 == 0
    if pool.size > 2 and np.any(local):
        d = np.linalg.norm(mid[first[local], None, :] - mid[None, pool, :], axis=2)
        k = min(neighbours, pool.size - 1)
        near = np.argpartition(d, k, axis=1)[:, 1:k + 1]               # skip itself
        second[local] = pool[near[np.arange(near.shape[0]), rng.integers(0, k, near.shape[0])]]
    same = first == second
    second[same] = rng.choice(pool, size=int(same.sum()))
    return np.stack([first, second], axis=1)


def sequential_msac(flows: LineFlows, tracks: np.ndarray, n: int, sigma: float, dof: np.ndarray,
                    rng: np.random.Generator, n_samples: int = 300) -> np.ndarray:
    """Labels from fitting one body at a time to the tracks not yet explained (MSAC)."""
    usable = np.flatnonzero(dof > 0)
    mid = _midpoints(tracks)
    # per-track normal equations (weights at c = 0) so a 2-track hypothesis is one 3x3 solve
    s = residual_covariance(flows, np.zeros((1, 3)))[:, 0]
    w = inv2(s)
    mtw = np.swapaxes(flows.M, 1, 2) @ w
    info = np.zeros((flows.n_tracks, 3, 3))
    rhs = np.zeros((flows.n_tracks, 3))
    np.add.at(info, flows.pair_track, mtw @ flows.M)
    np.add.at(rhs, flows.pair_track, np.einsum('pij,pj->pi', mtw, flows.b))
    cap = chi2_quantile(OUTLIER_P, dof) * sigma ** 2
    labels = np.full(flows.n_tracks, -1, dtype=np.int64)
    pool = usable
    for body in range(n):
        if pool.size < 2:
            break
        pairs = _sample_pairs(rng, pool, mid, n_samples)
        hyp = solve_normal_equations(info[pairs[:, 0]] + info[pairs[:, 1]],
                                     rhs[pairs[:, 0]] + rhs[pairs[:, 1]])
        costs = track_costs(flows, hyp, weighted=True)[pool]          # (|pool|, H)
        score = np.sum(np.minimum(costs, cap[pool, None]), axis=0)
        best = int(np.argmin(score))
        inl = pool[costs[:, best] < cap[pool]]
        if body == n - 1:
            inl = pool
        labels[inl] = body
        pool = np.setdiff1d(pool, inl)
    return labels


def robust_segmentation(flows: LineFlows, tracks: np.ndarray, n: int,
                        rng: np.random.Generator, sigma: Optional[float] = None,
                        init_labels: Optional[np.ndarray] = None
                        ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Best of several initialisations, weighted K-subspaces, outliers rejected.

    Returns labels ``(N,)``, Cayley vectors ``(n, 3)``, costs ``(N, n)`` and diagnostics.
    """
    dof = 2.0 * flows.pairs_per_track()
    candidates = []
    if init_labels is not None:
        candidates.append(('previous', np.asarray(init_labels, dtype=np.int64)))
    rows = flows.rows.reshape(-1, 4)
    for name, r in (('gpca-weighted', whitened_rows(flows)), ('gpca', rows)):
        try:
            u = algebraic_normals(r, n)
        except np.linalg.LinAlgError:
            continue
        candidates.append((name, assign(track_costs(flows, u[:, :3], weighted=True))))
    refined = []
    for name, lab in candidates:
        lab, c, costs = ksubspaces(flows, n, lab, weighted=True)
        refined.append((name, lab, c, costs))
    if sigma is None:
        sigma = min(noise_sigma(costs, lab, dof) for _, lab, _, costs in refined)
    lab = sequential_msac(flows, tracks, n, sigma, dof, rng)
    refined.append(('msac',) + ksubspaces(flows, n, lab, weighted=True))
    cap = chi2_quantile(OUTLIER_P, dof) * sigma ** 2
    scores = [total_cost(costs, lab, cap) for _, lab, _, costs in refined]
    name, lab, c, costs = refined[int(np.argmin(scores))]
    # final pass with outlier rejection: outliers do not move any body
    lab, c, costs = ksubspaces(flows, n, lab, weighted=True, c0=c, threshold=cap)
    info = {'sigma_px': sigma, 'candidate': name,
            'candidate_costs': dict(zip([r[0] for r in refined], scores))}
    return lab, c, costs, info
