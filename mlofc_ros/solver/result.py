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
"""The solver's result type."""
from dataclasses import dataclass, field
from typing import Dict

import numpy as np


@dataclass
class SegmentationResult:
    """What :func:`mlofc_ros.solver.segment_lines` returns.

    Attributes
    ----------
    labels : (N,) int64
        Body index of every track, ``-1`` = unassigned (unusable track or outlier).
    angular_velocities : (n, 3) float64
        Rotation vector of each body per frame interval (rad per frame), camera optical frame
        (x right, y down, z forward), right-handed: the body moves relative to the camera as
        ``X' = expm([w]x) X`` (+ translation, which the rotation-only model ignores).
    angular_covariances : (n, 3, 3) float64
        Covariance of each row of ``angular_velocities`` ((rad/frame)^2) from the fit; ``inf`` on
        the diagonal when a body has too few lines to be determined.
    focal_length : float
        Focal length in pixels (given, or estimated when the intrinsics were unknown).
    residuals : (N,) float64
        RMS residual of each track under its assigned body (or under the best body for -1
        outliers), in pixels-equivalent (the Mahalanobis distance times the endpoint noise);
        ``nan`` for unusable tracks.
    costs : (N, n) float64
        Normalised cost of every track under every body (sum of squared whitened residuals).
    method : str
        The method that produced the result.
    info : dict
        Diagnostics (noise estimate, iterations, candidate costs, ...).
    """

    labels: np.ndarray
    angular_velocities: np.ndarray
    angular_covariances: np.ndarray
    focal_length: float
    residuals: np.ndarray
    costs: np.ndarray
    method: str
    info: Dict[str, object] = field(default_factory=dict)

    @property
    def n_bodies(self) -> int:
        """Number of bodies in the model."""
        return int(self.angular_velocities.shape[0])
