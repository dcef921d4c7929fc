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
Segmentation search of the 'general' method: lines to bodies with rotation AND translation.

Fitted line directions (:func:`.line_residuals`) leave bodies nearly indistinguishable over
a few frames, so the labels come from the marginalised model (:func:`.marginal_residuals`):
:func:`general_search` measures the noise level and runs :func:`marginal_segmentation` from
several labellings; :func:`general_warm` tracks the previous window's bodies instead. Each
body is also a Gaussian blob in the image (:func:`position_costs`): over a few frames two
objects may move alike, and the motion costs alone then prefer merging them and splitting a
third body; the segmentation also tries split-and-merge moves from its best start
(:func:`split_merge_starts`).
"""
from typing import Optional, Tuple

import numpy as np

from .fit import best_fits, rescale_translations
from .model import general_costs, LineObservations, marginal_costs
from .starts import fit_bodies_multistart
from ..ksubspaces import assign, total_cost
from ..models import chi2_quantile
from ..spatial import largest_region, smooth_labels, track_spacing


def spatial_labels(mid: np.ndarray, n: int, rng: np.random.Generator,
                   iterations: int = 10) -> np.ndarray:
    """Cluster the track midpoints ``mid (N, 2)`` (px) by K-means: near lines share a body."""
    centres = mid[rng.choice(mid.shape[0], n, replace=False)]
    labels = np.zeros(mid.shape[0], dtype=np.int64)
    for _ in range(iterations):
        labels = np.argmin(np.linalg.norm(mid[:, None] - centres[None], axis=2), axis=1)
        for b in range(n):
            if np.any(labels == b):
                centres[b] = mid[labels == b].mean(axis=0)
    return labels


def background_labels(obs: LineObservations, n: int, W: np.ndarray, sigma2: float,
                      rng: np.random.Generator, p: float = 0.99) -> np.ndarray:
    """
    Return labels ``(N,)``: the tracks that a rotation of ``W (C, 3)`` explains, the rest by place.

    The candidate that explains the most tracks (within the chi-square bound at ``p`` of the
    measured noise ``sigma2`` px^2, no translation) is body 0, the background; the others are
    clustered by their midpoints (:func:`spatial_labels`) into bodies 1 to ``n - 1``.
    """
    dof = np.maximum(2.0 * obs.frames - 2.0, 1.0)
    costs = general_costs(obs, W, np.zeros_like(W))
    inside = np.nan_to_num(costs, nan=np.inf) <= chi2_quantile(p, dof)[:, None] * sigma2
    still = inside[:, np.argmax(inside.sum(axis=0))]
    labels = np.zeros(obs.n_tracks, dtype=np.int64)
    if n > 1 and np.count_nonzero(~still) >= n - 1:
        labels[~still] = 1 + spatial_labels(obs.midpoints[~still], n - 1, rng)
    return labels


def fitted_start(obs: LineObservations, labels: np.ndarray, n: int, measured: float,
                 sigma2: float, iterations: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return motions ``W, T (n, 3)`` for a start's ``labels (N,)`` and the bodies fitted.

    Every body of at least 3 tracks is fitted as a rescan fits it (``iterations`` LM
    iterations from the pivot starts, at the measured noise ``measured`` px^2 on the robust
    cost: at the segmentation's inflated noise a box's first fit from its own lines often
    ends in a wrong basin), its translation then rescaled to the segmentation's noise
    ``sigma2`` (:func:`.fit.rescale_translations`); ``fitted (n,)`` marks them (the start's
    others have no motion).
    """
    usable = obs.frames >= 3
    members = [np.flatnonzero(usable & (labels == b)) for b in range(n)]   # bodies, not lines
    fitted = np.array([idx.size >= 3 for idx in members])
    W, T = np.zeros((n, 3)), np.zeros((n, 3))
    some = np.flatnonzero(fitted)
    if some.size:
        idx = [members[b] for b in some]
        w, t, _ = fit_bodies_multistart(obs, idx, np.zeros((some.size, 3)), None,
                                        iterations, 1, measured, robust=measured,
                                        per_rate=True)
        W[some], T[some] = w, rescale_translations(obs, idx, w, t, sigma2)
    return W, T, fitted


