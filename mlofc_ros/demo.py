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
"""``python -m mlofc_ros.demo`` (``make demo``): the node, end to end, on a rendered bag.

1. Render boxes rotating about the camera centre in front of a static striped wall (2 boxes +
   background = 3 bodies, 640x480, 60 frames at 30 Hz, known angular velocities and edges).
2. Write them as a rosbag2 (mcap) with ``sensor_msgs/Image`` mono8 and ``CameraInfo``.
3. Start ``mlofc_node`` as a separate process on the run's ``ROS_DOMAIN_ID``, play the bag into it
   over DDS with :mod:`mlofc_ros.bag.player` (lock-step: the next frame goes out when the node
   has answered the previous one, so no frame is dropped however slow the machine), and collect
   ``/mlofc/segments`` and ``/mlofc/body_<i>/twist``.
4. Score against the ground truth: detected segments are matched to true edges by endpoint
   distance, node body ids to true bodies by label overlap; print each body's angular velocity
   (deg/s) next to the truth and the label accuracy, and write ``demo_strip.png`` (frames with
   segments coloured by body) and ``demo.md`` to the output directory (``docs/results`` in a
   source checkout).

Exits non-zero with a message when the node does not start or stops answering.
"""
import argparse
from dataclasses import dataclass, field
import itertools
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
#: A detected segment matches a true edge when both its endpoints lie within this many pixels
#: of the edge (point-to-segment distance).
MATCH_TOLERANCE_PX = 3.0


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
    method: Optional[str] = None
    window: Optional[int] = None
    frame_timeout: float = 30.0
    startup_timeout: float = 60.0
    domain_id: Optional[int] = None

    @property
    def num_bodies(self) -> int:
        """Bodies the node is asked for: the boxes plus the static background."""
        return self.boxes + 1


# --- ground-truth scoring (numpy only) -------------------------------------------------------

def point_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distances (K, L) in pixels from ``points`` (K, 2) ``(u, v)`` to ``segments`` (L, 4)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
    s = np.asarray(segments, dtype=np.float64).reshape(1, -1, 4)
    a, b = s[..., :2], s[..., 2:]
    ab = b - a
    denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-12)
    t = np.clip(np.sum((p - a) * ab, axis=-1) / denom, 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1)


def match_segments(detected: np.ndarray, truth: np.ndarray,
                   tolerance: float = MATCH_TOLERANCE_PX) -> np.ndarray:
    """Index (M,) of the true edge each detected segment lies on, ``-1`` when none does.

    ``detected`` (M, 4) and ``truth`` (L, 4) are ``(u1, v1, u2, v2)`` pixels. A detection lies
    on an edge when both endpoints are within ``tolerance`` px of it (detections are often
    parts of edges, so endpoint-to-segment, not endpoint-to-endpoint); the closest edge wins.
    """
    det = np.asarray(detected, dtype=np.float64).reshape(-1, 4)
    gt = np.asarray(truth, dtype=np.float64).reshape(-1, 4)
    if not len(det) or not len(gt):
        return np.full(len(det), -1, dtype=np.int64)
    d1 = point_segment_distance(det[:, :2], gt)
    d2 = point_segment_distance(det[:, 2:], gt)
    worst = np.maximum(d1, d2)
    best = np.argmin(worst, axis=1)
    ok = worst[np.arange(len(det)), best] <= tolerance
    return np.where(ok, best, -1)


