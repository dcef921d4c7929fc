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
Front-end benchmark: line detection and tracking on rendered and real sequences.

Run ``python -m mlofc_tools.bench frontend`` (or ``python -m mlofc_tools.bench.frontend``); writes
``README.md`` and ``frontend.png`` to ``docs/results/frontend/`` (or ``--out``).
"""
import argparse
from collections import defaultdict
import json
import os
import pathlib
import sys
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import cv2
from mlofc_ros.segments.detect import has_ximgproc, LineDetector
from mlofc_ros.tracks.config import TrackerConfig
from mlofc_ros.tracks.tracker import LineTracker
from mlofc_tools.bench import common
from mlofc_tools.bench.pipeline import read_real_sequence, REAL_DIR
from mlofc_tools.scoring import match_to_truth, score_tracks
import numpy as np

#: Real sequences (no ground truth), see ``/work/shared/data/real/README.md``.
REAL_SEQUENCES = ('visp_cube', 'rubik_cube', 'hamburg_taxi')


# ---------------------------------------------------------------------------------- inputs
def rendered_sequences(frames: int, seeds: Sequence[int], motions: Sequence[str],
                       boxes: Sequence[int]) -> List[Tuple[str, object]]:
    """Render the 640x480 test sequences: ``(label, RenderedSequence)`` per motion x seed."""
    from mlofc_tools.render import render_sequence
    out = []
    for motion in motions:
        for i, seed in enumerate(seeds):
            nb = int(boxes[i % len(boxes)])
            seq = render_sequence(n_boxes=nb, n_frames=frames, size=(640, 480), motion=motion,
                                  background=True, noise_sigma=2.0, fps=30.0, seed=int(seed))
            out.append((f'{motion} s{seed} {nb} boxes', seq))
    return out


def real_sequences(root: str, max_frames: int) -> List[Tuple[str, List[np.ndarray]]]:
    """Gray frames of the real sequences found under ``root`` (missing ones are skipped)."""
    out = []
    for name in REAL_SEQUENCES:
        frames, _ = read_real_sequence(os.path.join(root, name), max_frames)
        if frames:
            out.append((name, frames))
    return out


def detector_candidates() -> List[Tuple[str, Dict[str, object]]]:
    """Detector configurations to compare (contrib backends only when cv2.ximgproc exists)."""
    cands: List[Tuple[str, Dict[str, object]]] = [
        ('LSD scale 1.0', {'backend': 'lsd', 'scale': 1.0}),
        ('LSD scale 0.8 (OpenCV default)', {'backend': 'lsd', 'scale': 0.8}),
        ('LSD scale 0.5', {'backend': 'lsd', 'scale': 0.5}),
        ('resize 0.8 + LSD', {'backend': 'lsd_resize', 'scale': 0.8}),
        ('resize 0.5 + LSD', {'backend': 'lsd_resize', 'scale': 0.5}),
    ]
    if has_ximgproc():
        cands += [('FLD (contrib) 1.0', {'backend': 'fld', 'scale': 1.0}),
                  ('FLD (contrib) 0.5', {'backend': 'fld', 'scale': 0.5}),
                  ('EDLines (contrib) 1.0', {'backend': 'edlines', 'scale': 1.0})]
    # the backends as they are; the tracker's default detector (resize 0.8 + LSD + bridge)
    # and full-resolution LSD + bridge (the former default) as rows
    cands = [(name, dict(kw, bridge=False)) for name, kw in cands]
    cands.insert(1, ('LSD scale 1.0 + bridge', {'backend': 'lsd', 'scale': 1.0, 'bridge': True}))
    cands.insert(4, ('resize 0.8 + LSD + bridge (tracker default)',
                     {'backend': 'lsd_resize', 'scale': 0.8, 'bridge': True}))
    return cands


def _now() -> float:
    return time.perf_counter()


# ---------------------------------------------------------------------------------- detectors
def bench_detectors(seqs: Sequence[Tuple[str, object]], every: int = 3,
                    repeat: int = 3) -> List[Dict[str, object]]:
    """
    Recall / precision / accuracy / time of each detector candidate on rendered frames.

    Times are wall-clock medians over ``repeat`` passes, interleaved with the raw OpenCV LSD
    default (``cv2.createLineSegmentDetector()``) on the same frame as the reference.
    """
    cands = [(name, LineDetector(min_length=20.0, **kw)) for name, kw in detector_candidates()]
    raw_lsd = cv2.createLineSegmentDetector()
    frames = [(seq.frames[f], seq.truth[f]) for _, seq in seqs
              for f in range(0, len(seq.frames), every)]
    times: Dict[str, List[float]] = defaultdict(list)
    for _ in range(repeat):
        for img, _t in frames:
            t0 = _now()
            raw_lsd.detect(img)
            times['ref'].append(_now() - t0)
            for name, det in cands:
                t0 = _now()
                det.detect(img)
                times[name].append(_now() - t0)
    ref = float(np.median(times['ref']))
    rows = []
    for name, det in cands:
        rec30, rec40, prec, lerr, eerr, count = [], [], [], [], [], []
        for img, tr in frames:
            seg = det.detect(img)
            gi, le, ee = match_to_truth(seg, tr.segments, visible_fraction=tr.visible_fraction)
            glen = np.hypot(*(tr.segments[:, 2:] - tr.segments[:, :2]).T)
            cov = np.zeros(len(glen), bool)
            cov[gi[gi >= 0]] = True
            rec30.append(cov[glen >= 30].mean())
            rec40.append(cov[glen >= 40].mean())
            prec.append((gi >= 0).mean() if len(gi) else np.nan)
            lerr += le[gi >= 0].tolist()
            eerr += ee[gi >= 0].tolist()
            count.append(len(seg))
        t = np.asarray(times[name])
        rows.append({'name': name, 'recall30': float(np.mean(rec30)),
                     'recall40': float(np.mean(rec40)), 'precision': float(np.nanmean(prec)),
                     'line_err': float(np.median(lerr)), 'end_err': float(np.median(eerr)),
                     'segments': float(np.mean(count)), 'ms': 1e3 * float(np.median(t)),
                     'p95': 1e3 * float(np.percentile(t, 95)),
                     'ratio': float(np.median(t)) / ref, 'ref_ms': 1e3 * ref,
                     'cv2': cv2.__version__})
    return rows


# ---------------------------------------------------------------------------------- tracking
def run_tracker(make: Callable[[], LineTracker], frames: Sequence[np.ndarray],
                reference: bool = True) -> Dict[str, object]:
    """
    Run a fresh tracker over ``frames``: outputs and per-frame stage times (s).

    With ``reference`` the raw OpenCV LSD default runs on every frame first (same run, same
    frame) as the timing reference. Wall-clock (``total``, ``detect``, ``track``, ``ref``) and
    thread CPU time (``cpu``, ``ref_cpu``) per frame.
    """
    cv2.setNumThreads(1)
    tracker = make()
    raw_lsd = cv2.createLineSegmentDetector()
    ids, segs, det_t, trk_t, tot_t, ref_t, cpu_t, ref_cpu = [], [], [], [], [], [], [], []
    for img in frames:
        if reference:
            t0, c0 = _now(), time.thread_time()
            raw_lsd.detect(img)
            ref_t.append(_now() - t0)
            ref_cpu.append(time.thread_time() - c0)
        t0, c0 = _now(), time.thread_time()
        i, s = tracker.update(img)
        tot_t.append(_now() - t0)
        cpu_t.append(time.thread_time() - c0)
        det_t.append(tracker.last_timing['detect'] if tracker.last_timing['detected']
                     else np.nan)
        trk_t.append(tracker.last_timing['track'])
        ids.append(i)
        segs.append(s)
    return {'ids': ids, 'segs': segs, 'detect': np.asarray(det_t), 'track': np.asarray(trk_t),
            'total': np.asarray(tot_t), 'ref': np.asarray(ref_t), 'cpu': np.asarray(cpu_t),
            'ref_cpu': np.asarray(ref_cpu)}


#: Issue #3's tracking goal (per sequence and pooled): ``tracked 5`` at least this, id
#: switches (%) below this.
TRACKED_GOAL, SWITCH_GOAL_PCT = 0.90, 1.0


def pooled_score(scores: Sequence[Dict[str, float]], key: str, weight: str) -> float:
    """
    Pool ``key`` of :func:`score_tracks` results over sequences, weighted by ``weight``.

    E.g. ``tracked_5`` by ``windows`` (every edge window of every sequence counts once),
    ``id_switch_pct`` by ``transitions``; NaN when no sequence has a finite value.
    """
    w = np.array([float(sc[weight]) for sc in scores])
    v = np.array([float(sc[key]) for sc in scores])
    ok = np.isfinite(v) & (w > 0)
    return float(np.sum(v[ok] * w[ok]) / np.sum(w[ok])) if ok.any() else float('nan')


def meets_goal(score: Dict[str, float]) -> bool:
    """Whether ``score`` (``tracked_5``, ``id_switch_pct``: one sequence's or pooled) meets #3."""
    return score['tracked_5'] >= TRACKED_GOAL and score['id_switch_pct'] < SWITCH_GOAL_PCT


def pooled_row(scores: Sequence[Dict[str, float]]) -> List[object]:
    """
    Tracking-table row over all sequences: ``tracked 5`` and id switches pooled.

    ``tracked 5`` over every (edge, 5-frame window) of every sequence, id switches over every
    transition; the other columns are means of the per-sequence values.
    """
    def mean(key: str) -> float:
        return float(np.nanmean([float(sc[key]) for sc in scores]))
    return [f'all {len(scores)} (pooled)', pooled_score(scores, 'tracked_5', 'windows'),
            mean('tracked_5_resolvable'), mean('recall'),
            pooled_score(scores, 'id_switch_pct', 'transitions'),
            mean('id_switch_pct_resolvable'),
            pooled_score(scores, 'id_switch_pct_in_view', 'transitions_in_view'),
            mean('id_jump_pct'),
            mean('cross_body_jump_pct'), mean('line_err_px'), mean('endpoint_err_px'),
            mean('precision'), mean('unresolvable_window_pct')]


def _goal_text(track_rows: Sequence[Sequence[object]]) -> str:
    """Say how the rows (per sequence, then pooled) meet issue #3's tracking goal."""
    per, pooled = track_rows[:-1], track_rows[-1]
    good = [r for r in per
            if meets_goal({'tracked_5': float(r[1]), 'id_switch_pct': float(r[4])})]
    short = '; '.join(f'{r[0]} {float(r[1]):.3f} / {float(r[4]):.2f}%'
                      for r in per if r not in good)
    return (f'Goal (issue #3): `tracked 5` >= 0.90 and id switches < 1%. Pooled over all '
            f'{len(per)} sequences: {float(pooled[1]):.3f} / {float(pooled[4]):.2f}%. Per '
            f'sequence: {len(good)} of {len(per)} meet both'
            + (f' (not: {short}).' if short else '.'))


def lifetimes(ids: Sequence[np.ndarray]) -> np.ndarray:
    """Frames each track id was reported in (one entry per id)."""
    if not ids:
        return np.zeros(0, np.int64)
    _, counts = np.unique(np.concatenate([np.asarray(i, np.int64) for i in ids]),
                          return_counts=True)
    return counts


def _ms(x: np.ndarray, q: Optional[float] = None) -> float:
    x = np.asarray(x, dtype=np.float64)
    if x.size == 0:
        return float('nan')
    return 1e3 * float(np.median(x) if q is None else np.percentile(x, q))


# ---------------------------------------------------------------------------------- report
def _time_row(label: str, run: Dict[str, np.ndarray]) -> List[object]:
    """Return the timing table row of one tracker run (ms, and ratios to the LSD reference)."""
    ref, ref_mean = _ms(run['ref']), 1e3 * float(np.mean(run['ref']))
    return [label, _ms(run['detect'][np.isfinite(run['detect'])]), _ms(run['track']),
            _ms(run['track'], 95), _ms(run['total']), _ms(run['total'], 95),
            1e3 * float(run['total'].mean()), ref, _ms(run['total']) / ref,
            1e3 * float(run['total'].mean()) / ref_mean, _ms(run['cpu']),
            1e3 * float(run['cpu'].mean()), _ms(run['ref_cpu'])]


def plot(path: pathlib.Path, track_runs: Sequence[Tuple[str, Dict[str, object]]],
         survival: Dict[str, np.ndarray]) -> None:
    """Per-frame stage times vs the LSD reference, and GT-edge track survival curves."""
    fig, axes = common.new_figure(2, 5.2, 3.8)
    ax = axes[0]
    tot = np.concatenate([r['total'] for _, r in track_runs]) * 1e3
    ref = np.concatenate([r['ref'] for _, r in track_runs]) * 1e3
    trk = np.concatenate([r['track'] for _, r in track_runs]) * 1e3
    bins = np.linspace(0, max(np.percentile(np.concatenate([tot, ref]), 99), 1.0), 40)
    ax.hist(trk, bins=bins, alpha=0.6, label='tracking only (KLT/edge search/assoc.)')
    ax.hist(tot, bins=bins, alpha=0.6, label='detection + tracking')
    ax.hist(ref, bins=bins, alpha=0.6, label='raw LSD default (reference)')
    ax.set_xlabel('ms per 640x480 frame (1 thread)')
    ax.set_ylabel('frames')
    ax.set_title('per-frame time, rendered sequences', fontsize=10)
    ax.legend(fontsize=7)
    ax = axes[1]
    for name, surv in survival.items():
        ax.plot(np.arange(1, surv.size + 1), surv, marker='o', markersize=3, label=name)
    ax.set_xlabel('consecutive frames')
    ax.set_ylabel('share of GT edges (>= 30 px) kept by one id')
    ax.set_ylim(0, 1.02)
    ax.grid(True, alpha=0.3)
    ax.set_title('track survival on rendered sequences', fontsize=10)
    common.save_figure(fig, path, legend_ax=ax)


def survival_curve(ids: Sequence[np.ndarray], segs: Sequence[np.ndarray],
                   truth: Sequence[object], max_k: int = 10) -> np.ndarray:
    """Share of (GT edge >= 30 px, start frame) pairs tracked by one id for k = 1..max_k."""
    out = []
    for k in range(1, max_k + 1):
        out.append(score_tracks(ids, segs, truth, window=k)['tracked_5'])
    return np.asarray(out)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='python -m mlofc_tools.bench frontend',
                                 description='line detection and tracking benchmark')
    ap.add_argument('--frames', type=int, default=30, help='frames per rendered sequence')
    ap.add_argument('--seeds', default='0,1,2,3', help='render seeds (comma separated)')
    ap.add_argument('--boxes', default='2,3', help='boxes per sequence, cycled over seeds')
    ap.add_argument('--detect-every', type=int, default=None,
                    help='TrackerConfig.detect_every (default: the tracker default)')
    ap.add_argument('--detect-every-max', type=int, default=None,
                    help='TrackerConfig.detect_every_max: longest detection interval in a quiet '
                         'scene (default: the tracker default)')
    ap.add_argument('--regions', choices=('on', 'off'), default=None,
                    help='TrackerConfig.detect_regions: detection on demand on the image regions '
                         'no track explains (default: the tracker default)')
    ap.add_argument('--backend', default=None,
                    help='tracker detector backend (lsd, lsd_resize, fld, edlines)')
    ap.add_argument('--scale', type=float, default=None, help='tracker detector scale')
    ap.add_argument('--bridge', choices=('on', 'off', 'join'), default=None,
                    help='TrackerConfig.bridge_crossings: lines cut up by crossings '
                         'added (on, the default), not (off), or joined with the segments they '
                         'continue (join: bridge_join=True)')
    ap.add_argument('--lsd-bins', type=int, default=None,
                    help='TrackerConfig.lsd_bins: gradient-norm bins of LSD')
    ap.add_argument('--real-dir', default=REAL_DIR)
    ap.add_argument('--real-frames', type=int, default=80)
    ap.add_argument('--quick', action='store_true', help='10 frames, one seed (smoke run)')
    ap.add_argument('--detectors-only', action='store_true',
                    help='only the detector comparison; print it as JSON (for other venvs)')
    ap.add_argument('--contrib-json', default=None,
                    help='detector rows measured in another venv (--detectors-only output) '
                         'to include in the report')
    ap.add_argument('--out', default=None, help='output folder (default docs/results/frontend)')
    return ap.parse_args(list(argv))