#: Smallest endpoint noise assumed (px): the non-linear fits converge to ~1e-9, not to zero,
#: and no detector locates lines better than this.
SIGMA_FLOOR_PX = 0.1


def _best_costs(costs: np.ndarray) -> np.ndarray:
    """Return the smallest cost ``(N,)`` of every track over the bodies (``inf``: none)."""
    if costs.shape[1] == 0:
        return np.full(costs.shape[0], np.inf)
    return np.min(np.where(np.isfinite(costs), costs, np.inf), axis=1)


def _robust_sigma2(best: np.ndarray, dof: np.ndarray) -> float:
    """Return the noise variance (1 px units) from the median of chi-square-normalised costs."""
    ok = np.isfinite(best) & (dof > 0)
    if not np.any(ok):
        return 1.0
    return float(max(np.median(best[ok] / chi2_quantile(0.5, dof[ok])), SIGMA_FLOOR_PX ** 2))


def measured_noise(obs: LineObservations, W: np.ndarray, T: np.ndarray,
                   costs_out: Optional[list] = None) -> float:
    """
    Return the endpoint noise variance (px^2) of the tracks at the motions ``(W, T) (n, 3)``.

    The median over the tracks of each one's cheapest fitted-direction cost
    (:func:`.general_costs`), normalised by its chi-square median (2K - 4 dof).
    ``costs_out``: a list that receives those costs ``(N, n)``.
    """
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    costs = general_costs(obs, W, T)
    if costs_out is not None:
        costs_out.append(costs)
    return _robust_sigma2(_best_costs(costs), dof)


def assign_fitted(obs: LineObservations, W: np.ndarray, T: np.ndarray,
                  outlier_p: float = 0.9999) -> Tuple[np.ndarray, float]:
    """
    Assign every track at the motions ``(W, T) (n, 3)`` by its fitted-direction costs.

    Returns the labels ``(N,)`` (``-1`` above the chi-square bound at ``outlier_p``) and the
    measured noise variance (px^2, :func:`measured_noise`).
    """
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    sigma2, _, labels = _assign_within_bound(general_costs(obs, W, T), dof, outlier_p)
    return labels, sigma2


def _assign_within_bound(costs: np.ndarray, dof: np.ndarray, outlier_p: float
                         ) -> Tuple[float, np.ndarray, np.ndarray]:
    """Return noise level, chi-square outlier bound ``(N,)`` and labels (``-1``: above it)."""
    sigma2 = _robust_sigma2(_best_costs(costs), dof)
    cap = chi2_quantile(outlier_p, dof) * sigma2
    return sigma2, cap, assign(costs, cap)


def _fit_each_body(obs: LineObservations, labels: np.ndarray, W: np.ndarray, T: np.ndarray,
                   fitted: np.ndarray, iterations: int, w_start,
                   sigma2: Optional[float] = None, t_start=None, keep: int = 3,
                   first_iterations: int = 15, pivots: bool = True) -> None:
    """
    Refit every body with >= 3 tracks in place: LM from its motion, or multi-start.

    ``fitted (n,)`` marks bodies whose ``(W, T)`` is a fit already (LM for ``iterations``);
    the others start a multi-start search at ``w_start(b)`` (and ``t_start(b)``), with
    :func:`.pivot_starts` towards the body's lines when ``pivots`` and a Necker check
    (:func:`.fit_body_multistart`), and become fitted (``keep`` LM runs of
    ``first_iterations``). ``sigma2``: marginalised directions (:func:`.marginal_residuals`).
    The bodies' runs go in lockstep batches (:func:`.fit.best_fits`,
    :func:`.fit_bodies_multistart`).
    """
    members = [np.flatnonzero(labels == b) for b in range(W.shape[0])]   # bodies, not lines
    refit = [b for b in range(W.shape[0]) if fitted[b] and members[b].size >= 3]
    if refit:                        # the fitted bodies' runs in one lockstep batch
        W[refit], T[refit], _ = best_fits(obs, [members[b] for b in refit], W[refit],
                                          T[refit], iterations, sigma2)
    first = [b for b in range(W.shape[0]) if not fitted[b] and members[b].size >= 3]
    if first:                        # and the others' multi-start searches in another
        W0 = np.array([w_start(b) for b in first])
        T0 = None if t_start is None else np.array([t_start(b) for b in first])
        W[first], T[first], _ = fit_bodies_multistart(
            obs, [members[b] for b in first], W0, T0, first_iterations, keep, sigma2, pivots)
        fitted[first] = True


