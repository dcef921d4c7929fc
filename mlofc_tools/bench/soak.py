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
Soak test: many frames through one :class:`~mlofc_ros.pipeline.Pipeline`, memory watched.

A rendered sequence (``--boxes`` boxes + background, ``--size``, ``--loop`` frames) is played in
a loop with monotonic stamps (1/30 s apart, so every loop is a jump in the image the tracker
has to restart from, not a stamp reset). Resident memory (``VmRSS`` of ``/proc/self/status``)
is sampled at the start, every ``--every`` frames and at the end; the report (``README.md``) is
rewritten at every sample, so an interrupted run still leaves its numbers. Memory is flat when
the end RSS minus the RSS after the first block (allocator and caches warmed up) is small.

Run ``python -m mlofc_tools.bench soak --frames 10000``.
"""
import argparse
import math
import os
import sys
import time
from typing import Dict, List, Optional, Sequence

# importing any mlofc_ros module first runs mlofc_ros/__init__ (one BLAS thread)
from mlofc_tools.bench import common
import numpy as np


def rss_mb(field: str = 'VmRSS') -> float:
    """
    Resident memory of this process from ``/proc/self/status`` (MB = 2**20 bytes).

    ``field`` is ``VmRSS`` (now) or ``VmHWM`` (peak). NaN where ``/proc`` is missing.
    """
    try:
        with open('/proc/self/status') as f:
            for line in f:
                if line.startswith(field + ':'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='python -m mlofc_tools.bench soak',
                                 description='Pipeline soak test: RSS over many frames.')
    ap.add_argument('--frames', type=int, default=10000, help='frames to process (10000)')
    ap.add_argument('--every', type=int, default=1000, help='RSS sample period, frames (1000)')
    ap.add_argument('--size', default='640x480', help='WxH of the rendered frames (640x480)')
    ap.add_argument('--boxes', type=int, default=2, help='moving boxes (2) + background')
    ap.add_argument('--loop', type=int, default=60, help='frames rendered and looped (60)')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--quick', action='store_true',
                    help='smoke run: 20 frames of 320x240, sample every 10')
    ap.add_argument('--out', default=None, help='output folder (default docs/results/soak)')
    args = ap.parse_args(list(argv))
    if args.quick:
        args.frames, args.every, args.size, args.loop = 20, 10, '320x240', 12
    w, _, h = args.size.lower().partition('x')
    args.wh = (int(w), int(h))
    if args.frames < 1 or args.every < 1 or args.loop < 2:
        ap.error('--frames, --every must be >= 1 and --loop >= 2')
    return args


def build_report(args: argparse.Namespace, argv: Sequence[str], samples: List[Dict[str, float]],
                 done: bool, wall: float) -> str:
    """Markdown of the samples so far (``done`` False while the run goes on)."""
    head = common.run_header(
        'Soak: memory over a long run of the pipeline',
        common.command_line('soak', argv),
        {'Scene': f'{args.boxes} boxes + background, {args.wh[0]}x{args.wh[1]}, '
                  f'{args.loop} rendered frames looped (stamps monotonic, 1/30 s apart)',
         'Pipeline': f'`Pipeline(num_bodies={args.boxes + 1})`, other parameters default; '
                     'single thread (cv2.setNumThreads(1), one BLAS thread)',
         'Load average (1 min) at start / now': f'{args.load:.1f} / {os.getloadavg()[0]:.1f}'},
        args.code)
    first, last = samples[0], samples[-1]
    warm = samples[1] if len(samples) > 1 else first
    rate = last['frames'] / wall if wall > 0 else math.nan
    status = ('complete' if done else
              f'**in progress / interrupted** at frame {last["frames"]} of {args.frames}')
    lines = [head, f'Status: {status}. {last["frames"]} frames in {wall:.0f} s '
             f'({rate:.1f} frames/s, {1e3 / rate if rate > 0 else math.nan:.0f} ms/frame '
             'wall, on a shared 2-core machine).', '',
             '## Headline', '',
             f'- RSS start (after import + render, before frame 1): {first["rss"]:.1f} MB',
             f'- RSS after {warm["frames"]} frames: {warm["rss"]:.1f} MB',
             f'- RSS end ({last["frames"]} frames): {last["rss"]:.1f} MB; peak (VmHWM) '
             f'{last["hwm"]:.1f} MB',
             f'- **Growth end - start: {last["rss"] - first["rss"]:+.1f} MB; end - after first '
             f'block: {last["rss"] - warm["rss"]:+.1f} MB** '
             f'({(last["rss"] - warm["rss"]) * 1024 / max(last["frames"] - warm["frames"], 1):.2f}'
             ' kB/frame)',
             f'- Tracks per frame (block median): {warm["tracks"]:.0f} in the first block, '
             f'{last["tracks"]:.0f} in the last (the same frames loop, so growth means tracks '
             'accumulate, e.g. on the static background).', '',
             '## Samples', '',
             common.markdown_table(
                 ['frames', 'RSS MB', 'peak MB', 'ms/frame median (block)',
                  'ms/frame p95 (block)', 'solved %', 'tracks median', 'problems'],
                 [[s['frames'], s['rss'], s['hwm'], s['ms_median'], s['ms_p95'],
                   s['solved'], s['tracks'], int(s['problems'])] for s in samples]),
             'Per-block columns summarise the frames since the previous sample '
             '(`Pipeline.process` `timings["total"]`); `problems` counts frames whose result '
             'reports one.', '']
    return '\n'.join(lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(argv or [])
    args = parse_args(argv)
    args.load = os.getloadavg()[0]
    args.code = common.commit()        # before the run imports the code
    import cv2
    cv2.setNumThreads(1)
    from mlofc_ros.pipeline import Pipeline
    from mlofc_tools.render import render_sequence

    out = common.results_dir('soak', args.out)
    common.eprint(f'soak: rendering {args.loop} frames {args.wh[0]}x{args.wh[1]}')
    seq = render_sequence(args.boxes, args.loop, size=args.wh, motion='camera_centre',
                          background=True, noise_sigma=2.0, seed=args.seed)
    frames = [np.ascontiguousarray(f) for f in seq.frames]
    pipe = Pipeline(num_bodies=args.boxes + 1)
    samples: List[Dict[str, float]] = [{
        'frames': 0, 'rss': rss_mb(), 'hwm': rss_mb('VmHWM'), 'ms_median': math.nan,
        'ms_p95': math.nan, 'solved': math.nan, 'tracks': math.nan, 'problems': 0}]
    block_ms: List[float] = []
    block_solved: List[bool] = []
    block_tracks: List[int] = []
    block_problems = 0
    path = out / common.REPORT_NAME
    t0 = time.monotonic()
    for i in range(args.frames):
        r = pipe.process(frames[i % len(frames)], i / 30.0, seq.camera)
        block_ms.append(r.timings.get('total', math.nan))
        block_solved.append(r.solved)
        block_tracks.append(r.n_tracks)
        block_problems += r.problem is not None
        n = i + 1
        if n % args.every == 0 or n == args.frames:
            ms = np.asarray(block_ms)
            samples.append({'frames': n, 'rss': rss_mb(), 'hwm': rss_mb('VmHWM'),
                            'ms_median': float(np.median(ms)),
                            'ms_p95': float(np.percentile(ms, 95)),
                            'solved': 100.0 * float(np.mean(block_solved)),
                            'tracks': float(np.median(block_tracks)),
                            'problems': block_problems})
            block_ms, block_solved, block_tracks, block_problems = [], [], [], 0
            wall = time.monotonic() - t0
            path.write_text(build_report(args, argv, samples, n == args.frames, wall))
            common.eprint(f'soak: {n}/{args.frames} frames, RSS {samples[-1]["rss"]:.1f} MB, '
                          f'{n / wall:.1f} frames/s')
    print(path.read_text())
    return 0


if __name__ == '__main__':
    raise SystemExit(main(sys.argv[1:]))
