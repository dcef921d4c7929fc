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
"""The synthetic scene generator (paper section 4.1), its outliers and the scoring helpers."""
from mlofc_tools.scoring import (best_permutation, misclassification, misclassification_any,
                                 motion_errors)
from mlofc_tools.synthetic import add_outliers, make_scene, MIXES, rotation_matrices
import numpy as np
import pytest


def _normals(tracks: np.ndarray, intrinsics) -> np.ndarray:
    """Return the unit interpretation-plane normals (N, K, 3) of pixel segments (N, K, 4)."""
    fx, fy, cx, cy = intrinsics
    p = tracks.reshape(tracks.shape[0], tracks.shape[1], 2, 2)
    x = np.stack([(p[..., 0] - cx) / fx, (p[..., 1] - cy) / fy, np.ones(p.shape[:-1])], axis=-1)
    m = np.cross(x[..., 0, :], x[..., 1, :])
    return m / np.linalg.norm(m, axis=-1, keepdims=True)


def _rotation_mismatch(scene) -> np.ndarray:
    """Return ``1 - |m_{k+1} . R m_k|`` for every line and frame pair, (N, K-1)."""
    m = _normals(scene.clean_tracks, scene.intrinsics)
    rot = rotation_matrices(scene.angular_velocities)[scene.labels]  # (N, 3, 3)
    pred = np.einsum('nij,nkj->nki', rot, m[:, :-1])
    return 1.0 - np.abs(np.sum(pred * m[:, 1:], axis=-1))


def test_shapes_and_ranges():
    s = make_scene(3, [5, 6, 7], n_frames=4, noise_px=0.5, seed=3)
    n = 18
    assert s.tracks.shape == (n, 4, 4) and s.clean_tracks.shape == (n, 4, 4)
    assert s.points.shape == (n, 4, 2, 3)
    assert s.labels.shape == (n,) and np.bincount(s.labels).tolist() == [5, 6, 7]
    assert s.angular_velocities.shape == (3, 3) and s.translations.shape == (3, 3)
    assert s.n_bodies == 3 and s.n_frames == 4 and s.reference_frame == 1
    assert s.intrinsics == (1000.0, 1000.0, 500.0, 500.0) and s.image_size == (1000, 1000)
    angles = np.degrees(np.linalg.norm(s.angular_velocities, axis=1))
    assert np.all((angles >= 2.0) & (angles <= 6.0))
    assert np.all(s.translations == 0.0)
    uv = s.clean_tracks.reshape(n, 4, 2, 2)
    assert np.all((uv >= 0) & (uv <= 999))
    length = np.linalg.norm(uv[:, :, 1] - uv[:, :, 0], axis=-1)
    assert length.min() >= 25.0 and length.max() <= 550.0
    depth = s.points[:, s.reference_frame, :, 2]
    assert depth.min() >= 5.0 * 0.8 and depth.max() <= 8.0 * 1.25  # sliding moves endpoints
    # endpoints do not correspond between frames: they slide along the line
    assert not np.allclose(s.points[:, 0], s.points[:, 1], atol=1e-6)
    noise = s.tracks - s.clean_tracks
    assert 0.3 < noise.std() < 0.7


def test_determinism():
    a = make_scene(2, 10, seed=42)
    b = make_scene(2, 10, seed=np.random.default_rng(42))
    c = make_scene(2, 10, seed=43)
    np.testing.assert_array_equal(a.tracks, b.tracks)
    np.testing.assert_array_equal(a.labels, b.labels)
    assert not np.allclose(a.tracks, c.tracks)


@pytest.mark.parametrize('n_frames', [2, 5])
def test_noise_free_lines_are_exact_projections(n_frames):
    s = make_scene(2, 20, n_frames=n_frames, noise_px=0.0, seed=7)
    np.testing.assert_array_equal(s.tracks, s.clean_tracks)
    # pure rotation about the camera centre: m_{k+1} = R m_k up to sign
    assert _rotation_mismatch(s).max() < 1e-12
    # and the clean tracks are the pinhole projections of the stored 3D endpoints
    p = s.points @ s.K.T
    np.testing.assert_allclose((p[..., :2] / p[..., 2:]).reshape(s.clean_tracks.shape),
                               s.clean_tracks, atol=1e-9)


