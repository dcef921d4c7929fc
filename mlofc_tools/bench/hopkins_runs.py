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
Runs of the Hopkins155 benchmark: windows of line tracks, every solver method, the oracles.

One :class:`Unit` (a window of a sequence) is the work of one worker call (:func:`run_unit`).
"""
from dataclasses import dataclass
import math
import pathlib
import re
import time
from typing import Dict, List, Optional, Sequence, Tuple
import zlib

from mlofc_tools.datasets import hopkins as hk
from mlofc_tools.scoring import misclassification
import numpy as np


ORACLE = 'oracle (weighted)'


ORACLE_U = 'oracle (unweighted)'


#: Diagnostic rows (K >= 3, with 'general'): (w, T) fitted to every TRUE group with the general
#: model at the oracle's focal length, every line assigned to the cheapest body.
ORACLE_G = 'oracle general (marginalised directions)'


ORACLE_GF = 'oracle general (fitted directions)'


#: Diagnostic runner: the robust method with the focal length fixed at the oracle's.
ROBUST_ORACLE_F = 'robust, f = oracle f'


#: Suffix of the diagnostic rows where unassigned lines (-1) go to their cheapest body.
REASSIGNED = ', -1 -> cheapest body'


#: Methods that leave outliers unassigned (-1): they get a REASSIGNED diagnostic row.
WITH_OUTLIERS = ('robust', 'general')


#: Diagnostic row: robust with a looser outlier bound (LOOSE_BOUND x the chi-square bound).
LOOSE_BOUND = 3.0


LOOSE = f', -1 bound x{LOOSE_BOUND:g}'


#: Frames per window (K) of the default run; ``--ks`` adds others (e.g. 10).
FRAMES = (2, 5)


BENCH_GROUPS = ('checkerboard', 'traffic', 'articulated')


QUICK_SEQUENCES = ('cars1', 'two_cranes')


LINES_PER_MOTION = 30


MIN_LENGTH_PX = 40.0


MAX_USES = 2


#: The oracle's focal length is searched in ``max(w, h) / F_SPAN .. max(w, h) * F_SPAN``.
F_SPAN = 5.0


#: Published numbers on Hopkins155 / the paper's real sequence (misclassification %, 2 / 3
#: motions); the point methods use all points and all frames, not line pairs.
REFERENCES = (
    ('paper, MLOFC on real lines (two boxes, 10 frame pairs)', 17.197, None),
    ('SSC on points (Elhamifar & Vidal 2013), mean', 1.52, 4.40),
    ('GPCA on points (Tron & Vidal 2007), mean', 4.59, 28.66),
)


TICK_NAMES = {'checkerboard': 'checker-\nboard'}


_CHECKER = re.compile(r'^(\d)([RT]+)(\d)([RT]+)C([RTP]*)(?:_[AB])?$')


@dataclass(frozen=True)
class Unit:
    """One window of one sequence: the work of one worker call."""

    path: str
    name: str
    n_motions: int
    k: int
    window: int
    start: int
    seed: int
    methods: Tuple[str, ...]


def window_starts(n_frames: int, k: int, windows: int) -> List[int]:
    """First frames of ``windows`` K-frame windows spread evenly (first to last; middle if 1)."""
    last = n_frames - k
    if last < 0:
        return []
    if windows == 1:
        return [last // 2]
    return sorted({int(round(x)) for x in np.linspace(0, last, windows)})


def checkerboard_motion(name: str) -> Optional[Dict[str, str]]:
    """
    Motion codes of a checkerboard name (``'2RT3RCT_A'``: objects RT and R, camera T).

    Returns ``{'objects': 'RT,R', 'camera': 'T' or '' (fixed), 'translation': bool as str}``
    or None for names that do not follow the pattern (``three-cars``).
    """
    mt = _CHECKER.match(hk.parent_name(name))
    if mt is None:
        return None
    cam = mt.group(5)
    trans = 'T' in mt.group(2) + mt.group(4) + cam
    return {'objects': f'{mt.group(2)},{mt.group(4)}', 'camera': cam or 'fixed',
            'translation': 'yes' if trans else 'no'}


def oracle_focal(tracks: np.ndarray, labels: np.ndarray, n: int, size: Tuple[int, int]
                 ) -> float:
    """
    Return the oracle's focal length (px), from the true grouping ``labels (N,)``.

    The rotation-only profile cost's minimum, the principal point at the image centre of
    ``size`` ``(w, h)``, searched within :data:`F_SPAN` of ``max(w, h)``.
    """
    from mlofc_ros.solver.focal import profile_cost, refine_focal

    w, h = size
    return refine_focal(profile_cost(tracks, labels, n, (w / 2.0, h / 2.0)), float(max(w, h)),
                        span=F_SPAN)


def oracle(tracks: np.ndarray, labels: np.ndarray, n: int, size: Tuple[int, int], seed: int,
           robust_at_f: bool = True) -> Dict[str, Dict[str, float]]:
    """
    Compute oracle labels from the true grouping (see the module docstring).

    Also runs the robust method with the oracle's focal length given (is the focal length what
    the search gets wrong?).
    """
    from mlofc_ros.solver import assign_with_motions, segment_lines

    t0, c0 = time.perf_counter(), time.process_time()
    w, h = size
    f = oracle_focal(tracks, labels, n, size)
    intr = (f, f, w / 2.0, h / 2.0)
    rot = np.zeros((n, 3))
    resid = np.full(tracks.shape[0], np.nan)
    for i in range(n):                                  # n <= 3 groups
        sel = labels == i
        if np.count_nonzero(sel) < 2:
            continue
        res = segment_lines(tracks[sel], 1, intrinsics=intr, method='robust', seed=0)
        rot[i] = res.angular_velocities[0]
        resid[sel] = res.residuals
    out = {}
    for name, weighted in ((ORACLE, True), (ORACLE_U, False)):
        res = assign_with_motions(tracks, rot, intr, weighted=weighted)
        out[name] = {'miscl': float(np.mean(res.labels != labels)), 'focal': f,
                     'unassigned': 0.0,
                     'f_bound': float(np.log(f / max(w, h)) > 0.99 * np.log(F_SPAN)),
                     'resid_px': float(np.nanmedian(resid)),
                     'rot_deg': float(np.degrees(np.median(np.linalg.norm(rot, axis=1))))}
    out[ORACLE]['seconds'] = time.perf_counter() - t0
    out[ORACLE]['cpu'] = time.process_time() - c0
    out[ORACLE_U]['seconds'] = out[ORACLE_U]['cpu'] = math.nan
    if not robust_at_f:
        return out
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        res = segment_lines(tracks, n, intrinsics=intr, method='robust', seed=seed)
        out[ROBUST_ORACLE_F] = {'miscl': misclassification(res.labels, labels, n),
                                'focal': f, 'unassigned': float(np.mean(res.labels < 0))}
    except ValueError as exc:
        out[ROBUST_ORACLE_F] = {'miscl': 1.0, 'focal': f, 'unassigned': 1.0, 'failed': 1,
                                'error': f'ValueError: {exc}'}
    out[ROBUST_ORACLE_F].update(seconds=time.perf_counter() - t0,
                                cpu=time.process_time() - c0)
    return out


def oracle_general(tracks: np.ndarray, labels: np.ndarray, n: int, focal: float,
                   size: Tuple[int, int]) -> Dict[str, Dict[str, float]]:
    """
    General-model oracles: each TRUE group fitted alone, every line to its cheapest body.

    At the oracle's focal length ``focal`` (px). First with fitted line directions
    (:func:`mlofc_ros.solver.general.line_residuals`, the multi-start fit per group), then with
    marginalised directions (:func:`mlofc_ros.solver.general.marginal_residuals`) from there,
    at the noise level the 'general' method would take on these labels.
    """
    from mlofc_ros.solver import general as gm
    from mlofc_ros.solver.ksubspaces import assign
    from mlofc_ros.solver.lines import cayley_to_rotvec, line_flows
    from mlofc_ros.solver.models import fit_bodies

    t0, c0 = time.perf_counter(), time.process_time()
    w, h = size
    obs = gm.LineObservations(tracks, (focal, focal, w / 2.0, h / 2.0))
    c, _ = fit_bodies(line_flows(tracks, obs.intrinsics), labels, n)
    w_rot = cayley_to_rotvec(c)
    dof = np.maximum(2.0 * obs.frames - 4.0, 0.0)
    W, T = w_rot.copy(), np.zeros((n, 3))
    gm._fit_each_body(obs, labels, W, T, np.zeros(n, dtype=bool), 6, lambda b: w_rot[b])
    costs = gm.general_costs(obs, W, T)
    out = {ORACLE_GF: {'miscl': float(np.mean(assign(costs) != labels))}}
    sigma2 = gm.NOISE_FACTOR * gm._robust_sigma2(gm._best_costs(costs), dof)
    gm._fit_each_body(obs, labels, W, T, np.zeros(n, dtype=bool), 6, lambda b: W[b], sigma2,
                      lambda b: T[b])
    costs, _ = gm.marginal_costs(obs, W, T, sigma2)
    out[ORACLE_G] = {'miscl': float(np.mean(assign(costs) != labels))}
    for vals in out.values():
        vals.update(focal=focal, unassigned=0.0, seconds=math.nan, cpu=math.nan)
    out[ORACLE_G].update(seconds=time.perf_counter() - t0, cpu=time.process_time() - c0)
    return out


def _robust_diagnostics(tracks: np.ndarray, labels: np.ndarray, seq, res
                        ) -> Tuple[np.ndarray, float]:
    """
    Labels with a looser outlier bound, and whether the true grouping costs less.

    Both at robust's focal length and noise level. The second is 1.0 when the truncated
    cost of bodies fitted to the TRUE groups is below that of robust's own answer (then the
    search failed), 0.0 when it is not (the rotation-only objective prefers a wrong grouping).
    """
    from mlofc_ros.solver.ksubspaces import assign, total_cost
    from mlofc_ros.solver.lines import line_flows
    from mlofc_ros.solver.models import chi2_quantile, fit_bodies, track_costs
    from mlofc_ros.solver.robust import OUTLIER_P

    w, h = seq.image_size
    f = float(res.focal_length)
    flows = line_flows(tracks, (f, f, w / 2.0, h / 2.0))
    cap = (chi2_quantile(OUTLIER_P, 2.0 * flows.pairs_per_track())
           * float(res.diagnostics.sigma_px) ** 2)
    costs = np.where(np.isfinite(res.costs), res.costs, np.inf)
    loose = np.where(np.min(costs, axis=1) <= LOOSE_BOUND * cap, np.argmin(costs, axis=1), -1)
    c, _ = fit_bodies(flows, labels, seq.n_motions)
    truth = track_costs(flows, c, weighted=True)
    cheaper = total_cost(truth, assign(truth, cap), cap) < total_cost(res.costs, res.labels, cap)
    return loose, float(cheaper)


def _general_diagnostics(tracks: np.ndarray, labels: np.ndarray, seq, res, seed: int
                         ) -> Dict[str, float]:
    """
    Search or model for 'general': its cold search with the TRUE grouping as the only start.

    The same rotation-only step, focal length, noise level and starting motions as the
    method's own call (:func:`mlofc_ros.solver.general.general_search`), with the true labels
    instead of its starts. Returns ``truth_cheaper`` (1.0 when that solution's score, the
    capped marginalised cost plus the position terms, is below the scores of the method's
    answer and of the same search restarted from that answer: the search missed a better
    basin; 0.0 when the model itself prefers a wrong grouping) and ``truth_start_miscl``,
    that solution's misclassification.
    """
    from mlofc_ros.solver import general as gm
    from mlofc_ros.solver import segment_lines
    from mlofc_ros.solver.general_method import ROTATION_STEP
    from mlofc_ros.solver.spatial import spatial_neighbours

    n = seq.n_motions
    rot = segment_lines(tracks, n, None, seq.image_size, 'robust', seed=seed, **ROTATION_STEP)
    f = float(rot.focal_length)
    cx, cy = rot.diagnostics.principal_point
    obs = gm.LineObservations(tracks, (f, f * rot.diagnostics.aspect, cx, cy))
    neighbours = spatial_neighbours(obs.midpoints)
    sol, again = (gm.general_search(obs, n, [(name, lab)], rot.labels, rot.angular_velocities,
                                    neighbours, points=obs.midpoints)
                  for name, lab in (('truth', labels), ('answer', res.labels)))
    # the method's answer is not always a fixed point of its search: compared with both it
    # and a search restarted from it, a cheaper truth start is a basin the search missed
    best = min(float(res.diagnostics.score), float(again['score']))
    return {'truth_cheaper': float(sol['score'] < best),
            'truth_start_miscl': misclassification(sol['labels'], labels, n)}


def run_unit(unit: Unit) -> List[Dict[str, object]]:
    """Build the unit's line tracks and run every method and the oracle (worker function)."""
    from mlofc_ros.solver import segment_lines

    seq = hk.load_sequence(unit.path)
    tracks, labels = hk.line_tracks(seq, LINES_PER_MOTION, (unit.start, unit.k), MIN_LENGTH_PX,
                                    seed=unit.seed, max_uses=MAX_USES)
    base = {'sequence': seq.name, 'group': seq.group, 'n': seq.n_motions, 'k': unit.k,
            'window': unit.window, 'start': unit.start, 'lines': int(tracks.shape[0]),
            'min_lines': int(np.bincount(labels, minlength=seq.n_motions).min()),
            'flow_px': float(np.median(np.linalg.norm(
                np.diff(tracks, axis=1).reshape(tracks.shape[0], unit.k - 1, 2, 2),
                axis=3)))}
    records = []
    for method in unit.methods:
        t0, c0 = time.perf_counter(), time.process_time()
        rec = dict(base, method=method)
        try:
            res = segment_lines(tracks, seq.n_motions, intrinsics=None,
                                image_size=seq.image_size, method=method, seed=unit.seed)
            rec.update(miscl=misclassification(res.labels, labels, seq.n_motions),
                       focal=float(res.focal_length), failed=0,
                       unassigned=float(np.mean(res.labels < 0)))
            full = np.where(res.labels >= 0, res.labels, np.argmin(
                np.nan_to_num(res.costs, nan=np.inf), axis=1))
            miscl_full = misclassification(full, labels, seq.n_motions)
        except Exception as exc:  # noqa: B902 (a failing method is a result, not a crash)
            rec.update(miscl=1.0, focal=math.nan, failed=1, unassigned=1.0,
                       error=f'{type(exc).__name__}: {exc}')
            miscl_full = 1.0
        rec.update(seconds=time.perf_counter() - t0, cpu=time.process_time() - c0)
        records.append(rec)
        if method == 'general' and unit.k >= 3 and not rec['failed']:
            rec.update(_general_diagnostics(tracks, labels, seq, res, unit.seed))
            # what the method would score had its search found that solution where cheaper
            rec['found_miscl'] = rec['truth_start_miscl'] if rec['truth_cheaper'] else \
                rec['miscl']
        if method == 'robust' and not rec['failed']:
            loose, rec['truth_cheaper'] = _robust_diagnostics(tracks, labels, seq, res)
            records.append(dict(rec, method=method + LOOSE, seconds=math.nan, cpu=math.nan,
                                miscl=misclassification(loose, labels, seq.n_motions),
                                unassigned=float(np.mean(loose < 0))))
        if method in WITH_OUTLIERS:
            records.append(dict(rec, method=method + REASSIGNED, miscl=miscl_full,
                                unassigned=rec['unassigned'] if rec['failed'] else 0.0,
                                seconds=math.nan, cpu=math.nan))
    try:
        oracles = oracle(tracks, labels, seq.n_motions, seq.image_size, unit.seed,
                         'robust' in unit.methods)
        if 'general' in unit.methods and unit.k >= 3:
            oracles.update(oracle_general(tracks, labels, seq.n_motions,
                                          oracles[ORACLE]['focal'], seq.image_size))
        for name, vals in oracles.items():
            records.append(dict(dict(base, method=name, failed=0), **vals))
    except Exception as exc:  # noqa: B902
        for name in (ORACLE, ORACLE_U) + ((ROBUST_ORACLE_F,) if 'robust' in unit.methods
                                          else ()):
            records.append(dict(base, method=name, miscl=1.0, focal=math.nan, failed=1,
                                unassigned=1.0, seconds=math.nan, cpu=math.nan,
                                error=f'{type(exc).__name__}: {exc}'))
    return records


