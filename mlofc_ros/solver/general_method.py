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
Method ``'general'``: a rotation AND a translation per body (the model of :mod:`.general`).

The rotation-only step (:func:`.solve_robust`, as :data:`ROTATION_STEP`) supplies the focal
length when it is unknown and a start (a step with the intrinsics given runs without it); the
bodies are then either stepped from the previous
window's motions (``step``: a few LM steps each, one assignment, :func:`_step`, which returns
at once), tracked from its labels and motions (:func:`.general_warm`, then the marginalised
segmentation) or found by the multi-start search (:func:`.general_search`). After these two,
every body is refit at the measured noise with the robust line cost (:func:`.polish_bodies`;
tracked bodies marked for a rescan are also refit from the pivot starts), and the published
rotation is a further refit at a fraction of that noise (:data:`PUBLISH_NOISE_SCALE`).
"""
from dataclasses import replace
from types import MappingProxyType
from typing import Mapping, NamedTuple, Optional, Tuple

import numpy as np

from .general import (assign_bodies, assign_fitted, background_labels, basin_spread,
                      body_covariances, fit_bodies, fit_bodies_multistart, fit_body,
                      fit_body_multistart, fitted_start, general_search, general_warm,
                      LineObservations, marginal_segmentation, measured_noise,
                      NOISE_FACTOR, polish_bodies, rescale_translations, spatial_labels,
                      WARM_INLIERS)
from .ksubspaces import total_cost
from .problem import Problem
from .result import Diagnostics, SegmentationResult, StepNotTaken
from .rotation import solve_robust
from .spatial import spatial_neighbours

#: How the method runs its rotation-only step: the robust solve without a lowered bar for the
#: warm start and without the warm start competing with the search (both tuned for 'robust'
#: alone): bench live's own3+bg at 10 Hz, whose runs swing by 5-10 points,
#: was 12.6-14.7% wrong in three runs with one or both, against 5.3-7.4% in four without. The
#: pipeline's stand-in for the method's first frames is run the same way
#: (:data:`.methods.ROTATION_STEP`).
ROTATION_STEP: Mapping[str, object] = MappingProxyType({'warm_competes': False})

#: Frames the model needs (the translation is seen from the third on); with fewer the method
#: answers with its rotation-only step.
MODEL_FRAMES = 3

#: LM iterations of the final refit of every body at the measured noise level.
POLISH_ITERATIONS = 10

#: The published rotation of every body is refit (:func:`.polish_body`, robust) at this fraction
#: of the measured noise variance, from the segmentation's motion and on its lines, which keep
#: their labels; the segmentation, the pipeline's body ids and the next window's warm start
#: keep the segmentation's motion. The marginalised model's prior on the line directions pulls
#: W towards a rotation-only fit by ~sigma2 (3.4% of |w| at :data:`.general.NOISE_FACTOR`, ~1%
#: at the measured noise); at a small fraction of it the model tends to the fitted-direction
#: one, unbiased near the right basin, and the robust cost at that scale lets the few
#: mislabelled lines hardly pull. Spinning benchmark (window 10, render seeds 0-5, the same
#: labels), boxes with omega within 5% own2+bg / own3+bg / own3: 7 / 14 / 13 -> 9 / 17 / 18
#: of 12 / 18 / 18, median error 2 / 3 / 2 -> 0 / 1 / 1%, for one more refit per body per
#: frame (docs/design/general.md). None: publish the segmentation's motion.
PUBLISH_NOISE_SCALE: Optional[float] = 0.01

#: A rescanned body (``rescan`` of :func:`.segment_lines`) takes the pivot search's fit
#: whenever it is cheaper than the tracked one by this share of its cost. The final refit of
#: every body and the rescan's pivot search and comparison use the robust (Cauchy) line cost
#: at the measured noise, the warm and segmentation fits least squares (the robust cost in
#: every fit as well measured 4.2 / 9.4 / 6.4 / 8.8 -> 7.8 / 11.9 / 2.7 / 1.5 on an earlier
#: front end: better without a background body and worse with one). Spinning benchmark,
#: window 10, six seeds, mean wrong % own2+bg / own3+bg / own2 / own3, least squares ->
#: robust: 4.6 / 16.9 / 2.1 / 9.8 -> 4.0 / 13.3 / 1.6 / 5.3
#: (margin 0; 3.1 / 17.4 / 1.7 / 7.8 with 0.1, which kept own3+bg seed 4 in a wrong basin,
#: 32% wrong, 13% with none: the robust cost makes a wrong basin only ~10% dearer), cam2+bg
#: 0.09 -> 0.10. The pivot search refines the best start of
#: every rate, not the best four overall (:func:`.general.pivot_picks`): a body fitted as
#: nearly static, its flow explained by a translation, ranks the starts at its true rate low
#: before any LM step (render seeds 0-11, 3.13 / 4.72 / 0.18 / 1.09 -> 2.08 /
#: 4.29 / 0.21 / 0.50, boxes with omega within 5% 106 -> 108 of 120, ~+6-10% CPU per frame;
#: the cold search keeps the global ranking: the best four plus the best of every rate there
#: took the 35 three-motion Hopkins155 sequences from 10.5 to 10.7%).
RESCAN_MARGIN = 0.0

#: Weight of each body's image-position term (:func:`.general.position_costs`, times the
#: noise level) in the warm path's assignment (the pipeline's tracked bodies; the cold search
#: uses :data:`.general.POSITION_WEIGHT`). Spinning benchmark, window 10, mean wrong % own2+bg
#: / own3+bg / own2 / own3 over render seeds 0-5: none 6.5 / 10.6 / 1.6 / 5.2, 0.5 2.8 / 9.8 /
#: 0.7 / 6.0, 1.0 2.3 / 10.5 / 0.4 / 3.0, 2.0 7.6 / 7.5 / 0.1 / 2.5; held-out seeds 6-8:
#: none 3.3 / 9.1 / 0.4 / 3.9, 1.0 3.4 / 3.8 / 0.0 / 0.5; cam2+bg 0.10 -> 0.07.
WARM_POSITION_WEIGHT = 1.0


#: LM iterations of every body's motion in a tracking step (:func:`_step`).
STEP_ITERATIONS = 2

#: A step that moves more than this share of the labelled tracks to another body is not
#: taken (the tracked solve runs): bodies do not trade many tracks from one frame to the next.
STEP_MOVES = 0.1

#: A tracked solve also starts from the background start (:func:`_track`) when it moves
#: more than this share of the labelled tracks to another body: a regrouping the warm starts
#: cannot reach. On bench spinning's own3+bg the start moved 2-8% of the tracks in most
#: windows of runs whose bodies were right (37-45% in a few: the boxes clustered otherwise),
#: 18-57% in a run that had a box split over the background and another body.
REGROUPED = 0.1

#: LM iterations of the pivot search of a body rescanned in a tracking step.
RESCAN_ITERATIONS = 10

#: A body without a motion (new) is fitted in a tracking step from the pivot starts when it
#: holds at least this many usable tracks (else the tracked solve finds it).
NEW_BODY_LINES = 6


class _Tracked(NamedTuple):
    """The warm path's segmentation and the noise level its LM refit measured."""

    solution: dict
    refit_sigma2: float


