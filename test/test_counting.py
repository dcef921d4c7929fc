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
"""The number of bodies found online (``num_bodies=0``): trials, ids, a stream that changes."""
from dataclasses import replace
from typing import List

from mlofc_ros.bodies import BodyTracker
from mlofc_ros.counting import (birth_candidate, BodyCount, compact_labels, HOLD,
                                in_view, IN_VIEW_FRAMES, merge_candidate, MERGE_CHI2,
                                SCORE_MARGIN, score_noise, scores_better, SEARCH_EVERY,
                                split_pair)
from mlofc_ros.pipeline import Pipeline
from mlofc_ros.solver import get_method
from mlofc_ros.solver.model_selection import bic_score, min_body_lines, track_neighbours
from mlofc_ros.solver.result import Diagnostics, SegmentationResult
from mlofc_ros.solver.warm import WarmStarts
from mlofc_tools.bench import count
from mlofc_tools.synthetic import make_scene, scheduled_scene
import numpy as np
import pytest


def _result(labels, w, sd=1e-4) -> SegmentationResult:
    w = np.asarray(w, dtype=float)
    n = len(w)
    return SegmentationResult(labels=np.asarray(labels), angular_velocities=w,
                              angular_covariances=np.tile(np.eye(3) * sd ** 2, (n, 1, 1)),
                              focal_length=500.0, residuals=np.zeros(len(labels)),
                              costs=np.zeros((len(labels), n)), method='robust')


def test_trials_one_less_and_one_more():
    dof = np.full(100, 8.0)
    assert min_body_lines(dof) == 4 and min_body_lines(np.full(400, 8.0)) == 16
    labels = np.repeat([0, 1, 2], [50, 30, 20])
    # a body below the smallest allowed: its tracks unlabelled, nothing kept
    tiny = labels.copy()
    tiny[80:97] = -1
    got, gone, keep = merge_candidate(_result(tiny, [[0, 0, 0], [0.01, 0, 0], [0, 0.02, 0]]),
                                      dof)
    assert (gone, keep) == (2, -1) and set(got[97:]) == {-1} and got.max() == 1
    # two bodies moving alike (within MERGE_CHI2): the later one joins the earlier
    alike = _result(labels, [[0.01, 0, 0], [0, 0, 0], [0, 0, 5e-4]])
    got, gone, keep = merge_candidate(alike, dof)
    assert merge_candidate(alike, dof, pairs=False) is None      # small bodies only
    assert (gone, keep) == (2, 1) and np.array_equal(got, np.repeat([0, 1], [50, 50]))
    assert 5e-4 ** 2 / (2 * 1e-4 ** 2) < MERGE_CHI2
    # distinct motions: no trial
    assert merge_candidate(_result(labels, [[0.01, 0, 0], [0, 0, 0], [0, 0.01, 0]]),
                           dof) is None
    # ... nor where a body's published covariance is wide because its motion misfits it (two
    # motions in one: general's reduced chi-square scale): compared within the noise alone
    mixed = _result(labels, [[0.01, 0, 0], [0, 0, 0], [0, 0, 2e-3]])
    mixed.noise_covariances = mixed.angular_covariances.copy()
    mixed.angular_covariances[2] *= 100.0
    assert merge_candidate(mixed, dof) is None
    mixed.noise_covariances = None
    assert merge_candidate(mixed, dof)[1:] == (2, 1)
    # one more: the unexplained tracks as body n, when there are enough of them
    loose = labels.copy()
    loose[:6] = -1
    assert np.array_equal(birth_candidate(_result(loose, np.zeros((3, 3))), dof)[:6], [3] * 6)
    loose[:6] = 0
    loose[:3] = -1
    assert birth_candidate(_result(loose, np.zeros((3, 3))), dof) is None
    # labelled tracks above the score's outlier bound at the result's noise are unexplained
    # too ('general' labels at an inflated noise level and keeps them)
    costs = np.zeros((100, 3))
    costs[10:16] = 1e3
    kept = replace(_result(labels, np.zeros((3, 3))), costs=costs,
                   diagnostics=Diagnostics(sigma_px=1.0))
    got = birth_candidate(kept, dof)
    assert np.array_equal(np.flatnonzero(got == 3), np.arange(10, 16))
    assert np.array_equal(np.delete(got, np.arange(10, 16)), np.delete(labels, np.arange(10, 16)))
    assert np.array_equal(compact_labels([7, 3, -1, 9, 3], [3, 7]), [1, 0, -1, -1, 0])


