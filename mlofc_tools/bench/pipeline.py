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
Per-stage timings of the per-frame pipeline, against OpenCV's LSD alone on the same frames.

For every frame of every sequence, in this order and single-threaded (``cv2.setNumThreads(1)``,
one BLAS thread): decode a ``sensor_msgs/Image``-like object (mono8, and bgr8 separately) with
:func:`~mlofc_ros.image.image_msg_to_gray`; :meth:`Pipeline.process` (its own ``timings``:
detect/track, undistort + window, solve, total); pack the result with
:func:`~mlofc_ros.messages.segment_cloud_fields`; and ``cv2.createLineSegmentDetector().detect``
on the same gray image as the reference. Interleaving the reference with the pipeline frame by
frame exposes both to the same machine load, so their ratio is meaningful on a shared machine
even when absolute milliseconds are not.

Sequences: rendered boxes + background (640x480 and 1280x720 by default) and the real sequences
under ``--real-dir`` (``*/frames/*.png``; visp_cube's ``cube.xml`` gives its intrinsics, the
others have none so the solver estimates the focal length). Statistics skip the first
``window`` frames (window filling). Writes ``README.md`` and ``pipeline.png``
to ``docs/results/pipeline/``.

Run ``python -m mlofc_tools.bench pipeline``.
"""
import argparse
import glob
import math
import os
import pathlib
import re
import sys
import time
from types import SimpleNamespace
from typing import Dict, List, Optional, Sequence, Tuple

# importing any mlofc_ros module first runs mlofc_ros/__init__ (one BLAS thread)
from mlofc_tools.bench import common
from mlofc_tools.datasets.shared import shared_data_dir
import numpy as np

REAL_DIR = os.environ.get('MLOFC_REAL_DIR', str(shared_data_dir() / 'real'))

#: Reported stages: (column key, label). ``other`` = undistort + window + pipeline bookkeeping.
STAGES = (('decode', 'decode mono8'), ('detect_track', 'detect/track'), ('other', 'other'),
          ('solve', 'solve'), ('pack', 'pack msg'))
#: Goal: pipeline / LSD at 640x480.
GOAL_RATIO = 0.5


class Sequence_(SimpleNamespace):
    """A named list of gray frames, their stamps (s), a camera or None, and num_bodies."""


def read_visp_camera(path: str) -> Optional[Tuple[float, float, float, float]]:
    """``(fx, fy, cx, cy)`` px from a ViSP ``<camera>`` block (``px, py, u0, v0``), else None."""
    try:
        text = open(path).read()
    except OSError:
        return None
    vals = {}
    for key in ('px', 'py', 'u0', 'v0'):
        m = re.search(rf'<camera>.*?<{key}>\s*([-+0-9.eE]+)\s*</{key}>', text, re.S)
        if not m:
            return None
        vals[key] = float(m.group(1))
    return vals['px'], vals['py'], vals['u0'], vals['v0']


def read_real_sequence(folder: str, max_frames: Optional[int] = None
                       ) -> Tuple[List[np.ndarray], Optional[Tuple[float, float, float, float]]]:
    """
    Read the gray frames of a real sequence and its ViSP intrinsics.

    ``folder``: the sequence's folder, ``frames/*.png`` and optionally a ViSP ``*.xml``.
    Returns the readable frames in name order (the first ``max_frames``) and
    ``(fx, fy, cx, cy)`` px, or None without an xml file.
    """
    import cv2
    files = sorted(glob.glob(os.path.join(folder, 'frames', '*.png')))[:max_frames]
    frames = [cv2.imread(f, cv2.IMREAD_GRAYSCALE) for f in files]
    xml = sorted(glob.glob(os.path.join(folder, '*.xml')))
    return [f for f in frames if f is not None], (read_visp_camera(xml[0]) if xml else None)


def real_sequences(root: str, max_frames: int) -> List[Sequence_]:
    """Load the real sequences under ``root`` (``<name>/frames/*.png``), gray, 30 Hz stamps."""
    out = []
    for d in sorted(glob.glob(os.path.join(root, '*', 'frames'))):
        frames, camera = read_real_sequence(os.path.dirname(d), max_frames)
        if len(frames) < 3:
            continue
        name = os.path.basename(os.path.dirname(d))
        out.append(Sequence_(name=name, frames=frames,
                             stamps=[i / 30.0 for i in range(len(frames))], camera=camera,
                             num_bodies=2, kind='real'))
    return out


def rendered_sequences(sizes: Sequence[Tuple[int, int]], frames: int, boxes: int,
                       seed: int) -> List[Sequence_]:
    """Render boxes + background at each size (``camera_centre`` motion, noise 2)."""
    from mlofc_tools.render import render_sequence
    out = []
    for w, h in sizes:
        seq = render_sequence(boxes, frames, size=(w, h), motion='camera_centre',
                              background=True, noise_sigma=2.0, seed=seed)
        out.append(Sequence_(name=f'rendered {w}x{h}', frames=list(seq.frames),
                             stamps=list(seq.stamps), camera=seq.camera,
                             num_bodies=boxes + 1, kind='rendered'))
    return out


def image_message(img: np.ndarray, encoding: str) -> SimpleNamespace:
    """Build a ``sensor_msgs/Image``-like object (fields only) holding ``img`` as ``encoding``."""
    from mlofc_ros.image import gray_to_image_fields
    fields = gray_to_image_fields(img, encoding)
    fields['data'] = bytes(fields['data'])
    return SimpleNamespace(**fields)


def run_sequence(seq: Sequence_, params: Optional[Dict[str, object]] = None
                 ) -> Dict[str, np.ndarray]:
    """
    Time every stage on every frame of ``seq``; returns ms arrays per key (one per frame).

    ``params``: :class:`Pipeline` parameters (node names) on top of the defaults.

    Keys: ``decode`` (mono8), ``decode_bgr8``, ``detect_track``, ``undistort``, ``window``,
    ``solve``, ``other`` (``total`` minus detect/track and solve), ``total`` (the whole
    ``Pipeline.process``), ``pack``, ``end_to_end`` (decode + process + pack), ``lsd``,
    ``segments`` and ``tracks`` (counts).
    """
    import cv2

    from mlofc_ros.image import image_msg_to_gray
    from mlofc_ros.messages import segment_cloud_fields
    from mlofc_ros.pipeline import Pipeline

    pipe = Pipeline(**dict(params or {}, num_bodies=seq.num_bodies))
    lsd = cv2.createLineSegmentDetector()
    rows: Dict[str, List[float]] = {k: [] for k in (
        'decode', 'decode_bgr8', 'detect_track', 'undistort', 'window', 'solve', 'other',
        'total', 'pack', 'end_to_end', 'lsd', 'total_cpu', 'lsd_cpu', 'segments', 'tracks',
        'solved', 'detected')}
    clock, cpu = time.perf_counter, time.thread_time
    for gray, stamp in zip(seq.frames, seq.stamps):
        mono = image_message(gray, 'mono8')
        bgr = image_message(cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR), 'bgr8')
        t = clock()
        decoded = image_msg_to_gray(mono)
        decode = (clock() - t) * 1e3
        t = clock()
        image_msg_to_gray(bgr)
        rows['decode_bgr8'].append((clock() - t) * 1e3)
        c = cpu()
        r = pipe.process(decoded, stamp, seq.camera)
        rows['total_cpu'].append((cpu() - c) * 1e3)
        t = clock()
        segment_cloud_fields(r.segments, r.track_ids, r.labels, r.residuals)
        pack = (clock() - t) * 1e3
        t, c = clock(), cpu()
        lsd.detect(gray)
        rows['lsd'].append((clock() - t) * 1e3)
        rows['lsd_cpu'].append((cpu() - c) * 1e3)
        tm = r.timings
        rows['decode'].append(decode)
        rows['pack'].append(pack)
        for k in ('detect_track', 'undistort', 'window', 'solve', 'total'):
            rows[k].append(tm.get(k, math.nan))
        rows['other'].append(tm['total'] - tm['detect_track'] - tm['solve'])
        rows['end_to_end'].append(decode + tm['total'] + pack)
        rows['segments'].append(len(r.segments))
        rows['tracks'].append(r.n_tracks)
        rows['solved'].append(float(r.solved))
        rows['detected'].append(float(tm.get('detect', 0.0) > 0.0))
    return {k: np.asarray(v, dtype=np.float64) for k, v in rows.items()}


def count_calls(seq: Sequence_, params: Optional[Dict[str, object]] = None
                ) -> Dict[str, np.ndarray]:
    """
    Python-level calls per frame of ``Pipeline.process`` on ``seq`` (cProfile's count).

    Every function call the profiler sees, numpy's and OpenCV's C functions included: at the
    pipeline's sizes each costs mostly its fixed overhead, so the count is the part of a
    frame's cost that does not depend on the machine. Returns ``calls`` and ``detected`` (1.0
    where the tracker ran the detector), one per frame.
    """
    import cProfile
    import pstats

    from mlofc_ros.pipeline import Pipeline

    pipe = Pipeline(**dict(params or {}, num_bodies=seq.num_bodies))
    calls, detected = [], []
    for gray, stamp in zip(seq.frames, seq.stamps):
        prof = cProfile.Profile()
        prof.enable()
        r = pipe.process(gray, stamp, seq.camera)
        prof.disable()
        calls.append(float(pstats.Stats(prof).total_calls))
        detected.append(float(r.timings.get('detect', 0.0) > 0.0))
    return {'calls': np.asarray(calls), 'detected': np.asarray(detected)}


def _calls_rows(seqs: Sequence[Sequence_], res: Dict[str, Dict[str, np.ndarray]],
                calls: Dict[str, Dict[str, np.ndarray]], skip: int) -> List[List[object]]:
    """Rows of the calls table: per sequence, frames without and with detection."""
    rows: List[List[object]] = []
    for s in seqs:
        if s.name not in calls:
            continue
        c = {k: _steady(v, skip) for k, v in calls[s.name].items()}
        r = {k: _steady(v, skip) for k, v in res[s.name].items()}
        row: List[object] = [s.name]
        # the count's own detection frames select the timed pass's CPU too (same frames)
        for m in (c['detected'] == 0, c['detected'] > 0):
            n = c['calls'][m]
            row += [int(m.sum()), int(round(_med(n))) if n.size else '-',
                    f'{int(n.min())}-{int(n.max())}' if n.size else '-',
                    1e3 * _med(r['total_cpu'][m]) / _med(n) if n.size else math.nan]
        rows.append(row)
    return rows


def _steady(values: np.ndarray, skip: int) -> np.ndarray:
    return values[skip:] if len(values) > skip + 1 else values


def _med(v: np.ndarray) -> float:
    return float(np.median(v)) if len(v) else math.nan


def _p95(v: np.ndarray) -> float:
    return float(np.percentile(v, 95)) if len(v) else math.nan


def _split_row(r: Dict[str, np.ndarray]) -> List[object]:
    """Return count, median ms, x median LSD and share of the time of detection frames, others."""
    det = r['detected'] > 0
    total, lsd = float(np.sum(r['total'])), _med(r['lsd'])
    out: List[object] = []
    for m in (det, ~det):
        t = r['total'][m]
        med = _med(t)                            # NaN for no frames, and so is its ratio
        out += [int(m.sum()), med, med / lsd, float(np.sum(t)) / total if total > 0 else math.nan]
    return out


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='python -m mlofc_tools.bench pipeline',
                                 description='Per-stage pipeline timings vs LSD alone.')
    ap.add_argument('--sizes', default='640x480,1280x720', help='rendered sizes, WxH,...')
    ap.add_argument('--frames', type=int, default=60, help='rendered frames per size (60)')
    ap.add_argument('--boxes', type=int, default=2, help='moving boxes (2) + background')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--real-dir', default=REAL_DIR, help='real sequences (*/frames/*.png)')
    ap.add_argument('--real-frames', type=int, default=80, help='max frames per real sequence')
    ap.add_argument('--method', default=None, help='solver method (default: the default)')
    common.add_param_option(ap, 'num_bodies is')
    ap.add_argument('--no-calls', dest='count_calls', action='store_false',
                    help='skip the count of calls per frame (a profiled second pass over the '
                         'first rendered sequence)')
    ap.add_argument('--quick', action='store_true',
                    help='smoke run: 7 frames of 320x240, no real sequence')
    ap.add_argument('--out', default=None, help='output folder (default docs/results/pipeline)')
    args = ap.parse_args(list(argv))
    args.params = common.parse_param_option(ap, args)
    if args.method:
        args.params['method'] = args.method
    if args.quick:
        args.sizes, args.frames, args.real_frames = '320x240', 7, 0
    args.wh = []
    for s in args.sizes.split(','):
        w, sep, h = s.strip().lower().partition('x')
        if not sep:
            ap.error(f'bad size {s!r}, expected WxH')
        args.wh.append((int(w), int(h)))
    return args


def plot(path: 'os.PathLike', names: Sequence[str], med: Dict[str, Dict[str, float]],
         estimated_f: Sequence[bool]) -> None:
    """
    Stacked bars of the median stage times per sequence, LSD alone next to each.

    Sequences with a known camera and those whose focal length is estimated (much slower
    solver) go on separate panels, each with its own scale.
    """
    groups = [[n for n, e in zip(names, estimated_f) if not e],
              [n for n, e in zip(names, estimated_f) if e]]
    groups = [g for g in groups if g]
    fig, axes = common.new_figure(len(groups), width_per_panel=max(4.5, 1.7 * max(map(
        len, groups))), height=4.2)
    for gi, (ax, group) in enumerate(zip(axes, groups)):
        x = np.arange(len(group))
        bottom = np.zeros(len(group))
        for i, (key, label) in enumerate(STAGES):
            vals = np.array([med[n][key] for n in group])
            ax.bar(x - 0.2, vals, 0.38, bottom=bottom, label=label, color=f'C{i}')
            bottom += vals
        ax.bar(x + 0.2, [med[n]['lsd'] for n in group], 0.38, label='LSD alone (reference)',
               color='0.45', hatch='//')
        for k, n in enumerate(group):
            ax.text(x[k] - 0.2, bottom[k], f'{med[n]["ratio"]:.2f}x', ha='center',
                    va='bottom', fontsize=8)
        ax.set_xticks(x)
        ax.set_xticklabels([n.replace('rendered ', 'rendered\n') for n in group], fontsize=8)
        ax.set_ylabel('median ms per frame (stages stacked)')
        known = med[group[0]].get('estimated_f') is False
        ax.set_title(('camera given' if known else 'focal length estimated')
                     + ' (label: process / LSD)', fontsize=10)
        ax.grid(True, axis='y', alpha=0.3)
        top = max(float(bottom.max()), max(med[n]['lsd'] for n in group))
        ax.set_ylim(0, 1.45 * top)       # room for the legend above the bars
        if gi == 0:
            ax.legend(fontsize=7, loc='upper left', ncol=2)
    common.save_figure(fig, path)


def build_report(args: argparse.Namespace, argv: Sequence[str], seqs: Sequence[Sequence_],
                 res: Dict[str, Dict[str, np.ndarray]], skip: int, wall: float,
                 calls: Optional[Dict[str, Dict[str, np.ndarray]]] = None) -> str:
    """Return the Markdown report of the timed runs ``res`` (and the call counts ``calls``)."""
    head = common.run_header(
        'Pipeline: per-stage timings vs LSD alone', common.command_line('pipeline', argv),
        {'Threads': 'single (`cv2.setNumThreads(1)`, one BLAS thread); the machine is shared, '
                    'so compare ratios to the LSD reference measured in the same run on the '
                    'same frames, not absolute ms across runs',
         'Parameters': ', '.join(f'`{k}:={v}`' for k, v in args.params.items())
                       or 'node defaults',
         'Wall time': f'{wall:.0f} s',
         'Load average (1 min) at start / end': f'{args.load:.1f} / {os.getloadavg()[0]:.1f}'},
        args.code)
    rows, stage_rows, split_rows = _table_rows(seqs, res, skip)
    lines = [head] + _headline(rows)
    lines += _pipeline_tables(rows, split_rows, skip)
    calls_rows = _calls_rows(seqs, res, calls or {}, skip)
    if calls_rows:
        lines += ['## Calls per frame (machine-independent)', '',
                  common.markdown_table(
                      ['sequence', 'frames without detection', 'calls (median)',
                       'calls (range)', 'us CPU per call', 'detection frames',
                       'calls (median)', 'calls (range)', 'us CPU per call'], calls_rows),
                  'Python-level calls of `Pipeline.process` per frame, numpy and OpenCV '
                  "functions included (`cProfile`'s count, a second pass over the same frames); "
                  'us CPU per call: the median process CPU time of those frames in the timed '
                  'pass over the median count. At these array sizes most calls cost their fixed '
                  'overhead, so fewer calls is what makes a frame cheaper on every machine.', '']
    lines += ['## Stages (median / p95 ms per frame)', '',
              common.markdown_table(
                  ['sequence', 'decode mono8', 'decode bgr8', 'detect/track', 'undistort',
                   'window', 'other (in process)', 'solve', 'pack msg', 'process total',
                   'LSD alone'], stage_rows),
              '- decode: `image_msg_to_gray` on a message-like object (mono8; bgr8 separately, '
              'not part of the pipeline total).',
              '- detect/track, undistort, window, solve: `FrameResult.timings`; other = process '
              'total - detect/track - solve (undistort, window, body ids, bookkeeping).',
              '- pack msg: `segment_cloud_fields` (the `~/segments` PointCloud2 payload).',
              '- LSD alone: `cv2.createLineSegmentDetector().detect` (default parameters, '
              'full resolution) on the same gray frame, timed right after the pipeline.', '',
              '![stages](pipeline.png)', '']
    return '\n'.join(lines)


def _table_rows(seqs: Sequence[Sequence_], res: Dict[str, Dict[str, np.ndarray]], skip: int
                ) -> Tuple[List[List[object]], List[List[object]], List[List[object]]]:
    """Return the rows of the whole-pipeline, stage and detection-split tables."""
    rows, stage_rows, split_rows = [], [], []
    for s in seqs:
        r = {k: _steady(v, skip) for k, v in res[s.name].items()}
        split_rows.append([s.name] + _split_row(r))
        ratio = _med(r['total']) / _med(r['lsd'])
        h, w = s.frames[0].shape
        cam = 'given' if s.camera is not None else 'none (f estimated)'
        rows.append([s.name, f'{w}x{h}', len(r['total']), s.num_bodies, cam,
                     _med(r['tracks']), _med(r['total']), _p95(r['total']),
                     _med(r['end_to_end']), _med(r['lsd']), _p95(r['lsd']), ratio,
                     _med(r['end_to_end']) / _med(r['lsd']), _med(r['total_cpu']),
                     _med(r['lsd_cpu']), _med(r['total_cpu']) / _med(r['lsd_cpu']),
                     _med(r['detect_track']) / _med(r['lsd']),
                     _med(r['solve']) / _med(r['total']),
                     float(np.mean(r['total'])), float(np.mean(r['lsd'])),
                     float(np.mean(r['total']) / np.mean(r['lsd'])),
                     f"{int(r['detected'].sum())} / {len(r['detected'])}"])
        stage_rows.append([s.name] + [f'{_med(r[k]):.3g} / {_p95(r[k]):.3g}' for k in (
            'decode', 'decode_bgr8', 'detect_track', 'undistort', 'window', 'other', 'solve',
            'pack', 'total', 'lsd')])
    return rows, stage_rows, split_rows


def _headline(rows: Sequence[Sequence[object]]) -> List[str]:
    """Return the headline: the first rendered 640x480 sequence against the goal."""
    first = next((rw for rw in rows if rw[1] == '640x480' and rw[0].startswith('rendered')),
                 rows[0] if rows else None)
    if first is None:
        return []
    verdict = 'met' if first[11] <= GOAL_RATIO else 'NOT met'
    verdict_mean = 'met' if first[20] <= GOAL_RATIO else 'NOT met'
    return ['## Headline', '',
            f'- {first[0]}: `Pipeline.process` median **{first[6]:.1f} ms** (p95 '
            f'{first[7]:.1f}), LSD alone {first[9]:.1f} ms on the same frames: ratio '
            f'**{first[11]:.2f}** (goal <= {GOAL_RATIO:g} on the median: {verdict}); '
            f'decode + process + '
            f'pack {first[8]:.1f} ms.',
            f'- Same frames in CPU time (`time.thread_time`, less sensitive to the load '
            f'of the shared machine): process {first[13]:.1f} ms, LSD {first[14]:.1f} ms, '
            f'ratio **{first[15]:.2f}**.',
            f'- The front end alone (detect/track) is {first[16]:.2f} x LSD; the solver '
            f'takes {100 * first[17]:.0f} % of `Pipeline.process` (median ratio).',
            f'- Throughput (mean over frames, which counts the detection frames: the '
            f'tracker runs the detector on {first[21]} frames here): process '
            f'{first[18]:.1f} ms ({1000.0 / first[18]:.0f} frames/s), LSD '
            f'{first[19]:.1f} ms: ratio of means **{first[20]:.2f}** (goal <= '
            f'{GOAL_RATIO:g} on the mean: {verdict_mean}).', '']


def _pipeline_tables(rows: Sequence[Sequence[object]], split_rows: Sequence[Sequence[object]],
                     skip: int) -> List[str]:
    """Return the whole-pipeline table and the split by detection frames."""
    return ['## Whole pipeline vs LSD', '',
            common.markdown_table(
                ['sequence', 'size', 'frames', 'bodies', 'camera', 'tracks (median)',
                 'process median ms', 'process p95 ms', 'decode+process+pack median ms',
                 'LSD median ms', 'LSD p95 ms', 'process / LSD', 'end-to-end / LSD',
                 'process CPU ms', 'LSD CPU ms', 'process / LSD (CPU)',
                 'detect/track / LSD', 'solve share', 'process mean ms', 'LSD mean ms',
                 'process / LSD (means)', 'detection frames'], rows),
            f'Statistics over frames >= {skip} (the first `window` frames fill the window). '
            'Ratios are of medians unless marked means. `process` is `Pipeline.process` '
            '(`timings["total"]`); CPU '
            'columns are the same calls timed with `time.thread_time` (the machine is shared: '
            'wall time includes waiting for a core). Solve share = median solve / median '
            'process.', '',
            '## Where the mean goes: frames with and without detection', '',
            common.markdown_table(
                ['sequence', 'detection frames', 'median ms', 'x LSD (median)',
                 'share of process time', 'other frames', 'median ms', 'x LSD (median)',
                 'share of process time'], split_rows),
            'A frame runs the detector when the tracker asks for it (detection on demand: '
            'every `detect_every`-th frame while new edges appear, up to every '
            '`detect_every_max`-th in a quiet scene). x LSD: the median '
            '`Pipeline.process` over the median LSD of all frames.', '']


def _plot_stages(path: pathlib.Path, seqs: Sequence[Sequence_],
                 res: Dict[str, Dict[str, np.ndarray]], skip: int) -> None:
    """Plot the median stage times of every sequence against LSD."""
    plot(path, [s.name for s in seqs],
         {s.name: dict({k: _med(_steady(res[s.name][k], skip)) for k, _ in STAGES},
                       lsd=_med(_steady(res[s.name]['lsd'], skip)),
                       ratio=_med(_steady(res[s.name]['total'], skip))
                       / _med(_steady(res[s.name]['lsd'], skip)),
                       estimated_f=s.camera is None) for s in seqs},
         [s.camera is None for s in seqs])


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(argv or [])
    args = parse_args(argv)
    args.load = os.getloadavg()[0]
    args.code = common.commit()       # before the runs import the code
    import cv2
    cv2.setNumThreads(1)
    from mlofc_ros import params
    from mlofc_ros.pipeline import window_frames

    t0 = time.monotonic()
    common.eprint('pipeline: rendering', ', '.join(f'{w}x{h}' for w, h in args.wh))
    seqs = rendered_sequences(args.wh, args.frames, args.boxes, args.seed)
    if args.real_frames > 0 and args.real_dir:
        seqs += real_sequences(args.real_dir, args.real_frames)
    skip = window_frames(dict(params.defaults(), **args.params))
    res = {}
    for s in seqs:
        common.eprint(f'pipeline: {s.name} ({len(s.frames)} frames)')
        res[s.name] = run_sequence(s, args.params)
        r = res[s.name]
        common.eprint(f'  process median {_med(r["total"]):.1f} ms, LSD {_med(r["lsd"]):.1f} ms')
    calls = {}
    if args.count_calls and seqs and seqs[0].kind == 'rendered':
        common.eprint(f'pipeline: counting calls on {seqs[0].name}')
        calls[seqs[0].name] = count_calls(seqs[0], args.params)
    report = build_report(args, argv, seqs, res, skip, time.monotonic() - t0, calls)
    _plot_stages(common.results_dir('pipeline', args.out) / 'pipeline.png', seqs, res, skip)
    common.write_report('pipeline', args.out, report)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
