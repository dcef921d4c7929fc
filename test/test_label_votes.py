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

from mlofc_ros.label_votes import DECAY, LabelVotes, match_bodies, ROTATION_WEIGHT
from mlofc_ros.pipeline import Pipeline
from mlofc_tools.scoring import misclassification
import numpy as np
import pytest
from scenes import random_scene


def test_bodies_match_the_ids_they_share_most_tracks_with():
    labels = np.array([0, 0, 0, 1, 1, 2, 2, -1])
    onto = np.array([5, 5, 3, 3, 3, 3, -1, 5])
    # body 1 (two tracks on 3) and body 0 (two on 5) first, then body 2 has none left
    np.testing.assert_array_equal(match_bodies(labels, onto, 3), [5, 3, -1])
    np.testing.assert_array_equal(match_bodies(labels, np.full(8, -1), 3), [-1, -1, -1])


def test_a_label_moves_after_a_few_solves_and_survives_a_single_one():
    votes = LabelVotes()
    ids = np.array([10, 11, 12])
    for _ in range(10):
        votes.new_solve(ids)
        votes.add(ids, np.array([0, 0, 1]))
    # one solve says otherwise (track 11 on body 1): nothing moves; a track it left
    # unassigned has no label from it (label_memory's to carry)
    votes.new_solve(ids)
    votes.add(ids, np.array([0, 1, -1]))
    np.testing.assert_array_equal(votes.labels(ids), [0, 0, -1])
    # said again and again, track 11 moves within a few solves (a body that stopped)
    moved = None
    for k in range(1, 10):
        votes.new_solve(ids)
        votes.add(ids, np.array([0, 1, 1]))
        if votes.labels(ids)[1] == 1:
            moved = k
            break
    assert moved is not None and moved <= 4
    # a memory of about 1 / (1 - DECAY) solves, not of the whole stream
    assert DECAY < 1.0


def test_tracks_that_leave_the_solve_are_forgotten_and_new_ones_have_no_label():
    votes = LabelVotes()
    votes.new_solve(np.array([1, 2]))
    votes.add(np.array([1, 2]), np.array([0, 3]))
    votes.new_solve(np.array([2, 7]))
    votes.add(np.array([2, 7]), np.array([-1, 0]))
    np.testing.assert_array_equal(votes.labels(np.array([1, 2, 7])), [-1, -1, 0])
    votes.add(np.array([2]), np.array([4]), 0.5)
    np.testing.assert_array_equal(votes.labels(np.array([1, 2, 7])), [-1, 3, 0])
    votes.reset()
    np.testing.assert_array_equal(votes.labels(np.array([2])), [-1])


def test_the_rotation_models_vote_wins_where_the_two_disagree_and_only_where_it_fits():
    votes = LabelVotes()
    ids = np.arange(4)
    general = np.array([0, 0, 1, 1])
    rotation = np.array([0, 1, 1, 0])
    fits = np.array([True, True, True, False])
    for _ in range(5):
        votes.new_solve(ids)
        votes.add(ids, general)
        votes.add(ids, rotation, ROTATION_WEIGHT, where=fits)
    # track 1: the two disagree every solve, the rotation model wins; track 3: it does not fit
    np.testing.assert_array_equal(votes.labels(ids), [0, 1, 1, 1])


def test_auto_publishes_the_voted_labels_and_hands_the_votes_over():
    tracks, _, _, intr = random_scene(2, 25, n_frames=8, noise=0.2, seed=0)
    ids = np.arange(tracks.shape[0])
    pipe = Pipeline(num_bodies=2, method='auto')
    for k in range(tracks.shape[1]):
        last = pipe.process_lines(ids, tracks[:, k], k / 30.0, (1000, 1000), intr)
    side = pipe.hand_over()
    np.testing.assert_array_equal(side.votes.labels(ids), last.labels)
    Pipeline(num_bodies=2, method='auto').take_over(side)


@pytest.mark.slow
def test_at_the_switch_the_rotation_models_labels_are_not_carried_over():
    # boxes spinning about their own centres: the rotation model's labels are 40% wrong
    tracks, truth, _, intr = random_scene(2, 25, n_frames=12, noise=0.2, seed=4,
                                          own_centre=True)
    ids = np.arange(tracks.shape[0])
    pipe = Pipeline(num_bodies=2, method='auto')
    wrong, methods = [], []
    for k in range(tracks.shape[1]):
        r = pipe.process_lines(ids, tracks[:, k], k / 30.0, (1000, 1000), intr)
        wrong.append(misclassification(r.labels, truth, 2))
        methods.append(pipe.method)
    first = methods.index('general')
    assert min(wrong[:first]) > 0.3, wrong
    # the general model's first solve is right, and so are the labels published from it
    assert max(wrong[first + 1:]) <= 0.05, wrong


def test_the_votes_go_with_autos_solving_and_stop_with_another_method():
    tracks, _, _, intr = random_scene(2, 25, n_frames=6, noise=0.2, seed=0)
    ids = np.arange(tracks.shape[0])
    auto = Pipeline(num_bodies=2, method='auto')
    for k in range(tracks.shape[1]):
        auto.process_lines(ids, tracks[:, k], k / 30.0, (1000, 1000), intr)
    side = auto.hand_over()
    assert side.votes is not None
    # the general model's pipeline that solves for auto after its switch (the node's child)
    child = Pipeline(num_bodies=2, method='general')
    child.take_over(side)
    assert child.hand_over().votes is side.votes
    # a method set by hand: its own labels
    child.take_over(side._replace(votes=None))
    assert child.hand_over().votes is None
    robust = Pipeline(num_bodies=2, method='robust')
    robust.take_over(side)
    assert robust.hand_over().votes is None
    assert Pipeline(num_bodies=2, method='general').hand_over().votes is None
    auto.reconfigure(method='robust')
    assert auto.hand_over().votes is None
    auto.reconfigure(method='auto')
    assert auto.hand_over().votes is not None
