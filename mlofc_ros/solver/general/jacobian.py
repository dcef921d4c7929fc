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
Gauss-Newton systems of a body's motion ``(w, T)`` from analytic derivatives.

Each line's direction enters its constraints linearly, ``r = An n0 + M u`` with ``M = Av B``
(:func:`.model._design`, ``B`` the basis of the plane orthogonal to the moment ``n0``), and
:func:`.model.marginal_residuals`' quadratic part is its minimum over ``u`` of
``|r|^2 + sigma2 |u|^2`` (Woodbury; ``sigma2 = 0``: the fitted directions). With ``n0`` held
(variable projection) the joint Gauss-Newton system in ``(w, T, u)`` reduced to the motion (Schur
complement of the ``u`` block) is ``H = sum J^T (I - M S^-1 M^T) J``, ``g = sum J^T r`` at the
optimal ``u``, ``S = M^T M + sigma2 I``; ``J`` is the derivative of the line model
``e . (R^k n0 + T_k x R^k v0)`` (``v0 = B u`` held), in closed form. The log-determinant
``sigma2 log det(S / sigma2)`` enters as the residual ``sqrt`` of itself, as in
:func:`.model._marginal_vectors`. One evaluation of the constraints and a few products per
line, instead of the 2 x 6 central differences of the residual vectors.

