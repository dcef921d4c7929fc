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
Closed-form smallest eigenpair of batches of symmetric 3x3 matrices.

Every line's moment is the eigenvector of the smallest eigenvalue of a 3x3 matrix; the solver
asks for tens to hundreds of them per call, where a per-matrix LAPACK call would dominate.
"""
from typing import Tuple

import numpy as np

from ..lines import orthonormal_pair


#: Index of a 3x3 matrix's rows and columns 1, 2, 0, 1 (a 4x4 matrix), so that its cofactors
#: are slices (:func:`_cofactors`).
_ROLLED = np.ix_([1, 2, 0, 1], [1, 2, 0, 1])


def _cofactors(A: np.ndarray) -> np.ndarray:
    """
    Return the cofactor matrices ``(3, 3, ...)`` of the 3x3 matrices ``A (3, 3, ...)``.

    Row ``i`` of a symmetric matrix's cofactors is the cross product of its other two rows.
    """
    X = A[_ROLLED]                                                   # (4, 4, ...)
    return X[0:3, 0:3] * X[1:4, 1:4] - X[0:3, 1:4] * X[1:4, 0:3]


def _first_cofactors(A: np.ndarray) -> np.ndarray:
    """
    Return row 0 ``(3, ...)`` of :func:`_cofactors` of ``A (3, 3, ...)``, the same products.

    Rows 1 and 2 alone, their columns rolled: a ninth of the full cofactors' copy.
    """
    X = np.concatenate([A[1:3], A[1:3, :2]], axis=1)                  # (2, 5, ...)
    return X[0, 1:4] * X[1, 2:5] - X[0, 2:5] * X[1, 1:4]


def _minus_diagonal(C: np.ndarray, x: np.ndarray) -> np.ndarray:
    """
    Return ``C - x I`` of matrices ``C (3, 3, ...)``, ``x (...)``.

    Only the diagonal is subtracted from (off it ``C - 0 x`` is ``C``): no ``x I`` temporary.
    """
    out = C.copy()
    out.reshape((9,) + C.shape[2:])[::4] -= x
    return out


def smallest_eigenpair(C: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the smallest eigenvalue ``(...)`` and a unit eigenvector ``(..., 3)`` of ``C``.

    ``C (..., 3, 3)`` symmetric; :func:`smallest_eigenpair_stacked` of its entries.
    """
    lam, v = smallest_eigenpair_stacked(np.moveaxis(C, (-2, -1), (0, 1)))
    return lam, np.moveaxis(v, 0, -1)


def smallest_eigenpair_stacked(C: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the smallest eigenvalue ``(...)`` and a unit eigenvector ``(3, ...)`` of ``C``.

    ``C (3, 3, ...)``: symmetric matrices, entries first (the solver's lines-last layout).
    Closed form, element-wise over the batch: the eigenvalue by the trigonometric formula, the
    eigenvector as the largest cross product of two rows of ``C - lam I`` (its null vector),
    then the eigenvalue again as that vector's Rayleigh quotient: accurate to rounding of the
    largest eigenvalue, as LAPACK's. Where the two smallest eigenvalues (nearly) coincide the
    cross products vanish; there :func:`_flat_eigenvector` solves in the plane orthogonal to
    the largest row. On batches of tens to hundreds of matrices (the solver's) this is 2-3x
    faster than ``np.linalg.eigh``, whose per-matrix LAPACK call dominates; the rows and
    their cross products go stacked, a few numpy calls for all nine entries.
    """
    q = (C[0, 0] + C[1, 1] + C[2, 2]) / 3.0
    B = _minus_diagonal(C, q)
    p = np.sqrt(np.einsum('ij...,ij...->...', B, B) / 6.0)
    det = np.einsum('j...,j...->...', B[0], _first_cofactors(B))
    r = np.minimum(np.maximum(det / np.maximum(2.0 * p * p * p, 1e-300), -1.0), 1.0)
    lam = q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)
    D = _minus_diagonal(C, lam)
    # the cross products of the rows of C - lam I: its cofactors' rows; the largest (two
    # selections: np.choose took 2.5x as long)
    cross = _cofactors(D)
    nn = np.einsum('ij...,ij...->i...', cross, cross)
    largest = np.argmax(nn, axis=0)
    v = np.where(largest == 0, cross[0], np.where(largest == 1, cross[1], cross[2]))  # (3, ...)
    # cofactors (~ s1 s2, singular values of C - lam I) below 1e-6 of the squared row scale
    # (~ s1^2): C - lam I is of rank one to that precision, the two smallest eigenvalues
    # (nearly) coincide (rare: a line with about one constraint)
    flat = nn.max(axis=0) <= 1e-12 * np.einsum('ij...,ij...->i...', D, D).max(axis=0) ** 2
    if flat.any():
        v[:, flat] = _flat_eigenvector(np.moveaxis(C[:, :, flat], (0, 1), (-2, -1)),
                                       lam[flat]).T
    v /= np.maximum(np.sqrt(np.einsum('i...,i...->...', v, v)), 1e-300)
    return np.einsum('i...,ij...,j...->...', v, C, v), v


def _flat_eigenvector(C: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """
    Return the smallest eigenvector ``(k, 3)`` of ``C (k, 3, 3)``, its eigenvalue (nearly) double.

    ``lam (k,)`` approximates them. The eigenvector lies in the plane orthogonal to the
    largest row of ``C - lam I``; there, a 2x2 eigenproblem picks it (LAPACK: few matrices).
    """
    B = C - lam[:, None, None] * np.eye(3)
    row = B[np.arange(B.shape[0]), np.argmax(np.sum(B * B, axis=2), axis=1)]
    row = np.where(np.any(row != 0.0, axis=1, keepdims=True), row, [1.0, 0.0, 0.0])
    plane = orthonormal_pair(row / np.linalg.norm(row, axis=1, keepdims=True))     # (k, 3, 2)
    _, vec = np.linalg.eigh(np.swapaxes(plane, 1, 2) @ C @ plane)
    return (plane @ vec[:, :, :1])[:, :, 0]
