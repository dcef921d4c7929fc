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
"""The cheaper forms of the cold robust solve agree with the direct ones they replace."""
from mlofc_ros.solver import robust
from mlofc_ros.solver.gpca import algebraic_normals, gram_null_vector, multibody_vector
from mlofc_ros.solver.ksubspaces import trim_bound
from mlofc_ros.solver.lines import line_flows, rotvec_to_cayley
from mlofc_ros.solver.models import chi2_quantile, solve_normal_equations, track_stats
from mlofc_ros.solver.veronese import embed
from mlofc_tools.synthetic import make_scene
import numpy as np


def _flows(noise_px, seed=3, k=5):
    sc = make_scene(3, 40, n_frames=k, noise_px=noise_px, seed=seed)
    return sc, line_flows(np.array(sc.tracks, dtype=float), tuple(sc.intrinsics))


def _same_hyperplanes(u, v, tol):
    """Both ``(n, 4)`` sets hold the same normals (last entry 1), in any order."""
    d = np.abs(u[:, None, :] - v[None, :, :]).max(axis=2)
    assert np.all(d.min(axis=1) < tol), d


def test_gram_null_vector_matches_the_qr_one():
    for noise_px, tol in ((0.0, 1e-6), (1.0, 1e-6)):
        _, flows = _flows(noise_px)
        rows = flows.whitened_rows.reshape(-1, 4)
        v = embed(rows, 3)
        qr = multibody_vector(rows, 3, embedded=v)
        gram = gram_null_vector(v)
        assert abs(abs(qr @ gram) - 1.0) < tol
        # the weighted start's normals: the true Cayley vectors at zero noise, and those of
        # the QR solution with noise
        _same_hyperplanes(algebraic_normals(rows, 3, gram=True), algebraic_normals(rows, 3),
                          1e-5)


def test_gram_start_recovers_the_true_motions_at_zero_noise():
    sc, flows = _flows(0.0)
    u = algebraic_normals(flows.whitened_rows.reshape(-1, 4), 3, gram=True)
    truth = np.hstack([rotvec_to_cayley(sc.angular_velocities), np.ones((3, 1))])
    _same_hyperplanes(u, truth, 1e-6)


def test_free_residuals_match_a_lapack_solve():
    for noise_px in (0.0, 1.0):
        _, flows = _flows(noise_px)
        stats = track_stats(flows)
        dof = 2.0 * flows.pairs_per_track()
        c = solve_normal_equations(stats.A, stats.g)
        ref = np.maximum(stats.k - np.einsum('ij,ij->i', stats.g, c), 0.0)
        got = robust.free_residuals(stats, dof)
        # both are k - g A^-1 g with k >> the result: rounding of k sets the tolerance
        assert np.allclose(got, ref, rtol=1e-5, atol=1e-9 * stats.k.max())


def test_free_residuals_of_rank_deficient_tracks_stay_finite():
    _, flows = _flows(1.0)
    stats = track_stats(flows)
    a = stats.A.copy()
    a[:5] = np.outer([1.0, 2.0, 0.0], [1.0, 2.0, 0.0])         # rank 1: the ridge holds it
    stats.A = a
    out = robust.free_residuals(stats, 2.0 * flows.pairs_per_track())
    assert np.all(np.isfinite(out)) and np.all(out >= 0.0)


def test_trim_bound_fast_path_matches_the_masked_one():
    rng = np.random.default_rng(0)
    costs = rng.gamma(2.0, 1.0, size=(50, 3))
    dof = np.full(50, 8.0)
    fast = trim_bound(costs, dof)
    q50 = chi2_quantile(0.5, dof)
    best = np.min(costs, axis=1) / q50
    assert np.array_equal(fast, chi2_quantile(0.9999, dof) * np.median(best))
    costs[3, 1] = np.nan                                        # one unusable track: masked
    masked = trim_bound(costs, dof)
    keep = np.arange(50) != 3
    assert np.array_equal(
        masked, chi2_quantile(0.9999, dof) * np.median(np.min(costs[keep], axis=1) / q50[keep]))


def test_line_flows_copy_the_per_pair_arrays_out_only_when_asked():
    _, flows = _flows(1.0)
    assert 'frames' not in flows.cache and 'Mb' not in flows.cache and 'E' not in flows.cache
    m0 = flows.m0
    assert flows.m0 is m0 and flows.M.shape == (flows.n_pairs, 2, 3)
    assert flows.rows.shape == (flows.n_pairs, 2, 4)