def test_translation_moves_lines_off_the_rotation_model():
    s = make_scene(2, 20, n_frames=3, noise_px=0.0, translation_ratio=4.0, seed=5)
    ratio = np.linalg.norm(s.translations, axis=1) / np.linalg.norm(s.angular_velocities, axis=1)
    np.testing.assert_allclose(ratio, 4.0)
    assert _rotation_mismatch(s).max() > 1e-6
    # X_{k+1} = R X_k + T holds for every body, on the 3D line (endpoints slide along it)
    rot = rotation_matrices(s.angular_velocities)[s.labels]
    moved = np.einsum('nij,nej->nei', rot, s.points[:, 0]) + s.translations[s.labels][:, None]
    d = s.points[:, 1, 1] - s.points[:, 1, 0]
    for e in range(2):
        off = moved[:, e] - s.points[:, 1, 0]
        dist = np.linalg.norm(np.cross(off, d), axis=1) / np.linalg.norm(d, axis=1)
        assert dist.max() < 1e-9


def test_pure_translation_body():
    s = make_scene(3, 10, noise_px=0.0, translation_ratio=2.0, pure_translation_body=True,
                   seed=11)
    assert np.all(s.angular_velocities[-1] == 0.0)
    w0 = np.linalg.norm(s.angular_velocities[0])
    np.testing.assert_allclose(np.linalg.norm(s.translations[-1]), 2.0 * w0)
    np.testing.assert_allclose(np.linalg.norm(s.translations[1]),
                               2.0 * np.linalg.norm(s.angular_velocities[1]))
    static = make_scene(2, 10, noise_px=0.0, pure_translation_body=True, seed=11)
    last = static.labels == 1
    # a static body's lines stay put (only the endpoints slide along them)
    m = _normals(static.clean_tracks[last], static.intrinsics)
    assert np.max(1.0 - np.abs(np.sum(m[:, 0] * m[:, 1], axis=-1))) < 1e-12


def test_invalid_arguments():
    with pytest.raises(ValueError):
        make_scene(2, 10, n_frames=1)
    with pytest.raises(ValueError):
        make_scene(2, 10, depth=(8.0, 5.0))
    with pytest.raises(ValueError, match='visible'):
        make_scene(1, 5, n_frames=30, rotation_deg=(40.0, 45.0), seed=0)


def test_scoring_helpers():
    truth = np.array([0, 0, 0, 1, 1, 2, 2])
    pred = np.array([2, 2, 1, 0, 0, 1, -1])
    perm, errors = best_permutation(pred, truth, 3)
    assert perm == (1, 2, 0) and errors == 2
    assert misclassification(pred, truth, 3) == pytest.approx(2 / 7)
    w = np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.0]])
    rel, abs_deg = motion_errors(w[[1, 2, 0]], w, perm)
    assert rel == 0.0 and abs_deg == 0.0
    # the count estimated: any ids, a body found beyond the true ones is wrong
    assert misclassification_any(pred * 10 + 7, truth) == pytest.approx(2 / 7)
    assert misclassification_any(np.array([5, 5, 5, 9, 9, 3, 3]), truth) == 0.0
    assert misclassification_any(np.array([5, 5, 4, 9, 9, 3, 3]), truth) == pytest.approx(1 / 7)
    assert misclassification_any(np.zeros(7, int), truth) == pytest.approx(4 / 7)


@pytest.mark.parametrize('mix', MIXES)
def test_add_outliers(mix: str) -> None:
    scene = make_scene(2, 20, n_frames=3, noise_px=1.0, seed=3)
    rng = np.random.default_rng(0)
    tracks, kind = add_outliers(scene.tracks, 0.15, rng, mix)
    assert tracks.shape == scene.tracks.shape
    assert np.sum(kind > 0) == 6
    np.testing.assert_array_equal(tracks[kind == 0], scene.tracks[kind == 0])
    if mix != 'stitched':
        jit = kind == 1
        moved = np.hypot(*(tracks[jit] - scene.tracks[jit]).reshape(-1, 2).T)
        assert np.all((moved >= 10.0 - 1e-9) & (moved <= 30.0 + 1e-9))
    if mix != 'jitter':
        # every frame of a stitched track is that frame of some OTHER line of the scene
        for i in np.flatnonzero(kind == 2):
            for k in range(scene.n_frames):
                same = np.all(scene.tracks[:, k] == tracks[i, k], axis=1)
                assert same.any() and not same[i]
    with pytest.raises(ValueError):
        add_outliers(scene.tracks, 0.15, rng, 'bogus')
