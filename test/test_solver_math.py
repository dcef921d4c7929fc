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
"""The equations of the line-flow model, checked numerically against finite rotations."""
from math import comb

from mlofc_ros.solver.focal import relation_space, unknown_f_rows_from_normals
from mlofc_ros.solver.gpca import algebraic_normals
from mlofc_ros.solver.lines import (cayley_to_rotvec, line_flows, orthonormal_pair,
                                    rotation_matrix, rotvec_to_cayley, skew)
from mlofc_ros.solver.veronese import embed, exponents, gradient, structural_zeros
import numpy as np
import pytest
from scenes import random_scene


RNG = np.random.default_rng(7)


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize('deg', [0.5, 3.0, 6.0, 20.0])
def test_cayley_midpoint_form_is_exact(deg):
    w = unit(RNG.normal(size=3)) * np.deg2rad(deg)
    R = rotation_matrix(w)
    m = unit(RNG.normal(size=(200, 3)))
    m2 = m @ R.T
    c = rotvec_to_cayley(w)
    # m' - m = c x m_bar exactly, for finite rotations
    np.testing.assert_allclose(m2 - m, np.cross(c, 0.5 * (m + m2)), atol=1e-14)
    np.testing.assert_allclose(cayley_to_rotvec(c), w, atol=1e-15)


def test_first_order_form_is_biased_at_several_degrees():
    w = unit(np.array([0.3, -0.5, 0.8])) * np.deg2rad(4.0)
    m = unit(RNG.normal(size=(500, 3)))
    m2 = m @ rotation_matrix(w).T
    # least-squares W from g = W x m (first order, the paper's eqs. 3-10)
    A = -skew(m).reshape(-1, 3)
    w_first, *_ = np.linalg.lstsq(A, (m2 - m).ravel(), rcond=None)
    rel = np.linalg.norm(w_first - w) / np.linalg.norm(w)
    assert 1e-4 < rel < 0.05           # a visible first-order bias (~1%), unlike the Cayley form


def test_rows_are_orthogonal_to_u_for_finite_rotations():
    tracks, labels, omegas, intr = random_scene(2, 15, n_frames=4, deg=(5.0, 6.0), seed=3)
    flows = line_flows(tracks, intr)
    c = rotvec_to_cayley(omegas)[labels[flows.pair_track]]                 # (P, 3)
    u = np.concatenate([c, np.ones((c.shape[0], 1))], axis=1)
    np.testing.assert_allclose(np.einsum('pjk,pk->pj', flows.rows, u), 0.0, atol=1e-13)
    assert flows.n_pairs == 30 * 3                                          # 2(K-1) rows a line


def test_orthonormal_pair_handles_every_direction():
    m = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [1, 1, 1e-12]])
    E = orthonormal_pair(m)
    np.testing.assert_allclose(np.einsum('pi,pij->pj', unit(m), E), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.swapaxes(E, 1, 2) @ E, np.broadcast_to(np.eye(2), (4, 2, 2)),
                               atol=1e-15)


def test_paper_slope_intercept_rows_first_order():
    """Corrected eq. (11): [kb, -b^2, 0, -1, -k, -db] and [1+k^2, -kb, b, 0, 0, -dk]."""
    f = 1.3
    for deg in (0.2, 0.05):
        w = unit(np.array([0.4, -0.7, 0.6])) * np.deg2rad(deg)
        k, b = RNG.uniform(-1, 1, 50), RNG.uniform(-1, 1, 50)
        m = np.stack([-k, np.ones_like(k), -b / f], axis=1)        # the paper's eq. (1)
        m2 = m @ rotation_matrix(w).T          # W: the body's rotation, as in the solver
        k2, b2 = -m2[:, 0] / m2[:, 1], -m2[:, 2] * f / m2[:, 1]
        u = np.array([w[2], w[0] / f, w[1] / f, w[0] * f, w[1] * f, 1.0])
        r1 = np.stack([k * b, -b * b, 0 * k, -np.ones_like(k), -k, -(b2 - b)], 1) @ u
        r2 = np.stack([1 + k * k, -k * b, b, 0 * k, 0 * k, -(k2 - k)], 1) @ u
        # the neglected terms are second order: relative to the flow they shrink with the angle
        rel = max(np.max(np.abs(r1)) / np.max(np.abs(b2 - b)),
                  np.max(np.abs(r2)) / np.max(np.abs(k2 - k)))
        assert rel < 1.5 * np.deg2rad(deg)


def test_unknown_f_row_is_orthogonal_to_u():
    f = 0.8                                              # in units of the pixel scale s
    w = unit(np.array([0.2, 0.9, -0.3])) * 1e-4          # first order: tiny rotation
    m_n = unit(RNG.normal(size=(100, 3)))                # normalised-coordinate normals
    m_n2 = m_n @ rotation_matrix(w).T
    to_pix = np.array([1.0, 1.0, f])                     # (a, b, c/f) -> (a, b, c)
    mp, mp2 = m_n * to_pix, m_n2 * to_pix
    e = unit(np.cross(mp, RNG.normal(size=(100, 3))))
    rows = unknown_f_rows_from_normals(mp, e, mp2 - mp)
    u = np.array([w[2], w[0] / f, w[1] / f, w[0] * f, w[1] * f, 1.0])
    assert np.max(np.abs(rows @ u)) < 1e-3 * np.max(np.abs(rows[:, 5]))


@pytest.mark.parametrize('n_vars,degree',
                         [(4, 1), (4, 2), (4, 3), (4, 4), (4, 5), (6, 2), (6, 3), (6, 5)])