def match_bodies(confusion: np.ndarray) -> Dict[int, int]:
    """Map node labels (rows) to true bodies (columns) maximising the total overlap.

    ``confusion[i, g]`` counts segments with label ``i`` on body ``g``. Exhaustive over
    assignments (a handful of bodies); labels left without a body (or with no overlap) are
    absent from the result.
    """
    conf = np.asarray(confusion)
    n_lab, n_gt = conf.shape
    best: Tuple[float, Tuple[int, ...]] = (-1.0, ())
    if n_lab <= n_gt:
        for perm in itertools.permutations(range(n_gt), n_lab):
            score = float(sum(conf[i, g] for i, g in enumerate(perm)))
            if score > best[0]:
                best = (score, perm)
        pairs = list(enumerate(best[1]))
    else:
        for perm in itertools.permutations(range(n_lab), n_gt):
            score = float(sum(conf[i, g] for g, i in enumerate(perm)))
            if score > best[0]:
                best = (score, perm)
        pairs = [(i, g) for g, i in enumerate(best[1])]
    return {int(i): int(g) for i, g in pairs if conf[i, g] > 0}


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


@dataclass
class BodyScore:
    """One node body against its true body: median angular velocity (deg/s) and its error."""

    label: int
    truth_index: int
    truth_name: str
    omega_deg_s: np.ndarray
    truth_deg_s: np.ndarray
    error_deg_s: float
    frames: int


@dataclass
class Evaluation:
    """Scores of a demo run."""

    bodies: List[BodyScore]
    label_accuracy: float
    assigned_fraction: float
    matched_segments: int
    total_segments: int
    mapping: Dict[int, int]
    first_scored_frame: int


def evaluate(seq: Any, collected: Collected, warmup: int) -> Evaluation:
    """Score ``collected`` against the rendered sequence ``seq`` (frames ``>= warmup`` only).

    Label accuracy: among detections lying on a true edge and carrying a label, the share
    whose label maps (by :func:`match_bodies`) to the edge's body. ``assigned_fraction``: share
    of matched detections with a label at all.
    """
    n_gt = len(seq.body_names)
    pairs: List[Tuple[np.ndarray, np.ndarray]] = []
    total = 0
    for f, out in sorted(collected.frames.items()):
        if f < warmup:
            continue
        total += len(out.segments)
        idx = match_segments(out.segments, seq.truth[f].segments)
        hit = idx >= 0
        pairs.append((out.labels[hit].astype(np.int64),
                      np.asarray(seq.truth[f].body_ids)[idx[hit]].astype(np.int64)))
    labels = np.concatenate([p[0] for p in pairs]) if pairs else np.zeros(0, np.int64)
    gt = np.concatenate([p[1] for p in pairs]) if pairs else np.zeros(0, np.int64)
    n_lab = max(int(labels.max()) + 1 if labels.size else 0,
                max(collected.twists, default=-1) + 1)
    conf = np.zeros((n_lab, n_gt), dtype=np.int64)
    assigned = labels >= 0
    np.add.at(conf, (labels[assigned], gt[assigned]), 1)
    mapping = match_bodies(conf) if n_lab else {}
    mapped = np.array([mapping.get(int(x), -2) for x in labels[assigned]], dtype=np.int64)
    correct = int(np.sum(mapped == gt[assigned]))
    n_assigned = int(np.sum(assigned))
    bodies = []
    for label, g in sorted(mapping.items()):
        ws = [w for f, (w, _) in collected.twists.get(label, {}).items() if f >= warmup]
        if not ws:
            continue
        omega = np.degrees(np.median(np.asarray(ws), axis=0))
        truth = np.degrees(np.asarray(seq.angular_velocities[g], dtype=np.float64))
        bodies.append(BodyScore(label, g, seq.body_names[g], omega, truth,
                                float(np.linalg.norm(omega - truth)), len(ws)))
    return Evaluation(bodies, correct / n_assigned if n_assigned else math.nan,
                      n_assigned / len(labels) if len(labels) else math.nan, int(len(labels)),
                      total, mapping, warmup)


# --- the node process ------------------------------------------------------------------------

def node_command() -> List[str]:
    """Command that starts the installed ``mlofc_node`` (console script, colcon or PATH)."""
    candidates = [Path(sys.executable).parent / 'mlofc_node',
                  Path(sys.prefix) / 'lib' / 'mlofc_ros' / 'mlofc_node']
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


