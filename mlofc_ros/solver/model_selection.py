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
Choosing the number of bodies (``n_bodies=0``): a BIC-style score on truncated costs.

For ``n = 1 .. n_max`` the method is run; every track costs its chi-square under its best body,
capped at the outlier bound, all at ONE noise level (the one estimated with the richest model,
so that an under-fitted model cannot hide behind an inflated noise estimate). The score adds
``log(rows)`` per parameter of a body's motion (three for a rotation, six with a translation)
and ``2 log n`` per track (its label), and the smallest score wins: a further body must
explain more than it costs to describe. The online count (:mod:`mlofc_ros.counting`) also
scores its changes under a label prior that knows bodies are compact in the image
(:func:`label_cost` with the tracks' neighbours).
"""
from dataclasses import replace
from typing import Optional, Tuple

import numpy as np

from .lines import first_midpoints
from .methods import Method, REGISTRY
from .models import chi2_quantile
from .problem import Problem
from .result import SegmentationResult
from .robust import noise_sigma, OUTLIER_P
from .spatial import spatial_neighbours

#: Largest number of bodies considered by default.
MAX_BODIES = 5
#: A body counts only with at least this many lines, and this fraction of the usable lines.
MIN_BODY_LINES = 4
MIN_BODY_FRACTION = 0.04
#: Pseudo-count per body of a track's label among its neighbours' (:func:`label_cost`:
#: Laplace's rule). Hopkins155 line tracks, three windows of 5 frames per sequence, the true
#: segmentation against one body less and one more, compared as the online count compares
#: them (bench count's score alone): the true count holds in 82 / 64% of the 2 / 3-motion
#: windows with 1, 79 / 62% with 4 ('general'; 71 / 52% with the uniform prior alone),
#: 'robust' 75 / 62%, 73 / 53% (65 / 45%).
LABEL_PRIOR = 1.0


def track_dof(tracks: np.ndarray) -> np.ndarray:
    """Return the equations ``(N,)`` of every track: 2 per pair of consecutive frames seen."""
    ok = np.isfinite(np.asarray(tracks)[..., 0])
    return 2.0 * np.sum(ok[:, :-1] & ok[:, 1:], axis=1)


def min_body_lines(dof: np.ndarray) -> int:
    """Return the fewest tracks a body may hold: ``MIN_BODY_LINES``, or 4% of the usable."""
    return max(MIN_BODY_LINES, int(np.ceil(MIN_BODY_FRACTION * int(np.sum(dof > 0)))))


def _capped_costs(res: SegmentationResult, sigma: Optional[float], dof: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return every usable track's cheapest cost and its outlier bound at noise ``sigma`` (px).

    Both ``(N_usable,)``, px^2; a track no body has a cost for is ``inf``. ``sigma`` None: the
    model's own robust noise estimate.
    """
    # a track no body has a cost for (all NaN, e.g. degenerate for the general model) is not
    # explained: +inf, capped at the outlier bound like any unexplained track
    costs = res.costs[dof > 0]
    best = (np.where(np.isnan(costs), np.inf, costs).min(axis=1) if costs.shape[1]
            else np.full(len(costs), np.inf))
    return best, _outlier_bound(res, sigma, dof)


def _outlier_bound(res: SegmentationResult, sigma: Optional[float], dof: np.ndarray
                   ) -> np.ndarray:
    """Return every usable track's outlier bound ``(N_usable,)`` px^2 at noise ``sigma``."""
    if sigma is None:
        sigma = noise_sigma(res.costs, res.labels, dof)
        sigma = sigma if np.isfinite(sigma) else 1.0
        sigma = max(sigma, 1e-9)
    return chi2_quantile(OUTLIER_P, dof[dof > 0]) * sigma ** 2


def explained(res: SegmentationResult, sigma: Optional[float], dof: np.ndarray) -> np.ndarray:
    """
    Return which body explains which track ``(N, n)`` bool: its cost within the outlier bound.

    The bound of :func:`bic_score` at noise ``sigma`` (px; None: the model's own estimate);
    a cost a body has none for (NaN) and an unusable track explain nothing.
    """
    costs = np.asarray(res.costs, dtype=float)
    out = np.zeros(costs.shape, dtype=bool)
    usable = dof > 0
    if np.any(usable):
        out[usable] = costs[usable] <= _outlier_bound(res, sigma, dof)[:, None]
    return out


def unexplained(res: SegmentationResult, sigma: Optional[float], dof: np.ndarray
                ) -> np.ndarray:
    """
    Return the tracks ``(N,)`` bool that :func:`bic_score` counts at their outlier bound.

    Usable tracks whose cheapest cost at noise ``sigma`` (px; None: the model's own estimate)
    is above the bound, whatever their label (no body :func:`explained` them): a model whose
    segmentation runs at an inflated noise level (``'general'``) keeps such tracks labelled,
    yet they are what one more body would explain.
    """
    return (dof > 0) & ~explained(res, sigma, dof).any(axis=1)


def track_neighbours(tracks: np.ndarray) -> np.ndarray:
    """Return the image neighbours ``(N, k)`` of tracks ``(N, K, 4)`` (:func:`label_cost`)."""
    return spatial_neighbours(first_midpoints(np.asarray(tracks)))


def label_cost(labels: np.ndarray, n: int, usable: np.ndarray,
               neighbours: Optional[np.ndarray] = None) -> float:
    """
    Return minus twice the log-likelihood of the usable tracks' labels (the score's label term).

    ``labels (N,)`` in ``0..n-1`` (``-1`` none), ``usable (N,)`` bool. Without ``neighbours``
    a uniform prior, ``2 log n`` per track. With ``neighbours (N, k)`` (image neighbours,
    ``-1`` none: :func:`track_neighbours`) each track's label is predicted by those of its
    labelled neighbours, ``(a + same) / (a n + labelled)`` with :data:`LABEL_PRIOR` ``a``:
    real bodies are compact in the image, so a segmentation into compact regions costs
    little more than one body (under the uniform prior one body less won in 38% of the
    3-motion windows of Hopkins155 given the true segmentation), while labels mixed among
    their neighbours (the paper's intermixed random lines) cost about ``2 log n`` each, as
    under the uniform prior. An unlabelled track costs ``2 log n``.
    """
    labels = np.asarray(labels)
    usable = np.asarray(usable, dtype=bool)
    if n <= 1 or not usable.any():
        return 0.0
    if neighbours is None or np.asarray(neighbours).shape[1] == 0:
        return 2.0 * float(np.count_nonzero(usable)) * float(np.log(n))
    nb = np.asarray(neighbours)
    theirs = np.where(nb >= 0, labels[nb], -1)
    labelled = np.count_nonzero(theirs >= 0, axis=1)
    same = np.count_nonzero((theirs == labels[:, None]) & (theirs >= 0), axis=1)
    share = np.where(labels >= 0, (LABEL_PRIOR + same) / (LABEL_PRIOR * n + labelled), 1.0 / n)
    return float(-2.0 * np.sum(np.log(share[usable])))


def bic_score(res: SegmentationResult, sigma: Optional[float], dof: np.ndarray,
              neighbours: Optional[np.ndarray] = None) -> float:
    """
    BIC of a segmentation: ``R log(RSS / R) + k n log R + L``.

    ``L`` is minus twice the log-likelihood of the labels (:func:`label_cost`; ``2 N log n``
    without ``neighbours``): with two frames a line has only two equations, and the freedom
    to pick the best of n bodies alone lowers the residual of pure noise by a factor of
    about n.

    ``RSS`` sums every track's cost capped at the outlier bound (at noise ``sigma``, or the
    model's own robust noise estimate when None); ``R`` rows, ``N`` usable tracks; ``k`` the
    parameters of a body's motion (:attr:`.Method.motion_parameters` of ``res.method``: 3,
    6 for ``'general'``, whose bodies also translate); ``neighbours (N, k)``: the tracks'
    image neighbours (:func:`track_neighbours`), None for the uniform label prior.
    """
    n = res.n_bodies
    k = REGISTRY[res.method].motion_parameters if res.method in REGISTRY else 3
    usable = dof > 0
    if not usable.any():
        return np.inf   # nothing to explain: no model is better than another
    best, cap = _capped_costs(res, sigma, dof)
    rss = float(np.sum(np.minimum(best, cap)))
    rows = float(np.sum(dof))
    return (rows * np.log(max(rss, 1e-300) / rows) + k * n * np.log(max(rows, 2.0))
            + label_cost(res.labels, n, usable, neighbours))


def select_bodies(tracks: np.ndarray, intrinsics: Optional[Tuple[float, float, float, float]],
                  image_size: Tuple[float, float], method: Method, *, seed: int = 0,
                  max_bodies: int = MAX_BODIES) -> SegmentationResult:
    """
    Run ``method`` for n = 1..max_bodies and return the result with the best score.

    ``tracks (N, K, 4)``, ``intrinsics`` and ``image_size`` as checked by
    :func:`.segment_lines`; every n is solved cold.
    """
    dof = track_dof(tracks)
    usable = int(np.sum(dof > 0))
    results = []
    for n in range(1, max_bodies + 1):
        if usable < method.min_tracks(n, tracks.shape[1], intrinsics is not None):
            break
        results.append(method.solve(Problem(tracks, n, intrinsics, image_size, seed)))
    if not results:
        raise ValueError(f'{usable} usable tracks: too few to fit even one body')
    # a body must hold a few lines: with 2 frames, 2 lines (4 equations, 3 unknowns) fit any
    # rotation, so tiny "bodies" would soak up the worst-fitting lines of a real one
    min_lines = min_body_lines(dof)
    scores = [bic_score(r, None, dof)
              if np.all(np.bincount(r.labels[r.labels >= 0], minlength=r.n_bodies) >= min_lines)
              or r.n_bodies == 1 else np.inf for r in results]
    best = results[int(np.argmin(scores))]
    return replace(best, diagnostics=replace(
        best.diagnostics, n_bodies_scores=dict(zip(range(1, len(scores) + 1), scores))))
