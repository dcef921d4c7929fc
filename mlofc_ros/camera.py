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
Pinhole camera model with optional lens distortion, as carried by ``sensor_msgs/CameraInfo``.

Pixels are ``(u, v)`` (column, row); the camera optical frame is x right, y down, z forward.
"""
from dataclasses import dataclass, field
import math
from typing import Optional, Sequence, Tuple, Union

import numpy as np

#: Distortion models understood by :class:`CameraModel` and the number of coefficients each takes
#: (``rational_polynomial`` accepts 8, or 5 with the rational terms zero, as drivers often send).
DISTORTION_MODELS = {
    'plumb_bob': (5,),
    'rational_polynomial': (8, 5),
    'equidistant': (4,),
}


@dataclass(frozen=True)
class CameraModel:
    """
    Intrinsics ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (pixels) and distortion.

    ``d`` holds the ``sensor_msgs/CameraInfo.d`` coefficients of ``distortion_model``; empty or
    all-zero means no distortion.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    d: Tuple[float, ...] = field(default=())
    distortion_model: str = 'plumb_bob'

    def __post_init__(self) -> None:
        vals = (self.fx, self.fy, self.cx, self.cy)
        if not all(math.isfinite(float(x)) for x in vals):
            raise ValueError(f'camera intrinsics must be finite, got {vals}')
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f'focal lengths must be > 0, got fx={self.fx}, fy={self.fy}')
        d = tuple(float(x) for x in self.d)
        object.__setattr__(self, 'd', d)
        if not all(math.isfinite(x) for x in d):
            raise ValueError(f'distortion coefficients must be finite, got {d}')
        if self.has_distortion:
            sizes = DISTORTION_MODELS.get(self.distortion_model)
            if sizes is None:
                raise ValueError(
                    f'unknown distortion model {self.distortion_model!r}; '
                    f'expected one of {sorted(DISTORTION_MODELS)}')
            if len(d) not in sizes:
                raise ValueError(
                    f'distortion model {self.distortion_model!r} takes '
                    f'{" or ".join(map(str, sizes))} coefficients, got {len(d)}')

    @property
    def has_distortion(self) -> bool:
        """Return whether any distortion coefficient is non-zero."""
        return any(x != 0.0 for x in self.d)

    @property
    def intrinsics(self) -> Tuple[float, float, float, float]:
        """``(fx, fy, cx, cy)`` in pixels, as :func:`mlofc_ros.solver.segment_lines` takes it."""
        return (float(self.fx), float(self.fy), float(self.cx), float(self.cy))

    @property
    def K(self) -> np.ndarray:  # noqa: N802 (the name every vision text uses)
        """Return the 3x3 intrinsic matrix (float64)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_camera_info(cls, k: Sequence[float], d: Sequence[float],
                         distortion_model: str) -> 'CameraModel':
        """
        Build from ``CameraInfo`` fields ``k`` (9, row-major), ``d`` and ``distortion_model``.

        Raises ``ValueError`` naming the problem (K all zeros or non-finite, wrong D length,
        unknown model with non-zero D).
        """
        k = np.asarray(k, dtype=float).ravel()
        if k.size != 9:
            raise ValueError(f'CameraInfo.k must have 9 entries, got {k.size}')
        if not np.all(np.isfinite(k)):
            raise ValueError('CameraInfo.k has non-finite entries')
        if not np.any(k):
            raise ValueError('CameraInfo.k is all zeros (uncalibrated camera)')
        return cls(float(k[0]), float(k[4]), float(k[2]), float(k[5]),
                   tuple(float(x) for x in d), distortion_model or 'plumb_bob')


CameraLike = Union[CameraModel, Sequence[float], None]


def as_camera(camera: CameraLike) -> Optional[CameraModel]:
    """Accept ``None``, a :class:`CameraModel` or ``(fx, fy, cx, cy)``; return CameraModel/None."""
    if camera is None or isinstance(camera, CameraModel):
        return camera
    vals = tuple(float(x) for x in camera)
    if len(vals) != 4:
        raise ValueError(f'camera must be (fx, fy, cx, cy), got {len(vals)} values')
    return CameraModel(*vals)
