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
``mlofc_bag INPUT OUTPUT``: run the pipeline over a bag as fast as it goes, no ROS graph.

Reads the images (and CameraInfo) of INPUT, runs :class:`mlofc_ros.pipeline.Pipeline` on every
image paired with the latest CameraInfo, and writes OUTPUT with the node's topics
(``/mlofc/segments``, ``/mlofc/body_<i>/twist``, optionally ``/mlofc/debug_image``) next to a copy
of the input images and camera info, each output message at its image's record time, so Foxglove
or RViz show input and result together. Parameters are the node's (``-p window:=7``).
"""
import argparse
from dataclasses import dataclass, field
import math
import signal
import sys
import threading
import time
from types import FrameType
from typing import Any, Dict, List, Optional, Sequence, TextIO, Tuple

from mlofc_ros import params as mlofc_params
from mlofc_ros.bag.bagfile import (BagError, BagReader, BagWriter, CAMERA_INFO_TYPE,
                                   DEFAULT_STORAGE, deserialize, IMAGE_TYPE, serialize,
                                   STORAGES)
from mlofc_ros.camera import CameraModel
from mlofc_ros.params import parse_param, parse_params  # noqa: F401 (re-exported)

SEGMENTS_TYPE = 'sensor_msgs/msg/PointCloud2'
TWIST_TYPE = 'geometry_msgs/msg/TwistWithCovarianceStamped'


def output_topics(node_name: str = 'mlofc') -> Dict[str, str]:
    """Return the node's output topic names under ``/<node_name>/`` (``body``: ``{i}`` slot)."""
    base = '/' + node_name.strip('/')
    return {'segments': f'{base}/segments', 'body': f'{base}/body_{{i}}/twist',
            'debug_image': f'{base}/debug_image'}


class ProgressBar:
    """A dependency-free progress bar on a stream (redrawn in place on a terminal)."""

    def __init__(self, total: int, stream: TextIO = sys.stderr, width: int = 30,
                 enabled: bool = True) -> None:
        self.total = max(int(total), 1)
        self.stream = stream
        self.width = width
        self.enabled = enabled
        self.tty = bool(getattr(stream, 'isatty', lambda: False)())
        self.start = time.monotonic()
        self._last_draw = -math.inf
        self._last_decile = -1
        self._last_done = -1

    def update(self, done: int, note: str = '') -> None:
        """Redraw for ``done`` of ``total`` (throttled to 10 Hz; every 10 % when not a tty)."""
        if not self.enabled or done == self._last_done:
            return
        now = time.monotonic()
        if self.tty:
            if now - self._last_draw < 0.1 and done < self.total:
                return
        else:
            decile = (10 * done) // self.total
            if decile == self._last_decile and done < self.total:
                return
            self._last_decile = decile
        self._last_draw = now
        self._last_done = done
        frac = min(done / self.total, 1.0)
        filled = int(round(frac * self.width))
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        line = (f'[{"#" * filled}{"." * (self.width - filled)}] {done}/{self.total} '
                f'{rate:5.1f} frames/s {note}')
        self.stream.write(('\r' + line + '\x1b[K') if self.tty else line + '\n')
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line."""
        if self.enabled and self.tty:
            self.stream.write('\n')
            self.stream.flush()


@dataclass
class OfflineStats:
    """Outcome of :func:`process_bag`: counts, per-topic messages written and timing (s)."""

    images: int = 0
    processed: int = 0
    skipped: int = 0
    errors: Dict[str, int] = field(default_factory=dict)
    written: Dict[str, int] = field(default_factory=dict)
    wall_time: float = 0.0
    pipeline_ms: List[float] = field(default_factory=list)
    image_topic: str = ''
    camera_info_topic: Optional[str] = None
    incomplete: bool = False
    recovered: int = 0
    interrupted: bool = False


class OfflineInterrupted(KeyboardInterrupt):
    """
    Ctrl-C stopped :func:`process_bag`; the output bag holds the frames processed until then.

    ``stats`` are those of the frames processed; the output bag is finished and readable.
    """

    def __init__(self, stats: OfflineStats) -> None:
        super().__init__('interrupted')
        self.stats = stats


class StopOnSigint:
    """
    Turn the first Ctrl-C into a request (``requested``) instead of an exception.

    A loop checks ``requested`` between frames and ends cleanly; a second Ctrl-C raises
    ``KeyboardInterrupt`` as usual. Only the main thread can handle signals: elsewhere this
    does nothing.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous: Any = None

    def __enter__(self) -> 'StopOnSigint':
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum: int, frame: Optional[FrameType]) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None


