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
"""Bodies that move alike, published as one (mlofc_ros.alike)."""
from mlofc_ros.alike import (ALIKE_MIN_SOLVES, ALIKE_RATIO, ALIKE_SOLVES, AlikeBodies,
                             cross_ratios)
from mlofc_ros.pipeline import Pipeline
import numpy as np
from test_pipeline import small_sequence


def test_cross_ratios_read_each_bodys_tracks_under_the_others_motion():
    # 8 rows a track: body 0's tracks cost 4x their own under body 1, body 1's 9x under body
    # 0; the jitter is their own rms
    labels = np.array([0] * 5 + [1] * 5 + [-1])
    own = np.full(11, 8 * 0.25)                                  # rms 0.5 px
    costs = np.stack([np.where(labels == 1, 9 * own, own),
                      np.where(labels == 0, 4 * own, own)], axis=1)
    residuals = np.full(11, 0.5)
    r = cross_ratios(costs, labels, residuals, 0.5)
    assert np.isnan(r[0, 0]) and np.isnan(r[1, 1])
    np.testing.assert_allclose([r[1, 0], r[0, 1]], [2.0, 3.0])
    # too few tracks, or no jitter: no ratio
    few = np.where(np.arange(11) < 3, 0, -1)
    assert np.all(np.isnan(cross_ratios(costs, few, residuals, 0.5)))
    assert np.all(np.isnan(cross_ratios(costs, labels, residuals, float('nan'))))


def split(ids, k: int, swapped: bool = True):
    """Window ``k``'s stable labels of its tracks: 8 tracks each of the bodies ``ids``."""
    labels = np.repeat(np.asarray(ids), 8)
    if swapped and k % 2:                  # an arbitrary split: half the tracks change body
        labels = np.roll(labels, 4)
    return labels


def add(alike, ids, ratios, k, swapped=True):
    """Window ``k`` after window ``k - 1``."""
    return alike.add(ids, ratios, split(ids, k, swapped), split(ids, k - 1, swapped))


def test_alike_bodies_merge_into_the_older_id_after_a_few_windows():
    alike = AlikeBodies()
    near = np.array([[np.nan, 1.2, 9.0], [1.5, np.nan, 9.0], [9.0, 9.0, np.nan]])
    ids = np.array([4, 2, 7])
    for k in range(ALIKE_MIN_SOLVES - 1):
        assert add(alike, ids, near, k) == {}
    assert add(alike, ids, near, ALIKE_MIN_SOLVES) == {4: 2}     # 2 is the older id
    # both ratios count: one body explaining the other is not enough
    far = near.copy()
    far[0, 1] = 3 * ALIKE_RATIO
    for k in range(3):
        add(alike, ids, far, k)
    assert add(alike, ids, far, 3) == {}
    # a pair that drifts apart until one body's tracks cannot be explained by the other's
    # motion at all (an infinite ratio) is apart again
    alike.reset()
    for k in range(ALIKE_MIN_SOLVES):
        add(alike, ids, near, k)
    apart = near.copy()
    apart[0, 1] = np.inf
    for k in range(ALIKE_MIN_SOLVES):
        merged = add(alike, ids, apart, k)
    assert merged == {}
    # a chain goes to the oldest; a body gone forgets its pairs
    chain = np.full((3, 3), 1.0)
    np.fill_diagonal(chain, np.nan)
    alike.reset()
    for k in range(ALIKE_MIN_SOLVES):
        merged = add(alike, ids, chain, k)
    assert merged == {4: 2, 7: 2}
    assert add(alike, ids[:2], chain[:2, :2], 0) == {4: 2}
    assert add(alike, ids[[1, 2]], chain[:2, :2], 1) == {}


def test_bodies_that_keep_their_tracks_are_two_however_alike_their_fit():
    # two motions the rotation model misfits about alike (Hopkins155's translating bodies):
    # each one's tracks fit the other's rotation within the ratio, but no track changes body
    alike = AlikeBodies()
    near = np.array([[np.nan, 1.3], [1.4, np.nan]])
    ids = np.array([0, 1])
    for k in range(2 * ALIKE_SOLVES):
        assert add(alike, ids, near, k, swapped=False) == {}
    # a few borderline tracks that change body are not noise deciding between the two
    before = split(ids, 0, swapped=False)
    for k in range(2 * ALIKE_SOLVES):
        labels = split(ids, 0, swapped=False)
        if k % 2:
            labels[0] = 1
        assert alike.add(ids, near, labels, before) == {}
        before = labels
    # once half of them change body from window to window, they are alike
    for k in range(ALIKE_MIN_SOLVES + 2):
        merged = add(alike, ids, near, k)
    assert merged == {1: 0}


def still_sequence(n_frames: int = 12):
    """Return the first frame of :func:`small_sequence` over and over, with sensor noise."""
    seq = small_sequence(1)
    rng = np.random.default_rng(0)
    frames = [np.clip(seq.frames[0] + rng.normal(0, 2.0, seq.frames[0].shape), 0,
                      255).astype(np.uint8) for _ in range(n_frames)]
    return frames, [k / 30.0 for k in range(n_frames)], seq.camera


def test_a_still_scene_is_published_as_one_body_and_a_moving_one_as_two():
    frames, stamps, camera = still_sequence()
    pipe = Pipeline(num_bodies=2, method='robust')
    out = [pipe.process(f, t, camera) for f, t in zip(frames, stamps)]
    last = out[-1]
    assert len(set(last.labels[last.labels >= 0].tolist())) == 1
    assert np.count_nonzero(last.body_valid) == 1
    assert np.sum(last.labels >= 0) > 10
    # a box turning about the camera in front of the wall: two bodies, two twists
    seq = small_sequence(12)
    pipe = Pipeline(num_bodies=2, method='robust')
    out = [pipe.process(f, t, seq.camera) for f, t in zip(seq.frames, seq.stamps)]
    assert len(set(out[-1].labels[out[-1].labels >= 0].tolist())) == 2
    assert np.all(out[-1].body_valid)
