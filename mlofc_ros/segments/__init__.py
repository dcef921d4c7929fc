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
"""Line segment detection: ``(u1, v1, u2, v2)`` pixel segments from gray images."""
from mlofc_ros.segments.bridge import bridge_crossings
from mlofc_ros.segments.detect import LineDetector
from mlofc_ros.segments.merge import merge_collinear, orient_by_polarity

__all__ = ['bridge_crossings', 'LineDetector', 'merge_collinear', 'orient_by_polarity']