def test_veronese_embedding_and_gradient(n_vars, degree):
    exps = exponents(n_vars, degree)
    assert exps.shape == (comb(degree + n_vars - 1, n_vars - 1), n_vars)
    y = RNG.normal(size=(7, n_vars))
    v = embed(y, degree)
    np.testing.assert_allclose(v, np.prod(y[:, None, :] ** exps[None], axis=2), rtol=1e-12)
    # built from a given lower degree: the same products
    lower = embed(y, degree - 1)
    assert np.array_equal(embed(y, degree, lower), v)
    coeffs = RNG.normal(size=exps.shape[0])
    grad = gradient(y, coeffs, degree)
    assert np.array_equal(gradient(y, coeffs, degree, lower), grad)
    h = 1e-6
    for j in range(n_vars):
        d = np.zeros(n_vars)
        d[j] = h
        fd = (embed(y + d, degree) @ coeffs - embed(y - d, degree) @ coeffs) / (2 * h)
        np.testing.assert_allclose(grad[:, j], fd, rtol=1e-6, atol=1e-8)


def test_veronese_degree_zero():
    y = RNG.normal(size=(5, 4))
    assert np.array_equal(embed(y, 0), np.ones((5, 1)))
    assert np.array_equal(gradient(y, np.ones(1), 0), np.zeros((5, 4)))


@pytest.mark.parametrize('n_vars,n', [(4, 1), (4, 3), (4, 5), (6, 3)])
def test_gpca_recovers_exact_hyperplanes(n_vars, n):
    normals = np.concatenate([RNG.normal(size=(n, n_vars - 1)), np.ones((n, 1))], axis=1)
    rows = []
    for u in normals:
        # rows on the hyperplane y . u = 0: free head, last entry solved for
        head = RNG.normal(size=(40, n_vars - 1))
        rows.append(np.concatenate([head, -(head @ u[:-1])[:, None]], axis=1))
    got = algebraic_normals(np.concatenate(rows), n)
    # one recovered normal per true one, in any order
    err = np.max(np.abs(got[:, None, :] - normals[None]), axis=2)
    assert np.all(np.min(err, axis=0) < 1e-6)


@pytest.mark.parametrize('n', [2, 3, 4])
def test_structural_zeros_of_the_paper_rows(n):
    """
    Z_n: monomials with y3 and (y4 or y5) vanish on every row of the paper's form.

    The count is C(n+4, 5) - C(n+2, 3) (monomials containing y3 minus those containing y3 but
    neither y4 nor y5): 2, 11, 36. The paper's closed form gives 2 for n = 2 but 17 for n = 3
    (garbled like its eqs. 19-22); this count is checked against the rank numerically.
    """
    k, b = RNG.normal(size=60), RNG.normal(size=60)
    r1 = np.stack([k * b, -b * b, 0 * k, -np.ones(60), -k, RNG.normal(size=60)], 1)
    r2 = np.stack([1 + k * k, -k * b, b, 0 * k, 0 * k, RNG.normal(size=60)], 1)
    rows = np.vstack([r1, r2])
    zeros = structural_zeros(rows, n)
    assert zeros.sum() == comb(n + 4, 5) - comb(n + 2, 3)
    v = embed(rows, n)
    assert np.all(v[:, zeros] == 0)


def test_unknown_f_rows_lie_on_a_quartic():
    """Our f-unknown rows have no structural zeros but one degree-4 relation (no y6 term)."""
    assert relation_space(2).shape[1] == 0 and relation_space(3).shape[1] == 0
    q = relation_space(4)
    assert q.shape[1] == 1
    m = RNG.normal(size=(50, 3))
    e = np.cross(m, RNG.normal(size=(50, 3)))
    rows = unknown_f_rows_from_normals(m, e, RNG.normal(size=(50, 3)))
    rows /= np.linalg.norm(rows, axis=1, keepdims=True)
    assert np.max(np.abs(embed(rows, 4) @ q)) < 1e-9


def _ksubspaces_naive(stats, n, labels, dof, max_iter=100):
    """K-subspaces with trimming as a plain loop (no cycle detection), the reference."""
    from mlofc_ros.solver.ksubspaces import reseed_empty, assign, trim_bound
    from mlofc_ros.solver.models import fit_stats, quad_costs
    labels, steps = labels.copy(), 0
    for steps in range(1, max_iter + 1):
        c, _ = fit_stats(stats, labels, n)
        costs = quad_costs(stats, c)
        new = reseed_empty(assign(costs, trim_bound(costs, dof)), costs, n, 2)
        if np.array_equal(new, labels):
            break
        labels = new
    return labels, c, costs, steps


@pytest.mark.parametrize('seed', [2, 22])
def test_ksubspaces_cycle_jump_gives_the_plain_loop_result(seed):
    # trimming makes these labellings cycle: the plain loop runs all 100 iterations, and the
    # cycle jump must end on exactly the same labels, c and costs
    from mlofc_ros.solver.ksubspaces import ksubspaces
    from mlofc_ros.solver.models import track_stats
    from mlofc_tools.synthetic import add_outliers, make_scene
    sc = make_scene(2, 15, n_frames=5, noise_px=2.0, seed=seed)
    tracks, _ = add_outliers(sc.tracks, 0.3, np.random.default_rng(seed))
    flows = line_flows(np.asarray(tracks, dtype=np.float64), sc.intrinsics)
    stats, dof = track_stats(flows), 2.0 * flows.pairs_per_track()
    init = np.random.default_rng(seed).integers(-1, 2, tracks.shape[0])
    lab0, c0, costs0, steps = _ksubspaces_naive(stats, 2, init, dof)
    assert steps == 100                                   # the case does cycle
    lab, c, costs = ksubspaces(stats, 2, init, trim_dof=dof)
    assert np.array_equal(lab, lab0)
    assert np.array_equal(c, c0)
    assert np.array_equal(costs, costs0, equal_nan=True)
