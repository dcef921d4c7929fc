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
Speed against tracking quality over the front end's settings: which goal costs which.

Run ``python -m mlofc_tools.bench tradeoff``; writes ``README.md`` and ``tradeoff.png`` to
``docs/results/tradeoff/``. For every combination of the node parameters ``detector_scale``,
``detect_every``, ``bridge_crossings`` and ``detect_every_max`` (``fixed`` = ``detect_every``, a
fixed rate; a larger value is detection on demand; the rest at their defaults):

- **speed**: :meth:`Pipeline.process` on the rendered 640x480 sequence of ``bench pipeline``
  (boxes rotating about the camera centre + background, 60 frames), thread CPU ms per frame,
  with OpenCV's default LSD on the same frame right after it as the reference. The ratio of
  MEANS counts the detection frames (the detector runs on every ``detect_every``-th frame
  only), so it is the throughput; the ratio of medians is that of a frame without detection
  (with ``detect_every`` >= 3; at 1-2 most frames detect). Issue #7's goal:
  the pipeline at most 0.5 x LSD.
- **quality**: the tracker the pipeline builds from the same parameters
  (:func:`~mlofc_ros.pipeline.make_tracker`) on the eight rendered sequences of ``bench
  frontend`` (camera_centre and own_centre, seeds 0-3, 30 frames), scored as there:
  ``tracked 5`` and id switches pooled over the eight, and how many sequences meet issue #3's
  goal on their own (``tracked 5`` >= 0.90 and id switches < 1%).

