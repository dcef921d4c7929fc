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
"""``segment_lines``: the public entry point of the solver."""
import math
from math import comb
from typing import Optional, Sequence, Tuple

import numpy as np

from .focal import first_order_focal, profile_cost, refine_focal
from .general import (body_covariance, fit_body_multistart, general_search, general_warm,
                      LineObservations, marginal_segmentation, NOISE_FACTOR, polish_body,
                      spatial_labels, WARM_INLIERS)
from .gpca import algebraic_normals
from .ksubspaces import assign, ksubspaces, total_cost
from .lines import (cayley_jacobian, cayley_to_rotvec, line_flows, LineFlows,
                    rotvec_to_cayley)
from .models import fit_bodies, fit_stats, quad_costs, track_costs, track_stats
from .result import SegmentationResult
from .robust import noise_sigma, robust_segmentation, WARM_INLIERS as ROBUST_WARM_INLIERS
from .spatial import spatial_neighbours

#: Methods accepted by :func:`segment_lines`.
METHODS = ('algebraic', 'kmeans', 'algebraic+kmeans', 'robust', 'general')

#: Plausible focal lengths, in units of the larger image side (fields of view ~7-170 deg);
#: an estimate outside is replaced by a scan over this range.
FOCAL_RANGE = (0.25, 8.0)

#: LM iterations of the final refit of every 'general' body at the measured noise level.
POLISH_ITERATIONS = 10

#: The published rotation of every 'general' body is refit (:func:`.polish_body`, robust) at
#: this fraction of the measured noise variance, from the segmentation's motion and on its
#: lines, which keep their labels; the segmentation, the pipeline's body ids and the next
#: window's warm start keep the segmentation's motion. The marginalised model's prior on the
#: line directions pulls W towards a rotation-only fit by ~sigma2 (3.4% of |w| at
#: :data:`.general.NOISE_FACTOR`, ~1% at the measured noise); at a small fraction of it the
#: model tends to the fitted-direction one, unbiased near the right basin, and the robust cost
#: at that scale lets the few mislabelled lines hardly pull. Spinning benchmark (window 10,
#: render seeds 0-5, the same labels), boxes with omega within 5% own2+bg / own3+bg / own3:
#: 7 / 14 / 13 -> 9 / 17 / 18 of 12 / 18 / 18, median error 2 / 3 / 2 -> 0 / 1 / 1%, for one
#: more refit per body per frame (session 19, docs/design.md). None: publish the
#: segmentation's motion.
PUBLISH_NOISE_SCALE: Optional[float] = 0.01

#: A rescanned body (``rescan`` of :func:`segment_lines`) takes the pivot search's fit only
#: when it is cheaper than the tracked one by this share of its cost: the fits are compared
#: on the same lines at the measured noise, but near-equal basins swap on noise (spinning
#: benchmark, 3 seeds: wrong % over own2+bg / own3+bg / own2 / own3, see the commit).
RESCAN_MARGIN = 0.1

#: Whether the final refit of every 'general' body (:func:`.polish_body`) and the rescan's
#: pivot search and comparison use the robust (Cauchy) line cost at the measured noise level,
#: with the warm and segmentation fits left least squares. (The cost in every fit as well,
#: helper branch h33, was not adopted: 4.2 / 9.4 / 6.4 / 8.8 -> 7.8 / 11.9 / 2.7 / 1.5 on an
#: earlier front end, better without a background body and worse with one; design.md.)
#: Spinning benchmark, window 10, six seeds, mean wrong % own2+bg / own3+bg / own2 / own3
#: 4.6 / 16.9 / 2.1 / 9.8 -> 4.0 / 13.3 / 1.6 / 5.3 (with :data:`RESCAN_MARGIN_ROBUST` 0;
#: 3.1 / 17.4 / 1.7 / 7.8 with 0.1), cam2+bg 0.09 -> 0.10 (design.md, session 10, h34).
GENERAL_ROBUST_POLISH = True

#: :data:`RESCAN_MARGIN` when the rescan compares robust costs
#: (:data:`GENERAL_ROBUST_POLISH`): the pivot search's fit wins whenever it is cheaper (the
#: robust cost makes a wrong basin only about 10% dearer; a 10% margin kept own3+bg seed 4 in
#: one, 32% wrong, 13% with none).
RESCAN_MARGIN_ROBUST = 0.0

