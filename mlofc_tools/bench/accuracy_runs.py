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
Scenes and runs of the accuracy benchmark: the tasks, the solver calls, their scores, speed.

Every runner of a section sees the same scenes (seeds fixed by section, point and trial).
"""
from dataclasses import dataclass
import math
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import mlofc_ros  # noqa: F401 (first of the package: one BLAS thread, set before numpy loads)
from mlofc_tools.bench import common
from mlofc_tools.scoring import best_permutation, motion_errors
from mlofc_tools.synthetic import add_outliers, make_scene, MIXES, split_lines
import numpy as np  # noqa: I100 (numpy must load after mlofc_ros, see above)


FLOOR = 'floor (unweighted)'


FLOOR_W = 'floor (weighted)'


ORACLE = 'true-label fit'


AUTO = 'robust (n auto)'


SECTIONS = ('speed', 'floor', 'outliers', 'frames', 'nbodies')


SECTION_NO = {'floor': 1, 'outliers': 2, 'frames': 3, 'nbodies': 4, 'speed': 5}


COLORS = {'algebraic': 'C0', 'kmeans': 'C1', 'algebraic+kmeans': 'C2', 'robust': 'C3',
          ORACLE: 'C4'}


#: Lines per body of the paper's protocol (section 4.1: 20 for two bodies, 30 for three).
LINES_PER_BODY = {1: 20, 2: 20, 3: 30, 4: 30}


#: Fraction of tracks replaced by outliers.
OUTLIER_FRACTION = 0.15


#: A trial counts as broken when the robust inlier misclassification exceeds this fraction.
BROKEN = 0.2


@dataclass(frozen=True)
class Grid:
    """Sweep values of every section (full run or ``--quick``)."""

    floor_n: Tuple[int, ...] = (2, 3, 4)
    floor_noise: Tuple[float, ...] = (0.5, 1.0, 2.0)
    outlier_n: Tuple[int, ...] = (2, 3)
    outlier_k: Tuple[int, ...] = (2, 5)
    frames_k: Tuple[int, ...] = (2, 3, 5, 8)
    frames_noise: Tuple[float, ...] = (1.0, 2.0)
    frames_n: int = 3
    nbodies_n: Tuple[int, ...] = (1, 2, 3, 4)
    nbodies_k: Tuple[int, ...] = (2, 5)
    speed_lines: Tuple[int, ...] = (50, 100, 200, 500, 1000, 2000)
    speed_scenes: int = 5
    speed_reps: int = 4


QUICK_GRID = Grid(floor_n=(2, 3), floor_noise=(1.0,), outlier_n=(2,), outlier_k=(2,),
                  frames_k=(2, 5), frames_noise=(1.0,), nbodies_n=(1, 2), nbodies_k=(2,),
                  speed_lines=(50, 200), speed_scenes=1, speed_reps=2)


@dataclass(frozen=True)
class Task:
    """One scene of a section and what runs on it; ``key`` locates the sweep point."""

    section: str
    key: Tuple
    trial: int
    seed: int
    methods: Tuple[str, ...] = ('robust',)


Record = Dict[str, object]


Raw = Dict[Tuple[str, Tuple, str], List[Record]]


def _seed(base: int, section: str, indices: Sequence[int]) -> int:
    ss = np.random.SeedSequence([base, SECTION_NO[section], *indices])
    return int(ss.generate_state(1)[0])


def make_tasks(sections: Sequence[str], grid: Grid, trials: int, seed: int,
               methods: Sequence[str] = ('robust',)) -> List[Task]:
    """
    Scenes of the accuracy sections; seeds depend only on (seed, section, point, trial).

    ``methods`` run in sections 1 and 2 (the other sections run 'robust' only).
    """
    tasks = []

    def add(section: str, key: Tuple, idx: Tuple[int, ...]) -> None:
        for t in range(trials):
            tasks.append(Task(section, key, t, _seed(seed, section, (*idx, t)), tuple(methods)))

    if 'floor' in sections:
        for n in grid.floor_n:
            for s in grid.floor_noise:
                add('floor', (n, s), (n, int(round(100 * s))))
    if 'outliers' in sections:
        for n in grid.outlier_n:
            for k in grid.outlier_k:
                for mix in MIXES:  # the same inlier scenes for every mix
                    add('outliers', (n, k, mix), (n, k))
    if 'frames' in sections:
        for k in grid.frames_k:
            for s in grid.frames_noise:
                add('frames', (k, s), (k, int(round(100 * s))))
    if 'nbodies' in sections:
        for k in grid.nbodies_k:
            for n in grid.nbodies_n:
                add('nbodies', (k, n), (k, n))
    return tasks


def _timed(fn: Callable[[], object]) -> Tuple[Optional[object], Optional[str], float]:
    """Call ``fn``; returns (result or None, error text or None, CPU seconds)."""
    c0 = time.process_time()
    try:
        res, err = fn(), None
    except Exception as exc:  # noqa: B902 (a failing method is a result, not a crash)
        res, err = None, f'{type(exc).__name__}: {exc}'
    return res, err, time.process_time() - c0


def _failed(err: str, cpu: float) -> Record:
    return {'miscl': 1.0, 'rel': math.nan, 'in_rej': math.nan, 'out_rej': math.nan,
            'rej_jitter': math.nan, 'rej_stitched': math.nan, 'unassigned': 1.0,
            'failed': 1, 'error': err, 'cpu': cpu}


def _score(labels: np.ndarray, w_est: Optional[np.ndarray], truth: np.ndarray,
           w_true: np.ndarray, kind: Optional[np.ndarray] = None) -> Record:
    """Misclassification (over the inliers; ``-1`` wrong), rejections, relative w error."""
    labels = np.asarray(labels, dtype=np.int64)
    n = w_true.shape[0]
    inl = np.ones(labels.shape[0], bool) if kind is None else kind == 0
    perm, errors = best_permutation(labels[inl], truth[inl], n)
    rec: Record = {'miscl': errors / max(int(inl.sum()), 1),
                   'unassigned': float(np.mean(labels < 0)),
                   'in_rej': float(np.mean(labels[inl] < 0)), 'failed': 0}
    rec['rel'] = (motion_errors(w_est, w_true, perm)[0]
                  if w_est is not None and np.shape(w_est)[0] == n else math.nan)
    for name, code in (('out_rej', None), ('rej_jitter', 1), ('rej_stitched', 2)):
        sel = (~inl if code is None else kind == code) if kind is not None else np.zeros(0, bool)
        rec[name] = float(np.mean(labels[sel] < 0)) if np.any(sel) else math.nan
    return rec


def _oracle_fit(tracks: np.ndarray, truth: np.ndarray, n: int,
                intrinsics: Sequence[float]) -> np.ndarray:
    """
    Fit the solver's model to the lines with their TRUE labels (weighted least squares).

    Returns the angular velocities ``(n, 3)`` in rad/frame: the reference for the motion error.
    """
    from mlofc_ros.solver.lines import cayley_to_rotvec, line_flows
    from mlofc_ros.solver.models import fit_bodies
    c, _ = fit_bodies(line_flows(np.asarray(tracks, np.float64), tuple(intrinsics)), truth, n,
                      weighted=True)
    return cayley_to_rotvec(c)


def _run_fixed_n(tracks: np.ndarray, scene: object, runners: Sequence[str], seed: int,
                 kind: Optional[np.ndarray] = None) -> Dict[str, Record]:
    """Run ``runners`` (methods, floors, oracle) with the true number of bodies and score."""
    from mlofc_ros.solver import assign_with_motions, segment_lines
    n = scene.n_bodies
    w_true = scene.angular_velocities
    inl = np.ones(tracks.shape[0], bool) if kind is None else kind == 0
    out: Dict[str, Record] = {}
    for name in runners:
        if name == ORACLE:
            w, err, cpu = _timed(lambda: _oracle_fit(tracks[inl], scene.labels[inl], n,
                                                     scene.intrinsics))
            rec = _failed(err, cpu) if err else {
                'miscl': math.nan, 'rel': motion_errors(w, w_true, range(n))[0],
                'failed': 0, 'cpu': cpu}
            out[name] = rec
            continue
        if name in (FLOOR, FLOOR_W):
            def call(name: str = name) -> object:
                return assign_with_motions(tracks, w_true, intrinsics=scene.intrinsics,
                                           weighted=name == FLOOR_W)
        else:
            def call(name: str = name) -> object:
                return segment_lines(tracks, n, intrinsics=scene.intrinsics,
                                     image_size=scene.image_size, method=name, seed=seed)
        res, err, cpu = _timed(call)
        if err:
            out[name] = _failed(err, cpu)
            continue
        w_est = None if name in (FLOOR, FLOOR_W) else res.angular_velocities
        rec = _score(res.labels, w_est, scene.labels, w_true, kind)
        rec['cpu'] = cpu
        out[name] = rec
    return out


def run_task(task: Task) -> Tuple[Task, Dict[str, Record]]:
    """Build the task's scene and run every runner of its section on it (worker function)."""
    from mlofc_ros.solver import segment_lines
    sec, key, methods = task.section, task.key, task.methods
    try:
        if sec == 'floor':
            n, noise = key
            scene = make_scene(n, LINES_PER_BODY[n], n_frames=2, noise_px=noise, seed=task.seed)
        elif sec == 'outliers':
            n, k, _ = key
            scene = make_scene(n, LINES_PER_BODY[n], n_frames=k, noise_px=1.0, seed=task.seed)
        elif sec == 'frames':
            k, noise = key
            scene = make_scene(3, LINES_PER_BODY[3], n_frames=k, noise_px=noise,
                               seed=task.seed)
        else:
            k, n = key
            scene = make_scene(n, LINES_PER_BODY[n], n_frames=k, noise_px=1.0, seed=task.seed)
    except ValueError as exc:
        return task, {'_scene': {'error': f'scene: {exc}'}}
    if sec == 'floor':
        return task, _run_fixed_n(scene.tracks, scene, (*methods, FLOOR, FLOOR_W), task.trial)
    if sec == 'outliers':
        rng = np.random.default_rng(np.random.SeedSequence([task.seed, 1]))
        tracks, kind = add_outliers(scene.tracks, OUTLIER_FRACTION, rng, key[2])
        runners = (*methods, FLOOR, FLOOR_W, ORACLE) if key[2] == 'mixed' else (
            'robust', FLOOR, FLOOR_W, ORACLE)
        return task, _run_fixed_n(tracks, scene, runners, task.trial, kind)
    if sec == 'frames':
        return task, _run_fixed_n(scene.tracks, scene, ('robust', FLOOR, FLOOR_W, ORACLE),
                                  task.trial)
    # nbodies: automatic choice of n
    res, err, cpu = _timed(lambda: segment_lines(scene.tracks, 0, intrinsics=scene.intrinsics,
                                                 image_size=scene.image_size,
                                                 method='robust', seed=task.trial))
    if err:
        return task, {AUTO: dict(_failed(err, cpu), n_est=0)}
    n_true, n_est = scene.n_bodies, res.n_bodies
    _, errors = best_permutation(res.labels, scene.labels, max(n_true, n_est))
    return task, {AUTO: {'miscl': errors / scene.labels.shape[0], 'n_est': n_est,
                         'failed': 0, 'cpu': cpu}}


