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
The number of bodies found online (``num_bodies=0``): a line stream that changes, real video.

Run ``python -m mlofc_tools.bench count``; writes ``README.md``, ``counts.png`` and a picture
per real sequence to ``docs/results/count/``.

Every stream goes through ``mlofc_ros.pipeline.Pipeline`` frame by frame (stamps at 30
frames/s) with ``num_bodies=0`` (:mod:`mlofc_ros.counting`) and again with the count given,
per solver method (``--methods``; each in its own window, :attr:`.Method.window`: 5 for
``robust``, 10 for ``general`` and ``auto``, which solves with the rotation model on the last
5 until the scene translates):

- **scheduled** (:func:`mlofc_tools.synthetic.scheduled_scene`, seeds 0-5): line tracks of a
  still background (120 lines) and three boxes of 40 lines rotating about the camera centre
  at 0.2-0.4 deg per frame, 60 frames, 0.5 px noise, f known: box 1 starts moving at frame
  15, box 2 stops at frame 30, box 3 leaves the view at frame 45. The true count at a frame
  is the background plus the boxes in view that moved since the frame before. Scored as
  issue #40 asks: the share of the frames at least 10 frames after the last change with the
  right count (the bodies solved in the frame with at least ``MIN_BODY_TRACKS`` tracks: the
  twists the node publishes), and the ids: the background keeps its id,
  the box that starts gets an id no body had, the box that stops takes the background's,
  the id of the box that left is not given to another body. The known-count run has
  ``num_bodies=4`` (the most bodies at any time).
- **Hopkins155** line tracks (the 155 sequences, lines built as ``bench hopkins_stream``
  does, window K = 5, f unknown) streamed through ``Pipeline.process_lines`` with each of
  ``--hopkins-methods`` (``robust``, ``general``), the count unknown and known: from the
  first full window on, the share of frames
  whose count is right and the misclassification (bodies matched one to one to the true
  motions; a body found beyond them is wrong; issue #40: right in 90% of the frames, at most
  1.25x the known-count misclassification). Beside it, the score alone
  (:func:`score_preference`): on three windows per sequence, how often the true count,
  solved from the true labels, holds against one body less and one more solved from
  scratch, compared as the online count compares them: what an online count deciding by
  this score can hope for.
- **real**: ``visp_cube`` (still until frame 38, then the sheet with the cube and the
  cylinder dragged by a hand: one body while still, two while it moves), ``rubik_cube`` (the
  cube turning on a turntable: two) and ``hamburg_taxi`` (three vehicles and the
  background), calibrated where a camera file exists (``visp_cube``), else f estimated;
  the known count 2, 2 and 4. Beside the counts, the share of the moving segments on a body
  apart from the still scene's (:func:`moving_apart`, bench real's motion proxy; visp_cube
  frames 48-79, hamburg_taxi 10-39), whatever the count, automatic and given: a count can be
  right with the moving thing on the background's body, or one more with it apart (a hand).

