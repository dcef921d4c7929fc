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
Line model of general rigid motion over three or more frames: rotation AND translation.

A 3D line with Plucker moment ``n0`` and direction ``v0`` on a body moving ``X' = R X + T`` per
frame has, in frame ``k``, the moment ``n_k = R^k n0 + T_k x R^k v0`` with
``T_k = sum_{j<k} R^j T``; its image is the line with normal ``m_k ~ n_k``. For the two directions
``e`` orthogonal to the observed ``m_k``, ``e . n_k = 0``, which is LINEAR in ``(n0, v0)``::

    (R^-k e) . n0 + (R^-k (e x T_k)) . v0 = 0

``v0`` is orthogonal to ``n0``: two unknowns per line (its direction within the plane and
``1/d``; the scale of ``T`` is absorbed by ``v0``). Projecting them out leaves a 3x3 problem in
``n0`` whose smallest eigenvalue is the line's (whitened) residual: ``2K - 4`` constraints per
line, none with two frames (as it must be), six with five. With ``T = 0`` it reduces to the
rotation-only model (:func:`line_residuals`).

Fitting the two direction unknowns per line removes all first-order information (the
translational flow spans the line's whole flow space), which leaves bodies nearly
indistinguishable over a few frames; :func:`marginal_residuals` instead gives the direction a
Gaussian prior scaled by the body's translation and integrates it out (docs/design/general.md).
"""
from typing import Optional, Tuple, Union

import numpy as np

from .eigen import smallest_eigenpair, smallest_eigenpair_stacked
from ..lines import (first_midpoints, interpretation_normals, normalise_points, orthonormal_pair,
                     pair_components, rotation_matrix, skew)


Intrinsics = Tuple[float, float, float, float]


class LineObservations:
    """
    Whitened observation directions of every track and frame.

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
        self.rows = np.where(ok[..., None, None], _whitened_rows(m, cov), 0.0)
        self.present = ok
        self.m = m
        first = np.argmax(ok, axis=1)
        self.m_first = m[np.arange(m.shape[0]), first]
        self.frames = ok.sum(axis=1)
        self.midpoints = first_midpoints(tracks)
        rays = normalise_points(self.midpoints, intrinsics)
        self.rays = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        self._products: Optional[np.ndarray] = None

    @property
    def n_tracks(self) -> int:
        """Return the number of tracks ``N``."""
        return self.rows.shape[0]

    def row_products(self, idx: Optional[np.ndarray] = None) -> np.ndarray:
        """
        Return :func:`_row_products` of the tracks ``idx (..., L)``, ``(..., 9 K, L)``.

        ``idx`` None: every track, ``(9 K, N)``. Made once per window and gathered: every fit
        and cost evaluation of a body's tracks starts from them.
        """
        if self._products is None:
            self._products = _row_products(self.rows)
        if idx is None:
            return self._products
        return np.ascontiguousarray(np.moveaxis(self._products[:, idx], 0, -2))

    def body_ray(self, idx: np.ndarray) -> np.ndarray:
        """Return the unit ray ``(3,)`` towards the tracks ``idx`` (camera frame)."""
        ray = self.rays[idx].sum(axis=0)
        return ray / np.linalg.norm(ray)


def _whitened_rows(m: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """
    Return the whitened observation rows ``(..., 2, 3)`` of unit normals ``m (..., 3)``.

    ``cov (..., 3, 3)``: the normals' covariance. The rows span the plane orthogonal to ``m``
    along the principal directions of ``cov`` there, smaller variance first, each divided by
    its standard deviation. The 2x2 eigenproblem in closed form, element-wise over the
    tracks and frames (LAPACK's per-matrix call took about 40% of the observations' cost:
    200 tracks of 10 frames 2.0-2.5 -> 1.1-1.2 ms).
    """
    E = orthonormal_pair(m)                                          # (..., 3, 2)
    e1, e2 = E[..., 0], E[..., 1]
    c1 = np.einsum('...ij,...j->...i', cov, e1)
    a = np.einsum('...i,...i->...', e1, c1)
    b = np.einsum('...i,...i->...', e2, c1)
    c = np.einsum('...i,...i->...', e2, np.einsum('...ij,...j->...i', cov, e2))
    half, mid = 0.5 * (a - c), 0.5 * (a + c)
    d = np.hypot(half, b)
    theta = 0.5 * np.arctan2(b, half)            # the larger variance's direction in (e1, e2)
    cos, sin = np.cos(theta)[..., None], np.sin(theta)[..., None]
    lo = np.sqrt(np.maximum(mid - d, 1e-30))[..., None]
    hi = np.sqrt(np.maximum(mid + d, 1e-30))[..., None]
    return np.stack([(cos * e2 - sin * e1) / lo, (cos * e1 + sin * e2) / hi], axis=-2)


def _motion_terms(w: np.ndarray, t: np.ndarray, n_frames: int) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return ``R^k (..., K, 3, 3)`` and ``T_k (..., K, 3)`` of motions ``w, t (..., 3)``.

    ``k = 0..K-1``. ``R^k`` is the rotation by ``k w`` (Rodrigues, one batched call rather than
    ``K - 1`` sequential products) and ``T_k = sum_{j<k} R^j t``. Leading axes batch several
    motions: each gets the same products as when alone.
    """
    k = np.arange(n_frames, dtype=float)
    Rk = rotation_matrix(w[..., None, :] * k[:, None])
    Tk = np.zeros(Rk.shape[:-1])
    Tk[..., 1:, :] = np.cumsum((Rk[..., :-1, :, :] @ t[..., None, :, None])[..., 0], axis=-2)
    return Rk, Tk


def _design(rows: np.ndarray, w: np.ndarray, t: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the linear constraints of tracks with whitened observation ``rows (L, K, 2, 3)``.

    ``w, t (..., 3)``: one motion or a batch of them (leading axes ``...``); ``rows`` may carry
    the same leading axes (each motion its own tracks). Returns
    ``An (..., L, 2K, 3)`` acting on the moment ``n0`` and ``Av (..., L, 2K, 3)`` acting on the
    direction ``v0``; both are independent of the basis of ``v0`` (:func:`_direction_columns`),
    so a second pass at the same motion reuses them.
    """
    L, K = rows.shape[-4], rows.shape[-3]
    Rk, Tk = _motion_terms(w, t, K)
    lead = Rk.shape[:-3]
    # (R^-k e) . n0 = e . R^k n0  ->  rows @ R^k ; e . (T_k x R^k v0) = (e x T_k) . R^k v0.
    # Written out term by term, lines last: long contiguous inner loops over the lines instead
    # of einsum's 3-long ones (3-5x faster on a batch), and the same products and sums in the
    # same order as einsum('lkji,kim->lkjm') and np.cross, so bit for bit the same result.
    rT = np.ascontiguousarray(np.moveaxis(rows, -4, -1))            # (K, 2, 3, L)
    r = [np.ascontiguousarray(rT[..., i, None, :]) for i in range(3)]  # (K, 2, 1, L)
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
    """
    Return the direction columns ``Av`` in the plane orthogonal to ``base``, ``(..., L, 2K, 2)``.

    ``base (..., L, 3)``; ``basis``: its :func:`.orthonormal_pair` if already computed.
    """
    return Av @ (orthonormal_pair(base) if basis is None else basis)


def _smallest(P: np.ndarray, base: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the smallest eigenvalue ``(..., L)`` of ``P^T P`` and its unit eigenvector.

    ``P (..., L, R, 3)``; the eigenvector ``(..., L, 3)`` is signed like ``base (..., L, 3)``.
    """
    return _toward(*smallest_eigenpair(np.swapaxes(P, -1, -2) @ P), base)


def _toward(val: np.ndarray, n0: np.ndarray, base: np.ndarray
            ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Clip eigenvalues ``(...)`` at 0 and sign unit eigenvectors ``n0 (..., 3)`` like ``base``.

    ``n0`` is flipped in place where it points away from ``base``.
    """
    n0 *= np.where(np.sum(n0 * base, axis=-1) < 0, -1.0, 1.0)[..., None]
    return np.maximum(val, 0.0), n0


def _apply(P: np.ndarray, n0: np.ndarray) -> np.ndarray:
    """
    Return the residual vectors ``(..., L, R)`` of ``P (..., L, R, 3)`` at ``n0 (..., L, 3)``.

    Summed term by term in a fixed order: the float result is then the same for every memory
    layout and batch shape (einsum picks its summation kernel by the operands' strides), and
    the same as einsum's with the strided moments the eigensolver returns.
    """
    n0 = n0[..., None, :]
    return P[..., 0] * n0[..., 0] + P[..., 1] * n0[..., 1] + P[..., 2] * n0[..., 2]


def _line_eval(An: np.ndarray, AvB: np.ndarray, base: np.ndarray,
               fixed: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """
    Evaluate :func:`line_residuals` from the constraints ``An``, ``AvB`` (batched).

    The solver's own fitted-direction costs take the Gram form (:func:`_marginal_costs` with
    ``sigma2`` None); this one, from the constraints, is :func:`line_residuals`' reference.
    """
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


#: Gram blocks of constraints (:func:`_grams`): an array ``(3, 3, 3, ..., L)`` of the
#: entries ``[block, i, j]`` of ``An^T An``, ``Av^T An`` and ``Av^T Av`` (blocks 0, 1, 2), lines
#: last; or the three blocks ``(3, 3, ..., L)`` as a tuple (broadcast against each other).
Grams = Union[np.ndarray, Tuple[np.ndarray, np.ndarray, np.ndarray]]


def _row_products(rows: np.ndarray) -> np.ndarray:
    """
    Return ``sum_r e e^T`` of each track's two observation rows per frame, ``(9 K, L)``.

    ``rows (..., L, K, 2, 3)``; laid out frame, row index, column index first, tracks last:
    the motion-independent part of every :func:`_grams`.
    """
    P = np.einsum('...lkri,...lkrj->...kijl', rows, rows)
    return np.ascontiguousarray(P.reshape(rows.shape[:-4] + (-1, rows.shape[-4])))


def _grams(products: np.ndarray, w: np.ndarray, t: np.ndarray, n_frames: int) -> Grams:
    """
    Return the :data:`Grams` of the constraints (:func:`_design`) at motions ``w, t (..., 3)``.

    ``products (9 K, L)``, or ``(..., 9 K, L)`` one per motion: :func:`_row_products`. A
    constraint row is ``e^T R^k`` on the moment and ``e^T [T_k]_x R^k`` on the direction, so
    each Gram block is ``sum_k X_k^T (sum_r e e^T) Y_k``: linear in the row products, with
    weights from the motion alone, one matrix product per motion instead of ``2K x 3``
    constraints per line. They hold all that the marginalised cost needs, whatever the basis
    of ``v0``: two passes at the same motion (:func:`_costs2`) share them.
    """
    Rk, Tk = _motion_terms(w, t, n_frames)                           # (..., K, 3, 3)
    Q = skew(Tk) @ Rk
    lead = Rk.shape[:-3]
    weights = np.concatenate(
        [np.einsum('...kai,...kbj->...ijkab', x, y).reshape(lead + (9, 9 * n_frames))
         for x, y in ((Rk, Rk), (Q, Rk), (Q, Q))], axis=-2)          # (..., 27, 9K)
    g = weights @ products                                           # (..., 27, L)
    entries = np.ascontiguousarray(np.moveaxis(g, -2, 0))           # (27, ..., L)
    return entries.reshape((3, 3, 3) + entries.shape[1:])


def _marginal_costs(grams: Grams, base: np.ndarray, sigma2: Optional[float],
                    basis: Optional[np.ndarray] = None, logdet_out: Optional[list] = None,
                    passes: int = 1) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return :func:`marginal_residuals`' costs ``(..., L)`` and moments ``(..., L, 3)``.

    From the :data:`Grams` ``grams``; ``sigma2`` None: :func:`line_residuals`' (fitted
    directions). ``passes``: each pass after the first takes the plane of ``v0`` orthogonal
    to the moments of the one before (the moments stay components first between them);
    ``logdet_out`` receives the last pass's log-determinant.

    With the whitened direction columns ``M = Av B / sqrt(sigma2)`` (``B`` the basis of the
    plane orthogonal to ``base``, :func:`.orthonormal_pair` or ``basis``) and ``S = M^T M``
    (2x2 per line), the cost's quadratic form is
    ``An^T (I + M M^T)^-1 An = An^T An - G^T (I + S)^-1 G`` with ``G = M^T An`` (Woodbury),
    and the log-determinant ``log det(I + S)``: no ``2K x 3`` products, a few 3x3 and 2x2
    ones per line, stacked entries first and lines last (:func:`_marginal_pass`). Fitted
    directions project the columns ``M = Av B`` out instead: ``An^T An - G^T S^+ G``
    (:func:`_column_projector`), as :func:`_line_eval` does from the constraints at twice
    the cost: the two differ by up to 5e-6 relative on bench spinning's windows, 5e-4 on a
    near-perfect line of visp_cube (a cost of 5e-6 px^2 from Gram entries of 3e6: the
    subtraction's rounding, 3e-9 px^2).
    """
    base_c = np.ascontiguousarray(np.moveaxis(base, -1, 0))
    basis_c = (None if basis is None
               else np.ascontiguousarray(np.moveaxis(basis, (-2, -1), (0, 1))))
    val, n0, logdet = _marginal_pass(grams, base_c, sigma2, basis_c)
    for _ in range(passes - 1):
        val, n0, logdet = _marginal_pass(grams, n0, sigma2)
    if logdet is not None and logdet_out is not None:
        logdet_out.append(logdet)
    n0 = np.ascontiguousarray(np.moveaxis(n0, 0, -1))
    return (val, n0) if logdet is None else (val + logdet, n0)


def _marginal_pass(grams: Grams, base: np.ndarray, sigma2: Optional[float],
                   basis: Optional[np.ndarray] = None
                   ) -> Tuple[np.ndarray, np.ndarray, Optional[np.ndarray]]:
    """
    Return :func:`_marginal_costs`' quadratic part ``(..., L)``, moments and log-determinant.

    Components first: ``base (3, ..., L)``, ``basis (3, 2, ..., L)`` (its
    :func:`.pair_components`, if known); the moments come back ``(3, ..., L)``, the
    log-determinant ``(..., L)`` (None with ``sigma2`` None). Each 2x2 and 3x3 product over
    all entries in one numpy call on contiguous arrays: at the solver's sizes a call's fixed
    cost dominates (entry by entry, one call per entry and term, a pass took 1.3x as long
    on 3 bodies of 67 lines, 1.2x on 3 of 200; the step 1.1x).
    """
    b = pair_components(base) if basis is None else basis          # b[i, c]: (3, 2, ..., L)
    nn, vn, vv = grams
    # the direction columns' Gram matrix S = B^T Av^T Av B and G = B^T Av^T An
    S = np.einsum('ic...,ij...,je...->ce...', b, vv, b)
    G = np.einsum('ic...,ij...->cj...', b, vn)
    logdet = None
    if sigma2 is None:
        i00, i01, i11 = _column_projector(S[0, 0], 0.5 * (S[0, 1] + S[1, 0]), S[1, 1])
    else:
        S /= sigma2
        G *= 1.0 / np.sqrt(sigma2)
        s00, s01, s11 = 1.0 + S[0, 0], 0.5 * (S[0, 1] + S[1, 0]), 1.0 + S[1, 1]
        # det(I + S) >= 1 (rounding could take it below, then its log's root would be NaN)
        det = np.maximum(s00 * s11 - s01 * s01, 1.0)
        logdet = sigma2 * np.log(det)
        # (I + S)^-1, the 2x2 inverse written out
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    # X = (I + S)^-1 G (or S^+ G); C = An^T An - G^T X
    X = np.stack([i00 * G[0] + i01 * G[1], i01 * G[0] + i11 * G[1]])
    val, n0 = smallest_eigenpair_stacked(nn - np.einsum('ci...,cj...->ij...', G, X))
    n0 *= np.where(np.einsum('i...,i...->...', n0, base) < 0.0, -1.0, 1.0)
    return np.maximum(val, 0.0), n0, logdet


#: Condition number of the direction columns' Gram matrix ``S`` above which they count as
#: one column (:func:`_column_projector`); the Gram form loses about ``eps * cond`` of the
#: residual there.
COLUMN_COND = 1e12


def _column_projector(s00: np.ndarray, s01: np.ndarray, s11: np.ndarray
                      ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return the entries ``(00, 01, 11)`` of the pseudo-inverse of ``S = [[s00, s01], [s01, s11]]``.

    ``S (...)`` entries of positive semi-definite 2x2 matrices: the Gram matrices of a line's
    two direction columns. Full rank below :data:`COLUMN_COND`; else one column (``S / tr^2``,
    parallel columns) or none (zero: no translation, the rotation-only model).
    """
    tr = s00 + s11
    det = s00 * s11 - s01 * s01
    full = det * COLUMN_COND > tr * tr
    one = ~full & (tr > 0.0)
    inv = 1.0 / np.where(full, det, np.where(one, tr * tr, 1.0))
    zero = ~(full | one)
    return (np.where(zero, 0.0, np.where(full, s11, s00) * inv),
            np.where(zero, 0.0, np.where(full, -s01, s01) * inv),
            np.where(zero, 0.0, np.where(full, s00, s11) * inv))


def _marginal_vectors(An: np.ndarray, M: np.ndarray, fixed: np.ndarray, sigma2: float,
                      logdet_out: Optional[list] = None) -> np.ndarray:
    """
    Return :func:`marginal_residuals`' residual vectors ``(..., L, 2K + 1)`` at ``fixed``.

    ``fixed (..., L, 3)``: the moments.

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
    """
    Return costs and moments (or residual vectors at ``fixed``) from :func:`_design`'s output.

    ``sigma2`` None: :func:`line_residuals`; else the residual vectors of
    :func:`marginal_residuals` at ``fixed`` (its costs come from :func:`_grams`); every array
    may carry leading batch axes.
    """
    M = _direction_columns(Av, base, basis)
    if sigma2 is None:
        return _line_eval(An, M, base, fixed)
    return _marginal_vectors(An, M, fixed, sigma2, logdet_out), fixed


def line_residuals(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                   n0: Optional[np.ndarray] = None, fixed: Optional[np.ndarray] = None
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the whitened residual ``(L,)`` (sum of squares) and moment direction ``n0 (L, 3)``.

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
    """
    Return the cost ``(L,)`` with each line's direction MARGINALISED, not fitted (1 px units).

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
    if fixed is None:
        grams = _grams(obs.row_products(idx), w, t, obs.rows.shape[1])
        return _marginal_costs(grams, base, sigma2, logdet_out=logdet_out)
    An, Av = _design(obs.rows[idx], w, t)
    return _evaluate(An, Av, base, sigma2, fixed, logdet_out=logdet_out)


def _costs2(rows: np.ndarray, base: np.ndarray, w: np.ndarray, t: np.ndarray,
            sigma2: Optional[float], basis: Optional[np.ndarray] = None,
            logdet_out: Optional[list] = None, products: Optional[np.ndarray] = None
            ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return costs ``(..., L)`` and moments after two passes (the v0 plane follows the moment).

    ``rows (L, K, 2, 3)``: the tracks' observation rows, or ``(..., L, K, 2, 3)`` each
    motion its own; ``w, t (..., 3)`` one motion or a
    batch; ``base (L, 3)`` or ``(..., L, 3)`` the first pass's moments, ``basis`` their
    :func:`.orthonormal_pair` if known. ``sigma2`` None: fitted directions
    (:func:`line_residuals`); else marginalised. Both passes share the motion's
    :data:`Grams`.
    ``logdet_out``: a list that receives the second pass's log-determinant terms (marginalised);
    ``products``: :func:`_row_products` of ``rows`` if already computed.
    """
    grams = _grams(_row_products(rows) if products is None else products, w, t, rows.shape[-3])
    return _marginal_costs(grams, base, sigma2, basis, logdet_out, passes=2)


def general_costs(obs: LineObservations, W: np.ndarray, T: np.ndarray,
                  sigma2: Optional[float] = None) -> np.ndarray:
    """
    Return the cost ``(N, n)`` of every track under every body ``(W (n, 3), T (n, 3))``.

    ``sigma2`` None: fitted line directions (:func:`line_residuals`, unit T); else
    marginalised (:func:`marginal_residuals`, T with its scale, ``sigma2`` px^2).
    ``nan`` for tracks with fewer than 3 frames (no constraint on a general motion).
    """
    # all bodies in one batch
    out = np.ascontiguousarray(_costs2(obs.rows, obs.m_first, W, T, sigma2,
                                       products=obs.row_products())[0].T)
    out[obs.frames < 3] = np.nan
    return out


def marginal_costs(obs: LineObservations, W: np.ndarray, T: np.ndarray, sigma2: float
                   ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return marginalised costs ``(N, n)`` and their log-determinant parts ``(N, n)`` (px^2).

    See :func:`marginal_residuals`; ``nan`` for tracks with fewer than 3 frames.
    """
    parts: list = []
    # all bodies in one batch
    out = np.ascontiguousarray(_costs2(obs.rows, obs.m_first, W, T, sigma2, logdet_out=parts,
                                       products=obs.row_products())[0].T)
    out[obs.frames < 3] = np.nan
    return out, np.ascontiguousarray(parts[0].T)
