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
``python -m mlofc_tools.demo`` (``make demo``): the node, end to end, on a rendered bag.

1. Render boxes spinning about their own centres, which also translate relative to the
   camera, in front of a static striped wall (2 boxes + background = 3 bodies, 640x480, 60
   frames at 30 Hz, known angular velocities and edges); ``--motion camera_centre``: boxes
   rotating about the camera centre (the paper's model, ``robust``'s).
2. Write them as a rosbag2 (mcap) with ``sensor_msgs/Image`` mono8 and ``CameraInfo``.
3. Start ``mlofc_node`` as a separate process on the run's ``ROS_DOMAIN_ID``, play the bag into it
   over DDS with :mod:`mlofc_ros.bag.player` (lock-step: the next frame goes out when the node
   has answered the previous one, so no frame is dropped however slow the machine), and collect
   ``/mlofc/segments`` and ``/mlofc/body_<i>/twist``.
4. Score against the ground truth: detected segments are matched to true edges by endpoint
   distance, node body ids to true bodies by label overlap; print each body's angular velocity
   (deg/s) next to the truth and the label accuracy, and write ``demo_strip.png`` (frames with
   segments coloured by body) and ``README.md`` to the output directory (``docs/results/demo``
   in a source checkout).

Exits non-zero with a message when the node does not start or stops answering.
"""
import argparse
from dataclasses import dataclass
import itertools
import math
from pathlib import Path
import sys
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

from mlofc_tools.bench import common
from mlofc_tools.demo_node import (Collected, DemoConfig, DemoError, FrameOutput,  # noqa: F401
                                   IMAGE_TOPIC, INFO_TOPIC, run_node)
import numpy as np

#: How the boxes may move (:func:`mlofc_tools.render.render_sequence`'s ``motion``), as the
#: report says it.
MOTIONS = {'camera_centre': 'rotating about the camera centre',
           'own_centre': 'spinning about their own centres (so translating relative to the '
                         'camera too)'}

#: A detected segment matches a true edge when both its endpoints lie within this many pixels
#: of the edge (point-to-segment distance).
MATCH_TOLERANCE_PX = 3.0


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
    """
    Index (M,) of the true edge each detected segment lies on, ``-1`` when none does.

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
    """
    Map node labels (rows) to true bodies (columns) maximising the total overlap.

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
    """
    Score ``collected`` against the rendered sequence ``seq`` (frames ``>= warmup`` only).

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


def strip_frames(n_frames: int, warmup: int, count: int = 4) -> List[int]:
    """Frame indices shown in the strip: ``count`` evenly spread after the warm-up."""
    first = min(warmup, n_frames - 1)
    return sorted({int(round(x)) for x in np.linspace(first, n_frames - 1, count)})


def render_strip(seq: Any, collected: Collected, frames: Sequence[int],
                 scale: Optional[float] = None) -> np.ndarray:
    """
    BGR strip (uint8) of ``frames`` with the node's segments drawn by body (draw_debug).

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


def write_report(out: Optional[str], lines: Sequence[str], cfg: DemoConfig,
                 collected: Collected, strip_name: str, argv: Sequence[str], total_time: float
                 ) -> Path:
    """Write the Markdown summary of a run to ``out`` (default ``docs/results/demo``)."""
    cmd = ' '.join(['python -m mlofc_tools.demo', *argv])
    node_cmd = ' '.join(Path(collected.node_command[0]).name if i == 0 else a
                        for i, a in enumerate(collected.node_command))
    head = common.run_header('Demo: mlofc_node on a rendered bag', cmd, {
        'Scene': f'{cfg.boxes} striped boxes {MOTIONS[cfg.motion]} in front of a '
                 f'static striped wall = {cfg.num_bodies} bodies; {cfg.size[0]}x{cfg.size[1]} '
                 f'px, {cfg.frames} frames at {cfg.fps:g} Hz, noise sigma {cfg.noise:g} grey '
                 f'levels, seed {cfg.seed}',
        'Bag': f'rosbag2 mcap, `{IMAGE_TOPIC}` (mono8) + `{INFO_TOPIC}`, played by '
               '`mlofc_ros.bag.player` in lock-step (each frame is sent when the node has '
               'answered the previous one)',
        'Node': f'separate process, `{node_cmd}`, its own `ROS_DOMAIN_ID`',
        'Scoring': f'a detection is on a true edge when both endpoints are within '
                   f'{MATCH_TOLERANCE_PX:g} px of it; node body ids are matched to true bodies '
                   'by label overlap; omega is the median over the scored frames of '
                   '`~/body_<i>/twist` (converted to deg/s, camera optical frame)',
        'Run time': f'{total_time:.0f} s'})
    text = [
        head,
        '```',
        *lines,
        '```',
        '',
        f'![segments coloured by body]({strip_name})',
        '',
    ]
    path = common.results_dir('demo', out) / common.REPORT_NAME
    path.write_text('\n'.join(text))
    return path


def _size(text: str) -> Tuple[int, int]:
    w, sep, h = text.lower().partition('x')
    if not sep:
        raise argparse.ArgumentTypeError(f'size must look like 640x480, got {text!r}')
    return int(w), int(h)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.demo', description=__doc__.split(
        '\n')[0].strip('`'), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--frames', type=int, default=60, help='frames to render (default 60)')
    p.add_argument('--boxes', type=int, default=2, help='moving boxes, 1..4 (default 2)')
    p.add_argument('--size', type=_size, default=(640, 480), help='WxH (default 640x480)')
    p.add_argument('--seed', type=int, default=0, help='scene and noise seed (default 0)')
    p.add_argument('--motion', choices=list(MOTIONS), default='own_centre',
                   help='how the boxes move (default own_centre: spinning in place, so '
                        "translating too; camera_centre: the paper's rotation about the camera)")
    p.add_argument('--method', help='solver method (node parameter; default: its default)')
    p.add_argument('--window', type=int, help='window length (node parameter)')
    p.add_argument('--out', default=None,
                   help='where README.md and demo_strip.png go (default docs/results/demo)')
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
                     motion=args.motion, method=args.method, window=args.window,
                     frame_timeout=args.frame_timeout, startup_timeout=args.startup_timeout,
                     domain_id=args.domain_id)
    t_start = time.monotonic()
    try:
        from mlofc_ros import params as mlofc_params
        from mlofc_ros.bag.bagfile import write_image_bag
        from mlofc_ros.pipeline import window_frames
        from mlofc_tools.render import render_sequence

        out_dir = common.results_dir('demo', args.out)
        print(f'rendering {cfg.frames} frames ({cfg.size[0]}x{cfg.size[1]}, {cfg.boxes} boxes '
              '+ background) ...', flush=True)
        try:
            seq = render_sequence(n_boxes=cfg.boxes, n_frames=cfg.frames, size=cfg.size,
                                  motion=cfg.motion, background=True,
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
        given = {k: v for k, v in (('method', cfg.method), ('window', cfg.window)) if v}
        window = window_frames(dict(mlofc_params.defaults(), **given))
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
        path = write_report(args.out, lines, cfg, collected, strip_path.name, argv, total)
        print(f'\nwrote {strip_path} and {path} ({total:.0f} s in all)')
    except DemoError as exc:
        print(f'demo: error: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print('demo: interrupted', file=sys.stderr)
        return 130
    return 0


if __name__ == '__main__':
    sys.exit(main())