def solve_general(problem: Problem, init_labels: Optional[np.ndarray] = None,
                  init_motions: Optional[Tuple[np.ndarray, np.ndarray]] = None,
                  rescan: Optional[np.ndarray] = None, step: bool = False,
                  step_only: bool = False) -> SegmentationResult:
    """
    Solve ``problem`` with a rotation and a translation per body.

    ``init_labels (N,)``: the previous window's labels (``-1`` unknown, ids below n);
    ``init_motions``: its motions ``(W (n, 3), T (n, 3))``, NaN rows unknown; ``rescan (n,)``
    bool: the tracked bodies to refit from the pivot starts too. ``step``: a tracking step
    (:func:`_step`); the tracked solve where it does not hold, or with ``step_only``
    :class:`.StepNotTaken`. With fewer than :data:`MODEL_FRAMES` frames the rotation-only
    step answers.
    """
    enough = problem.tracks.shape[1] >= MODEL_FRAMES
    warm = init_labels is not None and init_motions is not None
    stepping = step and warm and enough
    if stepping and problem.intrinsics is not None:
        # with the intrinsics given a step needs no rotation-only solve (about 9% of its CPU)
        fx, fy, cx, cy = problem.intrinsics
        obs = LineObservations(problem.tracks, problem.intrinsics)
        given = Diagnostics(principal_point=(cx, cy), aspect=fy / fx,
                            image_size=problem.image_size)
        stepped, motions = _step(obs, given, fx, init_labels, init_motions,
                                 spatial_neighbours(obs.midpoints), rescan)
        if stepped is not None:
            return stepped
        if step_only:
            raise StepNotTaken('the tracked bodies no longer explain the window', motions)
    rot = solve_robust(problem, init_labels=init_labels, **ROTATION_STEP)
    if not enough:
        note = f'window has fewer than {MODEL_FRAMES} frames: rotation-only result'
        return replace(rot, method='general', diagnostics=replace(rot.diagnostics, note=note))
    d = rot.diagnostics
    f = rot.focal_length
    obs = LineObservations(problem.tracks, (f, f * d.aspect) + tuple(d.principal_point))
    neighbours = spatial_neighbours(obs.midpoints)
    tracked = None
    if stepping and problem.intrinsics is None:     # the focal length from the solve above
        stepped, motions = _step(obs, d, f, init_labels, init_motions, neighbours, rescan)
        if stepped is not None:
            return stepped
        if step_only:
            raise StepNotTaken('the tracked bodies no longer explain the window', motions)
    if warm:
        tracked = _track(obs, rot, init_labels, init_motions, neighbours,
                         np.random.default_rng(problem.seed))
    if tracked is None:
        sol = _search(obs, rot, init_labels, neighbours, np.random.default_rng(problem.seed))
        sigma2 = sol['sigma2'] / NOISE_FACTOR
    else:
        sol = tracked.solution
        # the labels need the inflated noise level (NOISE_FACTOR); the motions are refit on
        # them at the measured one, where the prior on the line directions biases them less
        # (about 2% of |w| at x8 on noise-free spinning bodies, 0.2% at x1)
        sigma2 = min(sol['sigma2'] / NOISE_FACTOR, tracked.refit_sigma2)
    if tracked is None or rescan is None:
        rescan = np.zeros(rot.n_bodies, dtype=bool)    # only tracked bodies are rescanned
    _refit_bodies(obs, sol, sigma2, rescan)
    return _result(obs, d, f, sol, sigma2)