def test_a_change_of_count_needs_a_better_score():
    """A trial is kept only when it scores better, then the count follows it."""
    calls: List[int] = []

    def solve(n, labels, bodies):
        calls.append(n)
        if n == 0:
            return _result(np.repeat([0, 1], 50), [[0, 0, 0], [0.01, 0, 0]])
        assert len(bodies) == n and labels is not None
        return _result(np.where(labels >= n, -1, labels), np.zeros((n, 3)))
    count = BodyCount()
    tracks = np.zeros((100, 5, 4))
    count.solve(tracks, None, solve)
    assert count.n == 2 and count.last_change == 'search' and calls == [0]
    # the bodies move alike (zero rotations in the fake solve): one less is tried; with
    # equal costs the poorer model wins the BIC by its fewer parameters
    count.merge_every = 1
    count.solve(tracks, np.repeat([0, 1], 50), solve)
    assert calls[1:] == [2, 1] and count.n == 1 and count.last_change == 'merge'
    assert count.kept == (0, 0)
    # no labels to start from (the tracker restarted): searched again
    count.solve(tracks, np.full(100, -1), solve)
    assert count.last_change == 'search' and calls[-1] == 0


def test_a_change_of_count_must_win_under_both_label_priors():
    """
    One body more must win under the uniform label prior, one less under the compact one.

    Two compact halves of the image, each fitted a little better by a body of its own: the
    neighbours' prior takes the split, the uniform one does not, and neither count is left
    for the other (no flicker between counts that score alike under one prior or the other).
    """
    rng = np.random.default_rng(5)
    points = rng.uniform(0.0, 640.0, (100, 2))
    seg = np.hstack([points - [5.0, 0.0], points + [5.0, 0.0]])
    tracks = np.repeat(seg[:, None, :], 5, axis=1)
    near = track_neighbours(tracks)
    dof = np.full(100, 8.0)
    halves = (points[:, 0] > 320.0).astype(int)

    def fitted(labels, n, gain):
        # every track costs 4 px^2 under one body, 4 (1 - gain) under its half's own
        costs = np.full((100, n), 4.0 * (1.0 - gain) if n > 1 else 4.0)
        return replace(_result(labels, np.zeros((n, 3))), costs=costs,
                       diagnostics=Diagnostics(sigma_px=1.0))
    one = fitted(np.zeros(100, dtype=int), 1, 0.0)
    split = fitted(halves, 2, 0.12)
    # 800 rows: 800 log(0.88) = -102 against 3 log 800 = 20 parameters and a label term of
    # 139 (uniform) or about 40 (compact halves)
    assert not scores_better(split, one, 1.0, dof, tracks)
    assert not scores_better(one, split, 1.0, dof, tracks)
    # each prior alone: the neighbours' takes the split, the uniform one keeps one body
    assert bic_score(split, 1.0, dof, near) < bic_score(one, 1.0, dof, near) - SCORE_MARGIN
    assert bic_score(one, 1.0, dof) < bic_score(split, 1.0, dof) - SCORE_MARGIN
    clear = fitted(halves, 2, 0.3)
    assert scores_better(clear, one, 1.0, dof, tracks)
    assert not scores_better(one, clear, 1.0, dof, tracks)


