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
"""A checked segmentation problem: what every method's solve gets from :func:`.segment_lines`."""
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np


@dataclass(frozen=True)
class Problem:
    """
    The arguments of :func:`.segment_lines` that every method uses, checked.

    Attributes
    ----------
    tracks : (N, K, 4) float64
        Line tracks, NaN where a frame is missing or degenerate (endpoints equal).
    n_bodies : int
        Number of bodies (>= 1).
    intrinsics : (fx, fy, cx, cy) or None
        Pixels; None: the focal length is estimated, the principal point at the image centre.
    image_size : (w, h)
        Pixels.
    seed : int
        Seed of the random parts.

    """

    tracks: np.ndarray
    n_bodies: int
    intrinsics: Optional[Tuple[float, float, float, float]]
    image_size: Tuple[float, float]
    seed: int = 0
