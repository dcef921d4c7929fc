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
The per-frame pipeline, without ROS: gray image in, segments, labels and body motions out.

Flow per frame: detect + track lines (:class:`~mlofc_ros.tracks.tracker.LineTracker`), undistort
their endpoints (when the camera has distortion), push them into a sliding
:class:`~mlofc_ros.tracks.window.TrackWindow` of the last ``window`` frames, segment the window
with :func:`mlofc_ros.solver.segment_lines`, and keep body ids stable with
:class:`~mlofc_ros.bodies.BodyTracker`. The node and the bag tool are thin shells around it.

Example::

    p = Pipeline(num_bodies=2, window=5)
    for gray, t in frames:                  # (H, W) uint8, seconds
        r = p.process(gray, t, camera=(fx, fy, cx, cy))
        r.labels, r.angular_velocities      # (M,), (2, 3) rad/s
"""
from collections import deque
import dataclasses
from dataclasses import dataclass, field
import math
import statistics
import time
from typing import Any, Deque, Dict, FrozenSet, List, Mapping, Optional, Set, Tuple

from mlofc_ros import params as _params
from mlofc_ros.bodies import BodyTracker, relabel
from mlofc_ros.camera import as_camera, CameraLike, CameraModel
from mlofc_ros.solver import get_method, Method, segment_lines, SegmentationResult, WarmStart
from mlofc_ros.solver.robust import WARM_INLIERS
from mlofc_ros.tracks.config import TrackerConfig
from mlofc_ros.tracks.tracker import LineTracker
from mlofc_ros.tracks.undistort import undistort_segments
from mlofc_ros.tracks.window import TrackWindow
import numpy as np

#: Keys of :attr:`FrameResult.timings` (milliseconds; ``detect``: the line detector alone, 0
#: in the frames it does not run, part of ``detect_track``).
TIMING_KEYS = ('detect_track', 'detect', 'undistort', 'window', 'solve', 'total')
#: An image whose gray levels span at most this much is blank: no lines, the tracker skips it.
BLANK_CONTRAST = 2
#: A body is reported (``body_valid``) only with at least this many tracks in the window: with
#: fewer (num_bodies above what the scene holds) its fitted motion is mostly noise.
MIN_BODY_TRACKS = 4
#: With no calibration, the focal length is fixed to the median of this many window estimates.
FOCAL_SAMPLES = 8

#: A method that takes ``warm_inliers`` returns the previous window's labels without a search
#: when they keep 75% of the tracks inliers (:data:`mlofc_ros.solver.robust.WARM_INLIERS`). A
#: real scene that the rotation model explains only in part stays below that: visp_cube's warm
#: starts kept 64-74%, every search then found fewer (40-64%), at 4-5 ms instead of 1.5 ms, in
#: 40% of the frames. After a search, a warm start is accepted when it keeps what the search
#: kept less WARM_FLOOR_MARGIN, for the next WARM_FLOOR_SOLVES solves (then a search looks
#: again).
WARM_FLOOR_MARGIN = 0.05
WARM_FLOOR_SOLVES = 10


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
        from at least ``MIN_BODY_TRACKS`` tracks of the window.
    timings : dict
        Milliseconds per stage: ``detect_track``, ``undistort``, ``window``, ``solve``, ``total``.
    window_fill : int
        Frames in the window (``1..window``).
    problem : str or None
        Why this frame gave no (or a degraded) result, for a warning; None when all went well.
    focal_length : float
        Focal length (px) the solver used or estimated; NaN when it did not run.
    frame_interval : float
        Median frame interval of the window (s); NaN with fewer than two frames.
    n_tracks : int
        Tracks handed to the solver.
    skipped : bool
        True when the frame was not processed at all (duplicate stamp): nothing to publish.
    carried : (M,) bool
        True where the label was carried over from an earlier window, not given by this solve.
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
    frame_interval: float = math.nan
    n_tracks: int = 0
    skipped: bool = False
    carried: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    rays: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.float32))

    @property
    def solved(self) -> bool:
        """Return whether at least one body has a valid angular velocity."""
        return bool(np.any(self.body_valid))


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


class _WarmStarts:
    """
    What the solves of a stream hand to the next one: the solver's warm start.

    Per stable body id the last motion the labels were made with (methods whose warm start
    is :attr:`WarmStart.MOTIONS`), and the lowered ``warm_inliers`` after a search
    (:data:`WARM_FLOOR_MARGIN`) with the solves it has left. The previous labels themselves
    come from the body tracker.
    """

    def __init__(self) -> None:
        self.motions: Dict[int, Tuple[np.ndarray, np.ndarray]] = {}
        self.floor: Optional[Tuple[float, int]] = None

    def reset(self) -> None:
        """Forget everything (the body ids restart)."""
        self.motions.clear()
        self.floor = None

    def keywords(self, method: Method, labels: Optional[np.ndarray], n: int) -> Dict[str, Any]:
        """
        Return the keywords of :func:`segment_lines` for a solve by ``method`` of n bodies.

        ``labels``: the previous stable body id of every track of the window (``-1`` none),
        None when there is no warm start (``num_bodies`` automatic).
        """
        if labels is None or method.warm_start is WarmStart.NONE:
            return {}
        out: Dict[str, Any] = dict(method.fixed, init_labels=np.where(labels < n, labels, -1))
        if method.warm_start is WarmStart.MOTIONS and self.motions:
            w = np.full((n, 3), np.nan)
            t = np.full((n, 3), np.nan)
            for body, (w_b, t_b) in self.motions.items():
                if body < n:
                    w[body], t[body] = w_b, t_b
            out['init_motions'] = (w, t)
            if method.rescans:
                out['rescan'] = list(range(n))
        if method.accepts('warm_inliers') and self.floor is not None:
            floor, left = self.floor
            out['warm_inliers'] = min(floor, WARM_INLIERS)
            self.floor = (floor, left - 1) if left > 1 else None
        return out

    def solved(self, method: Method, res: SegmentationResult) -> None:
        """Note a solve by ``method``: after a search past the warm start, lower the bar."""
        if method.accepts('warm_inliers') and res.diagnostics.warm_rejected:
            share = res.diagnostics.inlier_share or 0.0
            self.floor = (max(share - WARM_FLOOR_MARGIN, 0.0), WARM_FLOOR_SOLVES)

    def remember(self, res: SegmentationResult, ids: np.ndarray, valid: np.ndarray) -> None:
        """Keep the motions of the valid bodies of ``res`` under their stable ``ids``."""
        if res.translation_directions is None:
            return
        segmented = np.asarray(res.segmentation_angular_velocities, dtype=float).reshape(-1, 3)
        for j in np.flatnonzero(valid):                  # bodies, not lines
            self.motions[int(ids[j])] = (segmented[j],
                                         np.asarray(res.translation_directions[j]))


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


def _invalid_bodies(n: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    cov = np.zeros((n, 3, 3))
    idx = np.arange(3)
    cov[:, idx, idx] = math.inf
    return np.full((n, 3), np.nan), cov, np.zeros(n, dtype=bool)


def _lookup(keys: np.ndarray, table_keys: np.ndarray, table_values: np.ndarray,
            fill: Any) -> np.ndarray:
    """``table_values`` at the positions of ``keys`` in ``table_keys`` (``fill`` when absent)."""
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


def _check_size(image_size: Any) -> Tuple[int, int]:
    """``(width, height)`` px as two positive integers, else ``ValueError``."""
    try:
        w, h = (int(v) for v in image_size)
        ok = (w, h) == tuple(float(v) for v in image_size)
    except (TypeError, ValueError):
        ok = False
    if not ok or w < 2 or h < 2:
        raise ValueError(f'image_size must be (width, height) in pixels, each >= 2, got '
                         f'{image_size!r}')
    return w, h


def make_tracker(params: Mapping[str, Any]) -> LineTracker:
    """Build the line tracker the pipeline runs with ``params`` (node names)."""
    return LineTracker(TrackerConfig.from_params(params))


class Pipeline:
    """
    Sliding-window motion segmentation of a gray image stream.

    Keyword parameters are those of :mod:`mlofc_ros.params` (the node's ROS parameters, same
    names and defaults); node-only ones (``queue_size``, ...) are accepted and ignored. Invalid
    values raise ``ValueError``, unknown names ``TypeError``.

    Threads: :meth:`observe` (tracking) and :meth:`solve` may run in two threads at once, each
    called from one thread at a time; :meth:`reconfigure` and :meth:`reset` only while neither
    runs. :meth:`process` does both in the calling thread.
    """

    def __init__(self, **kwargs: Any) -> None:
        unknown = sorted(set(kwargs) - set(_params.PARAMS))
        if unknown:
            raise TypeError(f'Pipeline got unknown parameters {unknown}')
        self.params: Dict[str, Any] = _params.defaults()
        self.params.update(_params.check_all(kwargs))
        self.bodies = BodyTracker()
        self._tracker = make_tracker(self.params)
        self._window = TrackWindow(self.params['window'])
        self._stamps: Deque[float] = deque(maxlen=self.params['window'])
        self._intervals: Deque[float] = deque(maxlen=2 * _params.PARAMS['window'].range[1])
        self._last_stamp: Optional[float] = None
        self._image_size: Optional[Tuple[int, int]] = None
        self._undistort_camera: Optional[CameraModel] = None
        # focal length estimated from the stream when no calibration is given: a camera
        # constant, so it is fixed once FOCAL_SAMPLES windows agree (the median) instead of
        # being re-estimated at every frame (100x the cost of a known-f solve)
        self._focal_samples: List[float] = []
        self._focal_fixed: Optional[float] = None
        # what a solve hands to the next: the solver's warm start besides the labels
        self._warm = _WarmStarts()
        # solve-side resets not handed over yet (a tracker failure, a skipped frame's): the
        # next observation carries them
        self._pending_resets: Set[str] = set()
        # where the track ids come from: 'image' (this pipeline's tracker, observe) or
        # 'lines' (the caller's, observe_lines); None until the first frame
        self._source: Optional[str] = None

    # --- configuration -------------------------------------------------------------------

    def reconfigure(self, **kwargs: Any) -> None:
        """
        Change parameters at run time; resets only what the change invalidates.

        ``window`` restarts the window; ``num_bodies`` restarts body numbering;
        ``min_segment_length`` restarts the tracker and the window; ``detect_every``,
        ``detect_every_max``, ``detect_regions``, ``detector_backend``, ``detector_scale``
        and ``bridge_crossings`` change only the detection (tracks carry on). Raises like the
        constructor, changing nothing when any value is invalid.
        """
        unknown = sorted(set(kwargs) - set(_params.PARAMS))
        if unknown:
            raise TypeError(f'Pipeline got unknown parameters {unknown}')
        new = _params.check_all(kwargs)
        changed = {k for k, v in new.items() if self.params[k] != v}
        self.params.update(new)
        if 'min_segment_length' in changed:
            self._tracker = make_tracker(self.params)
            self._restart_window()
            self.bodies.forget_tracks()
        else:
            # detection settings, not state: the tracks carry on
            self._tracker.reconfigure(TrackerConfig.from_params(self.params))
        if 'window' in changed:
            self._window = TrackWindow(self.params['window'])
            self._stamps = deque(maxlen=self.params['window'])
        if 'num_bodies' in changed:
            self.bodies.reset()
            self._warm.reset()

    def reset(self) -> None:
        """
        Forget all state (tracks, window, body ids, stamps), as at construction.

        After a reset the pipeline takes images (:meth:`observe`) or line tracks
        (:meth:`observe_lines`) afresh.
        """
        self._tracker.reset()
        self._restart_window()
        self.bodies.reset()
        self._warm.reset()
        self._intervals.clear()
        self._last_stamp = None
        self._image_size = None
        self._forget_focal()
        self._pending_resets = set()
        self._source = None

    def _forget_focal(self) -> None:
        self._focal_samples.clear()
        self._focal_fixed = None

    def _restart_window(self) -> None:
        self._window.reset()
        self._stamps.clear()

    def _restart_tracks(self) -> None:
        """
        Restart the tracker and the window.

        The solve side forgets the track ids when it gets an observation whose resets hold
        ``'tracks'``: the caller adds it.
        """
        self._tracker.reset()
        self._restart_window()

    @property
    def window_fill(self) -> int:
        """Frames currently in the window."""
        return len(self._stamps)

    @property
    def n_bodies(self) -> int:
        """Bodies reported per frame (``num_bodies``, or the stable ids seen when automatic)."""
        n = int(self.params['num_bodies'])
        return n if n > 0 else self.bodies.n_slots

    # --- per frame -----------------------------------------------------------------------

    def _check_image(self, gray: np.ndarray) -> np.ndarray:
        gray = np.asarray(gray)
        if gray.ndim != 2:
            raise ValueError(f'expected a (H, W) gray image, got shape {gray.shape}')
        if gray.dtype != np.uint8:
            raise ValueError(f'expected a uint8 gray image, got dtype {gray.dtype}')
        if gray.shape[0] < 2 or gray.shape[1] < 2:
            raise ValueError(f'image of {gray.shape[1]}x{gray.shape[0]} pixels is too small')
        if gray.size > self.params['max_pixels']:
            raise ValueError(f'image of {gray.shape[1]}x{gray.shape[0]} = {gray.size} pixels '
                             f'exceeds max_pixels = {self.params["max_pixels"]}')
        return gray

    def _intrinsics(self, camera: Optional[CameraModel], size: Tuple[int, int]
                    ) -> Tuple[Optional[Tuple[float, float, float, float]],
                               Optional[CameraModel]]:
        """Solver intrinsics (None = estimate f) and the camera to undistort with (or None)."""
        f = float(self.params['focal_length'])
        if f > 0:
            return (f, f, size[0] / 2.0, size[1] / 2.0), None
        if camera is None:
            if self._focal_fixed is None:
                return None, None
            f = self._focal_fixed
            return (f, f, size[0] / 2.0, size[1] / 2.0), None
        return camera.intrinsics, (camera if camera.has_distortion else None)

    def _empty(self, stamp: float, problem: Optional[str], skipped: bool, fill: int
               ) -> FrameResult:
        w, c, v = _invalid_bodies(self.n_bodies)
        return FrameResult(stamp, np.zeros((0, 4), np.float32), np.zeros(0, np.uint32),
                           np.zeros(0, np.int32), np.zeros(0, np.float32), w, c, v,
                           dict.fromkeys(TIMING_KEYS, 0.0), fill, problem, skipped=skipped)

    def process(self, gray: np.ndarray, stamp_seconds: float,
                camera: CameraLike = None) -> FrameResult:
        """
        Process one frame and return the newest frame's segmentation.

        Parameters
        ----------
        gray : (H, W) uint8
            The image.
        stamp_seconds : float
            Its capture time (s); frame intervals (and so rad/s) come from the stamps.
        camera : (fx, fy, cx, cy) | CameraModel | None
            Intrinsics (px) and distortion of this image; None = unknown (focal length
            estimated unless the ``focal_length`` parameter is set).

        Raises ``ValueError`` for an unusable image or camera (wrong shape/dtype, too large, bad
        intrinsics, non-finite stamp). Stamp jumps, too few tracks and solver failures are not
        errors: they are reported in :attr:`FrameResult.problem` (labels -1, bodies invalid).
        An exception from the line tracker propagates after the tracks are restarted.

        The same as ``solve(observe(gray, stamp_seconds, camera))``.

        """
        return self.solve(self.observe(gray, stamp_seconds, camera))

    def observe(self, gray: np.ndarray, stamp_seconds: float,
                camera: CameraLike = None, dropped: int = 0) -> Observation:
        """
        Track the lines of one frame and add them to the window; do not solve.

        Arguments and errors as :meth:`process`. ``dropped`` is the number of frames the caller
        received since the previous one and did not pass on (the node's full queue): their
        time is not a gap in the stream, so they do not restart the window
        (``max_frame_gap`` counts intervals beyond them). The returned :class:`Observation` goes to
        :meth:`solve`, which may run in another thread, one observation at a time, while this
        method runs on the next frames (the node does so: tracking keeps the camera's rate
        when the solver cannot). Observations must be solved in order; one may be dropped
        unsolved when a newer one replaces it with :meth:`Observation.replacing`.
        """
        t0 = time.perf_counter()
        gray = self._check_image(gray)
        self._check_source('image')
        return self._observe(stamp_seconds, camera, (int(gray.shape[1]), int(gray.shape[0])),
                             t0, gray=gray, dropped=dropped)

    def observe_lines(self, track_ids: np.ndarray, segments: np.ndarray, stamp_seconds: float,
                      image_size: Tuple[int, int], camera: CameraLike = None) -> Observation:
        """
        Add one frame of line segments from your own tracker to the window; do not solve.

        For a stream whose lines are detected and tracked elsewhere (another front end, or
        point tracks paired into lines): everything after the tracker is the same as for
        :meth:`observe` (undistortion, window, stamps, focal-length estimation, and in
        :meth:`solve` the segmentation and the stable body ids).

        Parameters
        ----------
        track_ids : (M,) int
            Persistent id of every segment's track, unique within the frame, in
            ``[0, 2**32)``. A track keeps its id from frame to frame.
        segments : (M, 4) float
            ``(u1, v1, u2, v2)`` px in the (distorted) image, pixel centres at integers; finite,
            non-zero length.
        stamp_seconds : float
            The frame's capture time (s).
        image_size : (width, height)
            Pixels (the principal point of an unknown camera is the image centre).
        camera : (fx, fy, cx, cy) | CameraModel | None
            As in :meth:`process`.

        Raises ``ValueError`` for malformed lines, a bad image size or camera, or when this
        pipeline has observed images (its tracker's ids would mix with yours; :meth:`reset`
        first). Stamps are handled as in :meth:`observe`.

        """
        t0 = time.perf_counter()
        ids, seg = check_lines(track_ids, segments)
        size = _check_size(image_size)
        self._check_source('lines')
        return self._observe(stamp_seconds, camera, size, t0, lines=(ids, seg))

    def process_lines(self, track_ids: np.ndarray, segments: np.ndarray, stamp_seconds: float,
                      image_size: Tuple[int, int], camera: CameraLike = None) -> FrameResult:
        """
        ``solve(observe_lines(...))``: segment a stream of your own line tracks, frame by frame.

        Arguments and errors as :meth:`observe_lines`; the result as :meth:`process` (its
        ``segments`` and ``track_ids`` are the ones given).
        """
        return self.solve(self.observe_lines(track_ids, segments, stamp_seconds, image_size,
                                             camera))

    def _check_source(self, source: str) -> None:
        """Refuse to mix the tracker's track ids (images) with a caller's (lines)."""
        if self._source is not None and self._source != source:
            raise ValueError(f'this pipeline has observed {self._source}; reset() it before '
                             f'observing {source}')
        self._source = source

    def _observe(self, stamp_seconds: float, camera: CameraLike, size: Tuple[int, int],
                 t0: float, gray: Optional[np.ndarray] = None,
                 lines: Optional[Tuple[np.ndarray, np.ndarray]] = None,
                 dropped: int = 0) -> Observation:
        """Add a frame to the window: an image (``gray``) or the caller's ``lines``."""
        dropped = int(dropped)
        if dropped < 0:
            raise ValueError(f'dropped must be >= 0, got {dropped}')
        stamp = float(stamp_seconds)
        if not math.isfinite(stamp):
            raise ValueError(f'stamp must be finite, got {stamp_seconds!r}')
        cam = as_camera(camera)
        problems: List[str] = []
        resets: Set[str] = set()
        self._check_image_size(size, problems, resets)
        if not self._check_stamp(stamp, problems, resets, dropped):
            self._pending_resets |= resets     # for the next observation to carry
            return Observation.skip(stamp, gray, f'duplicate stamp {stamp:.9f} s; frame '
                                    'skipped', self.window_fill)
        intrinsics, undistort_cam = self._intrinsics(cam, size)
        if undistort_cam != self._undistort_camera:
            self._restart_window()        # stored endpoints were corrected with another model
            self._undistort_camera = undistort_cam
        timings: Dict[str, float] = {}
        blank = lines is None and int(gray.max()) - int(gray.min()) <= BLANK_CONTRAST
        track_ids, segments = self._frame_lines(gray, lines, blank, problems, timings)
        t = time.perf_counter()
        corrected = segments
        if undistort_cam is not None and len(segments):
            corrected = np.asarray(undistort_segments(segments, undistort_cam),
                                   dtype=np.float64).reshape(-1, 4)
        timings['undistort'] = (time.perf_counter() - t) * 1e3
        t = time.perf_counter()
        win_ids, win_tracks = self._push(track_ids, corrected, stamp)
        timings['window'] = (time.perf_counter() - t) * 1e3
        resets |= self._pending_resets
        self._pending_resets = set()
        return Observation(stamp=stamp, gray=gray, segments=segments, track_ids=track_ids,
                           win_ids=win_ids, win_tracks=win_tracks, intrinsics=intrinsics,
                           image_size=size, window_fill=len(self._stamps),
                           frame_interval=self._frame_interval(), blank=blank,
                           problems=problems, timings=timings, resets=frozenset(resets),
                           elapsed_ms=(time.perf_counter() - t0) * 1e3,
                           undistorted=corrected if corrected is not segments else None)

    def _check_image_size(self, size: Tuple[int, int], problems: List[str],
                          resets: Set[str]) -> None:
        """Restart the tracks (and forget the focal length) when the image size changes."""
        if self._image_size is not None and size != self._image_size:
            problems.append(f'image size changed from {self._image_size[0]}x'
                            f'{self._image_size[1]} to {size[0]}x{size[1]}; tracks restarted')
            self._restart_tracks()
            resets |= {'tracks', 'focal'}
            self._intervals.clear()
            self._focal_fixed = None    # the solve side forgets its samples (resets)
        self._image_size = size

    def _check_stamp(self, stamp: float, problems: List[str], resets: Set[str],
                     dropped: int = 0) -> bool:
        """
        Check the stamp against the last frame's; False for a duplicate (skip the frame).

        A stamp that went back (a bag loop, a clock reset) restarts the tracks and the body
        ids; a gap over ``max_frame_gap`` frame intervals beyond the ``dropped`` frames the
        caller did not pass on restarts the tracks.
        """
        if self._last_stamp is not None:
            dt = stamp - self._last_stamp
            if dt == 0.0:
                return False
            if dt < 0.0:
                problems.append(f'stamp went back {-dt:.3f} s (bag loop or clock reset); '
                                'tracks and window restarted')
                self._restart_tracks()
                resets |= {'tracks', 'bodies'}
                self._intervals.clear()
            else:
                gap = float(self.params['max_frame_gap'])
                # statistics.median: the same value as np.median, ~20x cheaper on a few numbers
                nominal = (float(statistics.median(self._intervals)) if self._intervals
                           else math.nan)
                # the frames the caller dropped fill their share of dt: only the rest is a gap
                if gap > 0 and math.isfinite(nominal) and dt > (gap + dropped) * nominal:
                    beyond = f' beyond {dropped} dropped' if dropped else ''
                    problems.append(f'{dt:.3f} s since the last frame (> {gap:g} x '
                                    f'{nominal:.3f} s{beyond}); window restarted')
                    self._restart_tracks()
                    resets.add('tracks')
                    self._intervals.clear()
                else:
                    self._intervals.append(dt / (1 + dropped))
        self._last_stamp = stamp
        return True

    def _frame_lines(self, gray: Optional[np.ndarray],
                     lines: Optional[Tuple[np.ndarray, np.ndarray]], blank: bool,
                     problems: List[str], timings: Dict[str, float]
                     ) -> Tuple[np.ndarray, np.ndarray]:
        """Return the frame's track ids and segments: the caller's ``lines``, or ``gray``'s."""
        t = time.perf_counter()
        if lines is not None:
            track_ids, segments = lines
        elif blank:
            # nothing to see (lens cap, dropped frame): the frame enters the window empty and
            # the tracker carries its tracks from the last frame with content to the next
            problems.append('blank image (no contrast): no lines')
            track_ids, segments = np.zeros(0, np.uint32), np.zeros((0, 4), np.float32)
        else:
            try:
                track_ids, segments = self._tracker.update(gray)
            except Exception:
                # its state may be half-updated: start clean next frame (and the solve side
                # forgets the old ids with the next observation)
                self._restart_tracks()
                self._pending_resets.add('tracks')
                raise
        track_ids = np.asarray(track_ids, dtype=np.uint32).ravel()
        segments = np.asarray(segments, dtype=np.float32).reshape(-1, 4)
        timings['detect_track'] = (time.perf_counter() - t) * 1e3
        ran = gray is not None and not blank and self._tracker.last_timing['detected']
        timings['detect'] = self._tracker.last_timing['detect'] * 1e3 if ran else 0.0
        return track_ids, segments

    def _push(self, track_ids: np.ndarray, corrected: np.ndarray, stamp: float
              ) -> Tuple[np.ndarray, np.ndarray]:
        """
        Add the frame's (undistorted) segments to the window; its tracks ``(ids, (N, K, 4))``.

        Tracks seen in at least ``min_track_frames`` frames (or every frame of a shorter
        window, and at least 2).
        """
        self._window.push(track_ids, corrected)
        self._stamps.append(stamp)
        min_frames = min(int(self.params['min_track_frames']), len(self._stamps))
        min_frames = max(min_frames, 2)
        win_ids, win_tracks = self._window.tracks(min_frames=min_frames)
        return (np.asarray(win_ids).astype(np.int64).ravel(),
                np.asarray(win_tracks, dtype=np.float64))

    def _frame_interval(self) -> float:
        """Median frame interval of the window (s); NaN with fewer than two frames."""
        stamps = list(self._stamps)
        if len(stamps) < 2:
            return math.nan
        return float(statistics.median([b - a for a, b in zip(stamps, stamps[1:])]))

    def solve(self, obs: Observation) -> FrameResult:
        """
        Segment the window of ``obs`` (from :meth:`observe`) and return the frame's result.

        Call from one thread at a time, in the order of the observations; it may run alongside
        :meth:`observe` of later frames.
        """
        t0 = time.perf_counter()
        self._apply_resets(obs.resets)
        if obs.skipped:
            return self._empty(obs.stamp, '; '.join(obs.problems) or None, skipped=True,
                               fill=obs.window_fill)
        problems = list(obs.problems)
        timings = dict(obs.timings)
        t = time.perf_counter()
        res = self._segment(obs, problems)
        timings['solve'] = (time.perf_counter() - t) * 1e3
        out = self._unsolved(obs) if res is None else self._publish(obs, res)
        rays = segment_rays(obs.segments if obs.undistorted is None else obs.undistorted,
                            self._ray_intrinsics(obs, out.get('focal_length', math.nan)))
        timings['total'] = obs.elapsed_ms + (time.perf_counter() - t0) * 1e3
        return FrameResult(
            stamp=obs.stamp, segments=obs.segments, track_ids=obs.track_ids,
            timings=timings, window_fill=obs.window_fill, problem='; '.join(problems) or None,
            frame_interval=obs.frame_interval, n_tracks=int(len(obs.win_ids)), rays=rays,
            **out)

    @staticmethod
    def _ray_intrinsics(obs: Observation, focal: float
                        ) -> Optional[Tuple[float, float, float, float]]:
        """Return the frame's intrinsics, else the solver's estimate; None while f is unknown."""
        if obs.intrinsics is not None:
            return obs.intrinsics
        if math.isfinite(focal) and focal > 0:     # as the solver's: the image centre
            return (focal, focal, obs.image_size[0] / 2.0, obs.image_size[1] / 2.0)
        return None

    def _apply_resets(self, resets: FrozenSet[str]) -> None:
        """Reset the solve side as an observation asks (see :attr:`Observation.resets`)."""
        if 'tracks' in resets:
            self.bodies.forget_tracks()     # the tracker restarted and may reuse track ids
        if 'bodies' in resets:
            self.bodies.reset()
            self._warm.reset()
        if 'focal' in resets:
            self._forget_focal()

    def _segment(self, obs: Observation, problems: List[str]) -> Optional[SegmentationResult]:
        """
        Run the solver on the window of ``obs``; None (and why in ``problems``) if it did not.

        The ``method`` parameter's method, or its stand-in while the window holds too few
        frames, warm-started from the previous solves.
        """
        if obs.window_fill < 2 or obs.blank:           # a blank frame observes no motion
            return None
        if not len(obs.win_ids):
            problems.append('no line tracks in the window')
            return None
        n_req = int(self.params['num_bodies'])
        method = get_method(self.params['method']).for_window(obs.window_fill,
                                                              int(self.params['window']))
        previous = self.bodies.previous_labels(obs.win_ids) if n_req > 0 else None
        try:
            res = segment_lines(obs.win_tracks, n_req, intrinsics=obs.intrinsics,
                                image_size=obs.image_size, method=method.name,
                                seed=int(self.params['seed']),
                                **self._warm.keywords(method, previous, n_req))
        except (ValueError, NotImplementedError) as exc:
            problems.append(f'solver: {exc}')
            return None
        except Exception as exc:  # noqa: B902 (a solver failure must not lose the frame)
            problems.append(f'solver failed: {type(exc).__name__}: {exc}')
            return None
        self._warm.solved(method, res)
        return res

    def _unsolved(self, obs: Observation) -> Dict[str, Any]:
        """Return the per-segment and per-body fields of a frame that was not solved."""
        m = len(obs.segments)
        w, c, v = _invalid_bodies(self.n_bodies)
        return {'labels': np.full(m, -1, dtype=np.int32),
                'residuals': np.full(m, np.nan, np.float32), 'angular_velocities': w,
                'angular_covariances': c, 'body_valid': v, 'carried': np.zeros(m, dtype=bool)}

    def _publish(self, obs: Observation, res: SegmentationResult) -> Dict[str, Any]:
        """
        Return the per-segment and per-body fields of a solved frame, by stable body id.

        Rotations in rad/s (the window's median frame interval); the body ids follow the
        motions the labels were made with (``segmentation_angular_velocities``), the published
        ones may be a refit of them.
        """
        interval = obs.frame_interval
        published = np.asarray(res.angular_velocities, dtype=float).reshape(-1, 3) / interval
        omega = (np.asarray(res.segmentation_angular_velocities, dtype=float).reshape(-1, 3)
                 / interval)
        cov = np.asarray(res.angular_covariances, dtype=float).reshape(-1, 3, 3) / interval ** 2
        lab = np.asarray(res.labels).astype(np.int64)
        support = np.bincount(lab[lab >= 0], minlength=len(omega))[:len(omega)]
        valid = (np.all(np.isfinite(omega), axis=1)
                 & np.all(np.isfinite(cov.reshape(len(cov), -1)), axis=1)
                 & (support >= MIN_BODY_TRACKS))
        mid = None
        if self.bodies.n_slots == 0:      # positions only order the bodies of a first window
            with np.errstate(invalid='ignore'):
                mid = np.nanmean(0.5 * (obs.win_tracks[..., :2] + obs.win_tracks[..., 2:]),
                                 axis=1)
        mapping = self.bodies.update(obs.win_ids, res.labels, omega, valid, positions=mid)
        n_out = max(self.n_bodies, int(mapping.max()) + 1 if mapping.size else 0)
        w_out, c_out, v_out = _invalid_bodies(n_out)
        w_out[mapping] = published
        c_out[mapping] = cov
        v_out[mapping] = valid
        self._warm.remember(res, mapping, valid)
        labels, carried = self._segment_labels(obs, res.labels, mapping)
        self._sample_focal(obs, float(res.focal_length))
        residuals = _lookup(obs.track_ids, obs.win_ids,
                            np.asarray(res.residuals, dtype=np.float32), np.nan)
        return {'labels': labels, 'residuals': residuals.astype(np.float32),
                'angular_velocities': w_out, 'angular_covariances': c_out, 'body_valid': v_out,
                'carried': carried, 'focal_length': float(res.focal_length)}

    def _segment_labels(self, obs: Observation, labels: np.ndarray, mapping: np.ndarray
                        ) -> Tuple[np.ndarray, np.ndarray]:
        """
        Stable body id of every segment of the frame, and where it was carried over.

        A segment whose track the solve left unassigned keeps the id it was last assigned for
        up to ``label_memory`` frames.
        """
        stable = relabel(labels, mapping)
        out = _lookup(obs.track_ids, obs.win_ids, stable.astype(np.int32), -1).astype(np.int32)
        carried = np.zeros(len(out), dtype=bool)
        memory = int(self.params['label_memory'])
        if memory > 0:
            old = self.bodies.previous_labels(obs.track_ids, max_age=memory)
            carried = (out < 0) & (old >= 0)
            out = np.where(carried, old, out).astype(np.int32)
        return out, carried

    def _sample_focal(self, obs: Observation, focal: float) -> None:
        """Collect an estimated focal length; fix the median of :data:`FOCAL_SAMPLES` of them."""
        # not from an image of another size than the tracker's now: solved late (the node's
        # solver worker) it would fix f for the new size
        if (obs.intrinsics is None and math.isfinite(focal) and focal > 0
                and obs.image_size == self._image_size):
            self._focal_samples.append(focal)
            if len(self._focal_samples) >= FOCAL_SAMPLES:
                self._focal_fixed = float(np.median(self._focal_samples))
