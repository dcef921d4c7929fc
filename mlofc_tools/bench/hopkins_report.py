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
"""Report of the Hopkins155 benchmark: tables per sequence, group and method; the plot."""
import argparse
import math
import pathlib
from typing import Dict, List, Optional, Sequence, Tuple

from mlofc_tools.bench import common
from mlofc_tools.bench.hopkins_runs import (BENCH_GROUPS, checkerboard_motion, F_SPAN,
                                            LINES_PER_MOTION, LOOSE, LOOSE_BOUND, MAX_USES,
                                            MIN_LENGTH_PX, ORACLE, ORACLE_G, ORACLE_GF,
                                            ORACLE_U, REASSIGNED, REFERENCES,
                                            ROBUST_ORACLE_F, TICK_NAMES, WITH_OUTLIERS)
import numpy as np


def per_sequence(records: Sequence[Dict[str, object]]
                 ) -> Dict[Tuple[str, int, str], Dict[str, object]]:
    """(sequence, K, method) -> mean over windows of misclassification %, focal, times."""
    raw: Dict[Tuple[str, int, str], List[Dict[str, object]]] = {}
    for r in records:
        raw.setdefault((str(r['sequence']), int(r['k']), str(r['method'])), []).append(r)
    out = {}
    for key, recs in raw.items():
        def col(f: str) -> np.ndarray:
            return np.array([float(r.get(f, math.nan)) for r in recs])
        out[key] = {'group': recs[0]['group'], 'n': int(recs[0]['n']),
                    'miscl': 100 * float(col('miscl').mean()),
                    'focal': _nanmedian(col('focal')),
                    'lines': float(col('lines').mean()), 'min_lines': int(col('min_lines').min()),
                    'flow_px': float(np.median(col('flow_px'))),
                    'resid_px': _nanmedian(col('resid_px')),
                    'failed': int(col('failed').sum()), 'windows': len(recs),
                    'unassigned': 100 * float(col('unassigned').mean()),
                    'f_bound': 100 * common.summarize(col('f_bound'))['mean'],
                    'truth_cheaper': 100 * common.summarize(col('truth_cheaper'))['mean'],
                    'truth_start_miscl': 100 * common.summarize(
                        col('truth_start_miscl'))['mean'],
                    'found_miscl': 100 * common.summarize(col('found_miscl'))['mean'],
                    'seconds': col('seconds'), 'cpu': col('cpu')}
    return out


def frames_of(seqs) -> List[int]:
    """Return the window lengths K of ``per_sequence`` results (or raw records), sorted."""
    if isinstance(seqs, dict):
        return sorted({int(k) for (_, k, _) in seqs})
    return sorted({int(r['k']) for r in seqs})


def _nanmedian(values: Sequence[float]) -> float:
    return common.summarize(values)['median']


def _stat(seqs: Dict[Tuple[str, int, str], Dict[str, object]], k: int, method: str,
          keep, field: str = 'miscl') -> Dict[str, float]:
    vals = [s[field] for (name, kk, m), s in seqs.items() if kk == k and m == method
            and keep(name, s)]
    return common.summarize(vals)


def _cell(s: Dict[str, float]) -> str:
    if not s['n']:
        return '—'
    return f"{s['mean']:.1f} ({s['median']:.1f})"


def _names(methods: Sequence[str]) -> List[str]:
    return list(methods) + [ORACLE, ORACLE_U]


def headline_table(seqs, methods: Sequence[str]) -> str:
    """Mean (median) misclassification % over all 2- and 3-motion sequences, K = 2 and 5."""
    ks = frames_of(seqs)
    headers = ['method'] + [f'{n} motions, K={k}' for k in ks for n in (2, 3)]
    rows = []
    for m in _names(methods):
        rows.append([m] + [_cell(_stat(seqs, k, m, lambda _, s, n=n: s['n'] == n))
                           for k in ks for n in (2, 3)])
    for name, two, three in REFERENCES:
        cells = [f'{two:.1f}', '—' if three is None else f'{three:.1f}']
        rows.append([f'*reference: {name}*'] + cells + cells)
    return common.markdown_table(headers, rows)


