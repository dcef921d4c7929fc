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
"""TrackWindow: layout, NaN gaps, id ordering, ring wraparound, growth."""
from mlofc_ros.tracks.window import TrackWindow
import numpy as np
import pytest


def _seg(k):
    return np.array([k, k + 0.5, k + 1, k + 1.5], float)


def test_layout_gaps_and_order():
    w = TrackWindow(size=5)
    assert w.fill == 0
    ids, win = w.tracks()
    assert ids.shape == (0,) and win.shape == (0, 0, 4)
    w.push(np.array([7, 3], np.uint32), np.stack([_seg(70), _seg(30)]))
    w.push(np.array([3, 9]), np.stack([_seg(31), _seg(91)]))
    w.push(np.array([9, 7, 3]), np.stack([_seg(92), _seg(72), _seg(32)]))
    assert w.fill == 3
    ids, win = w.tracks(min_frames=1)
    assert ids.dtype == np.uint32 and win.dtype == np.float64
    np.testing.assert_array_equal(ids, [3, 7, 9])
    assert win.shape == (3, 3, 4)
    np.testing.assert_array_equal(win[0], [_seg(30), _seg(31), _seg(32)])
    np.testing.assert_array_equal(win[1, 0], _seg(70))
    assert np.all(np.isnan(win[1, 1]))                    # id 7 missing in frame 2
    np.testing.assert_array_equal(win[1, 2], _seg(72))    # last column = newest frame
    assert np.all(np.isnan(win[2, 0]))
    ids2, win2 = w.tracks(min_frames=3)
    np.testing.assert_array_equal(ids2, [3])
    np.testing.assert_array_equal(win2[0], win[0])
    ids3, _ = w.tracks()                                  # default: >= 2 frames
    np.testing.assert_array_equal(ids3, [3, 7, 9])


def test_ring_wraparound():
    w = TrackWindow(size=3)
    for f in range(7):                                    # id f lives in frames f and f + 1
        w.push(np.array([f, max(f - 1, 0)][:1 + (f > 0)]),
               np.stack([_seg(10 * f), _seg(10 * f + 1)])[:1 + (f > 0)])
    assert w.fill == 3
    ids, win = w.tracks(min_frames=1)
    np.testing.assert_array_equal(ids, [3, 4, 5, 6])      # frames 4, 5, 6 held
    np.testing.assert_array_equal(win[0, 0], _seg(41))    # id 3 seen in frame 4 only
    assert np.all(np.isnan(win[0, 1:]))
    np.testing.assert_array_equal(win[3, 2], _seg(60))
    np.testing.assert_array_equal(win[2], [[np.nan] * 4, _seg(50), _seg(61)])


def test_reset_empty_frames_and_errors():
    w = TrackWindow(size=2)
    w.push([1], [_seg(1)])
    w.push(np.zeros(0, np.uint32), np.zeros((0, 4)))
    ids, win = w.tracks(min_frames=1)
    np.testing.assert_array_equal(ids, [1])
    assert win.shape == (1, 2, 4) and np.all(np.isnan(win[0, 1]))
    w.reset()
    assert w.fill == 0
    with pytest.raises(ValueError):
        w.push([1, 1], np.zeros((2, 4)))
    with pytest.raises(ValueError):
        w.push([1, 2], np.zeros((3, 4)))
    with pytest.raises(ValueError):
        w.push([1], np.zeros((1, 3)))
    with pytest.raises(ValueError):
        w.push([-1], np.zeros((1, 4)))
    with pytest.raises(ValueError):
        TrackWindow(size=0)


def test_many_tracks_grow_and_match_reference():
    rng = np.random.default_rng(0)
    w = TrackWindow(size=5, capacity=16)
    frames = []
    for _ in range(8):
        ids = rng.choice(3000, size=1000, replace=False).astype(np.uint32)
        seg = rng.normal(size=(1000, 4))
        w.push(ids, seg)
        frames.append(dict(zip(ids.tolist(), seg)))
    ids, win = w.tracks(min_frames=2)
    held = frames[-5:]
    for row, tid in zip(win[::97], ids[::97]):
        for col, fr in enumerate(held):
            if int(tid) in fr:
                np.testing.assert_array_equal(row[col], fr[int(tid)])
            else:
                assert np.all(np.isnan(row[col]))
    counts = np.isfinite(win[..., 0]).sum(1)
    assert counts.min() >= 2 and np.all(np.diff(ids.astype(np.int64)) > 0)
