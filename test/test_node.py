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

"""The node over real DDS: in-process next to a test node, and as the installed executable."""
import os
import pathlib
import re
import signal
import subprocess
import time
from types import SimpleNamespace
from typing import Dict, List

from dds import DdsHarness, executable, FRAME_ID, image_msg, stamp_of
from geometry_msgs.msg import TwistWithCovarianceStamped
from mlofc_ros import params as P
from mlofc_ros.camera import CameraModel
from mlofc_ros.messages.segments import SEGMENT_FIELDS
from mlofc_ros.node import MlofcNode, parameter_descriptor
from mlofc_ros.ros_messages import (camera_info_size, camera_model_from_info,
                                    LINEAR_UNKNOWN_VARIANCE, parse_segment_rays,
                                    parse_segments_msg, parse_twist_msg, segments_msg, twist_msg)
from mlofc_ros.tracks.undistort import undistort_segments
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image, PointCloud2
from test_pipeline import (evaluate, GOAL_MISCLASSIFIED, GOAL_OMEGA_ERROR, small_sequence,
                           two_box_sequence)
from test_solve_process import running


pytestmark = pytest.mark.ros

CONFIG = pathlib.Path(__file__).resolve().parents[1] / 'config' / 'mlofc.yaml'


def camera_info_msg(camera, size, t: float = 0.0) -> CameraInfo:
    msg = CameraInfo()
    msg.header = image_msg(np.zeros((2, 2), np.uint8), t).header
    msg.width, msg.height = size
    msg.k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    msg.d = list(camera.d)
    msg.distortion_model = camera.distortion_model
    return msg


class Harness(DdsHarness):
    """A test node and an executor spinning in a thread (with the node under test, if any)."""

    def __init__(self, *nodes) -> None:
        super().__init__('mlofc_test_harness', *nodes)
        self.start()

    def topics(self) -> Dict[str, List[str]]:
        return dict(self.node.get_topic_names_and_types())


def send_frames(h: Harness, pub, frames, stamps, clouds: List, cam_pub=None, cam=None,
                timeout: float = 20.0) -> None:
    """Publish frames one at a time, each after the previous one's cloud arrived."""
    for img, t in zip(frames, stamps):
        if cam_pub is not None:
            cam_pub.publish(camera_info_msg(cam, (img.shape[1], img.shape[0]), t))
        n = len(clouds)
        msg = image_msg(img, t)
        for _ in range(3):            # best effort: resend if this frame never got through
            pub.publish(msg)
            if h.wait(lambda: len(clouds) > n, timeout / 3):
                break
        assert len(clouds) > n, f'no ~/segments for the frame at {t:.3f} s'
        assert stamp_of(clouds[-1]) == round(t, 6)


# --- message builders (no DDS) -------------------------------------------------------------


def test_segment_cloud_round_trip_and_empty_cloud():
    header = image_msg(np.zeros((2, 2), np.uint8), 1.5).header
    segs = np.array([[1, 2, 3, 4], [5.5, 6, 7, 8]], np.float32)
    rays = np.array([[-0.5, 0.25, 1.0], [0.0, 0.125, 1.0]], np.float32)
    msg = segments_msg(header, segs, np.array([7, 9], np.uint32), np.array([-1, 2]),
                       np.array([np.nan, 0.25], np.float32), rays)
    assert msg.width == 2 and msg.point_step == 40 and msg.row_step == 80 and msg.is_dense
    assert [f.name for f in msg.fields[:3]] == ['x', 'y', 'z']
    np.testing.assert_array_equal(parse_segment_rays(msg), rays)
    assert msg.header.frame_id == FRAME_ID and stamp_of(msg) == 1.5
    s, ids, labels, res = parse_segments_msg(msg)
    np.testing.assert_array_equal(s, segs)
    assert ids.tolist() == [7, 9] and labels.tolist() == [-1, 2]
    assert np.isnan(res[0]) and res[1] == np.float32(0.25)
    empty = segments_msg(header, np.zeros((0, 4)), np.zeros(0, np.uint32), np.zeros(0, int),
                         np.zeros(0))
    assert empty.width == 0 and len(empty.data) == 0 and len(empty.fields) == 10
    msg.fields[3].offset = 4
    with pytest.raises(ValueError, match='layout'):
        parse_segments_msg(msg)