def diagnostic_table(seqs, methods: Sequence[str]) -> str:
    """Mean misclassification % (mean unassigned %) of the diagnostic runners."""
    ks = frames_of(seqs)
    runners = []
    for m in WITH_OUTLIERS:
        if m in methods:
            runners += [m, m + REASSIGNED] + ([m + LOOSE] if m == 'robust' else [])
    if 'robust' in methods:
        runners.append(ROBUST_ORACLE_F)
    runners.append(ORACLE)
    if 'general' in methods:
        runners += [ORACLE_GF, ORACLE_G]
    rows = []
    for m in runners:
        row: List[object] = [m]
        for k in ks:
            for n in (2, 3):
                def keep(_, s, n=n) -> bool:
                    return s['n'] == n
                miscl = _stat(seqs, k, m, keep)
                row.append('—' if not miscl['n'] else f"{miscl['mean']:.1f} "
                           f"({_stat(seqs, k, m, keep, 'unassigned')['mean']:.1f})")
        rows.append(row)
    return common.markdown_table(['runner'] + [f'{n} motions, K={k}' for k in ks
                                               for n in (2, 3)], rows)


def _truth_cheaper_text(seqs) -> str:
    ks = frames_of(seqs)
    share = ', '.join(f"{_stat(seqs, k, 'robust', lambda *_: True, 'truth_cheaper')['mean']:.0f} %"
                      f' (K = {k})' for k in ks)
    return ("Search or model? At robust's focal length and noise level, bodies fitted to the "
            "TRUE groups have a lower truncated cost than robust's own answer in "
            f'{share} of the windows (mean over sequences): there the search, or the spatial '
            'prior (which trades cost for coherence), ends above the truth. In the other '
            'windows the rotation-only objective itself prefers a wrong grouping (bodies that '
            'translate), which no search can fix; a richer model or a prior can.\n')


def _general_truth_text(seqs) -> str:
    ks = [k for k in frames_of(seqs) if k >= 3]
    rows = []
    for k in ks:
        for n in (2, 3):
            def keep(_, s, n=n) -> bool:
                return s['n'] == n

            def stat(field: str, k=k, keep=keep) -> float:
                return _stat(seqs, k, 'general', keep, field)['mean']
            if not _stat(seqs, k, 'general', keep, 'truth_cheaper')['n']:
                continue
            rows.append(f'| {n} | {k} | {stat("miscl"):.1f} | {stat("truth_cheaper"):.0f} | '
                        f'{stat("truth_start_miscl"):.1f} | {stat("found_miscl"):.1f} |')
    if not rows:
        return ''
    return ('Search or model for `general`? Its cold search run once more with the TRUE '
            'grouping as its only start (same focal length, noise level and starting '
            "motions): where that solution's score (capped marginalised cost plus the "
            "position terms) is below the scores of the method's answer and of the search "
            'restarted from that answer, the search missed a better basin; elsewhere the '
            'model itself prefers a wrong grouping. Means over '
            'sequences; the last column is `general` had it found the truth-started solution '
            'wherever that is cheaper:\n\n'
            '| motions | K | general % | truth start cheaper, % of windows | truth start % '
            '| general, search perfect % |\n|--:|--:|--:|--:|--:|--:|\n'
            + '\n'.join(rows) + '\n')


def group_table(seqs, methods: Sequence[str], k: int) -> str:
    """Mean (median) misclassification % per benchmark group and number of motions."""
    cols = [(g, n) for g in BENCH_GROUPS for n in (2, 3)]
    counts = {c: sum(1 for (name, kk, m), s in seqs.items() if kk == k and m == ORACLE
                     and (s['group'], s['n']) == c) for c in cols}
    headers = ['method'] + [f'{g}, {n} ({counts[(g, n)]} seq.)' for g, n in cols]
    rows = [[m] + [_cell(_stat(seqs, k, m, lambda _, s, g=g, n=n: (s['group'], s['n']) == (g, n)))
                   for g, n in cols] for m in _names(methods)]
    return common.markdown_table(headers, rows)


