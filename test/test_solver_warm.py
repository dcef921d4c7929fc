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
"""Warm-started robust solves (``init_labels``: the previous window's labels, as the pipeline)."""
from mlofc_ros.solver import segment_lines
from mlofc_tools.scoring import best_permutation, motion_errors
from mlofc_tools.synthetic import make_scene
import numpy as np
import pytest


def _wrong(labels, truth, n):
    return best_permutation(labels, truth, n)[1] / truth.size


def _scene(seed):
    return make_scene(3, 40, n_frames=6, noise_px=1.0, seed=seed)


def test_warm_start_from_the_last_window_keeps_the_labels_and_skips_the_search():
    for seed in range(3):
        sc = _scene(seed)
        cold = segment_lines(sc.tracks[:, :5], 3, intrinsics=sc.intrinsics, seed=0)
        warm = segment_lines(sc.tracks[:, 1:], 3, intrinsics=sc.intrinsics, seed=0,
                             init_labels=cold.labels)
        again = segment_lines(sc.tracks[:, 1:], 3, intrinsics=sc.intrinsics, seed=0)
        assert warm.diagnostics.candidate == 'previous'
        assert _wrong(warm.labels, sc.labels, 3) <= _wrong(again.labels, sc.labels, 3) + 0.01
        assert _wrong(warm.labels, sc.labels, 3) < 0.03
        perm = best_permutation(warm.labels, sc.labels, 3)[0]
        assert motion_errors(warm.angular_velocities, sc.angular_velocities, perm)[0] < 0.05


def test_a_body_missing_from_the_previous_labels_is_searched_for():
    # the previous window merged bodies 1 and 2: a warm start would keep a body with no tracks
    sc = _scene(7)
    merged = np.where(sc.labels == 2, 1, sc.labels)
    res = segment_lines(sc.tracks[:, 1:], 3, intrinsics=sc.intrinsics, seed=0,
                        init_labels=merged)
    assert res.diagnostics.candidate != 'previous' or len(res.diagnostics.candidate_costs) > 1
    # the search from previous labels: they stand in for the paper's unweighted GPCA start
    # (its QR took a fifth of a search of five bodies, bench count's trials); the whitened
    # one and MSAC still run
    assert {'previous', 'gpca-weighted', 'msac'} <= set(res.diagnostics.candidate_costs)
    assert 'gpca' not in res.diagnostics.candidate_costs
    assert _wrong(res.labels, sc.labels, 3) < 0.03


def test_stale_labels_that_no_longer_explain_the_window_fall_back_to_the_search():
    sc = _scene(11)
    rng = np.random.default_rng(0)
    stale = rng.integers(0, 3, sc.labels.size)                       # every body held, but wrong
    res = segment_lines(sc.tracks[:, 1:], 3, intrinsics=sc.intrinsics, seed=0,
                        init_labels=stale)
    assert _wrong(res.labels, sc.labels, 3) < 0.03


def test_warm_inliers_sets_the_share_a_warm_start_keeps_without_a_search():
    # two bodies and a third one's tracks as outliers (27%): the previous labels keep 73% of
    # the tracks, under the default 75%, so a search runs (and the warm pass competes in it);
    # a lower warm_inliers (the pipeline's, after such a search) returns the warm pass alone
    for seed in range(2):
        sc = make_scene(3, [40, 40, 30], n_frames=6, noise_px=1.0, seed=seed)
        body = sc.labels < 2
        init = np.where(body, sc.labels, -1)
        searched = segment_lines(sc.tracks[:, 1:], 2, intrinsics=sc.intrinsics, seed=0,
                                 init_labels=init)
        assert searched.diagnostics.warm_rejected
        assert 'previous-pass' in searched.diagnostics.candidate_costs
        assert 0.7 < searched.diagnostics.inlier_share < 0.75
        warm = segment_lines(sc.tracks[:, 1:], 2, intrinsics=sc.intrinsics, seed=0,
                             init_labels=init, warm_inliers=0.6)
        assert warm.diagnostics.candidate == 'previous' and not warm.diagnostics.warm_rejected
        np.testing.assert_array_equal(warm.labels[body], sc.labels[body])
        assert np.all(warm.labels[~body] == -1)
        np.testing.assert_array_equal(warm.labels, searched.labels)
    alone = segment_lines(sc.tracks[:, 1:], 2, intrinsics=sc.intrinsics, seed=0,
                          init_labels=init, warm_competes=False)
    assert alone.diagnostics.warm_rejected
    assert 'previous-pass' not in alone.diagnostics.candidate_costs
    for bad in (-0.1, 1.5, float('nan')):
        with pytest.raises(ValueError, match='warm_inliers'):
            segment_lines(sc.tracks[:, 1:], 2, intrinsics=sc.intrinsics, init_labels=init,
                          warm_inliers=bad)


