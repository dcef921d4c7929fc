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
The node's solver lane replayed offline: every frame solved in turn vs answers that come late.

Run ``python -m mlofc_tools.bench lane``; writes ``README.md`` and ``lane.png`` to
``docs/results/lane/``. At 30 Hz the node's solver process steps the frames while its lane
(:mod:`mlofc_ros.lane`) runs the searches, full solves and rescans, whose answers come back
tens of frames later (``bench live``). Live runs move by several points from one run to the
next (two processes on the machine's cores, a real-time clock), too much to judge a change of
the lane's logic by. This replays the same rendered scenes (``bench spinning``'s) through
:class:`~mlofc_ros.pipeline.Pipeline` with ``method='general'`` and a lane whose answers come
back a FIXED number of frames later, by job: :data:`DELAYS` times each ``--delays`` scale
(about what a 2-core machine takes at 30 Hz at scale 1). Scale 0 solves every frame in turn
(no lane): the floor the lane is measured against. Every frame is stepped (the step's own CPU
is not modelled: ``bench live`` measures that), and the same code gives the same figures on
every run and machine. ``--methods``: ``general``, and the node's default ``auto``, which
solves rotation-only until the rotation model misfits the scene, then as ``general`` (its
first search, in the lane, starts from the rotation-only labels too).

Scored like ``bench spinning`` from frame 9 (the first full window): ``wrong %``, ``-1 %``,
the same from frame 90 (3 s on), boxes within 5% of their omega (the median over frames of
the published rate), and the frames answered from the running fit (a step that did not hold,
or before the first search is back).
"""
import argparse
import time
from typing import Dict, List, Optional, Sequence, Tuple

from mlofc_ros.lane import InlineLane, SolveJob
from mlofc_tools.bench import common
from mlofc_tools.bench.spinning import render_scene, scene_list, score_run
import numpy as np

#: Frames between a lane job's submission and its answer at scale 1, by job: a search, a
#: full solve, a rescan (at 30 Hz on a 2-core EPYC about 1.3 s, 0.6 s and 0.1 s of CPU
#: beside the steps).
DELAYS = {'search': 45, 'full': 20, 'rescan': 4}

#: First frame scored (a full window of 10), and the first of the late score (3 s at 30 Hz).
FIRST, LATE = 9, 90

HEADERS = ['scene', 'method', 'seed', 'delays', 'wrong %', 'wrong % from frame 90', '-1 %',
           'omega err % (boxes)', 'boxes with omega err <= 5%',
           'answered from the running fit']
SUMMARY_HEADERS = ['scene', 'method', 'delays', 'runs', 'wrong % (mean)', 'wrong % (worst)',
                   'wrong % from frame 90 (mean)', '-1 % (mean)', 'boxes with omega err <= 5%',
                   'boxes with omega err <= 10%', 'answered from the running fit (mean)']


def job_kind(job: SolveJob) -> str:
    """Return ``'rescan'``, ``'full'`` (a tracked full solve) or ``'search'``."""
    if job.rescan:
        return 'rescan'
    return 'full' if 'init_motions' in job.keywords else 'search'


class FixedDelayLane(InlineLane):
    """An :class:`~mlofc_ros.lane.InlineLane` answering after :data:`DELAYS` x ``scale``."""

    def __init__(self, scale: float) -> None:
        super().__init__()
        self.scale = scale

    def submit(self, job: SolveJob) -> None:
        """Run ``job`` now; its answer comes back after its kind's delay."""
        self.delay = max(1, round(DELAYS[job_kind(job)] * self.scale))
        super().submit(job)


def run_one(item: Tuple[str, int, float, int, str]) -> Dict[str, object]:
    """Replay ``(scene, seed, delay scale, frames, method)``; its record (:data:`HEADERS`)."""
    from mlofc_ros.pipeline import Pipeline
    scene, seed, scale, frames, method = item
    seq = render_scene(scene, seed, frames)
    pipe = Pipeline(num_bodies=len(seq.body_names), window=10, method=method)
    if scale > 0:
        pipe.use_lane(FixedDelayLane(scale))
    outs = [(pipe.process(gray, stamp, camera=seq.camera), 0.0)
            for gray, stamp in zip(seq.frames, seq.stamps)]
    late = score_run(seq, outs, LATE) if frames > LATE else None
    return {'scene': scene, 'method': method, 'seed': seed, 'scale': scale,
            'score': score_run(seq, outs, min(FIRST, frames - 1)),
            'late_wrong': late['wrong'] if late else float('nan'),
            'running_fit': sum(bool(r.from_running_fit) for r, _ in outs)}


def _delays(scale: float) -> str:
    return 'every frame in turn' if scale == 0 else f'x{scale:g}'


def _boxes(err: np.ndarray, within: float = 0.05) -> Tuple[int, int]:
    err = err[np.isfinite(err)]
    return int(np.count_nonzero(err <= within)), int(err.size)


