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
Covariance of a 'general' body's rotation vector, published with its angular velocity.

The noise level is measured over all lines; a body the model fits worse (model error over
the window, a rotation partly explained by translation) would publish a covariance that does
not cover its error, so the covariance is widened by the body's reduced chi-square. Measured
on bench covariance (window 10, NEES of a consistent estimate: median 2.37, 95% of the frames
<= 7.81): boxes within 5% of their omega, NEES median 16-36 -> 3.3-7.8 (own-centre scenes);
camera-centre rotation (the model holds) 5.8 -> 2.5 with 92% of the frames within the 95%
bound. A box fitted in a wrong basin stays far outside (NEES 34 to 5100): that is a second
minimum, not a wider one.
"""
from typing import Optional

import numpy as np

from .jacobian import normal_equations
from .model import _costs2, LineObservations
from ..lines import orthonormal_pair


def body_covariance(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                    sigma2: float, marginal: bool = False,
                    fitted: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Return the covariance ``(3, 3)`` of a body's rotation vector from the Gauss-Newton information.

    ``sigma2``: noise variance (px^2). ``marginal``: the body was fitted with
    :func:`.marginal_residuals` at that ``sigma2`` (``t`` with its scale); the covariance is
    then also scaled by the body's reduced chi-square (its fitted-direction costs over
    ``sigma2``) when above 1; ``fitted (L,)``: those costs of the tracks ``idx`` at ``(w, t)``
    if already known (:func:`.general_costs`; NaN: fewer than 3 frames, no constraint).
    """
    if idx.size < 3:
        return np.full((3, 3), np.inf)
    rows = obs.rows[idx]
    sigma = sigma2 if marginal else None
    _, n0 = _costs2(rows, obs.m_first[idx], w, t, sigma)
    # the Gauss-Newton information with the line directions marginalised (or fitted) and the
    # moments held, analytic (:func:`.jacobian.normal_equations`), in units of sigma2
    info = normal_equations(rows, w[None], t[None], n0[None], orthonormal_pair(n0)[None],
                            sigma)[0][0]
    scale = 1.0
    if marginal:
        # the data term alone: the fitted-direction costs (px^2, two unknowns per line); the
        # marginal residuals also hold the direction prior, which does not scale with sigma2
        if fitted is None:
            fitted, _ = _costs2(rows, obs.m_first[idx], w, t, None)
        dof = float(np.sum(2.0 * obs.frames[idx] - 4.0)) - 6.0
        total = float(np.sum(np.nan_to_num(fitted, nan=0.0)))
        if dof > 0 and np.isfinite(total):
            scale = max(total / dof / sigma2, 1.0)
    try:
        return scale * sigma2 * np.linalg.pinv(info, rcond=1e-10)[:3, :3]
    except np.linalg.LinAlgError:
        return np.full((3, 3), np.inf)
