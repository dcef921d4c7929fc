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
"""Line tracks: persistent ids over frames, undistortion, and the solver's sliding window."""
from mlofc_ros.tracks.config import TrackerConfig
from mlofc_ros.tracks.tracker import LineTracker
from mlofc_ros.tracks.undistort import undistort_points, undistort_segments
from mlofc_ros.tracks.window import TrackWindow

__all__ = ['LineTracker', 'TrackerConfig', 'TrackWindow', 'undistort_points',
           'undistort_segments']