def checkerboard_table(seqs, methods: Sequence[str], k: int) -> str:
    """Checkerboard sequences split by what their name says about the motions."""
    def motion(name: str) -> Optional[Dict[str, str]]:
        return checkerboard_motion(name)

    splits = [
        ('no T in name', lambda nm, s: (motion(nm) or {}).get('translation') == 'no'),
        ('some T', lambda nm, s: (motion(nm) or {}).get('translation') == 'yes'),
        ('camera fixed', lambda nm, s: (motion(nm) or {}).get('camera') == 'fixed'),
        ('camera moves', lambda nm, s: (motion(nm) or {}).get('camera', 'fixed') != 'fixed'),
    ]
    counts = [sum(1 for (nm, kk, m), s in seqs.items() if kk == k and m == ORACLE
                  and s['group'] == 'checkerboard' and keep(nm, s)) for _, keep in splits]
    headers = ['method'] + [f'{t} ({c} seq.)' for (t, _), c in zip(splits, counts)]
    rows = []
    for m in _names(methods):
        rows.append([m] + [_cell(_stat(seqs, k, m, lambda nm, s, keep=keep:
                                       s['group'] == 'checkerboard' and keep(nm, s)))
                           for _, keep in splits])
    return common.markdown_table(headers, rows)


def diagnostics_table(seqs, k: int) -> str:
    """Per group: lines, endpoint motion, oracle residual and focal lengths (medians)."""
    rows = []
    for g in BENCH_GROUPS:
        for n in (2, 3):
            sel = [(nm, s) for (nm, kk, m), s in seqs.items() if kk == k and m == ORACLE
                   and (s['group'], s['n']) == (g, n)]
            if not sel:
                continue
            rob = [seqs.get((nm, k, 'robust'), {}).get('focal', math.nan) for nm, _ in sel]

            def med(key: str, sel=sel) -> float:
                v = np.array([float(s[key]) for _, s in sel])
                return float(np.nanmedian(v)) if np.any(np.isfinite(v)) else math.nan
            rows.append([f'{g}, {n}', len(sel), med('lines'), med('min_lines'), med('flow_px'),
                         med('resid_px'), med('focal'),
                         float(np.nanmedian(rob)) if np.any(np.isfinite(rob)) else math.nan])
    return common.markdown_table(
        ['group', 'seq.', 'lines', 'fewest lines of a motion', 'endpoint motion px/frame',
         'oracle residual px', 'oracle f px', 'robust f px'], rows)


def timing_table(seqs, records, methods: Sequence[str]) -> str:
    """Median wall / CPU ms per solve and total CPU s per method, K = 2 and 5."""
    ks = frames_of(seqs)
    rows = []
    for m in list(methods) + [ORACLE, ROBUST_ORACLE_F]:
        row: List[object] = [m]
        for k in ks:
            sec = np.array([float(r['seconds']) for r in records
                            if r['method'] == m and r['k'] == k])
            cpu = np.array([float(r['cpu']) for r in records
                            if r['method'] == m and r['k'] == k])
            row += [1000 * float(np.median(cpu)) if cpu.size else math.nan,
                    1000 * float(np.median(sec)) if sec.size else math.nan,
                    float(np.sum(cpu))]
        rows.append(row)
    headers = ['runner'] + [f'{t}, K={k}' for k in ks
                            for t in ('CPU ms (median)', 'wall ms (median)', 'CPU s total')]
    return common.markdown_table(headers, rows)


def sequence_table(seqs, methods: Sequence[str]) -> str:
    """Long table: misclassification % per sequence (mean over windows), per method and K."""
    ks = frames_of(seqs)
    names = _names(methods)[:-1]               # methods + weighted oracle
    headers = ['sequence', 'group', 'n', 'lines'] + [f'{m}, K={k}' for k in ks
                                                     for m in names]
    rows = []
    for seq in sorted({nm for (nm, _, _) in seqs}):
        ref = seqs.get((seq, ks[0], ORACLE)) or next(
            s for (nm, _, _), s in seqs.items() if nm == seq)
        row: List[object] = [seq, ref['group'], ref['n'], f"{ref['lines']:.0f}"]
        for k in ks:
            for m in names:
                s = seqs.get((seq, k, m))
                row.append('—' if s is None else f"{s['miscl']:.0f}" +
                           (f" [{s['failed']}f]" if s['failed'] else ''))
        rows.append(row)
    return common.markdown_table(headers, rows)