def _track(obs: LineObservations, rot: SegmentationResult, init_labels: np.ndarray,
           init_motions: Tuple[np.ndarray, np.ndarray], neighbours: np.ndarray,
           rng: np.random.Generator) -> Optional[_Tracked]:
    """
    Track the previous window's bodies; None when they no longer explain the window.

    The lines are assigned at the previous motions as they are (a few LM steps on the flat
    fitted-direction model moved a body with few lines into another basin: own2+bg s2, frame
    212, 137 -> 28 deg/s about y; it lost its lines to a neighbour and the ids came back
    permuted 20 frames later; render seeds 0-2 over 300 frames, own2+bg / own3+bg
    11.6 / 28.0 -> 1.2 / 3.2% wrong), and the marginalised segmentation starts from them.
    Starts: the previous labels where the tracks had one (the assignment for the others), and
    every track assigned at the previous motions; the lower score is kept (the
    fitted-direction costs carry little first-order information at short windows and right
    groupings fell apart in the next windows, Hopkins155 streamed 23.3 -> 10.6%; the
    reassigned start repairs groupings a wrong first search left: spinning seeds 0-11, wrong %
    own2+bg / own3+bg / own2 / own3 3.6 / 5.3 / 0.2 / 2.0 -> 1.6 / 3.9 / 0.2 / 1.2, +12-25%
    CPU per frame). Each body is a blob in the image too (:data:`WARM_POSITION_WEIGHT`). The
    LM refit from the previous motions still measures the noise of the final refit and the
    rescan when it fits better: at a motion from a wrong basin the noise would be inflated and
    the rescan could not leave it. A third start, the search's background start with its
    bodies fitted as rescans (:func:`.general.fitted_start`), competes when it regroups more
    than :data:`REGROUPED` of the labelled tracks and every body has a motion: both warm
    starts keep a box whose lines the previous bodies split (half on the background, half
    on a body fitted as nearly still), and its rescans, on lines a quarter of which are the
    wall's, keep that body's wrong basin (bench degraded's sharp own3+bg, render seed 3: a
    box 103% off to the end of the run, 19.7% of the segments wrong; with the start 1.5%,
    every box within 1% of its omega from frame 17).
    """
    w0, t0 = init_motions
    known = np.all(np.isfinite(w0), axis=1) & np.all(np.isfinite(t0), axis=1)
    if not np.any(known):
        return None
    w_start = np.where(known[:, None], w0, rot.angular_velocities)
    t_start = np.where(known[:, None], t0, 0.0)
    warm = general_warm(obs, init_labels, w_start, t_start, known, iterations=0)
    if warm['inliers'] < WARM_INLIERS:
        return None
    refit_sigma2 = general_warm(obs, init_labels, w_start, t_start, known)['sigma2']
    W = np.where(known[:, None], w0, warm['W'])
    T = np.where(known[:, None], t0, warm['T'])
    prev = np.asarray(init_labels)
    starts = [('warm', np.where(prev >= 0, prev, warm['labels'])), ('warm', warm['labels'])]
    # the search's background start, numbered as the previous bodies, when it regroups the
    # tracks (the warm starts cannot): a box whose lines the previous bodies split comes back
    # whole; its bodies fitted as rescans. Not for a body without a motion (the automatic
    # count's trial of one more body is a regrouping of its own: with the start beside it the
    # count's stream of 'general' stayed at one body)
    if np.all(known):
        candidates = np.concatenate([np.zeros((1, 3)), w0])
        background = background_labels(obs, rot.n_bodies, candidates, warm['sigma2'], rng)
        background = _numbered_after(background, prev, rot.n_bodies)[background]
        both = (prev >= 0) & (obs.frames >= MODEL_FRAMES)
        if np.count_nonzero(background[both] != prev[both]) > REGROUPED * np.count_nonzero(both):
            starts.append(('warm', background) + fitted_start(
                obs, background, rot.n_bodies, warm['sigma2'], NOISE_FACTOR * warm['sigma2'],
                RESCAN_ITERATIONS))
    sol = marginal_segmentation(obs, rot.n_bodies, starts, W, T, NOISE_FACTOR * warm['sigma2'],
                                rounds=2, iterations=4, neighbours=neighbours, keep=1,
                                first_iterations=4, pivots=False, points=obs.midpoints,
                                position_weight=WARM_POSITION_WEIGHT)
    return _Tracked(sol, refit_sigma2)


