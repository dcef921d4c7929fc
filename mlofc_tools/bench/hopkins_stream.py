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
Hopkins155 line tracks streamed through a method's warm path, as the node solves them.

``python -m mlofc_tools.bench hopkins_stream [--motions 3] [--methods general,auto]
[--sequences ...] [--out DIR]``
writes ``README.md`` to ``docs/results/hopkins_stream/`` (or ``--out``), prints it
(the 35 three-motion sequences by default, ~22 min on 2 cores).

`bench hopkins` solves each K-frame window cold. A node sees the sequence as a stream: one
window per frame, each warm-started from the previous window's labels and motions. Here the
line tracks are built once, in the sequence's first frame
(:func:`mlofc_tools.datasets.hopkins.line_tracks` with all frames, the same pairing rules as
`bench hopkins`), and go frame by frame through
:meth:`mlofc_ros.pipeline.Pipeline.process_lines` (``method='general'``, or each of
``--methods``; ``window`` K = 5 or ``--window``, 0 being each method's own as the node's
default; the node's other defaults): the node's own solve path, body
ids and all. The first frames, until the window holds ``solver.methods.GENERAL_MIN_FRAMES``,
are solved rotation-only; then the first full window is searched (from those labels too) and
every later one is warm-started (from the previous labels and from every track reassigned at
the previous motions, the lower score kept) with every body rescanned; focal length unknown,
estimated per window until ``pipeline.FOCAL_SAMPLES`` estimates, then started at their median
and refined from windows that share no frame (:class:`mlofc_ros.solver.focal.FocalEstimate`).
Scored on the published labels of every full window (a line the solver leaves unassigned keeps
its last body for ``label_memory`` frames, as the node publishes it; ``-1`` counts as wrong).
Stamps are 30 frames/s (only the published rad/s depend on them). Reference on the same lines:
the cold search (as `bench hopkins`, f unknown) at the middle and the last window, and the
floor there (:func:`floor`: every line given to the cheapest of the true motions, each
fitted to its true group by the general model). With
``--methods auto`` each stream starts rotation-only (``'robust'``) and moves to ``'general'``
once the rotation model misfits it (:mod:`mlofc_ros.method_choice`).
"""
import argparse
import os
import time
from typing import Dict, List, Optional, Sequence, Tuple
import zlib

from mlofc_tools.bench import common
from mlofc_tools.bench.hopkins_runs import (LINES_PER_MOTION, MAX_USES, MIN_LENGTH_PX,
                                            n_motions_of, oracle_focal, ORACLE_G,
                                            oracle_general, pick_sequences)
from mlofc_tools.datasets import hopkins as hk
from mlofc_tools.scoring import misclassification
import numpy as np

#: Frames per window (`bench hopkins`'s K = 5).
K = 5
#: Stamps of the streamed frames (frames/s).
FPS = 30.0
QUICK_SEQUENCE = 'three-cars'


def stream_sequence(path: str, seed: int = 155, windows: Optional[int] = None,
                    cold: bool = True, method: str = 'general', window: int = K
                    ) -> Dict[str, object]:
    """
    Stream one sequence through the warm path; per-window misclassification (worker).

    ``windows``: stop after this many (default: to the end of the sequence); ``cold=False``
    skips the cold reference solves; ``method``: the pipeline's (the cold reference is
    always ``'general'``); ``window``: the pipeline's ``window`` parameter (0: the method's
    own, the node's default), frames; the cold reference solves windows as long.

    Returns a record: ``name``, ``method``, ``n``, ``frames``, ``lines``, ``stream`` (the
    misclassification of every window, first to last), ``cold_mid`` / ``cold_last`` (the
    cold search at the middle / last window), ``cpu_warm`` (median CPU s per warm solve).
    """
    from mlofc_ros.pipeline import Pipeline, window_frames
    from mlofc_ros.solver import segment_lines

    size = window_frames({'window': window, 'method': method})
    seq = hk.load_sequence(path)
    n = seq.n_motions
    s = int(np.random.SeedSequence([seed, zlib.crc32(seq.name.encode())])
            .generate_state(1)[0] % (2 ** 31))
    tracks, truth = hk.line_tracks(seq, LINES_PER_MOTION, None, MIN_LENGTH_PX, seed=s,
                                   max_uses=MAX_USES)
    frames = tracks.shape[1]
    ids = np.arange(tracks.shape[0])
    pipe = Pipeline(num_bodies=n, window=window, method=method, seed=s)
    stream, cpu = [], []
    end = frames if windows is None else min(frames, size + windows - 1)
    for t in range(end):                                 # frames, not lines
        c = time.process_time()
        res = pipe.process_lines(ids, tracks[:, t], t / FPS, seq.image_size)
        if t >= size:                                    # warm solves of full windows
            cpu.append(time.process_time() - c)
        if t >= size - 1:
            stream.append(misclassification(res.labels, truth, n))
    rec = {'name': seq.name, 'method': method, 'group': seq.group, 'n': n, 'frames': frames,
           'lines': int(len(truth)), 'stream': stream, 'window': size,
           'cpu_warm': float(np.median(cpu)) if cpu else float('nan')}
    last = frames - size
    for key, start in (('mid', last // 2), ('last', last)) if cold else ():
        window_tracks = tracks[:, start:start + size]
        res = segment_lines(window_tracks, n, intrinsics=None, image_size=seq.image_size,
                            method='general', seed=s)
        rec['cold_' + key] = misclassification(res.labels, truth, n)
        rec['floor_' + key] = floor(window_tracks, truth, n, seq.image_size)
    return rec


def floor(tracks: np.ndarray, truth: np.ndarray, n: int, size: Tuple[int, int]) -> float:
    """
    Misclassification of the true motions: the floor of a window (``bench hopkins``'s).

    ``tracks (N, K, 4)`` the window's line tracks, ``truth (N,)`` their groups in ``[0, n)``.
    Every true group is fitted alone by the general model (rotation and translation,
    marginalised line directions) at the oracle's focal length, and every line goes to its
    cheapest body (``bench hopkins``'s ``oracle general (marginalised directions)``).
    """
    return oracle_general(tracks, truth, n, oracle_focal(tracks, truth, n, size),
                          size)[ORACLE_G]['miscl']


def _unit(item) -> Dict[str, object]:
    return stream_sequence(*item)


def summary_table(records: Sequence[Dict[str, object]]) -> str:
    """Markdown: mean (median) misclassification % per number of motions."""
    lines = ['| method | motions | sequences | every window | middle window | last window '
             '| cold search, middle | cold search, last | floor, middle | floor, last '
             '| CPU s per warm solve (median) |',
             '|:--|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|']

    def cell(v: List[float]) -> str:
        return f'{100 * np.mean(v):.1f} ({100 * np.median(v):.1f})' if v else '-'
    for method, n in dict.fromkeys((r['method'], r['n'])
                                   for r in sorted(records, key=lambda r: r['n'])):
        sel = [r for r in records if r['n'] == n and r['method'] == method]
        mid = [r['stream'][min((r['frames'] - r['window']) // 2, len(r['stream']) - 1)]
               for r in sel]
        ref = {key: [r[key] for r in sel if key in r]
               for key in ('cold_mid', 'cold_last', 'floor_mid', 'floor_last')}
        lines.append(
            f'| {method} | {n} | {len(sel)} | {cell([np.mean(r["stream"]) for r in sel])} '
            f'| {cell(mid)} | {cell([r["stream"][-1] for r in sel])} '
            f'| {cell(ref["cold_mid"])} | {cell(ref["cold_last"])} '
            f'| {cell(ref["floor_mid"])} | {cell(ref["floor_last"])} '
            f'| {np.median([r["cpu_warm"] for r in sel]):.2f} |')
    return '\n'.join(lines)


def sequence_table(records: Sequence[Dict[str, object]]) -> str:
    """Markdown: per sequence, every window's mean % and the last, and the cold search's."""
    lines = ['| sequence | method | motions | frames | lines | every / last window '
             '| cold: middle / last | floor: middle / last |',
             '|:--|:--|--:|--:|--:|--:|--:|--:|']
    for r in sorted(records, key=lambda r: (r['name'], r['method'])):
        cold, low = (f'{100 * r[a]:.1f} / {100 * r[b]:.1f}' if a in r else '-'
                     for a, b in (('cold_mid', 'cold_last'), ('floor_mid', 'floor_last')))
        lines.append(f'| {r["name"]} | {r["method"]} | {r["n"]} | {r["frames"]} | {r["lines"]} '
                     f'| {100 * np.mean(r["stream"]):.1f} / {100 * r["stream"][-1]:.1f} '
                     f'| {cold} | {low} |')
    return '\n'.join(lines)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """Command-line options of ``python -m mlofc_tools.bench hopkins_stream``."""
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench hopkins_stream',
                                description=__doc__.split('\n')[0])
    p.add_argument('--sequences', default=None,
                   help='comma-separated sequence names (default all 155)')
    p.add_argument('--motions', type=int, default=None,
                   help='only sequences with this many motions (default 3 without '
                        '--sequences; 0 = all)')
    p.add_argument('--windows', type=int, default=None,
                   help='stop each stream after this many windows (default: its end)')
    p.add_argument('--window', type=int, default=K,
                   help=f"the pipeline's window, frames (default {K}; 0: each method's own, "
                        "the node's default)")
    p.add_argument('--methods', default='general',
                   help='comma-separated pipeline methods (general, auto, ...; default general)')
    p.add_argument('--quick', action='store_true',
                   help=f'smoke run: {QUICK_SEQUENCE}, 3 windows, one process')
    p.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1))
    p.add_argument('--out', default=None,
                   help='output folder (default docs/results/hopkins_stream)')
    args = p.parse_args(list(argv))
    if args.quick:
        args.sequences, args.windows, args.jobs = QUICK_SEQUENCE, 3, 1
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the benchmark; returns the process exit code."""
    argv = list(argv or [])
    args = parse_args(argv)
    wanted = [s.strip() for s in args.sequences.split(',') if s.strip()] \
        if args.sequences else None
    try:
        paths = pick_sequences(hk.list_sequences(), wanted)
    except ValueError as exc:
        common.eprint(f'hopkins_stream: {exc}')
        return 2
    motions = args.motions if args.motions is not None else (0 if args.sequences else 3)
    if motions:
        paths = [p for p in paths if n_motions_of(p) == motions]
    # cut streams (--windows) have no middle or last window to compare with
    methods = [m for m in args.methods.split(',') if m]
    # the cold reference once per sequence (it does not depend on the stream's method)
    items = [(str(p), 155, args.windows, args.windows is None and i == 0, m, args.window)
             for p in paths for i, m in enumerate(methods)]
    t0 = time.perf_counter()
    records = common.run_parallel(_unit, items, args.jobs, 'sequences')
    seconds = time.perf_counter() - t0
    report = '\n'.join([
        common.run_header('Hopkins155 line tracks streamed through the warm path: '
                          + ', '.join(f'`{m}`' for m in methods),
                          common.command_line('hopkins_stream', argv), {
                              'Sequences': f'{len(paths)}; window '
                                           f'{args.window or "0 (each method its own)"}',
                              'Run time': f'{seconds:.0f} s wall with {args.jobs} worker '
                                          'process(es)'}),
        __doc__.split('\n\n', 2)[2].strip(), '',
        '## Misclassification %, mean (median) over sequences', '', summary_table(records), '',
        "Every window: the mean over the sequence's windows (the first one cold). Middle and "
        'last: the window at the middle / end of the sequence, streamed, against the cold '
        'search and the floor (the true motions, each line to the cheapest) on the same lines '
        'and frames.', '',
        '## Per sequence', '', sequence_table(records), ''])
    common.write_report('hopkins_stream', args.out, report)
    return 0
