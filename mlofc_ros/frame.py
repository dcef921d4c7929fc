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
One frame through the pipeline: what ``observe`` hands to ``solve``, and what ``solve`` returns.

:class:`Observation` is a frame tracked and added to the window; :class:`FrameResult` the
frame's segments with their labels and the bodies' motions. Also the checks of a caller's line
tracks and the per-segment helpers both sides use.
"""
import dataclasses
from dataclasses import dataclass, field
import math
from typing import Any, Dict, FrozenSet, List, Optional, Tuple

import numpy as np

from .solver.focal import FOCAL_OBSERVABLE

#: Keys of :attr:`FrameResult.timings` (milliseconds; ``detect``: the line detector alone, 0
#: in the frames it does not run, part of ``detect_track``).
TIMING_KEYS = ('detect_track', 'detect', 'undistort', 'window', 'solve', 'total')


@dataclass
class FrameResult:
    """
    What :meth:`Pipeline.process` returns for one frame.

    Attributes
    ----------
    stamp : float
        The frame's stamp, seconds.
    segments : (M, 4) float32
        Segments of this frame, ``(x1, y1, x2, y2)`` pixels as detected in the (distorted) image.
    track_ids : (M,) uint32
        Track id of every segment.
    labels : (M,) int32
        Stable body id of every segment, ``-1`` unassigned (new track, outlier, or no solve).
        A track the solver leaves unassigned in this window keeps the id it was last assigned
        for up to ``label_memory`` frames (see :attr:`carried`).
    residuals : (M,) float32
        Residual of every segment's track under its body (solver units, pixels-equivalent);
        NaN when not solved.
    angular_velocities : (n, 3) float64
        Angular velocity of every stable body relative to the camera, rad/s, camera optical frame
        (x right, y down, z forward); rad per frame divided by the window's median frame interval.
    angular_covariances : (n, 3, 3) float64
        Their covariances, (rad/s)^2; ``inf`` diagonal when undetermined.
    body_valid : (n,) bool
        True when the body's angular velocity and covariance are finite (solved this frame)
        from at least ``MIN_BODY_TRACKS`` tracks of the window, and published: not where the
        rotation model misfits the body's tracks (:func:`~mlofc_ros.method_choice.misfit_bodies`).
    timings : dict
        Milliseconds per stage: ``detect_track``, ``undistort``, ``window``, ``solve``, ``total``.
    window_fill : int
        Frames in the window (``1..window``).
    problem : str or None
        Why this frame gave no (or a degraded) result, for a warning; None when all went well.
    focal_length : float
        Focal length (px) the solver used or estimated; NaN when it did not run.
    focal_log_sigma : float
        Standard deviation of ``ln focal_length`` (about its relative error): 0 when given
        (camera_info, ``focal_length`` parameter), the running estimate's when estimated
        (at most :data:`~mlofc_ros.solver.focal.FOCAL_PRIOR_LOG_SIGMA`), NaN when the solver
        did not run. The angular covariances include it.
    frame_interval : float
        Median frame interval of the window (s); NaN with fewer than two frames.
    n_tracks : int
        Tracks handed to the solver.
    skipped : bool
        True when the frame was not processed at all (duplicate stamp): nothing to publish.
    carried : (M,) bool
        True where the label was carried over from an earlier window, not given by this solve.
    from_running_fit : bool
        True when the frame was answered from the running fit (:meth:`.Pipeline.carry`)
        instead of a solve: every label carried, no body valid.
    body_solved : (n,) bool
        True when the body was solved this frame from at least ``MIN_BODY_TRACKS`` tracks of
        the window, its twist published or not (the bodies of the frame); empty where not
        known (:attr:`solved` then reads :attr:`body_valid`).
    rays : (M, 3) float32
        Viewing ray through every segment's midpoint at unit depth ``(x, y, 1)``, camera optical
        frame, from the undistorted segment and the intrinsics of this frame (the camera's, the
        ``focal_length`` parameter, or the estimated focal length with the principal point at
        the image centre); NaN while the focal length is not known.

    """

    stamp: float
    segments: np.ndarray
    track_ids: np.ndarray
    labels: np.ndarray
    residuals: np.ndarray
    angular_velocities: np.ndarray
    angular_covariances: np.ndarray
    body_valid: np.ndarray
    timings: Dict[str, float] = field(default_factory=dict)
    window_fill: int = 0
    problem: Optional[str] = None
    focal_length: float = math.nan
    focal_log_sigma: float = math.nan
    frame_interval: float = math.nan
    n_tracks: int = 0
    skipped: bool = False
    carried: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    from_running_fit: bool = False
    rays: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.float32))
    body_solved: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def solved(self) -> bool:
        """Return whether at least one body was solved this frame."""
        return bool(np.any(self.body_solved if self.body_solved.size else self.body_valid))

    @property
    def focal_observable(self) -> bool:
        """Return whether the focal length is known within 10% (given, or estimated so)."""
        return bool(self.focal_log_sigma <= FOCAL_OBSERVABLE)


@dataclass
class Observation:
    """
    One frame tracked and added to the window, not yet solved (:meth:`Pipeline.observe`).

    Attributes
    ----------
    stamp : float
        The frame's stamp, seconds.
    gray : (H, W) uint8 or None
        The image (for a debug drawing); None for line tracks (:meth:`Pipeline.observe_lines`).
    segments : (M, 4) float32
        Segments of this frame, pixels as detected (distorted).
    track_ids : (M,) uint32
        Their track ids.
    win_ids : (N,) int64
        Ids of the tracks of the window handed to the solver.
    win_tracks : (N, K, 4) float64
        Their endpoints over the window (undistorted) px, NaN where a track was not seen.
    intrinsics : (fx, fy, cx, cy) or None
        Solver intrinsics, px; None = estimate the focal length.
    focal_log_sigma : float
        Standard deviation of ``ln fx`` of ``intrinsics``: 0 when given (camera, parameter),
        the running estimate's when estimated, NaN when ``intrinsics`` is None.
    image_size : (width, height)
        Pixels.
    window_fill : int
        Frames in the window (K).
    frame_interval : float
        Median frame interval of the window, s (NaN with one frame).
    blank : bool
        The image had no contrast (no lines, nothing to solve).
    problems : list of str
        What went wrong so far (reported with the result).
    timings : dict
        Milliseconds of ``detect_track``, ``undistort``, ``window``.
    resets : frozenset of str
        Solve-side state to reset before solving: ``'tracks'`` (the tracker restarted and
        reuses ids), ``'bodies'`` (body ids restart), ``'focal'`` (forget the focal estimate).
    elapsed_ms : float
        Milliseconds :meth:`Pipeline.observe` took.
    skipped : bool
        The frame was not processed (duplicate stamp): nothing to solve or publish.
    undistorted : (M, 4) float64 or None
        ``segments`` undistorted (None: the same as ``segments``, no distortion).
    epoch : int
        Restarts of the track ids or body ids before this frame (observing side): labels of
        a solve in another epoch do not apply to this frame's tracks.

    """

    stamp: float
    gray: Optional[np.ndarray]
    segments: np.ndarray
    track_ids: np.ndarray
    win_ids: np.ndarray
    win_tracks: np.ndarray
    intrinsics: Optional[Tuple[float, float, float, float]]
    image_size: Tuple[int, int]
    window_fill: int
    frame_interval: float
    blank: bool
    problems: List[str]
    timings: Dict[str, float]
    resets: FrozenSet[str] = frozenset()
    elapsed_ms: float = 0.0
    skipped: bool = False
    undistorted: Optional[np.ndarray] = None
    epoch: int = 0
    focal_log_sigma: float = 0.0

    @classmethod
    def skip(cls, stamp: float, gray: Optional[np.ndarray], problem: str, fill: int
             ) -> 'Observation':
        """Make the observation of a frame not processed (``problem`` says why), no resets."""
        return cls(stamp, gray, np.zeros((0, 4), np.float32), np.zeros(0, np.uint32),
                   np.zeros(0, np.int64), np.zeros((0, 0, 4)), None, (0, 0), fill, math.nan,
                   False, [problem], {}, skipped=True)

    def replacing(self, older: 'Observation') -> 'Observation':
        """
        Return this observation with the resets and problems of ``older`` (dropped unsolved).

        A solve-side reset (a restart of the tracker, a bag loop) must not be lost with the
        observation that carried it.
        """
        problems = list(dict.fromkeys(older.problems + self.problems))
        return dataclasses.replace(self, resets=self.resets | older.resets, problems=problems)


def segment_rays(segments: np.ndarray,
                 intrinsics: Optional[Tuple[float, float, float, float]]) -> np.ndarray:
    """
    Return the viewing ray ``(x, y, 1)`` through every segment's midpoint, ``(M, 3)`` float32.

    ``segments`` are ``(M, 4)`` undistorted pixels, ``intrinsics`` ``(fx, fy, cx, cy)``; the
    rays are NaN when ``intrinsics`` is None (the focal length is not known).
    """
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    rays = np.full((len(seg), 3), np.nan, dtype=np.float32)
    if intrinsics is None or not len(seg):
        return rays
    fx, fy, cx, cy = intrinsics
    rays[:, 0] = (0.5 * (seg[:, 0] + seg[:, 2]) - cx) / fx
    rays[:, 1] = (0.5 * (seg[:, 1] + seg[:, 3]) - cy) / fy
    rays[:, 2] = 1.0
    return rays


def invalid_bodies(n: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``n`` undetermined bodies: NaN rotations, infinite covariances, not valid."""
    cov = np.zeros((n, 3, 3))
    idx = np.arange(3)
    cov[:, idx, idx] = math.inf
    return np.full((n, 3), np.nan), cov, np.zeros(n, dtype=bool)


