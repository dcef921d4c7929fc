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
"""
Run ``mlofc_node`` for the demo: a separate process, fed a bag in lock-step, outputs collected.

The node runs on its own ``ROS_DOMAIN_ID`` with localhost discovery; this process plays the bag
with :mod:`mlofc_ros.bag.player` and waits for the node's answer to every frame.
"""
from dataclasses import dataclass, field
import math
import os
from pathlib import Path
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np


#: Node name of the demo (its outputs are ``/<NODE_NAME>/...``).
NODE_NAME = 'mlofc'


IMAGE_TOPIC = '/camera/image_raw'


INFO_TOPIC = '/camera/camera_info'


class DemoError(Exception):
    """The demo cannot go on; the message says why (printed without a traceback)."""


@dataclass
class DemoConfig:
    """What to render and how to run the node."""

    frames: int = 60
    boxes: int = 2
    size: Tuple[int, int] = (640, 480)
    fps: float = 30.0
    noise: float = 2.0
    seed: int = 0
    motion: str = 'camera_centre'
    method: Optional[str] = None
    window: Optional[int] = None
    frame_timeout: float = 30.0
    startup_timeout: float = 60.0
    domain_id: Optional[int] = None

    @property
    def num_bodies(self) -> int:
        """Bodies the node is asked for: the boxes plus the static background."""
        return self.boxes + 1


@dataclass
class FrameOutput:
    """One ``~/segments`` message: (M, 4) px, track ids, labels (-1 unassigned), residuals."""

    segments: np.ndarray
    track_ids: np.ndarray
    labels: np.ndarray
    residuals: np.ndarray
    latency: float = math.nan


