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
The settings of the line tracker and its detector, as one typed, immutable object.

:meth:`TrackerConfig.from_params` builds it from the node's parameters (the table of
:mod:`mlofc_ros.params`); the benchmarks vary the few settings the node does not expose.
Everything that no user and no benchmark varies is a constant of the module that uses it.
"""
from dataclasses import dataclass, fields
from typing import Any, Mapping

from mlofc_ros.segments.backends import check_backend
from mlofc_ros.segments.detect import LineDetector


@dataclass(frozen=True)
class TrackerConfig:
    """
    Settings of :class:`~mlofc_ros.tracks.tracker.LineTracker` and its line detector.

    Lengths are pixels of the input image.

    Attributes
    ----------
    min_segment_length : float
        Shortest segment detected, reported or born, px. 10 (edges cut by stripes born on
        their pieces, then grown) tracked 0.4-2.4 points more edges but switched ids more
        often and let short tracks jump between edges at junctions (bench frontend).
    detect_every : int
        Run the detector on every n-th frame at least; tracks are carried between (frames).
        3 rather than 4: edges of faces turning into view are born a frame earlier (measured:
        own_centre tracked-5 0.897 -> 0.911, bench frontend) for ~20 % more mean CPU.
    detect_every_max : int
        Detection on demand: longest interval between detections in a quiet scene (frames);
        ``<= detect_every``: a fixed rate.
    detect_regions : bool
        In a quiet scene, detect only in the image regions where something is new.
    detector_scale : float
        The detector runs on the image resized by this factor, in (0, 1].
    detector_backend : str
        Backend of :class:`~mlofc_ros.segments.detect.LineDetector`: ``'lsd_resize'`` (the
        node's ``lsd``: LSD on the resized image), ``'lsd'`` (LSD's own sub-sampling),
        ``'fld'`` or ``'edlines'`` (opencv-contrib).
    bridge_crossings : bool
        Also find lines that other lines cross at short intervals.
    bridge_join : bool
        Join the bridged lines with the detected segments they continue (else only lines the
        backend missed altogether are added).
    lsd_bins : int
        Gradient-norm bins in which LSD orders its seed pixels (OpenCV's ``n_bins``).

    """

    min_segment_length: float = 20.0
    detect_every: int = 3
    detect_every_max: int = 12
    detect_regions: bool = False
    detector_scale: float = 0.8
    detector_backend: str = 'lsd_resize'
    bridge_crossings: bool = True
    bridge_join: bool = False
    lsd_bins: int = 1024

    def __post_init__(self) -> None:
        if not self.min_segment_length >= 0:
            raise ValueError(f'min_segment_length must be >= 0, got {self.min_segment_length}')
        if int(self.detect_every) < 1:
            raise ValueError(f'detect_every must be >= 1, got {self.detect_every}')
        if int(self.detect_every_max) < 1:
            raise ValueError(f'detect_every_max must be >= 1, got {self.detect_every_max}')
        if not 0.0 < self.detector_scale <= 1.0:
            raise ValueError(f'detector_scale must be in (0, 1], got {self.detector_scale}')
        if int(self.lsd_bins) < 1:
            raise ValueError(f'lsd_bins must be >= 1, got {self.lsd_bins}')
        check_backend(self.detector_backend)

    @classmethod
    def from_params(cls, values: Mapping[str, Any]) -> 'TrackerConfig':
        """
        Build the configuration from node parameters (names of :mod:`mlofc_ros.params`).

        Names missing from ``values`` keep their defaults; names that are no tracker setting
        (``window``, ``method``, ...) are ignored. The node's ``detector_backend`` ``'lsd'``
        is the detector's ``'lsd_resize'``.
        """
        kw = {k: values[k] for k in ('min_segment_length', 'detect_every', 'detect_every_max',
                                     'detect_regions', 'detector_scale', 'bridge_crossings')
              if k in values}
        if 'detector_backend' in values:
            kw['detector_backend'] = ('fld' if values['detector_backend'] == 'fld'
                                      else 'lsd_resize')
        types = {f.name: f.type for f in fields(cls)}
        return cls(**{k: types[k](v) for k, v in kw.items()})

    def detector_settings(self) -> tuple:
        """Return the settings the detector is built from (equal tuples: the same detector)."""
        return (self.min_segment_length, self.detector_scale, self.detector_backend,
                self.bridge_crossings, self.bridge_join, self.lsd_bins)

    def make_detector(self) -> LineDetector:
        """Build the line detector these settings describe."""
        return LineDetector(min_length=self.min_segment_length, scale=self.detector_scale,
                            backend=self.detector_backend, bridge=self.bridge_crossings,
                            bridge_join=self.bridge_join, lsd_bins=self.lsd_bins)
