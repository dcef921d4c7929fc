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
Image quality: the default pipeline on blurred, noisy and compressed frames of spinning boxes.

Run ``python -m mlofc_tools.bench degraded``; writes ``README.md`` and ``degraded.png`` to
``docs/results/degraded/``. The rendered scenes of ``bench spinning`` (boxes spinning about
their own centres in front of a static wall: they translate relative to the camera; and, as
the control where the rotation model holds and the default keeps it, boxes rotating about the
camera; the renderer's frames are sharp, with sensor noise of 2 grey levels) are degraded
frame by frame as a real camera and its transport degrade them, and go through
:class:`~mlofc_ros.pipeline.Pipeline` with its default parameters (``num_bodies`` the scene's):

- ``Gaussian blur s px``: defocus, ``cv2.GaussianBlur`` with sigma ``s``;
- ``noise s``: more sensor noise, Gaussian with ``s`` grey levels, clipped to 8 bits;
- ``JPEG qQ``: a compressed image transport, encoded and decoded at quality ``Q``;
- ``motion blur L px``: a camera panning during the exposure, a horizontal box filter of
  ``L`` px on the whole frame;
- ``camera``: a plausible camera, Gaussian blur 0.8 px, noise 3, JPEG q80, in that order.

The noise draws depend on the render seed only, so every run of a condition sees the same
frames. Scored on the frames with a full window as ``bench spinning`` scores them (wrong %,
-1 %: of the segments matched to true edges; each box's median angular-velocity error), and
the pipeline's own tracks as ``bench frontend`` scores the tracker's (tracked 5, id switches,
precision: the share of reported segments on some true edge, segments per frame).
"""
import argparse
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from mlofc_tools.bench import common
import numpy as np

#: Conditions by name, each a list of ``(kind, amount)`` steps applied in turn.
CONDITIONS: Dict[str, List[Tuple[str, float]]] = {
    'clean': [],
    'Gaussian blur 1.0 px': [('blur', 1.0)],
    'Gaussian blur 1.5 px': [('blur', 1.5)],
    'noise 5': [('noise', 5.0)],
    'noise 10': [('noise', 10.0)],
    'JPEG q75': [('jpeg', 75)],
    'JPEG q30': [('jpeg', 30)],
    'motion blur 5 px': [('motion', 5)],
    'motion blur 9 px': [('motion', 9)],
    'camera': [('blur', 0.8), ('noise', 3.0), ('jpeg', 80)],
}

#: The label goal of issue #39 (mean wrong %, worst run), as the report states it.
GOAL_WRONG_PCT, GOAL_WORST_PCT = 5.0, 10.0


def degrade(frames: Sequence[np.ndarray], steps: Sequence[Tuple[str, float]], seed: int
            ) -> List[np.ndarray]:
    """
    Return ``frames`` (uint8 gray) with the ``steps`` of a condition applied to each frame.

    ``steps``: ``(kind, amount)`` pairs of :data:`CONDITIONS`; the noise draws come from
    ``seed``. Raises ``ValueError`` for an unknown kind.
    """
    import cv2
    rng = np.random.default_rng(seed)
    out = []
    for gray in frames:
        img = np.asarray(gray)
        for kind, amount in steps:
            if kind == 'blur':
                img = cv2.GaussianBlur(img, (0, 0), float(amount))
            elif kind == 'noise':
                img = np.clip(img + rng.normal(0.0, amount, img.shape), 0, 255).astype(np.uint8)
            elif kind == 'jpeg':
                ok, buf = cv2.imencode('.jpg', img, [cv2.IMWRITE_JPEG_QUALITY, int(amount)])
                if not ok:
                    raise ValueError(f'cannot encode a {img.shape} {img.dtype} frame as JPEG')
                img = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
            elif kind == 'motion':
                img = cv2.filter2D(img, -1, np.full((1, int(amount)), 1.0 / int(amount)))
            else:
                raise ValueError(f'unknown degradation {kind!r}')
        out.append(img)
    return out


def run_one(item: Tuple[str, str, int, int]) -> Dict[str, object]:
    """
    Run one scene, condition and render seed through the pipeline; return its scores.

    ``item``: ``(scene, condition, seed, frames)``. Module-level: run in worker processes.
    """
    from mlofc_ros.pipeline import window_frames
    from mlofc_tools.bench.spinning import render_scene, run_pipeline, score_run
    from mlofc_tools.scoring import score_tracks
    scene, condition, seed, frames = item
    seq = render_scene(scene, seed, frames)
    seq.frames[:] = degrade(seq.frames, CONDITIONS[condition], seed)
    outs = run_pipeline(seq, 'auto', 0)
    first = min(window_frames({'method': 'auto', 'window': 0}) - 1, frames - 1)
    score = score_run(seq, outs, first)
    tracks = score_tracks([np.asarray(r.track_ids) for r, _ in outs],
                          [np.asarray(r.segments, dtype=float).reshape(-1, 4) for r, _ in outs],
                          seq.truth)
    score.update(tracked_5=tracks['tracked_5'], id_switch_pct=tracks['id_switch_pct'],
                 precision=tracks['precision'],
                 segments=float(np.mean([len(r.segments) for r, _ in outs[first:]])))
    return {'scene': scene, 'condition': condition, 'seed': seed, 'score': score}


def summary_rows(records: Sequence[Dict[str, object]]) -> List[List[object]]:
    """One row per (scene, condition) over its seeds, in :data:`CONDITIONS` order."""
    groups: Dict[Tuple[str, str], List[Dict[str, object]]] = {}
    for r in records:
        groups.setdefault((r['scene'], r['condition']), []).append(r['score'])
    order = {name: i for i, name in enumerate(CONDITIONS)}
    rows = []
    for (scene, condition) in sorted(groups, key=lambda k: (k[0], order.get(k[1], 99))):
        scores = groups[(scene, condition)]
        err = np.concatenate([s['omega_err'][np.isfinite(s['omega_err'])] for s in scores])
        rows.append([scene, condition, len(scores),
                     common.percent(float(np.mean([s['wrong'] for s in scores]))),
                     common.percent(float(max(s['wrong'] for s in scores))),
                     common.percent(float(np.mean([s['unassigned'] for s in scores]))),
                     f'{int(np.sum(err <= 0.10))} of {err.size}' if err.size else '—',
                     f'{100 * np.max(err):.0f}' if err.size else '—',
                     float(np.mean([s['tracked_5'] for s in scores])),
                     float(np.mean([s['id_switch_pct'] for s in scores])),
                     float(np.mean([s['precision'] for s in scores])),
                     float(np.mean([s['segments'] for s in scores]))])
    return rows


SUMMARY_HEADERS = ['scene', 'condition', 'seeds', 'wrong % (mean)', 'wrong % (worst)',
                   '-1 % (mean)', 'boxes within 10% of omega', 'worst box omega err %',
                   'tracked 5', 'id switch %', 'precision', 'segments per frame']


def plot(path, records: Sequence[Dict[str, object]]) -> None:
    """Bars per condition: mean wrong % (and the worst run) per scene; tracked 5 beside."""
    fig, axes = common.new_figure(2, width_per_panel=7.0, height=5.0)
    scenes = list(dict.fromkeys(r['scene'] for r in records))
    names = [c for c in CONDITIONS if any(r['condition'] == c for r in records)]
    width = 0.8 / max(len(scenes), 1)
    x0 = np.arange(len(names))
    for i, scene in enumerate(scenes):
        mean, worst, tracked = [], [], []
        for name in names:
            rs = [r['score'] for r in records if r['scene'] == scene and r['condition'] == name]
            mean.append(100 * np.mean([s['wrong'] for s in rs]) if rs else np.nan)
            worst.append(100 * max(s['wrong'] for s in rs) if rs else np.nan)
            tracked.append(np.mean([s['tracked_5'] for s in rs]) if rs else np.nan)
        x = x0 + (i - (len(scenes) - 1) / 2) * width
        axes[0].bar(x, mean, width, color=f'C{i}', label=f'{scene}: mean')
        axes[0].plot(x, worst, 'v', color=f'C{i}', label=f'{scene}: worst run')
        axes[1].bar(x, tracked, width, color=f'C{i}', label=scene)
    axes[0].axhline(GOAL_WRONG_PCT, color='0.3', linestyle='--', linewidth=1)
    axes[0].set_yscale('log')
    axes[0].set_title('segments on the wrong body, %', fontsize=10)
    axes[1].set_title('tracked 5 (the tracks)', fontsize=10)
    axes[1].set_ylim(0.0, 1.0)
    for ax in axes:
        ax.set_xticks(x0)
        ax.set_xticklabels(names, rotation=35, ha='right', fontsize=8)
        ax.grid(True, axis='y', alpha=0.3)
    fig.subplots_adjust(bottom=0.32)            # room for the conditions' slanted names
    common.save_figure(fig, path, legend_ax=axes[0])


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    from mlofc_tools.bench.spinning import scene_list
    p = argparse.ArgumentParser(prog='python -m mlofc_tools.bench degraded',
                                description=__doc__.split('\n')[1])
    p.add_argument('--scenes', type=scene_list, default=['own2+bg', 'own3+bg', 'cam2+bg'],
                   help='comma-separated scenes of bench spinning (default own2+bg,own3+bg,'
                        'cam2+bg)')
    p.add_argument('--conditions', default=','.join(CONDITIONS),
                   help=f'comma-separated conditions from {list(CONDITIONS)}')
    p.add_argument('--seeds', default='0,1,2,3', help='comma-separated render seeds')
    p.add_argument('--frames', type=int, default=60, help='frames per sequence (30 Hz)')
    p.add_argument('--jobs', type=int, default=2, help='worker processes')
    p.add_argument('--out', default=None, help='output folder (default docs/results/degraded)')
    args = p.parse_args(list(argv))
    args.seeds = [int(s) for s in args.seeds.split(',') if s]
    if not args.seeds:
        p.error('no seeds')
    args.conditions = [c for c in args.conditions.split(',') if c]
    unknown = [c for c in args.conditions if c not in CONDITIONS]
    if unknown or not args.conditions:
        p.error(f'unknown or no conditions {unknown}; choose from {list(CONDITIONS)}')
    return args


def build_report(argv: Sequence[str], args: argparse.Namespace,
                 records: Sequence[Dict[str, object]], seconds: float,
                 revision: Optional[str] = None) -> str:
    """Return the Markdown report; ``revision``: the commit at the start of the runs."""
    head = common.run_header(
        'Image quality: the default pipeline on degraded frames',
        common.command_line('degraded', argv),
        {'Sequences': f"{args.frames} frames 640x480 at 30 Hz of bench spinning's scenes, "
                      f"render seeds {','.join(map(str, args.seeds))}",
         'Pipeline': "node defaults (`method=auto`), `num_bodies` the scene's",
         'Run time': f'{seconds:.0f} s'}, revision)
    parts = [head, '', common.markdown_table(SUMMARY_HEADERS, summary_rows(records)), '',
             f'Issue #39 asks for at most {GOAL_WRONG_PCT:g}% wrong on the mean over the seeds '
             f'and {GOAL_WORST_PCT:g}% in the worst run, on its own scenes; the other columns '
             'say where a condition loses: in the tracks, or in the solve.', '',
             __doc__.split('\n\n', 1)[1].strip(), '', '![degraded](degraded.png)', '']
    return '\n'.join(parts)


def main(argv: Optional[Sequence[str]] = None,
         runner: Callable[[Tuple[str, str, int, int]], Dict[str, object]] = run_one) -> int:
    import sys
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    t0 = time.monotonic()
    # before the runs import the code: the report names the commit that ran, not a later one
    revision = common.commit()
    items = [(scene, cond, seed, args.frames) for scene in args.scenes
             for cond in args.conditions for seed in args.seeds]
    records = common.run_parallel(runner, items, args.jobs, what='runs')
    plot(common.results_dir('degraded', args.out) / 'degraded.png', records)
    common.write_report('degraded', args.out,
                        build_report(argv, args, records, time.monotonic() - t0, revision))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
