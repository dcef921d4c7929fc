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
"""The solve side of a pipeline in a child process (mlofc_ros.solve_process)."""
import signal
import subprocess
import sys
import time
from typing import List

from mlofc_ros.pipeline import FOCAL_SAMPLES, Pipeline
from mlofc_ros.solve_process import SolveProcess, SolverProcessEnded, SolverProcessError
import numpy as np
import pytest
from test_pipeline import small_sequence


def test_a_child_solves_as_the_pipeline_itself_and_hands_back_its_state():
    seq = small_sequence(8)
    params = {'num_bodies': 2, 'window': 5, 'method': 'general', 'focal_length': 300.0}
    here, observing = Pipeline(**params), Pipeline(**params)
    with SolveProcess(observing.params, lane=False) as remote:     # every solve in turn
        assert remote.alive
        for k, (gray, t) in enumerate(zip(seq.frames[:7], seq.stamps[:7])):
            a = here.process(gray, t)
            b = remote.solve(observing.observe(gray, t), observing)
            # the same solve, the same answer
            np.testing.assert_array_equal(a.labels, b.labels)
            np.testing.assert_array_equal(a.body_valid, b.body_valid)
            np.testing.assert_allclose(a.angular_velocities, b.angular_velocities)
        # the observing pipeline carries the child's last answer to the next frame
        ca = here.carry(here.observe(seq.frames[7], seq.stamps[7]))
        cb = observing.carry(observing.observe(seq.frames[7], seq.stamps[7]))
        assert np.sum(cb.carried) > 10
        np.testing.assert_array_equal(ca.labels, cb.labels)
        pid = remote.pid
    assert not remote.alive and remote.pid is None and pid is not None
    remote.close()                                      # idempotent


def test_the_solve_side_moves_into_a_child_and_back_with_its_body_ids():
    seq = small_sequence(12)
    params = {'num_bodies': 2, 'window': 5, 'focal_length': 300.0}
    here, observing = Pipeline(**params), Pipeline(**params)
    before = [here.process(gray, t) for gray, t in zip(seq.frames[:6], seq.stamps[:6])]
    for gray, t in zip(seq.frames[:6], seq.stamps[:6]):
        observing.solve(observing.observe(gray, t))
    known = set(observing.bodies.track_labels)
    with SolveProcess(dict(observing.params, method='general'), lane=False) as remote:
        remote.take_over(observing.hand_over())         # sent with the first solve
        r = remote.solve(observing.observe(seq.frames[6], seq.stamps[6]), observing)
        side = remote.hand_over()
        # the child went on from the tracks' histories here, even those of tracks it has
        # not seen (the body ids restarted would have only its own window's)
        assert known - set(r.track_ids.tolist())
        assert known <= set(side.bodies.track_labels)
        # the child's bodies keep the ids they had here: the same tracks, the same ids
        prev = dict(zip(before[-1].track_ids.tolist(), before[-1].labels.tolist()))
        both = [(prev[t], lab) for t, lab in zip(r.track_ids.tolist(), r.labels.tolist())
                if prev.get(t, -1) >= 0 and lab >= 0]
        assert len(both) > 10
        assert np.mean([a == b for a, b in both]) > 0.9
    # and back: this pipeline solves on from the child's state, with the same ids
    observing.take_over(side)
    again = observing.solve(observing.observe(seq.frames[7], seq.stamps[7]))
    prev = dict(zip(r.track_ids.tolist(), r.labels.tolist()))
    both = [(prev[t], lab) for t, lab in zip(again.track_ids.tolist(), again.labels.tolist())
            if prev.get(t, -1) >= 0 and lab >= 0]
    assert len(both) > 10 and np.mean([a == b for a, b in both]) > 0.9
    # a state handed over but not sent yet is still the caller's
    with SolveProcess(observing.params, lane=False) as remote:
        handed = observing.hand_over()
        remote.take_over(handed)
        assert remote.hand_over() is handed