def build_rows(records: Sequence[Dict[str, object]]) -> List[List[object]]:
    """One row per run."""
    rows = []
    for r in sorted(records, key=lambda r: (r['scene'], r['method'], r['scale'], r['seed'])):
        s = r['score']
        err = s['omega_err'][np.isfinite(s['omega_err'])]
        rows.append([r['scene'], r['method'], r['seed'], _delays(r['scale']), 100 * s['wrong'],
                     100 * r['late_wrong'], 100 * s['unassigned'],
                     ' / '.join(f'{100 * x:.0f}' for x in err) or '—',
                     '{} of {}'.format(*_boxes(s['omega_err'])), r['running_fit']])
    return rows


def summary_rows(records: Sequence[Dict[str, object]]) -> List[List[object]]:
    """One row per (scene, method, delay scale) over its seeds: mean and worst."""
    groups: Dict[Tuple[str, str, float], List[Dict[str, object]]] = {}
    for r in records:
        groups.setdefault((r['scene'], r['method'], r['scale']), []).append(r)
    rows = []
    for (scene, method, scale), runs in sorted(groups.items()):
        wrong = [100 * r['score']['wrong'] for r in runs]
        boxes = [np.sum([_boxes(r['score']['omega_err'], within) for r in runs], axis=0)
                 for within in (0.05, 0.10)]
        rows.append([scene, method, _delays(scale), len(runs), float(np.mean(wrong)),
                     max(wrong), float(np.mean([100 * r['late_wrong'] for r in runs])),
                     float(np.mean([100 * r['score']['unassigned'] for r in runs])),
                     *(f'{b[0]} of {b[1]}' for b in boxes),
                     float(np.mean([r['running_fit'] for r in runs]))])
    return rows


def plot(path, records: Sequence[Dict[str, object]]) -> None:
    """Wrong % per run: a panel per scene, a series per method and delay scale (x: seed)."""
    scenes = sorted({r['scene'] for r in records})
    fig, axes = common.new_figure(len(scenes))
    for ax, scene in zip(axes, scenes):
        series: Dict[str, List[float]] = {}
        seeds = sorted({r['seed'] for r in records if r['scene'] == scene})
        for method, scale in sorted({(r['method'], r['scale']) for r in records}):
            by_seed = {r['seed']: 100 * r['score']['wrong'] for r in records
                       if (r['scene'], r['method'], r['scale']) == (scene, method, scale)}
            series[f'{method}, {_delays(scale)}'] = [by_seed.get(s, float('nan'))
                                                     for s in seeds]
        common.plot_series(ax, seeds, series, 'render seed', 'wrong %', scene)
    common.save_figure(fig, path, legend_ax=axes[0])


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench lane',
                                description=__doc__.split('\n')[1])
    p.add_argument('--scenes', type=scene_list, default=['own2+bg', 'own3+bg'],
                   help='comma-separated scenes of bench spinning')
    p.add_argument('--seeds', default='0,1,2,3,4,5', help='render seeds')
    common.add_methods_option(p, 'general,auto')
    p.add_argument('--delays', default='0,1',
                   help='scales of the lane delays (0: every frame solved in turn, no lane)')
    p.add_argument('--frames', type=int, default=300, help='frames per run (300: 10 s)')
    p.add_argument('--jobs', type=int, default=2, help='worker processes')
    p.add_argument('--out', default=None, help='output folder (default docs/results/lane)')
    args = p.parse_args(list(argv))
    args.method_list = common.method_list(p, args)
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    import sys
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    t0 = time.monotonic()
    revision = common.commit()       # before the runs import the code
    items = [(scene, int(seed), float(scale), args.frames, method) for scene in args.scenes
             for method in args.method_list
             for scale in args.delays.split(',') if scale for seed in args.seeds.split(',')
             if seed]
    records = common.run_parallel(run_one, items, args.jobs, 'runs', reports=len(items))
    head = common.run_header(
        "The node's solver lane replayed offline with fixed delays",
        common.command_line('lane', argv),
        {'Runs': f'{args.frames} frames 640x480 at 30 Hz per run, `method` '
                 f'{", ".join(args.method_list)}, window 10; '
                 f'lane delays at x1 (frames): {DELAYS}',
         'Run time': f'{time.monotonic() - t0:.0f} s'}, revision)
    text = '\n'.join([head, '', '## Over the seeds', '',
                      common.markdown_table(SUMMARY_HEADERS, summary_rows(records)), '',
                      '## Every run', '', common.markdown_table(HEADERS, build_rows(records)),
                      '', __doc__.split('\n\n', 1)[1].strip(), '', '![lane](lane.png)', ''])
    plot(common.results_dir('lane', args.out) / 'lane.png', records)
    common.write_report('lane', args.out, text)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