def test_twist_covariance_and_undetermined_bodies():
    header = image_msg(np.zeros((2, 2), np.uint8), 0.0).header
    cov = np.diag([1e-4, 2e-4, 3e-4])
    msg = twist_msg(header, np.array([0.1, -0.2, 0.3]), cov)
    w, c = parse_twist_msg(msg)
    np.testing.assert_allclose(w, [0.1, -0.2, 0.3])
    np.testing.assert_allclose(c, cov)
    full = np.asarray(msg.twist.covariance).reshape(6, 6)
    assert np.all(np.diag(full)[:3] == LINEAR_UNKNOWN_VARIANCE)
    assert msg.twist.twist.linear.x == 0.0 and np.all(full[:3, 3:] == 0)
    bad = twist_msg(header, np.array([np.nan, 0.0, 0.0]), np.full((3, 3), np.inf))
    w, c = parse_twist_msg(bad)
    assert np.all(np.isfinite(w)) and np.all(np.isinf(np.diag(c)))


def test_camera_info_parsing_with_binning_and_roi():
    cam = CameraModel(500.0, 510.0, 320.0, 240.0, (0.1, 0.0, 0.0, 0.0, 0.0), 'plumb_bob')
    info = camera_info_msg(cam, (640, 480))
    assert camera_model_from_info(info) == cam
    assert camera_info_size(info) == (640, 480)
    info.binning_x = info.binning_y = 2
    info.roi.x_offset, info.roi.y_offset = 100, 40
    info.roi.width, info.roi.height = 400, 300
    binned = camera_model_from_info(info)
    assert (binned.fx, binned.fy, binned.cx, binned.cy) == (250.0, 255.0, 110.0, 100.0)
    assert camera_info_size(info) == (200, 150)
    info.k = [0.0] * 9
    with pytest.raises(ValueError, match='zero'):
        camera_model_from_info(info)
    info = camera_info_msg(cam, (640, 480))
    info.d = [0.1, 0.2]
    with pytest.raises(ValueError, match='coefficients'):
        camera_model_from_info(info)


# --- in process --------------------------------------------------------------------------


def test_descriptors_match_the_parameter_table():
    for spec in P.PARAMETERS:
        d = parameter_descriptor(spec)
        assert d.description == spec.description
        if spec.type is int and spec.range is not None:
            assert (d.integer_range[0].from_value, d.integer_range[0].to_value) == spec.range
        if spec.type is float:
            assert d.dynamic_typing and d.floating_point_range[0].to_value == spec.range[1]


@pytest.mark.slow
def test_in_process_two_boxes_one_cloud_per_image_and_accuracy(ros):
    seq = two_box_sequence()
    node = MlofcNode(namespace='/inproc', parameter_overrides=[
        Parameter('num_bodies', value=3), Parameter('publish_debug_image', value=True)])
    h = Harness(node)
    try:
        clouds = h.collect(PointCloud2, '/inproc/mlofc/segments')
        twists = {i: h.collect(TwistWithCovarianceStamped, f'/inproc/mlofc/body_{i}/twist')
                  for i in range(3)}
        debug = h.collect(Image, '/inproc/mlofc/debug_image')
        pub, cam_pub = h.camera_publishers('/inproc')
        send_frames(h, pub, seq.frames, seq.stamps, clouds, cam_pub, seq.camera)
        h.wait(lambda: len(debug) >= len(seq.frames)
               and all(len(t) >= len(seq.frames) - 1 for t in twists.values()), 5.0)
        # exactly one cloud per processed image, in order, with the image's header
        assert node.stats['processed'] == len(seq.frames) == len(clouds)
        assert [stamp_of(c) for c in clouds] == [round(t, 6) for t in seq.stamps]
        assert all(c.header.frame_id == FRAME_ID for c in clouds)
        c = clouds[-1]
        assert [(f.name, f.offset, f.datatype, f.count) for f in c.fields] == \
            [tuple(x) for x in SEGMENT_FIELDS]
        assert c.point_step == 40 and c.height == 1 and not c.is_bigendian
        assert c.row_step == 40 * c.width and len(c.data) == c.row_step and c.width > 50
        # x y z: the ray through each segment's undistorted midpoint at unit depth
        segs, _, _, _ = parse_segments_msg(c)
        und = undistort_segments(segs.astype(np.float64), seq.camera)
        cam = seq.camera
        want = np.stack([(0.5 * (und[:, 0] + und[:, 2]) - cam.cx) / cam.fx,
                         (0.5 * (und[:, 1] + und[:, 3]) - cam.cy) / cam.fy,
                         np.ones(len(und))], axis=1)
        assert c.is_dense
        np.testing.assert_allclose(parse_segment_rays(c), want, rtol=1e-5, atol=1e-5)
        # twists: rad/s in the image frame, linear marked unknown
        tw = twists[0][-1]
        assert tw.header.frame_id == FRAME_ID and stamp_of(tw) == stamp_of(c)
        cov = np.asarray(tw.twist.covariance).reshape(6, 6)
        assert np.allclose(np.diag(cov)[:3], LINEAR_UNKNOWN_VARIANCE)
        assert np.all(np.isfinite(cov[3:, 3:])) and np.all(np.diag(cov)[3:] > 0)
        assert debug and debug[-1].encoding == 'bgr8' and debug[-1].width == 640
        # accuracy through DDS, scored like the pipeline test
        by_stamp = {i: {stamp_of(m): parse_twist_msg(m)[0] for m in twists[i]} for i in twists}
        results = []
        for cloud in clouds:
            segs, ids, labels, _ = parse_segments_msg(cloud)
            t = stamp_of(cloud)
            w = np.array([by_stamp[i].get(t, np.full(3, np.nan)) for i in range(3)])
            results.append(SimpleNamespace(segments=segs, labels=labels.astype(int),
                                           angular_velocities=w))
        ev = evaluate(results, seq, first_frame=4)
        print('node (in process), two boxes + wall, window full:',
              {k: round(v, 4) for k, v in ev.items()})
        assert ev['wrong'] <= GOAL_MISCLASSIFIED, ev
        assert ev['omega_error'] <= GOAL_OMEGA_ERROR, ev
        assert ev['unassigned'] < 0.15, ev
    finally:
        h.close(node)


