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
The paper's synthetic experiments (section 4.1, Fig. 2-5), rerun for every solver method.

``python -m mlofc_tools.bench paper [--trials 50] [--quick] [--out DIR] [--jobs 2]`` writes
``README.md`` and ``paper_fig2.png`` .. ``paper_fig5.png`` to ``docs/results/paper/`` (or
``--out``) and prints the tables.

- Fig. 2: n = 2 bodies, 20 lines each, noise 0..2 px, pure rotation.
- Fig. 3: n = 2, 20 lines each, 1 px, both bodies also translate, ``|T| = t |w|``.
- Fig. 4: n = 2, 20 lines each, 1 px, the second body translates only (``w = 0``,
  ``|T| = t |w_0|``).
- Fig. 5: n = 3 bodies, 30 lines each, noise 0..2 px.

Every point runs the same ``--trials`` scenes (fixed seeds) through every method of
:data:`mlofc_ros.solver.METHODS` with known intrinsics, through the two floors (every line
assigned with the TRUE motions: the paper's unweighted residual, and the noise-weighted one), with
two views as in the paper; then the multi-frame methods (:data:`MULTI_FRAME_METHODS`: 'robust',
and 'general', which also fits translation from three or more views) and the floors with
``K = --frames`` views; and,
at Fig. 2 settings, the robust and algebraic methods with unknown focal length.
"""
import argparse
from dataclasses import dataclass
import math
import os
import time
from typing import Dict, List, Optional, Sequence, Tuple

from mlofc_tools.bench import common
from mlofc_tools.scoring import best_permutation, motion_errors
from mlofc_tools.synthetic import make_scene
import numpy as np

FLOOR = 'floor (unweighted)'
FLOOR_W = 'floor (weighted)'
F_UNKNOWN_METHODS = ('robust', 'algebraic')
NOISE_GRID = (0.0, 0.5, 1.0, 1.5, 2.0)
TRANSLATION_GRID = (0.0, 1.0, 2.0, 4.0, 8.0)
QUICK_NOISE_GRID = (0.0, 1.0)
QUICK_TRANSLATION_GRID = (0.0, 8.0)
COLORS = {'algebraic': 'C0', 'kmeans': 'C1', 'algebraic+kmeans': 'C2', 'robust': 'C3',
          'general': 'C4'}
#: Methods also run on the multi-frame (K > 2) scenes.
MULTI_FRAME_METHODS = ('robust', 'general')
#: Multi-frame methods run on the K-view scenes of the translation experiments only (Fig. 3, 4):
#: 'general' fits translation too and costs ~1-2 s per call, the budget of the whole benchmark.
TRANSLATION_ONLY_METHODS = ('general',)


@dataclass(frozen=True)
class Experiment:
    """One figure of the paper: a scene family and the swept parameter."""

    key: str
    title: str
    n_bodies: int
    lines_per_body: int
    sweep: str  # 'noise_px' or 'translation_ratio'
    xs: Tuple[float, ...]
    noise_px: float = 1.0
    pure_translation_body: bool = False

    @property
    def xlabel(self) -> str:
        """Axis label of the swept parameter."""
        if self.sweep == 'noise_px':
            return 'endpoint noise (px)'
        return 't = |T| / |w| (scene units per rad)'

    def scene_kwargs(self, x: float) -> Dict[str, object]:
        """Keyword arguments of :func:`mlofc_tools.synthetic.make_scene` at sweep value ``x``."""
        kw: Dict[str, object] = {'noise_px': self.noise_px, 'translation_ratio': 0.0,
                                 'pure_translation_body': self.pure_translation_body}
        kw[self.sweep] = float(x)
        return kw


def experiments(quick: bool = False) -> List[Experiment]:
    """Experiments of the paper's section 4.1 (reduced grids with ``quick``)."""
    noise = QUICK_NOISE_GRID if quick else NOISE_GRID
    trans = QUICK_TRANSLATION_GRID if quick else TRANSLATION_GRID
    return [
        Experiment('fig2', 'Fig. 2: n = 2, 20 lines/body, vs noise', 2, 20, 'noise_px', noise),
        Experiment('fig3', 'Fig. 3: n = 2, 20 lines/body, 1 px, both bodies translate',
                   2, 20, 'translation_ratio', trans),
        Experiment('fig4', 'Fig. 4: n = 2, 20 lines/body, 1 px, body 2 pure translation',
                   2, 20, 'translation_ratio', trans, pure_translation_body=True),
        Experiment('fig5', 'Fig. 5: n = 3, 30 lines/body, vs noise', 3, 30, 'noise_px', noise),
    ]


@dataclass(frozen=True)
class Unit:
    """One scene (experiment, number of frames, sweep point, trial) and what runs on it."""

    exp: Experiment
    exp_index: int
    n_frames: int
    point: int
    trial: int
    seed: int
    runners: Tuple[str, ...]


def runner_names(exp: Experiment, n_frames: int, methods: Sequence[str],
                 multi: Sequence[str] = MULTI_FRAME_METHODS) -> Tuple[str, ...]:
    """
    Names of what runs on a scene: methods, floors and (Fig. 2, two views) f-unknown runs.

    ``methods`` run on two-view scenes, those of them also in ``multi`` on K-view scenes.
    """
    if n_frames > 2:
        return tuple(m for m in methods if m in multi and (
            exp.sweep == 'translation_ratio' or m not in TRANSLATION_ONLY_METHODS)
        ) + (FLOOR, FLOOR_W)
    names = tuple(methods) + (FLOOR, FLOOR_W)
    if exp.key == 'fig2':
        names += tuple(f'{m} (f unknown)' for m in F_UNKNOWN_METHODS if m in methods)
    return names


def _score(result: object, scene: object) -> Dict[str, float]:
    """Misclassification, motion errors and focal-length error of one solver result."""
    n = scene.n_bodies
    perm, errors = best_permutation(result.labels, scene.labels, n)
    rel, abs_deg = motion_errors(result.angular_velocities, scene.angular_velocities, perm)
    # error of the true body n-1 (the pure-translation body of Fig. 4), deg/frame
    inv = {t: p for p, t in enumerate(perm)}
    last = float(np.degrees(np.linalg.norm(
        result.angular_velocities[inv[n - 1]] - scene.angular_velocities[n - 1])))
    f_true = scene.intrinsics[0]
    return {'miscl': errors / scene.labels.shape[0], 'rel': rel, 'abs_deg': abs_deg,
            'last_deg': last, 'f_err': abs(float(result.focal_length) - f_true) / f_true}


def run_unit(unit: Unit) -> Tuple[Unit, Dict[str, Dict[str, object]]]:
    """Build the unit's scene and run every runner on it (worker function)."""
    from mlofc_ros.solver import assign_with_motions, segment_lines

    exp = unit.exp
    scene = make_scene(exp.n_bodies, exp.lines_per_body, n_frames=unit.n_frames,
                       seed=unit.seed, **exp.scene_kwargs(exp.xs[unit.point]))
    out: Dict[str, Dict[str, object]] = {}
    for name in unit.runners:
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            if name in (FLOOR, FLOOR_W):
                res = assign_with_motions(scene.tracks, scene.angular_velocities,
                                          intrinsics=scene.intrinsics,
                                          weighted=name == FLOOR_W)
            elif name.endswith(' (f unknown)'):
                res = segment_lines(scene.tracks, exp.n_bodies, intrinsics=None,
                                    image_size=scene.image_size, method=name.split(' ')[0],
                                    seed=unit.trial)
            else:
                res = segment_lines(scene.tracks, exp.n_bodies, intrinsics=scene.intrinsics,
                                    image_size=scene.image_size, method=name, seed=unit.trial)
            rec: Dict[str, object] = _score(res, scene)
            rec['unassigned'] = float(np.mean(np.asarray(res.labels) < 0))
            rec['failed'] = 0
        except Exception as exc:  # noqa: B902 (a failing method is a result, not a crash)
            rec = {'miscl': 1.0, 'rel': math.nan, 'abs_deg': math.nan, 'last_deg': math.nan,
                   'f_err': math.nan, 'unassigned': 1.0, 'failed': 1,
                   'error': f'{type(exc).__name__}: {exc}'}
        rec['seconds'] = time.perf_counter() - t0
        rec['cpu_seconds'] = time.process_time() - c0
        out[name] = rec
    return unit, out


def make_units(exps: Sequence[Experiment], methods: Sequence[str], trials: int,
               extra_frames: int, seed: int,
               multi: Sequence[str] = MULTI_FRAME_METHODS) -> List[Unit]:
    """All scenes of the run; seeds depend only on (seed, experiment, K, point, trial)."""
    units = []
    frames = (2,) + ((extra_frames,) if extra_frames > 2 else ())
    for ei, exp in enumerate(exps):
        fig_no = int(exp.key[3:])
        for k in frames:
            names = runner_names(exp, k, methods, multi)
            for j in range(len(exp.xs)):
                for i in range(trials):
                    ss = np.random.SeedSequence([seed, fig_no, k, j, i])
                    units.append(Unit(exp, ei, k, j, i, int(ss.generate_state(1)[0]), names))
    return units


Key = Tuple[str, int, str, int]  # (experiment key, K, runner, point)


def aggregate(results: Sequence[Tuple[Unit, Dict[str, Dict[str, object]]]]
              ) -> Tuple[Dict[Key, Dict[str, float]], Dict[str, List[str]]]:
    """Per (experiment, K, runner, point): mean/median misclassification, errors, timings."""
    raw: Dict[Key, List[Dict[str, object]]] = {}
    errors: Dict[str, List[str]] = {}
    for unit, out in results:
        for name, rec in out.items():
            raw.setdefault((unit.exp.key, unit.n_frames, name, unit.point), []).append(rec)
            if 'error' in rec:
                errors.setdefault(f'{name}, {unit.exp.key}, K={unit.n_frames}', []).append(
                    str(rec['error']))
    stats = {}
    for key, recs in raw.items():
        col = {f: np.array([float(r[f]) for r in recs]) for f in
               ('miscl', 'rel', 'abs_deg', 'last_deg', 'f_err', 'seconds', 'cpu_seconds',
                'unassigned', 'failed')}
        stats[key] = {
            'miscl_mean': 100 * float(col['miscl'].mean()),
            'miscl_median': 100 * float(np.median(col['miscl'])),
            'rel_mean': 100 * common.summarize(col['rel'])['mean'],
            'rel_median': 100 * common.summarize(col['rel'])['median'],
            'abs_deg': common.summarize(col['abs_deg'])['mean'],
            'last_deg': common.summarize(col['last_deg'])['mean'],
            'f_err_mean': 100 * common.summarize(col['f_err'])['mean'],
            'f_err_median': 100 * common.summarize(col['f_err'])['median'],
            'ms_median': 1000 * float(np.median(col['seconds'])),
            'cpu_ms_median': 1000 * float(np.median(col['cpu_seconds'])),
            'cpu_total': float(col['cpu_seconds'].sum()),
            'unassigned': 100 * float(col['unassigned'].mean()),
            'failed': int(col['failed'].sum()),
            'trials': len(recs),
        }
    return stats, errors


def _cell_miscl(s: Optional[Dict[str, float]]) -> str:
    if s is None:
        return '—'
    txt = f"{s['miscl_mean']:.1f} ({s['miscl_median']:.1f})"
    if s['failed']:
        txt += f" [{s['failed']} fail]"
    return txt


def _cell_rel(s: Optional[Dict[str, float]]) -> str:
    if s is None:
        return '—'
    return f"{_fmt(s['rel_mean'])} ({_fmt(s['rel_median'])})"


def _x_headers(exp: Experiment) -> List[str]:
    unit = ' px' if exp.sweep == 'noise_px' else ''
    prefix = '' if exp.sweep == 'noise_px' else 't = '
    return [f'{prefix}{x:g}{unit}' for x in exp.xs]


def _table(exp: Experiment, stats: Dict[Key, Dict[str, float]], k: int,
           names: Sequence[str], cell) -> str:
    rows = []
    for name in names:
        rows.append([name] + [cell(stats.get((exp.key, k, name, j)))
                              for j in range(len(exp.xs))])
    return common.markdown_table(['method'] + _x_headers(exp), rows)


def _fmt(value: float, digits: int = 2) -> str:
    return '—' if not math.isfinite(value) else f'{value:.{digits}f}'


def _unassigned_table(exp: Experiment, stats: Dict[Key, Dict[str, float]],
                      methods: Sequence[str], extra_frames: int, multi: Sequence[str]) -> str:
    """Rows (runner, K) that left any line unassigned (-1) at some point; '' if none did."""
    frames = [2] + ([extra_frames] if extra_frames > 2 else [])
    rows = []
    for k in frames:
        for name in runner_names(exp, k, methods, multi):
            vals = [stats.get((exp.key, k, name, j)) for j in range(len(exp.xs))]
            if any(v is not None and v['unassigned'] > 0 for v in vals):
                rows.append([f'{name}, K={k}'] + ['—' if v is None else _fmt(v['unassigned'], 1)
                                                  for v in vals])
    return common.markdown_table(['method'] + _x_headers(exp), rows) if rows else ''


def figure_section(exp: Experiment, stats: Dict[Key, Dict[str, float]], methods: Sequence[str],
                   extra_frames: int, multi: Sequence[str] = MULTI_FRAME_METHODS) -> str:
    """Markdown section of one experiment: misclassification, motion error, K-frame tables."""
    names2 = runner_names(exp, 2, methods)
    parts = [f'## {exp.title}', '']
    parts += ['Misclassification %, mean (median) over trials, two views:', '',
              _table(exp, stats, 2, names2, _cell_miscl)]
    motion_names = [n for n in names2 if not n.startswith('floor')]
    parts += ['Relative angular-velocity error %, mean (median) over trials of the mean over '
              'rotating bodies of |w_est - w_true| / |w_true|, two views:', '',
              _table(exp, stats, 2, motion_names, _cell_rel)]
    unassigned = _unassigned_table(exp, stats, methods, extra_frames, multi)
    if unassigned:
        parts += ['Of which unassigned (label -1, rejected as outliers), % of lines, mean:', '',
                  unassigned]
    if exp.pure_translation_body:
        parts += ['Error |w_est| of the pure-translation body (deg/frame; its true w = 0), '
                  'two views:', '',
                  _table(exp, stats, 2, motion_names,
                         lambda s: '—' if s is None else _fmt(s['last_deg'], 3))]
    if any(n.endswith('(f unknown)') for n in names2):
        fnames = [n for n in names2 if n.endswith('(f unknown)')]
        parts += ['Focal-length relative error % with unknown intrinsics, mean (median):', '',
                  _table(exp, stats, 2, fnames,
                         lambda s: '—' if s is None else
                         f"{_fmt(s['f_err_mean'])} ({_fmt(s['f_err_median'])})")]
    if extra_frames > 2:
        namesk = runner_names(exp, extra_frames, methods, multi)
        rows = []
        for name in namesk:
            rows.append([f'{name}, K={extra_frames}'] + [
                _cell_miscl(stats.get((exp.key, extra_frames, name, j)))
                for j in range(len(exp.xs))])
        if 'robust' in methods:
            rows.append(['robust, K=2 (same table above)'] + [
                _cell_miscl(stats.get((exp.key, 2, 'robust', j))) for j in range(len(exp.xs))])
        parts += [f'Misclassification %, mean (median), {extra_frames} views (constant motion; '
                  f'each line gives {2 * (extra_frames - 1)} rows):', '',
                  common.markdown_table(['method'] + _x_headers(exp), rows)]
        run_multi = [m for m in runner_names(exp, extra_frames, methods, multi)
                     if not m.startswith('floor')]
        if run_multi:
            parts += [f'Relative angular-velocity error %, mean (median), {extra_frames} views:',
                      '', _table(exp, stats, extra_frames, run_multi, _cell_rel)]
    return '\n'.join(parts)


def headline(exps: Sequence[Experiment], stats: Dict[Key, Dict[str, float]],
             methods: Sequence[str], extra_frames: int,
             multi: Sequence[str] = MULTI_FRAME_METHODS) -> str:
    """Mean misclassification % per method and floor at the noise levels of Fig. 2 and 5."""
    cols: List[Tuple[Experiment, int]] = []
    for exp in exps:
        if exp.sweep == 'noise_px':
            cols += [(exp, j) for j, x in enumerate(exp.xs) if x > 0]
    if not cols:
        return ''
    headers = ['method'] + [f'n={e.n_bodies}, {e.xs[j]:g} px' for e, j in cols]
    rows = []
    names = list(methods) + [FLOOR, FLOOR_W]
    frames = [(2, n) for n in names]
    if extra_frames > 2:
        names_k = runner_names(exps[0], extra_frames, methods, multi)
        frames += [(extra_frames, n) for n in names_k]
    for k, name in frames:
        label = name if k == 2 else f'{name}, K={extra_frames}'
        rows.append([label] + [
            _fmt(stats[(e.key, k, name, j)]['miscl_mean'], 1)
            if (e.key, k, name, j) in stats else '—' for e, j in cols])
    return common.markdown_table(headers, rows)


def timing_table(exps: Sequence[Experiment], stats: Dict[Key, Dict[str, float]],
                 field: str = 'cpu_ms_median') -> str:
    """Median solver time per call (ms, ``field`` of the stats) per runner and experiment."""
    rows = []
    keys = sorted({(k, name) for (_, k, name, _) in stats}, key=lambda t: (t[0], t[1]))
    for k, name in keys:
        row: List[object] = [f'{name}, K={k}']
        for exp in exps:
            vals = [stats[(exp.key, k, name, j)][field] for j in range(len(exp.xs))
                    if (exp.key, k, name, j) in stats]
            row.append(_fmt(float(np.median(vals)), 1) if vals else '—')
        rows.append(row)
    return common.markdown_table(['runner'] + [e.key for e in exps], rows)


def plot_experiment(exp: Experiment, stats: Dict[Key, Dict[str, float]],
                    methods: Sequence[str], extra_frames: int, path,
                    multi: Sequence[str] = MULTI_FRAME_METHODS) -> None:
    """PNG: misclassification and motion error vs the swept value (+ the K-frame panel)."""
    n_panels = 3 if extra_frames > 2 else 2
    fig, axes = common.new_figure(n_panels)
    names2 = runner_names(exp, 2, methods)
    xs = list(exp.xs)

    def series(k: int, names: Sequence[str], field: str) -> Dict[str, List[float]]:
        return {n: [stats.get((exp.key, k, n, j), {}).get(field, math.nan)
                    for j in range(len(xs))] for n in names}

    fstyle = {n: {'color': COLORS.get(n.split(' ')[0], 'C5')} for n in names2
              if not n.startswith('floor')}
    for n in names2:
        if n.endswith('(f unknown)'):
            fstyle[n].update(linestyle=':', marker='s')
    common.plot_series(axes[0], xs, series(2, names2, 'miscl_mean'), exp.xlabel,
                       'misclassified lines (%), mean', 'two views', styles=fstyle)
    common.plot_series(axes[1], xs, series(2, [n for n in names2 if not n.startswith('floor')],
                                           'rel_mean'),
                       exp.xlabel, 'relative error of w (%), mean (log scale)', 'two views',
                       styles=fstyle)
    axes[1].set_yscale('log', nonpositive='mask')
    if n_panels == 3:
        namesk = runner_names(exp, extra_frames, methods, multi)
        sk = series(extra_frames, namesk, 'miscl_mean')
        s = {f'{n}, K={extra_frames}': v for n, v in sk.items()}
        styles = {f'{FLOOR_W}, K={extra_frames}': {'color': '0.55'}}
        styles.update({f'{m}, K={extra_frames}': {'color': COLORS[m]}
                       for m in MULTI_FRAME_METHODS})
        if 'robust' in methods:
            s['robust, K=2'] = series(2, ['robust'], 'miscl_mean')['robust']
            styles['robust, K=2'] = {'color': 'C3', 'alpha': 0.5, 'linestyle': '-.'}
        common.plot_series(axes[2], xs, s, exp.xlabel, 'misclassified lines (%), mean',
                           f'{extra_frames} views', styles=styles)
        axes[2].legend(fontsize=7, loc='best')
    fig.suptitle(exp.title, fontsize=11)
    common.save_figure(fig, path, legend_ax=axes[0])


HOW_TO_READ = """\
## How to read

- Scenes follow the paper's section 4.1 (`mlofc_tools.synthetic.make_scene`): 1000 x 1000 px,
  f = 1000 px, principal point at the centre, random 3D segments 5-8 units deep and 50-400 px
  long, each body rotating about the camera centre by 2-6 deg per frame about a random axis,
  Gaussian noise on every endpoint coordinate, endpoints sliding along their 3D line between
  frames (no point correspondence), lines shuffled.
- Translation (Fig. 3, 4): `|T| = t |w|` per frame with `w` in rad/frame and `T` in scene units
  (the paper's "linear velocity t times as large as the angular velocity"); at 5-8 units depth the
  translational image flow is about `t / 6.5` times the rotational one. In Fig. 4 the second body
  has `w = 0` and `|T| = t |w_0|`; at t = 0 it is static.
- Misclassification: fraction of lines whose label differs from the truth after the best
  relabelling of the predicted bodies; unassigned lines (`-1`) count as wrong. Cells give the
  mean over trials and, in brackets, the median; `[k fail]` counts trials where the method raised
  (counted as 100 % misclassified, excluded from motion errors).
- Motion error: `|w_est - w_true| / |w_true|` per body after the same relabelling, averaged over
  the bodies that rotate (Fig. 4's pure-translation body is reported separately, in deg/frame).
- Floors: every line assigned to the body whose TRUE motion explains it best, with the paper's
  unweighted residual (`floor (unweighted)`) and with the noise-weighted residual
  (`floor (weighted)`). No method can be expected to beat the floor of the same residual on the
  same data; a method below the unweighted floor is using a better residual.
- `(f unknown)`: intrinsics not given (image size only); the focal length is estimated.
- `K=5`: the same protocol with five views and constant motion (rotation and translation);
  the multi-frame methods (`robust`; `general`, which also fits a translation per body and needs
  three or more views: with two views it returns the rotation-only result; run with K views on
  the translation experiments, Fig. 3-4, only, for time) and the floors (true rotations,
  translation ignored). Under translation a "floor" built from the true rotations
  alone is not a bound: estimated rotations can absorb part of the translational flow.
- Every method sees the same scenes (seeds fixed by experiment, K, point and trial).
"""


def build_report(exps: Sequence[Experiment], stats: Dict[Key, Dict[str, float]],
                 errors: Dict[str, List[str]], methods: Sequence[str], args: argparse.Namespace,
                 command: str, seconds: float, revision: Optional[str] = None) -> str:
    """Return the whole Markdown report; ``revision``: the commit the run imported."""
    cpu = sum(s['cpu_total'] for s in stats.values())
    extra = {'Trials per point': str(args.trials), 'Methods': ', '.join(methods),
             f'Methods on the {args.frames}-view scenes': ', '.join(
                 m for m in methods if m in args.multi) or 'none',
             'Run time': f'{seconds:.0f} s wall with {args.jobs} worker process(es); '
                         f'{cpu:.0f} s CPU in the solver calls (the wall time depends on what '
                         f'else the machine runs; CPU / workers is the uncontended estimate)',
             'Base seed': str(args.seed)}
    parts = [common.run_header('Paper experiments (section 4.1, Fig. 2-5)', command, extra,
                               revision)]
    head = headline(exps, stats, methods, args.frames, args.multi)
    if head:
        parts += ['## Headline: misclassification %, mean over trials', '', head]
    parts.append(HOW_TO_READ)
    for exp in exps:
        parts.append(figure_section(exp, stats, methods, args.frames, args.multi))
        parts.append(f'![{exp.key}](paper_{exp.key}.png)\n')
    parts += ['## Solver time', '', 'Median CPU time per call (ms), one process, per experiment:',
              '', timing_table(exps, stats, 'cpu_ms_median'),
              'Median wall time per call (ms; inflated when the machine is shared):', '',
              timing_table(exps, stats, 'ms_median')]
    if errors:
        parts += ['## Failures', '']
        for where, msgs in sorted(errors.items()):
            uniq = sorted(set(msgs))
            parts.append(f'- {where}: {len(msgs)} trial(s); e.g. `{uniq[0][:200]}`')
        parts.append('')
    return '\n'.join(parts)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """Command-line options of ``python -m mlofc_tools.bench paper``."""
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench paper', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--trials', type=int, default=None,
                   help='scenes per point (default 50; 2 with --quick)')
    p.add_argument('--quick', action='store_true',
                   help='smoke run: 2 points per figure, 2 trials, K=3 extra views')
    p.add_argument('--out', default=None, help='output folder (default docs/results/paper)')
    p.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1),
                   help='worker processes (default min(2, cores))')
    p.add_argument('--seed', type=int, default=2007, help='base seed (default 2007)')
    p.add_argument('--frames', type=int, default=None,
                   help='views of the extra multi-frame runs (default 5; 3 with --quick; '
                        '2 = none)')
    p.add_argument('--figs', default='fig2,fig3,fig4,fig5',
                   help='comma-separated subset of fig2,fig3,fig4,fig5')
    p.add_argument('--methods', default=None,
                   help='comma-separated subset of mlofc_ros.solver.METHODS (default all)')
    p.add_argument('--multi', default=None,
                   help='methods also run on the multi-frame scenes (default '
                        f'{",".join(MULTI_FRAME_METHODS)}; robust with --quick)')
    args = p.parse_args(list(argv))
    if args.trials is None:
        args.trials = 2 if args.quick else 50
    if args.frames is None:
        args.frames = 3 if args.quick else 5
    if args.multi is None:
        args.multi = ('robust',) if args.quick else MULTI_FRAME_METHODS
    else:
        args.multi = tuple(m.strip() for m in args.multi.split(',') if m.strip())
    if args.trials < 1 or args.jobs < 1 or args.frames < 2:
        p.error('--trials and --jobs must be >= 1, --frames >= 2')
    return args


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the benchmark; returns the process exit code."""
    argv = list(argv or [])
    args = parse_args(argv)
    revision = common.commit()  # the code imported next
    from mlofc_ros.solver import METHODS

    methods = list(METHODS) if args.methods is None else [
        m.strip() for m in args.methods.split(',') if m.strip()]
    unknown = set(methods) - set(METHODS)
    if unknown:
        common.eprint(f'unknown methods {sorted(unknown)}; choose from {list(METHODS)}')
        return 2
    wanted = [f.strip() for f in args.figs.split(',') if f.strip()]
    exps = [e for e in experiments(args.quick) if e.key in wanted]
    if not exps:
        common.eprint(f'no experiment selected by --figs {args.figs!r}')
        return 2
    out_dir = common.results_dir('paper', args.out)
    units = make_units(exps, methods, args.trials, args.frames, args.seed, args.multi)
    # biggest scenes first so the pool ends evenly
    units.sort(key=lambda u: -(u.n_frames * u.exp.n_bodies ** 2 * len(u.runners)))
    common.eprint(f'paper: {len(units)} scenes, {sum(len(u.runners) for u in units)} solver '
                  f'calls, {args.jobs} process(es)')
    t0 = time.perf_counter()
    results = common.run_parallel(run_unit, units, args.jobs, 'scenes', reports=20,
                                  chunksize=2)
    seconds = time.perf_counter() - t0
    stats, errors = aggregate(results)
    command = common.command_line('paper', argv)
    report = build_report(exps, stats, errors, methods, args, command, seconds, revision)
    for exp in exps:
        plot_experiment(exp, stats, methods, args.frames, out_dir / f'paper_{exp.key}.png',
                        args.multi)
    common.write_report('paper', args.out, report)
    return 0