def test_a_reported_noise_below_the_costs_scale_does_not_hide_a_body():
    # 'general' on real video reports the noise of its fitted-direction fits, far below the
    # scale of its costs: at that level every track is above the outlier bound, whatever
    # the count. The score then takes the costs' own scale (their median chi-square).
    tracks = np.zeros((100, 5, 4))                    # 8 equations a track
    dof = np.full(100, 8.0)
    truth = np.repeat([0, 1], [60, 40])
    rng = np.random.default_rng(0)
    fit = rng.chisquare(8, 100)                       # noise 1 px under the right body

    def result(labels, n, sigma_px):
        costs = np.where(truth[:, None] == np.arange(n), fit[:, None], 100.0 + fit[:, None])
        return replace(_result(labels, np.zeros((n, 3))), costs=costs,
                       diagnostics=Diagnostics(sigma_px=sigma_px))
    one = result(np.zeros(100, dtype=int), 1, 0.2)
    # at 0.2 px every track would be loose, at the costs' own scale only the second body's
    assert np.array_equal(birth_candidate(one, dof), truth)

    def solve(n, labels, bodies):
        return one if n <= 1 else result(truth, 2, 0.2)
    count = BodyCount(birth_every=1)
    count.solve(tracks, None, solve)
    assert count.n == 1
    count.solve(tracks, np.zeros(100, dtype=int), solve)
    assert count.n == 2 and count.last_change == 'birth'
    # a reported noise on the costs' scale is kept: a track 100 above it is loose
    fine = result(np.zeros(100, dtype=int), 1, 1.0)
    assert np.array_equal(birth_candidate(fine, dof), truth)
    # a tenth of the labelled tracks above the bound at the reported noise: it is kept; a
    # third: the costs are at another level ('general' labels at an inflated one; two
    # bodies of a Hopkins155 stream perfectly apart were merged, half of their tracks
    # capped at the reported level)
    for every, kept in ((10, True), (3, False)):
        off = replace(fine, labels=truth, costs=np.where(
            np.arange(100)[:, None] % every == 0, 9.0, 1.0) * fit[:, None] * [1.0, 1.0])
        assert (score_noise(off, dof) == 1.0) == kept, every


def test_a_birth_that_splits_one_motion_in_two_is_refused():
    """Two bodies that explain each other's tracks are one motion, whatever the score says."""
    tracks = np.zeros((100, 5, 4))                    # 8 equations a track
    dof = np.full(100, 8.0)
    labels = np.repeat([0, 1], [80, 20])

    def result(labels, costs):
        n = costs.shape[1]
        return replace(_result(labels, np.zeros((n, 3))), costs=costs,
                       diagnostics=Diagnostics(sigma_px=1.0))
    # one body: 20 tracks left unlabelled at 5 px^2, well within the outlier bound at 1 px
    one = result(np.where(labels == 1, -1, 0), np.where(labels == 1, 5.0, 1.0)[:, None])

    def trial(other):
        # each track costs 1 under its own body, `other` under the other one
        return result(labels, np.where(labels[:, None] == [0, 1], 1.0, other))
    split, apart = trial(5.0), trial(1e3)
    assert split_pair(split, 1.0, dof) == (0, 1) and split_pair(apart, 1.0, dof) is None
    # 19 of the 20 explained by body 0 (95%), 72 of the 80 by body 1 (90%: not more)
    mostly = split.costs.copy()
    mostly[80, 0] = mostly[:8, 1] = 1e3
    assert split_pair(replace(split, costs=mostly), 1.0, dof) is None
    for other, n in ((5.0, 1), (1e3, 2)):
        count = BodyCount(birth_every=1)
        count.solve(tracks, None, lambda n, labels, bodies: one)
        # the split scores far better (a smaller residual for one more body) yet is refused
        count.solve(tracks, np.where(labels == 1, -1, 0),
                    lambda n, labels, bodies, t=trial(other): t if n == 2 else one)
        assert count.n == n, other