@pytest.mark.slow
def test_in_process_slow_solver_tracks_every_frame_and_solves_the_newest(ros):
    """
    Track every frame with a solver slower than the camera (as method general is).

    The solver takes the newest window; the frames it had no time for are counted and
    answered from the running fit, the clouds' stamps increasing.
    """
    seq = two_box_sequence(24)
    node = MlofcNode(namespace='/slow', parameter_overrides=[
        Parameter('num_bodies', value=3), Parameter('queue_size', value=30)])
    pipe, observed = node._pipeline, []
    observe, solve = pipe.observe, pipe.solve

    def counting_observe(*args, **kwargs):
        obs = observe(*args, **kwargs)
        observed.append(obs.stamp)
        return obs

    solved_stamps = set()

    def slow_solve(obs):
        time.sleep(0.12)               # ~4 frame intervals at 30 Hz
        solved_stamps.add(round(obs.stamp, 6))
        return solve(obs)
    pipe.observe, pipe.solve = counting_observe, slow_solve
    h = Harness(node)
    try:
        clouds = h.collect(PointCloud2, '/slow/mlofc/segments')
        twists = {i: h.collect(TwistWithCovarianceStamped, f'/slow/mlofc/body_{i}/twist')
                  for i in range(3)}
        pub, cam_pub = h.camera_publishers('/slow')
        for img, t in zip(seq.frames, seq.stamps):
            cam_pub.publish(camera_info_msg(seq.camera, (640, 480), t))
            pub.publish(image_msg(img, t))
            time.sleep(1 / 30)
        assert h.wait(lambda: node.stats['received'] > 0 and node.pending_frames() == 0
                      and node.stats['processed'] > 0
                      and stamp_of(clouds[-1]) == round(observed[-1], 6), 30.0)
        time.sleep(0.2)
        s = dict(node.stats)
        print('slow solver, 24 frames at 30 Hz:', s)
        assert s['processed'] + s['dropped'] + s['skipped'] + s['errors'] == s['received']
        assert s['errors'] == 0 and s['skipped'] == 0
        # the tracker saw every frame that arrived; only the solver skipped some, answered
        # from the running fit once a solve had labelled their tracks
        assert len(observed) == s['received'] and s['dropped'] == s['unsolved'] > 0
        # carried: the unsolved frames and those still being solved when a newer one was
        # answered (their own cloud late)
        assert 0 < s['carried'] <= s['unsolved'] + s['late']
        stamps = [stamp_of(c) for c in clouds]
        assert stamps == sorted(set(stamps)) and stamps[-1] == round(observed[-1], 6)
        # NaN residuals: carried, or the first frame (no window to solve yet)
        carried = [c for c in clouds[1:] if np.all(np.isnan(parse_segments_msg(c)[3]))]
        assert len(carried) == s['carried']
        assert all(stamp_of(c) in solved_stamps for c in clouds if c not in carried)
        assert len(clouds) == s['processed'] - s['late'] + s['carried'] > s['carried']
        # every frame is answered once a solve labelled its tracks (the first few wait)
        assert len(clouds) >= s['received'] - 6, (len(clouds), s)
        # the solved frames are segmented as well as when every frame is solved
        index = {round(t, 6): i for i, t in enumerate(seq.stamps)}
        by_stamp = {i: {stamp_of(m): parse_twist_msg(m)[0] for m in twists[i]} for i in twists}
        solved_clouds = [c for c in clouds if c not in carried]
        solved = [index[stamp_of(c)] for c in solved_clouds]
        results = []
        for cloud in solved_clouds:
            segs, _, labels, _ = parse_segments_msg(cloud)
            w = np.array([by_stamp[i].get(stamp_of(cloud), np.full(3, np.nan))
                          for i in range(3)])
            results.append(SimpleNamespace(segments=segs, labels=labels.astype(int),
                                           angular_velocities=w))
        late = [k for k, f in enumerate(solved) if f >= 4]
        sub = SimpleNamespace(truth=[seq.truth[solved[k]] for k in late],
                              angular_velocities=seq.angular_velocities)
        ev = evaluate([results[k] for k in late], sub, first_frame=0)
        print('slow solver, solved frames', solved, {k: round(v, 4) for k, v in ev.items()})
        assert ev['wrong'] <= GOAL_MISCLASSIFIED, ev
        assert ev['omega_error'] <= GOAL_OMEGA_ERROR, ev
    finally:
        h.close(node)


