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
"""General rigid motion from lines over three or more frames (rotation AND translation).

A 3D line with Plucker moment ``n0`` and direction ``v0`` on a body moving ``X' = R X + T`` per
frame has, in frame ``k``, the moment ``n_k = R^k n0 + T_k x R^k v0`` with
``T_k = sum_{j<k} R^j T``; its image is the line with normal ``m_k ~ n_k``. For the two directions
``e`` orthogonal to the observed ``m_k``, ``e . n_k = 0``, which is LINEAR in ``(n0, v0)``::

    (R^-k e) . n0 + (R^-k (e x T_k)) . v0 = 0

``v0`` is orthogonal to ``n0``: two unknowns per line (its direction within the plane and
``1/d``; the scale of ``T`` is absorbed by ``v0``). Projecting them out leaves a 3x3 problem in
``n0`` whose smallest eigenvalue is the line's (whitened) residual: ``2K - 4`` constraints per
line, none with two frames (as it must be), six with five. With ``T = 0`` it reduces to the
rotation-only model. Per body, ``(w, T)`` are found by Levenberg-Marquardt on these residuals.
"""
from typing import Optional, Tuple

import numpy as np

from .lines import first_midpoints, interpretation_normals, orthonormal_pair, rotation_matrix

Intrinsics = Tuple[float, float, float, float]


class LineObservations:
    """Whitened observation directions of every track and frame.

    ``rows (N, K, 2, 3)``: for each frame the two directions ``e`` orthogonal to ``m_k``, scaled
    by the inverse standard deviation of ``m_k`` along them (1 px endpoint noise), so that
    ``rows . n_k / |n_k|`` has unit variance; zero where the track is missing.
    """

    def __init__(self, tracks: np.ndarray, intrinsics: Intrinsics) -> None:
        self.intrinsics = tuple(float(x) for x in intrinsics)
        m, cov = interpretation_normals(tracks, intrinsics)
        ok = np.isfinite(m[..., 0])
        m = np.where(ok[..., None], m, np.array([0.0, 0.0, 1.0]))
        cov = np.where(ok[..., None, None], cov, np.eye(3))
        E = orthonormal_pair(m)                                      # (N, K, 3, 2)
        s = np.swapaxes(E, -1, -2) @ cov @ E                         # (N, K, 2, 2)
        val, vec = np.linalg.eigh(s)
        dirs = E @ vec                                               # principal directions
        rows = np.swapaxes(dirs, -1, -2) / np.sqrt(np.maximum(val, 1e-30))[..., None]
        self.rows = np.where(ok[..., None, None], rows, 0.0)
        self.present = ok
        self.m = m
        first = np.argmax(ok, axis=1)
        self.m_first = m[np.arange(m.shape[0]), first]
        self.frames = ok.sum(axis=1)

    @property
    def n_tracks(self) -> int:
        return self.rows.shape[0]


def _motion_terms(w: np.ndarray, t: np.ndarray, n_frames: int) -> Tuple[np.ndarray, np.ndarray]:
    """``R^k`` and ``T_k`` for k = 0..K-1 (``(K, 3, 3)``, ``(K, 3)``)."""
    R = rotation_matrix(w)
    Rk = np.empty((n_frames, 3, 3))
    Tk = np.zeros((n_frames, 3))
    Rk[0] = np.eye(3)
    for k in range(1, n_frames):                       # a few frames, not lines
        Rk[k] = R @ Rk[k - 1]
        Tk[k] = R @ Tk[k - 1] + t
    return Rk, Tk