def choose_topics(topics: Dict[str, str], image_topic: Optional[str],
                  info_topic: Optional[str], path: str) -> Tuple[str, Optional[str]]:
    """
    Pick the image topic (given, or the only Image topic) and its CameraInfo topic.

    The CameraInfo topic is the given one, the only CameraInfo topic, or the one next to the
    image topic (``<ns>/camera_info``); None when there is none. Raises ``BagError``.
    """
    images = sorted(t for t, m in topics.items() if m == IMAGE_TYPE)
    infos = sorted(t for t, m in topics.items() if m == CAMERA_INFO_TYPE)
    if not images:
        found = ', '.join(f'{t} ({m})' for t, m in sorted(topics.items())) or 'no topics'
        raise BagError(f'{path}: no image topic: 0 sensor_msgs/msg/Image topics in the bag (it '
                       f'has {found}); expected a recording of a camera')
    if image_topic is None:
        if len(images) != 1:
            found = ', '.join(images) if images else 'none'
            raise BagError(f'{path}: cannot choose the image topic: {len(images)} '
                           f'sensor_msgs/msg/Image topics ({found}); pass --image-topic')
        image_topic = images[0]
    elif topics.get(image_topic) != IMAGE_TYPE:
        what = topics.get(image_topic)
        raise BagError(f'{path}: image topic {image_topic} '
                       + (f'has type {what}, not {IMAGE_TYPE}' if what else 'is not in the bag')
                       + f'; Image topics: {", ".join(images) or "none"}')
    if info_topic is not None:
        if topics.get(info_topic) != CAMERA_INFO_TYPE:
            raise BagError(f'{path}: camera info topic {info_topic} is not a '
                           f'{CAMERA_INFO_TYPE} topic of the bag; CameraInfo topics: '
                           f'{", ".join(infos) or "none"}')
        return image_topic, info_topic
    sibling = image_topic.rsplit('/', 1)[0] + '/camera_info'
    if sibling in infos:
        return image_topic, sibling
    return image_topic, infos[0] if len(infos) == 1 else None


class CameraInfoPairing:
    """
    Pairs each image with the latest CameraInfo (the first one for images before it).

    As the node does, a CameraInfo whose image size differs from the image's is not used.
    """

    def __init__(self, first: Optional[Tuple[CameraModel, Optional[Tuple[int, int]]]] = None
                 ) -> None:
        self.first = first
        self.latest: Optional[Tuple[CameraModel, Optional[Tuple[int, int]]]] = None
        self.problem: Optional[str] = None

    def add_info(self, msg: Any) -> None:
        """Take a ``sensor_msgs/CameraInfo``; an invalid one is remembered as :attr:`problem`."""
        from mlofc_ros.ros_messages import camera_info_size, camera_model_from_info
        try:
            self.latest = (camera_model_from_info(msg), camera_info_size(msg))
            self.problem = None
        except ValueError as exc:
            self.problem = f'invalid CameraInfo: {exc}'

    def camera(self, size: Tuple[int, int]) -> Tuple[Optional[CameraModel], Optional[str]]:
        """
        Camera for an image of ``size`` ``(width, height)`` and a problem (or None).

        The camera is None when unknown (the focal length is then estimated).
        """
        entry = self.latest if self.latest is not None else self.first
        if entry is None:
            return None, None
        camera, expected = entry
        if expected is not None and expected != size:
            return None, (f'camera_info is for {expected[0]}x{expected[1]} images but the image '
                          f'is {size[0]}x{size[1]}; ignoring camera_info')
        return camera, None