def _numbered_after(labels: np.ndarray, prev: np.ndarray, n: int) -> np.ndarray:
    """
    Return the body ``(n,)`` in ``prev`` each body of ``labels`` shares most tracks with.

    ``labels``, ``prev (N,)``: bodies ``0..n-1`` (``-1`` none). Greedy, the largest overlap
    first; a permutation of ``0..n-1`` (bodies that share no tracks take the ids left), so
    that a start from other labels keeps the previous window's body numbers.
    """
    both = (labels >= 0) & (prev >= 0)
    overlap = np.zeros((n, n))
    np.add.at(overlap, (labels[both], prev[both]), 1.0)
    order = np.full(n, -1)
    for _ in range(n):                                               # bodies, not lines
        i, j = np.unravel_index(int(np.argmax(overlap)), overlap.shape)
        order[i] = j
        overlap[i, :], overlap[:, j] = -1.0, -1.0
    return order


def _step(obs: LineObservations, diagnostics: Diagnostics, focal_length: float,
          init_labels: np.ndarray, init_motions: Tuple[np.ndarray, np.ndarray],
          neighbours: np.ndarray, rescan: Optional[np.ndarray] = None
          ) -> Tuple[Optional[SegmentationResult], Optional[Tuple[np.ndarray, np.ndarray]]]:
    """
    Advance the previous window's bodies by one frame; the result (None: they no longer hold).

    Returned with the stepped motions ``(W, T)`` (None when it fitted none): those of a step
    that did not hold go with :class:`.StepNotTaken`.

    ``diagnostics``, ``focal_length``: the camera's (the rotation-only solve's, or the given
    intrinsics'), which the result reports (:func:`_result`).

    New tracks take the body their fitted-direction cost prefers at the previous motions;
    every body's motion ``(w, T)``, T with its scale, then takes :data:`STEP_ITERATIONS` LM
    steps on its tracks from the previous one, at the published noise level
    (:data:`PUBLISH_NOISE_SCALE` of the measured one, robust cost), so that the state a
    stream carries is the unbiased motion the full solve publishes (steps at the inflated
    segmentation noise drifted towards rotation-only: 5-29% wrong, boxes 40-100% off);
    bodies marked in ``rescan`` are also refit from the pivot starts (:func:`_rescanned`), and
    a body without a motion (a new one: the automatic count's trial of one more body, its
    tracks labelled) starts from them instead of a tracked solve (bench count's ``general``
    stream, six seeds: the same counts frame by frame, its CPU 2.0 -> 1.8x the count
    given's on the mean).
    Every track is then assigned once at the segmentation's inflated noise with the
    image-position term, each body's T rescaled to that noise first
    (:func:`.general.rescale_translation`: its scale is nearly free at the published noise,
    and a translating body's lines went to the background, visp_cube 16% of the moving-phase
    frames right instead of 91%); the published motions are the stepped ones. No search: the
    pipeline's schedule (:mod:`.warm`) asks for full solves. None (the caller runs the
    tracked solve) when no body has a motion or one without holds fewer than
    :data:`NEW_BODY_LINES` usable tracks, fewer than :data:`.general.WARM_INLIERS` of
    the usable tracks stay inliers, or more than :data:`STEP_MOVES` of the labelled tracks
    would change body.
    """
    w0, t0 = init_motions
    known = np.all(np.isfinite(w0), axis=1) & np.all(np.isfinite(t0), axis=1)
    prev = np.asarray(init_labels)
    usable = obs.frames >= MODEL_FRAMES
    new = np.flatnonzero(~known)
    if (not np.any(known)
            or any(np.count_nonzero(usable & (prev == b)) < NEW_BODY_LINES for b in new)):
        return None, None
    n = w0.shape[0]
    nearest, sigma2 = assign_fitted(obs, w0[known], t0[known])
    assigned = np.where(nearest >= 0, np.flatnonzero(known)[nearest], -1)
    start = np.where(prev >= 0, prev, assigned)
    fine = sigma2 * PUBLISH_NOISE_SCALE
    W, T = np.array(w0, dtype=float), np.array(t0, dtype=float)
    members = [np.flatnonzero(start == b) for b in range(n)]       # bodies, not lines
    if new.size:
        # a body without a motion (a new one: the count's trial of one more) from the pivot
        # starts on its tracks, as a rescan; the LM steps below refine it with the others
        W[new], T[new], _ = fit_bodies_multistart(
            obs, [members[b] for b in new], np.zeros((new.size, 3)), np.zeros((new.size, 3)),
            RESCAN_ITERATIONS, 1, sigma2, robust=sigma2, per_rate=True)
    moved = [b for b in range(n) if members[b].size >= 3]
    if moved:                       # every body's LM steps in one lockstep batch
        W[moved], T[moved], _ = fit_bodies(obs, [members[b] for b in moved], W[moved],
                                           T[moved], STEP_ITERATIONS, fine, fine)
    spreads = np.full((n, 3, 3), np.nan)
    for b in moved:                                                  # bodies, not lines
        if rescan is not None and rescan[b]:
            W[b], T[b], spreads[b] = _rescanned(obs, members[b], W[b], T[b], sigma2)
    fitted: list = []
    sigma2 = measured_noise(obs, W, T, fitted)
    # the labels at the segmentation's inflated noise level, where T's scale matters: the
    # stepped T rescaled there (W held: the state stays the published motion)
    T_labels = T.copy()
    if moved:
        T_labels[moved] = rescale_translations(obs, [members[b] for b in moved], W[moved],
                                               T[moved], NOISE_FACTOR * sigma2)
    labels, costs, total, cap = assign_bodies(obs, W, T_labels, NOISE_FACTOR * sigma2, start,
                                              neighbours=neighbours, points=obs.midpoints,
                                              position_weight=WARM_POSITION_WEIGHT)
    if not np.any(usable) or np.mean(labels[usable] >= 0) < WARM_INLIERS:
        return None, (W, T)
    held = usable & (prev >= 0) & (labels >= 0)
    if np.count_nonzero(held & (labels != prev)) > STEP_MOVES * max(np.count_nonzero(held), 1):
        return None, (W, T)
    sol = {'labels': labels, 'W': W, 'T': T, 'costs': costs, 'sigma2': NOISE_FACTOR * sigma2,
           'start': 'step', 'score': total_cost(total, labels, cap), 'spreads': spreads}
    return _result(obs, diagnostics, focal_length, sol, sigma2, 0, fitted[0]), (W, T)


