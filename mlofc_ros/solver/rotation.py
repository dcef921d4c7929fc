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
The rotation-only methods, at a known or an unknown focal length.

``'algebraic'``, ``'kmeans'`` and ``'algebraic+kmeans'`` are the paper's (unweighted);
``'robust'`` is ours (:mod:`.robust`). Each is a *known-f segmentation*: line flows in, a
:class:`~.robust.Segmentation` out. :func:`solve_rotation` runs one on a
:class:`~.problem.Problem`, estimating the focal length first when the intrinsics are unknown,
and makes the :class:`~.result.SegmentationResult` (covariances, residuals).
"""
import math
from typing import Callable, Optional, Tuple

import numpy as np

from .focal import first_order_focal, profile_cost, refine_focal
from .gpca import algebraic_normals
from .ksubspaces import assign, ksubspaces, total_cost
from .lines import cayley_jacobian, cayley_to_rotvec, line_flows, LineFlows
from .models import fit_bodies, fit_stats, quad_costs, track_costs, track_stats
from .problem import Problem
from .result import Diagnostics, noted, SegmentationResult
from .robust import noise_sigma, robust_segmentation, Segmentation, WARM_INLIERS

#: A known-f segmentation: ``(flows, tracks (N, K, 4), n, rng) -> Segmentation``.
KnownFocal = Callable[[LineFlows, np.ndarray, int, np.random.Generator], Segmentation]

#: Plausible focal lengths, in units of the larger image side (fields of view ~7-170 deg);
#: an estimate outside is replaced by a scan over this range.
FOCAL_RANGE = (0.25, 8.0)

#: Random restarts of the paper's K-means from a random labelling (the best is kept).
KMEANS_RESTARTS = 10


def _paper(flows: LineFlows, n: int,
           group: Callable[[object], Tuple[np.ndarray, np.ndarray]]) -> Segmentation:
    """One of the paper's methods (unweighted): ``group(stats) -> (labels, c)`` for n >= 2."""
    stats = track_stats(flows, weighted=False)
    if n == 1:
        labels = np.where(stats.usable, 0, -1)
        c, _ = fit_stats(stats, labels, 1)
    else:
        labels, c = group(stats)
    return Segmentation(labels, c, track_costs(flows, c, weighted=True), Diagnostics())


def algebraic(flows: LineFlows, tracks: np.ndarray, n: int,
              rng: np.random.Generator) -> Segmentation:
    """Segment by the paper's Algorithm 1 (a GPCA fit, each track to its cheapest body)."""
    def group(stats):
        c = algebraic_normals(flows.rows.reshape(-1, 4), n)[:, :3]
        return assign(quad_costs(stats, c)), c
    return _paper(flows, n, group)


def algebraic_kmeans(flows: LineFlows, tracks: np.ndarray, n: int,
                     rng: np.random.Generator) -> Segmentation:
    """Segment by Algorithm 1, then the paper's K-means from its labels (the paper's best)."""
    def group(stats):
        c = algebraic_normals(flows.rows.reshape(-1, 4), n)[:, :3]
        labels, c, _ = ksubspaces(stats, n, assign(quad_costs(stats, c)))
        return labels, c
    return _paper(flows, n, group)


def kmeans(flows: LineFlows, tracks: np.ndarray, n: int,
           rng: np.random.Generator) -> Segmentation:
    """Segment by the paper's K-means from random labellings (best of :data:`KMEANS_RESTARTS`)."""
    def group(stats):
        best = None
        for _ in range(KMEANS_RESTARTS):
            start = np.where(stats.usable, rng.integers(0, n, flows.n_tracks), -1)
            lab, cc, costs = ksubspaces(stats, n, start)
            score = total_cost(costs, lab)
            if best is None or score < best[0]:
                best = (score, lab, cc)
        return best[1], best[2]
    return _paper(flows, n, group)


def robust_segmenter(init_labels: Optional[np.ndarray] = None,
                     warm_inliers: Optional[float] = None,
                     warm_competes: Optional[bool] = None) -> KnownFocal:
    """
    Return our method (:func:`.robust_segmentation`) with this warm start, as a known-f one.

    ``None`` keeps a keyword's default (:data:`.robust.WARM_INLIERS`; the warm start competes).
    """
    def segment(flows: LineFlows, tracks: np.ndarray, n: int,
                rng: np.random.Generator) -> Segmentation:
        return robust_segmentation(
            flows, tracks, n, rng, init_labels=init_labels,
            warm_inliers=WARM_INLIERS if warm_inliers is None else warm_inliers,
            warm_competes=True if warm_competes is None else warm_competes)
    return segment


def solve_rotation(problem: Problem, method: str, segment: KnownFocal,
                   refine_with: Optional[KnownFocal] = None) -> SegmentationResult:
    """
    Solve ``problem`` with the known-f segmentation ``segment``; the result names ``method``.

    Unknown intrinsics: the focal length is estimated first (:func:`estimate_focal`), refined
    with ``refine_with`` (default: :func:`robust_segmenter` without a warm start).
    """
    rng = np.random.default_rng(problem.seed)
    if problem.intrinsics is not None:
        fx, fy, cx, cy = problem.intrinsics
        flows = line_flows(problem.tracks, problem.intrinsics)
        seg = segment(flows, problem.tracks, problem.n_bodies, rng)
        return finish(flows, seg, fx, method,
                      noted(seg.diagnostics, principal_point=(cx, cy), aspect=fy / fx,
                            image_size=problem.image_size))
    f, first_order = estimate_focal(problem, rng, refine_with or robust_segmenter())
    w, h = problem.image_size
    centre = (w / 2.0, h / 2.0)
    flows = line_flows(problem.tracks, (f, f) + centre)
    seg = segment(flows, problem.tracks, problem.n_bodies, rng)
    return finish(flows, seg, f, method,
                  noted(seg.diagnostics, focal_first_order=first_order,
                        principal_point=centre, aspect=1.0, image_size=problem.image_size))