def _nth(k: int) -> str:
    """Return the English ordinal of ``k`` (1st, 2nd, 3rd, 4th, ..., 11th, 12th, 21st)."""
    suffix = 'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')
    return f'{k}{suffix}'


def _schedule(tracker: LineTracker) -> str:
    """Say when the tracker's detector runs (a fixed rate, or on demand)."""
    if tracker.detect_every_max <= tracker.detect_every:
        return f'every {_nth(tracker.detect_every)}'
    return (f'on demand: every {_nth(tracker.detect_every)} frame up to every '
            f'{_nth(tracker.detect_every_max)} while the scene is quiet')


def _detector_table(rows: Sequence[Dict[str, object]]) -> str:
    return common.markdown_table(
        ['detector (+ merge, >= 20 px)', 'recall GT>=30', 'recall GT>=40', 'precision',
         'line err px', 'endpoint err px', 'segments', 'ms median', 'ms p95',
         'x LSD default', 'LSD default ms (same run)', 'OpenCV'],
        [[r['name'], r['recall30'], r['recall40'], r['precision'], r['line_err'],
          r['end_err'], r['segments'], r['ms'], r['p95'], r['ratio'], r['ref_ms'], r['cv2']]
         for r in rows])


def tracker_config(args: argparse.Namespace) -> TrackerConfig:
    """Return the tracker settings the options ask for (the defaults for the others)."""
    kw = {name: value for name, value in (
        ('detect_every', args.detect_every), ('detect_every_max', args.detect_every_max),
        ('detector_backend', args.backend), ('detector_scale', args.scale),
        ('lsd_bins', args.lsd_bins)) if value is not None}
    if args.regions is not None:
        kw['detect_regions'] = args.regions == 'on'
    if args.bridge is not None:
        kw['bridge_crossings'] = args.bridge != 'off'
        kw['bridge_join'] = args.bridge == 'join'
    return TrackerConfig(**kw)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the benchmark; returns the process exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse_args(argv)
    cv2.setNumThreads(1)
    frames = 10 if args.quick else args.frames
    seeds = [int(x) for x in args.seeds.split(',') if x.strip()][:1 if args.quick else None]
    boxes = [int(x) for x in args.boxes.split(',') if x.strip()]
    t_start = _now()
    common.eprint('frontend: rendering sequences')
    seqs = rendered_sequences(frames, seeds, ('camera_centre', 'own_centre'), boxes)
    common.eprint('frontend: detectors')
    det_rows = bench_detectors(seqs, every=3, repeat=1 if args.quick else 3)
    if args.detectors_only:
        print(json.dumps(det_rows, indent=1))
        return 0
    config = tracker_config(args)

    def make() -> LineTracker:
        return LineTracker(config)
    common.eprint('frontend: tracking (rendered)')
    track_rows, time_rows, track_runs, survival = [], [], [], {}
    pooled: List[Dict[str, float]] = []
    for label, seq in seqs:
        run = run_tracker(make, seq.frames)
        sc = score_tracks(run['ids'], run['segs'], seq.truth)
        survival[label] = survival_curve(run['ids'], run['segs'], seq.truth,
                                         min(10, len(seq.frames)))
        track_runs.append((label, run))
        track_rows.append([label, sc['tracked_5'], sc['tracked_5_resolvable'], sc['recall'],
                           sc['id_switch_pct'], sc['id_switch_pct_resolvable'],
                           sc['id_switch_pct_in_view'],
                           sc['id_jump_pct'], sc['cross_body_jump_pct'], sc['line_err_px'],
                           sc['endpoint_err_px'], sc['precision'],
                           sc['unresolvable_window_pct']])
        time_rows.append(_time_row(label, run))
        pooled.append(sc)
    track_rows.append(pooled_row(pooled))
    common.eprint('frontend: real sequences')
    real_rows = []
    for name, imgs in real_sequences(args.real_dir, args.real_frames):
        run = run_tracker(make, imgs)
        life = lifetimes(run['ids'])
        counts = np.asarray([len(i) for i in run['ids']])
        h, w = imgs[0].shape
        label = f'{name} ({w}x{h}, {len(imgs)} frames)'
        real_rows.append([label, float(counts.mean()),
                          float(np.median(life)) if life.size else float('nan'),
                          float(np.percentile(life, 90)) if life.size else float('nan'),
                          int(life.size)])
        time_rows.append(_time_row(label, run))
    contrib_rows = []
    if args.contrib_json:
        contrib_rows = json.loads(pathlib.Path(args.contrib_json).read_text())
    report = build_report(args, argv, det_rows, contrib_rows, track_rows, real_rows,
                          time_rows, _now() - t_start, make())
    plot(common.results_dir('frontend', args.out) / 'frontend.png', track_runs, survival)
    common.write_report('frontend', args.out, report)
    return 0


