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
"""Hopkins155 line tracks: loading and point pairing."""
import pathlib

from mlofc_tools.datasets import hopkins as hk
import numpy as np
import pytest

DATA = hk.DEFAULT_DATA_DIR
pytestmark = pytest.mark.skipif(not (DATA / '1R2RC.npz').is_file(),
                                reason=f'Hopkins155 data not found in {DATA}')


@pytest.fixture(scope='module')
def seq() -> hk.HopkinsSequence:
    return hk.load_sequence(DATA / '1R2RC.npz')


def test_list_and_groups() -> None:
    paths = hk.list_sequences()
    assert len(paths) == 155
    assert 'dancing' not in {p.stem for p in paths}
    assert len(hk.list_sequences(include_extra=True)) == 156
    assert hk.sequence_group('1RT2TCRT_A_g13') == 'checkerboard'
    assert hk.sequence_group('three-cars_g12') == 'checkerboard'
    assert hk.sequence_group('cars2B_g12') == 'traffic'
    assert hk.sequence_group('kanatani2') == 'traffic'
    assert hk.sequence_group('kanatani3') == 'articulated'
    assert hk.sequence_group('two_cranes_g23') == 'articulated'
    assert hk.sequence_group('dancing') == 'extra'
    with pytest.raises(ValueError, match='unknown'):
        hk.sequence_group('not_a_sequence')


def test_load(seq: hk.HopkinsSequence) -> None:
    assert seq.name == '1R2RC' and seq.group == 'checkerboard' and not seq.is_subset
    assert seq.points.shape == (29, 459, 2) and seq.points.dtype == np.float64
    assert seq.labels.shape == (459,) and seq.n_motions == 3
    assert seq.image_size == (640, 480)
    assert set(np.unique(seq.labels)) == {0, 1, 2}


def test_load_rejects_bad_file(tmp_path: pathlib.Path) -> None:
    bad = tmp_path / 'x.npz'
    np.savez(bad, points=np.zeros((3, 4, 2)))
    with pytest.raises(ValueError, match='missing keys'):
        hk.load_sequence(bad)


@pytest.mark.parametrize('strategy', hk.STRATEGIES)
def test_pairing(seq: hk.HopkinsSequence, strategy: str) -> None:
    start, k = 7, 5
    tracks, labels = hk.line_tracks(seq, 20, (start, k), min_length_px=60.0, seed=3,
                                    strategy=strategy)
    pairs, plabels = hk.pair_points(seq, 20, start, 60.0, seed=3, strategy=strategy)
    assert tracks.shape == (60, k, 4) and labels.shape == (60,)
    assert np.array_equal(labels, plabels)
    assert np.array_equal(np.bincount(labels), [20, 20, 20])
    # both points of every line carry the line's label
    assert np.all(seq.labels[pairs[:, 0]] == labels) and np.all(seq.labels[pairs[:, 1]] == labels)
    # endpoints are the two tracked points in every frame of the window
    win = seq.points[start:start + k]
    assert np.array_equal(tracks[:, :, :2], win[:, pairs[:, 0]].transpose(1, 0, 2))
    assert np.array_equal(tracks[:, :, 2:], win[:, pairs[:, 1]].transpose(1, 0, 2))
    # minimum length in the first frame, no point in more than 2 lines, no repeated pair
    length = np.hypot(tracks[:, 0, 2] - tracks[:, 0, 0], tracks[:, 0, 3] - tracks[:, 0, 1])
    assert length.min() >= 60.0
    assert np.bincount(pairs.ravel()).max() <= 2
    assert np.unique(np.sort(pairs, axis=1), axis=0).shape[0] == pairs.shape[0]
    # deterministic for a seed, different for another
    again, _ = hk.line_tracks(seq, 20, (start, k), min_length_px=60.0, seed=3,
                              strategy=strategy)
    assert np.array_equal(tracks, again)
    if strategy == 'random':
        other, _ = hk.line_tracks(seq, 20, (start, k), min_length_px=60.0, seed=4)
        assert not np.array_equal(tracks, other)
    else:
        assert np.all(np.diff(length[labels == 0]) <= 1e-9)   # longest first


def test_pairing_runs_out_of_points() -> None:
    small = hk.load_sequence(DATA / 'cars2_07_g12.npz')
    pairs, labels = hk.pair_points(small, 1000, min_length_px=40.0, max_uses=1)
    assert np.bincount(pairs.ravel()).max() == 1          # maximal matching, each point once
    for lab in range(small.n_motions):
        idx = np.flatnonzero(small.labels == lab)
        free = np.setdiff1d(idx, pairs.ravel())
        p = small.points[0, free]
        d = np.hypot(*(p[:, None] - p[None]).transpose(2, 0, 1))
        assert not np.any(d >= 40.0)                      # no further pair would fit


def test_pairing_bad_arguments(seq: hk.HopkinsSequence) -> None:
    with pytest.raises(ValueError, match='does not fit'):
        hk.line_tracks(seq, frames=(28, 2))
    with pytest.raises(ValueError, match='does not fit'):
        hk.line_tracks(seq, frames=(0, 1))
    with pytest.raises(ValueError, match='strategy'):
        hk.line_tracks(seq, strategy='nearest')