#: Whether the rescan refines the best pivot start of every rate instead of the best four
#: overall (:func:`.general.pivot_picks`): a body fitted as nearly static, its flow explained
#: by a translation, ranks the starts at its true rate low before any LM step (session 23).
#: Spinning benchmark, window 10, render seeds 0-11, mean wrong % own2+bg / own3+bg / own2 /
#: own3: 3.13 / 4.72 / 0.18 / 1.09 -> 2.08 / 4.29 / 0.21 / 0.50, boxes with omega within 5%
#: 106 -> 108 of 120, ~+6-10% CPU per frame. The cold search keeps the global ranking: the
#: best four plus the best of every rate there (and in the rescan) took the 35 three-motion
#: Hopkins155 sequences from 10.5 to 10.7% (and own3+bg to 5.2%).
RESCAN_PER_RATE = True

#: Weight of each body's image-position term (:func:`.general.position_costs`, times the
#: noise level) in the warm path's assignment (the pipeline's tracked bodies; the cold search
#: uses :data:`.general.POSITION_WEIGHT`). Spinning benchmark, window 10, mean wrong % own2+bg
#: / own3+bg / own2 / own3 over render seeds 0-5: none 6.5 / 10.6 / 1.6 / 5.2, 0.5 2.8 / 9.8 /
#: 0.7 / 6.0, 1.0 2.3 / 10.5 / 0.4 / 3.0, 2.0 7.6 / 7.5 / 0.1 / 2.5; held-out seeds 6-8:
#: none 3.3 / 9.1 / 0.4 / 3.9, 1.0 3.4 / 3.8 / 0.0 / 0.5; cam2+bg 0.10 -> 0.07 (session 13).
WARM_POSITION_WEIGHT = 1.0

#: Whether the warm path assigns the lines with the tracked bodies' previous motions as they
#: are and starts the marginalised segmentation from them (True), rather than from a few LM
#: steps on the fitted-direction model (:func:`.general_warm`). That model is flat (two
#: unknowns per line): the steps moved a body with few lines into another basin (own2+bg s2,
#: frame 212: 137 -> 28 deg/s about y), it lost its lines to a neighbour and the ids came back
#: permuted 20 frames later. The LM refit still measures the noise level of the final refit
#: and the rescan when it fits better: at a tracked motion from a wrong basin the noise would
#: be inflated and the rescan could not leave it. Spinning benchmark, window 10, mean wrong %
#: over render seeds 0-2 (session 14): 300 frames own2+bg / own3+bg 11.6 / 28.0 -> 1.2 / 3.2;
#: 30 frames, seeds 0-5, own2+bg / own3+bg / own2 / own3 3.8 / 5.5 / 0.4 / 2.6 -> 4.4 / 6.4 /
#: 0.3 / 2.9.
WARM_KEEP_MOTIONS = True

#: Whether the warm path starts the marginalised segmentation from the previous window's
#: labels of the tracks that had one (new and unassigned tracks take the assignment at the
#: previous motions), instead of from that assignment for every track. The assignment uses
#: the fitted-direction costs (:func:`.general_warm`), which at short windows carry little
#: first-order information (two unknowns per line; 2K - 4 constraints): on Hopkins155
#: streamed through the warm path (`bench hopkins_stream`, K = 5) right groupings fell apart
#: in the next windows (1R2TCR 0 -> 33% wrong: two bodies' lines swapped). The 35 three-motion
#: sequences, mean over every window: 23.3 -> 10.7% (session 28).
WARM_KEEP_LABELS = True

#: With :data:`WARM_KEEP_LABELS`, also run the old start (every track reassigned) and keep
#: the lower score of the two: one more marginalised segmentation per warm solve (+12-25% CPU
#: per frame). The reassignment repairs groupings that the kept labels would carry on (a
#: wrong first cold search). Spinning benchmark, window 10, mean wrong % own2+bg / own3+bg /
#: own2 / own3, render seeds 0-5: reassigned only (before) 5.9 / 6.7 / 0.4 / 3.9, kept only
#: 3.4 / 8.0 / 0.1 / 5.6, both 1.8 / 5.3 / 0.4 / 2.1; seeds 0-11, before -> both: 3.6 / 5.3
#: / 0.2 / 2.0 -> 1.6 / 3.9 / 0.2 / 1.2, boxes with omega within 5% 106 -> 112 of 120.
#: Hopkins streamed: 10.6% (session 28).
WARM_ALSO_REASSIGNED = True

#: Random restarts of the paper's K-means from a random labelling (the best is kept).
KMEANS_RESTARTS = 10


