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
``mlofc_play``: a small ``ros2 bag play`` stand-in for machines without rosbag2.

Publishes the recorded CDR bytes unchanged (``Publisher.publish`` takes serialised bytes) at the
recorded pace times ``rate`` (0 = as fast as possible). Image topics get sensor-data QoS (best
effort, as camera drivers publish), everything else reliable QoS. As a library::

    stats = play('my_bag', rate=2.0, wait_for_subscribers=5.0)
    stats.published            # {'/camera/image_raw': 60, '/camera/camera_info': 60}
"""
import argparse
from dataclasses import dataclass, field
import signal
import sys
import time
from types import FrameType
from typing import Any, Callable, Dict, List, Optional, Sequence

from mlofc_ros.bag.bagfile import BagError, BagMessage, BagReader, IMAGE_TYPE, message_class
import rclpy
from rclpy.duration import Duration
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import (HistoryPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy)
from rclpy.signals import SignalHandlerOptions

#: Message types published with sensor-data QoS (best effort).
SENSOR_TYPES = frozenset({IMAGE_TYPE, 'sensor_msgs/msg/CompressedImage'})
#: History depth of reliable publishers: deep enough that ``rate=0`` does not overwrite
#: samples a subscriber has not acknowledged yet.
RELIABLE_DEPTH = 100


def publisher_qos(msgtype: str, reliable: bool = False) -> QoSProfile:
    """Return the publisher QoS for ``msgtype``: sensor data for images unless ``reliable``."""
    if msgtype in SENSOR_TYPES and not reliable:
        return qos_profile_sensor_data
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RELIABLE_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE)


@dataclass
class PlayStats:
    """What :func:`play` did: messages published per (output) topic, loops and wall time (s)."""

    published: Dict[str, int] = field(default_factory=dict)
    loops: int = 0
    wall_time: float = 0.0
    skipped_topics: List[str] = field(default_factory=list)


def parse_remaps(remaps: Sequence[str]) -> Dict[str, str]:
    """Parse ``['from:=to', ...]`` into a dict; ``ValueError`` naming a malformed entry."""
    out = {}
    for item in remaps:
        src, sep, dst = item.partition(':=')
        if not sep or not src or not dst:
            raise ValueError(f'remap {item!r} is not of the form /from:=/to')
        out[src] = dst
    return out


class Player:
    """
    Publish the messages of a bag from ``node``; one publisher per played topic.

    ``topics`` selects topics (all when None); ``remap`` renames them on output. Topics whose
    message type is not installed are skipped (listed in ``skipped_topics``).
    """

    def __init__(self, node: Node, bag_path: str, *, topics: Optional[Sequence[str]] = None,
                 remap: Optional[Dict[str, str]] = None, reliable: bool = False,
                 strict: bool = False) -> None:
        self.node = node
        self.bag_path = bag_path
        self.remap = dict(remap or {})
        self.strict = strict
        self.publishers: Dict[str, Publisher] = {}
        self.skipped_topics: List[str] = []
        with BagReader(bag_path, strict=strict) as bag:
            available = bag.topics
            self.start_ns = bag.start_ns
            if bag.incomplete:
                node.get_logger().warning(
                    f'{bag_path}: incomplete bag ({"; ".join(bag.problems)}); playing the '
                    f'{bag.message_count} complete messages recovered from it')
        if topics:
            missing = sorted(set(topics) - set(available))
            if missing:
                raise BagError(f'{bag_path}: no topic(s) {", ".join(missing)} in the bag; it has '
                               f'{", ".join(sorted(available)) or "no topics"}')
            available = {t: available[t] for t in topics}
        for topic, msgtype in sorted(available.items()):
            try:
                cls = message_class(msgtype)
            except BagError as exc:
                node.get_logger().warning(f'skipping {topic}: {exc}')
                self.skipped_topics.append(topic)
                continue
            out = self.remap.get(topic, topic)
            self.publishers[topic] = node.create_publisher(
                cls, out, publisher_qos(msgtype, reliable))
        if not self.publishers:
            raise BagError(f'{bag_path}: nothing to play (no topic with an installed type)')

    def wait_for_subscribers(self, timeout: float, sleep: Callable[[float], None] = time.sleep,
                             should_stop: Callable[[], bool] = lambda: False) -> bool:
        """Wait up to ``timeout`` s until every publisher has a subscriber; True when all do."""
        deadline = time.monotonic() + timeout
        while True:
            if all(p.get_subscription_count() > 0 for p in self.publishers.values()):
                return True
            if time.monotonic() >= deadline or should_stop():
                return False
            sleep(0.05)

    def play(self, *, rate: float = 1.0, loop: bool = False,
             after_publish: Optional[Callable[[BagMessage], None]] = None,
             sleep: Callable[[float], None] = time.sleep,
             should_stop: Callable[[], bool] = lambda: False) -> PlayStats:
        """
        Publish the bag once (or forever with ``loop``) at ``rate`` x the recorded pace.

        ``after_publish(msg)`` is called after each message (e.g. to wait for a consumer);
        ``sleep(seconds)`` waits between messages (pass one that spins an executor to keep
        callbacks of the same process running); ``should_stop()`` ends playback early.
        """
        if rate < 0:
            raise ValueError(f'rate must be >= 0 (0 = as fast as possible), got {rate}')
        stats = PlayStats({self.remap.get(t, t): 0 for t in self.publishers},
                          skipped_topics=list(self.skipped_topics))
        t_start = time.monotonic()
        while self.node.context.ok() and not should_stop():
            wall0 = time.monotonic()
            with BagReader(self.bag_path, strict=self.strict) as bag:
                for msg in bag.messages(self.publishers):
                    if not self.node.context.ok() or should_stop():
                        break
                    if rate > 0:
                        due = wall0 + (msg.timestamp_ns - self.start_ns) * 1e-9 / rate
                        while (left := due - time.monotonic()) > 0 and not should_stop():
                            sleep(min(left, 0.1))
                        if should_stop():
                            break
                    self.publishers[msg.topic].publish(msg.rawdata)
                    stats.published[self.remap.get(msg.topic, msg.topic)] += 1
                    if after_publish is not None:
                        after_publish(msg)
            stats.loops += 1
            if not loop:
                break
        stats.wall_time = time.monotonic() - t_start
        return stats

    def flush(self, timeout: float = 0.5) -> None:
        """
        Wait up to ``timeout`` s in all until reliable samples are acknowledged.

        Fast DDS acknowledges on its heartbeat (seconds), so this is a bounded courtesy wait,
        not a delivery guarantee.
        """
        deadline = time.monotonic() + timeout
        for pub in self.publishers.values():
            left = deadline - time.monotonic()
            if left <= 0:
                break
            if pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
                pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))

    def destroy(self) -> None:
        """Destroy the publishers (the node stays)."""
        for pub in self.publishers.values():
            self.node.destroy_publisher(pub)
        self.publishers.clear()


def spinning_sleep(executor: Executor) -> Callable[[float], None]:
    """Return a ``sleep(seconds)`` that spins ``executor`` meanwhile (same-process subscribers)."""
    def sleep(seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            executor.spin_once(timeout_sec=left)
    return sleep


def play(bag_path: str, rate: float = 1.0, *, node: Optional[Node] = None,
         topics: Optional[Sequence[str]] = None, remap: Optional[Dict[str, str]] = None,
         loop: bool = False, start_delay: float = 0.0, wait_for_subscribers: float = 0.0,
         reliable: bool = False, executor: Optional[Executor] = None,
         after_publish: Optional[Callable[[BagMessage], None]] = None, strict: bool = False,
         should_stop: Callable[[], bool] = lambda: False) -> PlayStats:
    """
    Play ``bag_path`` and return :class:`PlayStats`.

    With ``node`` None a node ``mlofc_play`` is created (rclpy must be initialised) and
    destroyed afterwards. ``wait_for_subscribers`` waits up to that many seconds for every
    topic to have a subscriber, then ``start_delay`` more seconds. With ``executor``, waiting
    spins it so subscribers in this process keep receiving. ``should_stop()`` ends waiting and
    playback early. Raises ``BagError`` for an unreadable bag (or, with ``strict``, an
    incomplete one) or unknown topics.
    """
    own = node is None
    node = node if node is not None else rclpy.create_node('mlofc_play')
    player = None
    try:
        player = Player(node, bag_path, topics=topics, remap=remap, reliable=reliable,
                        strict=strict)
        sleep = spinning_sleep(executor) if executor is not None else time.sleep
        if wait_for_subscribers > 0 and not player.wait_for_subscribers(
                wait_for_subscribers, sleep, should_stop) and not should_stop():
            node.get_logger().warning(
                f'not every topic has a subscriber after {wait_for_subscribers:g} s; playing')
        deadline = time.monotonic() + start_delay
        while (left := deadline - time.monotonic()) > 0 and not should_stop():
            sleep(min(left, 0.1))
        node.get_logger().info(f'playing {len(player.publishers)} topics of {bag_path} at '
                               f'rate {rate:g}' + (' in a loop' if loop else ''))
        stats = player.play(rate=rate, loop=loop, after_publish=after_publish, sleep=sleep,
                            should_stop=should_stop)
        if not should_stop():
            player.flush()
            sleep(0.1)  # let best-effort samples leave before the publishers go
        return stats
    finally:
        if player is not None:
            player.destroy()
        if own:
            node.destroy_node()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='mlofc_play',
        description='Publish the messages of a rosbag2 bag (mcap or sqlite3) at the recorded '
                    'pace; a ros2 bag play stand-in. ROS arguments go after --ros-args.')
    p.add_argument('bag', help='bag directory (or a .mcap / .db3 file)')
    p.add_argument('--rate', '-r', type=float, default=1.0,
                   help='playback speed factor; 0 = as fast as possible (default 1)')
    p.add_argument('--loop', '-l', action='store_true', help='play again and again')
    p.add_argument('--topics', nargs='+', action='extend', metavar='TOPIC',
                   help='play only these topics (repeatable)')
    p.add_argument('--remap', '-m', nargs='+', action='extend', default=[], metavar='FROM:=TO',
                   help='publish topic FROM as TO (repeatable)')
    p.add_argument('--start-delay', '-d', type=float, default=0.0, metavar='S',
                   help='seconds to wait before publishing (after discovery)')
    p.add_argument('--wait-for-subscribers', '-w', type=float, default=0.0, metavar='S',
                   help='wait up to S seconds for every topic to have a subscriber')
    p.add_argument('--reliable', action='store_true',
                   help='publish image topics with reliable QoS too')
    p.add_argument('--strict', action='store_true',
                   help='refuse an incomplete bag (cut short, not closed) instead of playing its '
                        'complete messages with a warning')
    return p


class StopRequest:
    """
    Turn SIGINT and SIGTERM into a request to stop (``requested``), checked between messages.

    rclpy's own handler shuts the context down from another thread at once, so a publish that
    is under way fails ("publisher's context is invalid"); ending the loop first and shutting
    down afterwards does not race.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.requested = False
        self._previous: Dict[int, Any] = {}

    def __call__(self) -> bool:
        return self.requested

    def __enter__(self) -> 'StopRequest':
        for sig in self.SIGNALS:
            self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum: int, frame: Optional[FrameType]) -> None:
        self.requested = True

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()