def test_a_body_below_the_smallest_size_is_tried_at_once():
    """Its object left the view: one less is tried at the next solve, not every 2nd one."""
    calls: List[int] = []
    w = [[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]]
    labels = np.repeat([0, 1, 2], [50, 47, 3])

    def solve(n, start, bodies):
        calls.append(n)
        if n == 0:
            return _result(labels, w)
        return _result(np.where(start >= n, -1, start), w[:n])
    count = BodyCount(merge_every=100)
    tracks = np.zeros((100, 5, 4))
    count.solve(tracks, None, solve)
    count.solve(tracks, labels, solve)
    assert calls[1:] == [3, 2] and count.n == 2 and count.last_change == 'merge'


def test_a_body_that_left_the_view_goes_at_once():
    """Its tracks stay in the window's older frames, but the count is of what is in view."""
    tracks = np.zeros((100, 8, 4))
    tracks[70:, -IN_VIEW_FRAMES:] = np.nan            # body 2's 30 tracks left the view
    labels = np.repeat([0, 1, 2], [40, 30, 30])
    w = [[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]]
    fit = np.random.default_rng(1).chisquare(8, 100)

    def result(labels, n):
        # each track fits its own body at 1 px; under another it is far off
        costs = np.where(np.repeat([0, 1, 2], [40, 30, 30])[:, None] == np.arange(n),
                         fit[:, None], 1e3)
        return replace(_result(labels, w[:n]), costs=costs,
                       diagnostics=Diagnostics(sigma_px=1.0))
    # the body is small in view only: 30 tracks in the window, none in the newest frame
    dof = np.full(100, 8.0)
    assert merge_candidate(result(labels, 3), dof, pairs=False) is None
    got, gone, keep = merge_candidate(result(labels, 3), dof, pairs=False,
                                      visible=np.arange(100) < 70)
    assert (gone, keep) == (2, -1) and set(got[70:]) == {-1}

    def solve(n, start, bodies):
        return result(labels, 3) if n in (0, 3) else result(np.where(start >= n, -1, start), n)
    count = BodyCount(merge_every=100)
    count.solve(tracks, None, solve)
    count.solve(tracks, labels, solve)
    # scored on its tracks in the window the body would stay (only it explains them)
    assert count.n == 2 and count.last_change == 'merge'

    # a body whose lines all missed the newest frames (blur, an occluder) is still in view,
    # as its tracks are to the tracker: it keeps its id
    tracks[70:] = 0.0
    tracks[70:, 1 - IN_VIEW_FRAMES:] = np.nan
    assert np.all(in_view(tracks))
    count = BodyCount(merge_every=100)
    count.solve(tracks, None, solve)
    count.solve(tracks, labels, solve)
    assert count.n == 3


def test_a_count_below_the_truth_comes_back():
    """One body fitted to two motions leaves no track loose; a search there finds two."""
    tracks = np.zeros((100, 5, 4))
    truth = np.repeat([0, 1], [60, 40])
    fit = np.random.default_rng(0).chisquare(8, 100)
    # one body: the second motion's tracks cost 4x (a misfit, 2 px), within the bound at
    # the noise it measures (2 px): no birth is proposed
    one = replace(_result(np.zeros(100, dtype=int), np.zeros((1, 3))),
                  costs=np.where(truth == 0, fit, 4.0 * fit)[:, None],
                  diagnostics=Diagnostics(sigma_px=2.0))
    two = replace(_result(truth, np.zeros((2, 3))),
                  costs=np.where(truth[:, None] == [0, 1], fit[:, None], 1e3),
                  diagnostics=Diagnostics(sigma_px=1.0))
    assert birth_candidate(one, np.full(100, 8.0)) is None
    for better, n in ((two, 2), (one, 1)):
        tried: List[int] = []

        def solve(n, labels, bodies, better=better):
            if n == 2:
                # the worst-fitting body's tracks unlabelled, for the search
                assert np.all(labels == -1) and list(bodies) == [0, -1]
                tried.append(k)
                return better if better.n_bodies == 2 else two_alike
            return one
        two_alike = replace(two, costs=np.tile(fit[:, None], (1, 2)))  # one motion cut in two
        count = BodyCount()
        count.solve(tracks, None, solve)
        for k in range(1, 40):
            count.solve(tracks, np.zeros(100, dtype=int), solve)
            if count.n == 2:
                break
        assert count.n == n
        if n == 2:
            # once the count settled (HOLD solves) and a search is due: the smaller half new
            assert tried == [k] and k >= HOLD and count.last_change == 'birth'
            assert count.new_body == 1
        else:
            # refused (the halves explain each other's tracks); the next waits twice as long
            assert tried[:2] == [tried[0], tried[0] + 2 * SEARCH_EVERY], tried


