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
Spinning boxes through the running node in real time: a slow solver at camera rates.

Run ``python -m mlofc_tools.bench live``; writes ``docs/results/live/``. Where ``bench
spinning`` feeds every frame to :class:`~mlofc_ros.pipeline.Pipeline` and waits for each
answer, this one publishes the same rendered scenes to ``mlofc_node`` (its own process, fresh
``ROS_DOMAIN_ID``, started like ``bench ros``) at a fixed rate, as a camera or a bag played in
real time would, whatever the node's speed. Each run (scene, seed, rate) gets a fresh node. The
image stamps are the scene's own (30 frames/s), so the published angular velocities are
comparable with the truth at any publishing rate.

Scored like ``bench spinning`` (segments matched to true edges, stable body ids to true bodies
by overlap; ``per frame``: the ids matched in every frame on its own, the segmentation without
the id switches), on the answered frames from the window's ``window``-th frame on, and from
frame :data:`SETTLED_FRAME` on (3 s: past the first search and the full solves after it at
30 Hz). Also reported:
the frames the node answered (``~/segments``), the frames it tracked but did not solve (the
solver was busy, or its solver process had no step to take while its lane ran a full solve;
the node counts them as dropped, ``unsolved``), those of them it answered
from the running fit (each segment labelled as its track was at the last solve,
``carried``; scored like the solved ones, without angular velocities; ``wrong % of the solved
frames`` leaves them out) and the frames its queue dropped before tracking.
"""
import argparse
import math
import os
import pathlib
import sys
import tempfile
import time
from types import SimpleNamespace
from typing import Any, Dict, List, Optional, Sequence

# importing any mlofc_ros module first runs mlofc_ros/__init__ (one BLAS thread)
from mlofc_tools.bench import common
from mlofc_tools.bench import ros as bench_ros
from mlofc_tools.bench import spinning
import numpy as np

TWIST_TOPIC = '/' + bench_ros.NODE_NAME + '/body_{}/twist'
#: Frames of the scene (30 frames/s stamps) after which a run counts as settled: the first
#: search and the full solves after it take a few seconds at 30 Hz.
SETTLED_FRAME = 90


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='python -m mlofc_tools.bench live',
                                 description=__doc__.split('\n')[0])
    ap.add_argument('--scenes', default='own2+bg,own3+bg', help='scenes of bench spinning')
    ap.add_argument('--seeds', default='0,1,2', help='render seeds')
    ap.add_argument('--rates', default='10,30', help='publishing rates, Hz')
    ap.add_argument('--methods', default='general',
                    help='comma-separated node methods, each run on every scene and rate')
    ap.add_argument('--window', type=int, default=10)
    ap.add_argument('--param', action='append', default=[], metavar='NAME:=VALUE',
                    help='another node parameter (repeatable), e.g. solver_process:=false')
    ap.add_argument('--frames', type=int, default=300, help='frames per scene (300: 10 s)')
    ap.add_argument('--startup-timeout', type=float, default=90.0)
    ap.add_argument('--drain-timeout', type=float, default=120.0)
    ap.add_argument('--quick', action='store_true',
                    help='smoke run: own2, seed 0, 10 Hz, 15 frames, window 5')
    ap.add_argument('--out', default=None, help='output folder (default docs/results/live)')
    args = ap.parse_args(list(argv))
    if args.quick:
        args.scenes, args.seeds, args.rates, args.frames, args.window = \
            'own2', '0', '10', 15, 5
    try:
        args.scene_list = spinning.scene_list(args.scenes)
    except argparse.ArgumentTypeError as exc:
        ap.error(str(exc))
    args.seed_list = [int(s) for s in args.seeds.split(',') if s]
    args.method_list = [m for m in args.methods.split(',') if m]
    args.rate_list = [float(r) for r in args.rates.split(',') if r]
    return args


class LiveBench(bench_ros.Bench):
    """``bench ros``'s publisher/receiver, keeping the answers (clouds and twists)."""

    def __init__(self, args: argparse.Namespace, domain: int, n_bodies: int) -> None:
        from geometry_msgs.msg import TwistWithCovarianceStamped
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        self.clouds: Dict[int, Any] = {}
        self.twists: Dict[int, Dict[int, Any]] = {i: {} for i in range(n_bodies)}
        super().__init__(args, domain)
        qos = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
        for i in range(n_bodies):
            self.node.create_subscription(TwistWithCovarianceStamped, TWIST_TOPIC.format(i),
                                          lambda m, i=i: self._on_twist(i, m), qos)

    @staticmethod
    def _key(msg: Any) -> int:
        return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)

    def _on_segments(self, msg: Any) -> None:
        super()._on_segments(msg)
        with self.lock:
            self.clouds[self._key(msg)] = msg

    def _on_twist(self, body: int, msg: Any) -> None:
        with self.lock:
            self.twists[body][self._key(msg)] = msg

    def publish_sequence(self, stamps: Sequence[float], rate: float) -> List[int]:
        """Publish the pre-built images at ``rate`` Hz, stamped ``stamps`` (s); their ns."""
        period, out = 1.0 / rate, []
        t_next = time.perf_counter()
        for msg, t in zip(self.images, stamps):
            delay = t_next - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            ns = int(round(t * 1e9))
            for m in (self.info, msg):
                m.header.stamp.sec, m.header.stamp.nanosec = divmod(ns, 1_000_000_000)
            self.info_pub.publish(self.info)
            self.image_pub.publish(msg)
            out.append(ns)
            t_next += period
        return out