def run_tasks(tasks: Sequence[Task], jobs: int) -> Tuple[Raw, Dict[str, List[str]], float]:
    """Run every task (``jobs`` worker processes); raw records per (section, key, runner)."""
    order = sorted(tasks, key=lambda t: -_cost(t))  # biggest first so the pool ends evenly
    t0 = time.perf_counter()
    results = common.run_parallel(run_task, order, jobs if len(order) >= 4 * jobs else 1,
                                  'scenes', chunksize=2)
    raw: Raw = {}
    errors: Dict[str, List[str]] = {}
    for task, out in results:
        for name, rec in out.items():
            raw.setdefault((task.section, task.key, name), []).append(rec)
            if 'error' in rec:
                errors.setdefault(f'{name}, {task.section} {task.key}', []).append(
                    str(rec['error']))
    return raw, errors, time.perf_counter() - t0


def _cost(task: Task) -> float:
    """Rough relative cost of a task (for scheduling)."""
    a, b = task.key[:2]
    if task.section == 'nbodies':
        return 6.0 * a * b
    if task.section == 'frames':
        return 3.0 * a
    return 4.0 * a * (b if task.section == 'outliers' else 2)


def _reference_data() -> Tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(12345)
    return rng.normal(size=(4000, 12)), rng.normal(size=50_000)