PAIRING = f"""## How the line tracks are made

Hopkins155 has point tracks only (no images). Two points of one rigid body span a 3D line of that
body, so a pair of tracked points with the same label is a real line track, with real tracking
noise and the real motion (rotation and translation). For each window and each motion, the
candidates are all pairs of its points at least {MIN_LENGTH_PX:g} px apart in the window's first
frame, taken in a random order (fixed seed per sequence, K and window) while both points have
been used in fewer than {MAX_USES} lines, up to {LINES_PER_MOTION} lines per motion (the paper's
m). A motion with few well-separated points gets fewer lines (column "fewest lines of a
motion"). The endpoints of a line in every frame are its two points
(`mlofc_tools.datasets.hopkins.line_tracks`); the solver only uses the line through them.
Every method gets the TRUE number of motions and no intrinsics (`intrinsics=None`,
`image_size=(w, h)`: principal point at the image centre, focal length estimated per window).
Misclassification: best relabelling of the predicted bodies; unassigned lines (`-1`) count as
wrong. Per sequence: mean over its windows; per group: mean (median) over sequences; the
`_g12/_g13/_g23` two-motion subsets count as separate sequences, as in the benchmark.

The oracle rows know the true grouping: the focal length minimising the exact rotation-only cost
of the true groups (the solver's `profile_cost`, bodies refit at each f), each true group fitted
alone with `segment_lines(tracks[labels == i], 1, intrinsics=(f, f, w/2, h/2),
method='robust')`, then every line assigned to the best of the fitted motions
(`assign_with_motions`, Mahalanobis cost = weighted, or the paper's algebraic residual =
unweighted). It bounds what the rotation-about-the-camera-centre model can do on these tracks.
The reference rows are published numbers: the paper's own real sequence (two boxes, 10 hand-picked
lines, 2 motions) and point-based methods on all Hopkins155 points and frames.
"""


def build_report(records, methods: Sequence[str], args: argparse.Namespace, command: str,
                 seconds: float, n_seq: int, commit: Optional[str] = None) -> str:
    """Return the whole Markdown report; ``commit`` is that of the run (default: now)."""
    seqs = per_sequence(records)
    ks = frames_of(seqs)
    cpu = float(np.nansum([float(r['cpu']) for r in records]))
    extra = {'Sequences': f'{n_seq}' + (' (--quick)' if args.quick else ' (Hopkins155, '
                                        'dancing excluded)'),
             'Windows per sequence and K': str(args.windows), 'K (frames per window)':
             ', '.join(map(str, ks)), 'Methods': ', '.join(methods),
             'Run time': f'{seconds:.0f} s wall with {args.jobs} worker process(es); '
                         f'{cpu:.0f} s CPU in solver and oracle calls',
             'Base seed': str(args.seed)}
    parts = [common.run_header('Hopkins155 as line tracks (pairs of tracked points)',
                               command, extra, commit)]
    parts += ['## Headline: misclassification %, mean (median) over sequences', '',
              headline_table(seqs, methods), PAIRING]
    if 'general' in methods:
        parts += ['The `general` method (rotation AND translation per body, '
                  '`mlofc_ros/solver/general.py`) needs K >= 3: at K = 2 it returns the robust '
                  'rotation-only result, so its K = 2 numbers repeat `robust`. With K >= 3 each '
                  "line's 3D direction is marginalised (a Gaussian prior whose scale is the "
                  "body's translation), not fitted; it starts from the rotation-only labels and "
                  'from a k-means of the line midpoints in the image, and every assignment is '
                  "smoothed by the spatial prior of `robust` (cues the paper's methods do not "
                  'use). Its outlier bound is loose (few `-1`). The oracle rows are '
                  'rotation-only, so they do not bound `general`; see the `oracle general` '
                  'rows under Diagnostics.', '']
    for k in ks:
        parts += [f'## Per group, K = {k}', '', 'Misclassification %, mean (median):', '',
                  group_table(seqs, methods, k),
                  'Checkerboard sequences by the motions in their names (object codes R/T, '
                  'camera letters after C; `_gij` subsets use the parent name):', '',
                  checkerboard_table(seqs, methods, k),
                  'Medians over sequences: lines per window, endpoint motion between '
                  "consecutive frames, oracle residual (RMS per line under its own group's "
                  'rotation-only fit, px-equivalent), focal lengths:', '',
                  diagnostics_table(seqs, k)]
    bound = ', '.join(f"{_stat(seqs, k, ORACLE, lambda *_: True, 'f_bound')['mean']:.0f} % "
                      f'(K = {k})' for k in ks)
    parts += ['## Diagnostics: unassigned lines, focal length', '',
              'Misclassification %, mean over sequences (in parentheses: unassigned lines %, '
              'already counted as wrong in the first number). `-1 -> cheapest body` gives '
              'every unassigned line to the body of lowest cost; '
              f'`{LOOSE.lstrip(", ")}` keeps lines whose cost is up to {LOOSE_BOUND:g}x the '
              'outlier bound (the rest stay -1); `robust, f = oracle f` runs '
              "the robust method with the focal length fixed at the oracle's; the "
              '`oracle general` rows (K >= 3 only) fit rotation AND translation to every true '
              "group at the oracle's focal length, with each line's 3D direction fitted (the "
              'old model) or marginalised (the model of `general`), and give every line to '
              'its cheapest body:', '',
              diagnostic_table(seqs, methods),
              *([_truth_cheaper_text(seqs)] if 'robust' in methods else []),
              *([_general_truth_text(seqs)] if 'general' in methods else []),
              f"The oracle's focal length ends at the top of its search range "
              f'({F_SPAN:g} x max(w, h)) in {bound} of the windows (mean over sequences). As '
              'f -> infinity a rotation about the x or y axis becomes a plain image '
              'translation, so the rotation-only model turns into a 2D rigid image motion '
              '(translation + rotation about the image centre), which fits translating '
              'bodies better than any finite f.', '']
    parts += ['![per group](hopkins.png)', '', '## Solver time', '',
              'Per call, f unknown (the focal length search is part of every call):', '',
              timing_table(seqs, records, methods)]
    errors: Dict[str, List[str]] = {}
    for r in records:
        if 'error' in r and not str(r['method']).endswith(REASSIGNED):
            errors.setdefault(f"{r['method']}, K={r['k']}", []).append(
                f"{r['sequence']}: {r['error']}")
    if errors:
        parts += ['## Failures (counted as 100 % misclassified)', '']
        for where, msgs in sorted(errors.items()):
            parts.append(f'- {where}: {len(msgs)} window(s); e.g. `{msgs[0][:200]}`')
        parts.append('')
    parts += ['## Per sequence', '', 'Misclassification % (mean over windows; `[nf]` = n '
              'failed windows):', '', sequence_table(seqs, methods)]
    return '\n'.join(parts)


