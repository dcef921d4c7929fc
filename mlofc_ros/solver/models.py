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
"""Per-body rotation models: residual costs of every track and (weighted) least-squares fits.

Two residuals exist side by side:

* ``weighted=False``: the paper's algebraic residual, the distance of each row ``y`` to the
  body's hyperplane ``u = [c ; 1]``: ``|y . u|^2 / |u|^2`` summed over a track's rows.
* ``weighted=True``: the Mahalanobis (Sampson) cost ``r^T S^-1 r`` with ``S`` the residual
  covariance propagated from 1 px endpoint noise (short lines weigh less). Divided by the true
  endpoint variance it is chi-square with ``2 * pairs`` degrees of freedom.
"""
from typing import Optional, Tuple

import numpy as np

from .lines import inv2, LineFlows, residual_covariance


def pair_residuals(flows: LineFlows, c: np.ndarray) -> np.ndarray:
    """Residuals ``(P, n, 2)`` of every pair under every body's Cayley vector ``c (n, 3)``."""
    return np.einsum('pjk,nk->pnj', flows.M, c) - flows.b[:, None, :]


def pair_costs(flows: LineFlows, c: np.ndarray, weighted: bool = True) -> np.ndarray:
    """Cost ``(P, n)`` of every frame pair under every body (see the module docstring)."""
    c = np.atleast_2d(np.asarray(c, dtype=float))
    r = pair_residuals(flows, c)
    if weighted:
        w = inv2(residual_covariance(flows, c))
        return np.einsum('pni,pnij,pnj->pn', r, w, r)
    return np.sum(r * r, axis=2) / (1.0 + np.sum(c * c, axis=1))[None, :]


def track_costs(flows: LineFlows, c: np.ndarray, weighted: bool = True) -> np.ndarray:
    """Cost ``(N, n)`` of every track under every body: sum over its frame pairs.

    Tracks with no frame pair get ``nan``.
    """
    pc = pair_costs(flows, c, weighted)
    out = np.zeros((flows.n_tracks, pc.shape[1]))
    np.add.at(out, flows.pair_track, pc)
    out[flows.pairs_per_track() == 0] = np.nan
    return out


def fit_bodies(flows: LineFlows, track_labels: np.ndarray, n: int, weighted: bool = True,
               c0: Optional[np.ndarray] = None, iterations: int = 2,
               pair_weights: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Least-squares Cayley vector of every body from the tracks labelled with it.

    Parameters
    ----------
    flows : LineFlows
    track_labels : (N,) int
        Body of every track, ``-1`` = not used.
    n : int
        Number of bodies.
    weighted : bool
        Mahalanobis weights (re-linearised ``iterations`` times around the current ``c``) or
        plain algebraic least squares.
    c0 : (n, 3), optional
        Starting point for the weights.
    pair_weights : (P,), optional
        Extra per-pair weights (e.g. robust IRLS weights).

    Returns
    -------
    c : (n, 3)
        Cayley vectors; zeros for a body without data.
    info : (n, 3, 3)
        Information matrices ``sum M^T W M`` (for 1 px noise when weighted); the covariance of
        ``c`` is ``sigma^2 info^-1``.
    """
    labels = np.asarray(track_labels)[flows.pair_track]
    use = labels >= 0
    lab = labels[use]
    M, b = flows.M[use], flows.b[use]
    pw = None if pair_weights is None else np.asarray(pair_weights, dtype=float)[use]
    c = np.zeros((n, 3)) if c0 is None else np.array(c0, dtype=float)
    info = np.zeros((n, 3, 3))
    sub = flows.subset(use) if weighted else None
    for _ in range(max(1, iterations) if weighted else 1):
        if weighted:
            cov = residual_covariance(sub, c)                       # (P, n, 2, 2)
            W = inv2(cov[np.arange(lab.size), lab])                 # (P, 2, 2)
        else:
            W = np.broadcast_to(np.eye(2), (lab.size, 2, 2))
        if pw is not None:
            W = W * pw[:, None, None]
        mtw = np.swapaxes(M, 1, 2) @ W                              # (P, 3, 2)
        info = np.zeros((n, 3, 3))
        rhs = np.zeros((n, 3))
        np.add.at(info, lab, mtw @ M)
        np.add.at(rhs, lab, np.einsum('pij,pj->pi', mtw, b))
        c = solve_normal_equations(info, rhs)
    return c, info


def solve_normal_equations(info: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``info c = rhs`` per body; a relative ridge keeps rank-deficient (and empty)
    bodies finite (a single line does not see the rotation about its own normal)."""
    scale = np.trace(info, axis1=-2, axis2=-1)[..., None, None] / 3.0
    ridge = 1e-9 * np.maximum(scale, 1e-300) * np.eye(3)
    return np.linalg.solve(info + ridge, rhs[..., None])[..., 0]


#: Standard normal quantiles for the chi-square levels used here (no scipy at runtime).
_Z = {0.5: 0.0, 0.9: 1.2815516, 0.95: 1.6448536, 0.99: 2.3263479, 0.999: 3.0902323,
      0.9999: 3.7190165}


def chi2_quantile(p: float, dof) -> np.ndarray:
    """Wilson-Hilferty approximation of the chi-square quantile for ``p`` in ``_Z``."""
    k = np.maximum(np.asarray(dof, dtype=float), 1.0)
    h = 2.0 / (9.0 * k)
    return k * np.maximum(1.0 - h + _Z[p] * np.sqrt(h), 0.0) ** 3
