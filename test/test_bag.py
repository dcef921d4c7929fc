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
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

from dds import executable
from mlofc_ros.bag import BagError, BagReader, BagWriter, write_image_bag
from mlofc_ros.bag.bagfile import CAMERA_INFO_TYPE, deserialize, IMAGE_TYPE, message_class
from mlofc_ros.bag.offline import main as bag_main, parse_param
from mlofc_ros.camera import CameraModel
import numpy as np
import pytest

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
    assert "window must be 0 (the method's own) or in [2, 30]" in capsys.readouterr().err
    assert bag_main([str(tmp_path / 'in'), str(tmp_path / 'out'),
                     '--image-topic', '/camera/camera_info']) == 1
    assert 'not sensor_msgs/msg/Image' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


@pytest.mark.slow
def test_mlofc_bag_end_to_end(tmp_path):
    from mlofc_tools.render import render_sequence
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


def test_mlofc_play_remaps_and_topics_add_up():
    """``--remap`` and ``--topics`` given several times all count (as ros2 bag play's)."""
    from mlofc_ros.bag.player import _parser
    args = _parser().parse_args(['bag', '--remap', '/a:=/b', '--remap', '/c:=/d', '/e:=/f',
                                 '--topics', '/a', '--topics', '/c'])
    assert args.remap == ['/a:=/b', '/c:=/d', '/e:=/f'] and args.topics == ['/a', '/c']
    assert _parser().parse_args(['bag']).remap == []


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


# --- incomplete bags: what is recovered must be exactly what was written before the cut ---

def _write_mcap(path, n, compressed=False, shape=(120, 160)):
    """Write ``n`` images (and CameraInfo) as mcap; return the messages in write order."""
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    from mlofc_ros.bag.bagfile import camera_info_cdr, image_cdr, QOS_PROFILES, typestore
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    if compressed:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    written = []
    with writer:
        info = writer.add_connection('/camera/camera_info', CAMERA_INFO_TYPE,
                                     typestore=typestore(),
                                     offered_qos_profiles=[QOS_PROFILES['reliable']])
        image = writer.add_connection('/camera/image_raw', IMAGE_TYPE, typestore=typestore(),
                                      offered_qos_profiles=[QOS_PROFILES['sensor_data']])
        for frame, t in zip(_frames(n, shape), range(10**9, 10**9 + n * 33_000_000, 33_000_000)):
            for conn, raw in ((info, camera_info_cdr(CAMERA, shape[1], shape[0], t)),
                              (image, image_cdr(frame, t))):
                writer.write(conn, t, raw)
                written.append((conn.topic, t, raw))
    return written


def _chunks(mcap):
    """``(end byte, messages)`` of each chunk record, from the intact file's own index."""
    from rosbags.rosbag2.storage_mcap import McapReader
    reader = McapReader(mcap)
    reader.open()
    try:
        return [(c.chunk_start_offset + c.chunk_length, sum(c.channel_count.values()))
                for c in reader.chunks]
    finally:
        reader.close()


def _cut(src, dst_dir, n_bytes, keep_metadata=False):
    dst_dir.mkdir()
    (dst_dir / src.name).write_bytes(src.read_bytes()[:n_bytes])
    if keep_metadata:
        (dst_dir / 'metadata.yaml').write_bytes((src.parent / 'metadata.yaml').read_bytes())
    return dst_dir


def _read_all(path, **kw):
    with BagReader(path, **kw) as bag:
        info = SimpleNamespace(incomplete=bag.incomplete, problems=bag.problems,
                               message_counts=bag.message_counts, start_ns=bag.start_ns)
        return info, [(m.topic, m.timestamp_ns, m.rawdata) for m in bag.messages()]


@pytest.mark.parametrize('compressed', [False, True], ids=['plain', 'zstd'])
@pytest.mark.parametrize('where', ['inside_chunk', 'between_chunks', 'sixty_percent',
                                   'last_byte', 'inside_header'])
def test_truncated_mcap_recovers_every_complete_chunk(tmp_path, compressed, where):
    written = _write_mcap(tmp_path / 'full', 120, compressed)
    mcap = tmp_path / 'full' / 'full.mcap'
    size = mcap.stat().st_size
    chunks = _chunks(mcap)
    assert len(chunks) >= 3        # the cut points below need several chunks
    cut = {'inside_chunk': chunks[1][0] - 1000, 'between_chunks': chunks[0][0],
           'sixty_percent': int(0.6 * size), 'last_byte': size - 1, 'inside_header': 20}[where]
    bag_dir = _cut(mcap, tmp_path / 'cut', cut, keep_metadata=where == 'last_byte')
    expected = sum(count for end, count in chunks if end <= cut)
    if expected == 0:
        with pytest.raises(BagError, match='no complete message') as err:
            BagReader(bag_dir).open()
        assert str(bag_dir) in str(err.value) and '\n' not in str(err.value)
        return
    bag, got = _read_all(bag_dir)
    assert bag.incomplete and bag.problems
    assert got == written[:expected]               # byte-identical, in order, nothing more
    assert sum(bag.message_counts.values()) == expected
    assert bag.start_ns == written[0][1]
    with pytest.raises(BagError, match='incomplete bag.*without --strict'):
        BagReader(bag_dir, strict=True).open()