def lookup(keys: np.ndarray, table_keys: np.ndarray, table_values: np.ndarray,
           fill: Any) -> np.ndarray:
    """Return ``table_values`` at the positions of ``keys`` in ``table_keys`` (else ``fill``)."""
    keys = np.asarray(keys).astype(np.int64)
    table_keys = np.asarray(table_keys).astype(np.int64)
    out = np.full(keys.shape, fill, dtype=np.asarray(table_values).dtype if table_values.size
                  else np.float64)
    if not table_keys.size or not keys.size:
        return out
    order = np.argsort(table_keys, kind='stable')
    sk = table_keys[order]
    pos = np.clip(np.searchsorted(sk, keys), 0, sk.size - 1)
    hit = sk[pos] == keys
    out[hit] = np.asarray(table_values)[order][pos[hit]]
    return out


def check_lines(track_ids: Any, segments: Any) -> Tuple[np.ndarray, np.ndarray]:
    """
    Validate one frame of line tracks: ``(ids (M,) uint32, segments (M, 4) float32)``.

    ``track_ids`` integers in ``[0, 2**32)``, unique; ``segments (M, 4)`` px, finite, each
    longer than 1e-3 px. Raises ``ValueError`` naming the first problem.
    """
    ids = np.asarray(track_ids)
    seg = np.asarray(segments)
    if ids.ndim != 1:
        raise ValueError(f'track_ids must be a 1-D array, got shape {ids.shape}')
    if ids.size and ids.dtype.kind not in 'iu':
        raise ValueError(f'track_ids must be integers, got dtype {ids.dtype}')
    if seg.shape != (ids.size, 4) and not (ids.size == 0 and seg.size == 0):
        raise ValueError(f'segments must be ({ids.size}, 4) for {ids.size} track ids, got '
                         f'shape {seg.shape}')
    seg = seg.astype(np.float64).reshape(-1, 4)
    ids64 = ids.astype(np.int64)
    if ids.size and (ids64.min() < 0 or ids64.max() >= 2 ** 32):
        raise ValueError('track_ids must be in [0, 2**32)')
    if np.unique(ids64).size != ids64.size:
        raise ValueError('track_ids must be unique within a frame')
    if not np.all(np.isfinite(seg)):
        raise ValueError(f'segments must be finite (row {int(np.argmin(np.isfinite(seg).all(1)))} '
                         'is not)')
    short = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) <= 1e-3
    if short.any():
        raise ValueError(f'segment {int(np.argmax(short))} has zero length: a line needs two '
                         'distinct endpoints')
    return ids64.astype(np.uint32), seg.astype(np.float32)