def _rescanned(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
               sigma2: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return a stepped body's motion, or the pivot search's when that fits its tracks better.

    As the full solve's rescan (:func:`_refit_bodies`): compared on the robust cost at the
    measured noise ``sigma2``; the winner is refit at the published noise level. Returned
    with the covariance term ``(3, 3)`` of the other minima the search ran into
    (:func:`_spread`).
    """
    fine = sigma2 * PUBLISH_NOISE_SCALE
    here = fit_body(obs, idx, w, t, 0, sigma2, sigma2)[2]
    runs: list = []
    alt = fit_body_multistart(obs, idx, w, t, RESCAN_ITERATIONS, 1, sigma2, obs.body_ray(idx),
                              robust=sigma2, per_rate=True, runs=runs)
    if not alt[2] < (1.0 - RESCAN_MARGIN) * here:
        return w, t, _spread(obs, idx, runs[0], (w, here), (w, here), sigma2)
    w_new, t_new = fit_body(obs, idx, alt[0], alt[1], STEP_ITERATIONS, fine, fine)[:2]
    return w_new, t_new, _spread(obs, idx, runs[0], (w, here), (alt[0], alt[2]), sigma2)


def _spread(obs: LineObservations, idx: np.ndarray, runs: Tuple[np.ndarray, np.ndarray],
            start: Tuple[np.ndarray, float], kept: Tuple[np.ndarray, float], sigma2: float
            ) -> np.ndarray:
    """
    Return :func:`.general.basin_spread` of a rescanned body on the tracks ``idx``.

    ``runs``: the rescan's ``(W (R, 3), costs (R,))``; ``start``: the fit it started from,
    ``(w, cost)``, one more run; ``kept``: the fit the body keeps, ``(w, cost)``; all at the
    measured noise ``sigma2``. The tracks give the frame pairs (their median).
    """
    W_runs = np.concatenate([runs[0], np.asarray(start[0], dtype=float)[None]])
    costs = np.concatenate([runs[1], [start[1]]])
    pairs = float(np.median(np.maximum(obs.frames[idx] - 1, 1)))
    return basin_spread(W_runs, costs, kept[0], kept[1], sigma2, pairs)


def _search(obs: LineObservations, rot: SegmentationResult, init_labels: Optional[np.ndarray],
            neighbours: np.ndarray, rng: np.random.Generator) -> dict:
    """
    Find the bodies by the multi-start search.

    Starts: the previous labels (when given), the rotation-only labels, a spatial clustering
    and the background start (:func:`.general.search.background_labels`).
    """
    n = rot.n_bodies
    starts = [('rotation-only', rot.labels), ('spatial', spatial_labels(obs.midpoints, n, rng))]
    if init_labels is not None:
        starts.insert(0, ('previous', np.asarray(init_labels)))
    return general_search(obs, n, starts, rot.labels, rot.angular_velocities, neighbours,
                          points=obs.midpoints, rng=rng)


def _refit_bodies(obs: LineObservations, sol: dict, sigma2: float, rescan: np.ndarray) -> None:
    """
    Refit every body of ``sol`` in place at the measured noise ``sigma2`` (robust cost).

    A body marked in ``rescan`` (tracked: it took only a few LM steps from the previous
    window's motion, so a wrong basin -- a pivot, the depth reversal -- would stay window after
    window) is also refit from the full search's pivot starts, compared at the measured noise
    (the inflated one flattens the cost and often prefers a wrong basin), and keeps the
    cheaper fit (:data:`RESCAN_MARGIN`); ``sol['spreads'] (n, 3, 3)`` takes the covariance
    term of the other minima it ran into (:func:`_spread`; NaN for the bodies not rescanned).
    """
    labels = sol['labels']
    sol['spreads'] = np.full((sol['W'].shape[0], 3, 3), np.nan)
    members = [np.flatnonzero(labels == b) for b in range(sol['W'].shape[0])]
    some = [b for b, idx in enumerate(members) if idx.size >= 3]    # bodies, not lines
    if not some:
        return
    W, T, cost = polish_bodies(obs, [members[b] for b in some], sol['W'][some],
                               sol['T'][some], POLISH_ITERATIONS, sigma2, sigma2)
    again = [i for i, b in enumerate(some) if rescan[b]]
    if again:
        runs: list = []
        alt = fit_bodies_multistart(obs, [members[some[i]] for i in again], W[again],
                                    T[again], POLISH_ITERATIONS, 1, sigma2, robust=sigma2,
                                    per_rate=True, runs=runs)
        take = alt[2] < (1.0 - RESCAN_MARGIN) * cost[again]
        for j, i in enumerate(again):                                # bodies, not lines
            # the polished fit is one more run; the body keeps the cheaper of the two
            kept = (alt[0][j], alt[2][j]) if take[j] else (W[i], cost[i])
            sol['spreads'][some[i]] = _spread(obs, members[some[i]], runs[j], (W[i], cost[i]),
                                              kept, sigma2)
        keep = np.asarray(again)[take]
        W[keep], T[keep] = alt[0][take], alt[1][take]
    sol['W'][some], sol['T'][some] = W, T


def _result(obs: LineObservations, diagnostics: Diagnostics, focal_length: float, sol: dict,
            sigma2: float, iterations: int = POLISH_ITERATIONS,
            fitted: Optional[np.ndarray] = None) -> SegmentationResult:
    """
    Make the method's result: published motions and covariances, residuals, diagnostics.

    ``diagnostics``: the rotation-only solve's (or the camera's alone), which the result's
    extend; ``focal_length`` (px) the solve's. ``fitted (N, n)``: the fitted-direction costs
    at the motions of ``sol`` if known.
    """
    labels = sol['labels']
    W_pub, cov, noise_cov = _published(obs, labels, sol['W'], sol['T'], sigma2, iterations,
                                       fitted)
    spreads = sol.get('spreads')
    if spreads is not None:
        # the other minima a rescan found widen the covariance towards them
        cov = cov + np.nan_to_num(spreads, nan=0.0)
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    scale = np.linalg.norm(sol['T'], axis=1)
    with np.errstate(invalid='ignore', divide='ignore'):
        best = sol['costs'][np.arange(labels.shape[0]),
                            np.where(labels >= 0, labels,
                                     np.argmin(np.nan_to_num(sol['costs'], nan=np.inf), 1))]
        rms = np.where(dof > 0, np.sqrt(best / dof), np.nan)
        directions = np.where(scale[:, None] > 0, sol['T'] / scale[:, None], 0.0)
    diagnostics = replace(diagnostics, sigma_px=float(np.sqrt(sigma2)), start=sol['start'],
                          score=float(sol['score']), translation_scales=scale)
    return SegmentationResult(labels=labels, angular_velocities=W_pub, angular_covariances=cov,
                              focal_length=focal_length, residuals=rms, costs=sol['costs'],
                              method='general', segmentation_angular_velocities=sol['W'],
                              translation_directions=directions, basin_spreads=spreads,
                              noise_covariances=noise_cov, diagnostics=diagnostics)


def _published(obs: LineObservations, labels: np.ndarray, W: np.ndarray, T: np.ndarray,
               sigma2: float, iterations: int, fitted: Optional[np.ndarray] = None
               ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return the published rotation vectors ``(n, 3)`` and two covariances ``(n, 3, 3)`` each.

    The covariances: the published ones, and those of the noise alone (without the
    model-error scale: :attr:`.SegmentationResult.noise_covariances`).

    Each body's refit (:func:`published_motions`); a body whose refit has no finite covariance
    publishes the segmentation's motion ``W`` (nor would it decide, through the pipeline's
    validity, which bodies are tracked). ``fitted (N, n)``: the fitted-direction costs at
    ``(W, T)`` if known (used for the bodies that are not refit). ``iterations`` 0: ``W, T``
    are a step's, fitted at the published noise level already.

    Each covariance is the information of the cost its motion minimises (at
    :data:`PUBLISH_NOISE_SCALE` of ``sigma2`` for a refit or a step; at ``sigma2`` for a body
    that keeps the segmentation's motion) at the noise ``sigma2``
    (:func:`.general.body_covariances`, ``fitted_at``).
    """
    W_pub, T_pub = published_motions(obs, labels, W, T, sigma2, iterations)
    n = W.shape[0]
    members = [np.flatnonzero(labels == b) for b in range(n)]          # bodies, not lines
    same = np.all(W_pub == W, axis=1) & np.all(T_pub == T, axis=1)
    known = ([fitted[idx, b] for b, idx in enumerate(members)]
             if fitted is not None and np.all(same) else None)
    fine = (np.ones(n, dtype=bool) if iterations == 0 and PUBLISH_NOISE_SCALE is not None
            else ~same)
    cov, scales = np.full((n, 3, 3), np.inf), np.ones(n)
    for at_fine in (True, False):
        some = np.flatnonzero(fine == at_fine)
        if some.size:
            out: list = []
            cov[some] = body_covariances(
                obs, [members[b] for b in some], W_pub[some], T_pub[some], sigma2,
                marginal=True, fitted=None if known is None else [known[b] for b in some],
                fitted_at=sigma2 * PUBLISH_NOISE_SCALE if at_fine else None, scales_out=out)
            scales[some] = out[0]
    back = [b for b in range(n)
            if not np.all(np.isfinite(cov[b])) and not np.array_equal(W_pub[b], W[b])]
    if back:
        W_pub[back], T_pub[back] = W[back], T[back]
        out = []
        cov[back] = body_covariances(obs, [members[b] for b in back], W[back], T[back],
                                     sigma2, marginal=True, scales_out=out)
        scales[back] = out[0]
    return W_pub, cov, cov / scales[:, None, None]