def answers(bench: LiveBench, stamps: Sequence[int], n_bodies: int) -> List[Any]:
    """Per published frame: a FrameResult-like namespace from its messages, or None."""
    from mlofc_ros.ros_messages import parse_segments_msg, parse_twist_msg
    out = []
    with bench.lock:
        for ns in stamps:
            cloud = bench.clouds.get(ns)
            if cloud is None:
                out.append(None)
                continue
            segs, _, labels, residuals = parse_segments_msg(cloud)
            w = np.full((n_bodies, 3), np.nan)
            valid = np.zeros(n_bodies, bool)
            for i in range(n_bodies):
                m = bench.twists[i].get(ns)
                if m is not None:
                    w[i], valid[i] = parse_twist_msg(m)[0], True
            # a solved frame has residuals; one answered from the running fit has none
            out.append(SimpleNamespace(segments=segs, labels=labels.astype(np.int64),
                                       angular_velocities=w, body_valid=valid,
                                       solved=bool(np.any(np.isfinite(residuals)))))
    return out


def run_one(args: argparse.Namespace, seq: Any, rate: float, work: pathlib.Path,
            method: str) -> Dict[str, Any]:
    """One fresh node with ``method``, one scene published at ``rate``; counts and scores."""
    from mlofc_tools.demo_node import fresh_domain_id
    n_bodies = len(seq.body_names)
    domain = fresh_domain_id()
    stats_path = work / f'stats_{domain}.json'
    ros_args = ['-p', f'num_bodies:={n_bodies}', '-p', f'method:={method}',
                '-p', f'window:={args.window}', '-p', 'queue_size:=2']
    for item in args.param:
        ros_args += ['-p', item]
    with bench_ros.running_node(ros_args, domain, stats_path, work / f'node_{domain}.log',
                                lambda: LiveBench(args, domain, n_bodies),
                                args.startup_timeout) as (bench, proc, _, _):
        bench.make_messages(seq.frames, seq.camera)
        time.sleep(0.5)
        base = time.time()
        stamps = bench.publish_sequence([base + t for t in seq.stamps], rate)
        bench_ros._drain(bench, stats_path, proc, args.drain_timeout)
        time.sleep(0.3)
        stats = bench_ros.read_stats(stats_path) or {}
        got = answers(bench, stamps, n_bodies)
    from mlofc_ros.pipeline import window_frames
    size = window_frames({'window': args.window, 'method': method})   # 0: the method's
    first = min(size - 1, len(stamps) - 1)
    scored = [f for f in range(first, len(stamps)) if got[f] is not None]
    solved = [f for f in scored if got[f].solved]
    return {'published': len(stamps), 'received': int(stats.get('received', 0)),
            'answered': sum(g is not None for g in got), 'scored': len(scored),
            'unsolved': int(stats.get('unsolved', 0)),
            'carried': int(stats.get('carried', 0)),
            'queue_dropped': int(stats.get('dropped', 0)) - int(stats.get('unsolved', 0)),
            'score': _score(seq, got, scored), 'solved': _score(seq, got, solved),
            'settled': _score(seq, got, [f for f in scored if f >= SETTLED_FRAME])}


def _score(seq: Any, got: Sequence[Any], frames: Sequence[int]) -> Optional[Dict[str, Any]]:
    """:func:`spinning.score_run` of the answers ``got`` on ``frames``; None for no frame."""
    if not frames:
        return None
    sub = SimpleNamespace(body_names=seq.body_names, truth=[seq.truth[f] for f in frames],
                          angular_velocities=seq.angular_velocities, pivots=seq.pivots)
    return spinning.score_run(sub, [(got[f], math.nan) for f in frames], 0)


HEADERS = ['scene', 'method', 'seed', 'rate Hz', 'published', 'answered', 'tracked, not solved',
           'answered from the running fit', 'dropped before tracking', 'scored frames',
           'wrong %', 'per frame', '-1 %', 'wrong % of the solved frames',
           'omega err % (boxes)', 'boxes with omega err <= 5%']


