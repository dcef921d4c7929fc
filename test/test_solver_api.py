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
"""The public contract of ``segment_lines``: exactness, conventions and bad input."""
import itertools

from mlofc_ros.solver import assign_with_motions, get_method, METHODS, segment_lines, WarmStart
from mlofc_ros.solver.lines import rotation_matrix
import numpy as np
import pytest
from scenes import random_scene


def misclassified(labels, truth, n):
    return min(np.mean(labels != np.array(p)[truth]) for p in itertools.permutations(range(n)))


def matched_rotation_error(est, true):
    n = len(true)
    return min(max(np.linalg.norm(est[list(p)] - true, axis=1) / np.linalg.norm(true, axis=1))
               for p in itertools.permutations(range(n)))


@pytest.mark.parametrize('n', [1, 2, 3, 4])
@pytest.mark.parametrize('method', METHODS)
def test_exact_at_zero_noise(n, method):
    tracks, labels, omegas, intr = random_scene(n, 12, n_frames=3, deg=(2.0, 8.0), seed=n,
                                                vertical=2)
    res = segment_lines(tracks, n, intrinsics=intr, method=method)
    assert misclassified(res.labels, labels, n) == 0.0
    assert matched_rotation_error(res.angular_velocities, omegas) < 1e-6
    assert res.labels.shape == (tracks.shape[0],) and res.residuals.shape == (tracks.shape[0],)
    assert res.angular_velocities.shape == (n, 3) and res.focal_length == intr[0]


@pytest.mark.parametrize('n', [1, 2, 3, 4])
@pytest.mark.parametrize('method', ['algebraic', 'robust'])
def test_unknown_focal_length_is_recovered(n, method):
    # the f-unknown model has C(n+5, 5) monomials: 126 for n = 4, so more lines are needed
    lines = 25 if n == 4 else 15
    tracks, labels, omegas, intr = random_scene(n, lines, n_frames=2, f=800.0, seed=10 + n)
    res = segment_lines(tracks, n, intrinsics=None, image_size=(1000, 1000), method=method)
    assert abs(res.focal_length - 800.0) / 800.0 < 0.01
    assert misclassified(res.labels, labels, n) == 0.0
    assert matched_rotation_error(res.angular_velocities, omegas) < 1e-6


def test_convention_body_rotation_in_the_optical_frame():
    """A line rotating by +5 deg about the optical axis gives w = (0, 0, +5 deg)."""
    f, c = 500.0, 320.0
    P = np.array([[-0.5, 0.2, 4.0], [0.6, 0.3, 4.0], [0.1, -0.6, 5.0], [0.2, 0.7, 6.0]])
    w = np.array([0.0, 0.0, np.deg2rad(5.0)])
    tracks = []
    for a, b in ((0, 1), (2, 3), (0, 3), (1, 2)):
        seg = []
        for k in range(2):
            Q = np.stack([P[a], P[b]]) @ rotation_matrix(k * w).T
            seg.append(np.r_[f * Q[:, 0] / Q[:, 2] + c, f * Q[:, 1] / Q[:, 2] + c])
        tracks.append([[s[0], s[2], s[1], s[3]] for s in seg])
    res = segment_lines(np.array(tracks), 1, intrinsics=(f, f, c, c))
    np.testing.assert_allclose(res.angular_velocities[0], w, atol=1e-9)


def test_missing_frames_and_endpoint_sliding():
    tracks, labels, omegas, intr = random_scene(2, 20, n_frames=5, seed=4)
    tracks[::3, 2] = np.nan                       # gaps
    tracks[1::4, 0] = np.nan
    res = segment_lines(tracks, 2, intrinsics=intr)
    assert misclassified(res.labels, labels, 2) == 0.0


def test_floor_and_noise_weighting():
    tracks, labels, omegas, intr = random_scene(2, 20, n_frames=2, noise=1.0, seed=5)
    floor = assign_with_motions(tracks, omegas, intr)
    assert floor.labels.shape == labels.shape
    res = segment_lines(tracks, 2, intrinsics=intr)
    assert 0.3 < res.diagnostics.sigma_px < 3.0       # the endpoint noise is estimated