def _result(labels, w, start='step', sigma=0.5):
    """Return a 'general' result of bodies turning by ``w (n, 3)``, translation 0.02 along z."""
    from mlofc_ros.solver.result import Diagnostics, SegmentationResult
    n = len(w)
    return SegmentationResult(
        labels=labels, angular_velocities=w, angular_covariances=np.stack([np.eye(3)] * n),
        focal_length=500.0, residuals=np.zeros(len(labels)), costs=np.zeros((len(labels), n)),
        method='general', segmentation_angular_velocities=np.array(w, dtype=float),
        translation_directions=np.tile([0.0, 0.0, 1.0], (n, 1)),
        diagnostics=Diagnostics(start=start, sigma_px=sigma, translation_scales=np.full(n, 0.02)))


def _general_solve(warm, labels, n, start, w, sigma=0.5, stamp=float('nan')):
    """Run ``warm``'s schedule through one solve of 'general' (motions ``w (n, 3)``)."""
    from mlofc_ros.solver.methods import GENERAL
    kw = warm.keywords(GENERAL, labels, n)
    res = _result(labels, w, start, sigma)
    warm.solved(GENERAL, res, stamp, 0.1)
    warm.remember(res, np.arange(n), np.ones(n, dtype=bool))
    return kw


def test_a_stream_of_general_solves_steps_between_full_solves():
    # the pipeline's schedule: full solves (every body rescanned) after a search, then steps,
    # one body rescanned in turn every RESCAN_EVERY steps, a full solve after a noise jump
    from mlofc_ros.solver.warm import FULL_AFTER_SEARCH, NOISE_JUMP, RESCAN_EVERY, WarmStarts
    warm, labels, n = WarmStarts(), np.zeros(6, dtype=np.int64), 2

    def solve(start, sigma=0.5, stamp=float('nan'), w=0.01):
        return _general_solve(warm, labels, n, start, np.full((n, 3), w), sigma, stamp)

    assert 'init_motions' not in solve('spatial')          # the first window: a search
    for _ in range(FULL_AFTER_SEARCH):
        kw = solve('warm')
        assert kw['rescan'] == [0, 1] and 'step' not in kw
    # the translation is handed on with its scale
    assert np.allclose(kw['init_motions'][1], [[0.0, 0.0, 0.02]] * n)
    rescanned = []
    for _ in range(2 * RESCAN_EVERY):
        kw = solve('step', w=0.011)            # the steps refine the motions
        assert kw['step']
        rescanned += kw.get('rescan', [])
    assert rescanned == [0, 1]                           # one body in turn
    assert solve('step', sigma=0.5 * NOISE_JUMP * 1.1)['step']
    kw = solve('warm')                                   # after the jump: a full solve
    assert 'step' not in kw and kw['rescan'] == [0, 1]
    assert solve('step')['step']
    # with stamps: full solves for the FULL_AFTER_SEARCH frames after a search, not solves
    # (a solver slower than the camera solves fewer of them)
    solve('spatial', stamp=10.0)
    for k in range(1, FULL_AFTER_SEARCH + 1):      # one frame (0.1 s) apart: as before
        assert 'step' not in solve('warm', stamp=10.0 + 0.1 * k)
    assert solve('step', stamp=10.5)['step']
    solve('spatial', stamp=20.0)
    assert 'step' not in solve('warm', stamp=21.5)    # 15 frames later: one full solve
    assert solve('step', stamp=21.6)['step']


