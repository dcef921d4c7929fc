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
Synthetic camera sequences of independently rotating striped boxes, with line ground truth.

:func:`render_sequence` returns a :class:`RenderedSequence` (frames, stamps, camera, angular
velocities and per-frame :class:`FrameTruth` of the visible straight edges).
"""
from mlofc_tools.render.boxes import FrameTruth, render_sequence, RenderedSequence

__all__ = ['FrameTruth', 'RenderedSequence', 'render_sequence']