def test_mcap_without_metadata_or_footer_but_whole(tmp_path):
    """A recorder killed after its last chunk: every message is there, the bag says so."""
    written = _write_mcap(tmp_path / 'full', 10)
    (tmp_path / 'full' / 'metadata.yaml').unlink()
    bag, got = _read_all(tmp_path / 'full')
    assert got == written and bag.incomplete
    assert any('metadata.yaml' in p for p in bag.problems)


def _sqlite_bag(tmp_path, n=60):
    write_image_bag(tmp_path / 'full', _frames(n, (120, 160)), [1.0 + i / 30 for i in range(n)],
                    CAMERA, storage='sqlite3')
    _, written = _read_all(tmp_path / 'full')
    return tmp_path / 'full' / 'full.db3', written


@pytest.mark.parametrize('fraction', [0.3, 0.6, 0.95])
@pytest.mark.parametrize('metadata', [True, False], ids=['metadata', 'no_metadata'])
def test_truncated_sqlite3_recovers_the_rows_on_disk(tmp_path, fraction, metadata):
    db3, written = _sqlite_bag(tmp_path)
    bag_dir = _cut(db3, tmp_path / 'cut', int(fraction * db3.stat().st_size), metadata)
    bag, got = _read_all(bag_dir)
    assert bag.incomplete and any('cut short' in p for p in bag.problems)
    # rows are stored in insertion order: what is left is a prefix of what was written
    assert 0.5 * fraction * len(written) < len(got) < len(written)
    assert got == written[:len(got)]


def test_sqlite3_without_metadata_reads_every_row(tmp_path, capsys):
    db3, written = _sqlite_bag(tmp_path, 6)
    (db3.parent / 'metadata.yaml').unlink()
    bag, got = _read_all(db3.parent)
    assert got == written and bag.problems == ['no metadata.yaml (the recording was not closed)']
    with pytest.raises(BagError, match='no metadata.yaml'):
        BagReader(db3.parent, strict=True).open()


def test_sqlite3_unflushed_messages_are_dropped(tmp_path):
    """A writer that dies mid-transaction leaves a hot journal: only committed rows count."""
    db3, written = _sqlite_bag(tmp_path, 20)
    bag_dir = tmp_path / 'killed'
    bag_dir.mkdir()
    shutil.copyfile(db3, bag_dir / db3.name)
    # uncommitted rows spill into the database file itself (tiny cache), then the process dies
    code = ('import os, sqlite3, sys\n'
            'c = sqlite3.connect(sys.argv[1])\n'
            'c.execute("PRAGMA cache_size = 1")\n'
            'for i in range(100):\n'
            '    c.execute("INSERT INTO messages (topic_id, timestamp, data) VALUES (1, ?, ?)",\n'
            '              (10**12 + i, os.urandom(20000)))\n'
            'os._exit(0)\n')
    subprocess.run([sys.executable, '-c', code, str(bag_dir / db3.name)], check=True)
    assert (bag_dir / (db3.name + '-journal')).exists()
    bag, got = _read_all(bag_dir)
    assert got == written and bag.incomplete
    assert any('journal' in p for p in bag.problems)
    assert sorted(p.name for p in bag_dir.iterdir()) == [db3.name, db3.name + '-journal']