def check_image_size(image_size: Any) -> Tuple[int, int]:
    """Return ``(width, height)`` px as two integers >= 2, else raise ``ValueError``."""
    try:
        w, h = (int(v) for v in image_size)
        ok = (w, h) == tuple(float(v) for v in image_size)
    except (TypeError, ValueError):
        ok = False
    if not ok or w < 2 or h < 2:
        raise ValueError(f'image_size must be (width, height) in pixels, each >= 2, got '
                         f'{image_size!r}')
    return w, h


def centred_intrinsics(focal: float, image_size: Tuple[int, int]
                       ) -> Tuple[float, float, float, float]:
    """Return ``(f, f, w / 2, h / 2)``: square pixels, principal point at the image centre."""
    return (focal, focal, image_size[0] / 2.0, image_size[1] / 2.0)


def ray_intrinsics(obs: Observation, focal: float
                   ) -> Optional[Tuple[float, float, float, float]]:
    """Return the frame's intrinsics, else the solver's estimate; None while f is unknown."""
    if obs.intrinsics is not None:
        return obs.intrinsics
    if math.isfinite(focal) and focal > 0:     # as the solver's: the image centre
        return centred_intrinsics(focal, obs.image_size)
    return None


def unsolved_fields(obs: Observation, n_bodies: int) -> Dict[str, Any]:
    """Return the per-segment and per-body fields of a :class:`FrameResult` not solved."""
    m = len(obs.segments)
    w, c, v = invalid_bodies(n_bodies)
    return {'labels': np.full(m, -1, dtype=np.int32),
            'residuals': np.full(m, np.nan, np.float32), 'angular_velocities': w,
            'angular_covariances': c, 'body_valid': v, 'body_solved': v.copy(),
            'carried': np.zeros(m, dtype=bool)}