def build_rows(records: Sequence[Dict[str, Any]]) -> List[List[object]]:
    rows = []
    for r in records:
        sc = r['score']
        err = np.asarray(sc['omega_err']) if sc else np.zeros(0)
        moving = err[np.isfinite(err)] if sc else err
        rows.append([r['scene'], r['method'], r['seed'], r['rate'], r['published'], r['answered'],
                     r['unsolved'], r['carried'], r['queue_dropped'], r['scored'],
                     100 * sc['wrong'] if sc else math.nan,
                     100 * sc['wrong_frame'] if sc else math.nan,
                     100 * sc['unassigned'] if sc else math.nan,
                     100 * r['solved']['wrong'] if r['solved'] else math.nan,
                     ' / '.join(f'{100 * e:.0f}' for e in moving) if sc else '',
                     float(np.mean(moving <= 0.05)) if moving.size else math.nan])
    return rows


def summary_rows(records: Sequence[Dict[str, Any]]) -> List[List[object]]:
    rows = []
    for scene, method, rate in sorted({(r['scene'], r['method'], r['rate']) for r in records}):
        rs = [r for r in records if (r['scene'], r['method'], r['rate']) == (scene, method, rate)
              and r['score']]
        if not rs:
            continue
        wrong = [100 * r['score']['wrong'] for r in rs]
        err = np.concatenate([np.asarray(r['score']['omega_err']) for r in rs])
        err = err[np.isfinite(err)]
        rows.append([scene, method, rate, len(rs), float(np.mean(wrong)), float(np.max(wrong)),
                     _mean_pct([r['score'] for r in rs], 'wrong_frame'),
                     _mean_pct([r['score'] for r in rs], 'unassigned'),
                     100 * float(np.median(err)) if err.size else math.nan,
                     float(np.mean(err <= 0.05)) if err.size else math.nan,
                     float(np.mean([r['answered'] / r['published'] for r in rs])),
                     _mean_pct([r['solved'] for r in rs], 'wrong'),
                     float(np.mean([r['answered'] - r['carried'] for r in rs])
                           / rs[0]['published']),
                     _mean_pct([r['settled'] for r in rs], 'wrong'),
                     _mean_pct([r['settled'] for r in rs], 'unassigned')])
    return rows


def _mean_pct(scores: Sequence[Optional[Dict[str, Any]]], key: str) -> float:
    """Mean of ``100 * score[key]`` over the scores that exist (NaN for none)."""
    values = [100 * sc[key] for sc in scores if sc]
    return float(np.mean(values)) if values else math.nan


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    t0 = time.monotonic()
    load = os.getloadavg()
    revision = common.commit()        # before the runs: the code they ran
    records = []
    with tempfile.TemporaryDirectory(prefix='mlofc_live_') as tmp:
        for scene in args.scene_list:
            for seed in args.seed_list:
                seq = spinning.render_scene(scene, seed, args.frames)
                for rate in args.rate_list:
                    for method in args.method_list:     # interleaved: the same load
                        rec = dict(run_one(args, seq, rate, pathlib.Path(tmp), method),
                                   scene=scene, seed=seed, rate=rate, method=method)
                        records.append(rec)
                        common.eprint('live: ' + ' '.join(common.format_number(c)
                                                          for c in build_rows([rec])[0]))
    text = '\n'.join([
        common.run_header('Spinning boxes through the running node, published in real time',
                          common.command_line('live', argv), {
                              'Node': f'`method:={"|".join(args.method_list)} '
                                      f'window:={args.window} '
                                      f'queue_size:=2{"".join(" " + p for p in args.param)}`, '
                                      'camera_info given; a fresh node per run',
                              'Sequences': f'{args.frames} frames 640x480 per run (image '
                                           'stamps 30 frames/s), published at each rate on a '
                                           'steady clock',
                              'Wall time': f'{time.monotonic() - t0:.0f} s; load average '
                                           f'(1 min) at start {load[0]:.1f}'}, revision),
        '## Over the seeds',
        '',
        common.markdown_table(['scene', 'method', 'rate Hz', 'runs', 'wrong % (mean)',
                               'wrong % (worst)', 'per frame (mean)', '-1 % (mean)',
                               'omega err % (median over boxes)', 'boxes with omega err <= 5%',
                               'answered share', 'wrong % of the solved frames (mean)',
                               'solved share', f'wrong % from frame {SETTLED_FRAME} (mean)',
                               f'-1 % from frame {SETTLED_FRAME} (mean)'],
                              summary_rows(records)),
        '',
        '## Every run',
        '',
        common.markdown_table(HEADERS, build_rows(records)),
        '',
        __doc__.split('\n\n', 1)[1].strip(),
        ''])
    common.write_report('live', args.out, text)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