def test_outlier_tracks_get_minus_one():
    tracks, labels, omegas, intr = random_scene(2, 30, n_frames=5, noise=0.5, seed=6)
    rng = np.random.default_rng(0)
    bad = rng.choice(tracks.shape[0], 9, replace=False)
    tracks[bad] += rng.normal(scale=25.0, size=tracks[bad].shape)    # follow no rigid motion
    res = segment_lines(tracks, 2, intrinsics=intr)
    assert np.mean(res.labels[bad] == -1) >= 0.6
    good = np.setdiff1d(np.arange(tracks.shape[0]), bad)
    assert misclassified(res.labels[good], labels[good], 2) <= 0.05


def test_seed_makes_results_repeat():
    tracks, *_, intr = random_scene(3, 15, noise=1.0, seed=8)
    a = segment_lines(tracks, 3, intrinsics=intr, method='kmeans', seed=3)
    b = segment_lines(tracks, 3, intrinsics=intr, method='kmeans', seed=3)
    np.testing.assert_array_equal(a.labels, b.labels)


GOOD = random_scene(2, 10, seed=9)


@pytest.mark.parametrize('kwargs,match', [
    ({'tracks': np.zeros((5, 2, 3))}, 'shape'),
    ({'tracks': np.zeros((5, 4))}, 'shape'),
    ({'tracks': GOOD[0][:, :1]}, 'K >= 2'),
    ({'tracks': 'abc'}, 'numeric|shape'),
    ({'n_bodies': -1}, 'n_bodies'),
    ({'n_bodies': 1.5}, 'integer'),
    ({'intrinsics': (np.nan, 1000, 500, 500)}, 'finite'),
    ({'intrinsics': (1000, 1000, 500)}, r'\(fx, fy, cx, cy\)'),
    ({'intrinsics': (-1, 1000, 500, 500)}, '> 0'),
    ({'intrinsics': None}, 'image_size'),
    ({'method': 'magic'}, 'unknown method'),
    ({'n_bodies': 4, 'method': 'algebraic', 'tracks': GOOD[0][:6]}, 'usable tracks'),
    ({'n_bodies': 2, 'tracks': np.full((30, 3, 4), np.nan)}, 'usable tracks'),
    ({'tracks': np.where(np.arange(4) < 2, np.inf, 1.0) * np.ones((20, 2, 4))}, 'infinite'),
    ({'method': 'algebraic', 'init_labels': np.zeros(20, int)},
     r"method 'algebraic' does not take init_labels \(it takes none of them\)"),
    ({'method': 'kmeans', 'warm_inliers': 0.5}, "'kmeans' does not take warm_inliers"),
    ({'init_motions': (np.zeros((2, 3)), np.zeros((2, 3)))},
     r"'robust' does not take init_motions \(it takes init_labels, warm_competes, "
     r'warm_inliers\)'),
    ({'method': 'general', 'warm_competes': False}, "'general' does not take warm_competes"),
    ({'method': 'general', 'warm_inliers': 0.5}, "'general' does not take warm_inliers"),
    ({'n_bodies': 0, 'init_labels': np.zeros(20, int)}, 'init_labels need n_bodies >= 1'),
    ({'init_labels': np.zeros(19, int)}, r'init_labels must have shape \(20,\)'),
    ({'init_labels': np.zeros(20)}, 'init_labels must be integers'),
    ({'method': 'general', 'init_motions': (np.zeros((2, 3)), np.zeros((2, 3)))},
     'init_motions need init_labels'),
    ({'method': 'general', 'init_labels': np.zeros(20, int), 'rescan': [0]},
     'rescan needs init_motions'),
    ({'method': 'general', 'init_labels': np.zeros(20, int),
      'init_motions': (np.zeros((2, 3)), np.zeros((2, 3))), 'rescan': [2]},
     r'rescan must name bodies in \[0, 2\)'),
])
def test_bad_input_raises_a_named_value_error(kwargs, match):
    args = {'tracks': GOOD[0], 'n_bodies': 2, 'intrinsics': GOOD[3]}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        segment_lines(args.pop('tracks'), args.pop('n_bodies'), **args)


