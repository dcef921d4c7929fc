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
"""Image decoding: ``sensor_msgs/Image`` payloads to 8-bit grayscale (numpy + OpenCV, no ROS)."""
from mlofc_ros.image.decode import (
    as_byte_array,
    byte_length,
    encoding_info,
    EncodingInfo,
    gray_to_image_fields,
    image_msg_to_gray,
    image_to_gray,
    SUPPORTED_ENCODINGS,
    WRITABLE_ENCODINGS,
)

__all__ = [
    'EncodingInfo',
    'SUPPORTED_ENCODINGS',
    'WRITABLE_ENCODINGS',
    'as_byte_array',
    'byte_length',
    'encoding_info',
    'gray_to_image_fields',
    'image_msg_to_gray',
    'image_to_gray',
]