def _first_camera(bag: BagReader, info_topic: Optional[str]
                  ) -> Optional[Tuple[CameraModel, Optional[Tuple[int, int]]]]:
    if info_topic is None:
        return None
    pairing = CameraInfoPairing()
    for msg in bag.messages([info_topic]):
        pairing.add_info(deserialize(msg.rawdata, msg.msgtype))
        if pairing.latest is not None:
            return pairing.latest
    return None


def _describe_input(bag: BagReader, stats: 'OfflineStats', image_topic: Optional[str],
                    camera_info_topic: Optional[str], input_path: str, log: TextIO) -> None:
    """Choose the input topics into ``stats``; warn of an incomplete bag or no CameraInfo."""
    stats.image_topic, stats.camera_info_topic = choose_topics(
        bag.topics, image_topic, camera_info_topic, input_path)
    if bag.incomplete:
        stats.incomplete, stats.recovered = True, bag.message_count
        log.write(f'mlofc_bag: warning: {input_path}: incomplete bag '
                  f'({"; ".join(bag.problems)}); recovered {bag.message_count} complete '
                  f'messages ({bag.message_counts.get(stats.image_topic, 0)} images); '
                  '--strict refuses such a bag\n')
    if stats.camera_info_topic is None:
        log.write(f'mlofc_bag: no CameraInfo topic for {stats.image_topic}; the focal '
                  'length is estimated (or set -p focal_length:=...)\n')
    stats.images = bag.message_counts.get(stats.image_topic, 0)
    if stats.images == 0:
        raise BagError(f'{input_path}: image topic {stats.image_topic} has no messages')


def _add_output_topics(out: BagWriter, stats: 'OfflineStats', names: Dict[str, str],
                       copy_input: bool, n_bodies: int, debug_image: bool) -> None:
    """Declare the output bag's topics: the input copy, the segments, twists, debug image."""
    if copy_input:
        out.add_topic(stats.image_topic, IMAGE_TYPE, 'sensor_data')
        if stats.camera_info_topic:
            out.add_topic(stats.camera_info_topic, CAMERA_INFO_TYPE, 'reliable')
    out.add_topic(names['segments'], SEGMENTS_TYPE)
    for i in range(n_bodies):
        out.add_topic(names['body'].format(i=i), TWIST_TYPE)
    if debug_image:
        out.add_topic(names['debug_image'], IMAGE_TYPE)


def _write_result(out: BagWriter, names: Dict[str, str], timestamp_ns: int, header: Any,
                  gray: Any, result: Any, debug_image: bool) -> None:
    """Write one solved frame's messages (as the node publishes them) into ``out``."""
    from mlofc_ros.messages.debug import draw_debug
    from mlofc_ros.ros_messages import debug_image_msg, segments_msg, twist_msg

    out.write(names['segments'], timestamp_ns, segments_msg(
        header, result.segments, result.track_ids, result.labels, result.residuals, result.rays))
    for i in range(len(result.body_valid)):
        if not result.body_valid[i]:
            continue
        topic = names['body'].format(i=i)
        out.add_topic(topic, TWIST_TYPE)
        out.write(topic, timestamp_ns, twist_msg(
            header, result.angular_velocities[i], result.angular_covariances[i]))
    if debug_image:
        bgr = draw_debug(gray, result.segments, result.labels, result.track_ids,
                         result.angular_velocities, result.body_valid)
        out.write(names['debug_image'], timestamp_ns,
                  serialize(debug_image_msg(header, bgr), IMAGE_TYPE))