def _assign_marginal(costs: np.ndarray, logdet: np.ndarray, dof: np.ndarray, sigma2: float,
                     outlier_p: float, neighbours: Optional[np.ndarray] = None
                     ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return labels ``(N,)`` and outlier caps ``(N,)`` of marginalised costs.

    A track is an outlier (``-1``) when, under its cheapest body, the quadratic part of its
    cost (without the log-determinant, and without any position term of
    :func:`position_costs` already added to ``costs`` and ``logdet``) is above the chi-square
    bound with ``dof`` degrees of freedom; the cap is that bound plus those terms. With
    ``neighbours`` the inliers are relabelled by :func:`.spatial.smooth_labels`.
    """
    lab = assign(costs)
    ok = lab >= 0
    ld = np.zeros(costs.shape[0])
    ld[ok] = logdet[np.flatnonzero(ok), lab[ok]]
    cap = chi2_quantile(outlier_p, dof) * sigma2 + ld
    lab = assign(costs, cap)
    if neighbours is not None:
        lab, _ = smooth_labels(costs, lab, neighbours)
    return lab, cap


#: Weight of the bodies' image-position term (:func:`position_costs`) in the 'general'
#: segmentation, relative to the motion costs (1 = the joint likelihood of positions and
#: motion at the segmentation's inflated noise level). Measured on bench hopkins, K = 5:
#: 8 three-motion checkerboard windows 24.5% misclassified (0), 19.3% (0.1), 13.6% (0.25),
#: 9.5% (0.5), 8.3% (1); 24 windows of 20 random two-motion sequences 3.7% (0), 3.2% (0.25),
#: 3.5% (0.5), 4.6% (1): a compact object pulls in the lines of a broad background near it.
POSITION_WEIGHT = 0.5


#: Pseudo-count of the shrinkage of a body's midpoint covariance towards all tracks' (tracks).
POSITION_PRIOR = 3.0


def position_costs(points: np.ndarray, labels: np.ndarray, n: int,
                   prior: float = POSITION_PRIOR) -> np.ndarray:
    """
    Return the image-position cost ``(N, n)`` of every track under every body's Gaussian blob.

    ``points (N, 2)``: the tracks' midpoints (px); ``labels (N,)`` the current bodies (``-1``
    none). Each body is a 2D Gaussian over the image fitted to its tracks' midpoints, its
    covariance shrunk towards that of all labelled tracks with ``prior`` pseudo-tracks (a body
    with few or no tracks falls back to it); the cost is twice the negative log-likelihood,
    ``d^T S^-1 d + log det S`` (scale-free: differences do not depend on the image size).
    Rigid bodies are compact in the image: a body made of two distant regions (two objects
    with nearly the same motion over the window) or lines far from a body's others pay for it.
    """
    pts = np.asarray(points, dtype=float)
    ok = labels >= 0
    ref = pts[ok] if np.count_nonzero(ok) >= 3 else pts
    S0 = np.cov(ref.T) + 1e-6 * np.eye(2)
    mu0 = ref.mean(axis=0)
    out = np.empty((pts.shape[0], n))
    for b in range(n):                                   # bodies, not lines
        p = pts[labels == b]
        mu = (p.sum(axis=0) + prior * mu0) / (p.shape[0] + prior)
        d = p - mu
        S = (d.T @ d + prior * (S0 + np.outer(mu0 - mu, mu0 - mu))) / (p.shape[0] + prior)
        r = pts - mu
        out[:, b] = (np.sum((r @ np.linalg.inv(S)) * r, axis=1)
                     + np.log(np.linalg.det(S)))
    return out


def assign_bodies(obs: LineObservations, W: np.ndarray, T: np.ndarray, sigma2: float,
                  labels: np.ndarray, outlier_p: float = 0.9999,
                  neighbours: Optional[np.ndarray] = None, points: Optional[np.ndarray] = None,
                  position_weight: float = POSITION_WEIGHT
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Assign every track to a body at the motions ``(W, T) (n, 3)`` (marginalised directions).

    ``sigma2``: the noise variance (px^2) of the costs; ``labels (N,)``: the labels the
    bodies were fitted to (their image blobs, :func:`position_costs`, when ``points`` is
    given); ``outlier_p``, ``neighbours``: as in :func:`marginal_segmentation`. Returns the
    new labels ``(N,)`` (``-1`` outliers), the motion costs ``(N, n)``, the costs with the
    position terms ``(N, n)`` and the outlier caps ``(N,)``.
    """
    dof = np.maximum(2.0 * obs.frames - 2.0, 0.0)
    costs, logdet = marginal_costs(obs, W, T, sigma2)
    total = costs
    if points is not None:
        # the blobs of the labels the bodies were just fitted to; the position term is no
        # evidence of an outlier, so it joins the log-determinant in the cap
        extra = position_weight * sigma2 * position_costs(points, labels, W.shape[0])
        total, logdet = costs + extra, logdet + extra
    new, cap = _assign_marginal(total, logdet, dof, sigma2, outlier_p, neighbours)
    return new, costs, total, cap