def plot(records, methods: Sequence[str], path: pathlib.Path) -> None:
    """Bar chart: mean misclassification per group (and all) per method, one panel per K."""
    seqs = per_sequence(records)
    ks = frames_of(seqs)
    cols = [(g, n) for g in BENCH_GROUPS for n in (2, 3)] + [('all', 2), ('all', 3)]
    names = _names(methods)
    fig, axes = common.new_figure(len(ks), width_per_panel=7.0, height=4.6)
    width = 0.8 / len(names)
    for ax, k in zip(axes, ks):
        stats = {m: [_stat(seqs, k, m, lambda _, s, g=g, n=n: s['n'] == n and
                           g in ('all', s['group'])) for g, n in cols] for m in names}
        shown = [j for j in range(len(cols)) if stats[names[0]][j]['n']]
        x = np.arange(len(shown))
        for i, m in enumerate(names):
            ax.bar(x + (i - (len(names) - 1) / 2) * width,
                   [stats[m][j]['mean'] for j in shown], width, label=m,
                   color='0.3' if m == ORACLE else '0.65' if m == ORACLE_U else f'C{i}')
        ax.axhline(REFERENCES[0][1], color='k', linestyle='--', linewidth=1,
                   label='paper, MLOFC on its real lines (2 motions)')
        for (ref, two, three), marker in zip(REFERENCES[1:], ('*', 'D')):
            xs = [xi for xi, j in zip(x, shown) if cols[j][0] == 'all']
            ys = [two if cols[j][1] == 2 else three for j in shown if cols[j][0] == 'all']
            ax.plot(xs, ys, linestyle='none', marker=marker, color='k', markersize=7,
                    label=ref.replace(', mean', ' (all points, all frames)'))
        ax.set_xticks(x)
        ax.set_xticklabels([TICK_NAMES.get(cols[j][0], cols[j][0]) + f'\n{cols[j][1]} motions'
                            for j in shown], fontsize=8)
        ax.set_ylabel('misclassified lines, mean over sequences (%)')
        ax.set_title(f'Hopkins155 line tracks, K = {k} frames, f unknown', fontsize=10)
        ax.grid(True, axis='y', alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc='lower center', ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    import matplotlib.pyplot as plt
    fig.savefig(path, dpi=110)
    plt.close(fig)
