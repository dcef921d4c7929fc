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
"""``segment_lines``: the public entry point of the solver (checks, then the method's solve)."""
import math
from typing import Any, Dict, Optional, Sequence, Tuple

import numpy as np

from .ksubspaces import assign
from .lines import line_flows, rotvec_to_cayley
from .methods import get_method, Method, METHODS
from .model_selection import select_bodies
from .models import track_costs
from .problem import Problem
from .result import Diagnostics, SegmentationResult
from .robust import Segmentation
from .rotation import finish

__all__ = ['assign_with_motions', 'METHODS', 'min_tracks_needed', 'segment_lines']


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
    """
    Fewest usable tracks (present in two consecutive frames) ``method`` can solve from.

    See :meth:`.Method.min_tracks`.
    """
    return get_method(method).min_tracks(n_bodies, n_frames, focal_known)


def segment_lines(tracks, n_bodies: int, intrinsics: Optional[Sequence[float]] = None,
                  image_size: Optional[Sequence[float]] = None, method: str = 'robust', *,
                  seed: int = 0, init_labels: Optional[np.ndarray] = None,
                  init_motions: Optional[Tuple[np.ndarray, np.ndarray]] = None,
                  rescan: Optional[Sequence[int]] = None, step: Optional[bool] = None,
                  step_only: Optional[bool] = None, warm_inliers: Optional[float] = None,
                  warm_competes: Optional[bool] = None) -> SegmentationResult:
    """
    Segment line tracks into rigid bodies by their rotation (multibody line optical flow).

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
        a translation per body too (K >= 3, :mod:`.general`). What each accepts and needs:
        :mod:`.methods`.
    seed : int
        Seed of the random parts (K-means starts, sampling); results repeat for a seed.

    The warm-start keywords below (the previous window of a stream) are accepted only by the
    methods that use them (:attr:`.Method.keywords`) and only with ``n_bodies >= 1``;
    ``None`` means not given.

    init_labels : (N,) int, optional
        'robust' and 'general': labels from a previous window (``-1`` unknown; ids of bodies
        this model does not have count as unknown), an extra starting point.
    init_motions : ((n, 3), (n, 3)) float, optional
        'general', with ``init_labels``: the previous window's rotation vectors (rad per
        frame) and translations per body
        (:attr:`.SegmentationResult.segmentation_angular_velocities` and
        :attr:`.SegmentationResult.translation_directions` times
        :attr:`.Diagnostics.translation_scales`; a unit direction is accepted, the scale is
        then refit), NaN rows unknown. The bodies are then tracked from them instead of the
        multi-start search (which still runs when too few tracks stay inliers).
    rescan : sequence of int, optional
        'general', with ``init_motions``: bodies (ids in ``[0, n)``) whose tracked motion is
        also refitted from the pivot starts of the multi-start search
        (:func:`.general.pivot_starts`, a turn about a point on the body's ray, at the
        measured noise level, robust line cost), which wins when cheaper
        (:data:`.general_method.RESCAN_MARGIN`). A body tracked in a wrong basin (a wrong
        pivot, the depth-reversed motion) otherwise keeps it window after window. The labels
        follow in the next window.
    step : bool, optional
        'general', with ``init_motions``: when true and every body has a motion, a tracking
        step instead of a solve: a few LM steps of every body from its motion, the tracks
        assigned once, no search (the bodies in ``rescan`` are rescanned;
        :func:`.general_method.solve_general`); the tracked solve runs instead when too few
        tracks stay inliers or many would change body. A stream asks for full solves after
        a search and after a step whose noise jumped (:data:`.warm.FULL_AFTER_SEARCH`).
    step_only : bool, optional
        'general', with ``step``: when true and the step does not hold, raise
        :class:`.StepNotTaken` instead of running the tracked solve (a caller that runs the
        full solves elsewhere: the pipeline's solver lane, :mod:`mlofc_ros.lane`).
    warm_inliers : float, optional
        'robust', with ``init_labels``: the share of the usable tracks that the previous
        labels' final pass must keep as inliers to be returned without a search (default
        :data:`.robust.WARM_INLIERS`, 0.75). A stream may lower it to what the last search
        achieved on scenes the rotation model explains only in part
        (:attr:`.Diagnostics.warm_rejected`, :attr:`.Diagnostics.inlier_share`).
    warm_competes : bool, optional
        'robust', with ``init_labels``: whether a warm start that was not accepted competes
        with the search's candidates, scored at the same noise level (default True: its final
        pass keeps the most inliers on real scenes the rotation model explains in part).
        'general' runs its rotation-only step without it and without a lowered bar
        (:data:`.general_method.ROTATION_STEP`).

    Returns
    -------
    SegmentationResult
        ``labels (N,)``, ``angular_velocities (n, 3)`` rad per frame interval in the camera
        optical frame, ``angular_covariances``, ``focal_length`` (px), ``residuals (N,)``,
        ``diagnostics``. With 'general' (K >= 3) ``angular_velocities`` and their covariances
        are each body's refit for publication (:data:`.general_method.PUBLISH_NOISE_SCALE`),
        ``segmentation_angular_velocities (n, 3)`` the motions the labels were made with, and
        ``translation_directions (n, 3)``: the next window's ``init_motions``.

    Raises
    ------
    ValueError
        Wrong shape, K < 2, non-finite intrinsics, ``n_bodies < 0``, unknown method, a
        keyword the method does not accept, ``init_labels`` of another length than the tracks,
        ``warm_inliers`` outside [0, 1], malformed ``init_motions`` or ``rescan``, or fewer
        usable tracks than the model needs.
    StepNotTaken
        With ``step_only``: the step did not hold.

    """
    spec = get_method(method)
    n = _check_n_bodies(n_bodies)
    arr = _check_tracks(tracks)
    intr, size = _check_intrinsics(intrinsics, image_size)
    given = {key: value for key, value in (('init_labels', init_labels),
                                           ('init_motions', init_motions),
                                           ('rescan', rescan), ('step', step),
                                           ('step_only', step_only),
                                           ('warm_inliers', warm_inliers),
                                           ('warm_competes', warm_competes))
             if value is not None}
    keywords = _check_keywords(spec, n, arr.shape[0], given)
    if n == 0:
        return select_bodies(arr, intr, size, spec, seed=seed)
    _check_enough_tracks(arr, n, spec, intr is not None)
    return spec.solve(Problem(arr, n, intr, size, seed), **keywords)


