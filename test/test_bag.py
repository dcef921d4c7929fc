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

"""Bag tools: rosbag2 round trips (mcap, sqlite3), ``mlofc_bag`` end to end, ``mlofc_play``."""
import subprocess
import threading
import time

from dds import executable
import numpy as np
import pytest

from mlofc_ros.bag import BagError, BagReader, BagWriter, write_image_bag
from mlofc_ros.bag.bagfile import CAMERA_INFO_TYPE, deserialize, IMAGE_TYPE, message_class
from mlofc_ros.bag.offline import main as bag_main, parse_param
from mlofc_ros.camera import CameraModel

# the bag tools are the ROS shell (rosbags, message classes): not for a run without ROS
pytestmark = pytest.mark.ros

CAMERA = CameraModel(60.0, 61.0, 31.5, 23.5, (0.01, -0.002, 0.0, 0.0, 0.0), 'plumb_bob')


def _frames(n, shape=(48, 64)):
    rng = np.random.default_rng(1)
    return [rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(n)]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_image_bag_round_trip(tmp_path, storage):
    frames = _frames(4)
    stamps = [1.0 + i / 30.0 for i in range(4)]
    path = write_image_bag(tmp_path / 'bag', frames, stamps, CAMERA, frame_id='cam',
                           storage=storage)
    assert (path / 'metadata.yaml').is_file()
    with BagReader(path) as bag:
        assert bag.storage == storage
        assert bag.topics == {'/camera/image_raw': IMAGE_TYPE,
                              '/camera/camera_info': CAMERA_INFO_TYPE}
        assert bag.message_counts == {'/camera/image_raw': 4, '/camera/camera_info': 4}
        msgs = list(bag.messages())
    # each CameraInfo comes before its image, record time = header stamp
    assert [m.topic for m in msgs] == ['/camera/camera_info', '/camera/image_raw'] * 4
    images = [m for m in msgs if m.topic == '/camera/image_raw']
    for i, m in enumerate(images):
        img = deserialize(m.rawdata, m.msgtype)
        assert (img.height, img.width, img.encoding, img.step) == (48, 64, 'mono8', 64)
        assert img.header.frame_id == 'cam'
        assert img.header.stamp.sec * 10**9 + img.header.stamp.nanosec == m.timestamp_ns
        assert m.timestamp_ns == round(stamps[i] * 1e9)
        np.testing.assert_array_equal(np.frombuffer(bytes(img.data), np.uint8).reshape(48, 64),
                                      frames[i])
    info = deserialize(msgs[0].rawdata, CAMERA_INFO_TYPE)
    assert list(info.k) == [60.0, 0.0, 31.5, 0.0, 61.0, 23.5, 0.0, 0.0, 1.0]
    assert list(info.d) == list(CAMERA.d) and info.distortion_model == 'plumb_bob'
    assert (info.width, info.height) == (64, 48)


def test_writer_takes_rclpy_messages_and_cleans_up_on_error(tmp_path):
    from std_msgs.msg import String
    with BagWriter(tmp_path / 'ok', storage='sqlite3') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.write('/chatter', 5, String(data='hello'))
    with BagReader(tmp_path / 'ok') as bag:
        (msg,) = bag.messages()
    assert deserialize(msg.rawdata, msg.msgtype).data == 'hello'

    with pytest.raises(RuntimeError):
        with BagWriter(tmp_path / 'broken') as bag:
            bag.add_topic('/chatter', 'std_msgs/msg/String')
            raise RuntimeError('boom')
    assert not (tmp_path / 'broken').exists()   # nothing half-written is left behind

    with pytest.raises(BagError, match='exists already'):
        BagWriter(tmp_path / 'ok').open()
    with pytest.raises(BagError, match='not added'):
        with BagWriter(tmp_path / 'other') as bag:
            bag.write('/nope', 0, b'')


def test_reader_errors_name_the_path(tmp_path):
    with pytest.raises(BagError, match='no such bag'):
        BagReader(tmp_path / 'missing').open()
    junk = tmp_path / 'junk'
    junk.mkdir()
    (junk / 'metadata.yaml').write_text('not: [a bag')
    with pytest.raises(BagError, match=str(junk)):
        BagReader(junk).open()
    with pytest.raises(BagError, match='not installed'):
        message_class('no_such_pkg/msg/Thing')


def test_parse_param():
    assert parse_param('num_bodies:=3') == ('num_bodies', 3)
    assert parse_param('focal_length:=500.5') == ('focal_length', 500.5)
    assert parse_param('publish_debug_image:=true') == ('publish_debug_image', True)
    assert parse_param('method:=robust') == ('method', 'robust')
    with pytest.raises(ValueError):
        parse_param('window=3')


