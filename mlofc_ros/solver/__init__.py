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
MLOFC solver: segment line tracks into rigid bodies by their rotation. Pure numpy, no ROS.

>>> from mlofc_ros.solver import segment_lines
>>> res = segment_lines(tracks, 2, intrinsics=(fx, fy, cx, cy))   # doctest: +SKIP
>>> res.labels, res.angular_velocities                            # doctest: +SKIP
"""
from .core import assign_with_motions, min_tracks_needed, segment_lines
from .methods import get_method, Method, METHODS, WarmStart
from .result import Diagnostics, SegmentationResult, StepNotTaken

__all__ = ['assign_with_motions', 'Diagnostics', 'get_method', 'Method', 'METHODS',
           'min_tracks_needed', 'segment_lines', 'SegmentationResult', 'StepNotTaken',
           'WarmStart']