def marginal_segmentation(obs: LineObservations, n: int, starts: list, W0: np.ndarray,
                          T0: np.ndarray, sigma2: float, rounds: int = 8, iterations: int = 5,
                          outlier_p: float = 0.9999, neighbours: Optional[np.ndarray] = None,
                          keep: int = 3, first_iterations: int = 15,
                          pivots: bool = True, points: Optional[np.ndarray] = None,
                          position_weight: float = POSITION_WEIGHT) -> dict:
    """
    Segment with the marginalised-direction model (:func:`.marginal_residuals`).

    From every start, rounds of LM fits of every body and assignment of every track
    (:func:`_fit_assign`); then, from the best start's solution, the split-and-merge moves of
    :func:`split_merge_starts`, each kept when it scores lower. Bench spinning (30 frames,
    seeds 0-2), wrong % with ``'general'`` own3+bg / own3 / wide2+bg 8.4 / 7.7 / 5.8 -> 1.2 /
    0.1 / 4.5 (worst seed 24 / 23 / 9.5 -> 2.5 / 0.3 / 5.4), ``'auto'`` wide3 12.6 -> 4.5;
    300 frames through the pipeline with ``'auto'`` (every frame solved, seeds 0-5),
    own2+bg / own3+bg 2.0 / 1.8 -> 1.0 / 1.7 (worst 6.9 / 4.4 -> 2.0 / 3.8); Hopkins155
    three motions streamed with ``'auto'`` 8.4 -> 7.7%.

    Parameters
    ----------
    obs : LineObservations
        The window's line tracks.
    n : int
        Number of bodies.
    starts : list of (name, labels (N,)) or (name, labels, W, T, fitted (n,) bool)
        Initial labellings; with motions, the ``fitted`` bodies refine theirs.
    W0, T0 : (n, 3)
        Rotation (rad/frame) and translation (direction; its length is rescanned) to start
        every body's first fit from (:func:`.fit_body_multistart`).
    sigma2 : float
        Endpoint noise variance (px^2), fixed.
    outlier_p : float
        Chi-square quantile of the outlier bound.
    neighbours : (N, k) int, optional
        Image neighbours for the spatial prior of :func:`.spatial.smooth_labels`.
    rounds, iterations : int
        Fit/assign rounds and LM iterations per body and round.
    keep, first_iterations : int
        LM runs (the best starts of the scan) and their iterations for a body's first fit.
    pivots : bool
        Whether a body's first fit also starts from :func:`.pivot_starts`.
    points : (N, 2) float, optional
        Track midpoints (px): each body also gets an image-position term
        (:func:`position_costs`, times ``position_weight * sigma2``) in the assignment and the
        score, so that the starts are compared on motion AND compactness.
    position_weight : float
        Weight of the position term (:data:`POSITION_WEIGHT`).

    Returns
    -------
    dict with ``labels (N,)``, ``W (n, 3)`` rotation vectors (rad/frame), ``T (n, 3)``
    translations per frame (camera frame; length = the scale of ``|T| / d``), ``costs (N, n)``
    (motion only), ``sigma2``, the winning ``start`` (a move keeps its start's name), its
    ``score`` (capped total cost, position terms included) and ``cap (N,)``, every track's
    outlier cap.

    """
    usable = obs.frames >= 3
    rounds_kw = {'rounds': rounds, 'iterations': iterations, 'outlier_p': outlier_p,
                 'neighbours': neighbours, 'keep': keep, 'first_iterations': first_iterations,
                 'pivots': pivots, 'points': points, 'position_weight': position_weight}
    best = None
    for name, lab, *motions in starts:
        lab = np.where(usable, np.asarray(lab, dtype=np.int64), -1)
        # a start with its motions (W, T, fitted) refines them; the others search from W0, T0
        W, T, fitted = motions if motions else (W0, T0, np.zeros(n, dtype=bool))
        sol = _fit_assign(obs, lab, np.array(W, dtype=float), np.array(T, dtype=float),
                          np.array(fitted, dtype=bool), sigma2, name, **rounds_kw)
        if best is None or sol['score'] < best['score']:
            best = sol
    # a move keeps the start's name: a tracked solve whose grouping a move repaired is still a
    # tracked solve to the pipeline's schedule (named apart, it counted as a search and asked
    # for more full solves: bench live own3+bg, 'auto', 9.4% wrong instead of 5.1%)
    for lab, W, T, fitted in split_merge_starts(obs.midpoints, best):
        sol = _fit_assign(obs, lab, W, T, fitted, sigma2, best['start'], **rounds_kw)
        if sol['score'] < best['score']:
            best = sol
    return best


