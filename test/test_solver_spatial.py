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
"""Spatial coherence prior (``mlofc_ros.solver.spatial``)."""
from mlofc_ros.solver.spatial import (label_coherence, largest_region, smooth_labels,
                                      spatial_neighbours, track_spacing)
import numpy as np


def _exact_knn(points, k):
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return np.argsort(d, axis=1)[:, :k]


def test_neighbours_exact_for_few_points_and_close_for_many():
    rng = np.random.default_rng(0)
    few = rng.uniform(0, 640, (40, 2))
    assert np.array_equal(np.sort(spatial_neighbours(few, 6), axis=1),
                          np.sort(_exact_knn(few, 6), axis=1))
    centres = rng.uniform(0, 640, (4, 2))
    clustered = np.concatenate([rng.normal(c, 40.0, (300, 2)) for c in centres])
    for many in (rng.uniform(0, 640, (1500, 2)), clustered):           # the approximate path
        got, want = spatial_neighbours(many, 6), _exact_knn(many, 6)
        recall = np.mean([len(set(g) & set(w)) / 6 for g, w in zip(got, want)])
        assert recall > 0.9
        assert np.all(got != np.arange(many.shape[0])[:, None])         # never itself
        assert np.all([len(set(g)) == 6 for g in got])                  # no repeats


def test_neighbours_degenerate_sizes():
    assert spatial_neighbours(np.zeros((1, 2))).shape == (1, 0)
    nb = spatial_neighbours(np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]]), k=6)
    assert nb.shape == (3, 2) and np.all(nb >= 0)


def test_coherence_zero_for_mixed_labels_one_for_regions():
    rng = np.random.default_rng(1)
    pts = rng.uniform(0, 640, (300, 2))
    nb = spatial_neighbours(pts)
    assert label_coherence(rng.integers(0, 2, 300), nb) < 0.1
    regions = (pts[:, 0] > 320).astype(int)
    assert label_coherence(regions, nb) > 0.8


def test_smoothing_flips_ambiguous_lines_to_their_region_and_keeps_outliers():
    rng = np.random.default_rng(2)
    pts = rng.uniform(0, 640, (400, 2))
    truth = (pts[:, 0] > 320).astype(int)
    costs = np.where(np.arange(2) == truth[:, None], 1.0, 10.0)
    # away from the border between the regions, where the neighbours vote one way
    ambiguous = np.flatnonzero(np.abs(pts[:, 0] - 320) > 120)[::10]
    costs[ambiguous] = costs[ambiguous][:, ::-1] * 0.1 + 0.9      # slightly prefers the wrong body
    labels = np.argmin(costs, axis=1)
    outlier = np.setdiff1d(np.arange(400), ambiguous)[0]
    labels[outlier] = -1                                            # an outlier stays one
    out, coupling = smooth_labels(costs, labels, spatial_neighbours(pts))
    assert coupling > 0
    assert np.array_equal(out[ambiguous], truth[ambiguous])
    assert out[outlier] == -1
    keep = np.setdiff1d(np.arange(400), np.r_[ambiguous, outlier])
    assert np.array_equal(out[keep], truth[keep])


def test_smoothing_leaves_mixed_scenes_alone():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 640, (200, 2))
    truth = rng.integers(0, 2, 200)
    costs = np.where(np.arange(2) == truth[:, None], 1.0, 1.5)
    out, coupling = smooth_labels(costs, truth, spatial_neighbours(pts))
    assert np.array_equal(out, truth)
    assert coupling < 0.2 * 1.0


def test_largest_region_parts_a_compact_object_from_what_lies_elsewhere():
    rng = np.random.default_rng(2)
    box = rng.normal((200.0, 150.0), 20.0, (30, 2))               # one object's lines
    wall = np.array([[20.0, 20.0], [620.0, 30.0], [600.0, 460.0], [30.0, 450.0]])
    other = rng.normal((500.0, 300.0), 15.0, (10, 2))             # a smaller object
    points = np.concatenate([wall[:2], box, other, wall[2:]])
    spacing = track_spacing(points)
    assert spacing == np.sqrt(np.prod(np.ptp(points, axis=0)) / len(points))
    region = largest_region(points, spacing)
    assert np.array_equal(np.flatnonzero(region), np.arange(2, 32))
    assert largest_region(box, spacing).all()                      # one region: all of it