def line_residuals(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                   n0: Optional[np.ndarray] = None, fixed: Optional[np.ndarray] = None
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """Whitened residual ``(L,)`` (sum of squares) and moment direction ``n0 (L, 3)``.

    ``idx``: tracks to evaluate; ``n0``: current moment estimates, whose orthogonal plane
    holds ``v0`` (defaults to the first observed normal). With ``fixed (L, 3)`` the moments are
    not re-solved: the projected residual VECTORS ``(L, 2K)`` at those moments are returned
    instead of the minimal costs (for Gauss-Newton by variable projection).
    """
    rows = obs.rows[idx]                                             # (L, K, 2, 3)
    L, K = rows.shape[0], rows.shape[1]
    Rk, Tk = _motion_terms(w, t, K)
    # (R^-k e) . n0 = e . R^k n0  ->  rows @ R^k ; e . (T_k x R^k v0) = (e x T_k) . R^k v0
    An = np.einsum('lkji,kim->lkjm', rows, Rk).reshape(L, 2 * K, 3)
    ex = np.cross(rows, Tk[None, :, None, :])
    Av = np.einsum('lkji,kim->lkjm', ex, Rk).reshape(L, 2 * K, 3)
    base = obs.m_first[idx] if n0 is None else n0
    B = orthonormal_pair(base)                                       # (L, 3, 2)
    AvB = Av @ B                                                     # (L, 2K, 2)
    # orthonormal basis of the two columns (Gram-Schmidt, vectorised), then project them out
    q1 = AvB[..., 0]
    n1 = np.linalg.norm(q1, axis=1, keepdims=True)
    q1 = np.where(n1 > 1e-12, q1 / np.maximum(n1, 1e-300), 0.0)
    q2 = AvB[..., 1] - q1 * np.sum(q1 * AvB[..., 1], axis=1, keepdims=True)
    n2 = np.linalg.norm(q2, axis=1, keepdims=True)
    q2 = np.where(n2 > 1e-12 * np.maximum(n1, 1.0), q2 / np.maximum(n2, 1e-300), 0.0)
    P = An - q1[..., None] * np.einsum('lr,lrc->lc', q1, An)[:, None, :]
    P = P - q2[..., None] * np.einsum('lr,lrc->lc', q2, P)[:, None, :]
    if fixed is not None:
        return np.einsum('lrc,lc->lr', P, fixed), fixed
    G = np.swapaxes(P, 1, 2) @ P                                     # (L, 3, 3)
    val, vec = np.linalg.eigh(G)
    n0_new = vec[..., 0]
    n0_new *= np.where(np.sum(n0_new * base, axis=1) < 0, -1.0, 1.0)[:, None]
    return np.maximum(val[:, 0], 0.0), n0_new


def _tangent(t: np.ndarray) -> np.ndarray:
    """Two unit vectors ``(2, 3)`` orthogonal to the unit vector ``t``."""
    return np.swapaxes(orthonormal_pair(t[None])[0], 0, 1)


def fit_body(obs: LineObservations, idx: np.ndarray, w0: np.ndarray, t0: np.ndarray,
             iterations: int = 15) -> Tuple[np.ndarray, np.ndarray, float]:
    """Levenberg-Marquardt on ``(w, T/|T|)`` for the tracks ``idx``; returns w, unit T, cost.

    Variable projection: the per-line unknowns are eliminated, the Jacobian is taken of every
    line's projected residual vector (central differences, moments held fixed) and the unit
    translation moves in its tangent plane (five parameters, no gauge freedom).
    """
    w = np.array(w0, dtype=float)
    t = np.array(t0, dtype=float)
    t = t / np.linalg.norm(t) if np.linalg.norm(t) > 1e-12 else np.array([0.0, 0.0, 1.0])
    res, n0 = line_residuals(obs, idx, w, t)
    res, n0 = line_residuals(obs, idx, w, t, n0)
    cost = float(res.sum())
    lam, h = 1e-3, 1e-6
    for _ in range(iterations):
        basis = _tangent(t)

        def vec(x: np.ndarray) -> np.ndarray:
            tt = t + x[3:] @ basis
            return line_residuals(obs, idx, w + x[:3], tt / np.linalg.norm(tt), n0,
                                  fixed=n0)[0].ravel()
        r0 = vec(np.zeros(5))
        J = np.empty((r0.size, 5))
        for j in range(5):                              # five parameters
            d = np.zeros(5)
            d[j] = h
            J[:, j] = (vec(d) - vec(-d)) / (2.0 * h)
        H, g = J.T @ J, J.T @ r0
        improved = False
        for _ in range(8):
            step = -np.linalg.solve(H + lam * (np.diag(np.diag(H)) + 1e-12 * np.eye(5)), g)
            tn = t + step[3:] @ basis
            tn /= np.linalg.norm(tn)
            rn, n0n = line_residuals(obs, idx, w + step[:3], tn, n0)
            rn, n0n = line_residuals(obs, idx, w + step[:3], tn, n0n)
            if rn.sum() < cost:
                w, t, n0, cost = w + step[:3], tn, n0n, float(rn.sum())
                lam = max(lam / 5.0, 1e-12)
                improved = True
                break
            lam *= 5.0
        if not improved or np.linalg.norm(step) < 1e-12:
            break
    return w, t, cost


def _hemisphere(n: int = 32) -> np.ndarray:
    """Spread ``(n, 3)`` directions over a hemisphere (Fibonacci lattice).

    The cost depends on T only through its span, so T and -T are the same start.
    """
    k = np.arange(n) + 0.5
    z = k / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


#: Translation directions scanned for a body without a previous estimate.
T_STARTS = _hemisphere()


def fit_body_multistart(obs: LineObservations, idx: np.ndarray, w0: np.ndarray,
                        t0: Optional[np.ndarray] = None, iterations: int = 15,
                        keep: int = 3) -> Tuple[np.ndarray, np.ndarray, float]:
    """Run :func:`fit_body` from ``t0``, or from the ``keep`` best of a scan of T directions.

    The scan evaluates :data:`T_STARTS` at ``w0``: the cost is not convex in the direction of T.
    """
    if t0 is not None:
        starts = np.atleast_2d(t0)
    else:
        scan = []
        for t in T_STARTS:                               # 32 directions, each vectorised
            res, n0 = line_residuals(obs, idx, w0, t)
            scan.append(line_residuals(obs, idx, w0, t, n0)[0].sum())
        starts = T_STARTS[np.argsort(scan)[:keep]]
    best = None
    for t in starts:
        fit = fit_body(obs, idx, w0, t, iterations)
        if best is None or fit[2] < best[2]:
            best = fit
    return best


def general_costs(obs: LineObservations, W: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Cost ``(N, n)`` of every track under every body ``(W (n, 3), T (n, 3))``.

    ``nan`` for tracks with fewer than 3 frames (no constraint on a general motion).
    """
    idx = np.arange(obs.n_tracks)
    out = np.empty((obs.n_tracks, W.shape[0]))
    for b in range(W.shape[0]):                          # bodies, not lines
        r, n0 = line_residuals(obs, idx, W[b], T[b])
        out[:, b], _ = line_residuals(obs, idx, W[b], T[b], n0)
    out[obs.frames < 3] = np.nan
    return out


def spatial_labels(tracks: np.ndarray, n: int, rng: np.random.Generator,
                   iterations: int = 10) -> np.ndarray:
    """K-means of the track midpoints (px): lines near each other tend to share a body."""
    mid = first_midpoints(tracks)
    centres = mid[rng.choice(mid.shape[0], n, replace=False)]
    labels = np.zeros(mid.shape[0], dtype=np.int64)
    for _ in range(iterations):
        labels = np.argmin(np.linalg.norm(mid[:, None] - centres[None], axis=2), axis=1)
        for b in range(n):
            if np.any(labels == b):
                centres[b] = mid[labels == b].mean(axis=0)
    return labels


#: Smallest endpoint noise assumed (px): the non-linear fits converge to ~1e-9, not to zero,
#: and no detector locates lines better than this.
SIGMA_FLOOR_PX = 0.1


def _best_costs(costs: np.ndarray) -> np.ndarray:
    """Smallest cost ``(N,)`` of every track over the bodies (``inf`` when it has none)."""
    if costs.shape[1] == 0:
        return np.full(costs.shape[0], np.inf)
    return np.min(np.where(np.isfinite(costs), costs, np.inf), axis=1)


def _robust_sigma2(best: np.ndarray, dof: np.ndarray) -> float:
    """Noise variance (1 px units) from the median of chi-square-normalised costs."""
    from .models import chi2_quantile
    ok = np.isfinite(best) & (dof > 0)
    if not np.any(ok):
        return 1.0
    return float(max(np.median(best[ok] / chi2_quantile(0.5, dof[ok])), SIGMA_FLOOR_PX ** 2))


def general_segmentation(obs: LineObservations, n: int, starts: list,
                         w_starts: np.ndarray, iterations: int = 8,
                         outlier_p: float = 0.9999) -> dict:
    """Segment tracks into ``n`` general rigid motions (tracks need >= 3 frames).

    Parameters
    ----------
    obs : LineObservations
    n : int
        Number of bodies.
    starts : list of (name, labels (N,))
        Initial labellings, e.g. the rotation-only solution and a spatial clustering.
    w_starts : (n, 3)
        Rotation (rad/frame) to start every body's fit from in the first round (the
        rotation-only estimate of its lines is a good start; T is searched from six axes).

    Returns
    -------
    dict with ``labels (N,)``, ``W (n, 3)`` rotation vectors (rad/frame), ``T (n, 3)`` unit
    translation directions (per frame, camera frame; zero when undetermined), ``costs (N, n)``,
    ``sigma2`` and the winning ``start``.
    """
    from .ksubspaces import total_cost
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    usable = dof > 0
    best = None
    for name, lab in starts:
        lab = np.where(usable, np.asarray(lab, dtype=np.int64), -1)
        W, T = np.zeros((n, 3)), np.zeros((n, 3))
        fitted = np.zeros(n, dtype=bool)
        cap = None
        costs = np.full((obs.n_tracks, n), np.nan)
        for _ in range(iterations):
            _fit_each_body(obs, lab, W, T, fitted, 6, lambda b: w_starts[b % len(w_starts)])
            costs = general_costs(obs, W, T)
            sigma2, cap, new = _assign_within_bound(costs, dof, outlier_p)
            if np.array_equal(new, lab):
                break
            lab = new
        score = total_cost(costs, lab, cap)
        if best is None or score < best['score']:
            best = {'labels': lab, 'W': W.copy(), 'T': T.copy(), 'costs': costs,
                    'sigma2': sigma2, 'start': name, 'score': score}
    # polish the winner: the alternation above stops LM early to save time
    for b in range(n):
        idx = np.flatnonzero(best['labels'] == b)
        if idx.size >= 3:
            best['W'][b], best['T'][b], _ = fit_body(obs, idx, best['W'][b], best['T'][b], 40)
    best['costs'] = general_costs(obs, best['W'], best['T'])
    return best


def _assign_within_bound(costs: np.ndarray, dof: np.ndarray, outlier_p: float
                         ) -> Tuple[float, np.ndarray, np.ndarray]:
    """Noise level, chi-square outlier bound ``(N,)`` and labels (``-1`` above it) of ``costs``."""
    from .ksubspaces import assign
    from .models import chi2_quantile
    sigma2 = _robust_sigma2(_best_costs(costs), dof)
    cap = chi2_quantile(outlier_p, dof) * sigma2
    return sigma2, cap, assign(costs, cap)


def _fit_each_body(obs: LineObservations, labels: np.ndarray, W: np.ndarray, T: np.ndarray,
                   fitted: np.ndarray, iterations: int, w_start) -> None:
    """Refit every body with >= 3 tracks in place: LM from its motion, or multi-start.

    ``fitted (n,)`` marks bodies whose ``(W, T)`` is a fit already (LM for ``iterations``);
    the others start a multi-start search at ``w_start(b)`` and become fitted.
    """
    for b in range(W.shape[0]):                               # bodies, not lines
        idx = np.flatnonzero(labels == b)
        if idx.size < 3:
            continue
        if fitted[b]:
            W[b], T[b], _ = fit_body(obs, idx, W[b], T[b], iterations)
        else:
            W[b], T[b], _ = fit_body_multistart(obs, idx, w_start(b))
            fitted[b] = True


#: A warm start is kept when at least this share of the usable tracks stay inliers (else the
#: full multi-start search runs).
WARM_INLIERS = 0.5


def general_warm(obs: LineObservations, labels: np.ndarray, W0: np.ndarray, T0: np.ndarray,
                 known: np.ndarray, rounds: int = 3, iterations: int = 4,
                 outlier_p: float = 0.9999) -> dict:
    """Track the bodies of the previous window: a few LM steps from its motions, then assign.

    Parameters
    ----------
    obs : LineObservations
    labels : (N,) int
        Starting labels (the previous window's, ``-1`` unknown).
    W0, T0 : (n, 3)
        Starting rotation vectors (rad/frame) and translation directions (unit or zero) per
        body, camera optical frame.
    known : (n,) bool
        Bodies whose ``(W0, T0)`` come from a previous fit; the others start from the
        multi-start search at ``W0`` (their rotation-only estimate).
    rounds, iterations : int
        Fit/assign rounds and LM iterations per body and round.

    Returns the dict of :func:`general_segmentation` (``start='warm'``) plus ``inliers``, the
    share of usable tracks within the outlier bound.
    """
    from .ksubspaces import total_cost
    n = W0.shape[0]
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    usable = dof > 0
    lab = np.where(usable, np.asarray(labels, dtype=np.int64), -1)
    W, T = np.array(W0, dtype=float), np.array(T0, dtype=float)
    fitted = np.asarray(known, dtype=bool).copy()
    costs = np.full((obs.n_tracks, n), np.nan)
    sigma2, cap = 1.0, None
    for _ in range(rounds):
        _fit_each_body(obs, lab, W, T, fitted, iterations, lambda b: W[b])
        costs = general_costs(obs, W, T)
        if not np.any(np.isfinite(costs)):
            break
        sigma2, cap, new = _assign_within_bound(costs, dof, outlier_p)
        if np.array_equal(new, lab):
            break
        lab = new
    inliers = float(np.mean(lab[usable] >= 0)) if np.any(usable) else 0.0
    score = total_cost(costs, lab, cap) if cap is not None else np.inf
    return {'labels': lab, 'W': W, 'T': T, 'costs': costs, 'sigma2': sigma2, 'start': 'warm',
            'score': score, 'inliers': inliers}


def body_covariance(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                    sigma2: float, step: float = 1e-6) -> np.ndarray:
    """Covariance ``(3, 3)`` of a body's rotation vector from the Gauss-Newton information."""
    if idx.size < 3:
        return np.full((3, 3), np.inf)
    res, n0 = line_residuals(obs, idx, w, t)
    res, n0 = line_residuals(obs, idx, w, t, n0)
    r0 = np.sqrt(res)
    x = np.r_[w, t]
    J = np.empty((idx.size, 6))
    for j in range(6):                                   # six parameters
        dx = np.zeros(6)
        dx[j] = step
        J[:, j] = (np.sqrt(line_residuals(obs, idx, x[:3] + dx[:3], x[3:] + dx[3:], n0)[0])
                   - r0) / step
    info = J.T @ J
    try:
        return sigma2 * np.linalg.pinv(info, rcond=1e-10)[:3, :3]
    except np.linalg.LinAlgError:
        return np.full((3, 3), np.inf)