def build_report(args: argparse.Namespace, argv: Sequence[str],
                 det_rows: Sequence[Dict[str, object]], contrib_rows: Sequence[Dict[str, object]],
                 track_rows: Sequence[Sequence[object]], real_rows: Sequence[Sequence[object]],
                 time_rows: Sequence[Sequence[object]], seconds: float,
                 tracker: LineTracker) -> str:
    """Return the Markdown report of the front-end benchmark."""
    command = common.command_line('frontend', argv)
    lines = [common.run_header(
        'Front end: line detection and tracking', command,
        {'Threads': 'cv2.setNumThreads(1); timings are wall-clock on a shared machine: '
                    'compare against the LSD reference measured in the same run',
         'Tracker': f'LineTracker({tracker.config})',
         'Run time': f'{seconds:.0f} s'})]
    lines += _detector_section(det_rows, contrib_rows)
    lines += _tracking_section(track_rows, real_rows)
    lines += _time_section(time_rows, tracker)
    lines += ['![frontend](frontend.png)', '']
    return '\n'.join(lines)


def _detector_section(det_rows: Sequence[Dict[str, object]],
                      contrib_rows: Sequence[Dict[str, object]]) -> List[str]:
    """Return the report's lines on the detectors, and why the tracker's is chosen."""
    lines: List[str] = []
    lines += ['## Detectors on rendered frames', '',
              'Every 3rd frame of the rendered sequences below. A detection matches a GT edge '
              'when within 3 deg, both ends of its overlap within 2 px of the GT line and at '
              'least half of it on the (visibility-extended) GT segment; recall = share of GT '
              'edges of the given length with a matching detection. All rows include the '
              'vectorised collinear merge and the 20 px floor.', '',
              _detector_table(det_rows)]
    if contrib_rows:
        lines += ['Measured in a separate venv holding opencv-contrib-python-headless instead '
                  'of opencv-python-headless (same rendered frames, its own LSD reference in '
                  'the same run): `PYTHONPATH=. /tmp/contrib-venv/bin/python -m '
                  'mlofc_tools.bench.frontend --detectors-only > contrib.json`, then this report '
                  'with `--contrib-json contrib.json`.', '', _detector_table(contrib_rows)]
    lines += ['**Choice.** The tracker detects on some frames only (every `detect_every`-th, '
              'or fewer on demand) and carries lines in between (edge search along the '
              'normals, ~0.1 px), so detection quality per detector call matters more than '
              'its speed: births of tracks need detections, and every missed birth is a '
              'missed edge for several frames. '
              'LSD at full resolution (`scale=1.0`) has the best recall and the lowest line '
              'error of all candidates, at about 2x the cost of the OpenCV default. On the '
              'image resized by 0.8 (area average, `lsd_resize`: the tracker default) LSD '
              'detects fewer edges per call but it is cheaper, and in the '
              'tracker, which refines and grows the lines it carries, it tracks as many edges '
              'as LSD 1.0 (the tracking table below; render seeds 0-9 in the docstring of '
              '`LineDetector`); the Gaussian sub-sampling of LSD itself at 0.8 tracks about 1 '
              'point fewer. LSD at scale 0.5 (or on a half-size image) is 2x cheaper than '
              'the default but misses '
              'a tenth of the edges and doubles the line error. The contrib detectors (FLD, '
              'EDLines) are 2.5-3x cheaper than the LSD default, with recall per call between '
              'LSD 0.8 and LSD 0.5 and 2-3x the line error of LSD 1.0. In the tracker with '
              '`bridge_crossings`, FLD at full resolution tracks about as many '
              'edges as the default (`tracked 5` / id switches, render seeds 0-3: 0.930 / '
              '0.52% vs 0.937 / 0.53%, `--backend fld --scale 1.0`; seeds 4-9: 0.937 / 0.48% '
              'vs 0.931 / '
              '0.52%) for about a third less front-end CPU per frame (mean), with ~30% larger '
              'line errors, about twice the endpoint error, own_centre s0 at 1.29% id '
              'switches and 10-15% fewer segments on two of the real sequences; the node '
              'offers it as `detector_backend:=fld` (with `detector_scale:=1.0`; it needs '
              'opencv-contrib-python-headless in place of opencv-python-headless). Without '
              '`bridge_crossings` FLD and EDLines track 5 points fewer edges.', '']
    return lines


