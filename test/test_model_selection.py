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

"""Model selection's score on degenerate inputs: no numpy warning, a defined value."""
from dataclasses import replace
import warnings

from mlofc_ros.solver.model_selection import (bic_score, label_cost, track_neighbours,
                                              unexplained)
from mlofc_ros.solver.models import chi2_quantile
from mlofc_ros.solver.result import SegmentationResult
from mlofc_ros.solver.robust import OUTLIER_P
import numpy as np


def _result(costs, labels):
    n = costs.shape[1]
    return SegmentationResult(labels=np.asarray(labels), angular_velocities=np.zeros((n, 3)),
                              angular_covariances=np.zeros((n, 3, 3)), focal_length=500.0,
                              residuals=np.zeros(len(labels)), costs=costs, method='general')


def test_track_without_any_cost_counts_as_unexplained():
    """A track no body has a cost for (all NaN) costs the outlier bound, silently."""
    rng = np.random.default_rng(0)
    costs = rng.uniform(0.1, 2.0, (20, 2))
    dof = np.full(20, 4.0)
    labels = np.argmin(costs, axis=1)
    capped = costs.copy()
    capped[3] = 1e12                                   # far above the cap
    costs[3] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        score = bic_score(_result(costs, labels), 1.0, dof)
        assert score == bic_score(_result(capped, labels), 1.0, dof)
        assert np.isfinite(score)
        # with every cost missing the noise level falls back instead of becoming NaN
        assert np.isfinite(bic_score(_result(np.full((20, 2), np.nan), labels), None, dof))
    assert chi2_quantile(OUTLIER_P, dof[:1])[0] < 1e12


def test_no_usable_track_scores_inf():
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert bic_score(_result(np.zeros((3, 1)), [0, 0, 0]), None, np.zeros(3)) == np.inf
        assert bic_score(_result(np.zeros((0, 2)), []), None, np.zeros(0)) == np.inf


def test_unexplained_tracks_are_those_the_score_caps():
    """Above the outlier bound at the noise given, whatever the label; unusable never."""
    costs = np.full((6, 2), 0.5)
    costs[1] = [40.0, 50.0]
    costs[4] = [np.nan, np.nan]
    dof = np.array([4.0, 4.0, 4.0, 0.0, 4.0, 4.0])
    res = _result(costs, [0, 0, 1, 1, -1, 1])
    assert np.array_equal(unexplained(res, 1.0, dof), [False, True, False, False, True, False])
    assert chi2_quantile(OUTLIER_P, 4.0) < 40.0 < chi2_quantile(OUTLIER_P, 4.0) * 4.0
    # at twice the noise the bound is four times higher: only the track without a cost
    assert np.array_equal(unexplained(res, 2.0, dof), [False, False, False, False, True, False])


def test_a_body_that_translates_costs_six_parameters():
    """'general' bodies are charged a rotation and a translation: 3 more log(rows) each."""
    rng = np.random.default_rng(1)
    costs = rng.uniform(0.1, 2.0, (30, 2))
    labels = np.argmin(costs, axis=1)
    dof = np.full(30, 8.0)
    rotation = replace(_result(costs, labels), method='robust')
    assert np.isclose(bic_score(_result(costs, labels), 1.0, dof) - bic_score(rotation, 1.0, dof),
                      3 * 2 * np.log(dof.sum()))


def _tracks_at(points: np.ndarray) -> np.ndarray:
    """Tracks ``(N, 5, 4)``: a short segment about each point, still over 5 frames."""
    seg = np.hstack([points - [5.0, 0.0], points + [5.0, 0.0]])
    return np.repeat(seg[:, None, :], 5, axis=1)


def test_the_label_prior_knows_bodies_are_compact():
    """Labels in compact regions cost little, labels mixed among neighbours 2 log n each."""
    rng = np.random.default_rng(3)
    points = rng.uniform(0.0, 640.0, (200, 2))
    near = track_neighbours(_tracks_at(points))
    usable = np.ones(200, dtype=bool)
    compact = (points[:, 0] > 320.0).astype(int)
    mixed = rng.integers(0, 2, 200)
    uniform = label_cost(compact, 2, usable)
    assert np.isclose(uniform, 2.0 * 200 * np.log(2.0)) and uniform == label_cost(mixed, 2, usable)
    assert label_cost(compact, 2, usable, near) < 0.4 * uniform
    assert 0.9 * uniform < label_cost(mixed, 2, usable, near) < 1.3 * uniform
    assert label_cost(np.zeros(200, dtype=int), 1, usable, near) == 0.0
    # only usable tracks count, an unlabelled one 2 log n as under the uniform prior
    fewer = usable.copy()
    fewer[:50] = False
    assert label_cost(compact, 2, fewer, near) < label_cost(compact, 2, usable, near)
    loose = compact.copy()
    loose[0] = -1
    one = np.zeros(200, dtype=bool)
    one[0] = True
    assert np.isclose(label_cost(loose, 2, one, near), 2.0 * np.log(2.0))
    # the score takes it in place of 2 N log n
    costs = rng.uniform(0.1, 2.0, (200, 2))
    res = _result(costs, compact)
    dof = np.full(200, 8.0)
    assert np.isclose(bic_score(res, 1.0, dof) - bic_score(res, 1.0, dof, near),
                      uniform - label_cost(compact, 2, usable, near))