def main(argv: Optional[Sequence[str]] = None) -> int:
    """
    Entry point of ``mlofc_play``; return the exit code.

    0: played (also when stopped by Ctrl-C or SIGTERM, as ``ros2 bag play``), 1: bad bag, 2: bad
    arguments.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    # only what follows --ros-args goes to rcl: ``--remap a:=b`` must not become a global remap
    split = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    args = _parser().parse_args(argv[:split])
    ros_args = ['mlofc_play', *argv[split:]]
    try:
        remap = parse_remaps(args.remap)
    except ValueError as exc:
        print(f'mlofc_play: {exc}', file=sys.stderr)
        return 2
    if args.rate < 0:
        print(f'mlofc_play: --rate must be >= 0, got {args.rate}', file=sys.stderr)
        return 2
    with StopRequest() as stop:
        rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = rclpy.create_node('mlofc_play')
            try:
                stats = play(args.bag, args.rate, node=node, topics=args.topics, remap=remap,
                             loop=args.loop, start_delay=args.start_delay,
                             wait_for_subscribers=args.wait_for_subscribers,
                             reliable=args.reliable, strict=args.strict, should_stop=stop)
            finally:
                node.destroy_node()
        except BagError as exc:
            print(f'mlofc_play: {exc}', file=sys.stderr)
            return 1
        finally:
            rclpy.try_shutdown()
    total = sum(stats.published.values())
    print(f'mlofc_play: {"stopped; " if stop.requested else ""}published {total} messages on '
          f'{len(stats.published)} topics in {stats.wall_time:.2f} s', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
