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
Line tracking with persistent ids: lines carried frame to frame, refreshed by detection.

Per frame, vectorised over tracks and detections (no Python loop per line):

1. *Carry* (:mod:`~mlofc_ros.tracks.carry`): predict each track by its velocity and re-locate
   it on the image edges, or carry it by KLT; grow carried lines along their edges.
2. *Detect* (:mod:`~mlofc_ros.tracks.schedule`): on every ``detect_every``-th frame at least,
   more rarely in a quiet scene, with a :class:`~mlofc_ros.segments.detect.LineDetector`.
3. *Associate* (:mod:`~mlofc_ros.tracks.associate`): detections join tracks or start new ones;
   duplicate tracks are dropped.
4. A track neither carried nor detected coasts on its velocity (not reported) and retires
   after :data:`MAX_MISSES` such frames.

Segments are ``(u1, v1, u2, v2)`` px in the input image. A track keeps the orientation it was
born with (the detector's: brighter side on the left).
"""
from typing import Dict, Optional, Tuple

import cv2
from mlofc_ros.segments.common import check_gray
from mlofc_ros.segments.detect import LineDetector
from mlofc_ros.tracks import associate as assoc
from mlofc_ros.tracks.carry import (carry, clip_to_image, grow, remap_velocity,
                                    update_motion)
from mlofc_ros.tracks.config import TrackerConfig
from mlofc_ros.tracks.frames import Frames
from mlofc_ros.tracks.schedule import DetectionSchedule
from mlofc_ros.tracks.state import TrackSet
import numpy as np

#: Consecutive frames a track may be neither carried nor detected before it retires.
MAX_MISSES = 2
#: Most live tracks; births beyond are dropped.
MAX_TRACKS = 2000


class _Frame:
    """The working state of one :meth:`LineTracker.update`: tracks as carried so far."""

    def __init__(self, seg: np.ndarray, seg_carried: np.ndarray, carried: np.ndarray,
                 confirmed: np.ndarray, vel: np.ndarray, omega: np.ndarray) -> None:
        self.seg, self.seg_carried = seg, seg_carried        # grown / as carried
        self.carried, self.confirmed = carried, confirmed
        self.vel, self.omega = vel, omega
        self.matched = np.zeros(seg.shape[0], bool)


class LineTracker:
    """
    Track line segments over a gray image stream with persistent ``uint32`` ids.

    ``config``: the settings (:class:`~mlofc_ros.tracks.config.TrackerConfig`, its defaults
    when None). ``detector``: a line detector to use instead of the one ``config`` describes
    (e.g. one with a callable backend).
    """

    def __init__(self, config: Optional[TrackerConfig] = None,
                 detector: Optional[LineDetector] = None) -> None:
        self.config = config if config is not None else TrackerConfig()
        self.detector = detector if detector is not None else self.config.make_detector()
        self._tracks = TrackSet()
        self._frames = Frames()
        self._schedule = DetectionSchedule(self.config)
        self.reset()

    def reconfigure(self, config: TrackerConfig) -> None:
        """
        Change the detection settings; the tracks carry on.

        The detector is rebuilt when its settings changed. A changed ``min_segment_length``
        applies to new detections and reports; build a new tracker to restart the tracks too.
        """
        if config.detector_settings() != self.config.detector_settings():
            self.detector = config.make_detector()
        self.config = config
        self._schedule.config = config

    def reset(self) -> None:
        """Drop every track and the previous image; ids restart from 0."""
        self._tracks.clear()
        self._frames = Frames()
        self._schedule.reset()
        self._frame = 0
        #: seconds spent in the last :meth:`update` per stage (``detect``, ``track``),
        #: ``detected`` = 1.0 when the detector ran in it and ``detected_area`` the share of
        #: the image it ran on (1.0 whole, less with ``detect_regions``, 0.0 not at all)
        self.last_timing: Dict[str, float] = {'detect': 0.0, 'track': 0.0, 'detected': 0.0,
                                              'detected_area': 0.0}

    @property
    def n_tracks(self) -> int:
        """Return the number of live tracks (reported or coasting)."""
        return self._tracks.size

    @property
    def min_length(self) -> float:
        """Return the shortest segment reported or born, px."""
        return self.config.min_segment_length

    @property
    def detect_every(self) -> int:
        """Return the shortest interval between detections, frames."""
        return self.config.detect_every

    @property
    def detect_every_max(self) -> int:
        """Return the longest interval between detections in a quiet scene, frames."""
        return self.config.detect_every_max

    @property
    def detect_regions(self) -> bool:
        """Return whether a quiet scene is detected in regions only."""
        return self.config.detect_regions

    def update(self, gray: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """
        Process one frame ``gray`` (H, W) uint8.

        Returns ``(track_ids (M,) uint32, segments (M, 4) float32)`` px (within the image) of
        the tracks observed in this frame (carried or matched to a detection), sorted by id.
        Raises ``ValueError`` on a non-uint8/non-2D image or a change of image size (call
        :meth:`reset` first).
        """
        check_gray(gray)
        if self._frames.shape is not None and gray.shape != self._frames.shape:
            raise ValueError(f'image size changed from {self._frames.shape} to {gray.shape}; '
                             'reset() the tracker first')
        tick = cv2.getTickCount
        t0 = tick()
        self._frames.begin(gray)
        image = gray.astype(np.float32)
        fr = self._carry(image)
        run_detect = self._schedule.due(self._frames, fr.seg, fr.carried)
        t1 = tick()
        det, clipped, area = self._detect(gray, fr, run_detect)
        t2 = tick()
        born = self._match(det, clipped, fr)
        report = self._advance(fr, born, run_detect)
        self._frames.end()
        self._frame += 1
        out_ids, out_seg = self._tracks.ids[report], self._tracks.seg[report]
        # a detection's endpoints, scaled back from the detector's image, may be a pixel or
        # two past the border: what is reported lies in the image
        out_seg = clip_to_image(out_seg, gray.shape)[0]
        order = np.argsort(out_ids, kind='stable')
        t3 = tick()
        f = cv2.getTickFrequency()
        self.last_timing = {'detect': (t2 - t1) / f, 'track': ((t1 - t0) + (t3 - t2)) / f,
                            'detected': float(run_detect), 'detected_area': area}
        return out_ids[order], out_seg[order].astype(np.float32)

    def _carry(self, image: np.ndarray) -> _Frame:
        """Carry the tracks into the current frame, update their motion, grow them."""
        tr = self._tracks
        seg, carried, confirmed = carry(self._frames, image, tr.seg, tr.vel, tr.has_vel)
        vel, omega = update_motion(tr.seg, seg, carried, tr.vel, tr.omega)
        # after the velocity: growth is new extent, not motion to extrapolate
        grown = grow(image, seg, carried)
        # a line carried wholly out of view is not seen (it coasts, then retires); one partly
        # in view keeps its whole extent (the part beyond the border is what slides in next),
        # and is reported clipped to the image
        inside = clip_to_image(grown, image.shape[:2])[1]
        return _Frame(grown, seg, carried & inside, confirmed & inside, vel, omega)

    def _detect(self, gray: np.ndarray, fr: _Frame, run: bool
                ) -> Tuple[np.ndarray, Optional[np.ndarray], float]:
        """Run the detector if ``run``: (segments (D, 4) float64, clipped (D,) or None, area)."""
        if not run:
            return np.zeros((0, 4)), None, 0.0
        boxes, area = self._schedule.boxes(self._frames, self._frame, fr.seg, fr.carried)
        if boxes is None:
            return self.detector.detect(gray).astype(np.float64), None, area
        det, clipped = self.detector.detect_regions(gray, boxes)
        return det.astype(np.float64), clipped, area

    def _match(self, det: np.ndarray, clipped: Optional[np.ndarray], fr: _Frame
               ) -> np.ndarray:
        """Fuse the detections ``det`` (D, 4) into the tracks they join; return the others."""
        tr = self._tracks
        t_n = fr.seg.shape[0]
        owner, absorbed = assoc.associate(fr.seg, det, ~fr.carried, fr.confirmed)
        claimed = owner >= 0
        fuse = claimed & ~absorbed
        if clipped is not None:
            # a crop's cut of a longer tracked line would shorten the track to the crop
            fuse &= ~clipped
        if fuse.any():
            own = owner[fuse]
            fr.matched[own] = True
            fused = assoc.fuse(det[fuse], own, t_n, fr.seg)
            # tracks seen only by the detector: velocity from the previous segment
            lost = fr.matched & ~fr.carried
            fr.vel[lost] = np.where(tr.has_vel[lost, None], (fused - tr.seg)[lost], 0.0)
            fr.seg[fr.matched] = fused[fr.matched]
        if fr.carried.any():
            # the carried endpoints' displacements belong to those points: moved to the grown
            # or fused endpoints along the line
            idx = np.nonzero(fr.carried)[0]
            fr.vel[idx] = remap_velocity(fr.seg_carried[idx], fr.vel[idx], fr.seg[idx])
        return det[~claimed]

    def _advance(self, fr: _Frame, born: np.ndarray, run_detect: bool) -> np.ndarray:
        """Retire, deduplicate and give birth; return the mask of the tracks to report."""
        tr = self._tracks
        min_length = self.config.min_segment_length
        observed = fr.carried | fr.matched
        misses = np.where(observed, 0, tr.misses + 1)
        length = np.hypot(fr.seg[:, 2] - fr.seg[:, 0], fr.seg[:, 3] - fr.seg[:, 1])
        alive = (misses <= MAX_MISSES) & (length >= 0.5 * min_length)
        has_vel = (tr.has_vel | fr.carried) & alive
        if run_detect and alive.sum() > 1:
            idx = np.nonzero(alive)[0]
            alive[idx[assoc.duplicates(fr.seg[idx], tr.age[idx])]] = False
        if run_detect:
            self._schedule.after_detect(self._frame, born.shape[0], int(alive.sum()))
        if self._frame > 0 and born.shape[0] > 1:
            # parallel births within a few px: converging stripes, born once they part
            born = born[~assoc.crowded(born)]
        born = born[:max(MAX_TRACKS - int(alive.sum()), 0)]
        report = np.concatenate([(observed & (length >= min_length))[alive],
                                 np.ones(born.shape[0], bool)])
        tr.advance(alive, fr.seg, fr.vel, has_vel, misses, fr.omega, born)
        if run_detect:
            self._schedule.after_births(self._frames, tr.seg)
        return report