def test_an_unknown_focal_length_estimated_in_the_child_reaches_the_observations():
    seq = small_sequence(FOCAL_SAMPLES + 3)
    observing = Pipeline(num_bodies=2, window=3)
    with SolveProcess(observing.params) as remote:
        focals = []
        for gray, t in zip(seq.frames, seq.stamps):
            obs = observing.observe(gray, t)
            focals.append(None if obs.intrinsics is None else obs.intrinsics[0])
            r = remote.solve(obs, observing)
        # the child starts its estimate after FOCAL_SAMPLES solves; the observing side then
        # gives it to the next observations
        assert focals[0] is None and focals[-1] is not None
        assert focals[-1] == pytest.approx(r.focal_length)


def test_a_failing_child_is_reported_and_a_dead_one_restarted():
    seq = small_sequence(6)
    observing = Pipeline(num_bodies=2, window=3, focal_length=300.0)
    with SolveProcess(observing.params) as remote:
        for gray, t in zip(seq.frames[:3], seq.stamps[:3]):
            remote.solve(observing.observe(gray, t), observing)
        # an error in the child: reported, the child goes on
        with pytest.raises(SolverProcessError, match='window'):
            remote.reconfigure(window=1)
        assert remote.alive
        epoch = observing.observe(seq.frames[3], seq.stamps[3]).epoch
        # the child dies: the solve fails with the reason, a new child takes over, and
        # the observing side restarts the body ids (the state died with the child)
        old = remote.pid
        remote._process.kill()
        remote._process.wait(5.0)
        obs = observing.observe(seq.frames[4], seq.stamps[4])
        with pytest.raises(SolverProcessEnded, match='ended'):
            remote.solve(obs, observing)
        assert remote.alive and remote.pid != old
        obs = observing.observe(seq.frames[5], seq.stamps[5])
        assert 'bodies' in obs.resets and obs.epoch > epoch
        r = remote.solve(obs, observing)
        assert r.problem is None and np.sum(r.labels >= 0) > 10


def running(pid: int) -> bool:
    """Whether process ``pid`` runs (ended: gone, or a zombie its new parent did not reap)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            return f.read().rsplit(')', 1)[1].split()[0] != 'Z'
    except FileNotFoundError:
        return False


def children(pid: int) -> List[int]:
    """Return the process ids of the children of ``pid`` (Linux)."""
    try:
        with open(f'/proc/{pid}/task/{pid}/children') as f:
            return [int(c) for c in f.read().split()]
    except FileNotFoundError:
        return []


def test_the_child_and_its_lane_end_with_their_parent_even_killed():
    code = ('from mlofc_ros.solve_process import SolveProcess\n'
            'import time\n'
            'remote = SolveProcess({"num_bodies": 2, "method": "general"})\n'
            'print(remote.pid, flush=True)\n'
            'time.sleep(60)\n')
    parent = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE, text=True)
    try:
        pid = int(parent.stdout.readline())
        assert running(pid)
        deadline = time.monotonic() + 20.0
        while not children(pid) and time.monotonic() < deadline:
            time.sleep(0.1)                         # 'general': its lane starts with it
        lane = children(pid)
        assert len(lane) == 1 and running(lane[0])
        parent.send_signal(signal.SIGKILL)
        parent.wait(10.0)
        deadline = time.monotonic() + 20.0
        # orphaned, each sees the end of its input and exits
        while (running(pid) or running(lane[0])) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not running(pid) and not running(lane[0])
    finally:
        parent.kill()
        parent.wait()


def test_a_child_that_cannot_be_restarted_is_reported_at_every_solve(monkeypatch):
    seq = small_sequence(4)
    observing = Pipeline(num_bodies=2, window=3, focal_length=300.0)
    with SolveProcess(observing.params) as remote:
        remote.solve(observing.observe(seq.frames[0], seq.stamps[0]), observing)
        remote._process.kill()
        remote._process.wait(5.0)
        monkeypatch.setattr(sys, 'executable', '/nonexistent/python')
        with pytest.raises(SolverProcessEnded, match='cannot restart'):
            remote.solve(observing.observe(seq.frames[1], seq.stamps[1]), observing)
        with pytest.raises(SolverProcessEnded, match='cannot start'):
            remote.solve(observing.observe(seq.frames[2], seq.stamps[2]), observing)
        monkeypatch.undo()
        r = remote.solve(observing.observe(seq.frames[3], seq.stamps[3]), observing)
        assert remote.alive and r.problem is None


def test_a_child_steps_the_frames_while_its_lane_runs_the_full_solves():
    from scenes import random_scene
    tracks, truth, _, intr = random_scene(2, 25, n_frames=360, noise=0.2, seed=3,
                                          own_centre=True)
    ids = np.arange(tracks.shape[0])
    observing = Pipeline(num_bodies=2, window=10, method='general')
    with SolveProcess(observing.params) as remote:
        results = []
        # frames until 20 stepped: a loaded machine's search takes longer than an idle one's
        for k in range(tracks.shape[1]):
            obs = observing.observe_lines(ids, tracks[:, k], k / 30.0, (1000, 1000), intr)
            results.append(remote.solve(obs, observing))
            if sum(r.body_valid.all() for r in results[4:]) >= 20:
                break
            time.sleep(0.03)                                 # a camera's pace
    # the first frames wait for the lane's search (answered from the running fit), the
    # later ones step from its answer
    waiting = [r for r in results[4:] if not r.body_valid.any()]
    stepped = [r for r in results[4:] if r.body_valid.all()]
    assert waiting and len(stepped) >= 20
    assert all(r.from_running_fit for r in waiting)      # the flag crosses the process
    for r in stepped[-3:]:
        for s in range(2):
            g = int(np.bincount(truth[r.labels == s]).argmax())
            assert np.count_nonzero((r.labels == s) & (truth != g)) <= 2


def _answer(lane, timeout=30.0):
    """Poll ``lane`` until its job is back (None after ``timeout`` seconds)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        finished = lane.poll()
        if finished is not None:
            return finished
        time.sleep(0.05)
    return None