def test_bag_path_errors_say_what_is_wrong(tmp_path, capsys):
    empty = tmp_path / 'empty'
    empty.mkdir()
    with pytest.raises(BagError, match=f'{empty}: empty folder; expected a rosbag2 bag'):
        BagReader(empty).open()
    other = tmp_path / 'photos'
    other.mkdir()
    (other / 'a.png').write_bytes(b'')
    with pytest.raises(BagError, match=f'{other}: not a bag: no metadata.yaml and no .mcap'):
        BagReader(other).open()
    text = tmp_path / 'notes.txt'
    text.write_text('hello')
    with pytest.raises(BagError, match=r"not a bag file \(suffix '.txt'\); expected"):
        BagReader(text).open()
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'definitely not mcap')
    with pytest.raises(BagError, match=f'{junk}: cannot read bag: junk.mcap: not an mcap file'):
        BagReader(junk).open()
    junk_db = tmp_path / 'junk.db3'
    junk_db.write_bytes(b'x' * 4096)
    with pytest.raises(BagError, match='not a readable sqlite3 database'):
        BagReader(junk_db).open()
    no_files = tmp_path / 'no_files'
    no_files.mkdir()
    (no_files / 'metadata.yaml').write_text('rosbag2_bagfile_information: {}')
    with pytest.raises(BagError, match='storage files are missing'):
        BagReader(no_files).open()
    # the command line gives the same one line, no traceback
    assert bag_main([str(empty), str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'empty folder' in err and 'Traceback' not in err


@pytest.mark.skipif(hasattr(os, 'geteuid') and os.geteuid() == 0,
                    reason='root reads files whatever their mode')
def test_unreadable_bag_file(tmp_path):
    _write_mcap(tmp_path / 'bag', 2)
    mcap = tmp_path / 'bag' / 'bag.mcap'
    mcap.chmod(0)
    with pytest.raises(BagError, match=str(tmp_path / 'bag')):
        BagReader(tmp_path / 'bag').open()


def test_writer_never_leaves_a_half_written_bag(tmp_path):
    out = tmp_path / 'out'
    with BagWriter(out) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.write('/chatter', 1, b'\x00\x01\x00\x00\x02\x00\x00\x00a\x00')
        assert not out.exists()                       # written elsewhere until complete
    assert (out / 'metadata.yaml').is_file() and (out / 'out.mcap').is_file()
    with BagWriter(out, overwrite=True) as bag:
        bag.add_topic('/other', 'std_msgs/msg/String')
        assert (out / 'metadata.yaml').is_file()      # the old bag stays until replaced
    with BagReader(out) as bag:
        assert bag.topics == {'/other': 'std_msgs/msg/String'}
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out']   # no temporary left


def test_mlofc_bag_processes_a_cut_recording(tmp_path, capsys):
    from mlofc_tools.render import render_sequence
    seq = render_sequence(n_boxes=1, n_frames=36, size=(320, 240), seed=3)
    write_image_bag(tmp_path / 'rec', seq.frames, seq.stamps, seq.camera)
    mcap = tmp_path / 'rec' / 'rec.mcap'
    chunks = _chunks(mcap)
    cut = _cut(mcap, tmp_path / 'cut', int(0.6 * mcap.stat().st_size))
    recovered = sum(count for end, count in chunks if end <= int(0.6 * mcap.stat().st_size))
    assert recovered > 0
    assert bag_main([str(cut), str(tmp_path / 'strict'), '--strict', '-q']) == 1
    err = capsys.readouterr().err
    assert 'incomplete bag' in err and not (tmp_path / 'strict').exists()
    assert bag_main([str(cut), str(tmp_path / 'out'), '-q']) == 0
    err = capsys.readouterr().err
    assert f'warning: {cut}: incomplete bag' in err
    assert f'recovered {recovered} complete messages ({recovered // 2} images)' in err
    with BagReader(tmp_path / 'out') as bag:
        counts = bag.message_counts
        assert not bag.incomplete
    assert counts['/camera/image_raw'] == counts['/mlofc/segments'] == recovered // 2


@pytest.mark.slow
def test_interrupted_mlofc_bag_keeps_a_finished_bag(tmp_path):
    from mlofc_tools.render import render_sequence
    seq = render_sequence(n_boxes=1, n_frames=200, size=(320, 240), seed=3)
    write_image_bag(tmp_path / 'in', seq.frames, seq.stamps, seq.camera)
    proc = subprocess.Popen([executable('mlofc_bag'), str(tmp_path / 'in'), str(tmp_path / 'out')],
                            stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stderr.readline()          # the bar's first 10 % line (not a tty)
        assert '/200' in first, first
        proc.send_signal(signal.SIGINT)
        err = first + proc.communicate(timeout=120)[1]
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert 'kept in' in err and 'Traceback' not in err
    kept = int(err.split('interrupted; the ')[1].split()[0])
    assert 0 < kept < 200
    with BagReader(tmp_path / 'out') as bag:
        assert not bag.incomplete
        images = [m.timestamp_ns for m in bag.messages(['/camera/image_raw'])]
        segments = [m.timestamp_ns for m in bag.messages(['/mlofc/segments'])]
    with BagReader(tmp_path / 'in') as bag:
        written = [m.timestamp_ns for m in bag.messages(['/camera/image_raw'])]
    assert images == written[:len(images)] and segments == images[-len(segments):]
    assert len(segments) == kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in', 'out']


@pytest.mark.ros
def test_mlofc_play_stops_cleanly_on_ctrl_c(tmp_path):
    write_image_bag(tmp_path / 'bag', _frames(60), [i / 30 for i in range(60)], CAMERA)
    rng = np.random.default_rng(7)
    for _ in range(4):
        # --rate 0 --loop: publishing all the time, so the signal lands inside a publish
        proc = subprocess.Popen([executable('mlofc_play'), str(tmp_path / 'bag'), '--rate', '0',
                                 '--loop'], stderr=subprocess.PIPE, text=True)
        try:
            started = proc.stderr.readline()
            assert 'playing' in started, started
            time.sleep(rng.uniform(0.05, 0.5))
            proc.send_signal(signal.SIGINT)
            err = started + proc.communicate(timeout=30)[1]
        finally:
            proc.kill()
        assert proc.returncode == 0, err
        assert 'Traceback' not in err and 'Error' not in err
        assert 'stopped; published' in err