def test_a_trial_that_cannot_be_solved_is_lost_not_the_frame():
    def solve(n, labels, bodies):
        if n == 0:
            return _result(np.repeat([0, -1], [80, 20]), [[0, 0, 0]])
        if n > 1:
            raise ValueError('20 usable tracks: too few for 2 bodies')
        return _result(np.where(labels >= n, -1, labels), np.zeros((n, 3)))
    count = BodyCount(birth_every=1)
    tracks = np.zeros((100, 5, 4))
    count.solve(tracks, None, solve)
    res = count.solve(tracks, np.repeat([0, -1], [80, 20]), solve)
    assert count.n == 1 and count.last_change is None and res.n_bodies == 1


def test_body_ids_of_a_new_body_and_a_merged_one():
    tracker = BodyTracker()
    ids = np.arange(60)
    w = np.zeros((2, 3))
    assert list(tracker.update(ids, np.repeat([0, 1], 30), w)) == [0, 1]
    # body 1's tracks split off into a new body 2: it gets a fresh id, not 1's
    got = tracker.update(ids, np.repeat([0, 1, 2], 20), np.zeros((3, 3)), new=[2])
    assert got[2] == 2 and sorted(got[:2]) == [0, 1]
    # bodies 0 and 1 merge: the kept id is the one asked for, whatever the histories
    got = tracker.update(ids, np.repeat([0, 1], [40, 20]), np.zeros((2, 3)), keeps={0: 1})
    assert got[0] == 1


def test_a_new_body_reuses_an_id_only_a_minute_after_its_last_body():
    tracker = BodyTracker()
    w3 = np.zeros((3, 3))
    assert list(tracker.update(np.arange(60), np.repeat([0, 1, 2], 20), w3, stamp=0.0)) \
        == [0, 1, 2]
    tracker.update(np.arange(60), np.repeat([0, 1, 2], 20), w3, stamp=1.0)
    # body 2 leaves (its tracks with it) after 1 s; two bodies go on
    assert sorted(tracker.update(np.arange(40), np.repeat([0, 1], 20), w3[:2],
                                 stamp=2.0)) == [0, 1]
    # a new body within the minute: a new id, 2 having been held 59 s ago
    got = tracker.update(np.arange(100, 160), np.repeat([0, 1, 2], 20), w3, new=[2],
                         stamp=60.0)
    assert got[2] == 3
    # it leaves; a minute after 2 and 3 were last held, a new body takes the smallest
    tracker.update(np.arange(100, 140), np.repeat([0, 1], 20), w3[:2], stamp=61.0)
    got = tracker.update(np.arange(200, 260), np.repeat([0, 1, 2], 20), w3, new=[2],
                         stamp=121.0)
    assert got[2] == 2 and tracker.n_slots == 4
    # never an id in use now, whatever the time
    got = tracker.update(np.arange(300, 380), np.repeat([0, 1, 2, 3], 20),
                         np.zeros((4, 3)), new=[3], stamp=500.0)
    assert len(set(got.tolist())) == 4 and tracker.n_slots == 4
    # without stamps new ids are never reused
    got = BodyTracker().update(np.arange(20), np.repeat([0], 20), w3[:1])
    assert list(got) == [0]


