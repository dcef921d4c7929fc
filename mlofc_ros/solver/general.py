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
"""General rigid motion from lines over three or more frames (rotation AND translation).

A 3D line with Plucker moment ``n0`` and direction ``v0`` on a body moving ``X' = R X + T`` per
frame has, in frame ``k``, the moment ``n_k = R^k n0 + T_k x R^k v0`` with
``T_k = sum_{j<k} R^j T``; its image is the line with normal ``m_k ~ n_k``. For the two directions
``e`` orthogonal to the observed ``m_k``, ``e . n_k = 0``, which is LINEAR in ``(n0, v0)``::

    (R^-k e) . n0 + (R^-k (e x T_k)) . v0 = 0

``v0`` is orthogonal to ``n0``: two unknowns per line (its direction within the plane and
``1/d``; the scale of ``T`` is absorbed by ``v0``). Projecting them out leaves a 3x3 problem in
``n0`` whose smallest eigenvalue is the line's (whitened) residual: ``2K - 4`` constraints per
line, none with two frames (as it must be), six with five. With ``T = 0`` it reduces to the
rotation-only model. Per body, ``(w, T)`` are found by Levenberg-Marquardt on these residuals.

Fitting the two direction unknowns per line removes all first-order information (the
translational flow spans the line's whole flow space), which leaves bodies nearly
indistinguishable over a few frames. The segmentation therefore uses
:func:`marginal_residuals`: the direction gets a Gaussian prior scaled by the body's
translation and is integrated out (:func:`general_search`, :func:`marginal_segmentation`;
docs/design.md). Each body is also a Gaussian blob in the image (:func:`position_costs`): over
a few frames two objects may move alike, and the motion costs alone then prefer merging them
and splitting a third body.
"""
from typing import Optional, Tuple

import numpy as np

from .lines import (first_midpoints, interpretation_normals, normalise_points, orthonormal_pair,
                    rotation_matrix)

Intrinsics = Tuple[float, float, float, float]


class LineObservations:
    """Whitened observation directions of every track and frame.

    ``rows (N, K, 2, 3)``: for each frame the two directions ``e`` orthogonal to ``m_k``, scaled
    by the inverse standard deviation of ``m_k`` along them (1 px endpoint noise), so that
    ``rows . n_k / |n_k|`` has unit variance; zero where the track is missing.
    ``midpoints (N, 2)``: the midpoint of every track's first segment (px); ``rays (N, 3)``: the
    unit viewing ray through it (camera frame).
    """

    def __init__(self, tracks: np.ndarray, intrinsics: Intrinsics) -> None:
        self.intrinsics = tuple(float(x) for x in intrinsics)
        m, cov = interpretation_normals(tracks, intrinsics)
        ok = np.isfinite(m[..., 0])
        m = np.where(ok[..., None], m, np.array([0.0, 0.0, 1.0]))
        cov = np.where(ok[..., None, None], cov, np.eye(3))
        E = orthonormal_pair(m)                                      # (N, K, 3, 2)
        s = np.swapaxes(E, -1, -2) @ cov @ E                         # (N, K, 2, 2)
        val, vec = np.linalg.eigh(s)
        dirs = E @ vec                                               # principal directions
        rows = np.swapaxes(dirs, -1, -2) / np.sqrt(np.maximum(val, 1e-30))[..., None]
        self.rows = np.where(ok[..., None, None], rows, 0.0)
        self.present = ok
        self.m = m
        first = np.argmax(ok, axis=1)
        self.m_first = m[np.arange(m.shape[0]), first]
        self.frames = ok.sum(axis=1)
        self.midpoints = first_midpoints(tracks)
        rays = normalise_points(self.midpoints, intrinsics)
        self.rays = rays / np.linalg.norm(rays, axis=1, keepdims=True)

    @property
    def n_tracks(self) -> int:
        return self.rows.shape[0]

    def body_ray(self, idx: np.ndarray) -> np.ndarray:
        """Return the unit ray ``(3,)`` towards the tracks ``idx`` (camera frame)."""
        ray = self.rays[idx].sum(axis=0)
        return ray / np.linalg.norm(ray)


def _motion_terms(w: np.ndarray, t: np.ndarray, n_frames: int) -> Tuple[np.ndarray, np.ndarray]:
    """``R^k (..., K, 3, 3)`` and ``T_k (..., K, 3)``, k = 0..K-1, of motions ``w, t (..., 3)``.

    ``R^k`` is the rotation by ``k w`` (Rodrigues, one batched call rather than ``K - 1``
    sequential products) and ``T_k = sum_{j<k} R^j t``. Leading axes batch several motions:
    each gets the same products as when alone.
    """
    k = np.arange(n_frames, dtype=float)
    Rk = rotation_matrix(w[..., None, :] * k[:, None])
    Tk = np.zeros(Rk.shape[:-1])
    Tk[..., 1:, :] = np.cumsum((Rk[..., :-1, :, :] @ t[..., None, :, None])[..., 0], axis=-2)
    return Rk, Tk