def test_a_lane_answers_a_job_as_the_solver_and_restarts_when_killed():
    from mlofc_ros.frame import Observation
    from mlofc_ros.lane import SolveJob
    from mlofc_ros.solve_process import ProcessLane
    from mlofc_ros.solver import segment_lines
    from scenes import random_scene
    tracks, _, _, intr = random_scene(2, 25, n_frames=6, noise=0.2, seed=3, own_centre=True)
    keywords = {'tracks': tracks, 'n_bodies': 2, 'intrinsics': intr, 'method': 'general'}
    obs = Observation.skip(0.0, None, 'a test', 6)
    lane = ProcessLane()
    try:
        assert lane.poll() is None and not lane.busy
        job = SolveJob(obs, keywords, 0)
        lane.submit(job)
        with pytest.raises(RuntimeError, match='busy'):
            lane.submit(job)
        finished = _answer(lane)
        assert finished is not None and finished[0] is job and not lane.busy
        np.testing.assert_array_equal(finished[1].labels, segment_lines(**keywords).labels)
        # its child runs jobs only: it has no pipeline to solve frames with
        lane._conn.send(('solve', obs))
        assert lane._conn.recv() == ('error', "ValueError: a lane runs jobs only, not 'solve'")
        # a job that fails comes back with its exception
        lane.submit(SolveJob(obs, dict(keywords, n_bodies=-1), 0))
        finished = _answer(lane)
        assert isinstance(finished[1], ValueError)
        # a killed child: its job comes back with the reason, the next job restarts it
        lane.submit(job)
        lane._process.kill()
        lane._process.wait()
        finished = _answer(lane)
        assert finished[0] is job and isinstance(finished[1], SolverProcessEnded)
        assert not lane.busy
        lane.submit(job)
        assert lane.busy and lane._process.poll() is None
        assert _answer(lane)[0] is job
        # a child killed while idle: the next job starts another
        lane._process.kill()
        lane._process.wait()
        lane.submit(job)
        finished = _answer(lane)
        assert finished[0] is job and finished[1].labels.shape == (tracks.shape[0],)
    finally:
        lane.close()
    assert lane._process is None and not lane.busy