def process_bag(input_path: str, output_path: str, *, image_topic: Optional[str] = None,
                camera_info_topic: Optional[str] = None,
                parameters: Optional[Dict[str, Any]] = None, node_name: str = 'mlofc',
                storage: str = DEFAULT_STORAGE, debug_image: Optional[bool] = None,
                copy_input: bool = True, overwrite: bool = False,
                progress: Optional[ProgressBar] = None, log: Optional[TextIO] = None,
                strict: bool = False) -> OfflineStats:
    """
    Run the pipeline over ``input_path`` and write ``output_path``; return the stats.

    ``parameters`` are node parameters (:mod:`mlofc_ros.params`); ``debug_image`` None follows
    ``publish_debug_image``. Raises ``BagError`` for unreadable/unsuitable bags and
    ``ValueError`` for invalid parameters. Frames the pipeline rejects are counted in
    ``stats.errors`` and skipped, as the node does. An incomplete input bag (cut short, not
    closed) is read from its complete messages with a warning on ``log``, or refused with
    ``strict``. The first Ctrl-C ends the run after the current frame: the output bag is
    finished with the frames so far and :class:`OfflineInterrupted` is raised. ``progress``
    gets its total from the bag; ``log`` (default: the current ``sys.stderr``) gets warnings.
    """
    out_log: TextIO = sys.stderr if log is None else log
    from mlofc_ros.image.decode import image_msg_to_gray
    from mlofc_ros.pipeline import Pipeline
    from mlofc_ros.ros_messages import stamp_to_seconds

    values = mlofc_params.check_all(dict(parameters or {}))
    pipeline = Pipeline(**values)
    all_values = {**mlofc_params.defaults(), **values}
    if debug_image is None:
        debug_image = bool(all_values['publish_debug_image'])
    names = output_topics(node_name)
    stats = OfflineStats()
    warned = set()
    t0 = time.monotonic()

    def warn(kind: str, text: str) -> None:
        stats.errors[kind] = stats.errors.get(kind, 0) + 1
        if kind not in warned:
            warned.add(kind)
            out_log.write(f'\nmlofc_bag: warning: {text} (further ones counted)\n')

    with BagReader(input_path, strict=strict) as bag:
        _describe_input(bag, stats, image_topic, camera_info_topic, input_path, out_log)
        pairing = CameraInfoPairing(_first_camera(bag, stats.camera_info_topic))
        read = [stats.image_topic] + ([stats.camera_info_topic] if stats.camera_info_topic
                                      else [])
        if progress is not None:
            progress.total = max(stats.images, 1)
        n_fixed = int(all_values['num_bodies'])
        # the flag outlives the writer: a Ctrl-C while the bag is finished does not abort it
        with StopOnSigint() as stop, BagWriter(output_path, storage=storage,
                                               overwrite=overwrite) as out:
            _add_output_topics(out, stats, names, copy_input, n_fixed, debug_image)
            done = 0
            for msg in bag.messages(read):
                if stop.requested:
                    stats.interrupted = True
                    break
                if copy_input:
                    out.write(msg.topic, msg.timestamp_ns, msg.rawdata)
                if msg.topic != stats.image_topic:
                    pairing.add_info(deserialize(msg.rawdata, msg.msgtype))
                    if pairing.problem:
                        warn('camera_info', pairing.problem)
                    continue
                done += 1
                image = deserialize(msg.rawdata, msg.msgtype)
                try:
                    gray = image_msg_to_gray(image, max_pixels=all_values['max_pixels'])
                    camera, problem = pairing.camera((gray.shape[1], gray.shape[0]))
                    if problem:
                        warn('camera_size', problem)
                    result = pipeline.process(gray, stamp_to_seconds(image.header.stamp),
                                              camera)
                except ValueError as exc:
                    warn('image', f'frame at {msg.timestamp_ns} ns skipped: {exc}')
                    continue
                if result.skipped:
                    stats.skipped += 1
                    continue
                stats.processed += 1
                stats.pipeline_ms.append(float(result.timings.get('total', math.nan)))
                _write_result(out, names, msg.timestamp_ns, image.header, gray, result,
                              debug_image)
                if progress is not None:
                    progress.update(done, f'{len(result.segments)} segments')
            stats.written = dict(out.counts)
    if progress is not None:
        if not stats.interrupted:
            progress.update(stats.images)
        progress.close()
    stats.wall_time = time.monotonic() - t0
    if stats.interrupted:
        raise OfflineInterrupted(stats)
    return stats


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='mlofc_bag',
        description='Segment the images of a rosbag2 bag (mcap or sqlite3) into moving rigid '
                    'bodies offline and write the topics of the node, with the input images, to a '
                    'new bag.')
    p.add_argument('input', help='input bag directory (or .mcap / .db3 file)')
    p.add_argument('output', help='output bag directory (must not exist unless --overwrite)')
    p.add_argument('--image-topic', help='sensor_msgs/Image topic (default: the only one)')
    p.add_argument('--camera-info-topic',
                   help='sensor_msgs/CameraInfo topic (default: <image ns>/camera_info or the '
                        'only one; none: the focal length is estimated)')
    p.add_argument('-p', '--param', action='append', default=[], metavar='NAME:=VALUE',
                   help='node parameter, e.g. -p num_bodies:=3 -p window:=7 (repeatable)')
    p.add_argument('--node-name', default='mlofc',
                   help='output topics go under /<node-name>/ (default mlofc)')
    p.add_argument('--storage', choices=sorted(STORAGES), default=DEFAULT_STORAGE,
                   help=f'output storage (default {DEFAULT_STORAGE})')
    p.add_argument('--debug-image', action='store_true',
                   help='also write /<node>/debug_image (same as -p publish_debug_image:=true)')
    p.add_argument('--no-input', action='store_true',
                   help='do not copy the input images and camera info')
    p.add_argument('--overwrite', action='store_true', help='replace an existing output bag')
    p.add_argument('--strict', action='store_true',
                   help='refuse an incomplete input bag (cut short, not closed) instead of '
                        'reading its complete messages with a warning')
    p.add_argument('-q', '--quiet', action='store_true', help='no progress bar')
    return p