def test_mlofc_bag_user_errors_exit_cleanly(tmp_path, capsys):
    assert bag_main([str(tmp_path / 'missing'), str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err
    assert 'no such bag' in err and 'Traceback' not in err

    with BagWriter(tmp_path / 'no_images') as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
    assert bag_main([str(tmp_path / 'no_images'), str(tmp_path / 'out')]) == 1
    assert '0 sensor_msgs/msg/Image topics' in capsys.readouterr().err

    write_image_bag(tmp_path / 'in', _frames(2), [0.0, 0.1], CAMERA)
    assert bag_main([str(tmp_path / 'in'), str(tmp_path / 'out'), '-p', 'window:=1']) == 2
    assert 'window must be in' in capsys.readouterr().err
    assert bag_main([str(tmp_path / 'in'), str(tmp_path / 'out'),
                     '--image-topic', '/camera/camera_info']) == 1
    assert 'not sensor_msgs/msg/Image' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


@pytest.mark.slow
def test_mlofc_bag_end_to_end(tmp_path):
    from mlofc_ros.render import render_sequence
    from mlofc_ros.ros_messages import parse_segments_msg, parse_twist_msg

    seq = render_sequence(n_boxes=1, n_frames=8, size=(320, 240), seed=3)
    write_image_bag(tmp_path / 'in', seq.frames, seq.stamps, seq.camera, storage='sqlite3')
    proc = subprocess.run(
        [executable('mlofc_bag'), str(tmp_path / 'in'), str(tmp_path / 'out'),
         '-p', 'num_bodies:=2', '--debug-image'],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert '8/8 images processed' in proc.stderr
    with BagReader(tmp_path / 'out') as bag:
        assert bag.storage == 'mcap'
        topics, counts = bag.topics, bag.message_counts
        msgs = list(bag.messages())
    assert topics['/mlofc/segments'] == 'sensor_msgs/msg/PointCloud2'
    assert topics['/mlofc/body_0/twist'] == 'geometry_msgs/msg/TwistWithCovarianceStamped'
    assert topics['/mlofc/debug_image'] == IMAGE_TYPE
    assert counts['/camera/image_raw'] == counts['/mlofc/segments'] == 8
    assert counts['/camera/camera_info'] == counts['/mlofc/debug_image'] == 8
    assert counts['/mlofc/body_0/twist'] >= 5 and counts['/mlofc/body_1/twist'] >= 5
    image_times = [m.timestamp_ns for m in msgs if m.topic == '/camera/image_raw']
    seg_msgs = [m for m in msgs if m.topic == '/mlofc/segments']
    assert [m.timestamp_ns for m in seg_msgs] == image_times   # aligned with the input
    last = seg_msgs[-1]
    segs, _, labels, _ = parse_segments_msg(deserialize(last.rawdata, last.msgtype))
    assert len(segs) > 10 and np.any(labels >= 0)
    twist = next(m for m in msgs if m.topic == '/mlofc/body_0/twist')
    omega, cov = parse_twist_msg(deserialize(twist.rawdata, twist.msgtype))
    assert np.all(np.isfinite(omega)) and np.all(np.isfinite(np.diag(cov)))


@pytest.mark.ros
def test_player_delivers_every_message(tmp_path):
    """``mlofc_play`` in its own process; a subscriber here must get every message over DDS."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import CameraInfo, Image

    n = 12
    frames = _frames(n)
    stamps = [2.0 + i / 30.0 for i in range(n)]
    write_image_bag(tmp_path / 'bag', frames, stamps, CAMERA)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('test_player_sub', context=ctx)
    got = {'image': [], 'info': []}
    # reliable on both ends: best effort (the default for images) may drop a frame on a loaded
    # machine, and this test is about the player sending every message
    node.create_subscription(Image, '/cam/image', lambda m: got['image'].append(
        (m.header.stamp.sec, m.header.stamp.nanosec, bytes(m.data))), 50)
    node.create_subscription(CameraInfo, '/camera/camera_info',
                             lambda m: got['info'].append(m.k[0]), 10)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        proc = subprocess.run(
            [executable('mlofc_play'), str(tmp_path / 'bag'), '--rate', '2',
             '--remap', '/camera/image_raw:=/cam/image', '--wait-for-subscribers', '20',
             '--reliable'],
            capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert f'published {2 * n} messages' in proc.stderr
        deadline = time.monotonic() + 5.0
        while (len(got['image']) < n or len(got['info']) < n) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        executor.shutdown()
        spinner.join(timeout=5.0)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert len(got['info']) == n and got['info'][0] == 60.0
    assert [(s, ns) for s, ns, _ in got['image']] == [
        (int(t), round(t * 1e9) % 10**9) for t in stamps]
    assert [d for _, _, d in got['image']] == [f.tobytes() for f in frames]


def test_mlofc_play_user_errors(tmp_path, capsys):
    from mlofc_ros.bag.player import main as play_main
    assert play_main([str(tmp_path / 'missing')]) == 1
    err = capsys.readouterr().err
    assert 'no such bag' in err and 'Traceback' not in err
    write_image_bag(tmp_path / 'bag', _frames(1), [0.0], CAMERA)
    assert play_main([str(tmp_path / 'bag'), '--topics', '/nope']) == 1
    assert 'no topic(s) /nope' in capsys.readouterr().err
    assert play_main([str(tmp_path / 'bag'), '--rate', '-1']) == 2


def test_camera_info_pairing():
    from sensor_msgs.msg import CameraInfo

    from mlofc_ros.bag.offline import CameraInfoPairing
    info = CameraInfo(width=64, height=48, distortion_model='plumb_bob',
                      k=[60.0, 0.0, 31.5, 0.0, 61.0, 23.5, 0.0, 0.0, 1.0], d=[0.0] * 5)
    first = CameraInfoPairing()
    first.add_info(info)
    pairing = CameraInfoPairing(first.latest)          # images before any CameraInfo
    camera, problem = pairing.camera((64, 48))
    assert camera is not None and camera.fx == 60.0 and problem is None
    camera, problem = pairing.camera((32, 24))          # wrong size: not used, as the node does
    assert camera is None and '64x48' in problem
    pairing.add_info(CameraInfo())                      # all-zero K: remembered as a problem
    assert 'invalid CameraInfo' in pairing.problem
    assert CameraInfoPairing().camera((64, 48)) == (None, None)