def test_warm_motions_follow_the_stable_ids_of_the_counted_bodies():
    warm = WarmStarts()
    warm.motions = {4: (np.ones(3), np.zeros(3)), 7: (2 * np.ones(3), np.ones(3))}
    kw = warm.keywords(get_method('general'), np.array([0, 1, -1]), 3, ids=[7, -1, 4])
    w, t = kw['init_motions']
    assert np.array_equal(w[0], 2 * np.ones(3)) and np.isnan(w[1]).all()
    assert np.array_equal(w[2], np.ones(3))


def test_a_body_not_rescanned_keeps_the_other_minima_of_its_last_rescan():
    def result(spreads, start):
        n = len(spreads)
        return SegmentationResult(
            labels=np.zeros(4, dtype=np.int64), angular_velocities=np.zeros((n, 3)),
            angular_covariances=np.tile(np.eye(3), (n, 1, 1)), focal_length=500.0,
            residuals=np.zeros(4), costs=np.zeros((4, n)), method='general',
            translation_directions=np.zeros((n, 3)), basin_spreads=np.asarray(spreads),
            diagnostics=Diagnostics(start=start, sigma_px=1.0, translation_scales=np.ones(n)))
    warm, S, none = WarmStarts(), np.diag([1.0, 2.0, 3.0]), np.full((3, 3), np.nan)
    ids = np.array([5, 9])
    warm.remember(result([S, none], 'warm'), ids, np.array([True, True]))
    got = warm.carried_spreads(result([none, none], 'step'), ids)
    assert np.array_equal(got[0], S) and np.all(got[1] == 0.0)
    # a body rescanned in this solve has its own in the result's covariance already
    assert np.all(warm.carried_spreads(result([2 * S, none], 'step'), ids) == 0.0)
    # by stable id; a method without them (rotation-only) carries none
    assert np.array_equal(warm.carried_spreads(result([none, none], 'step'), ids[::-1])[1], S)
    rotation = replace(result([none, none], 'step'), basin_spreads=None)
    assert np.all(warm.carried_spreads(rotation, ids) == 0.0)
    # a search finds the bodies' minima afresh; a reset forgets them
    warm.solved(get_method('general'), result([none, none], 'warm'))
    assert 5 in warm.spreads
    warm.solved(get_method('general'), result([none, none], 'spatial'))
    assert not warm.spreads
    warm.remember(result([S, S], 'warm'), ids, np.array([True, False]))
    assert list(warm.spreads) == [5]
    warm.reset()
    assert not warm.spreads


@pytest.mark.parametrize('method, seed', [('robust', 2), ('robust', 5), ('general', 0)])
def test_bodies_are_found_and_retired_as_the_scene_changes(method, seed):
    """A box starts, one stops, one leaves: the count follows, ids as a user expects."""
    # 'general' too: it labels at an inflated noise level, so a box that starts moving keeps
    # its lines labelled (on the background) and is found as tracks the score leaves
    # unexplained
    run = count.stream_run(seed, method)
    score = count.score_stream(run)
    assert score['right'] >= 0.9, (run['count'], run['want'])
    assert all(d is not None and d <= count.SETTLE for d in score['delays']), score
    for rule in ('background_kept', 'new_id_fresh', 'stopped_joins_background',
                 'left_id_unused'):
        assert score[rule], (rule, run['ids'])


def test_a_still_scene_is_one_body():
    """A fixed count splits a still scene arbitrarily; the automatic one does not."""
    sc = scheduled_scene([(10 ** 6, 10 ** 6, 10 ** 6)] * 2, 20, seed=1)
    p = Pipeline(num_bodies=0, window=5)
    ids = np.arange(len(sc.tracks))
    counts = [int(p.process_lines(ids, sc.tracks[:, k], k / 30.0, sc.image_size,
                                  camera=sc.intrinsics).body_solved.sum()) for k in range(20)]
    assert counts[1:] == [1] * 19, counts


