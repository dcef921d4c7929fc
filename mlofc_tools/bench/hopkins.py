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
"""Hopkins155: real line tracks from pairs of tracked points, every solver method, f unknown.

``python -m mlofc_tools.bench hopkins [--windows 2] [--quick] [--methods ...] [--out DIR]``
writes ``hopkins.md`` and ``hopkins.png`` to ``docs/results/`` (or ``--out``) and prints the
report.

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
from dataclasses import dataclass
import json
import math
import os
import pathlib
import re
import subprocess
import time
from typing import Dict, List, Optional, Sequence, Tuple
import zlib

import numpy as np

from mlofc_tools.bench import common
from mlofc_tools.datasets import hopkins as hk

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
    """Motion codes of a checkerboard name (``'2RT3RCT_A'``: objects RT and R, camera T).

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


def _oracle(tracks: np.ndarray, labels: np.ndarray, n: int, size: Tuple[int, int], seed: int,
            robust_at_f: bool = True) -> Dict[str, Dict[str, float]]:
    """Compute oracle labels from the true grouping (see the module docstring).

    Also runs the robust method with the oracle's focal length given (is the focal length what
    the search gets wrong?).
    """
    from mlofc_ros.solver import assign_with_motions, segment_lines
    from mlofc_ros.solver.focal import profile_cost, refine_focal

    t0, c0 = time.perf_counter(), time.process_time()
    w, h = size
    centre = (w / 2.0, h / 2.0)
    f = refine_focal(profile_cost(tracks, labels, n, centre), float(max(w, h)), span=F_SPAN)
    intr = (f, f) + centre
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
        out[ROBUST_ORACLE_F] = {'miscl': common.misclassification(res.labels, labels, n),
                                'focal': f, 'unassigned': float(np.mean(res.labels < 0))}
    except ValueError as exc:
        out[ROBUST_ORACLE_F] = {'miscl': 1.0, 'focal': f, 'unassigned': 1.0, 'failed': 1,
                                'error': f'ValueError: {exc}'}
    out[ROBUST_ORACLE_F].update(seconds=time.perf_counter() - t0,
                                cpu=time.process_time() - c0)
    return out


def _oracle_general(tracks: np.ndarray, labels: np.ndarray, n: int, focal: float,
                    size: Tuple[int, int]) -> Dict[str, Dict[str, float]]:
    """General-model oracles: each TRUE group fitted alone, every line to its cheapest body.

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
    """Labels with a looser outlier bound, and whether the true grouping costs less.

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
    """Search or model for 'general': its cold search with the TRUE grouping as the only start.

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
            'truth_start_miscl': common.misclassification(sol['labels'], labels, n)}


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
            rec.update(miscl=common.misclassification(res.labels, labels, seq.n_motions),
                       focal=float(res.focal_length), failed=0,
                       unassigned=float(np.mean(res.labels < 0)))
            full = np.where(res.labels >= 0, res.labels, np.argmin(
                np.nan_to_num(res.costs, nan=np.inf), axis=1))
            miscl_full = common.misclassification(full, labels, seq.n_motions)
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
                                miscl=common.misclassification(loose, labels, seq.n_motions),
                                unassigned=float(np.mean(loose < 0))))
        if method in WITH_OUTLIERS:
            records.append(dict(rec, method=method + REASSIGNED, miscl=miscl_full,
                                unassigned=rec['unassigned'] if rec['failed'] else 0.0,
                                seconds=math.nan, cpu=math.nan))
    try:
        oracles = _oracle(tracks, labels, seq.n_motions, seq.image_size, unit.seed,
                          'robust' in unit.methods)
        if 'general' in unit.methods and unit.k >= 3:
            oracles.update(_oracle_general(tracks, labels, seq.n_motions,
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


# ---------------------------------------------------------------- aggregation and report

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
                 seconds: float, n_seq: int, solver: str = '') -> str:
    """Whole Markdown report."""
    seqs = per_sequence(records)
    ks = frames_of(seqs)
    cpu = float(np.nansum([float(r['cpu']) for r in records]))
    extra = {'Sequences': f'{n_seq}' + (' (--quick)' if args.quick else ' (Hopkins155, '
                                        'dancing excluded)'),
             'Windows per sequence and K': str(args.windows), 'K (frames per window)':
             ', '.join(map(str, ks)), 'Methods': ', '.join(methods),
             'Run time': f'{seconds:.0f} s wall with {args.jobs} worker process(es); '
                         f'{cpu:.0f} s CPU in solver and oracle calls',
             'Base seed': str(args.seed), 'Solver': solver or 'unknown'}
    parts = [common.run_header('Hopkins155 as line tracks (pairs of tracked points)',
                               command, extra)]
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
    p.add_argument('--out', default=None, help='output folder (default docs/results)')
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


def solver_state() -> str:
    """Git commit of the checkout and whether ``mlofc_ros/solver`` has uncommitted changes."""
    root = pathlib.Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=root, check=True,
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(['git', 'status', '--porcelain', '--', 'mlofc_ros/solver'],
                               cwd=root, check=True, capture_output=True, text=True,
                               timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return 'unknown (not a git checkout)'
    return f'git {head}' + (' with uncommitted changes in mlofc_ros/solver' if dirty else '')


def _shown(command: str) -> str:
    """Return the command without ``--save-records FILE`` (it does not change the results)."""
    return re.sub(r' --save-records(=| )\S+', '', command)


def _render(records, methods: Sequence[str], args: argparse.Namespace, command: str,
            seconds: float, n_seq: int, out_dir: pathlib.Path, solver: str) -> None:
    report = build_report(records, methods, args, command, seconds, n_seq, solver)
    (out_dir / 'hopkins.md').write_text(report)
    plot(records, methods, out_dir / 'hopkins.png')
    print(report)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the benchmark; returns the process exit code."""
    argv = list(argv or [])
    args = parse_args(argv)
    out_dir = common.results_dir(args.out)
    if args.load_records:
        saved = json.loads(pathlib.Path(args.load_records).read_text())
        run_args = argparse.Namespace(**saved['args'])
        _render(saved['records'], saved['methods'], run_args, _shown(saved['command']),
                saved['seconds'], saved['n_seq'], out_dir, saved.get('solver', 'unknown'))
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
    solver = solver_state()
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
             'args': run_args, 'solver': solver, 'records': records}))
    _render(records, methods, args, command, seconds, len(paths), out_dir, solver)
    common.eprint(f'hopkins: wrote {out_dir / "hopkins.md"} and hopkins.png in {seconds:.0f} s')
    return 0