def _check_tracks(tracks) -> np.ndarray:
    try:
        arr = np.array(tracks, dtype=np.float64, order='C')           # a copy: NaNs go in
    except (TypeError, ValueError) as exc:
        raise ValueError(f'tracks must be a numeric array of shape (N, K, 4): {exc}') from None
    if arr.ndim != 3 or arr.shape[2] != 4:
        raise ValueError(f'tracks must have shape (N, K, 4) (endpoints u1, v1, u2, v2 per '
                         f'frame), got {arr.shape}')
    if arr.shape[1] < 2:
        raise ValueError(f'tracks need K >= 2 frames, got K = {arr.shape[1]}')
    if np.isinf(arr).any():
        raise ValueError('tracks contain infinite coordinates (use NaN for missing frames)')
    # a frame counts only if all four coordinates are there and the endpoints differ: with no
    # infinities, a nan coordinate makes the length nan, so one comparison tests both
    length = np.hypot(arr[..., 2] - arr[..., 0], arr[..., 3] - arr[..., 1])
    arr[~(length > 1e-9)] = np.nan
    return arr


def _check_intrinsics(intrinsics, image_size
                      ) -> Tuple[Optional[Tuple[float, float, float, float]], Tuple[float, float]]:
    if intrinsics is not None:
        vals = np.asarray(intrinsics, dtype=float).ravel()
        if vals.size != 4:
            raise ValueError(f'intrinsics must be (fx, fy, cx, cy), got {vals.size} values')
        # four numbers, checked as Python floats: numpy calls on them cost more than the checks
        fx, fy, cx, cy = vals.tolist()
        if not all(map(math.isfinite, (fx, fy, cx, cy))):
            raise ValueError(f'intrinsics must be finite, got {tuple(vals)}')
        if fx <= 0 or fy <= 0:
            raise ValueError(f'focal lengths must be > 0, got fx={vals[0]}, fy={vals[1]}')
        size = (2.0 * cx, 2.0 * cy) if image_size is None else image_size
        return (fx, fy, cx, cy), _check_size(size)
    if image_size is None:
        raise ValueError('image_size=(w, h) is needed when intrinsics are unknown (None)')
    return None, _check_size(image_size)


def _check_size(image_size) -> Tuple[float, float]:
    vals = np.asarray(image_size, dtype=float).ravel()
    w, h = vals.tolist() if vals.size == 2 else (math.nan, math.nan)
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        raise ValueError(f'image_size must be (w, h) > 0, got {image_size!r}')
    return w, h


