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
"""Sequential MSAC, the robust solver's sampled start: its sampling and scoring helpers."""
import itertools

import numpy as np
import pytest
from scenes import random_scene

from mlofc_ros.solver.lines import line_flows
from mlofc_ros.solver.models import track_stats
from mlofc_ros.solver.robust import _column_quantile, _sample_pairs, sequential_msac


@pytest.mark.parametrize('rows', [1, 2, 7, 200])
@pytest.mark.parametrize('q', [0.0, 1.0 / 6.0, 0.25, 0.5, 0.999, 1.0])
def test_column_quantile_is_numpys(rows, q):
    x = np.random.default_rng(rows).normal(size=(rows, 30))
    x[:, 3] = 1.0                                     # ties
    assert np.array_equal(_column_quantile(x, q), np.quantile(x, q, axis=0))


def _pairs(pool, mid, seed=0, n_samples=400):
    return _sample_pairs(np.random.default_rng(seed), pool, mid, n_samples)


def test_pairs_are_two_distinct_pool_tracks():
    mid = np.random.default_rng(1).uniform(0, 640, size=(120, 2))
    pool = np.flatnonzero(np.arange(120) % 3 != 0)
    pairs = _pairs(pool, mid)
    assert pairs.shape == (400, 2)
    assert np.all(np.isin(pairs, pool))
    assert np.all(pairs[:, 0] != pairs[:, 1])


def test_local_pairs_stay_near_their_anchor():
    # two far-apart clusters: a local partner is in its anchor's cluster, a global one is not
    # always
    rng = np.random.default_rng(2)
    mid = np.concatenate([rng.uniform(0, 100, (60, 2)), rng.uniform(900, 1000, (60, 2))])
    pairs = _pairs(np.arange(120), mid)
    side = pairs >= 60
    assert np.all(side[::2, 0] == side[::2, 1])
    assert np.any(side[1::2, 0] != side[1::2, 1])
    # uniform: a local partner shares its anchor's cell of ~6 tracks (side ~122 px here), bar
    # the rare anchor alone in its cell
    mid = rng.uniform(0, 1000, (400, 2))
    pairs = _pairs(np.arange(400), mid)
    dist = np.linalg.norm(mid[pairs[::2, 0]] - mid[pairs[::2, 1]], axis=1)
    cell = np.sqrt(np.prod(np.ptp(mid, axis=0)) * 6 / 400)
    assert np.mean(dist <= cell * np.sqrt(2)) > 0.95


@pytest.mark.parametrize('layout', ['same point', 'on a line', 'two tracks'])
def test_pairs_in_degenerate_layouts(layout):
    if layout == 'same point':
        mid = np.full((30, 2), 5.0)
    elif layout == 'on a line':
        mid = np.stack([np.linspace(0, 300, 30), np.zeros(30)], axis=1)
    else:
        mid = np.array([[0.0, 0.0], [10.0, 10.0]])
    pool = np.arange(mid.shape[0])
    pairs = _pairs(pool, mid)
    assert np.all(np.isin(pairs, pool)) and np.all(pairs[:, 0] != pairs[:, 1])
    if layout == 'on a line':
        # cells along the line, not one per track
        assert np.median(np.abs(pairs[::2, 0] - pairs[::2, 1])) <= 6


@pytest.mark.parametrize('n', [2, 3])
def test_sequential_msac_finds_the_bodies(n):
    tracks, truth, _, intr = random_scene(n, 40, n_frames=3, noise=0.5, seed=n)
    flows = line_flows(tracks, intr)
    stats = track_stats(flows, weighted=True)
    dof = 2.0 * flows.pairs_per_track()
    labels, sigma = sequential_msac(stats, tracks, n, dof, np.random.default_rng(0))
    wrong = min(np.mean(labels != np.array(p)[truth]) for p in itertools.permutations(range(n)))
    assert wrong < 0.1
    assert 0.1 < sigma < 2.0