def _tracking_section(track_rows: Sequence[Sequence[object]],
                      real_rows: Sequence[Sequence[object]]) -> List[str]:
    """Return the report's lines on tracking, rendered (scored) and real sequences."""
    lines: List[str] = []
    lines += ['## Tracking on rendered sequences (640x480, background + boxes)', '',
              '`tracked 5` = share of (GT edge >= 30 px, 5 consecutive frames in which it is '
              'visible) with one track id on the edge in all 5 frames. `id switch` = % of '
              'frame-to-frame transitions of a GT edge where none of its previous ids remains '
              '(MOT style, re-acquisition after a loss counts). `id jump` = % of a track’s '
              'consecutive matches on a *different* GT edge (a track mixing two 3D lines; most '
              'are stripes collapsing onto a cube edge as a face turns edge-on), `cross-body` '
              'the subset onto another body. Errors are medians over matched track segments; '
              '`precision` = share of reported segments on some GT edge.', '',
              '`tracked 5` and `id switch %` are the headline (strict) numbers: every GT edge '
              'counts. The `resolvable edges only` columns are an additional view: they leave '
              'out the windows / transitions in which the GT edge is, in some frame, '
              'unresolvable, i.e. another GT edge lies within 3 deg of it and within 2 px of '
              'its line along at least half of its length (the tolerances by which a track is '
              'matched to an edge, so a track there would match both; in these renders: '
              'stripes converging on each other or on a box edge as a face turns edge-on). '
              '`unresolvable windows %` = share of the `tracked 5` windows so left out. '
              '`edge in view throughout`: the id switches of the transitions in which the GT '
              'edge stayed in view (>= 30 px) in every frame since it was last matched, i.e. '
              'without the re-acquisitions of an edge that left the view (a face turning away '
              'and back), which a tracker without re-identification always counts as '
              'switches; over long sequences of boxes spinning about their own centres they '
              'are most of the switches.', '',
              common.markdown_table(
                  ['sequence', 'tracked 5', 'tracked 5, resolvable edges only', 'recall',
                   'id switch %', 'id switch %, resolvable edges only',
                   'id switch %, edge in view throughout', 'id jump %',
                   'cross-body jump %', 'line err px', 'endpoint err px', 'precision',
                   'unresolvable windows %'],
                  track_rows), '', _goal_text(track_rows)]
    lines += ['## Real sequences (no ground truth)', '',
              common.markdown_table(
                  ['sequence', 'segments / frame', 'track lifetime median (frames)',
                   'lifetime p90', 'tracks'], real_rows)]
    return lines


def _time_section(time_rows: Sequence[Sequence[object]], tracker: LineTracker) -> List[str]:
    """Return the report's lines on the time per frame, against the LSD reference."""
    lines: List[str] = []
    lines += ['## Time per frame (one thread)', '',
              'Wall-clock ms per frame on a shared 2-core machine, so read them against '
              '`LSD ref`: the raw OpenCV LSD default (`cv2.createLineSegmentDetector()`) run on '
              'the same frame just before, in the same run; the `/ LSD` columns are the '
              'ratios of medians / means. `detect` = the detector on the frames where it runs '
              f'({_schedule(tracker)}), `track` = everything else (edge search, KLT '
              'for new or lost tracks, association, births). CPU = thread CPU time (less '
              'sensitive to other processes).', '',
              common.markdown_table(
                  ['sequence', 'detect ms (det. frames)', 'track ms median', 'track p95',
                   'total median', 'total p95', 'total mean', 'LSD ref median',
                   'median / LSD', 'mean / LSD', 'CPU total median', 'CPU total mean',
                   'CPU LSD ref'], time_rows)]
    return lines


if __name__ == '__main__':
    sys.exit(main())