def _design(rows: np.ndarray, w: np.ndarray, t: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Linear constraints of tracks with observation rows ``rows (L, K, 2, 3)`` (whitened).

    ``w, t (..., 3)``: one motion or a batch of them (leading axes ``...``). Returns
    ``An (..., L, 2K, 3)`` acting on the moment ``n0`` and ``Av (..., L, 2K, 3)`` acting on the
    direction ``v0``; both are independent of the basis of ``v0`` (:func:`_direction_columns`),
    so a second pass at the same motion reuses them.
    """
    L, K = rows.shape[0], rows.shape[1]
    Rk, Tk = _motion_terms(w, t, K)
    lead = Rk.shape[:-3]
    # (R^-k e) . n0 = e . R^k n0  ->  rows @ R^k ; e . (T_k x R^k v0) = (e x T_k) . R^k v0.
    # Written out term by term, lines last: long contiguous inner loops over the lines instead
    # of einsum's 3-long ones (3-5x faster on a batch), and the same products and sums in the
    # same order as einsum('lkji,kim->lkjm') and np.cross, so bit for bit the same result.
    rT = np.ascontiguousarray(np.moveaxis(rows, 0, -1))             # (K, 2, 3, L)
    r = [np.ascontiguousarray(rT[:, :, i, None, :]) for i in range(3)]  # (K, 2, 1, L)
    Rb = Rk[..., :, None, :, :, None]                                # (..., K, 1, 3, 3, 1)
    Tb = Tk[..., :, None, :, None]                                   # (..., K, 1, 3, 1)
    An = r[0] * Rb[..., 0, :, :] + r[1] * Rb[..., 1, :, :] + r[2] * Rb[..., 2, :, :]
    ex = [r[1] * Tb[..., 2, None, :] - r[2] * Tb[..., 1, None, :],  # e x T_k
          r[2] * Tb[..., 0, None, :] - r[0] * Tb[..., 2, None, :],
          r[0] * Tb[..., 1, None, :] - r[1] * Tb[..., 0, None, :]]
    Av = ex[0] * Rb[..., 0, :, :] + ex[1] * Rb[..., 1, :, :] + ex[2] * Rb[..., 2, :, :]
    # (..., K, 2, 3, L) -> (..., L, 2K, 3), C-contiguous as einsum's output was: the matrix
    # products downstream then take the same BLAS path per line (a strided operand would take
    # numpy's own loop, whose rounding may differ)
    An = np.ascontiguousarray(np.moveaxis(An, -1, -4)).reshape(lead + (L, 2 * K, 3))
    Av = np.ascontiguousarray(np.moveaxis(Av, -1, -4)).reshape(lead + (L, 2 * K, 3))
    return An, Av


def _direction_columns(Av: np.ndarray, base: np.ndarray,
                       basis: Optional[np.ndarray] = None) -> np.ndarray:
    """``M (..., L, 2K, 2)``: the direction columns ``Av`` in the plane orthogonal to ``base``.

    ``base (..., L, 3)``; ``basis``: its :func:`.orthonormal_pair` if already computed.
    """
    return Av @ (orthonormal_pair(base) if basis is None else basis)


def _smallest_eigenpair(C: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Smallest eigenvalue ``(...)`` and a unit eigenvector ``(..., 3)`` of ``C (..., 3, 3)``.

    ``C`` symmetric. Closed form, element-wise over the batch: the eigenvalue by the
    trigonometric formula, the eigenvector as the largest cross product of two rows of
    ``C - lam I`` (its null vector), then the eigenvalue again as that vector's Rayleigh
    quotient: accurate to rounding of the largest eigenvalue, as LAPACK's. Where the two
    smallest eigenvalues (nearly) coincide the cross products vanish; there
    :func:`_flat_eigenvector` solves in the plane orthogonal to the largest row. On batches
    of tens to hundreds of matrices (the solver's) this is 2-3x faster than
    ``np.linalg.eigh``, whose per-matrix LAPACK call dominates.
    """
    return _smallest_eigenpair_parts(C[..., 0, 0], C[..., 0, 1], C[..., 0, 2], C[..., 1, 1],
                                     C[..., 1, 2], C[..., 2, 2])


def _smallest_eigenpair_parts(a00: np.ndarray, a01: np.ndarray, a02: np.ndarray,
                              a11: np.ndarray, a12: np.ndarray, a22: np.ndarray
                              ) -> Tuple[np.ndarray, np.ndarray]:
    """:func:`_smallest_eigenpair` of the symmetric matrices with these entries ``(...)``."""
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    s01, s02, s12 = a01 * a01, a02 * a02, a12 * a12
    p = np.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (s01 + s02 + s12)) / 6.0)
    det = b00 * b11 * b22 + 2.0 * a01 * a02 * a12 - b00 * s12 - b11 * s02 - b22 * s01
    r = np.minimum(np.maximum(det / np.maximum(2.0 * p * p * p, 1e-300), -1.0), 1.0)
    lam = q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)
    c00, c11, c22 = a00 - lam, a11 - lam, a22 - lam
    # cross products of the rows (0, 1), (0, 2), (1, 2) of the symmetric C - lam I
    x = [a01 * a12 - a02 * c11, a01 * c22 - a02 * a12, c11 * c22 - a12 * a12]
    y = [a02 * a01 - c00 * a12, a02 * a02 - c00 * c22, a12 * a02 - a01 * c22]
    z = [c00 * c11 - a01 * a01, c00 * a12 - a01 * a02, a01 * a12 - c11 * a02]
    nn = [x[i] * x[i] + y[i] * y[i] + z[i] * z[i] for i in range(3)]
    vx, vy, vz, best = x[0], y[0], z[0], nn[0]
    for i in (1, 2):                                     # three candidates, not lines
        take = nn[i] > best
        vx, vy, vz = np.where(take, x[i], vx), np.where(take, y[i], vy), np.where(take, z[i], vz)
        best = np.maximum(best, nn[i])
    # cofactors (~ s1 s2, singular values of C - lam I) below 1e-6 of the squared row scale
    # (~ s1^2): C - lam I is of rank one to that precision, the two smallest eigenvalues
    # (nearly) coincide (rare: a line with about one constraint)
    rn = [c00 * c00 + s01 + s02, s01 + c11 * c11 + s12, s02 + s12 + c22 * c22]
    flat = best <= 1e-12 * np.maximum(np.maximum(rn[0], rn[1]), rn[2]) ** 2
    v = np.stack([vx, vy, vz], axis=-1)
    if np.any(flat):
        C = np.stack([np.stack([a00, a01, a02], -1), np.stack([a01, a11, a12], -1),
                      np.stack([a02, a12, a22], -1)], -2)
        v[flat] = _flat_eigenvector(C[flat], lam[flat])
    v /= np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    lam = (a00 * vx * vx + a11 * vy * vy + a22 * vz * vz
           + 2.0 * (a01 * vx * vy + a02 * vx * vz + a12 * vy * vz))
    return lam, v