def reference_workload(data: Tuple[np.ndarray, np.ndarray]) -> float:
    """
    Run a fixed numpy workload (~ the solver's mix of small BLAS/LAPACK and elementwise work).

    QR and normal equations of a 4000 x 12 matrix, an SVD of the 12 x 12 product, row norms,
    and exp / sort of 50 000 numbers. Its time tracks how fast this machine runs numpy right
    now, so solver times are also reported as ratios to it.
    """
    a, v = data
    q, r = np.linalg.qr(a)
    g = a.T @ a
    s = np.linalg.svd(g, compute_uv=False)
    rows = np.einsum('ij,ij->i', a, a)
    e = np.exp(-np.abs(v)).sum() + np.sort(v)[len(v) // 2]
    return float(s[0] + rows.sum() + e + abs(r[0, 0]) + q[0, 0])


def run_speed(grid: Grid, seed: int) -> Dict[int, Dict[str, Dict[str, np.ndarray]]]:
    """
    Time the reference, 'algebraic' and 'robust' interleaved, per number of lines.

    For each N: ``grid.speed_scenes`` scenes (n = 3, K = 5, 1 px), one warm-up call each, then
    ``grid.speed_reps`` rounds of (reference, algebraic, robust, robust warm). 'robust warm' is
    the streaming case: the window one frame later, started from the labels of the first
    window's solve (``init_labels``), as the pipeline does. Returns per N and runner the wall and
    CPU seconds of every timed call.
    """
    from mlofc_ros.solver import segment_lines
    data = _reference_data()
    reference_workload(data)
    out: Dict[int, Dict[str, Dict[str, np.ndarray]]] = {}
    for n_lines in grid.speed_lines:
        scenes = [make_scene(3, split_lines(n_lines, 3), n_frames=6, noise_px=1.0,
                             seed=_seed(seed, 'speed', (n_lines, s)))
                  for s in range(grid.speed_scenes)]
        calls = {'reference': lambda sc: reference_workload(data)}
        for m in ('algebraic', 'robust'):
            calls[m] = (lambda sc, m=m: segment_lines(sc.tracks[:, :5], 3,
                                                      intrinsics=sc.intrinsics,
                                                      image_size=sc.image_size, method=m,
                                                      seed=0))
        first = {id(sc): calls['robust'](sc).labels for sc in scenes}
        calls['robust warm'] = (lambda sc: segment_lines(
            sc.tracks[:, 1:], 3, intrinsics=sc.intrinsics, image_size=sc.image_size, seed=0,
            init_labels=first[id(sc)]))
        wall = {name: [] for name in calls}
        cpu = {name: [] for name in calls}
        for sc in scenes:
            for fn in calls.values():
                fn(sc)
            for _ in range(grid.speed_reps):
                for name, fn in calls.items():
                    t0, c0 = time.perf_counter(), time.process_time()
                    fn(sc)
                    cpu[name].append(time.process_time() - c0)
                    wall[name].append(time.perf_counter() - t0)
        out[n_lines] = {name: {'wall': np.array(wall[name]), 'cpu': np.array(cpu[name])}
                        for name in calls}
        common.eprint(f'  speed N={n_lines}: robust '
                      f'{1000 * np.median(cpu["robust"]):.1f} ms CPU (warm '
                      f'{1000 * np.median(cpu["robust warm"]):.1f}), algebraic '
                      f'{1000 * np.median(cpu["algebraic"]):.1f} ms CPU, reference '
                      f'{1000 * np.median(cpu["reference"]):.2f} ms CPU')
    return out
