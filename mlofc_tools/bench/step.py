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
One warm solver update of ``general`` against OpenCV's LSD alone, by number of lines.

Run ``python -m mlofc_tools.bench step``; writes ``README.md`` and ``step.png`` to
``docs/results/step/``. A stream solved with ``method='general'`` mostly steps: each frame
advances the previous window's bodies (``segment_lines(..., step=True)``), and every few
frames a step also rescans a body from the pivot starts. Issue #39 asks for one such update
of 200 lines, 3 bodies and a 10-frame window within 0.25x the CPU of OpenCV's default LSD
alone on a 640x480 frame. Scenes: :func:`mlofc_tools.synthetic.make_scene` with 3 bodies,
each turning 0.5-1.5 deg per frame and translating (``translation_ratio`` 3: at 5-8 units
the translational flow is about half the rotational), 1 px of endpoint noise, 11 frames; the
first 10 are solved cold (untimed), and the window one frame later is the update, started
from that solve's labels and motions. Timed in turn, CPU of this thread
(``time.thread_time``), so that all see the same machine load: LSD alone on frames of
``bench spinning``'s own3+bg (640x480), the plain step, the step that rescans one body, and
for scale ``robust``'s warm solve of the last 5 frames (its own window). Calls: the function
calls of one step (``cProfile``'s count: Python's and numpy's functions, not numpy's
arithmetic operators), the same on every machine; a step's CPU grows little with its lines:
at these array sizes most numpy calls and operations cost their fixed overhead.
"""
import argparse
import cProfile
import pstats
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from mlofc_tools.bench import common
import numpy as np

#: Bodies, window (frames), each body's rotation (deg per frame, about the camera centre:
#: larger turns take lines out of the image within 11 frames) and its translation per frame
#: relative to its rotation (:func:`mlofc_tools.synthetic.make_scene`).
BODIES, WINDOW, ROTATION_DEG, TRANSLATION_RATIO = 3, 10, (0.5, 1.5), 3.0

#: The update's goal, a multiple of LSD alone (issue #39), and the number of lines it is read at.
GOAL_X_LSD, GOAL_LINES = 0.25, 200

RUNNERS = ('step', 'step with a rescan', 'robust warm')

HEADERS = ['N lines', 'steps held', 'step wrong % (mean)', 'step CPU ms (p90)', 'step / LSD',
           'step with a rescan CPU ms (p90)', 'rescan step / LSD', 'robust warm CPU ms (p90)',
           'robust warm / LSD', 'LSD CPU ms (p90)', 'calls per step']


def _updates(n_lines: int, seed: int) -> Tuple[Dict[str, Callable[[], object]], np.ndarray]:
    """
    Return the timed calls of one scene of ``n_lines`` lines (each runner's update), its labels.

    The scene's first :data:`WINDOW` frames are solved cold first; a step that does not hold
    raises :class:`~mlofc_ros.solver.StepNotTaken` (counted by the caller).
    """
    from mlofc_ros.solver import segment_lines
    from mlofc_ros.solver.warm import result_motions
    from mlofc_tools.synthetic import make_scene, split_lines
    sc = make_scene(BODIES, split_lines(n_lines, BODIES), n_frames=WINDOW + 1, noise_px=1.0,
                    rotation_deg=ROTATION_DEG, translation_ratio=TRANSLATION_RATIO, seed=seed)
    common_kw = {'intrinsics': sc.intrinsics, 'image_size': sc.image_size, 'seed': 0}
    cold = segment_lines(sc.tracks[:, :WINDOW], BODIES, method='general', **common_kw)
    warm = {'init_labels': cold.labels, 'init_motions': result_motions(cold), 'step': True,
            'step_only': True}
    later = sc.tracks[:, 1:]
    rescan = [0]                                   # one body, as a stream rescans
    return {
        'step': lambda: segment_lines(later, BODIES, method='general', **common_kw, **warm),
        'step with a rescan': lambda: segment_lines(later, BODIES, method='general',
                                                    rescan=rescan, **common_kw, **warm),
        'robust warm': lambda: segment_lines(later[:, -5:], BODIES, method='robust',
                                             init_labels=cold.labels, **common_kw)}, sc.labels


def count_calls(fn: Callable[[], object]) -> int:
    """Return the function calls (``cProfile``'s count) of one call of ``fn``."""
    profile = cProfile.Profile()
    profile.enable()
    try:
        fn()
    except Exception:  # noqa: B902 (a step that does not hold still made its calls)
        pass
    profile.disable()
    return int(pstats.Stats(profile).total_calls)


def run(lines: Sequence[int], scenes: int, reps: int, seed: int) -> Dict[int, Dict[str, object]]:
    """
    Time every runner and LSD alone in turn; return per N the CPU ms of every timed call.

    Per N: ``scenes`` scenes, each runner called once untimed, then ``reps`` rounds of (LSD,
    each runner). Also ``held``: the steps that held (of the timed ones), ``wrong``: the
    mean misclassification of the steps' labels, and ``calls``: the median calls of a step.
    """
    import cv2
    from mlofc_ros.solver import StepNotTaken
    from mlofc_tools.bench.spinning import render_scene
    from mlofc_tools.scoring import misclassification
    cv2.setNumThreads(1)
    frames = render_scene('own3+bg', 0, 3).frames
    lsd = cv2.createLineSegmentDetector()
    out: Dict[int, Dict[str, object]] = {}
    for n_lines in lines:
        ms: Dict[str, List[float]] = {name: [] for name in ('LSD',) + RUNNERS}
        held, tried, calls, wrong = 0, 0, [], []
        for s in range(scenes):
            updates, truth = _updates(n_lines, seed + 1000 * n_lines + s)
            for name, fn in updates.items():
                try:
                    res = fn()
                    if name == 'step':
                        wrong.append(misclassification(res.labels, truth, BODIES))
                except StepNotTaken:
                    pass
            calls.append(count_calls(updates['step']))
            for r in range(reps):
                c = time.thread_time()
                lsd.detect(frames[r % len(frames)])
                ms['LSD'].append((time.thread_time() - c) * 1e3)
                for name, fn in updates.items():
                    c = time.thread_time()
                    try:
                        fn()
                        held += name == 'step'
                    except StepNotTaken:
                        pass
                    ms[name].append((time.thread_time() - c) * 1e3)
                    tried += name == 'step'
        out[n_lines] = {'ms': ms, 'held': held, 'tried': tried,
                        'calls': float(np.median(calls)),
                        'wrong': float(np.mean(wrong)) if wrong else float('nan')}
    return out


def _cell(values: Sequence[float]) -> str:
    st = common.summarize(values)
    return f"{st['median']:.1f} ({st['p90']:.1f})"


def build_rows(results: Dict[int, Dict[str, object]]) -> List[List[object]]:
    """Return the table's rows, one per number of lines (medians, ratios of medians)."""
    rows = []
    for n_lines, r in sorted(results.items()):
        ms = r['ms']
        lsd = float(np.median(ms['LSD']))
        row: List[object] = [n_lines, f"{r['held']} of {r['tried']}",
                             round(100.0 * r['wrong'], 2)]
        for name in RUNNERS:
            row += [_cell(ms[name]), round(float(np.median(ms[name])) / lsd, 2)]
        row += [_cell(ms['LSD']), int(r['calls'])]
        rows.append(row)
    return rows


def headline(results: Dict[int, Dict[str, object]]) -> str:
    """Return the goal's line: the step at :data:`GOAL_LINES` lines against LSD alone."""
    if GOAL_LINES not in results:
        return f'- No run at N = {GOAL_LINES}: the goal is not read.'
    r = results[GOAL_LINES]
    ratio = float(np.median(r['ms']['step'])) / float(np.median(r['ms']['LSD']))
    met = 'met' if ratio <= GOAL_X_LSD else 'NOT met'
    return (f'- One step of {GOAL_LINES} lines, {BODIES} bodies, a {WINDOW}-frame window: '
            f'**{ratio:.2f}x** LSD alone (median CPU; goal <= {GOAL_X_LSD}x: {met}), '
            f"{int(r['calls'])} calls per step.")


def plot(path, results: Dict[int, Dict[str, object]]) -> None:
    """CPU ms per update against N, with LSD alone and the goal as flat lines."""
    ns = sorted(results)
    fig, axes = common.new_figure(1, width_per_panel=6.0)
    series = {name: [float(np.median(results[n]['ms'][name])) for n in ns]
              for name in RUNNERS + ('LSD',)}
    series[f'goal: {GOAL_X_LSD}x LSD'] = [GOAL_X_LSD * v for v in series['LSD']]
    common.plot_series(axes[0], ns, series, 'lines', 'CPU ms (median)',
                       'one warm update vs LSD alone (640x480)')
    axes[0].set_yscale('log')
    common.save_figure(fig, path, legend_ax=axes[0])


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench step',
                                description=__doc__.split('\n')[1])
    p.add_argument('--lines', default='50,100,200,400', help='comma-separated line counts')
    p.add_argument('--scenes', type=int, default=5, help='scenes per line count')
    p.add_argument('--reps', type=int, default=4, help='timed rounds per scene')
    p.add_argument('--seed', type=int, default=0, help='base seed of the scenes')
    p.add_argument('--out', default=None, help='output folder (default docs/results/step)')
    return p.parse_args(list(argv))


def main(argv: Optional[Sequence[str]] = None) -> int:
    import sys
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    t0 = time.monotonic()
    revision = common.commit()       # before the runs import the code
    lines = [int(x) for x in args.lines.split(',') if x]
    results = run(lines, args.scenes, args.reps, args.seed)
    head = common.run_header(
        'One warm solver update of general against LSD alone', common.command_line('step', argv),
        {'Scenes': f'{args.scenes} per line count, {BODIES} bodies, {WINDOW}-frame window, '
                   f'{args.reps} timed rounds each',
         'Run time': f'{time.monotonic() - t0:.0f} s'}, revision)
    text = '\n'.join([head, '', '## Headline', '', headline(results), '',
                      '## By number of lines', '',
                      common.markdown_table(HEADERS, build_rows(results)), '',
                      'Medians over the timed calls, p90 in brackets; ratios are of medians. '
                      'Steps held: timed steps that returned a result (the others raised '
                      '`StepNotTaken` after the same work).', '',
                      __doc__.split('\n\n', 1)[1].strip(), '', '![step](step.png)', ''])
    plot(common.results_dir('step', args.out) / 'step.png', results)
    common.write_report('step', args.out, text)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