def _report(stats: OfflineStats, output: str) -> None:
    ms = sorted(x for x in stats.pipeline_ms if math.isfinite(x))
    median = ms[len(ms) // 2] if ms else math.nan
    print(f'mlofc_bag: {stats.processed}/{stats.images} images processed in '
          f'{stats.wall_time:.1f} s (pipeline median {median:.1f} ms/frame) -> {output}',
          file=sys.stderr)
    for topic, count in sorted(stats.written.items()):
        print(f'  {topic}: {count}', file=sys.stderr)
    if stats.errors:
        print(f'  frames with problems: {stats.errors}', file=sys.stderr)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """
    Entry point of ``mlofc_bag``; return the exit code.

    0: done (also for an incomplete input bag whose complete messages were processed), 1: bad
    input or bag, 2: bad arguments, 130: interrupted (what was processed is kept in the output
    bag when the run had started writing it).
    """
    args = _parser().parse_args(argv)
    try:
        parameters = parse_params(args.param)
    except ValueError as exc:
        print(f'mlofc_bag: error: {exc}', file=sys.stderr)
        return 2
    if args.debug_image:
        parameters['publish_debug_image'] = True
    try:
        stats = process_bag(args.input, args.output, image_topic=args.image_topic,
                            camera_info_topic=args.camera_info_topic, parameters=parameters,
                            node_name=args.node_name, storage=args.storage,
                            copy_input=not args.no_input, overwrite=args.overwrite,
                            progress=ProgressBar(0, enabled=not args.quiet), strict=args.strict)
    except (BagError, ValueError) as exc:
        print(f'mlofc_bag: error: {exc}', file=sys.stderr)
        return 1
    except OfflineInterrupted as exc:
        _report(exc.stats, args.output)
        print(f'mlofc_bag: interrupted; the {exc.stats.processed} frames processed so far are '
              f'kept in {args.output} (a finished bag)', file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print('\nmlofc_bag: interrupted; no output written', file=sys.stderr)
        return 130
    _report(stats, args.output)
    return 0


if __name__ == '__main__':
    sys.exit(main())