def _fit_assign(obs: LineObservations, labels: np.ndarray, W: np.ndarray, T: np.ndarray,
                fitted: np.ndarray, sigma2: float, name: str, rounds: int, iterations: int,
                outlier_p: float, neighbours: Optional[np.ndarray], keep: int,
                first_iterations: int, pivots: bool, points: Optional[np.ndarray],
                position_weight: float) -> dict:
    """
    Run :func:`marginal_segmentation`'s fit/assign rounds from one start; return its solution.

    ``labels (N,)``: the start (``-1`` none); ``W, T (n, 3)``: the bodies' motions, refit in
    place (LM where ``fitted (n,)``, else a multi-start search, :func:`_fit_each_body`);
    ``name``: the start's name. The rest as :func:`marginal_segmentation` takes them; the
    solution as it returns it, with ``cap (N,)``, every track's outlier cap, too.
    """
    n = W.shape[0]
    costs = np.full((obs.n_tracks, n), np.nan)
    cap = np.full(obs.n_tracks, np.inf)
    total = costs
    for _ in range(rounds):
        _fit_each_body(obs, labels, W, T, fitted, iterations, lambda b: W[b], sigma2,
                       lambda b: T[b], keep, first_iterations, pivots)
        new, costs, total, cap = assign_bodies(obs, W, T, sigma2, labels, outlier_p,
                                               neighbours, points, position_weight)
        if np.array_equal(new, labels):
            break
        labels = new
    return {'labels': labels, 'W': W.copy(), 'T': T.copy(), 'costs': costs,
            'sigma2': sigma2, 'start': name, 'score': total_cost(total, labels, cap),
            'cap': cap}