def test_in_process_bad_input_queue_drops_and_parameter_changes(ros):
    seq = small_sequence()
    node = MlofcNode(namespace='/robust', parameter_overrides=[
        Parameter('queue_size', value=1), Parameter('warn_period', value=0.0)])
    h = Harness(node)
    try:
        clouds = h.collect(PointCloud2, '/robust/mlofc/segments')
        pub, cam_pub = h.camera_publishers('/robust')
        # a bad image: warned about and skipped, the node keeps going
        bad = image_msg(seq.frames[0], 0.0)
        bad.encoding = 'no_such_encoding'
        pub.publish(bad)
        assert h.wait(lambda: node.stats['skipped'] >= 1)
        # an uncalibrated camera_info (K all zero): ignored, the focal length is estimated
        zero = camera_info_msg(seq.camera, (320, 240))
        zero.k = [0.0] * 9
        cam_pub.publish(zero)
        send_frames(h, pub, seq.frames[:3], seq.stamps[:3], clouds)
        assert node.stats['processed'] == 3 and len(clouds) == 3
        # a burst: the queue (size 1) drops the stalest frames, the newest is always processed
        burst = [seq.stamps[3] + k / 30.0 for k in range(12)]
        for k, t in enumerate(burst):
            pub.publish(image_msg(seq.frames[3 + k % 5], t))
        assert h.wait(lambda: node.pending_frames() == 0 and stamp_of(clouds[-1]) ==
                      round(burst[-1], 6), 20.0)
        time.sleep(0.2)
        s = node.stats
        assert s['processed'] + s['dropped'] + s['skipped'] == s['received']
        assert len(clouds) == s['processed']
        assert len({stamp_of(c) for c in clouds}) == len(clouds)
        print('burst of 12 frames:', s)
        # run-time parameters through the parameter services
        ok = h.set_params('/robust/mlofc', num_bodies=3, window=4, min_segment_length=25,
                          detect_regions=True)
        assert all(r.successful for r in ok), [r.reason for r in ok]
        assert h.wait(lambda: '/robust/mlofc/body_2/twist' in h.topics())
        for name, value, word in (('window', 1, 'window'), ('method', 'nope', 'nope'),
                                  ('focal_length', 'x', 'double'), ('queue_size', 0, '1')):
            res = h.set_params('/robust/mlofc', **{name: value})[0]
            assert not res.successful and word in res.reason, res.reason
        assert h.get_params('/robust/mlofc', 'window', 'method', 'num_bodies',
                            'detect_regions') == [4, 'auto', 3, True]
        n = len(clouds)
        send_frames(h, pub, seq.frames[5:7], [10.0, 10.0 + 1 / 30], clouds)
        assert len(clouds) == n + 2
        assert node.count_publishers('/robust/mlofc/body_2/twist') == 1
    finally:
        h.close(node)


# --- the installed executable --------------------------------------------------------------


