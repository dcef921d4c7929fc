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
Hopkins155 point tracks as real line tracks (no images: tracks and labels only).

Hopkins155 (R. Tron and R. Vidal, CVPR 2007) tracks feature points through short videos of 2 or
3 independent motions and labels every point with its motion. The files used here are the
``.npz`` conversion described in ``README.md`` of the data folder: ``points (F, P, 2)`` float32
pixel coordinates ``(u, v)`` (column, row), ``labels (P,)`` 0-based, ``width``, ``height``,
``n_motions``; every point is tracked in every frame.

Two points of one rigid body span a 3D line of that body, so a PAIR of tracked points with the
same label is a real line track: its endpoints are the two points in every frame, with the real
tracking noise and the real motion (rotation AND translation, which the paper's rotation-only
model ignores). :func:`pair_points` chooses the pairs, :func:`line_tracks` builds the
``(N, K, 4)`` endpoint array the solver takes.

Example::

    seq = load_sequence(DEFAULT_DATA_DIR / '1R2RC.npz')
    tracks, labels = line_tracks(seq, n_lines_per_motion=30, frames=(0, 2))
    tracks.shape        # (90, 2, 4): (u1, v1, u2, v2) per line and frame, pixels
"""
from dataclasses import dataclass
import os
import pathlib
import re
from typing import List, Optional, Tuple, Union

from mlofc_tools.datasets.shared import shared_data_dir
import numpy as np

PathLike = Union[str, 'os.PathLike[str]']

#: Folder of the ``.npz`` files: ``$MLOFC_HOPKINS_DIR`` if set, else the project's shared copy.
DEFAULT_DATA_DIR = pathlib.Path(os.environ.get('MLOFC_HOPKINS_DIR',
                                               shared_data_dir() / 'hopkins155'))

#: Benchmark groups (the benchmark's README); ``extra`` is ``dancing``, not one of the 155.
GROUPS = ('checkerboard', 'traffic', 'articulated', 'extra')

#: Pairing strategies of :func:`pair_points`.
STRATEGIES = ('random', 'long')

_TRAFFIC = re.compile(r'^(cars|truck)|^kanatani[12]$')
_ARTICULATED = ('arm', 'articulated', 'people1', 'people2', 'kanatani3', 'head', 'two_cranes')
_SUBSET = re.compile(r'_g\d\d$')


def parent_name(name: str) -> str:
    """Name of the full sequence a ``_g12``/``_g13``/``_g23`` two-motion subset comes from."""
    return _SUBSET.sub('', name)


def sequence_group(name: str) -> str:
    """
    Benchmark group of a sequence name: checkerboard, traffic, articulated or extra.

    Checkerboard: names starting with a digit and ``three-cars``; traffic: ``cars*``,
    ``truck*``, ``kanatani1/2``; articulated/non-rigid: ``arm``, ``articulated``, ``people1/2``,
    ``kanatani3``, ``head``, ``two_cranes``; ``dancing`` (5 motions) is ``extra``. Subsets
    (``_g12`` ...) belong to the group of their parent.

    Raises
    ------
    ValueError
        The name is none of the above.

    """
    base = parent_name(name)
    if base[:1].isdigit() or base == 'three-cars':
        return 'checkerboard'
    if _TRAFFIC.match(base):
        return 'traffic'
    if base in _ARTICULATED:
        return 'articulated'
    if base == 'dancing':
        return 'extra'
    raise ValueError(f'unknown Hopkins155 sequence {name!r} (no benchmark group)')


@dataclass(frozen=True)
class HopkinsSequence:
    """
    One Hopkins155 sequence.

    Attributes
    ----------
    name : str
        File stem, e.g. ``'1R2RC'`` or ``'1R2RC_g12'``.
    group : str
        One of :data:`GROUPS`.
    points : (F, P, 2) float64
        Pixel coordinates ``(u, v)`` of P points in F frames (no missing entries).
    labels : (P,) int64
        Motion of every point, ``0 .. n_motions-1``.
    width, height : int
        Frame size in pixels.
    n_motions : int
        Number of distinct motions (2 or 3 in the benchmark, 5 for ``dancing``).

    """

    name: str
    group: str
    points: np.ndarray
    labels: np.ndarray
    width: int
    height: int
    n_motions: int

    @property
    def n_frames(self) -> int:
        """Return the number of frames F."""
        return int(self.points.shape[0])

    @property
    def n_points(self) -> int:
        """Return the number of tracked points P."""
        return int(self.points.shape[1])

    @property
    def image_size(self) -> Tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self.width, self.height

    @property
    def is_subset(self) -> bool:
        """Return whether this is a ``_g12``/``_g13``/``_g23`` subset of a 3-motion sequence."""
        return parent_name(self.name) != self.name


def load_sequence(path: PathLike) -> HopkinsSequence:
    """
    Load one ``<sequence>.npz`` file.

    Raises
    ------
    ValueError
        Missing keys, inconsistent shapes, or non-finite coordinates.

    """
    path = pathlib.Path(path)
    with np.load(path) as z:
        missing = {'points', 'labels', 'width', 'height', 'n_motions'} - set(z.files)
        if missing:
            raise ValueError(f'{path}: missing keys {sorted(missing)}')
        points = np.asarray(z['points'], dtype=np.float64)
        labels = np.asarray(z['labels'], dtype=np.int64)
        width, height, n_motions = int(z['width']), int(z['height']), int(z['n_motions'])
    if points.ndim != 3 or points.shape[2] != 2 or points.shape[0] < 2:
        raise ValueError(f'{path}: points must have shape (F >= 2, P, 2), got {points.shape}')
    if labels.shape != (points.shape[1],):
        raise ValueError(f'{path}: labels shape {labels.shape} does not match '
                         f'{points.shape[1]} points')
    if not np.all(np.isfinite(points)):
        raise ValueError(f'{path}: points contain non-finite coordinates')
    if labels.min() < 0 or np.unique(labels).size != n_motions or labels.max() >= n_motions:
        raise ValueError(f'{path}: labels {np.unique(labels)} are not 0 .. {n_motions - 1}')
    return HopkinsSequence(name=path.stem, group=sequence_group(path.stem), points=points,
                           labels=labels, width=width, height=height, n_motions=n_motions)


def list_sequences(data_dir: Optional[PathLike] = None, include_extra: bool = False
                   ) -> List[pathlib.Path]:
    """
    Sorted ``.npz`` files of the benchmark (155; plus ``dancing`` if ``include_extra``).

    Raises
    ------
    ValueError
        The folder does not exist or holds no ``.npz`` file.

    """
    folder = pathlib.Path(data_dir) if data_dir is not None else DEFAULT_DATA_DIR
    if not folder.is_dir():
        raise ValueError(f'Hopkins155 folder {folder} does not exist (set MLOFC_HOPKINS_DIR)')
    paths = sorted(folder.glob('*.npz'))
    if not paths:
        raise ValueError(f'no .npz file in {folder}')
    return [p for p in paths if include_extra or sequence_group(p.stem) != 'extra']


def _occurrence_rank(ends: np.ndarray) -> np.ndarray:
    """For each entry of ``ends (M,)``, how many earlier entries hold the same value."""
    order = np.argsort(ends, kind='stable')
    srt = ends[order]
    first = np.searchsorted(srt, srt, side='left')
    rank = np.empty_like(ends)
    rank[order] = np.arange(ends.size) - first
    return rank


def _capped_selection(pairs: np.ndarray, n_points: int, max_uses: int, limit: int
                      ) -> np.ndarray:
    """
    Select the first ``limit`` pairs of ``pairs (M, 2)``, in priority order.

    No point is used more than ``max_uses`` times.

    Vectorised rounds: a pair is taken when both its points occur fewer than their remaining
    capacity times among the not-yet-taken pairs before it (in order); the first remaining pair
    always qualifies, so every round takes at least one pair and the result is maximal (no
    further pair fits) when fewer than ``limit`` pairs exist. Returns indices into ``pairs``.
    """
    uses = np.zeros(n_points, dtype=np.int64)
    remaining = np.arange(pairs.shape[0])
    taken: List[np.ndarray] = []
    n_taken = 0
    while remaining.size and n_taken < limit:
        cand = pairs[remaining]
        rank = _occurrence_rank(cand.ravel()).reshape(-1, 2)
        ok = np.all(rank < (max_uses - uses)[cand], axis=1)
        new = remaining[ok]
        taken.append(new)
        n_taken += new.size
        uses += np.bincount(pairs[new].ravel(), minlength=n_points)
        rest = remaining[~ok]
        remaining = rest[np.all(uses[pairs[rest]] < max_uses, axis=1)]
    if not taken:
        return np.zeros(0, dtype=np.int64)
    return np.sort(np.concatenate(taken))[:limit]


def pair_points(seq: HopkinsSequence, n_lines_per_motion: int = 30, start: int = 0,
                min_length_px: float = 40.0, seed: int = 0, strategy: str = 'random',
                max_uses: int = 2) -> Tuple[np.ndarray, np.ndarray]:
    """
    Choose pairs of same-motion points that span the line tracks.

    For every motion, the candidates are all pairs of its points at least ``min_length_px``
    apart in frame ``start``. They are put in a priority order, ``'random'`` (a random
    permutation, ``seed``) or ``'long'`` (longest first, random among equal lengths), and taken
    in that order while both points of a pair have been used fewer than ``max_uses`` times
    (default 2: every point in at most two lines), up to ``n_lines_per_motion`` pairs per
    motion. A motion with few points yields fewer lines (possibly none).

    Parameters
    ----------
    seq
        The sequence.
    n_lines_per_motion
        Cap on the number of lines per motion (the paper's m).
    start
        Frame in which the minimum length is checked (first frame of the window).
    min_length_px
        Shortest allowed segment, pixels.
    seed
        Seed of the random order; the result repeats for a seed.
    strategy
        ``'random'`` or ``'long'``.
    max_uses
        The most lines a point may belong to.

    Returns
    -------
    pairs : (N, 2) int64
        Point indices ``(a, b)`` of every line, grouped by motion.
    labels : (N,) int64
        Motion of every line (the common label of its two points).

    Raises
    ------
    ValueError
        Unknown strategy, ``start`` outside the sequence, or a non-positive cap.

    """
    if strategy not in STRATEGIES:
        raise ValueError(f'unknown pairing strategy {strategy!r}; choose from {STRATEGIES}')
    if not 0 <= start < seq.n_frames:
        raise ValueError(f'start frame {start} outside 0 .. {seq.n_frames - 1} of {seq.name}')
    if n_lines_per_motion < 1 or max_uses < 1:
        raise ValueError(f'n_lines_per_motion ({n_lines_per_motion}) and max_uses '
                         f'({max_uses}) must be >= 1')
    rng = np.random.default_rng(seed)
    all_pairs, all_labels = [], []
    for label in range(seq.n_motions):                 # 2..5 motions, not a per-line loop
        idx = np.flatnonzero(seq.labels == label)
        a, b = np.triu_indices(idx.size, 1)
        p0 = seq.points[start, idx]
        length = np.hypot(*(p0[a] - p0[b]).T)
        keep = np.flatnonzero(length >= min_length_px)
        key = rng.random(keep.size)
        order = np.argsort(key) if strategy == 'random' else np.lexsort((key, -length[keep]))
        cand = np.stack([a[keep][order], b[keep][order]], axis=1)
        if strategy == 'random':                       # random orientation of each segment
            flip = rng.random(cand.shape[0]) < 0.5
            cand[flip] = cand[flip, ::-1]
        sel = _capped_selection(cand, idx.size, max_uses, n_lines_per_motion)
        all_pairs.append(idx[cand[sel]])
        all_labels.append(np.full(sel.size, label, dtype=np.int64))
    pairs = np.concatenate(all_pairs).reshape(-1, 2).astype(np.int64)
    return pairs, np.concatenate(all_labels)


def line_tracks(seq: HopkinsSequence, n_lines_per_motion: int = 30,
                frames: Optional[Tuple[int, int]] = (0, 2), min_length_px: float = 40.0,
                seed: int = 0, strategy: str = 'random', max_uses: int = 2
                ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Line tracks over a window of the sequence, from pairs of same-motion points.

    The pairs come from :func:`pair_points` (minimum length checked in the window's first
    frame; every point in at most ``max_uses`` lines; at most ``n_lines_per_motion`` lines per
    motion; fixed ``seed``). The endpoints of a line in every frame are its two tracked points,
    so they correspond between frames (the solver only uses the line through them).

    Parameters
    ----------
    seq
        The sequence.
    n_lines_per_motion, min_length_px, seed, strategy, max_uses
        As in :func:`pair_points`.
    frames
        ``(start, K)``: K >= 2 consecutive frames from ``start``; None = all frames.

    Returns
    -------
    tracks : (N, K, 4) float64
        Endpoints ``(u1, v1, u2, v2)`` in pixels per line and frame (no NaN).
    labels : (N,) int64
        True motion of every line.

    Raises
    ------
    ValueError
        The window does not fit in the sequence or K < 2; see also :func:`pair_points`.

    """
    start, k = (0, seq.n_frames) if frames is None else (int(frames[0]), int(frames[1]))
    if k < 2 or start < 0 or start + k > seq.n_frames:
        raise ValueError(f'window (start={start}, K={k}) does not fit the {seq.n_frames} '
                         f'frames of {seq.name} (K >= 2 needed)')
    pairs, labels = pair_points(seq, n_lines_per_motion, start, min_length_px, seed, strategy,
                                max_uses)
    window = seq.points[start:start + k]                  # (K, P, 2)
    tracks = np.concatenate([window[:, pairs[:, 0]], window[:, pairs[:, 1]]], axis=2)
    return np.ascontiguousarray(tracks.transpose(1, 0, 2)), labels