@pytest.mark.parametrize('n', [1, 2, 3, 4])
def test_number_of_bodies_is_chosen(n):
    tracks, labels, omegas, intr = random_scene(n, 25, n_frames=4, noise=1.0, seed=40 + n)
    res = segment_lines(tracks, 0, intrinsics=intr)
    assert res.n_bodies == n
    assert misclassified(res.labels, labels, n) < 0.05
    assert set(res.diagnostics.n_bodies_scores) >= {1, 2}


def test_multi_frame_beats_two_frames():
    errs = {2: [], 5: []}
    for trial in range(6):
        for k in errs:
            tracks, labels, omegas, intr = random_scene(3, 20, n_frames=k, noise=2.0,
                                                        seed=60 + trial)
            res = segment_lines(tracks, 3, intrinsics=intr)
            errs[k].append(misclassified(res.labels, labels, 3))
    assert np.mean(errs[5]) < 0.5 * np.mean(errs[2])


@pytest.mark.parametrize('n_frames', [2, 5])
def test_stitched_outlier_tracks_do_not_move_the_bodies(n_frames):
    """15% tracks whose every frame is a different real line (mis-association)."""
    tracks, labels, omegas, intr = random_scene(3, 25, n_frames=n_frames, noise=1.0, seed=70)
    rng = np.random.default_rng(1)
    n_out = 13
    out = np.stack([tracks[rng.integers(0, len(tracks), n_out), k] for k in range(n_frames)], 1)
    res = segment_lines(np.concatenate([tracks, out]), 3, intrinsics=intr)
    assert misclassified(res.labels[:len(tracks)], labels, 3) <= 0.03
    assert np.mean(res.labels[len(tracks):] == -1) >= 0.8
    assert matched_rotation_error(res.angular_velocities, omegas) < 0.15


def test_every_method_declares_what_its_callers_need():
    assert METHODS == ('algebraic', 'kmeans', 'algebraic+kmeans', 'robust', 'general')
    for name in METHODS:
        method = get_method(name)
        assert method.name == name and method.keywords <= {
            'init_labels', 'init_motions', 'rescan', 'step', 'step_only', 'warm_inliers',
            'warm_competes'}
        # a method takes the previous window's labels exactly when it has a warm start
        assert ('init_labels' in method.keywords) == (method.warm_start is not WarmStart.NONE)
        assert ('init_motions' in method.keywords) == (method.warm_start is WarmStart.MOTIONS)
        assert ('rescan' in method.keywords) == method.rescans
    general = get_method('general')
    assert general.slow and general.min_frames == 5
    # before five frames (or a shorter window's all), the rotation-only step answers
    assert general.for_window(4, 10).name == 'robust' and general.for_window(5, 10) is general
    assert general.for_window(3, 3) is general
    stand_in = general.for_window(2, 10)
    assert not stand_in.slow and stand_in.warm_start is WarmStart.LABELS
    assert stand_in.accepts('init_labels') and not stand_in.accepts('warm_inliers')
    assert not stand_in.accepts('warm_competes') and stand_in.fixed == {'warm_competes': False}
    robust = get_method('robust')
    assert robust.for_window(2, 10) is robust and robust.accepts('warm_inliers')
    with pytest.raises(ValueError, match='unknown method'):
        get_method('magic')


def test_the_stand_in_is_the_rotation_only_step_of_general():
    # 'general' on two frames answers with its rotation-only step: the stand-in's solve
    tracks, labels, omegas, intr = random_scene(2, 12, n_frames=2, seed=2)
    init = labels.copy()
    init[::5] = -1
    stand_in = get_method('general').for_window(2, 10)
    a = segment_lines(tracks, 2, intrinsics=intr, method=stand_in.name, init_labels=init,
                      **stand_in.fixed)
    b = segment_lines(tracks, 2, intrinsics=intr, method='general', init_labels=init)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.angular_velocities, b.angular_velocities)
    assert b.method == 'general' and a.method == 'robust'