def interrupt(proc: subprocess.Popen, again_after: float = None, timeout: float = 30.0) -> str:
    """Stop ``proc`` with Ctrl-C (a second one ``again_after`` s later); return its output."""
    proc.send_signal(signal.SIGINT)
    if again_after is not None:
        time.sleep(again_after)
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def test_installed_executable_remapping_parameters_and_clean_shutdown(ros):
    env = dict(os.environ, HOME=os.environ.get('HOME', '/tmp'), PYTHONUNBUFFERED='1')
    proc = subprocess.Popen(
        [executable('mlofc_node'), '--ros-args', '--params-file', str(CONFIG),
         '-r', 'image:=/cam/image_raw', '-r', 'camera_info:=/cam/camera_info',
         '-p', 'num_bodies:=3', '-p', 'focal_length:=300', '-p', 'window:=3'],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    h = None
    try:
        h = Harness()
        clouds = h.collect(PointCloud2, '/mlofc/segments')
        pub = h.node.create_publisher(Image, '/cam/image_raw', qos_profile_sensor_data)
        # discovery reports the other process's endpoints one by one: wait for all of them
        twists = [f'/mlofc/body_{i}/twist' for i in range(3)]
        assert h.wait(lambda: pub.get_subscription_count() == 1
                      and h.node.count_publishers('/mlofc/segments') == 1
                      and h.node.count_subscribers('/cam/camera_info') == 1
                      and all(h.node.count_publishers(t) == 1 for t in twists), 30.0), \
            'node did not come up'
        topics = h.topics()
        assert '/mlofc/body_3/twist' not in topics and '/image' not in topics
        # -p focal_length:=300 (an integer) was accepted for the double, and stored as one
        got = h.get_params('/mlofc', 'focal_length', 'num_bodies', 'window', 'max_frame_gap')
        assert got == [300.0, 3, 3, 3.0] and type(got[0]) is float and type(got[3]) is float
        seq = small_sequence()
        send_frames(h, pub, seq.frames[:4], seq.stamps[:4], clouds)
        assert len(clouds) == 4
        assert clouds[-1].header.frame_id == FRAME_ID
        _, _, labels, _ = parse_segments_msg(clouds[-1])
        assert labels.max() >= 0
        res = h.set_params('/mlofc', window=1)[0]
        assert not res.successful and 'window' in res.reason
        # as `ros2 param set /mlofc focal_length 320` sends it: an integer, read back a double
        res = h.set_params('/mlofc', focal_length=320, num_bodies=2, warn_period=1)
        assert all(r.successful for r in res)
        got = h.get_params('/mlofc', 'window', 'focal_length', 'warn_period')
        assert got == [3, 320.0, 1.0] and type(got[1]) is float and type(got[2]) is float
        assert h.wait(lambda: '/mlofc/body_2/twist' not in h.topics())
        send_frames(h, pub, seq.frames[4:6], seq.stamps[4:6], clouds)
    finally:
        if h is not None:
            h.close()
        out = interrupt(proc)
    assert proc.returncode == 0, out
    assert 'Traceback' not in out, out


def test_installed_executable_refuses_invalid_parameters_with_the_reason():
    env = dict(os.environ, HOME=os.environ.get('HOME', '/tmp'))
    proc = subprocess.run([executable('mlofc_node'), '--ros-args', '-p', 'method:=magic'], env=env,
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 1
    out = proc.stdout + proc.stderr
    assert 'method' in out and 'magic' in out and 'robust' in out, out
    assert 'Traceback' not in out, out


@pytest.mark.slow
def test_a_second_ctrl_c_during_shutdown_leaves_no_traceback(ros):
    # a terminal's Ctrl-C signals the whole process group and ros2 launch forwards its own
    # SIGINT: the node gets two, the second while it waits for a busy solver to stop
    env = dict(os.environ, HOME=os.environ.get('HOME', '/tmp'))
    proc = subprocess.Popen(
        [executable('mlofc_node'), '--ros-args', '-r', 'image:=/cam/image_raw',
         '-p', 'method:=general', '-p', 'window:=5', '-p', 'focal_length:=300.0'],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    h = None
    try:
        h = Harness()
        pub = h.node.create_publisher(Image, '/cam/image_raw', qos_profile_sensor_data)
        assert h.wait(lambda: pub.get_subscription_count() == 1, 30.0), \
            'node did not come up: ' + (proc.stdout.read() if proc.poll() is not None else '')
        seq = small_sequence()
        for frame, t in zip(seq.frames[:8], seq.stamps[:8]):
            pub.publish(image_msg(frame, t))
            time.sleep(0.05)
        time.sleep(0.5)                     # the solver takes the first full window (seconds)
    finally:
        if h is not None:
            h.close()
        out = interrupt(proc, again_after=0.3)
    assert proc.returncode == 0, out
    assert 'Traceback' not in out and 'KeyboardInterrupt' not in out, out
    # the solver's child process ended with the node
    pid = int(re.search(r'solving in a child process \(pid (\d+)\)', out).group(1))
    assert not running(pid), out
