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
Accuracy of the solver: robust vs the floor, outliers, frames, number of bodies, speed.

``python -m mlofc_tools.bench accuracy [--trials 50] [--quick] [--out DIR] [--jobs 2]
[--seed 4711] [--sections speed,floor,outliers,frames,nbodies]`` writes ``README.md`` and
``accuracy_*.png`` to ``docs/results/accuracy/`` (or ``--out``) and prints the report.

1. floor: the paper's protocol (two views, 1000 x 1000 px, 20 lines/body for n = 2, 30 for
   n = 3, 4) at 0.5, 1, 2 px: every method of :data:`mlofc_ros.solver.METHODS` against the
   two floors (every line assigned with the TRUE motions, unweighted and weighted residual).
2. outliers: 15 % of the tracks replaced by tracks that follow no rigid motion, 1 px,
   n = 2, 3, K = 2, 5: inlier misclassification, rejection rates, angular-velocity error.
3. frames: K = 2, 3, 5, 8 views at 1 and 2 px, n = 3.
4. nbodies: ``n_bodies=0`` (automatic) for n = 1 .. 4, K = 2 and 5, 1 px.
5. speed: wall and CPU time of ``segment_lines`` ('robust', 'algebraic') vs the number of
   lines, n = 3, K = 5, 1 px, with a fixed numpy workload timed in between as the reference.

The speed section runs first, in this process, single-threaded (``import mlofc_ros`` sets
``OPENBLAS_NUM_THREADS=1`` before numpy loads), before the worker pool of the other sections
exists. Every runner of a section sees the same scenes (seeds fixed by section, point and trial).
"""
import argparse
import os
import time
from typing import List, Optional, Sequence

import mlofc_ros  # noqa: F401 (first of the package: one BLAS thread, set before numpy loads)

from mlofc_tools.bench import common  # noqa: I100 (after mlofc_ros, see above)
from mlofc_tools.bench.accuracy_report import (section_floor, section_frames, section_nbodies,
                                               section_outliers, section_speed)
from mlofc_tools.bench.accuracy_runs import (Grid, make_tasks, QUICK_GRID, run_speed,
                                             run_tasks, SECTIONS)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """Command-line options of ``python -m mlofc_tools.bench accuracy``."""
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench accuracy', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--trials', type=int, default=None,
                   help='scenes per point (default 50; 2 with --quick)')
    p.add_argument('--quick', action='store_true', help='smoke run: tiny grids, 2 trials')
    p.add_argument('--out', default=None, help='output folder (default docs/results/accuracy)')
    p.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1),
                   help='worker processes of sections 1-4 (default min(2, cores))')
    p.add_argument('--seed', type=int, default=4711, help='base seed (default 4711)')
    p.add_argument('--methods', default=None,
                   help='comma-separated subset of mlofc_ros.solver.METHODS for sections 1-2 '
                        '(default all)')
    p.add_argument('--label', default='',
                   help='free text for the report header (e.g. the code revision when run '
                        'outside a git checkout)')
    p.add_argument('--sections', default=','.join(SECTIONS),
                   help=f'comma-separated subset of {",".join(SECTIONS)} (speed always runs '
                        'first)')
    args = p.parse_args(list(argv))
    if args.trials is None:
        args.trials = 2 if args.quick else 50
    if args.trials < 1 or args.jobs < 1:
        p.error('--trials and --jobs must be >= 1')
    args.sections = [s.strip() for s in args.sections.split(',') if s.strip()]
    bad = set(args.sections) - set(SECTIONS)
    if bad or not args.sections:
        p.error(f'--sections: choose from {",".join(SECTIONS)}')
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the benchmark; returns the process exit code."""
    argv = list(argv or [])
    args = parse_args(argv)
    from mlofc_ros.solver import METHODS
    methods = list(METHODS) if args.methods is None else [
        m.strip() for m in args.methods.split(',') if m.strip()]
    unknown = set(methods) - set(METHODS)
    if unknown or 'robust' not in methods:
        common.eprint(f'--methods: choose from {list(METHODS)}, including robust')
        return 2
    grid = QUICK_GRID if args.quick else Grid()
    out_dir = common.results_dir('accuracy', args.out)
    t0 = time.perf_counter()
    speed = None
    if 'speed' in args.sections:  # first, alone in the process, before any worker exists
        common.eprint('accuracy: speed section')
        speed = run_speed(grid, args.seed)
    tasks = make_tasks(args.sections, grid, args.trials, args.seed, methods)
    common.eprint(f'accuracy: {len(tasks)} scenes, {args.jobs} process(es)')
    raw, errors, seconds = run_tasks(tasks, args.jobs)
    cpu = sum(float(r.get('cpu', 0.0)) for recs in raw.values() for r in recs)
    summary: List[List[str]] = []
    body = []
    if 'floor' in args.sections:
        body.append(section_floor(raw, grid, methods, args, summary, out_dir))
    if 'outliers' in args.sections:
        body.append(section_outliers(raw, grid, methods, args, summary, out_dir))
    if 'frames' in args.sections:
        body.append(section_frames(raw, grid, args, summary, out_dir))
    if 'nbodies' in args.sections:
        body.append(section_nbodies(raw, grid, args, summary))
    if speed is not None:
        body.append(section_speed(speed, grid, args, summary, out_dir))
    total = time.perf_counter() - t0
    extra = {'Trials per point': str(args.trials), 'Methods': ', '.join(methods),
             'Base seed': str(args.seed),
             'Run time': f'{total:.0f} s wall; sections 1-4: {seconds:.0f} s wall with '
                         f'{args.jobs} worker process(es), {cpu:.0f} s CPU in the solver calls'}
    if args.label:
        extra['Note'] = args.label
    command = common.command_line('accuracy', argv)
    parts = [common.run_header('Solver accuracy and speed', command, extra),
             '## Goals', '',
             common.markdown_table(['goal', 'measured', 'met'], summary, align='llc'),
             *body]
    if errors:
        parts += ['## Failures', '']
        for where, msgs in sorted(errors.items()):
            parts.append(f'- {where}: {len(msgs)} trial(s); e.g. `{sorted(set(msgs))[0][:200]}`')
        parts.append('')
    common.write_report('accuracy', args.out, '\n'.join(parts))
    return 0
