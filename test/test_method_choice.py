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
"""``method='auto'``: the tracks' jitter, the switch to the general model, the pipeline's use."""
import math

from mlofc_ros.method_choice import (MethodChoice, misfit_bodies, MISFIT_QUARTILE_RATIO,
                                     MISFIT_RATIO, MISFIT_SOLVES, track_jitter,
                                     track_jitters, TRANSLATION_METHOD)
from mlofc_ros.pipeline import Pipeline
from mlofc_tools.scoring import misclassification
import numpy as np
import pytest
from scenes import random_scene


def moving_lines(n: int, k: int, noise: float, seed: int = 0) -> np.ndarray:
    """``(n, k, 4)`` px: lines turning and sliding at constant rates, endpoint noise ``noise``."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform(100, 900, (n, 1, 2))
    half = rng.uniform(15, 60, (n, 1, 1))
    # up to 1 deg and 2 px per frame: over 10 frames still about quadratic
    angle = rng.uniform(0, np.pi, (n, 1)) + rng.uniform(-0.02, 0.02, (n, 1)) * np.arange(k)
    centre = centre + rng.uniform(-2, 2, (n, 1, 2)) * np.arange(k)[None, :, None]
    d = half * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    tracks = np.concatenate([centre - d, centre + d], axis=-1)
    return tracks + rng.normal(0.0, noise, tracks.shape)


@pytest.mark.parametrize('k', [5, 6, 10])
def test_the_jitter_is_the_endpoint_noise_whatever_the_smooth_motion(k):
    for noise in (0.1, 0.5, 2.0):
        jitter = track_jitter(moving_lines(400, k, noise, seed=k))
        # the median of a chi-square over its dof is a little below 1
        assert 0.8 * noise < jitter < 1.05 * noise, (noise, jitter)
    assert track_jitter(moving_lines(400, k, 0.0)) < 0.02        # the motion leaves nothing


def test_the_jitter_needs_tracks_seen_in_every_frame_and_five_frames():
    tracks = moving_lines(40, 5, 0.5)
    tracks[:31, 2] = np.nan                                       # 9 tracks seen throughout
    assert math.isnan(track_jitter(tracks))
    assert math.isnan(track_jitter(moving_lines(40, 4, 0.5)))
    tracks = moving_lines(40, 5, 0.5)
    tracks[:5, :, 2:] = tracks[:5, :, :2]                         # zero-length lines: left out
    assert 0.4 < track_jitter(tracks) < 0.55
    with pytest.raises(ValueError, match='must be'):
        track_jitter(np.zeros((10, 5, 3)))


def test_the_choice_moves_on_the_median_of_a_few_windows_and_for_good():
    tracks = moving_lines(50, 5, 0.5)
    jitter = track_jitter(tracks)
    choice = MethodChoice()

    def residuals(level: float) -> np.ndarray:
        # a median of ``level``: the tail (outliers, a few tracks left unusable) does not count
        r = np.full(50, level)
        r[:10], r[10:15] = 100.0 * level, np.nan
        return r
    high = residuals(3.0 * MISFIT_RATIO * jitter)
    # one poor window among good ones: no switch
    for r in [high] + [residuals(0.5 * jitter)] * (2 * MISFIT_SOLVES):
        assert not choice.add(r, track_jitter(tracks))
    assert choice.method == 'robust' and choice.ratio is None
    # too few usable residuals or tracks are not counted
    assert not choice.add(np.full(50, np.nan), track_jitter(tracks))
    assert not choice.add(high[:5], track_jitter(tracks[:5]))
    switched = [choice.add(high, track_jitter(tracks)) for _ in range(MISFIT_SOLVES)]
    assert switched.index(True) == MISFIT_SOLVES // 2 and sum(switched) == 1
    assert choice.method == TRANSLATION_METHOD and choice.ratio > MISFIT_RATIO
    assert not choice.add(residuals(0.1 * jitter), track_jitter(tracks))
    assert choice.method == TRANSLATION_METHOD
    choice.reset()
    assert choice.method == 'robust' and choice.ratio is None


def test_the_choice_moves_when_a_quarter_of_the_tracks_misfit_far_beyond_their_own_jitter():
    # the median track fits (the bodies the model explains); the worst third do not
    jitter = 0.5
    fits = np.full(60, 0.8 * MISFIT_RATIO * jitter)
    few, third = fits.copy(), fits.copy()
    few[:12] = 10.0 * MISFIT_QUARTILE_RATIO * jitter            # a fifth: outliers, clutter
    third[:20] = 1.5 * MISFIT_QUARTILE_RATIO * jitter
    smooth = np.full(60, 0.5 * jitter)       # each track's own: taken as the scene's at least
    wobbly = smooth.copy()
    wobbly[:20] = 2.0 * jitter               # tracks the tracker follows poorly misfit alike
    choice = MethodChoice()
    assert not any(choice.add(few, jitter, smooth) for _ in range(2 * MISFIT_SOLVES))
    assert not any(choice.add(third, jitter, wobbly) for _ in range(2 * MISFIT_SOLVES))
    # tracks seen in too few frames for a jitter of their own are left out of the quartile
    unseen = np.where(np.arange(60) < 20, np.nan, smooth)
    assert not any(choice.add(third, jitter, unseen) for _ in range(2 * MISFIT_SOLVES))
    assert choice.method == 'robust'
    # one window of many that misfits does not count
    assert not any(choice.add(r, jitter, smooth) for r in [third] + [few] * MISFIT_SOLVES)
    switched = [choice.add(third, jitter, smooth) for _ in range(MISFIT_SOLVES)]
    assert switched.index(True) == MISFIT_SOLVES // 2 and sum(switched) == 1
    assert choice.method == TRANSLATION_METHOD
    assert choice.ratio < MISFIT_RATIO < MISFIT_QUARTILE_RATIO < choice.quartile_ratio
    choice.reset()
    assert choice.quartile_ratio is None
    # without the tracks' own jitters every track is judged against the scene's
    choice = MethodChoice()
    assert [choice.add(third, jitter) for _ in range(MISFIT_SOLVES)][-1]


def test_each_tracks_own_jitter_has_the_scenes_as_its_median():
    tracks = moving_lines(300, 5, 0.5, seed=4)
    tracks[:3, 2] = np.nan                                        # not seen in every frame
    tracks[3, :, 2:] = tracks[3, :, :2]                           # zero length
    own = track_jitters(tracks)
    assert own.shape == (300,) and np.all(np.isnan(own[:4])) and np.all(own[4:] >= 0)
    assert track_jitter(tracks) == pytest.approx(track_jitter(tracks, own), rel=1e-12)
    assert track_jitter(tracks) == pytest.approx(np.median(own[4:]), rel=0.02)
    assert np.all(np.isnan(track_jitters(tracks[:, :4])))


def stream(pipe: Pipeline, tracks: np.ndarray, intr) -> list:
    ids = np.arange(tracks.shape[0])
    return [pipe.process_lines(ids, tracks[:, k], k / 30.0, (1000, 1000), intr)
            for k in range(tracks.shape[1])]


def test_auto_keeps_the_rotation_model_where_bodies_rotate_about_the_camera():
    tracks, truth, _, intr = random_scene(2, 25, n_frames=16, noise=0.2, seed=0)
    pipe = Pipeline(num_bodies=2, method='auto')
    assert pipe.window_size == 10                   # the general model's, should it move
    results = stream(pipe, tracks, intr)
    assert pipe.method == 'robust' and pipe.params['method'] == 'auto'
    # its rotation-model solves are robust's on robust's own 5 frames
    robust = stream(Pipeline(num_bodies=2, method='robust'), tracks, intr)
    for a, b in zip(results, robust):
        np.testing.assert_array_equal(a.labels, b.labels)
        np.testing.assert_allclose(a.angular_velocities, b.angular_velocities, atol=1e-9)


@pytest.mark.slow
def test_auto_moves_to_the_general_model_once_bodies_translate():
    tracks, truth, _, intr = random_scene(2, 25, n_frames=20, noise=0.2, seed=3,
                                          own_centre=True)
    pipe = Pipeline(num_bodies=2, method='auto')
    results, methods = [], []
    ids = np.arange(tracks.shape[0])
    for k in range(tracks.shape[1]):
        results.append(pipe.process_lines(ids, tracks[:, k], k / 30.0, (1000, 1000), intr))
        methods.append(pipe.method)
    # the first full 5-frame window is frame 4: MISFIT_SOLVES of them decide
    first = methods.index('general')
    assert first == 4 + MISFIT_SOLVES - 1, methods
    # meanwhile the rotation model's rates of the bodies that translate are not published;
    # the bodies are solved all the same
    for r in results[4:first]:
        assert np.count_nonzero(r.body_valid) <= 1 and np.count_nonzero(r.body_solved) == 2
        assert r.solved
    assert pipe.method_choice.ratio > 3.0
    assert misclassification(results[-1].labels, truth, 2) <= 0.05
    # set again, 'auto' starts from the rotation model; other changes keep the choice; a
    # reset starts it again too
    pipe.reconfigure(detect_every=2, num_bodies=3)
    assert pipe.method == 'general'
    pipe.reconfigure(method='auto')
    assert pipe.method == 'robust'
    pipe.method_choice.method = 'general'
    pipe.reset()
    assert pipe.method == 'robust'


def test_misfit_bodies_are_those_whose_tracks_the_rotation_model_misfits():
    labels = np.repeat([0, 1, 2, -1], [6, 6, 3, 2])
    residuals = np.concatenate([np.full(6, 0.5), np.full(6, 3.0), np.full(3, 9.0),
                                [9.0, 9.0]])
    residuals[0] = np.nan                                      # an unusable track
    np.testing.assert_array_equal(misfit_bodies(labels, residuals, 1.0, 3),
                                  [False, True, False])        # body 2: too few tracks
    assert not np.any(misfit_bodies(labels, residuals, 2.0, 3))
    assert not np.any(misfit_bodies(labels, residuals, float('nan'), 3))


def test_the_quartile_is_numpys_75th_percentile_of_the_ratios_to_each_tracks_own_jitter():
    # the switch's quartile is np.percentile's, bit for bit (the solver's column_quantile)
    rng = np.random.default_rng(7)
    jitter = 0.4
    residuals = jitter * np.concatenate([rng.uniform(0.2, 1.0, 40), rng.uniform(4.0, 10.0, 31)])
    residuals[[3, 50]] = np.nan                                   # unusable tracks
    jitters = jitter * rng.uniform(0.5, 2.0, residuals.size)
    jitters[7] = np.nan                                           # no jitter of its own
    choice = MethodChoice()
    switched = [choice.add(residuals, jitter, jitters) for _ in range(MISFIT_SOLVES)]
    assert switched[-1] and choice.ratio < MISFIT_RATIO
    ratios = residuals / np.maximum(jitters, jitter)
    assert choice.quartile_ratio == float(np.percentile(ratios[np.isfinite(ratios)], 75))
