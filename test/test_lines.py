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
"""Line flows against straightforward per-track references (dense Cholesky, stacked 3x3s)."""
from mlofc_ros.solver.lines import interpretation_normals, line_flows, whiten_tracks
from mlofc_tools.synthetic import make_scene
import numpy as np
import pytest


def dense_whiten(n_tracks, n_slots, ti, ki, E, cov0, cov1, M, b):
    """Whiten with the dense ``(N, 2S, 2S)`` covariance, LAPACK Cholesky and solve."""
    d = 2 * n_slots
    full = np.zeros((n_tracks, d, d))
    full[:, np.arange(d), np.arange(d)] = 1.0                         # missing pairs: unit
    cov = full.reshape(n_tracks, n_slots, 2, n_slots, 2)
    Et = np.swapaxes(E, 1, 2)
    cov[ti, ki, :, ki] = Et @ (cov0 + cov1) @ E
    lookup = np.full((n_tracks, n_slots + 1), -1)
    lookup[ti, ki] = np.arange(ti.size)
    nxt = lookup[ti, ki + 1]
    p, q = np.flatnonzero(nxt >= 0), nxt[nxt >= 0]
    off = -(Et[p] @ cov1[p] @ E[q])
    cov[ti[p], ki[p], :, ki[q]] = off
    cov[ti[p], ki[q], :, ki[p]] = np.swapaxes(off, 1, 2)
    stacked = np.zeros((n_tracks, n_slots, 2, 4))
    stacked[ti, ki, :, :3] = M
    stacked[ti, ki, :, 3] = -b
    return np.linalg.solve(np.linalg.cholesky(full), stacked.reshape(n_tracks, d, 4))


def stacked_normals(tracks, intrinsics):
    """Compute normals and covariances with per-frame 3x3 matrices and a loop for signs."""
    fx, fy, cx, cy = intrinsics
    xa = np.stack([(tracks[..., 0] - cx) / fx, (tracks[..., 1] - cy) / fy,
                   np.ones(tracks.shape[:2])], -1)
    xb = np.stack([(tracks[..., 2] - cx) / fx, (tracks[..., 3] - cy) / fy,
                   np.ones(tracks.shape[:2])], -1)
    n = np.cross(xa, xb)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    m = n / norm
    last = np.full((m.shape[0], 3), np.nan)
    for k in range(m.shape[1]):
        m[np.sum(m[:, k] * last, axis=1) < 0, k] *= -1.0
        ok = np.isfinite(m[:, k, 0])
        last[ok] = m[ok, k]

    def sk(v):
        out = np.zeros(v.shape + (3,))
        out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
        return out - np.swapaxes(out, -1, -2)

    K2 = np.array([[1.0 / fx, 0.0], [0.0, 1.0 / fy], [0.0, 0.0]])
    J = np.concatenate([-sk(xb) @ K2, sk(xa) @ K2], axis=-1)           # d n / d endpoints
    P = np.eye(3) - m[..., :, None] * m[..., None, :]
    G = P @ J / norm[..., None]
    return m, G @ np.swapaxes(G, -1, -2)


def window(seed, n=40):
    """Make a noisy window with random K, missing frames and swapped endpoints (flips)."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(2, 8))
    sc = make_scene(2, n // 2, n_frames=k, noise_px=1.0, seed=seed)
    tracks = np.array(sc.tracks, dtype=float)
    swap = rng.random(tracks.shape[:2]) < 0.2
    tracks[swap] = tracks[swap][:, [2, 3, 0, 1]]
    tracks[rng.random(tracks.shape[:2]) < rng.uniform(0.1, 0.4)] = np.nan
    return tracks, tuple(sc.intrinsics)        # missing frames: whole rows of NaN


@pytest.mark.parametrize('seed', range(12))
def test_whitening_matches_dense_cholesky(seed):
    tracks, intr = window(seed)
    fl = line_flows(tracks, intr)
    n, s = tracks.shape[0], tracks.shape[1] - 1
    args = (n, s, fl.pair_track, fl.pair_slot, fl.E, fl.cov0, fl.cov1, fl.M, fl.b)
    ref = dense_whiten(*args)
    scale = np.linalg.norm(ref, axis=-1, keepdims=True) + 1e-300
    assert fl.track_rows.shape == ref.shape == (n, 2 * s, 4)
    assert np.max(np.abs(fl.track_rows - ref) / scale) < 1e-9
    assert np.max(np.abs(whiten_tracks(*args) - ref) / scale) < 1e-9
    # missing pairs: zero rows, exactly
    have = np.zeros((n, s), bool)
    have[fl.pair_track, fl.pair_slot] = True
    assert not np.any(fl.track_rows.reshape(n, s, 2, 4)[~have])
    assert (~have).any() and (s < 2 or (have[:, :-1] & ~have[:, 1:]).any())   # gaps inside


@pytest.mark.parametrize('seed', range(6))
def test_line_flow_fields_match_stacked_forms(seed):
    tracks, intr = window(seed)
    fl = line_flows(tracks, intr)
    m, cov = stacked_normals(tracks, intr)
    m_new, cov_new = interpretation_normals(tracks, intr)
    ok = np.isfinite(m[..., 0])
    assert np.array_equal(ok, np.isfinite(m_new[..., 0]))
    np.testing.assert_allclose(m_new[ok], m[ok], rtol=0, atol=1e-15)
    np.testing.assert_allclose(cov_new[ok], cov[ok], rtol=1e-10,
                               atol=1e-12 * np.abs(cov[ok]).max())
    ti, ki = np.nonzero(ok[:, :-1] & ok[:, 1:])
    assert np.array_equal(fl.pair_track, ti) and np.array_equal(fl.pair_slot, ki)
    assert np.array_equal(fl.m0, m_new[ti, ki]) and np.array_equal(fl.cov1, cov_new[ti, ki + 1])
    mbar = 0.5 * (fl.m0 + fl.m1)
    Et = np.swapaxes(fl.E, 1, 2)
    np.testing.assert_allclose(Et @ fl.E, np.broadcast_to(np.eye(2), (ti.size, 2, 2)), atol=1e-15)
    np.testing.assert_allclose(np.einsum('pji,pi->pj', Et, mbar), 0.0, atol=1e-15)
    np.testing.assert_allclose(fl.M, np.cross(mbar[:, None], Et), atol=1e-16)
    np.testing.assert_allclose(fl.b, np.einsum('pji,pi->pj', Et, fl.m1 - fl.m0), atol=1e-16)


def test_exactly_perpendicular_normals_keep_their_signs():
    # horizontal, the same reversed (flipped back), then vertical through the principal point:
    # m_2 . m_1 = 0 exactly, which never flips whatever the earlier flips (the frame-by-frame
    # path), then the vertical reversed (flipped)
    intr = (500.0, 500.0, 320.0, 240.0)
    tracks = np.array([[[300.0, 240, 340, 240], [340, 240, 300, 240], [320, 220, 320, 260],
                        [320, 260, 320, 220]]])
    m, _ = interpretation_normals(tracks, intr)
    np.testing.assert_array_equal(m[0], [[0, 1, 0], [0, 1, 0], [-1, 0, 0], [-1, 0, 0]])
    np.testing.assert_array_equal(m, stacked_normals(tracks, intr)[0])
