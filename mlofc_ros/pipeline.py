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
import math
import statistics
import time
from typing import (Any, Deque, Dict, FrozenSet, List, Mapping, NamedTuple, Optional, Sequence,
                    Set, Tuple)

from mlofc_ros import params as _params
from mlofc_ros.alike import AlikeBodies, cross_ratios
from mlofc_ros.bodies import BodyTracker, relabel
from mlofc_ros.camera import as_camera, CameraLike, CameraModel
from mlofc_ros.counting import BodyCount, compact_labels
from mlofc_ros.frame import (centred_intrinsics, check_image_size, check_lines, FrameResult,
                             invalid_bodies, lookup, Observation, ray_intrinsics, segment_rays,
                             TIMING_KEYS, unsolved_fields)
from mlofc_ros.label_votes import LabelVotes, match_bodies, ROTATION_GATE, ROTATION_WEIGHT
from mlofc_ros.lane import Finished, SolveJob
from mlofc_ros.method_choice import (AUTO, MethodChoice, MIN_JITTER_FRAMES, misfit_bodies,
                                     ROTATION_METHOD, track_jitter, track_jitters,
                                     TRANSLATION_METHOD)
from mlofc_ros.solver import get_method, Method, segment_lines, SegmentationResult, StepNotTaken
from mlofc_ros.solver.focal import focal_evidence, FOCAL_PRIOR_LOG_SIGMA, FocalEstimate
from mlofc_ros.solver.warm import FULL_AFTER_SEARCH, result_motions, WarmStarts
from mlofc_ros.tracks.config import TrackerConfig
from mlofc_ros.tracks.tracker import LineTracker
from mlofc_ros.tracks.undistort import undistort_segments
from mlofc_ros.tracks.window import TrackWindow
import numpy as np

#: An image whose gray levels span at most this much is blank: no lines, the tracker skips it.
BLANK_CONTRAST = 2
#: A body is reported (``body_valid``) only with at least this many tracks in the window: with
#: fewer (num_bodies above what the scene holds) its fitted motion is mostly noise.
MIN_BODY_TRACKS = 4
#: With no calibration, the focal length starts at the median of this many window estimates
#: (each from a solve with f unknown), then is refined from non-overlapping windows.
FOCAL_SAMPLES = 8
#: A lane's search answer is polished until fewer than this share of its labels change (0.1
#: replayed a little better, bench lane x1 own2+bg / own3+bg 3.06 / 4.59 -> 2.79 / 4.16%
#: wrong, but the live node at 30 Hz stepped fewer frames from its less settled answers,
#: own3+bg `auto` 9-10% of the frames solved against 22-28%, 48% unlabelled against 39%).
POLISH_SETTLED = 0.02


class RunningFit(NamedTuple):
    """The last solve's answer, for :meth:`Pipeline.carry` (replaced in one assignment)."""

    epoch: int                       # Observation.epoch of the solved frame
    track_ids: np.ndarray            # (M,) uint32, the solved frame's tracks
    labels: np.ndarray               # (M,) int32, their stable body ids (-1 none)
    focal_length: float              # px
    focal_log_sigma: float           # standard deviation of ln f
    n_bodies: int                    # bodies reported per frame at that solve


class SolveState(NamedTuple):
    """
    What a solve hands to the observing side (:meth:`Pipeline.solve_state`).

    ``running``: the answer to carry to unsolved frames; ``focal``: the focal length the next
    observations are given, ``(f px, std of ln f)``, None while unknown.
    """

    running: Optional[RunningFit]
    focal: Optional[Tuple[float, float]]


class SolveSide(NamedTuple):
    """
    The solve side's state that moves with the solving (:meth:`Pipeline.hand_over`).

    ``bodies``: the stable body ids and their tracks' histories; ``count``, ``counted_ids``:
    the automatic count and the stable id of each of its bodies; ``focal``: the focal
    estimate of an uncalibrated stream (its window samples, the estimate, the stamp of its
    last evidence, and what it gives the observations: ``(f px, std of ln f)`` or None);
    ``running``: the last answer, carried until the next one; ``votes``: ``method='auto'``'s
    label votes (:mod:`.label_votes`), None for another method: a pipeline that solves with
    the general model for an ``'auto'`` stream (the node's solver process after the switch)
    goes on with them.
    """

    bodies: BodyTracker
    count: BodyCount
    counted_ids: Optional[np.ndarray]
    focal: Tuple[List[float], Optional[FocalEstimate], float, Optional[Tuple[float, float]]]
    running: Optional[RunningFit]
    votes: Optional[LabelVotes]


def make_tracker(params: Mapping[str, Any]) -> LineTracker:
    """Build the line tracker the pipeline runs with ``params`` (node names)."""
    return LineTracker(TrackerConfig.from_params(params))


def window_frames(params: Mapping[str, Any]) -> int:
    """
    Return the sliding window's length (frames) that ``params`` ask for.

    ``params['window']``, or when it is 0 the window of ``params['method']``
    (:attr:`.Method.window`: 10 for 'general', 5 for the others; 'auto' the general model's,
    which it may move to, its rotation-model solves on the last 5).
    """
    return int(params['window']) or get_method(_declared_method(params)).window


