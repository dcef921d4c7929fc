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
"""Early accept of the robust solver's first start, and its fallback to the full search."""
from mlofc_ros.solver import robust, segment_lines
from mlofc_ros.solver.lines import line_flows
from mlofc_ros.solver.models import fit_bodies, track_costs, track_stats
from mlofc_tools.scoring import best_permutation
from mlofc_tools.synthetic import make_scene
import numpy as np


def _scene(seed, k=5):
    return make_scene(3, 30, n_frames=k, noise_px=1.0, seed=seed)


def _wrong(labels, truth):
    return best_permutation(labels, truth, 3)[1] / truth.size


def test_a_clear_first_start_is_accepted_alone_with_the_full_search_result(monkeypatch):
    scenes = [_scene(seed) for seed in range(3)]
    early = [segment_lines(sc.tracks, 3, intrinsics=sc.intrinsics, seed=0) for sc in scenes]
    # the full search, as when the test has no reference noise to decide with
    monkeypatch.setattr(robust, 'early_stats', lambda *args, **kwargs: None)
    for sc, res in zip(scenes, early):
        assert res.diagnostics.early_accept
        assert res.diagnostics.candidate == 'gpca-weighted'
        assert not res.diagnostics.candidate_costs            # no other start was scored
        full = segment_lines(sc.tracks, 3, intrinsics=sc.intrinsics, seed=0)
        assert not full.diagnostics.early_accept
        assert len(full.diagnostics.candidate_costs) == 3
        # the same bodies; their order may differ (the last bits of the starts' scores)
        perm, errors = best_permutation(res.labels, full.labels, 3)
        assert errors == 0 and sorted(perm) == [0, 1, 2]
        assert np.allclose(np.asarray(res.angular_velocities),
                           np.asarray(full.angular_velocities)[list(perm)], atol=1e-12)


def test_two_frames_have_no_reference_noise_and_search_everything():
    sc = _scene(0, k=2)
    res = segment_lines(sc.tracks, 3, intrinsics=sc.intrinsics, seed=0)
    assert not res.diagnostics.early_accept
    assert len(res.diagnostics.candidate_costs) == 3


def test_the_test_rejects_a_merged_and_split_grouping():
    sc = _scene(1)
    flows = line_flows(sc.tracks, sc.intrinsics)
    stats = track_stats(flows)
    dof = 2.0 * flows.pairs_per_track()
    truth = sc.labels
    bad = np.where(truth == 2, 1, truth)                     # bodies 1 and 2 merged ...
    zero = np.flatnonzero(truth == 0)
    bad[zero[::2]] = 2                                       # ... and body 0 split in two
    stat = {}
    for name, lab in (('truth', truth), ('bad', bad)):
        c, _ = fit_bodies(flows, lab, 3)
        stat[name] = robust.early_stats(stats, track_costs(flows, c), lab, dof)
    ratio, fits, separated = stat['truth']
    assert ratio <= robust.EARLY_RATIO and fits >= robust.EARLY_SHARE
    assert separated >= robust.EARLY_SEPARATED
    ratio, fits, separated = stat['bad']
    assert (ratio > robust.EARLY_RATIO or fits < robust.EARLY_SHARE
            or separated < robust.EARLY_SEPARATED)


def test_a_wrong_first_start_falls_back_to_the_full_search(monkeypatch):
    sc = _scene(2)
    calls = []
    original = robust.ksubspaces

    def first_wrong(stats, n, labels, **kw):
        calls.append(1)
        if len(calls) == 1:
            # the first (gpca-weighted) start ends merged and split: one step from such labels
            bad = np.where(sc.labels == 2, 1, sc.labels)
            bad[np.flatnonzero(sc.labels == 0)[::2]] = 2
            return original(stats, n, bad, max_iter=1, **kw)
        return original(stats, n, labels, **kw)

    monkeypatch.setattr(robust, 'ksubspaces', first_wrong)
    res = segment_lines(sc.tracks, 3, intrinsics=sc.intrinsics, seed=0)
    assert not res.diagnostics.early_accept
    assert len(res.diagnostics.candidate_costs) == 3         # every start, the wrong one too
    assert res.diagnostics.candidate != 'gpca-weighted'
    assert _wrong(res.labels, sc.labels) < 0.03