def published_motions(obs: LineObservations, labels: np.ndarray, W: np.ndarray,
                      T: np.ndarray, sigma2: float, iterations: int = POLISH_ITERATIONS
                      ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the motions ``(W (n, 3), T (n, 3))`` that the method publishes.

    Each body's refit from ``W, T`` (the segmentation's, at noise ``sigma2`` px^2) on its
    ``labels`` at :data:`PUBLISH_NOISE_SCALE` of that noise; bodies with fewer than 3 lines
    or a non-finite refit, or all of them when it is None, keep ``W, T``.
    """
    W_pub, T_pub = W.copy(), T.copy()
    if PUBLISH_NOISE_SCALE is None or iterations == 0:
        return W_pub, T_pub
    s2 = sigma2 * PUBLISH_NOISE_SCALE
    members = [np.flatnonzero(labels == b) for b in range(W.shape[0])]
    some = [b for b, idx in enumerate(members) if idx.size >= 3]    # bodies, not lines
    if not some:
        return W_pub, T_pub
    w, t, _ = polish_bodies(obs, [members[b] for b in some], W[some], T[some], iterations,
                            s2, s2)
    ok = np.all(np.isfinite(w), axis=1) & np.all(np.isfinite(t), axis=1)
    done = np.asarray(some)[ok]
    W_pub[done], T_pub[done] = w[ok], t[ok]
    return W_pub, T_pub