def estimate_focal(problem: Problem, rng: np.random.Generator, refine_with: KnownFocal
                   ) -> Tuple[float, Optional[float]]:
    """
    Return the focal length (px) of a problem and its first-order estimate (or None).

    The first-order multibody estimate (:func:`.first_order_focal`), or a scan when it is
    undetermined or implausible (outside :data:`FOCAL_RANGE`), then two exact profile
    refinements on the labels of ``refine_with``: f is a property of the camera, and the
    first-order estimate can be ~10% off for n = 4.
    """
    arr, n = problem.tracks, problem.n_bodies
    w, h = problem.image_size
    centre = (w / 2.0, h / 2.0)
    first_order = first_order_focal(arr, n, problem.image_size)
    f = first_order
    if f is not None and not FOCAL_RANGE[0] <= f / max(w, h) <= FOCAL_RANGE[1]:
        f = None                   # implausible (a field of view over 170 or under 7 deg)
    if f is None:
        f = _scan_focal(arr, n, problem.image_size, rng)
    for span in (3.0, 1.2):
        flows = line_flows(arr, (f, f) + centre)
        labels = refine_with(flows, arr, n, rng).labels
        f = refine_focal(profile_cost(arr, labels, n, centre), f, span=span)
    return f, first_order


def _scan_focal(arr: np.ndarray, n: int, size: Tuple[float, float],
                rng: np.random.Generator) -> float:
    """
    Return the focal length whose known-f solution explains the tracks best (wide scan).

    For when the paper's eq. (18) is undetermined (e.g. the sum of w1 and w2 over the bodies
    is ~ 0).
    """
    w, h = size
    scan = []
    for f in max(w, h) * np.geomspace(0.3, 3.0, 9):
        flows = line_flows(arr, (f, f, w / 2.0, h / 2.0))
        seg = algebraic_kmeans(flows, arr, n, rng)
        scan.append((total_cost(seg.costs, seg.labels), f))
    return min(scan)[1]


def finish(flows: LineFlows, seg: Segmentation, focal: float, method: str,
           diagnostics: Diagnostics) -> SegmentationResult:
    """
    Make the result of a segmentation: covariances, rotation vectors, residuals per track.

    The covariances are at the noise level of ``diagnostics.sigma_px``, or estimated from the
    costs when it is not set.
    """
    labels, c, costs = seg.labels, seg.cayley, seg.costs
    n = c.shape[0]
    dof = 2.0 * flows.pairs_per_track()
    sigma = diagnostics.sigma_px
    if math.isnan(sigma) or sigma == 0:
        sigma = noise_sigma(costs, labels, dof)
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
    return SegmentationResult(labels=labels.astype(np.int64),
                              angular_velocities=cayley_to_rotvec(c), angular_covariances=cov,
                              focal_length=float(focal), residuals=rms, costs=costs,
                              method=method,
                              diagnostics=noted(diagnostics, sigma_px=float(sigma)))


def _covariances(information: np.ndarray, jac: np.ndarray, sigma2: float, fitted: np.ndarray
                 ) -> np.ndarray:
    """
    Covariances ``(n, 3, 3)`` of the bodies' rotation vectors; ``inf`` for the unfitted.

    ``information (n, 3, 3)``: information matrices of the Cayley vectors for 1 px noise; ``jac``:
    Jacobians of the rotation vectors; ``sigma2``: noise variance (px^2); ``fitted``: the
    bodies to compute (enough tracks).
    """
    n = information.shape[0]
    cov = np.full((n, 3, 3), np.inf)
    every = slice(None) if fitted.size == n else fitted    # no copies in the usual case
    try:
        # all bodies in one stacked call (the same LAPACK inverse and 3x3 products per body)
        j = jac[every]
        cov[every] = j @ (sigma2 * np.linalg.inv(information[every])) @ j.transpose(0, 2, 1)
    except np.linalg.LinAlgError:
        for i in fitted:                                  # n bodies, not a per-line loop
            try:
                cov_c = sigma2 * np.linalg.inv(information[i])
            except np.linalg.LinAlgError:
                continue
            cov[i] = jac[i] @ cov_c @ jac[i].T
    return cov


def _argmin_nan_to_num(costs: np.ndarray) -> np.ndarray:
    """
    ``np.argmin(np.nan_to_num(costs, nan=np.inf), axis=1)`` of ``costs (M, n)``, ``(M,)``.

    The same mapping (nan to inf, +-inf to +-the largest float: inf ranks after it) in a few
    ufunc calls instead of nan_to_num's generic machinery.
    """
    clipped = np.minimum(np.maximum(costs, -_BIG), _BIG)
    return np.where(np.isnan(costs), np.inf, clipped).argmin(axis=1)


_BIG = float(np.finfo(np.float64).max)


def solve_robust(problem: Problem, init_labels: Optional[np.ndarray] = None,
                 warm_inliers: Optional[float] = None,
                 warm_competes: Optional[bool] = None) -> SegmentationResult:
    """
    Solve ``problem`` with our method (``'robust'``); the focal length refined with it too.

    ``init_labels`` (N,): the previous window's labels (``-1`` unknown, ids below n);
    ``warm_inliers``, ``warm_competes``: see :func:`.segment_lines`.
    """
    segment = robust_segmenter(init_labels, warm_inliers, warm_competes)
    return solve_rotation(problem, 'robust', segment, refine_with=segment)