def _flat_eigenvector(C: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Smallest eigenvector ``(k, 3)`` of ``C (k, 3, 3)`` whose two smallest eigenvalues meet.

    ``lam (k,)`` approximates them. The eigenvector lies in the plane orthogonal to the
    largest row of ``C - lam I``; there, a 2x2 eigenproblem picks it (LAPACK: few matrices).
    """
    B = C - lam[:, None, None] * np.eye(3)
    row = B[np.arange(B.shape[0]), np.argmax(np.sum(B * B, axis=2), axis=1)]
    row = np.where(np.any(row != 0.0, axis=1, keepdims=True), row, [1.0, 0.0, 0.0])
    plane = orthonormal_pair(row / np.linalg.norm(row, axis=1, keepdims=True))     # (k, 3, 2)
    _, vec = np.linalg.eigh(np.swapaxes(plane, 1, 2) @ C @ plane)
    return (plane @ vec[:, :, :1])[:, :, 0]


def _smallest(P: np.ndarray, base: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Smallest eigenvalue ``(..., L)`` of ``P^T P`` and its unit eigenvector ``(..., L, 3)``.

    ``P (..., L, R, 3)``; the eigenvector's sign follows ``base (..., L, 3)``.
    """
    return _toward(*_smallest_eigenpair(np.swapaxes(P, -1, -2) @ P), base)


def _toward(val: np.ndarray, n0: np.ndarray, base: np.ndarray
            ) -> Tuple[np.ndarray, np.ndarray]:
    """Eigenvalues ``(...)`` clipped at 0, unit eigenvectors ``n0 (..., 3)`` signed like ``base``.

    ``n0`` is flipped in place where it points away from ``base``.
    """
    n0 *= np.where(np.sum(n0 * base, axis=-1) < 0, -1.0, 1.0)[..., None]
    return np.maximum(val, 0.0), n0


def _apply(P: np.ndarray, n0: np.ndarray) -> np.ndarray:
    """Residual vectors ``(..., L, R)`` of constraints ``P (..., L, R, 3)`` at ``n0 (..., L, 3)``.

    Summed term by term in a fixed order: the float result is then the same for every memory
    layout and batch shape (einsum picks its summation kernel by the operands' strides), and
    the same as einsum's with the strided moments the eigensolver returns.
    """
    n0 = n0[..., None, :]
    return P[..., 0] * n0[..., 0] + P[..., 1] * n0[..., 1] + P[..., 2] * n0[..., 2]


def _line_eval(An: np.ndarray, AvB: np.ndarray, base: np.ndarray,
               fixed: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """:func:`line_residuals` from the constraints ``An``, ``AvB`` (:func:`_design`), batched."""
    # orthonormal basis of the two columns (Gram-Schmidt, vectorised), then project them out
    q1 = AvB[..., 0]
    n1 = np.linalg.norm(q1, axis=-1, keepdims=True)
    q1 = np.where(n1 > 1e-12, q1 / np.maximum(n1, 1e-300), 0.0)
    q2 = AvB[..., 1] - q1 * np.sum(q1 * AvB[..., 1], axis=-1, keepdims=True)
    n2 = np.linalg.norm(q2, axis=-1, keepdims=True)
    q2 = np.where(n2 > 1e-12 * np.maximum(n1, 1.0), q2 / np.maximum(n2, 1e-300), 0.0)
    P = An - q1[..., None] * np.einsum('...r,...rc->...c', q1, An)[..., None, :]
    P = P - q2[..., None] * np.einsum('...r,...rc->...c', q2, P)[..., None, :]
    if fixed is not None:
        return _apply(P, fixed), fixed
    return _smallest(P, base)


#: Gram blocks of constraints (:func:`_grams`): ``{'nn', 'vn', 'vv'}`` -> 3 x 3 nested lists
#: of arrays ``(..., L)``, the entries of ``An^T An``, ``Av^T An`` and ``Av^T Av``.
Grams = dict


def _grams(An: np.ndarray, Av: np.ndarray) -> Grams:
    """:data:`Grams` of :func:`_design`'s output ``(..., L, 2K, 3)``.

    They hold all that the marginalised cost needs of the ``2K x 3`` constraints, whatever the
    basis of ``v0``: two passes at the same motion (:func:`_costs2`) share them.
    """
    AnT, AvT = np.swapaxes(An, -1, -2), np.swapaxes(Av, -1, -2)
    out = {}
    for key, g in (('nn', AnT @ An), ('vn', AvT @ An), ('vv', AvT @ Av)):
        out[key] = [[g[..., i, j] for j in range(3)] for i in range(3)]
    return out


def _marginal_costs(grams: Grams, base: np.ndarray, sigma2: float,
                    basis: Optional[np.ndarray] = None, logdet_out: Optional[list] = None
                    ) -> Tuple[np.ndarray, np.ndarray]:
    """:func:`marginal_residuals`' costs ``(..., L)`` and moments ``(..., L, 3)`` from grams.

    With the whitened direction columns ``M = Av B / sqrt(sigma2)`` (``B`` the basis of the
    plane orthogonal to ``base``, :func:`.orthonormal_pair` or ``basis``) and ``S = M^T M``
    (2x2 per line), the cost's quadratic form is
    ``An^T (I + M M^T)^-1 An = An^T An - G^T (I + S)^-1 G`` with ``G = M^T An`` (Woodbury),
    and the log-determinant ``log det(I + S)``: no ``2K x 3`` products, a few 3x3 and 2x2
    ones per line, written out element-wise over the batch (stacked 3x3 matrix products cost
    several times more at the solver's batch sizes).
    """
    B = orthonormal_pair(base) if basis is None else basis          # (..., L, 3, 2)
    b = [[B[..., i, c] for i in range(3)] for c in range(2)]        # b[c][i]: column c
    nn, vn, vv = grams['nn'], grams['vn'], grams['vv']
    # Av^T Av B and B^T Av^T An, column by column
    vvb = [[vv[i][0] * b[c][0] + vv[i][1] * b[c][1] + vv[i][2] * b[c][2] for i in range(3)]
           for c in range(2)]
    S = [[(b[c][0] * vvb[e][0] + b[c][1] * vvb[e][1] + b[c][2] * vvb[e][2]) / sigma2
          for e in range(2)] for c in range(2)]
    root = 1.0 / np.sqrt(sigma2)
    G = [[(b[c][0] * vn[0][j] + b[c][1] * vn[1][j] + b[c][2] * vn[2][j]) * root
          for j in range(3)] for c in range(2)]
    s00, s01, s11 = 1.0 + S[0][0], 0.5 * (S[0][1] + S[1][0]), 1.0 + S[1][1]
    # det(I + S) >= 1 (rounding could take it below, then its log's root would be NaN)
    det = np.maximum(s00 * s11 - s01 * s01, 1.0)
    logdet = sigma2 * np.log(det)
    if logdet_out is not None:
        logdet_out.append(logdet)
    # X = (I + S)^-1 G, the 2x2 inverse written out; C = An^T An - G^T X
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    X = [[i00 * G[0][j] + i01 * G[1][j] for j in range(3)],
         [i01 * G[0][j] + i11 * G[1][j] for j in range(3)]]
    C = {(i, j): nn[i][j] - G[0][i] * X[0][j] - G[1][i] * X[1][j]
         for i in range(3) for j in range(i, 3)}
    val, n0 = _smallest_eigenpair_parts(C[0, 0], C[0, 1], C[0, 2], C[1, 1], C[1, 2], C[2, 2])
    val, n0 = _toward(val, n0, base)
    return val + logdet, n0


def _marginal_vectors(An: np.ndarray, M: np.ndarray, fixed: np.ndarray, sigma2: float,
                      logdet_out: Optional[list] = None) -> np.ndarray:
    """:func:`marginal_residuals`' residual vectors ``(..., L, 2K + 1)`` at moments ``fixed``.

    ``An``, ``M``: the constraints and direction columns (:func:`_design`,
    :func:`_direction_columns`). The vector is ``(I + M M^T)^-1/2 An n0`` (``M`` whitened)
    and the root of the log-determinant. ``(I + M M^T)^-1/2 = I - M H M^T`` with
    ``H = V diag(g) V^T`` for ``S = M^T M = V diag(s) V^T`` and
    ``g = (1 - 1/q) / s = 1 / (q (1 + q))``, ``q = sqrt(1 + s)``; with the eigenvalues
    ``lo <= hi`` of ``S`` in closed form and ``u`` its top unit eigenvector,
    ``H = g_lo I + (g_hi - g_lo) u u^T``, ``u u^T = (I + [[c, t], [t, -c]]) / 2`` where
    ``(c, t) = (S00 - S11, 2 S01) / (2 d)``.
    """
    M = M / np.sqrt(sigma2)
    m0, m1 = M[..., 0], M[..., 1]
    a, b, c = np.sum(m0 * m0, axis=-1), np.sum(m0 * m1, axis=-1), np.sum(m1 * m1, axis=-1)
    logdet = sigma2 * np.log(np.maximum((1.0 + a) * (1.0 + c) - b * b, 1.0))   # det(I + S)
    if logdet_out is not None:
        logdet_out.append(logdet)
    half, mid = 0.5 * (a - c), 0.5 * (a + c)
    d = np.hypot(half, b)
    q_lo, q_hi = np.sqrt(1.0 + np.maximum(mid - d, 0.0)), np.sqrt(1.0 + mid + d)
    g_lo, g_hi = 1.0 / (q_lo * (1.0 + q_lo)), 1.0 / (q_hi * (1.0 + q_hi))
    g_mid = 0.5 * (g_lo + g_hi)
    g_off = 0.5 * (g_hi - g_lo) / np.where(d > 0.0, d, 1.0)
    r = _apply(An, fixed)                                           # (..., L, R)
    t0, t1 = np.sum(m0 * r, axis=-1), np.sum(m1 * r, axis=-1)       # M^T r
    u0 = (g_mid + g_off * half) * t0 + g_off * b * t1               # H M^T r
    u1 = g_off * b * t0 + (g_mid - g_off * half) * t1
    r = r - m0 * u0[..., None] - m1 * u1[..., None]
    return np.concatenate([r, np.sqrt(logdet)[..., None]], axis=-1)


def _evaluate(An: np.ndarray, Av: np.ndarray, base: np.ndarray, sigma2: Optional[float],
              fixed: Optional[np.ndarray] = None, basis: Optional[np.ndarray] = None,
              logdet_out: Optional[list] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Costs and moments (or residual vectors at ``fixed``) from :func:`_design`'s output.

    ``sigma2`` None: :func:`line_residuals`, else :func:`marginal_residuals`; every array may
    carry leading batch axes.
    """
    if sigma2 is not None and fixed is None:
        return _marginal_costs(_grams(An, Av), base, sigma2, basis, logdet_out)
    M = _direction_columns(Av, base, basis)
    if sigma2 is None:
        return _line_eval(An, M, base, fixed)
    return _marginal_vectors(An, M, fixed, sigma2, logdet_out), fixed


def line_residuals(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                   n0: Optional[np.ndarray] = None, fixed: Optional[np.ndarray] = None
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """Whitened residual ``(L,)`` (sum of squares) and moment direction ``n0 (L, 3)``.

    ``idx``: tracks to evaluate; ``n0``: current moment estimates, whose orthogonal plane
    holds ``v0`` (defaults to the first observed normal). With ``fixed (L, 3)`` the moments are
    not re-solved: the projected residual VECTORS ``(L, 2K)`` at those moments are returned
    instead of the minimal costs (for Gauss-Newton by variable projection).
    """
    base = obs.m_first[idx] if n0 is None else n0
    An, Av = _design(obs.rows[idx], w, t)
    return _evaluate(An, Av, base, None, fixed)


def marginal_residuals(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                       sigma2: float, n0: Optional[np.ndarray] = None,
                       fixed: Optional[np.ndarray] = None, logdet_out: Optional[list] = None
                       ) -> Tuple[np.ndarray, np.ndarray]:
    """Cost ``(L,)`` with each line's direction MARGINALISED, not fitted (1 px units).

    The direction ``v0`` (two unknowns per line, in the plane orthogonal to ``n0``) is given
    the prior ``N(0, I)`` and integrated out, with ``t`` (3,) a translation per frame whose
    length is the body's scale of ``|T| / d`` (``d`` the line's distance to the camera centre,
    rad per frame). The residuals are then Gaussian with covariance ``sigma2 I + M M^T``
    (``M`` the whitened direction columns), and the cost is ``sigma2`` times its negative
    log-likelihood (up to a constant)::

        r^T (I + M M^T / sigma2)^-1 r + sigma2 log det(I + M^T M / sigma2),  r = An n0

    minimised over the unit moment ``n0`` (a 3x3 eigenproblem, as in :func:`line_residuals`).
    ``t = 0`` is the rotation-only model; ``|t| -> inf`` tends to the fitted-direction model of
    :func:`line_residuals` plus a log-determinant. Unlike that model, a line's first-order
    flow still counts: a body explains large per-line translational flows only at the price
    of a large ``|t|``, paid by every line through the log-determinant.

    ``sigma2``: endpoint noise variance (px^2). With ``fixed (L, 3)`` returns residual VECTORS
    ``(L, 2K + 1)`` whose squares sum to the cost at those moments (for Gauss-Newton).
    ``logdet_out``: a list that receives the log-determinant term ``(L,)`` (included in the
    cost).
    """
    base = obs.m_first[idx] if n0 is None else n0
    An, Av = _design(obs.rows[idx], w, t)
    return _evaluate(An, Av, base, sigma2, fixed, logdet_out=logdet_out)


def _costs2(rows: np.ndarray, base: np.ndarray, w: np.ndarray, t: np.ndarray,
            sigma2: Optional[float], basis: Optional[np.ndarray] = None,
            logdet_out: Optional[list] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Costs ``(..., L)`` and moments after two passes (the v0-plane basis follows the moment).

    ``rows (L, K, 2, 3)``: the tracks' observation rows; ``w, t (..., 3)`` one motion or a
    batch; ``base (L, 3)`` or ``(..., L, 3)`` the first pass's moments, ``basis`` their
    :func:`.orthonormal_pair` if known. Both passes share the motion's constraints.
    ``logdet_out``: a list that receives the second pass's log-determinant terms (marginalised).
    """
    if sigma2 is None:
        An, Av = _design(rows, w, t)
        _, n0 = _evaluate(An, Av, base, None, basis=basis)
        return _evaluate(An, Av, n0, None)
    grams = _grams(*_design(rows, w, t))
    _, n0 = _marginal_costs(grams, base, sigma2, basis)
    return _marginal_costs(grams, n0, sigma2, logdet_out=logdet_out)


def _tangent(t: np.ndarray) -> np.ndarray:
    """Two unit vectors ``(2, 3)`` orthogonal to the unit vector ``t``."""
    return np.swapaxes(orthonormal_pair(t[None])[0], 0, 1)


#: Scale of the robust per-line cost (:func:`_robust_costs`), in units of a line's median cost
#: at the noise level: ``sigma2`` times the chi-square median of its ``2 K - 4`` degrees of
#: freedom. Spinning benchmark (session 9 diagnosis, own3 seed 3, a box's true lines): a few
#: tracks cost 20-50x the median under the true motion and make a wrong basin cheaper; with
#: each line's cost bounded near 4x the median the true basin is cheaper.
ROBUST_SCALE = 4.0


def robust_scale(frames: np.ndarray, sigma2: float) -> np.ndarray:
    """Per-line scale ``(L,)`` of the robust cost for tracks seen in ``frames (L,)``.

    :data:`ROBUST_SCALE` times the median cost of a line at the noise variance ``sigma2``
    (px^2): ``sigma2`` times the chi-square median with ``2 K - 4`` degrees of freedom.
    """
    from .models import chi2_quantile
    dof = np.maximum(2.0 * np.asarray(frames, dtype=float) - 4.0, 1.0)
    return ROBUST_SCALE * sigma2 * chi2_quantile(0.5, dof)


def _robust_costs(res: np.ndarray, logdet: Optional[np.ndarray], scale: np.ndarray
                  ) -> np.ndarray:
    """Cauchy line costs ``s log(1 + q / s)`` (plus the log-determinant), same shape as ``res``.

    ``res (..., L)``: line costs; ``logdet``: their log-determinant parts (marginalised
    directions; None for fitted ones), which stay as they are: only the residual part ``q``
    is robust. ``scale (L,)``: :func:`robust_scale`. A line at the median costs about 0.9 of
    its plain cost, one at 50x the median about 10 medians instead of 50.
    """
    q = res if logdet is None else np.maximum(res - logdet, 0.0)
    out = scale * np.log1p(q / scale)
    return out if logdet is None else out + logdet


def _totals(rows: np.ndarray, base: np.ndarray, w: np.ndarray, t: np.ndarray,
            sigma2: Optional[float], scale: Optional[np.ndarray],
            basis: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """:func:`_costs2` with the line costs made robust when ``scale`` is given."""
    if scale is None:
        return _costs2(rows, base, w, t, sigma2, basis)
    parts: list = []
    res, n0 = _costs2(rows, base, w, t, sigma2, basis, parts if sigma2 is not None else None)
    return _robust_costs(res, parts[0] if parts else None, scale), n0


#: LM step tries per lockstep round of the line search (8 in all, the damping x5 per try;
#: the first success counts, later tries of the round are wasted). The first try succeeds in
#: ~85% of the iterations; after a failure ~3/4 succeed within three more. One batched call
#: for several tries costs little more than one: on Hopkins155 and pipeline windows (1, 3, 4)
#: was ~5% faster than one try per round, (1, 7) no faster.
_TRIES = (1, 3, 4)

#: Largest batch (motions x tracks x frames) of the start scan's cost evaluations: bounds the
#: temporaries (a few tens of floats per unit).
_BATCH = 50000


def _scan_costs(rows: np.ndarray, base: np.ndarray, w: np.ndarray, T: np.ndarray,
                sigma2: Optional[float], scale: Optional[np.ndarray] = None) -> list:
    """Total two-pass cost of the tracks ``rows`` at each motion ``(w, T)``.

    ``T (C, 3)``; ``w (3,)`` for all of them or ``(C, 3)``, one per candidate. ``scale``: the
    robust per-line cost's (:func:`robust_scale`), None for least squares.
    """
    size = max(1, _BATCH // max(rows.shape[0] * rows.shape[1], 1))
    w = np.broadcast_to(w, T.shape)
    out: list = []
    for s in range(0, T.shape[0], size):                 # chunks of many candidates
        res, _ = _totals(rows, base, w[s:s + size], T[s:s + size], sigma2, scale)
        out += [r.sum() for r in res]                    # per candidate: a sum as in a loop
    return out


def _lm_runs(obs: LineObservations, idx: np.ndarray, W0: np.ndarray, T0: np.ndarray,
             iterations: int, sigma2: Optional[float], robust: Optional[float] = None
             ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Independent :func:`fit_body` runs from ``(W0, T0) (S, 3)`` on the same tracks.

    Returns ``W (S, 3)``, ``T (S, 3)`` and costs ``(S,)``. The runs advance in lockstep so that
    every numpy call serves all of them (and, for the Jacobian, its 2 x 5 or 2 x 6 central
    differences too): each call is dominated by its fixed overhead at these sizes (tens of
    tracks), so one batched call costs little more than a single evaluation. Each run takes
    exactly the steps it takes alone: the batched operations repeat its products per motion.

    ``robust`` (px^2, a noise variance): minimise the robust cost of :func:`_robust_costs` at
    :func:`robust_scale` of that variance instead of the sum of squares, by iteratively
    reweighted Gauss-Newton (each line's residuals and Jacobian rows weighted by the Cauchy
    weight ``s / (s + q)`` of its current cost ``q``); steps are accepted on the robust cost,
    which is also the cost returned.
    """
    rows = obs.rows[idx]                                 # gathered once for all evaluations
    scale = None if robust is None else robust_scale(obs.frames[idx], robust)
    free = sigma2 is not None
    n_run = W0.shape[0]
    W = np.array(W0, dtype=float)
    T = np.array(T0, dtype=float)
    if not free:
        for s in range(n_run):                           # a few runs, not lines
            nt = np.linalg.norm(T[s])
            T[s] = T[s] / nt if nt > 1e-12 else np.array([0.0, 0.0, 1.0])
    res, n0 = _totals(rows, obs.m_first[idx], W, T, sigma2, scale)
    cost = [float(r.sum()) for r in res]
    lam, h = [1e-3] * n_run, 1e-6
    n_par = 6 if free else 5
    # parameter offsets of the Jacobian (+-h per parameter) and the residual itself (row 0).
    # Forward differences would halve the probes (a warm frame ~15% faster), but on the
    # spinning benchmark they moved three runs into wrong basins that central ones avoid
    # (own2+bg render seeds 3 and 6, own3+bg seed 2; session 24)
    probe = np.zeros((1 + 2 * n_par, n_par))
    probe[1::2, :][np.arange(n_par), np.arange(n_par)] = h
    probe[2::2, :][np.arange(n_par), np.arange(n_par)] = -h
    active = np.arange(n_run)                            # runs still iterating
    for _ in range(iterations):
        if active.size == 0:
            break
        bases = [np.eye(3) if free else _tangent(T[s]) for s in active]

        def moved(a: int, x: np.ndarray) -> np.ndarray:
            tt = T[active[a]] + x[3:] @ bases[a]
            return tt if free else tt / np.linalg.norm(tt)
        Wp = W[active, None, :] + probe[:, :3]                     # (A, Q, 3)
        if free:
            # t + x @ I is exactly t + x: at most one non-zero product per element
            Tp = T[active, None, :] + probe[:, 3:]
        else:
            Tp = np.stack([[moved(a, x) for x in probe]             # runs x probes, not lines
                           for a in range(active.size)])
        n0a = n0[active]
        basis = orthonormal_pair(n0a)                   # shared by probes and the next pass
        An, Av = _design(rows, Wp, Tp)
        r = _evaluate(An, Av, n0a[:, None], sigma2, n0a[:, None], basis[:, None])[0]
        if scale is not None:
            # IRLS: each line's residual rows (not the log-determinant) weighted by the root
            # of its Cauchy weight at the current motion, the same for every probe
            nq = r.shape[-1] - (1 if free else 0)
            q = np.sum(r[:, 0, :, :nq] ** 2, axis=-1)                   # (A, L)
            r = r.copy()
            r[..., :nq] *= np.sqrt(scale / (scale + q))[:, None, :, None]
        r = r.reshape(active.size, probe.shape[0], -1)
        systems = []
        for a in range(active.size):                     # a few runs, not lines
            # C order, as the column-by-column fill was: J^T J runs the same BLAS kernel
            J = np.ascontiguousarray(((r[a, 1::2] - r[a, 2::2]) / (2.0 * h)).T)
            systems.append((J.T @ J, J.T @ r[a, 0]))
        searching, accepted = list(range(active.size)), {}
        for n_try in _TRIES:
            if not searching:
                break
            cand = []                                    # (run position, step, damping)
            for a in searching:                          # a few runs and tries, not lines
                H, g = systems[a]
                lam_a = lam[active[a]]
                for _ in range(n_try):
                    step = -np.linalg.solve(H + lam_a * (np.diag(np.diag(H))
                                                         + 1e-12 * np.eye(n_par)), g)
                    cand.append((a, step, lam_a))
                    lam_a *= 5.0
            pos = [a for a, _, _ in cand]
            cw = np.array([W[active[a]] + step[:3] for a, step, _ in cand])
            ct = np.array([moved(a, step) for a, step, _ in cand])
            rn, n0n = _totals(rows, n0a[pos], cw, ct, sigma2, scale, basis[pos])
            for i, (a, step, lam_a) in enumerate(cand):  # each run's tries in order
                s = active[a]
                if a in accepted:
                    continue
                c = rn[i].sum()
                if c < cost[s]:
                    W[s], T[s], n0[s], cost[s] = cw[i], ct[i], n0n[i], float(c)
                    lam[s] = max(lam_a / 5.0, 1e-12)
                    accepted[a] = step
                else:
                    lam[s] = lam_a * 5.0
            searching = [a for a in searching if a not in accepted]
        active = active[[a for a in range(active.size)
                         if a in accepted and not np.linalg.norm(accepted[a]) < 1e-12]]
    return W, T, np.array(cost)


def fit_body(obs: LineObservations, idx: np.ndarray, w0: np.ndarray, t0: np.ndarray,
             iterations: int = 15, sigma2: Optional[float] = None,
             robust: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray, float]:
    """Levenberg-Marquardt on ``(w, T)`` for the tracks ``idx``; returns w, T, cost.

    Variable projection: the per-line unknowns are eliminated, the Jacobian is taken of every
    line's projected residual vector (central differences, moments held fixed, all evaluated
    in one batch: :func:`_lm_runs`). With ``sigma2`` None (fitted line directions,
    :func:`line_residuals`) T is a unit vector that moves in its tangent plane (five
    parameters, no gauge freedom); with ``sigma2`` (px^2, marginalised directions,
    :func:`marginal_residuals`) T is free (six parameters, its length is the body's
    translation scale). ``robust`` (px^2): the robust cost at that noise level
    (:func:`_lm_runs`).
    """
    W, T, cost = _lm_runs(obs, idx, np.atleast_2d(np.asarray(w0, dtype=float)),
                          np.atleast_2d(np.asarray(t0, dtype=float)), iterations, sigma2,
                          robust)
    return W[0], T[0], float(cost[0])


def _hemisphere(n: int = 32, whole: bool = False) -> np.ndarray:
    """Spread ``(n, 3)`` directions over a hemisphere, or the ``whole`` sphere (Fibonacci).

    The cost depends on T only through its span, so T and -T are the same start.
    """
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n if whole else k / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


#: Translation directions scanned for a body without a previous estimate.
T_STARTS = _hemisphere()


#: Translation scales ``|T| / d`` (rad per frame) scanned with the marginalised directions.
T_SCALES = np.geomspace(3e-4, 0.3, 7)


#: Rates (rad per frame) of the pivot starts: six, 0.3 to 9 degrees per frame.
PIVOT_RATES = np.geomspace(0.005, 0.16, 6)

#: Rotation vectors (rad per frame) of the pivot starts (:func:`pivot_starts`): 64 axes over
#: the whole sphere (the sign of W matters there, T follows from it) at each of
#: :data:`PIVOT_RATES` (axis-major: start ``i`` turns at rate ``i % 6``).
PIVOT_W = (_hemisphere(64, whole=True)[:, None, :] * PIVOT_RATES[:, None]).reshape(-1, 3)

#: LM runs started from the best pivot starts of the scan (besides the ``keep`` others).
PIVOT_KEEP = 4


def pivot_picks(scan: np.ndarray, per_rate: bool = False) -> np.ndarray:
    """Return the indices of the pivot starts to refine, given their scan costs ``(C,)``.

    The :data:`PIVOT_KEEP` cheapest, or with ``per_rate`` the cheapest of each rate of
    :data:`PIVOT_RATES` (which holds the cheapest of all). Before any LM step a fast start
    costs more than a slow one whose translation explains the flow (the scan's T is only the
    pivot's), so the global ranking favours the slow starts, from which LM slides into a
    nearly static fit: on a box spinning at 138 deg/s (own2+bg, render seed 4, frame 12 of
    the rescan) 9 of the 384 starts reach its motion, the first of them ranked 117th by the
    scan (41st after 3 LM iterations from all), but 1st among the starts at its rate.
    """
    scan = np.asarray(scan, dtype=float)
    if not per_rate:
        return np.argsort(scan)[:PIVOT_KEEP]
    k = PIVOT_RATES.size
    return np.argmin(scan.reshape(-1, k), axis=0) * k + np.arange(k)


def pivot_starts(ray: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Motions ``W, T (C, 3)`` of a body turning about a point on the unit ``ray`` (3,).

    An object that spins about its own centre ``C`` (a box turned on a table, a wheel) moves
    as ``X' = R (X - C) + C``, so ``T = C - R C``: its image barely moves, and the
    rotation-only fit, which sees a camera-centred rotation, is no start for W at all (its
    translation cancels most of the rotation's flow). Here ``C`` is taken on the ray through
    the body's lines at their distance (T in units of it, as the marginalised model's scale),
    for every rotation of :data:`PIVOT_W`.
    """
    return PIVOT_W, _pivot_translation(PIVOT_W, ray)


def _pivot_translation(w: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Return ``c - R c`` ``(..., 3)``: the translation of a turn ``w (..., 3)`` about ``c``."""
    return c - rotation_matrix(w) @ c


def fit_body_multistart(obs: LineObservations, idx: np.ndarray, w0: np.ndarray,
                        t0: Optional[np.ndarray] = None, iterations: int = 15,
                        keep: int = 3, sigma2: Optional[float] = None,
                        ray: Optional[np.ndarray] = None, pivots: bool = True,
                        robust: Optional[float] = None, per_rate: bool = False
                        ) -> Tuple[np.ndarray, np.ndarray, float]:
    """Run :func:`fit_body` from the ``keep`` best starts of a scan at ``w0``.

    Fitted directions (``sigma2`` None): from ``t0``, or the best of :data:`T_STARTS` (the cost
    is not convex in the direction of T). Marginalised directions: the direction of ``t0``
    (else :data:`T_STARTS`) at every scale of :data:`T_SCALES`, ``t0`` itself and T = 0.
    With ``ray`` (unit, camera frame: towards the body's lines), also from the
    :data:`PIVOT_KEEP` best of :func:`pivot_starts` (when ``pivots``; with ``per_rate`` the
    best of each rate instead, :func:`pivot_picks`), and the winner's :func:`necker_mirror`
    is tried too. The cheapest run wins. ``robust`` (px^2): scans, fits and comparisons on
    the robust cost at that noise level (:func:`_lm_runs`).
    """
    rows, base = obs.rows[idx], obs.m_first[idx]
    scale = None if robust is None else robust_scale(obs.frames[idx], robust)
    if sigma2 is None and t0 is not None:
        starts = np.atleast_2d(t0)
    else:
        if sigma2 is None:
            cands = T_STARTS
        else:
            dirs = T_STARTS
            extra = [np.zeros((1, 3))]
            if t0 is not None and np.linalg.norm(t0) > 0:
                dirs = np.atleast_2d(t0) / np.linalg.norm(t0)
                extra.append(np.atleast_2d(t0))
            cands = np.concatenate(extra + [(dirs[:, None, :] * T_SCALES[:, None]
                                             ).reshape(-1, 3)])
        scan = _scan_costs(rows, base, np.asarray(w0, dtype=float), cands,
                           sigma2, scale)                # a few hundred starts, vectorised
        starts = cands[np.argsort(scan)[:keep]]
    w_starts = None
    if ray is not None and pivots:
        pw, pt = pivot_starts(np.asarray(ray, dtype=float))
        best = pivot_picks(_scan_costs(rows, base, pw, pt, sigma2, scale), per_rate)
        w_starts = np.concatenate([np.broadcast_to(np.asarray(w0, dtype=float), starts.shape),
                                   pw[best]])
        starts = np.concatenate([starts, pt[best]])
    fit = _best_fit(obs, idx, w0, starts, iterations, sigma2, w_starts, robust)
    return fit if ray is None else _necker_check(obs, idx, fit, ray, iterations, sigma2, robust)


def necker_mirror(w: np.ndarray, ray: np.ndarray) -> np.ndarray:
    """Rotation vector ``(3,)`` of the depth-reversed motion of ``w`` seen along unit ``ray``.

    Under (weak) perspective, an object turning by ``w`` and its mirror image in the plane
    orthogonal to the line of sight, turning by ``2 (w . r) r - w``, give nearly the same
    images (the Necker reversal); only perspective tells them apart. On small objects the
    LM lands in the wrong one of the two basins as often as not.
    """
    return 2.0 * float(w @ ray) * ray - w


def _necker_check(obs: LineObservations, idx: np.ndarray,
                  fit: Tuple[np.ndarray, np.ndarray, float], ray: np.ndarray, iterations: int,
                  sigma2: Optional[float], robust: Optional[float] = None
                  ) -> Tuple[np.ndarray, np.ndarray, float]:
    """Return ``fit`` or the LM run from its :func:`necker_mirror`, whichever is cheaper."""
    w = necker_mirror(fit[0], ray)
    t = _pivot_translation(w, ray)                       # the mirror turns about the pivot too
    if sigma2 is None:
        t = t * (np.linalg.norm(fit[1]) / max(np.linalg.norm(t), 1e-300))
    W, T, cost = _lm_runs(obs, idx, w[None], t[None], iterations, sigma2, robust)
    return (W[0], T[0], float(cost[0])) if cost[0] < fit[2] else fit


def polish_body(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                iterations: int, sigma2: float, robust: Optional[float] = None
                ) -> Tuple[np.ndarray, np.ndarray, float]:
    """Refit a segmented body at the measured noise ``sigma2``: LM from ``(w, t)`` and its mirror.

    The segmentation's noise level is inflated (:data:`NOISE_FACTOR`), which flattens the cost
    in W; at the measured noise the depth-reversed motion (:func:`necker_mirror`) may fit
    better, so an LM run from it goes beside the one from ``(w, t)`` (and from T = 0, as in
    every :func:`_best_fit`) and the cheapest wins. ``robust``: as in :func:`_lm_runs`.
    """
    fit = _best_fit(obs, idx, w, np.atleast_2d(t), iterations, sigma2, robust=robust)
    return _necker_check(obs, idx, fit, obs.body_ray(idx), iterations, sigma2, robust)


def _best_fit(obs: LineObservations, idx: np.ndarray, w0: np.ndarray, starts: np.ndarray,
              iterations: int, sigma2: Optional[float], w_starts: Optional[np.ndarray] = None,
              robust: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray, float]:
    """Run :func:`fit_body` from ``w0`` and each T of ``starts (S, 3)``; the cheapest wins.

    ``w_starts (S, 3)``: a rotation per start instead of ``w0`` for all. With marginalised
    directions (``sigma2``) T = 0 (at ``w0``) is always one of the starts: the cost is even in
    T, so T = 0 is stationary and no LM run started at another T returns to it.
    """
    w0 = np.asarray(w0, dtype=float)
    W0 = np.broadcast_to(w0, starts.shape) if w_starts is None else w_starts
    if sigma2 is not None and np.all(np.any(starts != 0.0, axis=1)):
        starts = np.concatenate([starts, np.zeros((1, 3))])
        W0 = np.concatenate([W0, w0[None]])
    W, T, cost = _lm_runs(obs, idx, W0, starts, iterations, sigma2, robust)  # in lockstep
    best = 0
    for s in range(1, cost.size):                        # a few starts, not lines
        if cost[s] < cost[best]:
            best = s
    return W[best], T[best], float(cost[best])


def general_costs(obs: LineObservations, W: np.ndarray, T: np.ndarray,
                  sigma2: Optional[float] = None) -> np.ndarray:
    """Cost ``(N, n)`` of every track under every body ``(W (n, 3), T (n, 3))``.

    ``sigma2`` None: fitted line directions (:func:`line_residuals`, unit T); else
    marginalised (:func:`marginal_residuals`, T with its scale, ``sigma2`` px^2).
    ``nan`` for tracks with fewer than 3 frames (no constraint on a general motion).
    """
    # all bodies in one batch
    out = np.ascontiguousarray(_costs2(obs.rows, obs.m_first, W, T, sigma2)[0].T)
    out[obs.frames < 3] = np.nan
    return out


def spatial_labels(mid: np.ndarray, n: int, rng: np.random.Generator,
                   iterations: int = 10) -> np.ndarray:
    """K-means of the track midpoints ``mid (N, 2)`` (px): lines near each other share a body."""
    centres = mid[rng.choice(mid.shape[0], n, replace=False)]
    labels = np.zeros(mid.shape[0], dtype=np.int64)
    for _ in range(iterations):
        labels = np.argmin(np.linalg.norm(mid[:, None] - centres[None], axis=2), axis=1)
        for b in range(n):
            if np.any(labels == b):
                centres[b] = mid[labels == b].mean(axis=0)
    return labels


#: Smallest endpoint noise assumed (px): the non-linear fits converge to ~1e-9, not to zero,
#: and no detector locates lines better than this.
SIGMA_FLOOR_PX = 0.1


def _best_costs(costs: np.ndarray) -> np.ndarray:
    """Smallest cost ``(N,)`` of every track over the bodies (``inf`` when it has none)."""
    if costs.shape[1] == 0:
        return np.full(costs.shape[0], np.inf)
    return np.min(np.where(np.isfinite(costs), costs, np.inf), axis=1)


def _robust_sigma2(best: np.ndarray, dof: np.ndarray) -> float:
    """Noise variance (1 px units) from the median of chi-square-normalised costs."""
    from .models import chi2_quantile
    ok = np.isfinite(best) & (dof > 0)
    if not np.any(ok):
        return 1.0
    return float(max(np.median(best[ok] / chi2_quantile(0.5, dof[ok])), SIGMA_FLOOR_PX ** 2))


def _assign_within_bound(costs: np.ndarray, dof: np.ndarray, outlier_p: float
                         ) -> Tuple[float, np.ndarray, np.ndarray]:
    """Noise level, chi-square outlier bound ``(N,)`` and labels (``-1`` above it) of ``costs``."""
    from .ksubspaces import assign
    from .models import chi2_quantile
    sigma2 = _robust_sigma2(_best_costs(costs), dof)
    cap = chi2_quantile(outlier_p, dof) * sigma2
    return sigma2, cap, assign(costs, cap)


def _fit_each_body(obs: LineObservations, labels: np.ndarray, W: np.ndarray, T: np.ndarray,
                   fitted: np.ndarray, iterations: int, w_start,
                   sigma2: Optional[float] = None, t_start=None, keep: int = 3,
                   first_iterations: int = 15, pivots: bool = True) -> None:
    """Refit every body with >= 3 tracks in place: LM from its motion, or multi-start.

    ``fitted (n,)`` marks bodies whose ``(W, T)`` is a fit already (LM for ``iterations``);
    the others start a multi-start search at ``w_start(b)`` (and ``t_start(b)``), with
    :func:`pivot_starts` towards the body's lines when ``pivots`` and a Necker check
    (:func:`fit_body_multistart`), and become fitted (``keep`` LM runs of
    ``first_iterations``). ``sigma2``: marginalised directions (:func:`marginal_residuals`).
    """
    for b in range(W.shape[0]):                               # bodies, not lines
        idx = np.flatnonzero(labels == b)
        if idx.size < 3:
            continue
        if fitted[b]:
            W[b], T[b], _ = _best_fit(obs, idx, W[b], np.atleast_2d(T[b]), iterations, sigma2)
        else:
            W[b], T[b], _ = fit_body_multistart(
                obs, idx, w_start(b), None if t_start is None else t_start(b),
                first_iterations, keep, sigma2, obs.body_ray(idx), pivots)
            fitted[b] = True


def marginal_costs(obs: LineObservations, W: np.ndarray, T: np.ndarray, sigma2: float
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """Marginalised costs ``(N, n)`` and their log-determinant parts ``(N, n)`` (px^2).

    See :func:`marginal_residuals`; ``nan`` for tracks with fewer than 3 frames.
    """
    An, Av = _design(obs.rows, W, T)                     # all bodies in one batch
    _, n0 = _evaluate(An, Av, obs.m_first, sigma2)
    parts: list = []
    out = np.ascontiguousarray(_evaluate(An, Av, n0, sigma2, logdet_out=parts)[0].T)
    out[obs.frames < 3] = np.nan
    return out, np.ascontiguousarray(parts[0].T)


def _assign_marginal(costs: np.ndarray, logdet: np.ndarray, dof: np.ndarray, sigma2: float,
                     outlier_p: float, neighbours: Optional[np.ndarray] = None
                     ) -> Tuple[np.ndarray, np.ndarray]:
    """Labels ``(N,)`` and outlier caps ``(N,)`` of marginalised costs.

    A track is an outlier (``-1``) when, under its cheapest body, the quadratic part of its
    cost (without the log-determinant, and without any position term of
    :func:`position_costs` already added to ``costs`` and ``logdet``) is above the chi-square
    bound with ``dof`` degrees of freedom; the cap is that bound plus those terms. With
    ``neighbours`` the inliers are relabelled by :func:`.spatial.smooth_labels`.
    """
    from .ksubspaces import assign
    from .models import chi2_quantile
    from .spatial import smooth_labels
    lab = assign(costs)
    ok = lab >= 0
    ld = np.zeros(costs.shape[0])
    ld[ok] = logdet[np.flatnonzero(ok), lab[ok]]
    cap = chi2_quantile(outlier_p, dof) * sigma2 + ld
    lab = assign(costs, cap)
    if neighbours is not None:
        lab, _ = smooth_labels(costs, lab, neighbours)
    return lab, cap


#: Weight of the bodies' image-position term (:func:`position_costs`) in the 'general'
#: segmentation, relative to the motion costs (1 = the joint likelihood of positions and
#: motion at the segmentation's inflated noise level). Hopkins155, K = 5: 8 three-motion
#: checkerboard windows 24.5% misclassified (0), 19.3% (0.1), 13.6% (0.25), 9.5% (0.5),
#: 8.3% (1); 24 windows of 20 random two-motion sequences 3.7% (0), 3.2% (0.25), 3.5%
#: (0.5), 4.6% (1): a compact object pulls in the lines of a broad background near it.
POSITION_WEIGHT = 0.5

#: Pseudo-count of the shrinkage of a body's midpoint covariance towards all tracks' (tracks).
POSITION_PRIOR = 3.0


def position_costs(points: np.ndarray, labels: np.ndarray, n: int,
                   prior: float = POSITION_PRIOR) -> np.ndarray:
    """Image-position cost ``(N, n)`` of every track under every body's Gaussian blob.

    ``points (N, 2)``: the tracks' midpoints (px); ``labels (N,)`` the current bodies (``-1``
    none). Each body is a 2D Gaussian over the image fitted to its tracks' midpoints, its
    covariance shrunk towards that of all labelled tracks with ``prior`` pseudo-tracks (a body
    with few or no tracks falls back to it); the cost is twice the negative log-likelihood,
    ``d^T S^-1 d + log det S`` (scale-free: differences do not depend on the image size).
    Rigid bodies are compact in the image: a body made of two distant regions (two objects
    with nearly the same motion over the window) or lines far from a body's others pay for it.
    """
    pts = np.asarray(points, dtype=float)
    ok = labels >= 0
    ref = pts[ok] if np.count_nonzero(ok) >= 3 else pts
    S0 = np.cov(ref.T) + 1e-6 * np.eye(2)
    mu0 = ref.mean(axis=0)
    out = np.empty((pts.shape[0], n))
    for b in range(n):                                   # bodies, not lines
        p = pts[labels == b]
        mu = (p.sum(axis=0) + prior * mu0) / (p.shape[0] + prior)
        d = p - mu
        S = (d.T @ d + prior * (S0 + np.outer(mu0 - mu, mu0 - mu))) / (p.shape[0] + prior)
        r = pts - mu
        out[:, b] = (np.sum((r @ np.linalg.inv(S)) * r, axis=1)
                     + np.log(np.linalg.det(S)))
    return out


def marginal_segmentation(obs: LineObservations, n: int, starts: list, W0: np.ndarray,
                          T0: np.ndarray, sigma2: float, rounds: int = 8, iterations: int = 5,
                          outlier_p: float = 0.9999, neighbours: Optional[np.ndarray] = None,
                          keep: int = 3, first_iterations: int = 15,
                          pivots: bool = True, points: Optional[np.ndarray] = None,
                          position_weight: float = POSITION_WEIGHT) -> dict:
    """Segment with the marginalised-direction model (:func:`marginal_residuals`).

    Parameters
    ----------
    obs : LineObservations
    n : int
        Number of bodies.
    starts : list of (name, labels (N,))
        Initial labellings.
    W0, T0 : (n, 3)
        Rotation (rad/frame) and translation (direction; its length is rescanned) to start
        every body's first fit from (:func:`fit_body_multistart`).
    sigma2 : float
        Endpoint noise variance (px^2), fixed.
    neighbours : (N, k) int, optional
        Image neighbours for the spatial prior of :func:`.spatial.smooth_labels`.
    rounds, iterations : int
        Fit/assign rounds and LM iterations per body and round.
    keep, first_iterations : int
        LM runs (the best starts of the scan) and their iterations for a body's first fit.
    pivots : bool
        Whether a body's first fit also starts from :func:`pivot_starts`.
    points : (N, 2) float, optional
        Track midpoints (px): each body also gets an image-position term
        (:func:`position_costs`, times ``position_weight * sigma2``) in the assignment and the
        score, so that the starts are compared on motion AND compactness.

    Returns
    -------
    dict with ``labels (N,)``, ``W (n, 3)`` rotation vectors (rad/frame), ``T (n, 3)``
    translations per frame (camera frame; length = the scale of ``|T| / d``), ``costs (N, n)``
    (motion only), ``sigma2``, the winning ``start`` and its ``score`` (capped total cost,
    position terms included).
    """
    from .ksubspaces import total_cost
    dof = np.maximum(2.0 * obs.frames - 2.0, 0.0)
    usable = obs.frames >= 3
    best = None
    for name, lab in starts:
        lab = np.where(usable, np.asarray(lab, dtype=np.int64), -1)
        W, T = np.array(W0, dtype=float), np.array(T0, dtype=float)
        fitted = np.zeros(n, dtype=bool)
        costs = np.full((obs.n_tracks, n), np.nan)
        cap = np.full(obs.n_tracks, np.inf)
        total = costs
        for _ in range(rounds):
            _fit_each_body(obs, lab, W, T, fitted, iterations, lambda b: W[b], sigma2,
                           lambda b: T[b], keep, first_iterations, pivots)
            costs, logdet = marginal_costs(obs, W, T, sigma2)
            total = costs
            if points is not None:
                # the blobs of the labels the bodies were just fitted to; the position term
                # is no evidence of an outlier, so it joins the log-determinant in the cap
                extra = position_weight * sigma2 * position_costs(points, lab, n)
                total, logdet = costs + extra, logdet + extra
            new, cap = _assign_marginal(total, logdet, dof, sigma2, outlier_p, neighbours)
            if np.array_equal(new, lab):
                break
            lab = new
        score = total_cost(total, lab, cap)
        if best is None or score < best['score']:
            best = {'labels': lab, 'W': W.copy(), 'T': T.copy(), 'costs': costs,
                    'sigma2': sigma2, 'start': name, 'score': score}
    return best


#: The marginalised model's noise variance, as a multiple of the noise variance of the
#: fitted-direction model on the rotation-only labels. That estimate is the median of costs
#: from which two unknowns per line and the best of n bodies were fitted away, and it ignores
#: model error (non-constant velocity, lens): taken as it is, a body's translation scale grows
#: until it explains other bodies' lines. Hopkins155, K = 5, one window of 16 sequences:
#: misclassified 30% (x1), 20% (x2), 16% (x4), 7% (x8); 32 sequences: 5.9% (x16), 7.4% (x64),
#: 7.5% (x1000, nearly rotation-only); robust 20.3%, robust with -1 -> cheapest body 11.1%.
#: Rechecked after every body fit got its T = 0 start: the 35 three-motion sequences, K = 5,
#: both windows, 12.2% (x8), 11.2% (x16), 12.2% (x32).
NOISE_FACTOR = 16.0


def general_search(obs: LineObservations, n: int, starts: list, rot_labels: np.ndarray,
                   w_rot: np.ndarray, neighbours: Optional[np.ndarray] = None,
                   noise_factor: float = NOISE_FACTOR, outlier_p: float = 0.9999,
                   points: Optional[np.ndarray] = None,
                   position_weight: float = POSITION_WEIGHT) -> dict:
    """Full search of the 'general' method: noise level, then :func:`marginal_segmentation`.

    Parameters
    ----------
    obs : LineObservations
    n : int
        Number of bodies.
    starts : list of (name, labels (N,))
        Initial labellings (the rotation-only solution, a spatial clustering, ...).
    rot_labels : (N,) int
        The rotation-only labels: each body is first fitted on them with fitted line
        directions (multi-start over T), which gives the noise level (times
        ``noise_factor``) and the starting motions.
    w_rot : (n, 3)
        Rotation-only rotation vectors (rad/frame), the first fits' starts.
    neighbours : (N, k) int, optional
        Image neighbours for the spatial prior.
    points : (N, 2) float, optional
        Track midpoints (px) for the bodies' position term (:func:`position_costs`).

    Returns the dict of :func:`marginal_segmentation`.
    """
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    W, T = np.array(w_rot, dtype=float), np.zeros((n, 3))
    lab = np.where(dof > 0, np.asarray(rot_labels, dtype=np.int64), -1)
    _fit_each_body(obs, lab, W, T, np.zeros(n, dtype=bool), 6, lambda b: w_rot[b])
    sigma2 = noise_factor * _robust_sigma2(_best_costs(general_costs(obs, W, T)), dof)
    return marginal_segmentation(obs, n, starts, W, T, sigma2, outlier_p=outlier_p,
                                 neighbours=neighbours, points=points,
                                 position_weight=position_weight)


#: A warm start is kept when at least this share of the usable tracks stay inliers (else the
#: full multi-start search runs).
WARM_INLIERS = 0.5


def general_warm(obs: LineObservations, labels: np.ndarray, W0: np.ndarray, T0: np.ndarray,
                 known: np.ndarray, rounds: int = 3, iterations: int = 4,
                 outlier_p: float = 0.9999) -> dict:
    """Track the bodies of the previous window: a few LM steps from its motions, then assign.

    Parameters
    ----------
    obs : LineObservations
    labels : (N,) int
        Starting labels (the previous window's, ``-1`` unknown).
    W0, T0 : (n, 3)
        Starting rotation vectors (rad/frame) and translation directions (unit or zero) per
        body, camera optical frame.
    known : (n,) bool
        Bodies whose ``(W0, T0)`` come from a previous fit; the others start from the
        multi-start search at ``W0`` (their rotation-only estimate).
    rounds, iterations : int
        Fit/assign rounds and LM iterations per body and round.

    Returns the dict of :func:`marginal_segmentation` (``start='warm'``, fitted directions, unit
    ``T``) plus ``inliers``, the
    share of usable tracks within the outlier bound.
    """
    from .ksubspaces import total_cost
    n = W0.shape[0]
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    usable = dof > 0
    lab = np.where(usable, np.asarray(labels, dtype=np.int64), -1)
    W, T = np.array(W0, dtype=float), np.array(T0, dtype=float)
    fitted = np.asarray(known, dtype=bool).copy()
    costs = np.full((obs.n_tracks, n), np.nan)
    sigma2, cap = 1.0, None
    for _ in range(rounds):
        _fit_each_body(obs, lab, W, T, fitted, iterations, lambda b: W[b])
        costs = general_costs(obs, W, T)
        if not np.any(np.isfinite(costs)):
            break
        sigma2, cap, new = _assign_within_bound(costs, dof, outlier_p)
        if np.array_equal(new, lab):
            break
        lab = new
    inliers = float(np.mean(lab[usable] >= 0)) if np.any(usable) else 0.0
    score = total_cost(costs, lab, cap) if cap is not None else np.inf
    return {'labels': lab, 'W': W, 'T': T, 'costs': costs, 'sigma2': sigma2, 'start': 'warm',
            'score': score, 'inliers': inliers}


#: Scale a 'general' body's covariance by its reduced chi-square (its fitted-direction costs
#: over the measured noise, when above 1): the noise level is measured over all lines, and a
#: body the model fits worse (model error over the window, a rotation partly explained by
#: translation) published a covariance that did not cover its error. ``bench covariance``
#: (30 frames, window 10, render seeds 0-5; honest: NEES median 2.37, 95% of the frames <=
#: 7.81): boxes within 5% of their omega, NEES median 16-36 -> 3.3-7.8 (own-centre scenes),
#: camera-centre rotation (the model holds) 5.8 -> 2.5 with 92% of the frames within the 95%
#: bound (robust on it: 1.9, 95%). A box fitted in a wrong basin stays far outside (NEES 34 to
#: 5100): that is a second minimum, not a wider one (session 15).
COVARIANCE_FIT_SCALE = True


def body_covariance(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                    sigma2: float, step: float = 1e-6, marginal: bool = False) -> np.ndarray:
    """Covariance ``(3, 3)`` of a body's rotation vector from the Gauss-Newton information.

    ``sigma2``: noise variance (px^2). ``marginal``: the body was fitted with
    :func:`marginal_residuals` at that ``sigma2`` (``t`` with its scale); the covariance is
    then also scaled by the body's reduced chi-square when above 1
    (:data:`COVARIANCE_FIT_SCALE`).
    """
    if idx.size < 3:
        return np.full((3, 3), np.inf)
    rows = obs.rows[idx]
    _, n0 = _costs2(rows, obs.m_first[idx], w, t, sigma2 if marginal else None)
    # the motion and its six forward differences, evaluated as one batch
    X = np.r_[w, t] + np.concatenate([np.zeros((1, 6)), step * np.eye(6)])
    An, Av = _design(rows, X[:, :3], X[:, 3:])
    if marginal:
        r = _evaluate(An, Av, n0, sigma2, n0)[0].reshape(7, -1)
    else:
        r = np.sqrt(_evaluate(An, Av, n0, None)[0])
    J = np.ascontiguousarray(((r[1:] - r[0]) / step).T)
    info = J.T @ J
    scale = 1.0
    if marginal and COVARIANCE_FIT_SCALE:
        # the data term alone: the fitted-direction costs (px^2, two unknowns per line); the
        # marginal residuals also hold the direction prior, which does not scale with sigma2
        fitted, _ = _costs2(rows, obs.m_first[idx], w, t, None)
        dof = float(np.sum(2.0 * obs.frames[idx] - 4.0)) - 6.0
        total = float(np.sum(fitted))
        if dof > 0 and np.isfinite(total):
            scale = max(total / dof / sigma2, 1.0)
    try:
        return scale * sigma2 * np.linalg.pinv(info, rcond=1e-10)[:3, :3]
    except np.linalg.LinAlgError:
        return np.full((3, 3), np.inf)