#: Bodies a segmentation needs for :func:`split_merge_starts` (one to merge into another, one
#: to split), and the fewest tracks a body split there holds (a body is fitted from 3).
SPLIT_MERGE_BODIES, SPLIT_MIN_TRACKS, SPLIT_PART_TRACKS = 3, 12, 3


def split_merge_starts(points: np.ndarray, sol: dict) -> list:
    """
    Return the starts of split-and-merge moves from a segmentation ``sol`` (Ueda et al. 2000).

    The fit/assign rounds only move tracks one at a time between bodies, and stay in a basin
    where one body holds two objects while another object is split over two bodies (two boxes
    that turn alike at different places have one rotation, and the rotation-only labels the
    search starts from put them together). A move merges the pair of bodies whose merge costs
    least (the capped costs that one body's tracks add under the other's motion) and, to keep
    the count, splits one body into its largest region of the image and the rest
    (:func:`.spatial.largest_region`): one start per body in two regions of at least
    :data:`SPLIT_PART_TRACKS` tracks each, the largest region the new body.

    ``points (N, 2)``: the tracks' midpoints (px); ``sol``: as :func:`_fit_assign` returns it
    (``labels (N,)``, ``costs (N, n)``, ``cap (N,)``, ``W``, ``T (n, 3)``). Returns
    ``(labels (N,), W (n, 3), T (n, 3), fitted (n,) bool)`` per start: the merged pair's
    survivor and the rest of the split body keep their motions, the largest region starts
    unfitted (a multi-start search from the split body's motion). No start with fewer than
    :data:`SPLIT_MERGE_BODIES` bodies or no labelled track.
    """
    labels = np.asarray(sol['labels'])
    n = sol['W'].shape[0]
    if n < SPLIT_MERGE_BODIES:
        return []
    capped = np.minimum(np.nan_to_num(np.asarray(sol['costs'], dtype=float), nan=np.inf),
                        np.asarray(sol['cap'], dtype=float)[:, None])
    held = (labels >= 0) & np.all(np.isfinite(capped), axis=1)
    own = capped[np.flatnonzero(held), labels[held]]
    # merge[a, b]: the capped cost that b's tracks add when a's motion takes them
    onehot = np.zeros((own.size, n))
    onehot[np.arange(own.size), labels[held]] = 1.0
    merge = (capped[held] - own[:, None]).T @ onehot
    np.fill_diagonal(merge, np.inf)
    into, gone = (int(i) for i in np.unravel_index(int(np.argmin(merge)), merge.shape))
    merged = np.where(labels == gone, into, labels)
    spacing = track_spacing(points)
    out = []
    for b in range(n):                                   # bodies, not lines
        idx = np.flatnonzero(merged == b)
        if b == gone or idx.size < SPLIT_MIN_TRACKS:
            continue
        region = largest_region(points[idx], spacing)
        if min(np.count_nonzero(region), np.count_nonzero(~region)) < SPLIT_PART_TRACKS:
            continue
        lab = merged.copy()
        lab[idx[region]] = gone
        W, T = sol['W'].copy(), sol['T'].copy()
        W[gone], T[gone] = W[b], T[b]
        fitted = np.ones(n, dtype=bool)
        fitted[gone] = False
        out.append((lab, W, T, fitted))
    return out


#: The marginalised model's noise variance, as a multiple of the noise variance of the
#: fitted-direction model on the rotation-only labels. That estimate is the median of costs
#: from which two unknowns per line and the best of n bodies were fitted away, and it ignores
#: model error (non-constant velocity, lens): taken as it is, a body's translation scale grows
#: until it explains other bodies' lines. Measured on bench hopkins, K = 5, one window of 16
#: sequences: misclassified 30% (x1), 20% (x2), 16% (x4), 7% (x8); 32 sequences: 5.9% (x16),
#: 7.4% (x64), 7.5% (x1000, nearly rotation-only); robust 20.3%, robust with -1 -> cheapest
#: body 11.1%. With a T = 0 start in every body fit, the 35 three-motion sequences, K = 5,
#: both windows: 12.2% (x8), 11.2% (x16), 12.2% (x32).
NOISE_FACTOR = 16.0


