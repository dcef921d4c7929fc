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
Hopkins155: real line tracks from pairs of tracked points, every solver method, f unknown.

``python -m mlofc_tools.bench hopkins [--windows 2] [--quick] [--methods ...] [--out DIR]``
writes ``README.md`` and ``hopkins.png`` to ``docs/results/hopkins/`` (or ``--out``) and prints
the report.

For every benchmark sequence (155; ``dancing`` excluded), ``--windows`` windows spread evenly over
the sequence, and K = 2 (two consecutive frames, as the paper) and K = 5 frames (``--ks`` adds
others, e.g. ``--ks 2,5,10``), the line tracks come from
:func:`mlofc_tools.datasets.hopkins.line_tracks` (pairs of same-motion points, see there) and
every method of :data:`mlofc_ros.solver.METHODS` segments them with the true number
of motions and UNKNOWN intrinsics (principal point at the image centre, focal length estimated;
the files' K is only a normalisation). Misclassification: best relabelling, ``-1`` wrong.

The oracle rows use the true labels: the focal length minimising the exact rotation-only cost of
the true grouping (the solver's profile, refit per group), each true group fitted alone with the
robust solver for ``n = 1`` at that focal length, and every line assigned to the best of those
motions (:func:`mlofc_ros.solver.assign_with_motions`). That is what the rotation-about-the-
camera-centre model can do at best on these tracks with one fitted motion per group.

Diagnostic rows: the methods that leave outliers unassigned with every ``-1`` line given to its
cheapest body, and the robust method with the focal length fixed at the oracle's. ``--save-records
FILE`` keeps the raw per-window results; ``--load-records FILE`` re-renders the report from them.
"""
import argparse
import json
import os
import pathlib
import re
import time
from typing import Dict, List, Optional, Sequence

from mlofc_tools.bench import common
from mlofc_tools.bench.hopkins_report import build_report, plot
from mlofc_tools.bench.hopkins_runs import (FRAMES, make_units, pick_sequences, QUICK_SEQUENCES,
                                            run_unit)
from mlofc_tools.datasets import hopkins as hk


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """Command-line options of ``python -m mlofc_tools.bench hopkins``."""
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench hopkins', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--windows', type=int, default=None,
                   help='windows per sequence and K (default 2; 1 with --quick)')
    p.add_argument('--quick', action='store_true',
                   help=f'smoke run: {", ".join(QUICK_SEQUENCES)}, 1 window')
    p.add_argument('--sequences', default=None,
                   help='comma-separated sequence names (default all 155)')
    p.add_argument('--methods', default=None,
                   help='comma-separated subset of mlofc_ros.solver.METHODS (default all)')
    p.add_argument('--data', default=None,
                   help=f'folder of the .npz files (default {hk.DEFAULT_DATA_DIR})')
    p.add_argument('--out', default=None, help='output folder (default docs/results/hopkins)')
    p.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1),
                   help='worker processes (default min(2, cores))')
    p.add_argument('--ks', default=None,
                   help='comma-separated frames per window K (default '
                        f'{",".join(map(str, FRAMES))})')
    p.add_argument('--seed', type=int, default=155, help='base seed (default 155)')
    p.add_argument('--save-records', metavar='FILE', default=None,
                   help='also write the raw per-window results (JSON)')
    p.add_argument('--load-records', metavar='FILE', default=None,
                   help='only re-render the report and plot from a --save-records file')
    args = p.parse_args(list(argv))
    if args.windows is None:
        args.windows = 1 if args.quick else 2
    if args.windows < 1 or args.jobs < 1:
        p.error('--windows and --jobs must be >= 1')
    try:
        args.ks = list(FRAMES) if args.ks is None else sorted(
            {int(k) for k in args.ks.split(',') if k.strip()})
    except ValueError:
        p.error('--ks takes comma-separated integers')
    if not args.ks or min(args.ks) < 2:
        p.error('--ks: every K must be >= 2')
    return args


def _shown(command: str) -> str:
    """Return the command without ``--save-records FILE`` (it does not change the results)."""
    return re.sub(r' --save-records(=| )\S+', '', command)


def _render(records, methods: Sequence[str], args: argparse.Namespace, command: str,
            seconds: float, n_seq: int, out: Optional[str], commit: Optional[str] = None
            ) -> None:
    report = build_report(records, methods, args, command, seconds, n_seq, commit)
    plot(records, methods, common.results_dir('hopkins', out) / 'hopkins.png')
    common.write_report('hopkins', out, report)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the benchmark; returns the process exit code."""
    argv = list(argv or [])
    args = parse_args(argv)
    if args.load_records:
        saved = json.loads(pathlib.Path(args.load_records).read_text())
        run_args = argparse.Namespace(**saved['args'])
        _render(saved['records'], saved['methods'], run_args, _shown(saved['command']),
                saved['seconds'], saved['n_seq'], args.out, saved.get('commit', 'unknown'))
        return 0
    from mlofc_ros.solver import METHODS

    methods = list(METHODS) if args.methods is None else [
        m.strip() for m in args.methods.split(',') if m.strip()]
    unknown = set(methods) - set(METHODS)
    if unknown:
        common.eprint(f'unknown methods {sorted(unknown)}; choose from {list(METHODS)}')
        return 2
    try:
        paths = hk.list_sequences(args.data)
    except ValueError as exc:
        common.eprint(f'hopkins: {exc}')
        return 2
    wanted = (QUICK_SEQUENCES if args.quick else None) if args.sequences is None else [
        s.strip() for s in args.sequences.split(',') if s.strip()]
    try:
        paths = pick_sequences(paths, wanted)
    except ValueError as exc:
        common.eprint(f'hopkins: {exc}')
        return 2
    units = make_units(paths, args.windows, methods, args.seed, args.ks)
    units.sort(key=lambda u: -(u.k * u.n_motions ** 2))   # biggest first: the pool ends evenly
    common.eprint(f'hopkins: {len(paths)} sequences, {len(units)} windows, '
                  f'{len(units) * len(methods)} solver calls, {args.jobs} process(es)')
    commit = common.commit()      # the code the runs import
    t0 = time.perf_counter()
    records: List[Dict[str, object]] = [
        r for recs in common.run_parallel(run_unit, units, args.jobs, 'windows', reports=20)
        for r in recs]
    seconds = time.perf_counter() - t0
    command = _shown(common.command_line('hopkins', argv))
    if args.save_records:
        run_args = {k: v for k, v in vars(args).items()
                    if k not in ('save_records', 'load_records')}
        pathlib.Path(args.save_records).write_text(json.dumps(
            {'command': command, 'seconds': seconds, 'n_seq': len(paths), 'methods': methods,
             'args': run_args, 'commit': commit, 'records': records}))
    _render(records, methods, args, command, seconds, len(paths), args.out, commit)
    return 0