def _run_node(bag_path: Path, cfg: DemoConfig, workdir: Path, domain: int,
              log: Any) -> Collected:
    env = dict(os.environ, PYTHONUNBUFFERED='1')

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from geometry_msgs.msg import TwistWithCovarianceStamped
    from sensor_msgs.msg import PointCloud2

    from mlofc_ros.bag.bagfile import BagReader, deserialize
    from mlofc_ros.bag.player import Player
    from mlofc_ros.ros_messages import parse_segments_msg, parse_twist_msg

    with BagReader(bag_path) as bag:
        stamps = [deserialize(m.rawdata, m.msgtype).header.stamp
                  for m in bag.messages([IMAGE_TOPIC])]
    frame_of = {(s.sec, s.nanosec): i for i, s in enumerate(stamps)}

    params = {'num_bodies': cfg.num_bodies}
    if cfg.method:
        params['method'] = cfg.method
    if cfg.window:
        params['window'] = cfg.window
    command = node_command() + ['--ros-args', '-r', f'__node:={NODE_NAME}',
                                '-r', f'image:={IMAGE_TOPIC}', '-r', f'camera_info:={INFO_TOPIC}']
    for k, v in params.items():
        command += ['-p', f'{k}:={v}']
    collected = Collected(node_command=command, domain_id=domain)
    sent_at: Dict[int, float] = {}

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('mlofc_demo', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
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
    for i in range(cfg.num_bodies):
        node.create_subscription(TwistWithCovarianceStamped, f'/{NODE_NAME}/body_{i}/twist',
                                 lambda m, i=i: on_twist(i, m), qos)

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


# --- outputs ---------------------------------------------------------------------------------

def strip_frames(n_frames: int, warmup: int, count: int = 4) -> List[int]:
    """Frame indices shown in the strip: ``count`` evenly spread after the warm-up."""
    first = min(warmup, n_frames - 1)
    return sorted({int(round(x)) for x in np.linspace(first, n_frames - 1, count)})


def render_strip(seq: Any, collected: Collected, frames: Sequence[int],
                 scale: Optional[float] = None) -> np.ndarray:
    """BGR strip (uint8) of ``frames`` with the node's segments drawn by body (draw_debug).

    ``scale`` resizes each tile (default: half size for images 600 px wide or more).
    """
    import cv2

    from mlofc_ros.messages.debug import draw_debug

    n_bodies = max(collected.twists, default=-1) + 1
    tiles = []
    for f in frames:
        out = collected.frames.get(f)
        if out is None:
            continue
        omega = np.full((n_bodies, 3), np.nan)
        valid = np.zeros(n_bodies, dtype=bool)
        for b in range(n_bodies):
            tw = collected.twists.get(b, {}).get(f)
            if tw is not None:
                omega[b], valid[b] = tw[0], True
        img = draw_debug(seq.frames[f], out.segments, out.labels, out.track_ids, omega, valid)
        h, w = img.shape[:2]
        if scale is None:
            scale = 0.5 if w >= 600 else 1.0
        img = cv2.resize(img, (int(w * scale), int(h * scale)), interpolation=cv2.INTER_AREA)
        cv2.putText(img, f'frame {f}', (8, img.shape[0] - 10), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(img)
    if not tiles:
        raise DemoError('no frame to draw: the node published no segments')
    gap = np.full((tiles[0].shape[0], 4, 3), 255, dtype=np.uint8)
    row = [tiles[0]]
    for t in tiles[1:]:
        row += [gap, t]
    return np.concatenate(row, axis=1)


def _vec(v: np.ndarray) -> str:
    return '(' + ', '.join(f'{x:+7.1f}' for x in v) + ')'


def summary_lines(seq: Any, ev: Evaluation, collected: Collected, cfg: DemoConfig) -> List[str]:
    """Plain-text result table (printed and put in demo.md)."""
    lines = [f'{"body":<12}{"node id":>8}  {"omega (deg/s)":<29}{"truth (deg/s)":<29}'
             f'{"|error|":>8}{"frames":>8}']
    for b in ev.bodies:
        lines.append(f'{b.truth_name:<12}{b.label:>8}  {_vec(b.omega_deg_s):<29}'
                     f'{_vec(b.truth_deg_s):<29}{b.error_deg_s:8.2f}{b.frames:>8}')
    missing = [seq.body_names[g] for g in range(len(seq.body_names))
               if g not in ev.mapping.values()]
    if missing:
        lines.append(f'not found: {", ".join(missing)}')
    labelled = (int(round(ev.assigned_fraction * ev.matched_segments))
                if ev.matched_segments else 0)
    lines.append(f'label accuracy {100 * ev.label_accuracy:.1f} % of '
                 f'{labelled} labelled segments on '
                 f'true edges ({100 * ev.assigned_fraction:.1f} % of the {ev.matched_segments} '
                 f'matched, {ev.total_segments} detected; frames >= {ev.first_scored_frame})')
    lat = [o.latency for o in collected.frames.values() if math.isfinite(o.latency)]
    median = 1e3 * float(np.median(lat)) if lat else math.nan
    lines.append(f'node: {len(collected.frames)}/{cfg.frames} frames answered in '
                 f'{collected.wall_time:.1f} s (median latency {median:.0f} ms/'
                 f'frame), {len(collected.dropped)} unanswered')
    return lines


def write_report(path: Path, lines: Sequence[str], cfg: DemoConfig, collected: Collected,
                 strip_name: str, argv: Sequence[str], total_time: float) -> None:
    """Write the Markdown summary of a run."""
    cmd = ' '.join(['python -m mlofc_ros.demo', *argv])
    node_cmd = ' '.join(Path(collected.node_command[0]).name if i == 0 else a
                        for i, a in enumerate(collected.node_command))
    text = [
        '# Demo: mlofc_node on a rendered bag',
        '',
        f'Generated by `{cmd}`{" (`make demo`)" if not argv else ""} in {total_time:.0f} s '
        'on this machine. Do not edit by hand.',
        '',
        f'- Scene: {cfg.boxes} striped boxes rotating about the camera centre in front of a '
        f'static striped wall = {cfg.num_bodies} bodies; {cfg.size[0]}x{cfg.size[1]} px, '
        f'{cfg.frames} frames at {cfg.fps:g} Hz, noise sigma {cfg.noise:g} grey levels, '
        f'seed {cfg.seed}.',
        f'- Bag: rosbag2 mcap, `{IMAGE_TOPIC}` (mono8) + `{INFO_TOPIC}`, played by '
        '`mlofc_ros.bag.player` in lock-step (each frame is sent when the node has answered '
        'the previous one).',
        f'- Node: separate process, `{node_cmd}`, its own `ROS_DOMAIN_ID`.',
        f'- Scoring: a detection is on a true edge when both endpoints are within '
        f'{MATCH_TOLERANCE_PX:g} px of it; node body ids are matched to true bodies by label '
        'overlap; omega is the median over the scored frames of `~/body_<i>/twist` (converted '
        'to deg/s, camera optical frame).',
        '',
        '```',
        *lines,
        '```',
        '',
        f'![segments coloured by body]({strip_name})',
        '',
    ]
    path.write_text('\n'.join(text))


def default_out_dir() -> Path:
    """``docs/results`` of the source checkout, else ``./mlofc_demo``."""
    docs = Path(__file__).resolve().parents[1] / 'docs' / 'results'
    return docs if docs.parent.is_dir() else Path.cwd() / 'mlofc_demo'


def _size(text: str) -> Tuple[int, int]:
    w, sep, h = text.lower().partition('x')
    if not sep:
        raise argparse.ArgumentTypeError(f'size must look like 640x480, got {text!r}')
    return int(w), int(h)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m mlofc_ros.demo', description=__doc__.split(
        '\n')[0].strip('`'), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--frames', type=int, default=60, help='frames to render (default 60)')
    p.add_argument('--boxes', type=int, default=2, help='moving boxes, 1..4 (default 2)')
    p.add_argument('--size', type=_size, default=(640, 480), help='WxH (default 640x480)')
    p.add_argument('--seed', type=int, default=0, help='scene and noise seed (default 0)')
    p.add_argument('--method', help='solver method (node parameter; default: its default)')
    p.add_argument('--window', type=int, help='window length (node parameter)')
    p.add_argument('--out', type=Path, default=None,
                   help='where demo.md and demo_strip.png go (default docs/results)')
    p.add_argument('--keep-bag', action='store_true', help='keep the bag and node log in --out')
    p.add_argument('--frame-timeout', type=float, default=30.0,
                   help='seconds to wait for the node to answer a frame (default 30)')
    p.add_argument('--startup-timeout', type=float, default=60.0,
                   help='seconds to wait for the node to subscribe (default 60)')
    p.add_argument('--domain-id', type=int,
                   help='ROS domain id (default: ROS_DOMAIN_ID, else a random one)')
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the demo; 0 on success, 1 when the node fails, 2 for bad arguments."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(argv)
    if args.frames < 3:
        print('demo: --frames must be >= 3', file=sys.stderr)
        return 2
    cfg = DemoConfig(frames=args.frames, boxes=args.boxes, size=args.size, seed=args.seed,
                     method=args.method, window=args.window, frame_timeout=args.frame_timeout,
                     startup_timeout=args.startup_timeout, domain_id=args.domain_id)
    out_dir = args.out if args.out is not None else default_out_dir()
    t_start = time.monotonic()
    try:
        from mlofc_ros import params as mlofc_params
        from mlofc_ros.bag.bagfile import write_image_bag
        from mlofc_ros.render import render_sequence

        out_dir.mkdir(parents=True, exist_ok=True)
        print(f'rendering {cfg.frames} frames ({cfg.size[0]}x{cfg.size[1]}, {cfg.boxes} boxes '
              '+ background) ...', flush=True)
        try:
            seq = render_sequence(n_boxes=cfg.boxes, n_frames=cfg.frames, size=cfg.size,
                                  motion='camera_centre', background=True,
                                  noise_sigma=cfg.noise, fps=cfg.fps, seed=cfg.seed)
        except ValueError as exc:  # a bad --boxes/--size, named by the renderer
            print(f'demo: error: {exc}', file=sys.stderr)
            return 2
        with tempfile.TemporaryDirectory(prefix='mlofc_demo_') as tmp:
            work = out_dir if args.keep_bag else Path(tmp)
            bag_path = work / 'demo_bag'
            write_image_bag(bag_path, seq.frames, seq.stamps, seq.camera,
                            image_topic=IMAGE_TOPIC, info_topic=INFO_TOPIC,
                            overwrite=args.keep_bag)
            print(f'wrote {bag_path if args.keep_bag else "the bag"} (mcap)', flush=True)
            collected = run_node(bag_path, cfg, work)
        window = cfg.window or int(mlofc_params.PARAMS['window'].default)
        warmup = min(window, cfg.frames - 1)
        ev = evaluate(seq, collected, warmup)
        lines = summary_lines(seq, ev, collected, cfg)
        print('\n'.join(['', *lines]))
        strip = render_strip(seq, collected, strip_frames(cfg.frames, warmup))
        import cv2
        strip_path = out_dir / 'demo_strip.png'
        if not cv2.imwrite(str(strip_path), strip, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
            raise DemoError(f'cannot write {strip_path}')
        total = time.monotonic() - t_start
        write_report(out_dir / 'demo.md', lines, cfg, collected, strip_path.name, argv, total)
        print(f'\nwrote {strip_path} and {out_dir / "demo.md"} ({total:.0f} s in all)')
    except DemoError as exc:
        print(f'demo: error: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('demo: interrupted', file=sys.stderr)
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
