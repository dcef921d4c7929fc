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

The information is that of the cost the published motion minimises (at a fraction of the
measured noise level, :data:`.general_method.PUBLISH_NOISE_SCALE`), with each line's moment
and direction eliminated (their Schur complement: the profile cost's curvature), times the
measured noise. Single bodies, 30 lines, 0.5 px, the fits over noise draws
(docs/design/general.md): a rotation about the camera, mean NEES 2.2 (honest: 3; 5.7 with
the moments held, as the LM holds them); a slow body that translates (0.5 deg per frame) is
covered far better than by the information at the measured level, whose direction prior
holds first-order information the published fit does not use (5-12x too narrow in
variance), though its fits stay biased.

The noise level is measured over all lines; a body the model fits worse (model error over
the window, a rotation partly explained by translation) would publish a covariance that does
not cover its error, so the covariance is widened by the body's reduced chi-square. Measured
when it came (the information then at the measured level, the moments held) on bench
covariance (window 10, NEES of a consistent estimate: median 2.37, 95% of the frames <=
7.81): boxes within 5% of their omega, NEES median 16-36 -> 3.3-7.8 (own-centre scenes);
camera-centre rotation (the model holds) 5.8 -> 2.5 with 92% of the frames within the 95%
bound. A box fitted in a wrong basin stays far outside (NEES 34 to 5100): that is a second
minimum, not a wider one. Where a body's rescan (the pivot starts, the Necker mirror) ends in
such minima, :func:`basin_spread` widens the covariance towards them by how likely each is.
"""
from typing import Optional, Sequence

import numpy as np

from .fit import padded_members
from .jacobian import normal_equations
from .model import _costs2, LineObservations
from ..lines import orthonormal_pair


def body_covariance(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                    sigma2: float, marginal: bool = False,
                    fitted: Optional[np.ndarray] = None,
                    fitted_at: Optional[float] = None) -> np.ndarray:
    """
    Return the covariance ``(3, 3)`` of a body's rotation vector from the Gauss-Newton information.

    ``sigma2``: noise variance (px^2). ``marginal``: the body was fitted with
    :func:`.marginal_residuals` at that ``sigma2`` (``t`` with its scale); the covariance is
    then also scaled by the body's reduced chi-square (its fitted-direction costs over
    ``sigma2``) when above 1; ``fitted (L,)``: those costs of the tracks ``idx`` at ``(w, t)``
    if already known (:func:`.general_costs`; NaN: fewer than 3 frames, no constraint).
    ``fitted_at`` (px^2): the noise level of the marginalised cost ``(w, t)`` minimise, when
    not ``sigma2`` (:func:`body_covariances`). One body of :func:`body_covariances`.
    """
    return body_covariances(obs, [idx], np.asarray(w, dtype=float)[None],
                            np.asarray(t, dtype=float)[None], sigma2, marginal,
                            None if fitted is None else [fitted], fitted_at)[0]


def body_covariances(obs: LineObservations, members: Sequence[np.ndarray], W: np.ndarray,
                     T: np.ndarray, sigma2: float, marginal: bool = False,
                     fitted: Optional[Sequence[np.ndarray]] = None,
                     fitted_at: Optional[float] = None,
                     scales_out: Optional[list] = None) -> np.ndarray:
    """
    Return :func:`body_covariance` of several bodies at once, ``(B, 3, 3)``.

    ``members``: each body's track indices; ``W, T (B, 3)`` their motions; ``fitted``: each
    body's fitted-direction costs of its tracks if known. ``fitted_at`` (px^2, marginal
    only): the noise level of the cost the motions minimise when it is not ``sigma2`` (the
    published motions: a fraction of it); the information is that cost's, the noise
    ``sigma2``. ``scales_out``: a list that receives each body's reduced chi-square scale
    ``(B,)`` (1 where none: the covariance over it is the noise's alone). A body with fewer
    than 3 tracks gets an infinite covariance. The bodies are evaluated in one batch, their
    tracks padded (:func:`.fit.padded_members`).
    """
    cov = np.full((len(members), 3, 3), np.inf)
    scales = np.ones(len(members))
    if scales_out is not None:
        scales_out.append(scales)
    some = [b for b, m in enumerate(members) if len(m) >= 3]          # bodies, not lines
    if not some:
        return cov
    idx, mask = padded_members([members[b] for b in some])
    W, T = np.asarray(W, dtype=float)[some], np.asarray(T, dtype=float)[some]
    rows, base = obs.rows[idx], obs.m_first[idx]
    sigma = (sigma2 if fitted_at is None else fitted_at) if marginal else None
    products = obs.row_products(idx)
    _, n0 = _costs2(rows, base, W, T, sigma, products=products)
    # the Gauss-Newton information with the line directions marginalised (or fitted) and the
    # moments eliminated, analytic (:func:`.jacobian.normal_equations`), in units of sigma2
    info = normal_equations(rows, W, T, n0, orthonormal_pair(n0), sigma, mask=mask,
                            moments=True)[0]
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
    scales[some] = scale
    try:
        # every body in one call; where one's SVD fails, each on its own
        cov[some] = (scale * sigma2)[:, None, None] * np.linalg.pinv(info, rcond=1e-10)[
            :, :3, :3]
    except np.linalg.LinAlgError:
        for i, b in enumerate(some):                                  # bodies, not lines
            try:
                cov[b] = scale[i] * sigma2 * np.linalg.pinv(info[i], rcond=1e-10)[:3, :3]
            except np.linalg.LinAlgError:
                pass
    return cov


#: Two fits of a body whose rotations differ by more than this share of its rate (or
#: BASIN_FLOOR rad per frame, for a still body) are two answers, not one answer's noise: the
#: accuracy a user asks of a published rate (issue #39: within 10%).
BASIN_SEPARATION = 0.1
BASIN_FLOOR = 2e-3


def basin_spread(W: np.ndarray, costs: np.ndarray, w: np.ndarray, cost: float, sigma2: float,
                 pairs: float) -> np.ndarray:
    """
    Return the covariance term ``(3, 3)`` of the other minima of a body's cost in W.

    ``W (R, 3)``: rotations (rad per frame) of fits of the body from other starts (a rescan's
    runs), ``costs (R,)`` their costs (px^2, robust, at the noise variance ``sigma2``); ``w
    (3,)``, ``cost``: the fit the body keeps. Runs further than :data:`BASIN_SEPARATION` from
    ``w`` and from each other are other minima, the cheapest run standing for each; each
    weighs ``exp(-(c - cost) / (2 sigma2 pairs))`` against 1 for the kept fit (weights
    normalised), and the term is ``sum p d d^T`` with ``d`` the minimum's offset from ``w``:
    the spread of a mixture about the published rotation. ``pairs``: the frame pairs a
    track sums (its costs add them up); a track's errors persist over the window (a line
    tracked off stays off), so a cost difference is worth about one pair's evidence, not that
    many (bench covariance, wide3, the other minima from every frame's rescan: frames with a
    30-sigma miss 27 -> 7%, the kept basin's standard deviation 1.07x; without the division
    the weights vanish and nothing changes). Zero when there is no other minimum.
    """
    W = np.asarray(W, dtype=float).reshape(-1, 3)
    costs = np.asarray(costs, dtype=float).ravel()
    w = np.asarray(w, dtype=float)
    ok = np.isfinite(costs) & np.all(np.isfinite(W), axis=1)
    order = np.argsort(costs[ok], kind='stable')
    W, costs = W[ok][order], costs[ok][order]
    apart = max(BASIN_SEPARATION * float(np.linalg.norm(w)), BASIN_FLOOR)
    minima: list = []
    for i in np.flatnonzero(np.linalg.norm(W - w, axis=1) > apart):   # runs, not lines
        if all(np.linalg.norm(W[i] - W[j]) > apart for j in minima):
            minima.append(i)
    if not minima or not (sigma2 > 0 and pairs > 0 and np.isfinite(cost)):
        return np.zeros((3, 3))
    log_p = -(costs[minima] - cost) / (2.0 * sigma2 * pairs)
    top = max(float(log_p.max()), 0.0)
    p = np.exp(log_p - top)
    p /= np.exp(-top) + p.sum()
    d = W[minima] - w
    return np.einsum('m,mi,mj->ij', p, d, d)
