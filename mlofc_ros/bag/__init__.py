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
Bag tools: rosbag2 files (``bagfile``), offline runs (``offline``), playback (``player``).

``bagfile`` needs only ``rosbags`` (plus rclpy message packages for :func:`.bagfile.deserialize`);
``offline`` and ``player`` need rclpy. (``bagfile``, not ``io``: a module named like the standard
library's ``io`` trips flake8-builtins' A005.)
"""
from mlofc_ros.bag.bagfile import (BagError, BagMessage, BagReader, BagWriter, read_bag,
                                   write_image_bag)

__all__ = ['BagError', 'BagMessage', 'BagReader', 'BagWriter', 'read_bag', 'write_image_bag']
