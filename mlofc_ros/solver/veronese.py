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
"""Veronese embedding of degree n and its gradient, vectorised over rows and monomials.

The multibody constraint ``prod_i (y . u_i) = 0`` is linear in the monomials of ``y``:
``p(y) = nu_n(y) . U``. Monomials are ordered by descending exponent of ``y_0`` first
(lexicographic, so ``y_0^n`` comes first and ``y_{D-1}^n`` last).
"""
from functools import lru_cache
import itertools
from math import comb
from typing import Optional

import numpy as np


@lru_cache(maxsize=None)
def exponents(n_vars: int, degree: int) -> np.ndarray:
    """Exponent matrix ``(M, n_vars)`` int of all monomials of ``degree`` in ``n_vars`` variables.

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


def _powers(y: np.ndarray, degree: int) -> np.ndarray:
    """``(R, D, degree + 1)`` table of ``y_j ** k`` for k = 0..degree (exact 0**0 = 1)."""
    pw = np.empty(y.shape + (degree + 1,))
    pw[..., 0] = 1.0
    for k in range(1, degree + 1):
        pw[..., k] = pw[..., k - 1] * y
    return pw


def _embed_powers(pw: np.ndarray, degree: int) -> np.ndarray:
    """``(R, M)`` monomials of ``degree`` from a power table ``(R, D, >= degree + 1)``."""
    exps = exponents(pw.shape[1], degree)
    # product over the variables in order: the same rounding as np.prod over a gathered
    # (R, M, D) array, without building it
    out = pw[:, 0, exps[:, 0]]
    for j in range(1, pw.shape[1]):                 # D <= 6 variables
        out = out * pw[:, j, exps[:, j]]
    return out


def embed(y: np.ndarray, degree: int) -> np.ndarray:
    """Veronese map ``nu_n``: rows ``(R, D)`` -> ``(R, M)`` monomials of ``degree``."""
    y = np.asarray(y, dtype=float)
    return _embed_powers(_powers(y, degree), degree)


@lru_cache(maxsize=None)
def _gradient_columns(n_vars: int, degree: int) -> np.ndarray:
    """``(D, M)`` columns of ``[nu_n | nu_(n-1)]`` holding ``d/dy_j`` of every monomial / e_j.

    Monomial ``k`` with ``e_kj > 0`` maps to ``y^(e_k - 1_j)`` (a degree n-1 monomial); with
    ``e_kj = 0`` its weight is zero and it maps to itself (any finite value will do).
    """
    exps = exponents(n_vars, degree)
    lower = {tuple(e): i for i, e in enumerate(exponents(n_vars, degree - 1))} if degree else {}
    out = np.empty((n_vars, exps.shape[0]), dtype=np.int64)
    for j in range(n_vars):
        for k, e in enumerate(exps):                # built once per (D, n)
            if e[j] > 0:
                d = list(e)
                d[j] -= 1
                out[j, k] = exps.shape[0] + lower[tuple(d)]
            else:
                out[j, k] = k
    out.setflags(write=False)
    return out


def gradient(y: np.ndarray, coeffs: np.ndarray, degree: int,
             embedded: Optional[np.ndarray] = None) -> np.ndarray:
    """Gradient ``(R, D)`` of ``p(y) = nu_n(y) . coeffs`` at every row of ``y``.

    ``d/dy_j prod_l y_l^e_l = e_j y_j^(e_j - 1) prod_{l != j} y_l^e_l``: the degree n-1
    monomials, gathered per variable. ``embedded``: ``embed(y, degree)`` when already computed.
    """
    y = np.asarray(y, dtype=float)
    d = y.shape[1]
    exps = exponents(d, degree)                  # (M, D)
    pw = _powers(y, degree)                      # (R, D, n+1)
    if embedded is None:
        embedded = _embed_powers(pw, degree)
    both = np.concatenate([embedded, _embed_powers(pw, degree - 1)], axis=1)
    cols = _gradient_columns(d, degree)
    grad = np.empty_like(y)
    for j in range(d):                           # D <= 6 variables, not a loop over rows/monomials
        grad[:, j] = both[:, cols[j]] @ (exps[:, j] * coeffs)
    return grad


def structural_zeros(rows: np.ndarray, degree: int, tol: float = 0.0) -> np.ndarray:
    """Boolean ``(M,)`` mask of monomials that vanish on every row (the paper's ``Z_n``).

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


@lru_cache(maxsize=None)
def relation_space(degree: int) -> np.ndarray:
    """Orthonormal basis ``(M, q)`` of degree-n polynomials vanishing on every f-unknown row.

    The first five coordinates of the f-unknown row (see :mod:`.focal`) depend on three
    parameters up to scale, so they lie on a hypersurface: for n >= 4 a polynomial in
    ``y1..y5`` alone vanishes on all rows whatever the motion (checked: rank 125 of 126 at
    n = 4). Found numerically on random rows; ``q = 0`` for n <= 3. Columns index the 6-variable
    embedding of :func:`exponents`.
    """
    from .focal import unknown_f_rows_from_normals   # local: focal imports this module
    rng = np.random.default_rng(12345)
    n_rows = 4 * comb(degree + 4, 4)
    m = rng.normal(size=(n_rows, 3))
    e = np.cross(m, rng.normal(size=(n_rows, 3)))
    rows = unknown_f_rows_from_normals(m, e, np.zeros((n_rows, 3)))[:, :5]
    v = embed(rows / np.linalg.norm(rows, axis=1, keepdims=True), degree)
    _, s, vt = np.linalg.svd(v)
    null5 = vt[int(np.sum(s > s[0] * 1e-9)):].T                 # (M5, q)
    exps6 = exponents(6, degree)
    out = np.zeros((exps6.shape[0], null5.shape[1]))
    for k, e5 in enumerate(exponents(5, degree)):               # index map, built once per n
        out[monomial_index(exps6, tuple(e5) + (0,)), :] = null5[k]
    return out