def general_search(obs: LineObservations, n: int, starts: list, rot_labels: np.ndarray,
                   w_rot: np.ndarray, neighbours: Optional[np.ndarray] = None,
                   noise_factor: float = NOISE_FACTOR, outlier_p: float = 0.9999,
                   points: Optional[np.ndarray] = None,
                   position_weight: float = POSITION_WEIGHT,
                   rng: Optional[np.random.Generator] = None) -> dict:
    """
    Search the 'general' method's labels: noise level, then :func:`marginal_segmentation`.

    Parameters
    ----------
    obs : LineObservations
        The window's line tracks.
    n : int
        Number of bodies.
    starts : list of (name, labels (N,))
        Initial labellings (the rotation-only solution, a spatial clustering, ...).
    rot_labels : (N,) int
        The rotation-only labels: each body is first fitted on them with fitted line
        directions (multi-start over T), which gives the noise level (times
        ``noise_factor``) and the starting motions.
    w_rot : (n, 3)
        Rotation-only rotation vectors (rad/frame), the first fits' starts.
    neighbours : (N, k) int, optional
        Image neighbours for the spatial prior.
    noise_factor : float
        The marginalised model's noise variance over the measured one (:data:`NOISE_FACTOR`).
    outlier_p : float
        Chi-square quantile of the outlier bound.
    points : (N, 2) float, optional
        Track midpoints (px) for the bodies' position term (:func:`position_costs`).
    position_weight : float
        Weight of the position term (:data:`POSITION_WEIGHT`).
    rng : numpy.random.Generator, optional
        Given: one more start, :func:`background_labels` at the measured noise (the lines
        that stand still, or turn with one of ``w_rot``, one body; the others split by place
        with ``rng``). None: ``starts`` only.

    Returns
    -------
    dict
        As :func:`marginal_segmentation`'s.

    """
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    W, T = np.array(w_rot, dtype=float), np.zeros((n, 3))
    lab = np.where(dof > 0, np.asarray(rot_labels, dtype=np.int64), -1)
    _fit_each_body(obs, lab, W, T, np.zeros(n, dtype=bool), 6, lambda b: w_rot[b])
    measured = measured_noise(obs, W, T)
    if rng is not None:
        # the background's candidates: no motion (a still camera), each rotation-only body's
        candidates = np.concatenate([np.zeros((1, 3)), np.asarray(w_rot, dtype=float)])
        starts = list(starts) + [('background',
                                  background_labels(obs, n, candidates, measured, rng))]
    sigma2 = noise_factor * measured
    return marginal_segmentation(obs, n, starts, W, T, sigma2, outlier_p=outlier_p,
                                 neighbours=neighbours, points=points,
                                 position_weight=position_weight)


#: A warm start is kept when at least this share of the usable tracks stay inliers (else the
#: full multi-start search runs).
WARM_INLIERS = 0.5


def general_warm(obs: LineObservations, labels: np.ndarray, W0: np.ndarray, T0: np.ndarray,
                 known: np.ndarray, rounds: int = 3, iterations: int = 4,
                 outlier_p: float = 0.9999) -> dict:
    """
    Track the bodies of the previous window: a few LM steps from its motions, then assign.

    Parameters
    ----------
    obs : LineObservations
        The window's line tracks.
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
    outlier_p : float
        Chi-square quantile of the outlier bound.

    Returns
    -------
    dict
        As :func:`marginal_segmentation`'s (``start='warm'``, fitted directions, unit ``T``)
        plus ``inliers``, the share of usable tracks within the outlier bound.

    """
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