def _declared_method(params: Mapping[str, Any]) -> str:
    """Return the method whose window ``method`` asks for: 'auto' the one it may move to."""
    method = params['method']
    return TRANSLATION_METHOD if method == AUTO else method


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
        self._window = TrackWindow(window_frames(self.params))
        self._stamps: Deque[float] = deque(maxlen=self._window.size)
        self._intervals: Deque[float] = deque(maxlen=2 * _params.PARAMS['window'].range[1])
        self._last_stamp: Optional[float] = None
        self._image_size: Optional[Tuple[int, int]] = None
        self._undistort_camera: Optional[CameraModel] = None
        # focal length estimated from the stream when no calibration is given: a camera
        # constant, so once FOCAL_SAMPLES windows were solved with f unknown (100x the cost of
        # a known-f solve) their median starts an estimate that the windows of a method with
        # translations refine at the cost of a profile (solve side); the observing side reads
        # (f, std of ln f), replaced in one assignment
        self._focal_samples: List[float] = []
        self._focal: Optional[FocalEstimate] = None
        self._focal_evidence_stamp = -math.inf
        self._focal_now: Optional[Tuple[float, float]] = None
        # what a solve hands to the next: the solver's warm start besides the labels
        self._warm = WarmStarts()
        # num_bodies=0: the current count, and the stable id of each of its bodies (solver
        # order) from the last solve
        self._count = BodyCount()
        self._counted_ids: Optional[np.ndarray] = None
        # solve-side resets not handed over yet (a tracker failure, a skipped frame's): the
        # next observation carries them
        self._pending_resets: Set[str] = set()
        # where the track ids come from: 'image' (this pipeline's tracker, observe) or
        # 'lines' (the caller's, observe_lines); None until the first frame
        self._source: Optional[str] = None
        # restarts of track or body ids seen by observe (Observation.epoch), and the last
        # solve's labels by track id for carry(), replaced in one assignment by the solving
        # thread, read by the observing one
        self._epoch = 0
        self._running: Optional[RunningFit] = None
        # the solver lane (use_lane) that runs the full solves of a stepping method while the
        # frames step, and the solve state's generation its jobs started from (a reset or a
        # reconfiguration drops a job in flight); a frame neither stepped nor solved is
        # answered from the running fit
        self._lane: Any = None
        self._generation = 0
        self._from_running_fit = False
        # method='auto': the method it solves with now (the rotation model until the scene
        # translates)
        self._choice = MethodChoice()
        # the rotation model's bodies that move alike, published as one; the tracks' jitter
        # of the last rotation-model solve (px), which both read
        self._alike = AlikeBodies()
        self._jitter = math.nan
        # method='auto': the labels it publishes, voted over the solves (None: another
        # method's own labels); once it solves with the general model, the rotation model's
        # solve of the same frame votes too: that solve's labels and which tracks it fits (set
        # by _segment, taken by _publish), and its labels by track id, its next warm start
        self._votes: Optional[LabelVotes] = (LabelVotes() if self.params['method'] == AUTO
                                             else None)
        self._rotation_side: Optional[Tuple[np.ndarray, np.ndarray]] = None
        self._rotation_prev: Optional[Tuple[np.ndarray, np.ndarray]] = None

    # --- configuration -------------------------------------------------------------------

    def reconfigure(self, **kwargs: Any) -> None:
        """
        Change parameters at run time; resets only what the change invalidates.

        ``window`` restarts the window; ``num_bodies`` restarts body numbering; ``method``
        set to ``'auto'``, even again, starts its choice from the rotation model;
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
        if changed:
            self._generation += 1           # a lane's job started from the old settings
        if 'min_segment_length' in changed:
            self._tracker = make_tracker(self.params)
            self._restart_window()
            self.bodies.forget_tracks()
        else:
            # detection settings, not state: the tracks carry on
            self._tracker.reconfigure(TrackerConfig.from_params(self.params))
        size = window_frames(self.params)               # `window`, or the method's own
        if size != self._window.size:
            self._window = TrackWindow(size)
            self._stamps = deque(maxlen=size)
        if 'num_bodies' in changed:
            self._reset_bodies()
        if changed & {'num_bodies', 'min_segment_length'}:
            self._running = None
        if 'method' in changed or new.get('method') == AUTO:
            self._choice.reset()            # 'auto' set (again) starts from the rotation model
            self._votes = LabelVotes() if self.params['method'] == AUTO else None
            self._forget_votes()

    def reset(self) -> None:
        """
        Forget all state (tracks, window, body ids, stamps), as at construction.

        After a reset the pipeline takes images (:meth:`observe`) or line tracks
        (:meth:`observe_lines`) afresh.
        """
        self._tracker.reset()
        self._restart_window()
        self._reset_bodies()
        self._intervals.clear()
        self._last_stamp = None
        self._image_size = None
        self._forget_focal()
        self._pending_resets = set()
        self._source = None
        self._running = None
        self._choice.reset()

    def _reset_bodies(self) -> None:
        """Restart body numbering: stable ids, warm starts, the automatic count."""
        self._generation += 1
        self.bodies.reset()
        self._warm.reset()
        self._alike.reset()
        self._count.reset()
        self._counted_ids = None
        self._forget_votes()

    def _forget_votes(self) -> None:
        if self._votes is not None:
            self._votes.reset()
        self._rotation_side = self._rotation_prev = None

    def _forget_focal(self) -> None:
        self._focal_samples.clear()
        self._focal = None
        self._focal_evidence_stamp = -math.inf
        self._focal_now = None

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
    def window_size(self) -> int:
        """Frames the window holds when full: ``window``, or the method's own when it is 0."""
        return self._window.size

    @property
    def method(self) -> str:
        """
        Return the solver method the solves use now: ``method``, or what 'auto' chose.

        ``'auto'`` solves with the rotation model (``'robust'``) until it misfits the scene,
        then with ``'general'`` (:mod:`mlofc_ros.method_choice`); a caller that places slow
        methods elsewhere (the node: a child process) looks here after every solve.
        """
        method = self.params['method']
        return self._choice.method if method == AUTO else method

    @property
    def method_choice(self) -> MethodChoice:
        """Return what 'auto' decided and why (:class:`~.method_choice.MethodChoice`)."""
        return self._choice

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
                               Optional[CameraModel], float]:
        """
        Return the solver intrinsics, the camera to undistort with, and the spread of ``ln f``.

        Intrinsics None: estimate f; camera None: no distortion; the standard deviation of
        ``ln f`` is 0 for a given focal length, NaN for intrinsics None.
        """
        f = float(self.params['focal_length'])
        if f > 0:
            return centred_intrinsics(f, size), None, 0.0
        if camera is None:
            now = self._focal_now
            if now is None:
                return None, None, math.nan
            return centred_intrinsics(now[0], size), None, now[1]
        return camera.intrinsics, (camera if camera.has_distortion else None), 0.0

    def _empty(self, stamp: float, problem: Optional[str], skipped: bool, fill: int
               ) -> FrameResult:
        w, c, v = invalid_bodies(self.n_bodies)
        return FrameResult(stamp, np.zeros((0, 4), np.float32), np.zeros(0, np.uint32),
                           np.zeros(0, np.int32), np.zeros(0, np.float32), w, c, v,
                           dict.fromkeys(TIMING_KEYS, 0.0), fill, problem, skipped=skipped,
                           body_solved=v.copy())

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
        size = check_image_size(image_size)
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
        intrinsics, undistort_cam, focal_log_sigma = self._intrinsics(cam, size)
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
        if resets & {'tracks', 'bodies'}:
            self._epoch += 1
        return Observation(stamp=stamp, gray=gray, segments=segments, track_ids=track_ids,
                           win_ids=win_ids, win_tracks=win_tracks, intrinsics=intrinsics,
                           focal_log_sigma=focal_log_sigma,
                           image_size=size, window_fill=len(self._stamps),
                           frame_interval=self._frame_interval(), blank=blank,
                           problems=problems, timings=timings, resets=frozenset(resets),
                           elapsed_ms=(time.perf_counter() - t0) * 1e3,
                           undistorted=corrected if corrected is not segments else None,
                           epoch=self._epoch)

    def _check_image_size(self, size: Tuple[int, int], problems: List[str],
                          resets: Set[str]) -> None:
        """Restart the tracks (and forget the focal length) when the image size changes."""
        if self._image_size is not None and size != self._image_size:
            problems.append(f'image size changed from {self._image_size[0]}x'
                            f'{self._image_size[1]} to {size[0]}x{size[1]}; tracks restarted')
            self._restart_tracks()
            resets |= {'tracks', 'focal'}
            self._intervals.clear()
            self._focal_now = None      # the solve side forgets its estimate (resets)
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
        if res is None and self._from_running_fit:
            self._from_running_fit = False
            return dataclasses.replace(self.carry(obs), problem='; '.join(problems) or None,
                                       timings=dict(timings, total=obs.elapsed_ms
                                                    + (time.perf_counter() - t0) * 1e3))
        out = (unsolved_fields(obs, self.n_bodies) if res is None
               else self._publish(obs, res, problems))
        rays = segment_rays(obs.segments if obs.undistorted is None else obs.undistorted,
                            ray_intrinsics(obs, out.get('focal_length', math.nan)))
        timings['total'] = obs.elapsed_ms + (time.perf_counter() - t0) * 1e3
        return FrameResult(
            stamp=obs.stamp, segments=obs.segments, track_ids=obs.track_ids,
            timings=timings, window_fill=obs.window_fill, problem='; '.join(problems) or None,
            frame_interval=obs.frame_interval, n_tracks=int(len(obs.win_ids)), rays=rays,
            **out)

    def carry(self, obs: Observation) -> FrameResult:
        """
        Return the result of ``obs`` from the running fit, without solving its window.

        For a frame the solver has no time for (the node's solver worker is busy): each
        segment takes the stable body id its track had at the last solve (``-1`` for a track
        that solve did not label or did not see, or after a restart of the track or body
        ids), marked :attr:`FrameResult.carried`; residuals are NaN and no body is valid (an
        angular velocity is published only from a solve). Call from the observing thread,
        alongside :meth:`solve` in another: it reads the last solve's labels, which a solve
        replaces in one assignment; it changes no state.
        """
        t0 = time.perf_counter()
        running = self._running
        current = running is not None and running.epoch == obs.epoch and not obs.skipped
        fields = unsolved_fields(obs, running.n_bodies if current else self.n_bodies)
        focal = focal_log_sigma = math.nan             # the last solve's estimate, if any
        if current:
            labels = lookup(obs.track_ids, running.track_ids, running.labels,
                            -1).astype(np.int32)
            fields.update(labels=labels, carried=labels >= 0)
            focal, focal_log_sigma = running.focal_length, running.focal_log_sigma
        if obs.intrinsics is not None:
            focal, focal_log_sigma = float(obs.intrinsics[0]), obs.focal_log_sigma
        rays = segment_rays(obs.segments if obs.undistorted is None else obs.undistorted,
                            ray_intrinsics(obs, focal))
        timings = dict(obs.timings)
        timings['total'] = obs.elapsed_ms + (time.perf_counter() - t0) * 1e3
        return FrameResult(
            stamp=obs.stamp, segments=obs.segments, track_ids=obs.track_ids, timings=timings,
            window_fill=obs.window_fill, problem=None, focal_length=focal,
            focal_log_sigma=focal_log_sigma,
            frame_interval=obs.frame_interval, n_tracks=int(len(obs.win_ids)), rays=rays,
            skipped=obs.skipped, from_running_fit=not obs.skipped, **fields)

    def solve_state(self) -> SolveState:
        """
        Return what the solves so far hand to the observing side.

        For a solve side in another process (:class:`~mlofc_ros.solve_process.SolveProcess`):
        the observing pipeline :meth:`adopt` s it after every solve, so that :meth:`carry` and
        the focal length of the next observations follow the remote solves.
        """
        return SolveState(self._running, self._focal_now)

    def adopt(self, state: SolveState) -> None:
        """Take the answer and focal length of solves run by another pipeline (see above)."""
        running = state.running
        if running is None or running.epoch == self._epoch:
            self._focal_now = state.focal
        # else: solved before a restart seen here (an image of another size: f for that)
        self._running = running

    def forget_solves(self) -> None:
        """
        Restart the solve side from the next observation: body ids, warm starts, the count.

        For a caller whose solve side was lost (a child process that ended; to move the
        solving elsewhere with its state, :meth:`hand_over`): the next observation resets the
        bodies and the focal estimate of whichever side solves it, and nothing is carried from
        solves before it.
        """
        self._pending_resets |= {'bodies', 'focal'}
        self._running = None
        self._focal_now = None

    def hand_over(self) -> SolveSide:
        """
        Return the solve side's state, for a pipeline that solves from now on instead.

        For a caller that moves the solving elsewhere (another process, or back): the other
        pipeline's :meth:`take_over` goes on with the same body ids, count, focal estimate and
        running fit, where :meth:`forget_solves` would restart them. This one's solve side is
        left as it is (stale: do not solve here until it takes a state back).
        """
        return SolveSide(self.bodies, self._count, self._counted_ids,
                         (list(self._focal_samples), self._focal, self._focal_evidence_stamp,
                          self._focal_now), self._running, self._votes)

    def take_over(self, side: SolveSide) -> None:
        """
        Solve from ``side`` on (another pipeline's :meth:`hand_over`), with this one's method.

        The warm starts restart (they belong to the method that made them) and a lane's job
        in flight is dropped; the body ids, the count and the focal estimate go on.
        """
        self._generation += 1
        self._warm.reset()
        self._alike.reset()
        self._rotation_side = self._rotation_prev = None
        self.bodies, self._count, self._counted_ids = side.bodies, side.count, side.counted_ids
        if self.params['method'] == AUTO:
            self._votes = side.votes if side.votes is not None else LabelVotes()
        else:
            # 'auto' whose solving moved here (the general model's process) goes on voting
            self._votes = side.votes if self.params['method'] == TRANSLATION_METHOD else None
        samples, self._focal, self._focal_evidence_stamp, self._focal_now = side.focal
        self._focal_samples = list(samples)
        self._running = side.running

    @property
    def lane(self) -> Any:
        """Return the solver lane of :meth:`use_lane` (None: every solve here, in turn)."""
        return self._lane

    def use_lane(self, lane: Any) -> None:
        """
        Run the full solves of a stepping method in ``lane`` (see :mod:`mlofc_ros.lane`).

        With a known count and a method that steps (``general``), a frame whose schedule asks
        for a search or a full solve hands it to the lane (when idle) and is stepped from
        the running fit meanwhile, or answered from it (:meth:`carry`) when the step does not
        hold and until the first search is back (the search waits for a full window, and its
        answer is polished on that window first: :meth:`_polished`); the lane's answer
        becomes the running fit at the next :meth:`solve`, and the first step from it labels
        every track afresh at its motions (its labels are of a window the stream has since
        left). ``lane``: an
        :class:`~mlofc_ros.lane.InlineLane`, a
        :class:`~mlofc_ros.solve_process.ProcessLane`, or None to solve every frame here
        (the default). A job in flight is dropped.
        """
        if self._lane is not None and self._lane is not lane:
            self._lane.close()
        self._lane = lane
        self._generation += 1

    def _apply_resets(self, resets: FrozenSet[str]) -> None:
        """Reset the solve side as an observation asks (see :attr:`Observation.resets`)."""
        if 'tracks' in resets:
            self.bodies.forget_tracks()     # the tracker restarted and may reuse track ids
            self._forget_votes()
            self._generation += 1
        if 'bodies' in resets:
            self._reset_bodies()
        if 'focal' in resets:
            self._forget_focal()

    def _segment(self, obs: Observation, problems: List[str]) -> Optional[SegmentationResult]:
        """
        Run the solver on the window of ``obs``; None (and why in ``problems``) if it did not.

        The ``method`` parameter's method, or its stand-in while the window holds too few
        frames, warm-started from the previous solves; with ``num_bodies=0`` at the count
        kept online (:class:`~mlofc_ros.counting.BodyCount`). With ``method='auto'`` solving
        with the general model, the rotation model solves the frame too (:meth:`_rotation_vote`).
        """
        self._rotation_side = None
        if obs.window_fill < 2 or obs.blank:           # a blank frame observes no motion
            return None
        if not len(obs.win_ids):
            problems.append('no line tracks in the window')
            return None
        n_req = int(self.params['num_bodies'])
        auto = self.params['method'] == AUTO
        method = get_method(self.method).for_window(obs.window_fill, self._window.size)
        tracks = obs.win_tracks
        if auto and int(self.params['window']) == 0:
            tracks = tracks[:, -method.window:]     # the general model's window, its own frames

        # the solver's keywords for this window, warm starts aside
        common = {'intrinsics': obs.intrinsics, 'image_size': obs.image_size,
                  'seed': int(self.params['seed']), 'method': method.name}

        def solve(n: int, labels: Optional[np.ndarray],
                  ids: Optional[Sequence[int]] = None) -> SegmentationResult:
            return segment_lines(tracks, n, **common,
                                 **self._warm.keywords(method, labels, n, ids))

        def counted(n: int, labels: Optional[np.ndarray],
                    bodies: Optional[Sequence[int]]) -> SegmentationResult:
            # the count's bodies by index into the current ones: their stable ids
            ids = (None if bodies is None
                   else [int(self._counted_ids[b]) if b >= 0 else -1 for b in bodies])
            return solve(n, labels, ids)

        lane = (self._lane if n_req > 0 and method.accepts('step_only') else None)
        try:
            if lane is not None:
                res = self._step_beside_lane(obs, method, n_req, lane, common, problems)
                if res is None:
                    return None
            elif n_req > 0:
                res = solve(n_req, self.bodies.previous_labels(obs.win_ids))
            else:
                previous = None
                if self._counted_ids is not None and len(self._counted_ids) == self._count.n:
                    previous = compact_labels(self.bodies.previous_labels(obs.win_ids),
                                              self._counted_ids)
                res = self._count.solve(tracks, previous, counted)
        except (ValueError, NotImplementedError) as exc:
            problems.append(f'solver: {exc}')
            return None
        except Exception as exc:  # noqa: B902 (a solver failure must not lose the frame)
            problems.append(f'solver failed: {type(exc).__name__}: {exc}')
            return None
        self._warm.solved(method, res, obs.stamp, obs.frame_interval)
        self._jitter, jitters = math.nan, None
        if res.method == ROTATION_METHOD and tracks.shape[1] >= MIN_JITTER_FRAMES:
            # the yardstick of the choice, the alike bodies and the misfit bodies
            jitters = track_jitters(tracks)
            self._jitter = track_jitter(tracks, jitters)
        if (auto and method.name == self._choice.method
                and tracks.shape[1] >= min(method.window, self._window.size)):
            if self._choice.add(res.residuals, self._jitter, jitters):
                # the votes so far are the rotation model's labels of a scene it misfits
                self._forget_votes()
        if self._votes is not None and res.method == TRANSLATION_METHOD:
            self._rotation_side = self._rotation_vote(obs, res.n_bodies, common)
        return res

    def _rotation_vote(self, obs: Observation, n: int, common: Dict[str, Any]
                       ) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """
        Solve the window of ``obs`` with the rotation model too, for ``'auto'``'s label votes.

        Its own frames (the last 5 when ``window`` is 0), ``n`` bodies, warm-started from its
        own previous labels, with no search once it has them (``warm_inliers`` 0: the model
        misfits the scene, so its warm start seldom kept the usual share of inliers and it
        searched in 110 of 143 frames of an own3+bg run, 10 ms each; its votes count only
        where it fits a track anyway; Hopkins155 streamed, 3 motions, 8.5 -> 8.4%). Returns
        its labels ``(N,)`` (solver bodies, ``-1`` none) and which tracks it fits within
        :data:`.label_votes.ROTATION_GATE` times their jitter; None when it cannot tell (too
        few frames or tracks for the jitter) or fails: the general model's labels then vote
        alone.
        """
        rotation = get_method(ROTATION_METHOD)
        tracks = obs.win_tracks
        if int(self.params['window']) == 0:
            tracks = tracks[:, -rotation.window:]
        jitter = track_jitter(tracks) if tracks.shape[1] >= MIN_JITTER_FRAMES else math.nan
        if not (jitter > 0):
            return None
        init = None
        if self._rotation_prev is not None:
            init = lookup(obs.win_ids, *self._rotation_prev, -1)
            init = np.where(init < n, init, -1)
        try:
            res = segment_lines(tracks, n, **dict(common, method=rotation.name),
                                **dict(rotation.fixed, init_labels=init, warm_inliers=0.0))
        except Exception:  # noqa: B902 (a vote the frame can do without)
            return None
        labels = np.asarray(res.labels, dtype=np.int64)
        self._rotation_prev = (np.asarray(obs.win_ids), labels)
        with np.errstate(invalid='ignore'):
            fits = np.asarray(res.residuals, dtype=float) <= ROTATION_GATE * jitter
        return labels, fits

    def _step_beside_lane(self, obs: Observation, method: Method, n: int, lane: Any,
                          common: Dict[str, Any], problems: List[str]
                          ) -> Optional[SegmentationResult]:
        """
        Step the window of ``obs``; hand a search, full solve or rescan that is due to ``lane``.

        ``common``: the solver's keywords for the window (camera, seed, method), warm starts
        aside. Returns the result (None: answer from the running fit). The lane's finished
        job, if any, first becomes the running fit (a rescan's: the rescanned body's motion,
        when it found another basin; a search's once polished, :meth:`_polished`), and this
        step starts from it. While a full solve asked for by a step that did not hold is out,
        each step rescans a body in turn itself.
        """
        finished = lane.poll()
        if finished is not None:
            finished = self._polished(finished, lane, problems)
        adopted = finished is not None and self._adopt(finished, problems)
        keywords = self._warm.keywords(method, self.bodies.previous_labels(obs.win_ids), n)
        first = 'init_motions' not in keywords
        if (not lane.busy and self._warm.full_solve_due()
                and not (first and obs.win_tracks.shape[1] < self.window_size)):
            # a search or a full solve, from the running fit as it is now
            lane.submit(SolveJob(dataclasses.replace(obs, gray=None),
                                 dict(common, tracks=obs.win_tracks, n_bodies=n, **keywords),
                                 self._generation))
        if first:
            # nothing to step from before the first search, which waits for a full window
            # (a search of 5 frames often put a box with the background or two together:
            # bench lane x1, own3+bg render seed 4, 16 -> 3.5% wrong)
            self._from_running_fit = True
            return None
        if not keywords.get('step'):              # meanwhile a step
            keywords = {k: v for k, v in keywords.items() if k != 'rescan'}
            keywords['step'] = True
            if lane.busy and self._warm.full_next:
                # the steps do not hold until the full solve is back: each rescans a body in
                # turn, whose new basin holds meanwhile (docs/design/general.md: the answers
                # come back stale, and the steps from a wrong basin would wait for them)
                keywords['rescan'] = self._warm.rescan_meanwhile(keywords['init_motions'][0])
        elif 'rescan' in keywords:
            # a rescan (a step of about 90 ms instead of 20) to the lane when it is idle, this
            # frame a plain step: at 30 Hz the plain steps keep up with the camera
            keywords = dict(keywords)
            rescan = keywords.pop('rescan')
            handed = not lane.busy
            if handed:
                lane.submit(SolveJob(dataclasses.replace(obs, gray=None),
                                     dict(common, tracks=obs.win_tracks, n_bodies=n,
                                          step_only=True, rescan=rescan, **keywords),
                                     self._generation, rescan=True))
            self._warm.rescan_aside(handed)
        if adopted:
            # the answer's labels are of a window the stream has since left (by the solve's
            # duration), its motions still hold: every track is labelled afresh at them (kept,
            # too many failed the step's guard: own2+bg / own3+bg at 30 Hz replayed offline,
            # each solve's CPU x1.3 its delay, render seeds 0-2, 150 frames, frames answered
            # from the running fit 52 / 50 -> 23 / 12, wrong from frame 90 on 5.7 / 8.3 ->
            # 4.3 / 2.7%)
            keywords['init_labels'] = np.full_like(keywords['init_labels'], -1)
        try:
            return segment_lines(obs.win_tracks, n, step_only=True, **common, **keywords)
        except StepNotTaken as exc:
            self._warm.step_declined(exc.motions)     # the lane's full solve next
            self._from_running_fit = True
            return None

    def _polished(self, finished: Finished, lane: Any, problems: List[str]
                  ) -> Optional[Finished]:
        """
        Return a lane's answer to adopt, or None while a search's window is being polished.

        A search's answer (and each polish's) goes back to the lane as a tracked full solve
        of the same window, every body rescanned, from its labels and motions, until the
        labels settle (fewer than :data:`POLISH_SETTLED` of them change) or
        :data:`~mlofc_ros.solver.warm.FULL_AFTER_SEARCH` polishes: what the frames after a
        search do when every frame is solved in turn (a search alone often misses a box
        that the rescans find), on one window instead of the next ones, which the lane
        reaches only a full solve's delay later each (own3+bg, render seed 3, replayed with
        the lane's delays: the follow-up full solves of moving windows, each from stale
        labels, lost again the boxes the one before found). A polish that failed gives the
        answer before it.
        """
        job, result = finished
        if (job.rescan or job.generation != self._generation
                or (job.polish == 0 and 'init_motions' in job.keywords)):
            return finished                  # not a search's window
        if not isinstance(result, SegmentationResult):
            if job.before is None:
                return finished
            problems.append(f'polish of a search: {type(result).__name__}: {result}')
            return job, job.before
        before = job.before
        if ((before is not None
             and np.mean(np.asarray(result.labels) != np.asarray(before.labels)) < POLISH_SETTLED)
                or job.polish >= FULL_AFTER_SEARCH):
            return finished
        keywords = dict(job.keywords, init_labels=np.asarray(result.labels),
                        init_motions=result_motions(result), rescan=list(range(result.n_bodies)))
        lane.submit(SolveJob(job.obs, keywords, job.generation, polish=job.polish + 1,
                             before=result))
        # meanwhile the frames carry its labels, not the older ones of the rotation model
        self._publish(job.obs, result, problems, interim=True)
        return None

    def _adopt(self, finished: Finished, problems: List[str]) -> bool:
        """
        Make a lane's answer the running fit (its frame was answered); return whether.

        Not an answer that failed (said in ``problems``) or that started before a reset.
        """
        job, result = finished
        if job.rescan:
            # the body's motion, when the rescan moved it (its frame was answered by a step)
            motions, spreads = None, None
            if job.generation == self._generation:
                if isinstance(result, SegmentationResult):
                    motions, spreads = result_motions(result), result.basin_spreads
                elif isinstance(result, StepNotTaken):
                    motions = result.motions
            self._warm.rescan_returned(motions, spreads)
            return False
        if job.generation != self._generation:
            return False
        if isinstance(result, Exception):
            problems.append(f'full solve: {type(result).__name__}: {result}')
            return False
        self._warm.solved(get_method(job.keywords['method']), result, job.obs.stamp,
                          job.obs.frame_interval)
        self._publish(job.obs, result, [])
        return True

    def _publish(self, obs: Observation, res: SegmentationResult, problems: List[str],
                 interim: bool = False) -> Dict[str, Any]:
        """
        Return the per-segment and per-body fields of a solved frame, by stable body id.

        Rotations in rad/s (the window's median frame interval); the body ids follow the
        motions the labels were made with (``segmentation_angular_velocities``), the published
        ones may be a refit of them. ``interim``: an answer that another will replace (a
        search's, while the lane polishes it): its labels become the running fit's, for the
        frames answered from it meanwhile, but its motions are no warm start, its labels no
        vote and its window no evidence of the focal length.
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
        new, keeps = (), None
        counted = int(self.params['num_bodies']) == 0
        if counted and self._counted_ids is not None:
            # the count just changed: a new body gets a new id, a merged one the older id
            if self._count.new_body is not None:
                new = (self._count.new_body,)
            if self._count.kept is not None:
                body, current = self._count.kept
                keeps = {body: int(self._counted_ids[current])}
        # a count given is the most: bodies the rotation model cannot tell apart are one body
        # (the automatic count merges by its own score); the labels of the solve before
        alike = not counted and res.method == ROTATION_METHOD and res.costs is not None
        before = self.bodies.previous_labels(obs.win_ids, max_age=0) if alike else None
        mapping = self.bodies.update(obs.win_ids, res.labels, omega, valid, positions=mid,
                                     new=new, keeps=keeps, stamp=obs.stamp)
        if counted:
            # the current bodies in the order of their stable ids: the older first
            self._counted_ids = np.sort(mapping)
        n_out = max(self.n_bodies, int(mapping.max()) + 1 if mapping.size else 0)
        w_out, c_out, v_out = invalid_bodies(n_out)
        focal_log_sigma = (FOCAL_PRIOR_LOG_SIGMA if obs.intrinsics is None
                           else obs.focal_log_sigma)
        w_out[mapping] = published
        # a body this solve did not rescan keeps the other minima its last rescan found
        cov = cov + self._warm.carried_spreads(res, mapping) / interval ** 2
        c_out[mapping] = cov + focal_covariance(published, focal_log_sigma)
        v_out[mapping] = valid
        if not interim:
            self._warm.remember(res, mapping, valid)
        stable = relabel(res.labels, mapping)
        if self._votes is not None and not interim:
            stable = self._voted(obs, stable)
        labels, carried = self._segment_labels(obs, stable)
        if alike:
            # published under the older id, with one twist
            into = self._alike.add(mapping, cross_ratios(res.costs, res.labels, res.residuals,
                                                         self._jitter), stable, before)
            for young, old in into.items():                  # bodies, not lines
                v_out[young] = False
                labels[labels == young] = old
        solved = v_out.copy()
        if res.method == ROTATION_METHOD:
            # a body the rotation model misfits (it translates) has a biased rate: none
            v_out[mapping[misfit_bodies(res.labels, res.residuals, self._jitter,
                                        len(mapping))]] = False
        self._running = RunningFit(obs.epoch, np.array(obs.track_ids), labels,
                                   float(res.focal_length), focal_log_sigma, n_out)
        if not interim:
            self._refine_focal(obs, res, problems)
        residuals = lookup(obs.track_ids, obs.win_ids,
                           np.asarray(res.residuals, dtype=np.float32), np.nan)
        return {'labels': labels, 'residuals': residuals.astype(np.float32),
                'angular_velocities': w_out, 'angular_covariances': c_out, 'body_valid': v_out,
                'body_solved': solved,
                'carried': carried, 'focal_length': float(res.focal_length),
                'focal_log_sigma': focal_log_sigma}

    def _voted(self, obs: Observation, stable: np.ndarray) -> np.ndarray:
        """
        Return the voted stable id of every track of the window (:mod:`.label_votes`).

        ``stable (N,)``: this solve's; the rotation model's solve of the frame, if any, votes
        too, its bodies under the stable ids they share most tracks with.
        """
        votes = self._votes
        assert votes is not None
        side, self._rotation_side = self._rotation_side, None
        votes.new_solve(obs.win_ids)
        votes.add(obs.win_ids, stable)
        if side is not None:
            labels, fits = side
            ids = match_bodies(labels, stable, int(labels.max(initial=-1)) + 1)
            votes.add(obs.win_ids, relabel(labels, ids), ROTATION_WEIGHT, where=fits)
        return votes.labels(obs.win_ids)

    def _segment_labels(self, obs: Observation, stable: np.ndarray
                        ) -> Tuple[np.ndarray, np.ndarray]:
        """
        Stable body id of every segment of the frame, and where it was carried over.

        ``stable (N,)``: the stable body id of each track of the window as solved. A segment
        whose track the solve left unassigned keeps the id it was last assigned for up to
        ``label_memory`` frames.
        """
        out = lookup(obs.track_ids, obs.win_ids, stable.astype(np.int32), -1).astype(np.int32)
        carried = np.zeros(len(out), dtype=bool)
        memory = int(self.params['label_memory'])
        if memory > 0:
            old = self.bodies.previous_labels(obs.track_ids, max_age=memory)
            carried = (out < 0) & (old >= 0)
            out = np.where(carried, old, out).astype(np.int32)
        return out, carried

    def _refine_focal(self, obs: Observation, res: SegmentationResult,
                      problems: List[str]) -> None:
        """
        Refine the focal length of an uncalibrated stream with a solved window.

        A solve with f unknown gives a sample; the median of :data:`FOCAL_SAMPLES` of them
        starts the running estimate (:class:`FocalEstimate`). A solve at the estimate gives
        the estimate the evidence of its window (:func:`focal_evidence`, the solve's labels
        held) when the window is full and shares no frame with the last window that did, and
        when its model has translations (``general``): only then does its noise tell the
        bodies that rotate about the camera from those that translate, which give the general
        model's profile instead of the rotation model's (biased for them). A rotation-only
        method's estimate stays at its start, not observable.
        """
        # not from an image of another size than the tracker's now: solved late (the node's
        # solver worker) it would estimate f for the new size (a solve side in another
        # process does not track: adopt() keeps such an estimate out)
        if ((self._image_size is not None and obs.image_size != self._image_size)
                or (obs.intrinsics is not None and obs.focal_log_sigma == 0.0)):
            return
        focal = float(res.focal_length)
        if obs.intrinsics is None:
            if math.isfinite(focal) and focal > 0 and self._focal is None:
                self._focal_samples.append(focal)
                if len(self._focal_samples) >= FOCAL_SAMPLES:
                    self._focal = FocalEstimate(float(np.median(self._focal_samples)))
                    self._focal_evidence_stamp = obs.stamp
                    self._focal_now = (self._focal.focal, self._focal.log_sigma)
            return
        span = (obs.window_fill - 0.5) * obs.frame_interval
        if (self._focal is None or obs.window_fill < self._window.size
                or res.diagnostics.translation_scales is None
                or not obs.stamp - self._focal_evidence_stamp >= span):
            return
        w, h = obs.image_size
        try:
            evidence = focal_evidence(obs.win_tracks, np.asarray(res.labels), res.n_bodies,
                                      (w / 2.0, h / 2.0), focal,
                                      noise_var=res.diagnostics.sigma_px ** 2,
                                      motions=result_motions(res))
        except Exception as exc:  # noqa: B902 (a failed refinement must not lose the frame)
            problems.append(f'focal length not refined: {type(exc).__name__}: {exc}')
            return
        self._focal_evidence_stamp = obs.stamp
        self._focal.add(evidence)
        self._focal_now = (self._focal.focal, self._focal.log_sigma)


def focal_covariance(angular_velocities: np.ndarray, focal_log_sigma: float) -> np.ndarray:
    """
    Covariance ``(n, 3, 3)`` the focal length's uncertainty adds to angular velocities ``(n, 3)``.

    The image-plane components scale as ``1 / f`` to first order (a rotation about x or y
    moves the image by ``f w``; about z by nothing that depends on f), so
    ``d w / d ln f = -(w_x, w_y, 0)``. Zero for a given focal length; NaN rows stay NaN.
    """
    w = np.asarray(angular_velocities, dtype=float).reshape(-1, 3)
    if not focal_log_sigma > 0:
        return np.zeros((len(w), 3, 3))
    jac = np.zeros_like(w)
    jac[:, :2] = -w[:, :2]
    return focal_log_sigma ** 2 * jac[:, :, None] * jac[:, None, :]