def min_tracks_needed(n_bodies: int, n_frames: int, method: str, focal_known: bool) -> int:
    """Fewest usable tracks (present in two consecutive frames) the model can be solved from.

    Each track gives ``2 (K - 1)`` equations; the algebraic fit needs one fewer than the
    number of monomials (``C(n + 3, 3)`` with known f, ``C(n + 5, 5)`` without); every body
    needs two tracks.
    """
    per_body = 2 * n_bodies
    dims = 4 if focal_known else 6
    if method == 'robust' and focal_known:
        return per_body
    monomials = comb(n_bodies + dims - 1, dims - 1)
    rows_per_track = 2 * max(n_frames - 1, 1)
    return max(per_body, -(-(monomials - 1) // rows_per_track))


def _solve_known_f(flows: LineFlows, tracks: np.ndarray, n: int, method: str,
                   rng: np.random.Generator, init_labels=None,
                   warm_inliers: Optional[float] = None, warm_competes: bool = True):
    """Labels, Cayley vectors, exact weighted costs and info for one method at known f."""
    if method in ('robust', 'general'):
        return robust_segmentation(flows, tracks, n, rng, init_labels=init_labels,
                                   warm_inliers=(ROBUST_WARM_INLIERS if warm_inliers is None
                                                 else warm_inliers),
                                   warm_competes=warm_competes)
    stats = track_stats(flows, weighted=False)          # the paper's methods are unweighted
    if n == 1:
        labels = np.where(stats.usable, 0, -1)
        c, _ = fit_stats(stats, labels, 1)
    elif method in ('algebraic', 'algebraic+kmeans'):
        c = algebraic_normals(flows.rows.reshape(-1, 4), n)[:, :3]
        labels = assign(quad_costs(stats, c))
        if method == 'algebraic+kmeans':
            labels, c, _ = ksubspaces(stats, n, labels)
    else:                                               # 'kmeans' from random labellings
        best = None
        for _ in range(KMEANS_RESTARTS):
            start = np.where(stats.usable, rng.integers(0, n, flows.n_tracks), -1)
            lab, cc, costs = ksubspaces(stats, n, start)
            score = total_cost(costs, lab)
            if best is None or score < best[0]:
                best = (score, lab, cc)
        _, labels, c = best
    return labels, c, track_costs(flows, c, weighted=True), {}


def _finish(flows: LineFlows, labels: np.ndarray, c: np.ndarray, costs: np.ndarray,
            focal: float, method: str, info: dict) -> SegmentationResult:
    n = c.shape[0]
    dof = 2.0 * flows.pairs_per_track()
    sigma = info.get('sigma_px') or noise_sigma(costs, labels, dof)
    _, inf_mat = fit_bodies(flows, labels, n)
    counts = np.bincount(labels[labels >= 0], minlength=n)
    cov = _covariances(inf_mat, cayley_jacobian(c), sigma ** 2, (counts >= 2).nonzero()[0])
    # outliers: the residual under their best body, found in their rows only
    assigned = labels.copy()
    out = (labels < 0).nonzero()[0]
    if out.size:
        assigned[out] = _argmin_nan_to_num(costs[out]) if n else 0
    # rms of the tracks with a frame pair; nan for the others (no 0 / 0)
    rms = np.divide(costs[np.arange(costs.shape[0]), assigned], dof,
                    out=np.full(costs.shape[0], np.nan), where=dof > 0)
    np.sqrt(rms, out=rms)
    info = dict(info, sigma_px=float(sigma))
    return SegmentationResult(labels=labels.astype(np.int64),
                              angular_velocities=cayley_to_rotvec(c), angular_covariances=cov,
                              focal_length=float(focal),
                              residuals=rms, costs=costs, method=method, info=info)


def _covariances(info: np.ndarray, jac: np.ndarray, sigma2: float, fitted: np.ndarray
                 ) -> np.ndarray:
    """Covariances ``(n, 3, 3)`` of the bodies' rotation vectors; ``inf`` for the unfitted.

    ``info (n, 3, 3)``: information matrices of the Cayley vectors for 1 px noise; ``jac``:
    Jacobians of the rotation vectors; ``sigma2``: noise variance (px^2); ``fitted``: the
    bodies to compute (enough tracks).
    """
    n = info.shape[0]
    cov = np.full((n, 3, 3), np.inf)
    every = slice(None) if fitted.size == n else fitted    # no copies in the usual case
    try:
        # all bodies in one stacked call (the same LAPACK inverse and 3x3 products per body)
        j = jac[every]
        cov[every] = j @ (sigma2 * np.linalg.inv(info[every])) @ j.transpose(0, 2, 1)
    except np.linalg.LinAlgError:
        for i in fitted:                                  # n bodies, not a per-line loop
            try:
                cov_c = sigma2 * np.linalg.inv(info[i])
            except np.linalg.LinAlgError:
                continue
            cov[i] = jac[i] @ cov_c @ jac[i].T
    return cov


def _argmin_nan_to_num(costs: np.ndarray) -> np.ndarray:
    """``np.argmin(np.nan_to_num(costs, nan=np.inf), axis=1)`` of ``costs (M, n)``, ``(M,)``.

    The same mapping (nan to inf, +-inf to +-the largest float: inf ranks after it) in a few
    ufunc calls instead of nan_to_num's generic machinery.
    """
    clipped = np.minimum(np.maximum(costs, -_BIG), _BIG)
    return np.where(np.isnan(costs), np.inf, clipped).argmin(axis=1)


_BIG = float(np.finfo(np.float64).max)


def segment_lines(tracks, n_bodies: int, intrinsics: Optional[Sequence[float]] = None,
                  image_size: Optional[Sequence[float]] = None, method: str = 'robust', *,
                  seed: int = 0, init_labels: Optional[np.ndarray] = None,
                  init_motions: Optional[Tuple[np.ndarray, np.ndarray]] = None,
                  rescan: Optional[Sequence[int]] = None,
                  warm_inliers: Optional[float] = None,
                  warm_competes: bool = True) -> SegmentationResult:
    """Segment line tracks into rigid bodies by their rotation (multibody line optical flow).

    Parameters
    ----------
    tracks : (N, K, 4) array_like of float
        N line tracks over K >= 2 consecutive frames, endpoints ``(u1, v1, u2, v2)`` in pixels
        (undistorted), NaN where a track is missing. Endpoints need not correspond between
        frames: only the line matters.
    n_bodies : int
        Number of rigid motions (>= 1; 0 = choose automatically).
    intrinsics : (fx, fy, cx, cy), optional
        Pixels. ``None``: principal point at the centre of ``image_size`` and the focal length
        estimated (paper section 3.3, then refined with the exact known-f model).
    image_size : (w, h), optional
        Pixels; required when ``intrinsics`` is None.
    method : {'algebraic', 'kmeans', 'algebraic+kmeans', 'robust', 'general'}
        The paper's Algorithm 1 alone; the paper's K-means from a random start (best of
        10 restarts); Algorithm 1 then K-means (the paper's best); ours (default); ours with
        a translation per body too (K >= 3, :mod:`.general`).
    seed : int
        Seed of the random parts (K-means starts, sampling); results repeat for a seed.
    init_labels : (N,) int, optional
        Labels from a previous window (``-1`` unknown), an extra starting point for 'robust'.
    init_motions : ((n, 3), (n, 3)) float, optional
        'general' only, with ``init_labels``: the previous window's rotation vectors (rad per
        frame) and unit translation directions per body (``info['translation_directions']``),
        NaN rows unknown. The bodies are then tracked by a few LM steps from them instead of
        the multi-start search (which still runs when too few tracks stay inliers).
    rescan : sequence of int, optional
        'general' only, with ``init_motions``: bodies whose tracked motion is refitted from
        the pivot starts of the multi-start search too (:func:`.general.pivot_starts`, a turn
        about a point on the body's ray, at the measured noise level), which wins when cheaper
        by :data:`RESCAN_MARGIN` (:data:`RESCAN_MARGIN_ROBUST` on the robust cost of
        :data:`GENERAL_ROBUST_POLISH`). A body tracked in a wrong basin (a wrong pivot, the
        depth-reversed motion) otherwise keeps it window after window. The labels follow in
        the next window. The pipeline rescans every tracked body at every warm solve
        (:data:`mlofc_ros.pipeline.RESCAN_EVERY_BODY`).
    warm_inliers : float, optional
        'robust' only, with ``init_labels``: the share
        of the usable tracks that the previous labels' final pass must keep as inliers to be
        returned without a search (default :data:`.robust.WARM_INLIERS`, 0.75). The pipeline
        lowers it to what the last search achieved on scenes the rotation model explains
        only in part (``info['warm_rejected']``, ``info['inlier_share']``).
    warm_competes : bool
        'robust' only, with ``init_labels``: a warm start that was not accepted competes with
        the search's candidates, scored at the same noise level (its final pass keeps the
        most inliers on real scenes the rotation model explains in part). 'general' runs its
        rotation-only step without either of these two (its results were tuned on that step;
        the pipeline passes neither for 'general', nor for the 'robust' solves of its first
        frames).

    Returns
    -------
    SegmentationResult
        ``labels (N,)``, ``angular_velocities (n, 3)`` rad per frame interval in the camera
        optical frame, ``angular_covariances``, ``focal_length`` (px), ``residuals (N,)``.
        With 'general' (K >= 3) ``angular_velocities`` and their covariances are each body's
        refit for publication (:data:`PUBLISH_NOISE_SCALE`) and
        ``info['segmentation_angular_velocities'] (n, 3)`` the motions the labels were made
        with, which go with ``info['translation_directions']`` into the next window's
        ``init_motions``.

    Raises
    ------
    ValueError
        Wrong shape, K < 2, non-finite intrinsics, ``n_bodies < 0``, unknown method,
        ``warm_inliers`` outside [0, 1], or fewer usable tracks than the model needs.
    """
    if method not in METHODS:
        raise ValueError(f'unknown method {method!r}; choose from {METHODS}')
    if isinstance(n_bodies, bool) or int(n_bodies) != n_bodies:
        raise ValueError(f'n_bodies must be an integer, got {n_bodies!r}')
    n = int(n_bodies)
    if n < 0:
        raise ValueError(f'n_bodies must be >= 0 (0 = automatic), got {n}')
    if warm_inliers is not None and not 0.0 <= warm_inliers <= 1.0:
        raise ValueError(f'warm_inliers must be a share in [0, 1], got {warm_inliers!r}')
    arr = _check_tracks(tracks)
    intr, size = _check_intrinsics(intrinsics, image_size)
    if n == 0:
        from .model_selection import select_bodies
        return select_bodies(arr, intr, size, method, seed=seed)
    ok = np.isfinite(arr[..., 0])
    usable = np.count_nonzero((ok[:, :-1] & ok[:, 1:]).any(axis=1))
    need = min_tracks_needed(n, arr.shape[1], method, intr is not None)
    if usable < need:
        raise ValueError(f'{usable} usable tracks (present in two consecutive frames), but '
                         f'{n} bodies with method {method!r} need at least {need}')
    if init_labels is not None:
        init_labels = np.asarray(init_labels)
        if init_labels.shape != (arr.shape[0],):
            raise ValueError(f'init_labels must have shape ({arr.shape[0]},), '
                             f'got {init_labels.shape}')
        # ids of bodies this model does not have are unknown
        init_labels = np.where((init_labels >= 0) & (init_labels < n), init_labels, -1)
        init_labels = init_labels.astype(np.int64)
    rng = np.random.default_rng(seed)
    if method == 'general':
        # the rotation-only step as before session 17 (no lowered bar, no competing warm
        # start): bench live's own3+bg at 10 Hz, whose runs swing by 5-10 points, was 12.6-14.7%
        # wrong in three runs with one or both, against 5.3-7.4% in four without
        rot = segment_lines(arr, n, intr, size, 'robust', seed=seed, init_labels=init_labels,
                            warm_competes=False)
        mask = np.zeros(n, dtype=bool)
        if rescan is not None:
            ids = np.asarray(rescan, dtype=np.int64).ravel()
            mask[ids[(ids >= 0) & (ids < n)]] = True
        return _general(arr, rot, rng, init_labels, _check_motions(init_motions, n), mask)
    if intr is not None:
        flows = line_flows(arr, intr)
        labels, c, costs, info = _solve_known_f(flows, arr, n, method, rng, init_labels,
                                                warm_inliers, warm_competes)
        info.update(principal_point=(intr[2], intr[3]), aspect=intr[1] / intr[0],
                    image_size=size)
        return _finish(flows, labels, c, costs, intr[0], method, info)
    # unknown focal length: first-order multibody estimate, then exact profile refinement
    w, h = size
    centre = (w / 2.0, h / 2.0)
    f0 = first_order_focal(arr, n, size)
    info = {'focal_first_order': f0}
    if f0 is not None and not FOCAL_RANGE[0] <= f0 / max(w, h) <= FOCAL_RANGE[1]:
        f0 = None                  # implausible (a field of view over 170 or under 7 deg)
    if f0 is None:
        # eq. (18) undetermined (e.g. sum of w1 and w2 over bodies ~ 0): scan a wide range and
        # keep the focal length whose known-f solution explains the tracks best
        scan = []
        for f in max(w, h) * np.geomspace(0.3, 3.0, 9):
            flows = line_flows(arr, (f, f) + centre)
            labels, _, costs, _ = _solve_known_f(flows, arr, n, 'algebraic+kmeans', rng)
            scan.append((total_cost(costs, labels), f))
        f0 = min(scan)[1]
    # the refinement segments with our robust method whatever the requested one: f is a
    # property of the camera, and the first-order estimate can be ~10% off for n = 4
    f = f0
    for span in (3.0, 1.2):
        flows = line_flows(arr, (f, f) + centre)
        labels, c, costs, sub = _solve_known_f(flows, arr, n, 'robust', rng, init_labels,
                                               warm_inliers, warm_competes)
        f = refine_focal(profile_cost(arr, labels, n, centre), f, span=span)
    flows = line_flows(arr, (f, f) + centre)
    labels, c, costs, sub = _solve_known_f(flows, arr, n, method, rng, init_labels,
                                           warm_inliers, warm_competes)
    info.update(sub, principal_point=centre, aspect=1.0, image_size=size)
    return _finish(flows, labels, c, costs, f, method, info)


def _check_motions(init_motions, n: int) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """``(W (n, 3), T (n, 3))`` from ``init_motions`` (None stays None); NaN rows unknown."""
    if init_motions is None:
        return None
    try:
        w, t = (np.asarray(x, dtype=np.float64) for x in init_motions)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'init_motions must be (W (n, 3), T (n, 3)): {exc}') from None
    if w.shape != (n, 3) or t.shape != (n, 3):
        raise ValueError(f'init_motions must be two ({n}, 3) arrays, got {w.shape}, {t.shape}')
    return w, t


def _general(arr: np.ndarray, rot: SegmentationResult, rng: np.random.Generator,
             init_labels=None, init_motions=None,
             rescan: Optional[np.ndarray] = None) -> SegmentationResult:
    """Solve with the 'general' method: rotation AND translation per body (:mod:`.general`).

    Starts from the rotation-only solution ``rot`` (which also supplies the focal length when
    it was unknown) and a spatial clustering; needs three frames, else returns ``rot``. With
    the previous window's labels and motions, first tracks them (:func:`.general_warm`): the
    marginalised segmentation starts from the previous labels where tracks had one
    (:data:`WARM_KEEP_LABELS`) and from every track assigned at the previous motions
    (:data:`WARM_ALSO_REASSIGNED`), the lower score kept;
    the tracked bodies marked in ``rescan (n,)`` bool are refitted from the pivot starts too
    (:func:`.fit_body_multistart` at the measured noise), kept when cheaper by
    :data:`RESCAN_MARGIN` (:data:`RESCAN_MARGIN_ROBUST` on the robust cost). The final refit
    (:func:`.polish_body`) and the rescan use the robust line cost with
    :data:`GENERAL_ROBUST_POLISH`.
    """
    if arr.shape[1] < 3:
        rot.method = 'general'
        rot.info['general'] = 'window has fewer than 3 frames: rotation-only result'
        return rot
    n, f = rot.n_bodies, rot.focal_length
    size = rot.info.get('image_size')
    cx, cy = rot.info['principal_point']
    obs = LineObservations(arr, (f, f * rot.info.get('aspect', 1.0), cx, cy))
    neighbours = spatial_neighbours(obs.midpoints)
    sol = None
    refit_sigma2 = None
    if init_labels is not None and init_motions is not None:
        w0, t0 = init_motions
        known = np.all(np.isfinite(w0), axis=1) & np.all(np.isfinite(t0), axis=1)
        if np.any(known):
            w_start = np.where(known[:, None], w0, rot.angular_velocities)
            t_start = np.where(known[:, None], t0, 0.0)
            warm = general_warm(obs, init_labels, w_start, t_start, known,
                                **({'iterations': 0} if WARM_KEEP_MOTIONS else {}))
            if WARM_KEEP_MOTIONS:
                # assign with the previous motions unchanged and start from them; a refit
                # measures the noise of the final refit and the rescan (WARM_KEEP_MOTIONS)
                refit_sigma2 = general_warm(obs, init_labels, w_start, t_start, known)['sigma2']
                warm['W'] = np.where(known[:, None], w0, warm['W'])
                warm['T'] = np.where(known[:, None], t0, warm['T'])
            if warm['inliers'] >= WARM_INLIERS:
                # the warm fits (fitted directions) give the noise level and the starts; each
                # body is also a blob in the image, as in the cold search (compact bodies keep
                # their lines when the motion costs alone would let a neighbour take them)
                starts = [('warm', warm['labels'])]
                if WARM_KEEP_LABELS:
                    prev = np.asarray(init_labels)
                    kept = ('warm', np.where(prev >= 0, prev, warm['labels']))
                    starts = [kept, starts[0]] if WARM_ALSO_REASSIGNED else [kept]
                sol = marginal_segmentation(obs, n, starts, warm['W'],
                                            warm['T'], NOISE_FACTOR * warm['sigma2'],
                                            rounds=2, iterations=4, neighbours=neighbours,
                                            keep=1, first_iterations=4, pivots=False,
                                            points=obs.midpoints,
                                            position_weight=WARM_POSITION_WEIGHT)
    if sol is None:
        starts = [('rotation-only', rot.labels),
                  ('spatial', spatial_labels(obs.midpoints, n, rng))]
        if init_labels is not None:
            starts.insert(0, ('previous', np.asarray(init_labels)))
        sol = general_search(obs, n, starts, rot.labels, rot.angular_velocities, neighbours,
                             points=obs.midpoints)
    labels = sol['labels']
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    # the labels need the inflated noise level (NOISE_FACTOR); the motions are refit on them at
    # the measured one, where the prior on the line directions biases them less (about 2% of
    # |w| at x8 on noise-free spinning bodies, 0.2% at x1)
    sigma2 = sol['sigma2'] / NOISE_FACTOR
    if sol['start'] == 'warm' and refit_sigma2 is not None:
        sigma2 = min(sigma2, refit_sigma2)
    robust = sigma2 if GENERAL_ROBUST_POLISH else None
    margin = RESCAN_MARGIN if robust is None else RESCAN_MARGIN_ROBUST
    for b in range(n):                                    # bodies, not lines
        idx = np.flatnonzero(labels == b)
        if idx.size >= 3:
            fit = polish_body(obs, idx, sol['W'][b], sol['T'][b], POLISH_ITERATIONS, sigma2,
                              robust)
            if rescan is not None and rescan[b] and sol['start'] == 'warm':
                # a tracked body only took a few LM steps from the previous window's motion,
                # so a wrong basin (pivot, depth reversal) would stay window after window: the
                # full search's pivot starts, compared at the measured noise (the inflated one
                # flattens the cost and often prefers a wrong basin)
                alt = fit_body_multistart(obs, idx, fit[0], fit[1], POLISH_ITERATIONS, 1,
                                          sigma2, obs.body_ray(idx), robust=robust,
                                          per_rate=RESCAN_PER_RATE)
                fit = alt if alt[2] < (1.0 - margin) * fit[2] else fit
            sol['W'][b], sol['T'][b] = fit[0], fit[1]
    W_pub, T_pub = _published_motions(obs, labels, sol['W'], sol['T'], sigma2)
    cov = np.empty((n, 3, 3))
    for b in range(n):                                    # bodies, not lines
        idx = np.flatnonzero(labels == b)
        cov[b] = body_covariance(obs, idx, W_pub[b], T_pub[b], sigma2, marginal=True)
        if not np.all(np.isfinite(cov[b])) and not np.array_equal(W_pub[b], sol['W'][b]):
            # a refit without a covariance is not published (nor would it decide, through the
            # pipeline's validity, which bodies are tracked): the segmentation's motion
            W_pub[b], T_pub[b] = sol['W'][b], sol['T'][b]
            cov[b] = body_covariance(obs, idx, W_pub[b], T_pub[b], sigma2, marginal=True)
    scale = np.linalg.norm(sol['T'], axis=1)
    with np.errstate(invalid='ignore', divide='ignore'):
        best = sol['costs'][np.arange(arr.shape[0]),
                            np.where(labels >= 0, labels,
                                     np.argmin(np.nan_to_num(sol['costs'], nan=np.inf), 1))]
        rms = np.where(dof > 0, np.sqrt(best / dof), np.nan)
        directions = np.where(scale[:, None] > 0, sol['T'] / scale[:, None], 0.0)
    info = dict(rot.info, sigma_px=float(np.sqrt(sigma2)), start=sol['start'],
                score=float(sol['score']), translation_directions=directions,
                translation_scales=scale, segmentation_angular_velocities=sol['W'],
                image_size=size)
    return SegmentationResult(labels=labels, angular_velocities=W_pub,
                              angular_covariances=cov, focal_length=f, residuals=rms,
                              costs=sol['costs'], method='general', info=info)


def _published_motions(obs: LineObservations, labels: np.ndarray, W: np.ndarray,
                       T: np.ndarray, sigma2: float) -> Tuple[np.ndarray, np.ndarray]:
    """Return the motions ``(W (n, 3), T (n, 3))`` that 'general' publishes.

    Each body's refit from ``W, T`` (the segmentation's, at noise ``sigma2`` px^2) on its
    ``labels`` at :data:`PUBLISH_NOISE_SCALE` of that noise; bodies with fewer than 3 lines
    or a non-finite refit, or all of them when it is None, keep ``W, T``.
    """
    W_pub, T_pub = W.copy(), T.copy()
    if PUBLISH_NOISE_SCALE is None:
        return W_pub, T_pub
    s2 = sigma2 * PUBLISH_NOISE_SCALE
    for b in range(W.shape[0]):                          # bodies, not lines
        idx = np.flatnonzero(labels == b)
        if idx.size >= 3:
            w, t, _ = polish_body(obs, idx, W[b], T[b], POLISH_ITERATIONS, s2, s2)
            if np.all(np.isfinite(w)) and np.all(np.isfinite(t)):
                W_pub[b], T_pub[b] = w, t
    return W_pub, T_pub


def assign_with_motions(tracks, angular_velocities, intrinsics: Sequence[float], *,
                        weighted: bool = False) -> SegmentationResult:
    """Assign every track with GIVEN (true) motions, no estimation: the floor.

    ``angular_velocities (n, 3)`` are rotation vectors in rad per frame interval (camera optical
    frame). ``weighted=False`` uses the paper's algebraic residual, ``True`` the Mahalanobis
    cost. No method can beat this on the same data with the same residual.
    """
    arr = _check_tracks(tracks)
    intr, _ = _check_intrinsics(intrinsics, None)
    if intr is None:
        raise ValueError('assign_with_motions needs intrinsics')
    w = np.atleast_2d(np.asarray(angular_velocities, dtype=float))
    c = rotvec_to_cayley(w)
    flows = line_flows(arr, intr)
    labels = assign(track_costs(flows, c, weighted=weighted))
    return _finish(flows, labels, c, track_costs(flows, c, weighted=True), intr[0],
                   'floor-weighted' if weighted else 'floor', {})
