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
Unknown focal length: the paper's section 3.3 without the slope singularity, then a refinement.

With the principal point known (image centre) and pixels centred and divided by a fixed scale
``s`` (~ image width, so the columns are comparable), a pixel line ``m_p = (a, b, c)`` is
``m = (a, b, c / f)`` in normalised coordinates (``f`` in units of ``s``) and, for any ``e``
orthogonal to ``m_p``, the row
``[-b e_x + a e_y, -c e_y, c e_x, b e_z, -a e_z, -(e . g_p)]`` is orthogonal to
``u = (w3, w1/f, w2/f, w1 f, w2 f, 1)`` (first order). The multibody coefficients of
``y4 y6^(n-1)`` and ``y2 y6^(n-1)`` are ``sum w1 f`` and ``sum w1 / f`` (likewise y5, y3), which
gives ``f^2`` (the paper's eq. 18, made precise); the two ratios are pooled by least squares.
The first-order estimate is then refined exactly: the profile of the Mahalanobis cost of the
exact known-f model over ``f`` with the labels fixed.
"""
from functools import lru_cache
from math import comb
from typing import Callable, Optional, Tuple

import numpy as np

from .gpca import balance_scale, multibody_vector
from .lines import line_flows
from .models import fit_bodies, track_costs
from .veronese import embed, exponents, monomial_index


def unknown_f_rows_from_normals(m: np.ndarray, e: np.ndarray, g: np.ndarray) -> np.ndarray:
    """
    Build the f-unknown rows ``(..., 6)`` (see the module docstring).

    From pixel-line normals ``m``, directions ``e`` (orthogonal to ``m``) and flows ``g``.
    """
    a, b, c = m[..., 0], m[..., 1], m[..., 2]
    ex, ey, ez = e[..., 0], e[..., 1], e[..., 2]
    return np.stack([-b * ex + a * ey, -c * ey, c * ex, b * ez, -a * ez,
                     -np.sum(e * g, axis=-1)], axis=-1)


@lru_cache(maxsize=None)
def relation_space(degree: int) -> np.ndarray:
    """
    Orthonormal basis ``(M, q)`` of degree-n polynomials vanishing on every f-unknown row.

    The first five coordinates of the f-unknown row (:func:`unknown_f_rows_from_normals`)
    depend on three parameters up to scale, so they lie on a hypersurface: for n >= 4 a
    polynomial in ``y1..y5`` alone vanishes on all rows whatever the motion (checked: rank 125
    of 126 at n = 4). Found numerically on random rows; ``q = 0`` for n <= 3. Columns index the
    6-variable embedding of :func:`.veronese.exponents`.
    """
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


def first_order_focal(tracks: np.ndarray, n: int, image_size: Tuple[float, float]
                      ) -> Optional[float]:
    """Focal length (px) from the f-unknown multibody vector, or None if it is not determined."""
    w, h = image_size
    scale = float(max(w, h))
    flows = line_flows(tracks, (scale, scale, w / 2.0, h / 2.0))
    if flows.n_pairs == 0:
        return None
    mbar = 0.5 * (flows.m0 + flows.m1)
    g = flows.m1 - flows.m0
    rows = unknown_f_rows_from_normals(mbar[:, None, :], np.swapaxes(flows.E, 1, 2),
                                       g[:, None, :]).reshape(-1, 6)
    t = balance_scale(rows)
    rows[:, 5] /= t          # the coefficient ratios below do not depend on t
    exps = exponents(6, n)
    relations = relation_space(n) if n >= 4 else None
    coeffs = multibody_vector(rows, n, relations)

    def coef(k: int) -> float:
        e = [0] * 6
        e[k] += 1
        e[5] += n - 1
        return float(coeffs[monomial_index(exps, e)])

    u2, u3, u4, u5 = coef(1), coef(2), coef(3), coef(4)
    den = u2 * u2 + u3 * u3
    f2 = (u4 * u2 + u5 * u3) / den if den > 0 else np.nan
    if not np.isfinite(f2) or f2 <= 0:
        return None
    return float(np.sqrt(f2) * scale)


def profile_cost(tracks: np.ndarray, labels: np.ndarray, n: int, centre: Tuple[float, float]
                 ) -> Callable[[float], float]:
    """
    ``cost(f)``: total Mahalanobis cost of the exact model at focal length ``f``, bodies refit.

    Tracks labelled ``-1`` do not count.
    """
    cx, cy = centre
    lab = np.asarray(labels)

    def cost(f: float) -> float:
        flows = line_flows(tracks, (f, f, cx, cy))
        c, _ = fit_bodies(flows, lab, n)
        costs = track_costs(flows, c, weighted=True)
        ok = (lab >= 0) & np.isfinite(costs).all(axis=1)
        return float(np.sum(costs[np.flatnonzero(ok), lab[ok]]))
    return cost


def refine_focal(cost: Callable[[float], float], f0: float, span: float = 3.0,
                 grid: int = 17, tol: float = 1e-9) -> float:
    """Minimise ``cost(f)`` over ``f0 / span .. f0 * span``: log grid then golden section."""
    logs = np.linspace(np.log(f0 / span), np.log(f0 * span), grid)
    vals = np.array([cost(float(np.exp(x))) for x in logs])
    k = int(np.argmin(vals))
    lo, hi = logs[max(k - 1, 0)], logs[min(k + 1, grid - 1)]
    phi = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - phi * (hi - lo), lo + phi * (hi - lo)
    fa, fb = cost(float(np.exp(a))), cost(float(np.exp(b)))
    while hi - lo > tol:
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - phi * (hi - lo)
            fa = cost(float(np.exp(a)))
        else:
            lo, a, fa = a, b, fb
            b = lo + phi * (hi - lo)
            fb = cost(float(np.exp(b)))
    return float(np.exp(0.5 * (lo + hi)))