def test_rescans_back_off_while_they_change_no_basin():
    # one body rescanned in turn every RESCAN_EVERY steps; after each round of n rescans that
    # moved no body to another basin the steps between them double, up to RESCAN_EVERY_MAX;
    # a rescan that does, or any solve that is not a step, brings them back
    from mlofc_ros.solver.warm import RESCAN_EVERY, RESCAN_EVERY_MAX, RESCAN_SWITCH, WarmStarts
    warm, labels, n = WarmStarts(), np.zeros(6, dtype=np.int64), 2
    w = np.full((n, 3), 0.02)

    def solve(start):
        kw = _general_solve(warm, labels, n, start, w.copy())
        return kw.get('rescan', []) if kw.get('step') else None

    def steps_between(count):
        at, k = [], 0
        while len(at) < count:
            k += 1
            if solve('step'):
                at.append(k)
        return list(np.diff([0] + at))

    solve('spatial')
    for _ in range(3):
        solve('warm')
    # rounds of two rescans: 3, 3, then 6, 6, 12, 12, 24, 24, 24 ...
    expected = [RESCAN_EVERY] * n + [2 * RESCAN_EVERY] * n + [4 * RESCAN_EVERY] * n
    assert steps_between(3 * n) == expected
    assert steps_between(3 * n) == [RESCAN_EVERY_MAX] * 3 * n
    # a rescan that moves its body to another basin: back to RESCAN_EVERY
    for k in range(RESCAN_EVERY_MAX):
        if k == RESCAN_EVERY_MAX - 1:
            w[:] = 0.02 * (1.0 + 2.0 * RESCAN_SWITCH)    # the rescanned body's new basin
        got = solve('step')
    assert got                                           # the rescan's step
    assert steps_between(n) == [RESCAN_EVERY] * n
    # refinements below RESCAN_SWITCH do not count as a basin change
    w[:] *= 1.0 + 0.5 * RESCAN_SWITCH
    assert steps_between(n) == [2 * RESCAN_EVERY] * n
    # a full solve brings the rescans back too
    solve('warm')
    assert steps_between(n) == [RESCAN_EVERY] * n


def test_a_declined_step_asks_for_a_full_solve_and_made_no_rescan():
    # a step that did not hold (StepNotTaken, the solver lane's steps): the next solve is a
    # full one, and the rescan the declined step was asked for is not counted as made
    from mlofc_ros.solver.methods import GENERAL
    from mlofc_ros.solver.warm import FULL_AFTER_SEARCH, WarmStarts
    warm, labels, n = WarmStarts(), np.zeros(6, dtype=np.int64), 2
    _general_solve(warm, labels, n, 'spatial', np.full((n, 3), 0.01), stamp=0.0)
    for _ in range(FULL_AFTER_SEARCH):            # past the full solves after the search
        _general_solve(warm, labels, n, 'warm', np.full((n, 3), 0.01), stamp=1.0)
    while warm.until_rescan > 0:
        _general_solve(warm, labels, n, 'step', np.full((n, 3), 0.01), stamp=2.0)
    kw = warm.keywords(GENERAL, labels, n)       # this step rescans a body, and is declined
    assert kw['step'] and kw['rescan'] and not warm.full_solve_due()
    warm.step_declined()
    assert warm.full_solve_due() and 'step' not in warm.keywords(GENERAL, labels, n)
    assert warm._rescanned is None


