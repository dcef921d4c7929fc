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
from typing import Optional, Sequence

import numpy as np

from .fit import padded_members
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
    One body of :func:`body_covariances`.
    """
    return body_covariances(obs, [idx], np.asarray(w, dtype=float)[None],
                            np.asarray(t, dtype=float)[None], sigma2, marginal,
                            None if fitted is None else [fitted])[0]


def body_covariances(obs: LineObservations, members: Sequence[np.ndarray], W: np.ndarray,
                     T: np.ndarray, sigma2: float, marginal: bool = False,
                     fitted: Optional[Sequence[np.ndarray]] = None) -> np.ndarray:
    """
    Return :func:`body_covariance` of several bodies at once, ``(B, 3, 3)``.

    ``members``: each body's track indices; ``W, T (B, 3)`` their motions; ``fitted``: each
    body's fitted-direction costs of its tracks if known. A body with fewer than 3 tracks
    gets an infinite covariance. The bodies are evaluated in one batch, their tracks padded
    (:func:`.fit.padded_members`).
    """
    cov = np.full((len(members), 3, 3), np.inf)
    some = [b for b, m in enumerate(members) if len(m) >= 3]          # bodies, not lines
    if not some:
        return cov
    idx, mask = padded_members([members[b] for b in some])
    W, T = np.asarray(W, dtype=float)[some], np.asarray(T, dtype=float)[some]
    rows, base = obs.rows[idx], obs.m_first[idx]
    sigma = sigma2 if marginal else None
    products = obs.row_products(idx)
    _, n0 = _costs2(rows, base, W, T, sigma, products=products)
    # the Gauss-Newton information with the line directions marginalised (or fitted) and the
    # moments held, analytic (:func:`.jacobian.normal_equations`), in units of sigma2
    info = normal_equations(rows, W, T, n0, orthonormal_pair(n0), sigma, mask=mask)[0]
    scale = np.ones(len(some))
    if marginal:
        # the data term alone: the fitted-direction costs (px^2, two unknowns per line); the
        # marginal residuals also hold the direction prior, which does not scale with sigma2
        if fitted is None:
            costs = _costs2(rows, base, W, T, None, products=products)[0]
        else:
            costs = np.zeros(idx.shape)
            for i, b in enumerate(some):                              # bodies, not lines
                costs[i, :len(members[b])] = fitted[b]
        dof = np.sum(mask * (2.0 * obs.frames[idx] - 4.0), axis=1) - 6.0
        total = np.sum(np.where(mask > 0, np.nan_to_num(costs, nan=0.0), 0.0), axis=1)
        with np.errstate(invalid='ignore', divide='ignore'):
            chi2 = np.where((dof > 0) & np.isfinite(total), total / dof / sigma2, 1.0)
        scale = np.maximum(chi2, 1.0)
    for i, b in enumerate(some):                                      # bodies, not lines
        try:
            cov[b] = scale[i] * sigma2 * np.linalg.pinv(info[i], rcond=1e-10)[:3, :3]
        except np.linalg.LinAlgError:
            pass
    return cov