def _check_n_bodies(n_bodies) -> int:
    if isinstance(n_bodies, bool) or int(n_bodies) != n_bodies:
        raise ValueError(f'n_bodies must be an integer, got {n_bodies!r}')
    n = int(n_bodies)
    if n < 0:
        raise ValueError(f'n_bodies must be >= 0 (0 = automatic), got {n}')
    return n


def _check_enough_tracks(arr: np.ndarray, n: int, spec: Method, focal_known: bool) -> None:
    ok = np.isfinite(arr[..., 0])
    usable = np.count_nonzero((ok[:, :-1] & ok[:, 1:]).any(axis=1))
    need = spec.min_tracks(n, arr.shape[1], focal_known)
    if usable < need:
        raise ValueError(f'{usable} usable tracks (present in two consecutive frames), but '
                         f'{n} bodies with method {spec.name!r} need at least {need}')


def _check_keywords(spec: Method, n: int, n_tracks: int, given: Dict[str, Any]
                    ) -> Dict[str, Any]:
    """
    Check the warm-start keywords ``given`` (not None) for ``spec``; their solver form.

    ``init_labels`` as int64 with unknown ids -1; ``init_motions`` as two float arrays;
    ``rescan`` as an ``(n,)`` bool mask.
    """
    refused = sorted(set(given) - spec.keywords)
    if refused:
        takes = ', '.join(sorted(spec.keywords)) or 'none of them'
        raise ValueError(f'method {spec.name!r} does not take {", ".join(refused)} (it takes '
                         f'{takes})')
    if given and n == 0:
        raise ValueError(f'{", ".join(sorted(given))} need n_bodies >= 1 (n_bodies=0 chooses '
                         'the number of bodies from cold solves)')
    out = dict(given)
    if 'init_labels' in given:
        out['init_labels'] = _check_labels(given['init_labels'], n, n_tracks)
    if 'warm_inliers' in given:
        share = given['warm_inliers']
        if not 0.0 <= share <= 1.0:
            raise ValueError(f'warm_inliers must be a share in [0, 1], got {share!r}')
    if 'init_motions' in given:
        if 'init_labels' not in given:
            raise ValueError('init_motions need init_labels (the tracks of every body)')
        out['init_motions'] = _check_motions(given['init_motions'], n)
    if 'rescan' in given:
        if 'init_motions' not in given:
            raise ValueError('rescan needs init_motions (it refits tracked bodies)')
        out['rescan'] = _check_rescan(given['rescan'], n)
    if 'step' in given:
        if 'init_motions' not in given:
            raise ValueError('step needs init_motions (it advances tracked bodies)')
        out['step'] = bool(given['step'])
    if 'step_only' in given:
        if 'step' not in given:
            raise ValueError('step_only needs step')
        out['step_only'] = bool(given['step_only'])
    return out


def _check_labels(init_labels, n: int, n_tracks: int) -> np.ndarray:
    """``init_labels (N,)`` as int64, ids of bodies this model does not have ``-1``."""
    labels = np.asarray(init_labels)
    if labels.shape != (n_tracks,):
        raise ValueError(f'init_labels must have shape ({n_tracks},) (one per track), '
                         f'got {labels.shape}')
    if labels.size and labels.dtype.kind not in 'iu':
        raise ValueError(f'init_labels must be integers, got dtype {labels.dtype}')
    return np.where((labels >= 0) & (labels < n), labels, -1).astype(np.int64)


def _check_motions(init_motions, n: int) -> Tuple[np.ndarray, np.ndarray]:
    """``(W (n, 3), T (n, 3))`` from ``init_motions``; NaN rows unknown."""
    try:
        w, t = (np.asarray(x, dtype=np.float64) for x in init_motions)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'init_motions must be (W (n, 3), T (n, 3)): {exc}') from None
    if w.shape != (n, 3) or t.shape != (n, 3):
        raise ValueError(f'init_motions must be two ({n}, 3) arrays, got {w.shape}, {t.shape}')
    return w, t


def _check_rescan(rescan, n: int) -> np.ndarray:
    """``(n,)`` bool mask of the bodies ``rescan`` names."""
    ids = np.asarray(rescan).ravel()
    if ids.size and (ids.dtype.kind not in 'iu' or ids.min() < 0 or ids.max() >= n):
        raise ValueError(f'rescan must name bodies in [0, {n}), got {rescan!r}')
    mask = np.zeros(n, dtype=bool)
    mask[ids.astype(np.int64)] = True
    return mask


def assign_with_motions(tracks, angular_velocities, intrinsics: Sequence[float], *,
                        weighted: bool = False) -> SegmentationResult:
    """
    Assign every track with GIVEN (true) motions, no estimation: the floor.

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
    seg = Segmentation(labels, c, track_costs(flows, c, weighted=True), Diagnostics())
    return finish(flows, seg, intr[0], 'floor-weighted' if weighted else 'floor', Diagnostics())