def test_a_rescan_handed_to_a_lane_changes_its_body_only_when_it_moved_it():
    # a solver lane takes the rescan out of a step: no other rescan is asked for until it is
    # back; its answer moves the body's motion only when it found another basin, and counts
    # for the back-off as a rescan in a step
    from mlofc_ros.solver.methods import GENERAL
    from mlofc_ros.solver.warm import (FULL_AFTER_SEARCH, RESCAN_EVERY, RESCAN_SWITCH,
                                       result_motions, WarmStarts)
    warm, labels, n = WarmStarts(), np.zeros(6, dtype=np.int64), 2
    w = np.full((n, 3), 0.01)
    _general_solve(warm, labels, n, 'spatial', w)
    for _ in range(FULL_AFTER_SEARCH):
        _general_solve(warm, labels, n, 'warm', w)

    def due():
        """Step until a step asks for a rescan; hand it to the lane; return its body."""
        for _ in range(10 * RESCAN_EVERY):
            kw = warm.keywords(GENERAL, labels, n)
            if 'rescan' in kw:
                warm.rescan_aside(True)
                warm.solved(GENERAL, _result(labels, w))
                warm.remember(_result(labels, w), np.arange(n), np.ones(n, dtype=bool))
                return kw['rescan'][0]
            _general_solve(warm, labels, n, 'step', w)
        raise AssertionError('no rescan asked for')

    body = due()
    for _ in range(3 * RESCAN_EVERY):              # while it is out, plain steps
        assert 'rescan' not in _general_solve(warm, labels, n, 'step', w)
    # an answer within the basin: the stepped motion stays
    near = w.copy()
    near[body] *= 1.0 + 0.5 * RESCAN_SWITCH
    assert not warm.rescan_returned(result_motions(_result(labels, near)))
    np.testing.assert_array_equal(warm.motions[body][0], w[body])
    # the next one, in another basin: the body takes the rescan's motion, T with its scale
    body = due()
    far = w.copy()
    far[body] = [0.03, -0.01, 0.0]
    assert warm.rescan_returned(result_motions(_result(labels, far)))
    np.testing.assert_array_equal(warm.motions[body][0], far[body])
    np.testing.assert_allclose(warm.motions[body][1], [0.0, 0.0, 0.02])
    np.testing.assert_array_equal(warm.motions[1 - body][0], w[1 - body])
    # the switch brought the rescans back to RESCAN_EVERY: steps in between, then the next
    for _ in range(RESCAN_EVERY - 1):
        assert 'rescan' not in _general_solve(warm, labels, n, 'step', w)
    kw = warm.keywords(GENERAL, labels, n)
    assert kw['rescan'] == [(body + 1) % n]
    # one that did not hold (or was dropped) is asked for again at the next step
    warm.rescan_aside(True)
    warm.solved(GENERAL, _result(labels, w))
    assert not warm.rescan_returned(None)
    assert warm.keywords(GENERAL, labels, n)['rescan'] == [(body + 1) % n]
    # a lane that was busy: the rescan stays due
    warm.rescan_aside(False)
    warm.solved(GENERAL, _result(labels, w))
    assert warm.keywords(GENERAL, labels, n)['rescan'] == [(body + 1) % n]


def test_a_rescan_in_a_step_that_did_not_hold_keeps_its_new_basin():
    # while a full solve is out the steps do not hold and the running fit stays as it was;
    # each rescans a body in turn, and a new basin one of them finds is kept meanwhile
    from mlofc_ros.solver.methods import GENERAL
    from mlofc_ros.solver.result import StepNotTaken
    from mlofc_ros.solver.warm import FULL_AFTER_SEARCH, WarmStarts
    import pickle
    warm, labels, n = WarmStarts(), np.zeros(6, dtype=np.int64), 2
    w = np.full((n, 3), 0.01)
    _general_solve(warm, labels, n, 'spatial', w)
    for _ in range(FULL_AFTER_SEARCH):
        _general_solve(warm, labels, n, 'warm', w)
    warm.keywords(GENERAL, labels, n)
    warm.step_declined()
    assert warm.full_solve_due()
    W, T = warm.keywords(GENERAL, labels, n)['init_motions']
    rescanned = []
    for k in range(2):
        body = warm.rescan_meanwhile(W)
        rescanned += body
        after = W.copy()
        if k == 1:
            after[body[0]] = [0.03, -0.01, 0.0]              # another basin
        T_after = np.full((n, 3), 0.5)
        exc = pickle.loads(pickle.dumps(StepNotTaken('declined', (after, T_after))))
        np.testing.assert_array_equal(exc.motions[0], after)   # across the lane's process
        warm.step_declined(exc.motions)
    assert rescanned == [0, 1]                                # one body in turn
    np.testing.assert_array_equal(warm.motions[0][0], W[0])   # within its basin: as it was
    np.testing.assert_array_equal(warm.motions[1][0], [0.03, -0.01, 0.0])
    np.testing.assert_array_equal(warm.motions[1][1], [0.5, 0.5, 0.5])
    assert warm.full_solve_due()                              # still the full solve's