Settings are independent, so ``--jobs 2`` runs them in two processes (CPU time per thread,
ratios to the reference measured in the same process; still, compare ratios, not ms).
"""
import argparse
import functools
import itertools
import pathlib
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple

from mlofc_tools.bench import common, frontend
from mlofc_tools.bench.frontend import SWITCH_GOAL_PCT, TRACKED_GOAL
from mlofc_tools.scoring import score_tracks
import numpy as np

#: Issue #7's speed goal: ``Pipeline.process`` / LSD alone, here on the means.
SPEED_GOAL = 0.5

#: A setting: (detector_scale, detect_every, bridge_crossings, detect_every_max); a
#: detect_every_max of 0 stands for ``fixed`` (= detect_every).
Setting = Tuple[float, int, bool, int]


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='python -m mlofc_tools.bench tradeoff',
                                 description=__doc__.split('\n\n')[0])
    ap.add_argument('--scales', default='1.0,0.8,0.7,0.6,0.5', help='detector_scale values')
    ap.add_argument('--every', default='1,2,3,4,5,6,8', help='detect_every values')
    ap.add_argument('--bridge', default='on,off', help='bridge_crossings values (on/off)')
    ap.add_argument('--max', default='fixed,12',
                    help='detect_every_max values: fixed (= detect_every) or an integer')
    ap.add_argument('--frames', type=int, default=30, help='frames per tracking sequence')
    ap.add_argument('--seeds', default='0,1,2,3', help='render seeds of the tracking sequences')
    ap.add_argument('--timing-frames', type=int, default=60,
                    help='frames of the timed sequence (the first `window` are not counted)')
    ap.add_argument('--jobs', type=int, default=1, help='settings run in this many processes')
    ap.add_argument('--out', default=None, help='output folder (default docs/results/tradeoff)')
    return ap.parse_args(list(argv))


def settings(args: argparse.Namespace) -> List[Setting]:
    """
    Every combination of the ``--scales``, ``--every``, ``--bridge`` and ``--max`` values.

    An on-demand maximum not above ``detect_every`` is the fixed rate, listed once.
    """
    scales = [float(x) for x in args.scales.split(',') if x]
    every = [int(x) for x in args.every.split(',') if x]
    bridge = [x.strip() == 'on' for x in args.bridge.split(',') if x]
    top = [0 if x.strip() == 'fixed' else int(x) for x in args.max.split(',') if x]
    out = []
    for scale, n, b, m in itertools.product(scales, every, bridge, top):
        m = 0 if m <= n else m
        if (scale, n, b, m) not in out:
            out.append((scale, n, b, m))
    return out


def params_of(setting: Setting) -> Dict[str, object]:
    """Node parameters of a setting."""
    scale, every, bridge, top = setting
    return {'detector_scale': scale, 'detect_every': every, 'bridge_crossings': bridge,
            'detect_every_max': top if top > every else every}


def setting_text(setting: Setting) -> str:
    """Write the node parameters of a setting as ``-p`` style assignments."""
    return ' '.join(f'{k}:={str(v).lower()}' for k, v in params_of(setting).items())


@functools.lru_cache(maxsize=2)
def _sequences(frames: int, seeds: Tuple[int, ...], timing_frames: int) -> Tuple[object, list]:
    """
    Render the timed sequence and the tracking sequences, once per process.

    Every setting runs on the same frames; rendering them is about a quarter of a setting's
    time, so a worker keeps them.
    """
    from mlofc_tools.bench import pipeline as bench_pipeline
    timed = bench_pipeline.rendered_sequences([(640, 480)], timing_frames, 2, 0)[0]
    tracking = frontend.rendered_sequences(frames, seeds, ('camera_centre', 'own_centre'),
                                           (2, 3))
    return timed, tracking


def run_setting(item: Tuple[Setting, int, Sequence[int], int]) -> Dict[str, object]:
    """Time and score one setting: ``item = (setting, frames, seeds, timing frames)``."""
    import cv2

    from mlofc_ros import params as _params
    from mlofc_tools.bench import pipeline as bench_pipeline
    from mlofc_ros.pipeline import make_tracker, window_frames

    setting, frames, seeds, timing_frames = item
    cv2.setNumThreads(1)
    params = dict(_params.defaults(), **params_of(setting))
    seq, tracking = _sequences(frames, tuple(seeds), timing_frames)
    run = bench_pipeline.run_sequence(seq, params_of(setting))
    skip = window_frames(params)
    cpu, lsd = run['total_cpu'][skip:], run['lsd_cpu'][skip:]
    scores = []
    for _label, rendered in tracking:
        out = frontend.run_tracker(lambda: make_tracker(params), rendered.frames,
                                   reference=False)
        scores.append(score_tracks(out['ids'], out['segs'], rendered.truth))
    return {'setting': setting, 'mean_ratio': float(cpu.mean() / lsd.mean()),
            'median_ratio': float(np.median(cpu) / np.median(lsd)),
            'mean_ms': float(cpu.mean()), 'median_ms': float(np.median(cpu)),
            'lsd_ms': float(np.median(lsd)),
            'tracked_5': frontend.pooled_score(scores, 'tracked_5', 'windows'),
            'id_switch_pct': frontend.pooled_score(scores, 'id_switch_pct', 'transitions'),
            'meets': sum(map(frontend.meets_goal, scores)), 'sequences': len(scores),
            'worst_tracked_5': float(min(sc['tracked_5'] for sc in scores))}


def pareto(records: Sequence[Dict[str, object]]) -> List[bool]:
    """Whether each record is on the front: no other is both cheaper and tracks more."""
    out = []
    for r in records:
        out.append(not any(o['mean_ratio'] < r['mean_ratio'] and o['tracked_5'] > r['tracked_5']
                           for o in records))
    return out


HEADERS = ['detector_scale', 'detect_every', 'bridge_crossings', 'detect_every_max',
           'process / LSD (means)',
           'process / LSD (medians)', 'process mean ms', 'LSD median ms', 'tracked 5 (pooled)',
           'id switch % (pooled)', 'worst sequence tracked 5', 'sequences meeting #3',
           'meets #3 pooled', 'meets #7 (means)', 'front']


def build_rows(records: Sequence[Dict[str, object]]) -> List[List[object]]:
    """Table rows, fastest first (ratio of means)."""
    records = sorted(records, key=lambda r: r['mean_ratio'])
    front = pareto(records)
    rows = []
    for r, on_front in zip(records, front):
        scale, every, bridge, top = r['setting']
        ok3 = frontend.meets_goal(r)
        rows.append([scale, every, 'on' if bridge else 'off', top or 'fixed', r['mean_ratio'],
                     r['median_ratio'], r['mean_ms'], r['lsd_ms'], r['tracked_5'],
                     r['id_switch_pct'], r['worst_tracked_5'],
                     f"{r['meets']} / {r['sequences']}", 'yes' if ok3 else 'no',
                     'yes' if r['mean_ratio'] <= SPEED_GOAL else 'no',
                     'yes' if on_front else ''])
    return rows


def plot(path: pathlib.Path, records: Sequence[Dict[str, object]]) -> None:
    """Tracked-5 against the ratio of means, one marker per setting, the goals as lines."""
    fig, axes = common.new_figure(1, width_per_panel=7.0, height=5.0)
    ax = axes[0]
    for bridge, demand, marker in ((True, False, 'o'), (False, False, 's'),
                                   (True, True, '^'), (False, True, 'v')):
        rs = [r for r in records
              if r['setting'][2] == bridge and bool(r['setting'][3]) == demand]
        if not rs:
            continue
        sc = ax.scatter([r['mean_ratio'] for r in rs], [r['tracked_5'] for r in rs],
                        c=[r['setting'][0] for r in rs], cmap='viridis', vmin=0.4, vmax=1.0,
                        marker=marker)
        # a grey legend marker: the colour is the scale, not the bridge
        ax.scatter([], [], c='0.5', marker=marker,
                   label=f"bridge_crossings {'on' if bridge else 'off'}"
                         + (', on demand' if demand else ''))
        for r in rs:
            ax.annotate(str(r['setting'][1]), (r['mean_ratio'], r['tracked_5']),
                        textcoords='offset points', xytext=(4, 3), fontsize=7)
    fig.colorbar(sc, ax=ax, label='detector_scale')
    ax.axvline(SPEED_GOAL, color='k', ls='--', lw=0.8)
    ax.axhline(TRACKED_GOAL, color='k', ls=':', lw=0.8)
    ax.set_xlabel('Pipeline.process / LSD alone, ratio of means (CPU)')
    ax.set_ylabel('tracked 5, pooled over 8 rendered sequences')
    ax.set_title('front-end settings (numbers: detect_every); goals dashed / dotted',
                 fontsize=9)
    common.save_figure(fig, path, legend_ax=ax)


def build_report(argv: Sequence[str], records: Sequence[Dict[str, object]],
                 seconds: float) -> str:
    """Return the Markdown report."""
    text = common.run_header(
        'Speed vs tracking quality over the front-end settings',
        common.command_line('tradeoff', argv),
        {'Threads': 'single (`cv2.setNumThreads(1)`, one BLAS thread); CPU time per thread',
         'Wall time': f'{seconds:.0f} s'})
    fast = [r for r in records if r['mean_ratio'] <= SPEED_GOAL]
    good = [r for r in records if frontend.meets_goal(r)]
    both = [r for r in good if r['mean_ratio'] <= SPEED_GOAL]
    lines = [text, '## Headline', '']
    if both:
        lines.append(f'- {len(both)} of {len(records)} settings meet both goals.')
    else:
        lines.append(f'- No setting of the {len(records)} meets both goals (issue #7: process '
                     f'<= {SPEED_GOAL} x LSD on the means; issue #3: tracked 5 >= '
                     f'{TRACKED_GOAL}, id switches < {SWITCH_GOAL_PCT}%, pooled).')
    if good:
        best = min(good, key=lambda r: r['mean_ratio'])
        lines.append('- Fastest setting meeting #3 (pooled): '
                     f'`{setting_text(best["setting"])}`, {best["mean_ratio"]:.2f} x LSD on the '
                     f'means ({best["tracked_5"]:.3f} tracked, {best["id_switch_pct"]:.2f}% '
                     'switches).')
    if fast:
        best = max(fast, key=lambda r: r['tracked_5'])
        lines.append(f'- Best tracking within #7 (means): `{setting_text(best["setting"])}`, '
                     f'{best["tracked_5"]:.3f} tracked, '
                     f'{best["id_switch_pct"]:.2f}% switches, {best["mean_ratio"]:.2f} x LSD.')
    lines += ['', common.markdown_table(HEADERS, build_rows(records)), '',
              '`front`: no other setting is both cheaper (ratio of means) and tracks more. '
              'Node defaults: `detector_scale:=0.8 detect_every:=3 bridge_crossings:=true '
              'detect_every_max:=12`. `detect_every_max` `fixed`: the detector on every '
              '`detect_every`-th frame; a number: detection on demand up to that interval.', '',
              '![tradeoff](tradeoff.png)', '']
    return '\n'.join(lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(',') if s]
    items = [(s, args.frames, seeds, args.timing_frames) for s in settings(args)]
    t0 = time.monotonic()
    records = common.run_parallel(run_setting, items, args.jobs, what='settings',
                                  reports=len(items))
    plot(common.results_dir('tradeoff', args.out) / 'tradeoff.png', records)
    common.write_report('tradeoff', args.out, build_report(argv, records, time.monotonic() - t0))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
