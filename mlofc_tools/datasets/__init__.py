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
Datasets for benchmarks: real line tracks built from public point-track benchmarks.

- :mod:`mlofc_tools.datasets.hopkins`: Hopkins155 motion-segmentation point tracks, paired into
  line tracks (two points of one rigid body span a 3D line of that body).
"""
from .hopkins import (DEFAULT_DATA_DIR, GROUPS, HopkinsSequence, line_tracks, list_sequences,
                      load_sequence, pair_points, sequence_group)

__all__ = ['DEFAULT_DATA_DIR', 'GROUPS', 'HopkinsSequence', 'line_tracks', 'list_sequences',
           'load_sequence', 'pair_points', 'sequence_group']