def test_bench_count_reports_a_stream(tmp_path):
    run = count.stream_run(3, 'robust')
    known = count.stream_run(3, 'robust', num_bodies=4)
    run.update(method='robust', seed=3, score=count.score_stream(run),
               cost=count.cost(run['ms'], known['ms'], 5))
    args = count.parse_args(['--methods', 'robust'])
    text = count.build_report(args, [], [run], [], 1.0, 'abc1234')
    assert '| robust | 3 |' in text and 'right count in' in text
    count.plot([run], [], tmp_path / 'counts.png')
    assert (tmp_path / 'counts.png').stat().st_size > 1000
    assert count.parse_args(['--quick']).seed_list == [0]


def test_bench_count_scores_the_moving_segments_apart_from_the_still_scene():
    from types import SimpleNamespace
    seg = np.array([[0, 0, 0, 50], [20, 0, 20, 50], [40, 0, 40, 50], [60, 0, 60, 50],
                    [80, 0, 80, 50], [100, 0, 100, 50], [120, 0, 120, 50]], dtype=float)
    ids = np.arange(7)
    before = SimpleNamespace(track_ids=ids, segments=seg, labels=np.zeros(7, dtype=int))
    moved = seg + np.array([0, 0, 0, 0, 5, 5, 5])[:, None] * [1, 0, 1, 0]   # 5 px sideways
    # four still segments on body 0 (the still scene's), the moving three: two on body 1
    after = SimpleNamespace(track_ids=ids, segments=moved, labels=np.array([0, 0, 0, 0, 1, 1, 0]))
    results = {0: before, count.LAG: after}
    assert count.moving_apart(results, (count.LAG, count.LAG + 1)) == pytest.approx(2 / 3)
    assert np.isnan(count.moving_apart(results, (0, 1)))        # no frame LAG before it


def test_bench_count_tables_hopkins_per_method():
    rec = {'n': 2, 'count': [2, 2, 1], 'auto': [0.1, 0.2, 0.3], 'known': [0.1] * 3,
           'auto_ms': [1.0] * 8, 'known_ms': [1.0] * 8}
    text = count.hopkins_table([dict(rec, method='general'), dict(rec, method='robust')])
    rows = [line for line in text.splitlines() if line.startswith('| ') and 'motions' not in line]
    assert rows[0].startswith('| robust | 2 | 1 | 67 | - | 20.0 | 10.0 | 2.00 |')
    assert rows[1].startswith('| general | 2 |')
    # single windows: kept in one of four, one less taken in two, one more in one
    rec['windows'] = [(False, False), (True, False), (True, False), (False, True)]
    text = count.hopkins_table([dict(rec, method='robust')])
    assert '| robust | 2 | 1 | 67 | 25 (50 / 25) | 20.0 |' in text
    assert count.parse_args(['--hopkins-methods', '']).hopkins_method_list == []


def test_bench_count_checks_the_score_alone_on_single_windows():
    """Two distinct rotations keep their count; one rotation split in two loses a body."""
    sc = make_scene(2, 30, n_frames=count.HOPKINS_K + 2, noise_px=0.5, image_size=(640, 480),
                    focal_length=550.0, rotation_deg=(1.0, 2.0), seed=4)
    size = (640.0, 480.0)
    windows = count.score_preference(sc.tracks, sc.labels, 2, size, 'robust', 0)
    assert len(windows) == count.SCORED_WINDOWS and not any(map(any, windows)), windows
    one = make_scene(1, 60, n_frames=count.HOPKINS_K + 2, noise_px=0.5, image_size=(640, 480),
                     focal_length=550.0, rotation_deg=(1.0, 2.0), seed=4)
    split = np.arange(60) % 2                       # no motion tells these halves apart
    windows = count.score_preference(one.tracks, split, 2, size, 'robust', 0)
    assert windows and all(fewer for fewer, _ in windows), windows
