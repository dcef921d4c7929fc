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
"""Message payloads the node publishes, built without ROS (numpy in, bytes / arrays out)."""
from mlofc_ros.messages.debug import BODY_PALETTE, draw_debug, label_color, MAX_TEXT_SEGMENTS
from mlofc_ros.messages.images import bgr8_fields
from mlofc_ros.messages.segments import (
    pack_segments,
    POINTFIELD_NUMPY_TYPES,
    segment_cloud_fields,
    SEGMENT_DTYPE,
    SEGMENT_FIELDS,
    SEGMENT_POINT_STEP,
    unpack_segments,
)

__all__ = [
    'BODY_PALETTE',
    'MAX_TEXT_SEGMENTS',
    'POINTFIELD_NUMPY_TYPES',
    'SEGMENT_DTYPE',
    'SEGMENT_FIELDS',
    'SEGMENT_POINT_STEP',
    'bgr8_fields',
    'draw_debug',
    'label_color',
    'pack_segments',
    'segment_cloud_fields',
    'unpack_segments',
]