Derivatives: ``d(R x)/dphi = -[R x]_x J_l(phi)`` with ``J_l`` the left Jacobian of SO(3), and
``T_k = sum_{j<k} R^j T``.
"""
from typing import Optional, Tuple

import numpy as np

from .model import _apply, _design, _motion_terms
from ..lines import skew


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """Left Jacobian of SO(3) ``(..., 3, 3)`` at rotation vectors ``phi (..., 3)`` (rad)."""
    t = np.linalg.norm(phi, axis=-1)[..., None, None]
    small = t < 1e-4
    ts = np.where(small, 1.0, t)
    # (1 - cos t) / t^2 and (t - sin t) / t^3, their series near 0
    a = np.where(small, 0.5 - t * t / 24.0, (1.0 - np.cos(ts)) / ts ** 2)
    b = np.where(small, 1.0 / 6.0 - t * t / 120.0, (ts - np.sin(ts)) / ts ** 3)
    k = skew(phi)
    return np.eye(3) + a * k + b * (k @ k)


def _cross(x: list, y: list) -> list:
    """Cross product of vectors given as their three components (broadcast arrays)."""
    return [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]


def _times(x: list, m: list) -> list:
    """Return the components of ``x^T m`` for ``m`` given as ``m[i][j]`` (broadcast arrays)."""
    return [x[0] * m[0][j] + x[1] * m[1][j] + x[2] * m[2][j] for j in range(len(m[0]))]


def _entries(m: np.ndarray) -> list:
    """Return the entries ``m[i][j]`` of matrices ``(A, K, 3, 3)`` as ``(A, K, 1, 1)`` arrays."""
    return [[np.ascontiguousarray(m[:, :, i, j])[..., None, None] for j in range(3)]
            for i in range(3)]


class _Derivatives:
    """
    Per-frame terms of motions ``W, T (A, 3)`` over ``K`` frames (shared by all lines).

    Vectors are lists of their three components laid out ``(A, K, rows, L)``, lines last:
    long contiguous element-wise products instead of stacked 3x3 ones or short inner loops.
    """

    def __init__(self, W: np.ndarray, T: np.ndarray, n_frames: int) -> None:
        k = np.arange(n_frames, dtype=float)
        self.Rk, Tk = _motion_terms(W, T, n_frames)                       # (A, K, 3, 3), (A, K, 3)
        Jl = left_jacobian(W[:, None, :] * k[:, None])                  # (A, K, 3, 3)
        Rt = (self.Rk @ T[:, None, :, None])[..., 0]                    # R^j T (A, K, 3)
        dRt = -k[:, None, None] * (skew(Rt) @ Jl)                        # d(R^j T)/dw
        Dw = np.zeros_like(self.Rk)                                       # dT_k/dw
        Dw[:, 1:] = np.cumsum(dRt[:, :-1], axis=1)
        Dt = np.zeros_like(self.Rk)                                       # dT_k/dT
        Dt[:, 1:] = np.cumsum(self.Rk[:, :-1], axis=1)
        self.R = _entries(self.Rk)
        self.Jlk = _entries(-k[:, None, None] * Jl)   # d(R^k x)/dw = [R^k x]_x (-k J_l)
        self.Dw = _entries(Dw)
        self.Dt = _entries(Dt)
        self.Tk = [np.ascontiguousarray(Tk[..., i])[..., None, None] for i in range(3)]

    def rotated(self, x: list) -> list:
        """Return the components of ``R^k x`` for components ``x`` ``(A, 1, rows, L)``."""
        return _times(x, [list(r) for r in zip(*self.R)])

    def rows(self, e: list, b: list, a: Optional[list] = None, summed: bool = False) -> list:
        """
        Return ``d/d(w, T)`` of ``e . (a + T_k x b)`` with ``a = R^k n0``, ``b = R^k v0`` held.

        ``e``: the observation rows' components ``(K, 2, L)``; ``b``, ``a``: components of
        rotated vectors ``(A, K, 1 or 2, L)`` (``a`` None: no moment term). Returns the six
        derivatives' ``(A, K, 2, L)`` arrays; ``summed``: their sums over the rows and frames,
        ``(A, L)`` each.
        """
        p = _cross(_cross(e, self.Tk), b)
        if a is not None:
            p = [x + y for x, y in zip(p, _cross(e, a))]
        q = _cross(b, e)
        if summed:
            # the per-frame matrices do not depend on the row: sum the rows first
            p = [x.sum(axis=2, keepdims=True) for x in p]
            q = [x.sum(axis=2, keepdims=True) for x in q]
        jw = [x + y for x, y in zip(_times(p, self.Jlk), _times(q, self.Dw))]
        out = jw + _times(q, self.Dt)
        return [x.sum(axis=(1, 2)) for x in out] if summed else out


def _components(x: np.ndarray) -> list:
    """Return the components ``(A, 1, 1, L)`` of vectors ``x (A, L, 3)``."""
    return [np.ascontiguousarray(x[..., i])[:, None, None] for i in range(3)]


def normal_equations(rows: np.ndarray, W: np.ndarray, T: np.ndarray, n0: np.ndarray,
                     basis: np.ndarray, sigma2: Optional[float],
                     scale: Optional[np.ndarray] = None, mask: Optional[np.ndarray] = None,
                     moments: bool = False) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the reduced Gauss-Newton systems ``H (A, 6, 6)``, ``g (A, 6)`` of motions ``W, T``.

    ``rows (L, K, 2, 3)``: the tracks' whitened observation rows, or ``(A, L, K, 2, 3)`` each
    run its own; ``W, T (A, 3)``: one motion
    per run; ``n0 (A, L, 3)``: the runs' moments (held), ``basis (A, L, 3, 2)`` their
    :func:`.orthonormal_pair`. ``sigma2`` (px^2): marginalised directions at that noise (the
    log-determinant included); None: fitted directions. ``scale (L,)`` or ``(A, L)``: the
    robust cost's (:func:`.fit.robust_scale`): each line weighted by ``s / (s + q)`` at its
    current quadratic cost ``q`` (iteratively reweighted), the log-determinant not.
    ``mask (A, L)``: 1 for a run's lines, 0 for its padding (left out). Parameters:
    ``(w, T)`` in rad per frame and T's units; ``g`` is half the cost's gradient at ``n0``.
    ``moments``: each line's moment is eliminated too (its two tangent directions, ``v0``
    kept orthogonal to it), as the directions are: the information of the profile cost, whose
    inverse is the motion's covariance (at the moments that minimise the cost; the LM holds
    them instead, which is enough to step by).
    """
    L, K = rows.shape[-4], rows.shape[-3]
    A = W.shape[0]
    An, Av = _design(rows, W, T)                                          # (A, L, 2K, 3)
    r0 = _apply(An, n0)                                                   # (A, L, 2K)
    M = Av @ basis                                                        # (A, L, 2K, 2)
    MT = np.swapaxes(M, -1, -2)
    reg = 0.0 if sigma2 is None else sigma2
    S = MT @ M
    s00, s01, s11 = S[..., 0, 0] + reg, S[..., 0, 1], S[..., 1, 1] + reg
    if sigma2 is None:
        # fitted directions: nearly parallel direction columns keep a finite inverse
        tiny = 1e-12 * (s00 + s11)
        s00, s11 = s00 + tiny, s11 + tiny
    det = s00 * s11 - s01 * s01
    # a line without direction columns (seen in the first frame only, fitted directions) has
    # no direction to eliminate: its inverse is taken as zero
    Sinv = np.stack([np.stack([s11, -s01], -1), np.stack([-s01, s00], -1)], -2) / np.where(
        det > 0.0, det, np.inf)[..., None, None]                          # (A, L, 2, 2)
    u = -(Sinv @ (MT @ r0[..., None]))[..., 0]                            # (A, L, 2)
    rho = r0 + (M @ u[..., None])[..., 0]                                 # (A, L, 2K)
    v0 = (basis @ u[..., None])[..., 0]                                   # (A, L, 3)
    d = _Derivatives(W, T, K)
    e = list(np.ascontiguousarray(np.moveaxis(rows, (-1, -4), (0, -1))))  # 3 x (K, 2, L)
    J = np.stack(d.rows(e, d.rotated(_components(v0)), d.rotated(_components(n0))), axis=-1)
    J = np.ascontiguousarray(np.moveaxis(J, 3, 1)).reshape(A, L, 2 * K, 6)
    q = np.sum(rho * rho, axis=-1) + reg * np.sum(u * u, axis=-1)         # (A, L)
    wt = np.ones((A, L)) if scale is None else scale / (scale + q)
    if mask is not None:
        wt = wt * mask
    # the columns of the per-line unknowns eliminated (transposed), their regularised Gram
    # matrix's inverse
    NT, Ninv = MT, Sinv
    if moments:
        # the moment turned by basis @ d (and v0 by -n0 (v0 . basis @ d), orthogonal to it):
        # its columns join the directions', the prior on the directions only
        Jn = An @ basis - (Av @ n0[..., None]) @ (v0[..., None, :] @ basis)   # (A, L, 2K, 2)
        NT = np.swapaxes(np.concatenate([M, Jn], axis=-1), -1, -2)       # (A, L, 4, 2K)
        N2 = NT @ np.swapaxes(NT, -1, -2) + np.diag([reg, reg, 0.0, 0.0])
        # a ridge of 1e-12 of the trace: a column a line does not constrain (its G row is
        # zero) drops out as in a pseudo-inverse, at a seventh of pinv's cost
        tr = np.einsum('...ii->...', N2)
        Ninv = np.linalg.inv(N2 + (1e-12 * np.where(tr > 0.0, tr, 1.0))[..., None, None]
                             * np.eye(4))
    G = NT @ J                                                            # (A, L, 2|4, 6)
    Jw = J * wt[..., None, None]
    H = (np.swapaxes(Jw.reshape(A, -1, 6), -1, -2) @ J.reshape(A, -1, 6)
         - np.swapaxes((G * wt[..., None, None]).reshape(A, -1, 6), -1, -2)
         @ (Ninv @ G).reshape(A, -1, 6))
    g = (np.swapaxes(Jw.reshape(A, -1, 6), -1, -2) @ rho.reshape(A, -1, 1))[..., 0]
    if sigma2 is not None:
        # log-determinant sigma2 log det(S / sigma2): d = 2 sigma2 tr(S^-1 M^T dM), dM = dAv B,
        # i.e. the direction term's derivative with each row's vector y = B (S^-1 M^T)_row
        logdet = sigma2 * np.log(np.maximum(det / sigma2 ** 2, 1.0))        # (A, L)
        z = np.moveaxis((M @ Sinv).reshape(A, L, K, 2, 2), 1, -1)           # (A, K, 2, 2, L)
        B = np.moveaxis(basis, 1, -1)[:, None, None]                      # (A, 1, 1, 3, 2, L)
        y = [z[..., 0, :] * B[..., i, 0, :] + z[..., 1, :] * B[..., i, 1, :] for i in range(3)]
        dL = 2.0 * sigma2 * np.stack(d.rows(e, d.rotated(y), summed=True), axis=-1)
        live = logdet > 1e-12 * sigma2
        root = np.where(live, 1.0 / np.sqrt(np.where(live, logdet, 1.0)), 0.0)
        if mask is not None:
            root = root * mask
        jl = 0.5 * dL * root[..., None]                                   # d sqrt(logdet)
        H = H + np.swapaxes(jl, -1, -2) @ jl
        g = g + np.sum(jl * np.sqrt(np.maximum(logdet, 0.0))[..., None], axis=1)
    return H, g
