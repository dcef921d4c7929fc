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
Veronese embedding of degree n and its gradient, vectorised over rows and monomials.

The multibody constraint ``prod_i (y . u_i) = 0`` is linear in the monomials of ``y``:
``p(y) = nu_n(y) . U``. Monomials are ordered by descending exponent of ``y_0`` first
(lexicographic, so ``y_0^n`` comes first and ``y_{D-1}^n`` last).
"""
from functools import lru_cache
import itertools
from math import comb
from typing import Optional, Tuple

import numpy as np


@lru_cache(maxsize=None)
def exponents(n_vars: int, degree: int) -> np.ndarray:
    """
    Exponent matrix ``(M, n_vars)`` int of all monomials of ``degree`` in ``n_vars`` variables.

    ``M = C(degree + n_vars - 1, n_vars - 1)``, e.g. 10, 20, 35 for 4 variables and degree 2-4.
    """
    out = np.array([e for e in itertools.product(range(degree, -1, -1), repeat=n_vars)
                    if sum(e) == degree], dtype=np.int64)
    assert out.shape[0] == comb(degree + n_vars - 1, n_vars - 1)
    out.setflags(write=False)
    return out


def monomial_index(exps: np.ndarray, exponent) -> int:
    """Column of the monomial with the given exponent tuple in an exponent matrix."""
    hit = np.flatnonzero(np.all(exps == np.asarray(exponent), axis=1))
    if hit.size != 1:
        raise KeyError(f'monomial {tuple(exponent)} not in the embedding')
    return int(hit[0])


@lru_cache(maxsize=None)
def _blocks(n_vars: int, degree: int) -> tuple:
    """
    ``(start, length)`` per variable ``j``: degree-n monomials are ``y_j`` times a tail.

    In the lexicographic order the degree-n monomials whose first variable is ``y_j`` form one
    block, ``y_j`` times the degree n-1 monomials free of ``y_0 .. y_(j-1)``, which are the
    last ``length`` columns of the degree n-1 embedding, starting at ``start``.
    """
    lower = comb(degree - 1 + n_vars - 1, n_vars - 1)
    out = []
    for j in range(n_vars):
        length = comb(degree - 1 + n_vars - 1 - j, n_vars - 1 - j)
        out.append((lower - length, length))
    return tuple(out)


def _raise_degree(lower_t: np.ndarray, y_t: np.ndarray, degree: int) -> np.ndarray:
    """
    Transposed monomials ``(M, R)`` of ``degree`` from those of ``degree - 1``, ``(M', R)``.

    One elementwise product per variable of a contiguous block (no exponent tables, powers or
    gathers); transposed so that every block is contiguous in memory.
    """
    blocks = _blocks(y_t.shape[0], degree)
    out = np.empty((sum(b[1] for b in blocks), y_t.shape[1]))
    k = 0
    for j, (start, length) in enumerate(blocks):     # D <= 6 variables
        np.multiply(lower_t[start:], y_t[j], out=out[k:k + length])
        k += length
    return out


def embed(y: np.ndarray, degree: int, lower: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Veronese map ``nu_n``: rows ``(R, D)`` -> ``(R, M)`` monomials of ``degree``.

    ``lower``: ``embed(y, degree - 1)`` when already computed. Every monomial of degree d is
    one product of a variable and a degree d-1 monomial, so the degrees are built in turn: one
    multiplication per monomial and row, where powers and a product over the D variables of
    gathered columns cost D (and 3-30x the time). The result is Fortran-ordered (the
    transpose of a C-ordered ``(M, R)`` table).
    """
    y_t = np.ascontiguousarray(np.asarray(y, dtype=float).T)     # (D, R)
    if degree == 0:
        return np.ones((y_t.shape[1], 1))
    if lower is not None:
        return _raise_degree(np.asarray(lower, dtype=float).T, y_t, degree).T
    out = y_t.copy()
    for d in range(2, degree + 1):
        out = _raise_degree(out, y_t, d)
    return out.T


@lru_cache(maxsize=None)
def _derivative_map(n_vars: int, degree: int) -> Tuple[np.ndarray, np.ndarray]:
    """
    Column ``(M', D)`` of ``y_j m_l`` in the degree-n embedding and its exponent of ``y_j``.

    ``m_l`` runs over the degree n-1 monomials: ``d/dy_j`` of the degree-n monomial
    ``y_j m_l`` is ``(e_lj + 1) m_l``.
    """
    index = {tuple(e): i for i, e in enumerate(exponents(n_vars, degree))}
    lower = exponents(n_vars, degree - 1)
    cols = np.empty(lower.shape, dtype=np.int64)
    for i, e in enumerate(lower):                    # built once per (D, n)
        for j in range(n_vars):
            up = list(e)
            up[j] += 1
            cols[i, j] = index[tuple(up)]
    cols.setflags(write=False)
    weight = lower + 1.0
    weight.setflags(write=False)
    return cols, weight


def gradient(y: np.ndarray, coeffs: np.ndarray, degree: int,
             lower: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Gradient ``(R, D)`` of ``p(y) = nu_n(y) . coeffs`` at every row of ``y``.

    Every partial derivative is a degree n-1 polynomial: ``d/dy_j p = sum_l (e_lj + 1)
    U[y_j m_l] m_l``, so the gradient is one product of the degree n-1 monomials ``(R, M')``
    with an ``(M', D)`` coefficient table. ``lower``: ``embed(y, degree - 1)`` when already
    computed.
    """
    y = np.asarray(y, dtype=float)
    if degree == 0:
        return np.zeros_like(y)
    if lower is None:
        lower = embed(y, degree - 1)
    cols, weight = _derivative_map(y.shape[1], degree)
    return lower @ (np.asarray(coeffs, dtype=float)[cols] * weight)


def structural_zeros(rows: np.ndarray, degree: int, tol: float = 0.0) -> np.ndarray:
    """
    Boolean ``(M,)`` mask of monomials that vanish on every row (the paper's ``Z_n``).

    A coordinate that is zero by construction in one row type makes every monomial mixing it
    with a coordinate that is zero in the other row type vanish identically; such columns carry
    no information and must be dropped or the null space is not one-dimensional.
    """
    nonzero = np.abs(np.asarray(rows, dtype=float)) > tol          # (R, D)
    exps = exponents(rows.shape[1], degree)
    uses = exps > 0                                                # (M, D)
    # monomial is non-zero on a row iff every variable it uses is non-zero there
    alive = (uses[None, :, :] <= nonzero[:, None, :]).all(axis=2)  # (R, M)
    return ~alive.any(axis=0)