@dataclass
class Collected:
    """What the node published, by frame index; twists as ``twists[body][frame]``."""

    frames: Dict[int, FrameOutput] = field(default_factory=dict)
    twists: Dict[int, Dict[int, Tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)
    wall_time: float = 0.0
    dropped: List[int] = field(default_factory=list)
    node_command: List[str] = field(default_factory=list)
    domain_id: int = 0


def node_command() -> List[str]:
    """
    Return the command that starts ``mlofc_node``, found as ``ros2 run`` finds it.

    ``lib/mlofc_ros/mlofc_node`` under the package's prefix in the ament index (a colcon
    workspace), then the console script beside this Python (a pip install), then ``PATH``.
    """
    candidates = [Path(sys.executable).parent / 'mlofc_node']
    try:
        from ament_index_python.packages import get_package_prefix, PackageNotFoundError
        try:
            candidates.insert(0, Path(get_package_prefix('mlofc_ros')) / 'lib' / 'mlofc_ros'
                              / 'mlofc_node')
        except (PackageNotFoundError, OSError):   # not in the index
            pass
    except ImportError:                            # no ROS on this Python
        pass
    for cand in candidates:
        if cand.is_file() and os.access(cand, os.X_OK):
            return [str(cand)]
    found = shutil.which('mlofc_node')
    if found:
        return [found]
    # not installed as a script (e.g. running from a plain checkout): same code, same process
    return [sys.executable, '-m', 'mlofc_ros.node']


def fresh_domain_id() -> int:
    """Return the ROS_DOMAIN_ID set in the environment, else a random one in 1..100."""
    current = os.environ.get('ROS_DOMAIN_ID', '').strip()
    if current.isdigit():
        return int(current)
    return random.SystemRandom().randint(1, 100)


class NodeProcess:
    """``mlofc_node`` in its own process (context manager); stopped with SIGINT, then harder."""

    def __init__(self, command: Sequence[str], env: Dict[str, str], log_path: Path) -> None:
        self.command = list(command)
        self.env = env
        self.log_path = log_path
        self.proc: Optional[subprocess.Popen] = None
        self._log = None

    def __enter__(self) -> 'NodeProcess':
        self._log = open(self.log_path, 'wb')
        try:
            self.proc = subprocess.Popen(self.command, env=self.env, stdout=self._log,
                                         stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        except OSError as exc:
            self._log.close()
            raise DemoError(f'cannot start the node ({" ".join(self.command)}): {exc}') from None
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    def alive(self) -> bool:
        """Return True while the process runs."""
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> None:
        """SIGINT (clean rclpy shutdown), then SIGTERM, then SIGKILL; closes the log."""
        proc = self.proc
        if proc is not None and proc.poll() is None:
            for sig, wait in ((signal.SIGINT, 10.0), (signal.SIGTERM, 5.0),
                              (signal.SIGKILL, 5.0)):
                proc.send_signal(sig)
                try:
                    proc.wait(timeout=wait)
                    break
                except subprocess.TimeoutExpired:
                    continue
        if self._log is not None:
            self._log.close()
            self._log = None

    def log_tail(self, lines: int = 15) -> str:
        """Return the last lines of the node's output."""
        try:
            text = self.log_path.read_text(errors='replace').splitlines()
        except OSError:
            return ''
        return '\n'.join(text[-lines:])


def run_node(bag_path: Path, cfg: DemoConfig, workdir: Path,
             log: Any = sys.stdout) -> Collected:
    """Start the node, play ``bag_path`` into it in lock-step, collect its outputs."""
    domain = cfg.domain_id if cfg.domain_id is not None else fresh_domain_id()
    overrides = {'ROS_DOMAIN_ID': str(domain),
                 'ROS_AUTOMATIC_DISCOVERY_RANGE': os.environ.get(
                     'ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST'),
                 'HOME': os.environ.get('HOME', tempfile.gettempdir())}
    saved = {k: os.environ.get(k) for k in overrides}
    os.environ.update(overrides)   # this process's rmw reads them too; restored on return
    try:
        return _run_node(bag_path, cfg, workdir, domain, log)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _node_command_line(cfg: DemoConfig) -> List[str]:
    """Return the node's command line: remappings and the parameters ``cfg`` sets."""
    from mlofc_ros import params as P
    from mlofc_ros.method_choice import AUTO
    from mlofc_ros.solver import get_method
    params: Dict[str, Any] = {'num_bodies': cfg.num_bodies}
    if cfg.method:
        params['method'] = cfg.method
    if cfg.window:
        params['window'] = cfg.window
    method = cfg.method or P.defaults()['method']
    if method == AUTO or get_method(method).slow:
        # fed in lock-step, every frame can be solved in turn: in a child process a slow
        # method's search runs beside the frames, which are answered from the running fit
        # until it is back (a demo clip is over by then); 'auto' may move to one
        params['solver_process'] = 'false'
    command = node_command() + ['--ros-args', '-r', f'__node:={NODE_NAME}',
                                '-r', f'image:={IMAGE_TOPIC}', '-r', f'camera_info:={INFO_TOPIC}']
    for k, v in params.items():
        command += ['-p', f'{k}:={v}']
    return command


def _subscribe(node: Any, num_bodies: int, frame_of: Dict[Tuple[int, int], int],
               collected: Collected, sent_at: Dict[int, float]) -> str:
    """Collect the node's segments and twists into ``collected``; return the segments topic."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from geometry_msgs.msg import TwistWithCovarianceStamped
    from sensor_msgs.msg import PointCloud2

    from mlofc_ros.ros_messages import parse_segments_msg, parse_twist_msg

    qos = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)

    def on_segments(msg: PointCloud2) -> None:
        f = frame_of.get((msg.header.stamp.sec, msg.header.stamp.nanosec))
        if f is None:
            return
        segs, ids, labels, res = parse_segments_msg(msg)
        collected.frames[f] = FrameOutput(
            np.asarray(segs, np.float64).reshape(-1, 4), np.asarray(ids),
            np.asarray(labels, np.int64), np.asarray(res, np.float64),
            time.monotonic() - sent_at.get(f, math.nan))

    def on_twist(body: int, msg: TwistWithCovarianceStamped) -> None:
        f = frame_of.get((msg.header.stamp.sec, msg.header.stamp.nanosec))
        if f is not None:
            collected.twists.setdefault(body, {})[f] = parse_twist_msg(msg)

    seg_topic = f'/{NODE_NAME}/segments'
    node.create_subscription(PointCloud2, seg_topic, on_segments, qos)
    for i in range(num_bodies):
        node.create_subscription(TwistWithCovarianceStamped, f'/{NODE_NAME}/body_{i}/twist',
                                 lambda m, i=i: on_twist(i, m), qos)
    return seg_topic


def _run_node(bag_path: Path, cfg: DemoConfig, workdir: Path, domain: int,
              log: Any) -> Collected:
    """Run the node on ``domain`` and play ``bag_path`` into it (see :func:`run_node`)."""
    env = dict(os.environ, PYTHONUNBUFFERED='1')

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from mlofc_ros.bag.bagfile import BagReader, deserialize
    from mlofc_ros.bag.player import Player

    with BagReader(bag_path) as bag:
        stamps = [deserialize(m.rawdata, m.msgtype).header.stamp
                  for m in bag.messages([IMAGE_TOPIC])]
    frame_of = {(s.sec, s.nanosec): i for i, s in enumerate(stamps)}
    command = _node_command_line(cfg)
    collected = Collected(node_command=command, domain_id=domain)
    sent_at: Dict[int, float] = {}

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('mlofc_demo', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    seg_topic = _subscribe(node, cfg.num_bodies, frame_of, collected, sent_at)

    def spin_for(seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            executor.spin_once(timeout_sec=min(left, 0.05))

    try:
        with NodeProcess(command, env, workdir / 'node.log') as proc:
            def fail(why: str) -> None:
                tail = proc.log_tail()
                raise DemoError(why + (f'\n--- node output ({proc.log_path}) ---\n{tail}'
                                       if tail else ''))

            log.write(f'starting the node: {" ".join(command)}  (ROS_DOMAIN_ID={domain})\n')
            player = Player(node, str(bag_path), topics=[IMAGE_TOPIC, INFO_TOPIC])
            t0 = time.monotonic()
            while not (player.wait_for_subscribers(0.0)
                       and node.count_publishers(seg_topic) > 0):
                if not proc.alive():
                    fail(f'the node exited with code {proc.proc.returncode} before it '
                         'subscribed to the camera')
                if time.monotonic() - t0 > cfg.startup_timeout:
                    fail(f'the node did not come up on ROS_DOMAIN_ID={domain} within '
                         f'{cfg.startup_timeout:g} s (no subscriber on {IMAGE_TOPIC})')
                spin_for(0.1)
            log.write(f'node up after {time.monotonic() - t0:.1f} s; playing '
                      f'{len(stamps)} frames in lock-step\n')
            # prime the node with the calibration so the first image already has it
            with BagReader(bag_path) as bag:
                first_info = next(bag.messages([INFO_TOPIC]), None)
            if first_info is not None:
                for _ in range(3):
                    player.publishers[INFO_TOPIC].publish(first_info.rawdata)
                    spin_for(0.05)

            state = {'misses': 0}

            def after_publish(msg: Any) -> None:
                if msg.topic != IMAGE_TOPIC:
                    return
                f = len(sent_at)
                sent_at[f] = time.monotonic()
                deadline = time.monotonic() + cfg.frame_timeout
                while f not in collected.frames:
                    if not proc.alive():
                        fail(f'the node exited with code {proc.proc.returncode} at frame {f}')
                    if time.monotonic() > deadline:
                        if not collected.frames:
                            fail(f'the node did not answer the first frame within '
                                 f'{cfg.frame_timeout:g} s (no {seg_topic})')
                        state['misses'] += 1
                        collected.dropped.append(f)
                        if state['misses'] >= 3:
                            fail(f'the node stopped answering (frames {collected.dropped} '
                                 'got no segments)')
                        return
                    executor.spin_once(timeout_sec=0.05)
                state['misses'] = 0
                if f % 10 == 9 or f == len(stamps) - 1:
                    log.write(f'  frame {f + 1}/{len(stamps)}: '
                              f'{len(collected.frames[f].segments)} segments, '
                              f'{collected.frames[f].latency * 1e3:.0f} ms\n')
                    log.flush()

            t_play = time.monotonic()
            player.play(rate=0.0, after_publish=after_publish, sleep=spin_for)
            collected.wall_time = time.monotonic() - t_play
            spin_for(0.5)          # twists of the last frame follow its segments
            player.destroy()
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return collected
