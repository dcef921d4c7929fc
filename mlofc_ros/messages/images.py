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
"""``sensor_msgs/Image`` fields for images the node publishes (no ROS)."""
from typing import Any, Dict

from mlofc_ros.image.decode import gray_to_image_fields
import numpy as np


def bgr8_fields(image: np.ndarray) -> Dict[str, Any]:
    """
    Return ``sensor_msgs/Image`` fields (all but ``header``) for a BGR image.

    Parameters
    ----------
    image : (H, W, 3) uint8
        BGR pixels, ``H, W > 0``.

    Returns
    -------
    dict
        ``height = H``, ``width = W``, ``encoding = 'bgr8'``, ``step = 3 W``,
        ``is_bigendian = 0``, ``data`` (``H * 3 W`` bytes).

    """
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3 or img.size == 0:
        raise ValueError('bgr8 image must be a non-empty (H, W, 3) uint8 array, got %s %s'
                         % (img.dtype, img.shape))
    return gray_to_image_fields(img, 'bgr8')