def pick_sequences(paths: Sequence[pathlib.Path], names: Optional[Sequence[str]]
                   ) -> List[pathlib.Path]:
    """Keep the ``paths`` whose stem is in ``names`` (all for None); ValueError if unknown."""
    if names is None:
        return list(paths)
    wanted = set(names)
    missing = wanted - {p.stem for p in paths}
    if missing:
        raise ValueError(f'unknown sequences {sorted(missing)}')
    return [p for p in paths if p.stem in wanted]


def n_motions_of(path: pathlib.Path) -> int:
    """Read the number of motions of a sequence file, not its point tracks."""
    with np.load(path) as z:
        return int(z['n_motions'])


def make_units(paths: Sequence[pathlib.Path], windows: int, methods: Sequence[str],
               seed: int, ks: Sequence[int] = FRAMES) -> List[Unit]:
    """All (sequence, K, window) units; pairing seeds depend on (seed, name, K, window)."""
    units = []
    for path in paths:
        with np.load(path) as z:
            n_frames, n_motions = int(z['points'].shape[0]), int(z['n_motions'])
        for k in ks:
            for w, start in enumerate(window_starts(n_frames, k, windows)):
                ss = np.random.SeedSequence([seed, zlib.crc32(path.stem.encode()), k, w])
                units.append(Unit(str(path), path.stem, n_motions, k, w, start,
                                  int(ss.generate_state(1)[0] % (2 ** 31)), tuple(methods)))
    return units