Cost: CPU (``time.thread_time``) of ``Pipeline.process`` per frame from the first full
window: the automatic count's mean against the known count's on the same frames, and its
largest frame against its median (issue #40: at most 1.5x and 5x).
"""
import argparse
import math
import os
import sys
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple
import zlib

import cv2
from mlofc_ros.counting import score_noise, scores_better
from mlofc_ros.pipeline import FrameResult, Pipeline, window_frames
from mlofc_ros.solver import segment_lines
from mlofc_ros.solver.model_selection import min_body_lines, track_dof
from mlofc_tools.bench import common
from mlofc_tools.bench.hopkins_runs import LINES_PER_MOTION, MAX_USES, MIN_LENGTH_PX
from mlofc_tools.bench.pipeline import read_real_sequence, REAL_DIR
from mlofc_tools.bench.real import (LAG, MOVING_PX, render_strip, STILL_PX, track_motion,
                                    track_table)
from mlofc_tools.datasets import hopkins as hk
from mlofc_tools.scoring import misclassification, misclassification_any
from mlofc_tools.synthetic import scheduled_scene
import numpy as np

#: Frame rate of the stamps.
FPS = 30.0
#: The scheduled stream: ``(start, stop, leave)`` per box (see the module docstring).
SCHEDULE = [(15, 10 ** 6, 10 ** 6), (0, 30, 10 ** 6), (0, 10 ** 6, 45)]
FRAMES = 60
#: Frames where the true count changes (the stream's start counts as one).
CHANGES = [0, 16, 31, 45]
#: Frames after a change before the count is scored.
SETTLE = 10
#: Frames per window of the Hopkins155 streams (``bench hopkins_stream``'s K).
HOPKINS_K = 5
#: Single windows per Hopkins155 sequence on which the count's score is checked alone.
SCORED_WINDOWS = 3
#: Real sequences seen by a still camera: name -> the frames where something moves (scored
#: by :func:`moving_apart`; not rubik_cube, whose turntable turns with the cube, its round
#: edges still in the image).
MOVING_FRAMES = {'visp_cube': (48, 80), 'hamburg_taxi': (10, 40)}
#: Real sequences: name -> (known count, frames shown in the picture).
REAL = {'visp_cube': (2, (30, 50, 70)), 'rubik_cube': (2, (8, 14, 20)),
        'hamburg_taxi': (4, (12, 24, 36))}


def frame_count(result: FrameResult) -> int:
    """Return the bodies of a frame: those solved with enough tracks (twist published or not)."""
    return int(np.sum(result.body_solved))


def stream_run(seed: int, method: str, num_bodies: int = 0) -> Dict[str, Any]:
    """
    Run the scheduled stream of ``seed``; per frame the count, the true one, ids, CPU ms.

    ``ids``: per frame ``{true body: published id held by most of its lines}`` (-1 none).
    """
    sc = scheduled_scene(SCHEDULE, FRAMES, seed=seed, rotation_deg=(0.2, 0.4))
    p = Pipeline(num_bodies=num_bodies, method=method)       # the method's own window
    track_ids = np.arange(len(sc.tracks))
    out: Dict[str, Any] = {'count': [], 'want': [], 'ids': [], 'ms': []}
    for k in range(FRAMES):
        seen = np.isfinite(sc.tracks[:, k, 0])
        t = time.thread_time()
        r = p.process_lines(track_ids[seen], sc.tracks[seen, k], k / FPS, sc.image_size,
                            camera=sc.intrinsics)
        out['ms'].append((time.thread_time() - t) * 1e3)
        out['count'].append(frame_count(r))
        out['want'].append(1 + int(np.sum(sc.moving[1:, k] & sc.visible[1:, k])))
        truth = sc.labels[seen]
        out['ids'].append({b: int(np.bincount(r.labels[truth == b] + 1).argmax()) - 1
                           for b in range(len(SCHEDULE) + 1) if np.any(truth == b)})
    return out


def score_stream(run: Dict[str, Any]) -> Dict[str, Any]:
    """Return the share of settled frames with the right count and the id checks."""
    last = np.array([max(c for c in CHANGES if c <= k) for k in range(FRAMES)])
    scored = np.arange(FRAMES) - last >= SETTLE
    right = np.array(run['count']) == np.array(run['want'])
    ids = run['ids']
    start, stop, leave = (s[i] for s, i in zip(SCHEDULE, (0, 1, 2)))
    background = ids[SETTLE][0]
    before = {i for frame in ids[:start] for i in frame.values()}
    gone = ids[leave - 1][3]
    delays = []
    for c in CHANGES[1:]:
        ok = np.flatnonzero(right[c:])
        delays.append(int(ok[0]) if ok.size else None)
    return {
        'right': float(right[scored].mean()),
        'delays': delays,
        'background_kept': all(f[0] == background for f in ids[SETTLE:]),
        'new_id_fresh': ids[start + SETTLE][1] not in before,
        'stopped_joins_background': all(f[2] == background for f in ids[stop + SETTLE:]),
        'left_id_unused': all(gone not in f.values() for f in ids[leave + 1:]),
    }


def hopkins_sequence(item: Tuple[str, str]) -> Dict[str, Any]:
    """
    Stream one Hopkins155 sequence with the count unknown and known (worker).

    ``item``: ``(path, method)``. Returns ``name``, ``n``, per full window ``count`` (bodies
    solved), ``auto`` and ``known`` (misclassification), and the CPU ms per frame of each.
    """
    path, method = item
    seq = hk.load_sequence(path)
    n = seq.n_motions
    s = int(np.random.SeedSequence([155, zlib.crc32(seq.name.encode())])
            .generate_state(1)[0] % (2 ** 31))
    tracks, truth = hk.line_tracks(seq, LINES_PER_MOTION, None, MIN_LENGTH_PX, seed=s,
                                   max_uses=MAX_USES)
    ids = np.arange(tracks.shape[0])
    rec: Dict[str, Any] = {'name': seq.name, 'n': n, 'method': method, 'count': []}
    for key, num_bodies in (('auto', 0), ('known', n)):
        pipe = Pipeline(num_bodies=num_bodies, window=HOPKINS_K, method=method, seed=s)
        errors, ms = [], []
        for t in range(tracks.shape[1]):
            c = time.thread_time()
            res = pipe.process_lines(ids, tracks[:, t], t / FPS, seq.image_size)
            ms.append((time.thread_time() - c) * 1e3)
            if t >= HOPKINS_K - 1:
                errors.append(misclassification_any(res.labels, truth) if num_bodies == 0
                              else misclassification(res.labels, truth, n))
                if num_bodies == 0:
                    rec['count'].append(frame_count(res))
        rec[key], rec[f'{key}_ms'] = errors, ms
    rec['windows'] = score_preference(tracks, truth, n, seq.image_size, method, s)
    return rec


def score_preference(tracks: np.ndarray, truth: np.ndarray, n: int,
                     image_size: Tuple[float, float], method: str, seed: int
                     ) -> List[Tuple[bool, bool]]:
    """
    Return, on single windows, whether the count's score leaves the true count (worker part).

    ``tracks (N, T, 4)``, ``truth (N,)`` of a Hopkins155 sequence with ``n`` motions. On
    :data:`SCORED_WINDOWS` windows of :data:`HOPKINS_K` frames (the first full one, the last,
    evenly between; the tracks seen in all their frames, f unknown) the true count is solved
    from the true labels, one body less and one more from scratch, and compared as
    :class:`~mlofc_ros.counting.BodyCount` compares a trial with the current count: the BIC at
    the richer model's noise level (:func:`~mlofc_ros.counting.score_noise`), a change must
    win by ``SCORE_MARGIN`` under both label priors (:func:`~mlofc_ros.counting.scores_better`),
    a new body needs ``min_body_lines`` tracks. Per window
    ``(fewer, more)``: one body less, one more would be taken. Neither: the score, given the
    true segmentation, keeps the true count.
    """
    out = []
    kw: Dict[str, Any] = {'image_size': image_size, 'method': method, 'seed': seed}
    for t in np.unique(np.linspace(HOPKINS_K - 1, tracks.shape[1] - 1, SCORED_WINDOWS)
                       .astype(int)):
        win = tracks[:, t - HOPKINS_K + 1:t + 1]
        seen = np.all(np.isfinite(win[..., 0]), axis=1)
        win, labels = win[seen], np.unique(truth[seen], return_inverse=True)[1]
        dof = track_dof(win)
        try:
            true = segment_lines(win, n, init_labels=labels, **kw)
            fewer = segment_lines(win, n - 1, **kw)
        except ValueError:
            continue
        try:
            more = segment_lines(win, n + 1, **kw)
            sizes = np.bincount(more.labels[more.labels >= 0], minlength=n + 1)
            more_ok = bool(np.all(sizes >= min_body_lines(dof)))
        except ValueError:
            more_ok = False
        sigma = score_noise(true, dof)
        took_fewer = scores_better(fewer, true, sigma, dof, win)
        took_more = False
        if more_ok:
            sigma = score_noise(more, dof)
            took_more = scores_better(more, true, sigma, dof, win)
        out.append((bool(took_fewer), bool(took_more)))
    return out


def hopkins_table(records: Sequence[Dict[str, Any]]) -> str:
    """Markdown: per method and number of motions, right counts and misclassification."""
    rows = []
    for method, n in sorted({(r['method'], r['n']) for r in records},
                            key=lambda k: (k[0] != 'robust', k)):
        sel = [r for r in records if r['n'] == n and r['method'] == method]
        right = np.mean([np.mean(np.asarray(r['count']) == n) for r in sel])
        auto = np.mean([np.mean(r['auto']) for r in sel])
        known = np.mean([np.mean(r['known']) for r in sel])
        ratio = np.mean([np.mean(r['auto_ms'][HOPKINS_K:]) / np.mean(r['known_ms'][HOPKINS_K:])
                         for r in sel])
        found = np.bincount(np.concatenate([r['count'] for r in sel]), minlength=6)
        windows = np.array([w for r in sel for w in r.get('windows', [])], dtype=bool)
        windows = windows.reshape(-1, 2)
        kept = (f'{100 * np.mean(~windows.any(axis=1)):.0f} ({100 * windows[:, 0].mean():.0f} '
                f'/ {100 * windows[:, 1].mean():.0f})' if len(windows) else '-')
        rows.append([method, n, len(sel), f'{100 * right:.0f}', kept, f'{100 * auto:.1f}',
                     f'{100 * known:.1f}', f'{auto / known:.2f}' if known else '-',
                     f'{ratio:.2f}',
                     ', '.join(f'{c}: {100 * v / found.sum():.0f}%'
                               for c, v in enumerate(found) if v)])
    return common.markdown_table(
        ['method', 'motions', 'sequences', 'right count % of the frames',
         'single windows: the score keeps the true count % (one less / one more taken %)',
         'misclassified % (count unknown)', 'misclassified % (count known)', 'ratio',
         'CPU mean ratio', 'counts found (share of frames)'], rows)


def real_run(frames: Sequence[np.ndarray], camera: Any, method: str, num_bodies: int
             ) -> Dict[str, Any]:
    """Run a real sequence; per frame the count and CPU ms, and the results by frame."""
    p = Pipeline(num_bodies=num_bodies, method=method)       # the method's own window
    out: Dict[str, Any] = {'count': [], 'ms': [], 'results': {}}
    for k, gray in enumerate(frames):
        t = time.thread_time()
        r = p.process(gray, k / FPS, camera=camera)
        out['ms'].append((time.thread_time() - t) * 1e3)
        out['count'].append(frame_count(r))
        out['results'][k] = r
    return out


def cost(auto: Sequence[float], known: Sequence[float], window: int) -> Dict[str, float]:
    """
    Return the automatic count's CPU against the known count's, from the window's end.

    ``mean_ratio``: their means' ratio; ``max_over_median``: the automatic count's largest
    frame over its median, ``known_max_over_median`` the same of the count given (a frame that
    runs the line detector is several times one that does not).
    """
    a, k = np.asarray(auto)[window:], np.asarray(known)[window:]
    return {'mean_ratio': float(a.mean() / k.mean()),
            'max_over_median': float(a.max() / np.median(a)),
            'known_max_over_median': float(k.max() / np.median(k))}


def real_goal(name: str, counts: Sequence[int]) -> str:
    """Return how a real sequence's counts compare with what it shows (see the docstring)."""
    c = np.asarray(counts)
    if name == 'visp_cube':
        still, moving = c[10:38], c[48:]
        return (f'one body in {100 * np.mean(still == 1):.0f}% of the still frames 10-37, '
                f'two in {100 * np.mean(moving == 2):.0f}% of the moving frames 48-79')
    if name == 'rubik_cube':
        return f'two bodies in {100 * np.mean(c[5:] == 2):.0f}% of frames 5-20'
    return (f'{int(np.median(c[10:]))} bodies (median of frames 10-39; the background and '
            f'{int(np.median(c[10:])) - 1} of the 3 vehicles at most)')


def moving_apart(results: Dict[int, FrameResult], frames: Tuple[int, int]) -> float:
    """
    Return the share of the moving segments on a body apart from the still scene's (mean).

    Over the frames ``[first, end)``: a segment that moved more than
    :data:`~mlofc_tools.bench.real.MOVING_PX` over :data:`~mlofc_tools.bench.real.LAG` frames
    (bench real's motion proxy) counts when it is labelled and its body is not the one
    holding most of the still segments (those that moved less than
    :data:`~mlofc_tools.bench.real.STILL_PX`). Whatever the count, a moving thing held by the
    background's body is what a robot would miss. NaN without moving segments.
    """
    shares = []
    for f in range(*frames):
        if f not in results or f - LAG not in results:
            continue
        r = results[f]
        motion = track_motion(track_table(results[f - LAG]), r)
        labels = np.asarray(r.labels, dtype=np.int64)
        with np.errstate(invalid='ignore'):
            moving, still = motion > MOVING_PX, motion < STILL_PX
        held = labels[still & (labels >= 0)]
        background = int(np.bincount(held).argmax()) if held.size else -1
        if moving.any():
            lab = labels[moving]
            shares.append(float(np.mean((lab >= 0) & (lab != background))))
    return float(np.mean(shares)) if shares else math.nan


def build_report(args: argparse.Namespace, argv: Sequence[str], streams: List[Dict[str, Any]],
                 reals: List[Dict[str, Any]], seconds: float, revision: Optional[str],
                 hopkins: Sequence[Dict[str, Any]] = ()) -> str:
    """Return the Markdown report."""
    head = common.run_header(
        'Number of bodies found online', common.command_line('count', argv),
        {'Pipeline': "`num_bodies=0` against the count given; the method's own `window`, "
                     + ', '.join(f"{window_frames({'window': 0, 'method': m})} ({m})"
                                 for m in args.method_list)
                     + f'; stamps at {FPS:g} frames/s',
         'Threads': 'single (`cv2.setNumThreads(1)`); CPU ratios within the same run',
         'Run time': f'{seconds:.0f} s'}, revision)
    rows = []
    for s in streams:
        sc = s['score']
        rows.append([s['method'], s['seed'], f"{100 * sc['right']:.0f}",
                     ', '.join('-' if d is None else str(d) for d in sc['delays']),
                     *('yes' if sc[k] else '**no**' for k in (
                         'background_kept', 'new_id_fresh', 'stopped_joins_background',
                         'left_id_unused')),
                     f"{s['cost']['mean_ratio']:.2f}", f"{s['cost']['max_over_median']:.1f}",
                     f"{s['cost']['known_max_over_median']:.1f}",
                     ''.join(map(str, s['count']))])
    stream_table = common.markdown_table(
        ['method', 'seed', 'right count % (settled frames)', 'frames to the right count '
         'after each change', 'background keeps its id', 'new body, new id',
         'stopped body takes the background id', "left body's id unused",
         'CPU mean / known count', 'CPU max / median', 'the same, count given',
         'count per frame'], rows)
    summary = []
    for method in args.method_list:
        mine = [s for s in streams if s['method'] == method]
        if mine:
            right = [s['score']['right'] for s in mine]
            summary.append(f'- `{method}`: right count in {100 * np.mean(right):.0f}% of the '
                           f'settled frames on the mean, {100 * min(right):.0f}% at worst '
                           '(goal 90%).')
    real_rows = []
    for r in reals:
        apart = ([moving_apart(x['results'], MOVING_FRAMES[r['name']]) for x in (r, r['known'])]
                 if r['name'] in MOVING_FRAMES else [math.nan, math.nan])
        real_rows.append([r['method'], r['name'], real_goal(r['name'], r['count']),
                          *('-' if math.isnan(a) else f'{100 * a:.0f}' for a in apart),
                          f"{r['cost']['mean_ratio']:.2f}", f"{r['cost']['max_over_median']:.1f}",
                          f"{r['cost']['known_max_over_median']:.1f}",
                          ''.join(map(str, r['count']))])
    real_table = common.markdown_table(
        ['method', 'sequence', 'counts', 'moving segments apart from the still scene %',
         'the same with the count given', 'CPU mean / known count', 'CPU max / median',
         'the same, count given', 'count per frame'], real_rows)
    pictures = [f'![{name}]({name}.png)' for name in dict.fromkeys(r['name'] for r in reals)]
    doc = __doc__.split('\n', 2)[2].strip()
    return '\n'.join([
        head, '## Scheduled stream', '', *summary, '', stream_table, '',
        'Frames to the right count: after the box starts (16), stops (31) and leaves (45).', '',
        *(['## Hopkins155 streamed', '', hopkins_table(hopkins), ''] if hopkins else []),
        '## Real video', '', real_table, '', '![counts per frame](counts.png)', '',
        *pictures, '', '## What is measured', '', doc, ''])


def plot(streams: List[Dict[str, Any]], reals: List[Dict[str, Any]], path: Any) -> None:
    """Draw the count per frame: the scheduled streams (with the truth), the real sequences."""
    names = ['scheduled'] + list(dict.fromkeys(r['name'] for r in reals))
    fig, axes = common.new_figure(len(names), width_per_panel=3.6, height=3.2)
    for ax, name in zip(axes, names):
        runs = streams if name == 'scheduled' else [r for r in reals if r['name'] == name]
        for i, r in enumerate(runs):
            label = f"{r['method']} seed {r['seed']}" if name == 'scheduled' else r['method']
            ax.step(np.arange(len(r['count'])), np.asarray(r['count']) + 0.04 * i,
                    where='post', color=f'C{i % 10}', linewidth=1, label=label)
        if name == 'scheduled' and streams:
            ax.step(np.arange(FRAMES), streams[0]['want'], where='post', color='0.2',
                    linestyle='--', linewidth=1.4, label='true')
        ax.set_title(name, fontsize=10)
        ax.set_xlabel('frame')
        ax.set_ylabel('bodies')
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=5, loc='best')
    common.save_figure(fig, path)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """
    Parse the command line of ``python -m mlofc_tools.bench count``.

    Parameters
    ----------
    argv
        The arguments after the benchmark's name.

    """
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench count',
                                description=__doc__.split('\n')[1])
    p.add_argument('--real-dir', default=REAL_DIR, help=f'real sequences (default {REAL_DIR})')
    common.add_methods_option(p, 'robust,general,auto')
    p.add_argument('--seeds', default='0,1,2,3,4,5', help='seeds of the scheduled stream')
    p.add_argument('--hopkins-methods', default='robust,general',
                   help="methods of the Hopkins155 streams (robust,general,auto); '' skips them")
    p.add_argument('--hopkins-sequences', type=int, default=None,
                   help='stream only the first this many Hopkins155 sequences')
    p.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1),
                   help='worker processes of the Hopkins155 streams')
    p.add_argument('--quick', action='store_true',
                   help='smoke run: one seed, one method, two Hopkins155 sequences')
    p.add_argument('--out', default=None, help='output folder (default docs/results/count)')
    args = p.parse_args(list(argv))
    args.seed_list = [int(s) for s in args.seeds.split(',') if s]
    args.method_list = common.method_list(p, args)
    args.hopkins_method_list = [m for m in args.hopkins_methods.split(',') if m]
    if args.quick:
        args.seed_list, args.method_list = args.seed_list[:1], args.method_list[:1]
        args.hopkins_method_list = args.hopkins_method_list[:1]
        args.hopkins_sequences = 2
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    """
    Run the benchmark; return 0.

    Parameters
    ----------
    argv
        The arguments after the benchmark's name (default ``sys.argv[1:]``).

    """
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    revision = common.commit()
    cv2.setNumThreads(1)
    t0 = time.monotonic()
    streams, reals = [], []
    sequences = {name: read_real_sequence(os.path.join(args.real_dir, name)) for name in REAL}
    for method in args.method_list:
        window = window_frames({'window': 0, 'method': method})
        for seed in args.seed_list:
            common.eprint(f'count: scheduled, {method}, seed {seed}')
            run = stream_run(seed, method)
            known = stream_run(seed, method, num_bodies=4)
            run.update(method=method, seed=seed, score=score_stream(run),
                       cost=cost(run['ms'], known['ms'], window))
            streams.append(run)
        for name, (n_known, _) in REAL.items():
            frames, camera = sequences[name]
            if len(frames) < 2 * window:
                common.eprint(f'count: {name} not found in {args.real_dir}; skipped')
                continue
            common.eprint(f'count: {name}, {method}')
            run = real_run(frames, camera, method, 0)
            known = real_run(frames, camera, method, n_known)
            run.update(method=method, name=name, frames=frames, known=known,
                       cost=cost(run['ms'], known['ms'], window))
            reals.append(run)
    hopkins: List[Dict[str, Any]] = []
    if args.hopkins_method_list:
        paths = hk.list_sequences()[:args.hopkins_sequences]
        common.eprint(f'count: {len(paths)} Hopkins155 sequences, '
                      f'{", ".join(args.hopkins_method_list)}')
        hopkins = common.run_parallel(hopkins_sequence, [(str(p), m)
                                                         for m in args.hopkins_method_list
                                                         for p in paths],
                                      args.jobs, 'sequences')
    out_dir = common.results_dir('count', args.out)
    plot(streams, reals, out_dir / 'counts.png')
    for name, (n_known, shown) in REAL.items():
        mine = [r for r in reals if r['name'] == name]
        if not mine:
            continue
        runs = {}
        for r in mine:          # one row per method: automatic, then the count given
            runs[f"{r['method']}, automatic"] = r
            runs[f"{r['method']}, {n_known} given"] = r['known']
        strip = render_strip(mine[0]['frames'], runs, shown)
        if strip is not None:
            cv2.imwrite(str(out_dir / f'{name}.png'), strip, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    common.write_report('count', args.out, build_report(args, argv, streams, reals,
                                                        time.monotonic() - t0, revision,
                                                        hopkins))
    return 0


if __name__ == '__main__':
    sys.exit(main())
