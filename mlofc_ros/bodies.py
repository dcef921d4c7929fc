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
Stable body ids over time.

The solver numbers its bodies arbitrarily in every window. :class:`BodyTracker` maps them onto
stable ids: body ``i`` of this window gets the id its tracks were given most often over their
lives (the tracker's track ids carry their labels across windows) and, second, the id whose
angular velocity is closest. A track votes with its whole history, not its last label, so that
a few windows of wrong labels (a body fitted in a wrong basin takes a neighbour's lines, and the
last labels rotate through the ids) do not hand the ids on: when the solver recovers, its
bodies get their old ids back. The assignment is exact (maximum total score over all permutations;
``n <= 8`` bodies). The first window numbers bodies by decreasing image extent (bounding box of
their tracks; track count when positions are not given), so the background, which spans the
image, is usually body 0; body ``i`` keeps its id while it is seen.
"""
import functools
import itertools
import math
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

#: Largest number of candidate assignments searched exhaustively (8! = 40320).
MAX_EXACT = 40320

#: A new body (``update(new=...)``) gets the smallest id that no body held in the last
#: REUSE_AFTER_S seconds of stamps, so that a long run of bodies coming and going keeps the
#: ids (and the node's twist topics) bounded, and no id means two bodies within a minute.
REUSE_AFTER_S = 60.0


@functools.lru_cache(maxsize=None)
def _permutations(k: int, r: int) -> np.ndarray:
    """``(k! / (k - r)!, r)``: every injective map of ``r`` rows into ``k`` columns, in order."""
    return np.array(list(itertools.permutations(range(k), r)), dtype=np.intp).reshape(-1, r)


def assign(score: np.ndarray) -> np.ndarray:
    """
    Maximum-score assignment of rows to columns (exact up to 8 bodies and ids, or more).

    Parameters
    ----------
    score : (R, C) float
        Score of giving row ``r`` column ``c``; the matrix is padded with zeros to be square.

    Returns
    -------
    (R,) intp
        Column of every row, all distinct; columns ``>= C`` are new ones (when ``R > C``).
        Ties go to the lexicographically smallest assignment (identity first).

    Problems with more than :data:`MAX_EXACT` candidate assignments fall back to a greedy one.

    """
    score = np.asarray(score, dtype=float)
    r, c = score.shape
    k = max(r, c)
    if r == 0:
        return np.zeros(0, dtype=np.intp)
    full = np.zeros((k, k))
    full[:r, :c] = np.nan_to_num(score, nan=0.0, posinf=0.0, neginf=0.0)
    if math.perm(k, r) <= MAX_EXACT:
        # only the rows' columns matter: k! / (k - r)! maps, not k! (1680, not 40320, for 4
        # bodies and 8 stable ids); lexicographic order keeps the tie rule
        perms = _permutations(k, r)
        totals = full[np.arange(r), perms].sum(axis=1)
        return perms[int(np.argmax(totals))].copy()
    out = np.full(k, -1, dtype=np.intp)  # greedy: best pair first
    work = full.copy()
    for _ in range(k):
        i, j = np.unravel_index(int(np.argmax(work)), work.shape)
        out[i] = j
        work[i, :] = -np.inf
        work[:, j] = -np.inf
    return out[:r]


def find_ids(table: np.ndarray, ids: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Positions ``(N,)`` of ``ids (N,)`` in the sorted int64 ``table``, and which are there."""
    if not table.size or not ids.size:
        return np.zeros(ids.shape, dtype=np.intp), np.zeros(ids.shape, dtype=bool)
    # (searchsorted is >= 0: np.minimum, not the much slower np.clip)
    pos = np.minimum(np.searchsorted(table, ids), table.size - 1)
    return pos, table[pos] == ids


def relabel(labels: np.ndarray, mapping: np.ndarray) -> np.ndarray:
    """Map solver labels (``-1`` unassigned) through ``mapping`` (solver body -> stable id)."""
    labels = np.asarray(labels, dtype=np.int64)
    mapping = np.asarray(mapping, dtype=np.int64)
    out = np.full(labels.shape, -1, dtype=np.int64)
    ok = (labels >= 0) & (labels < mapping.size)
    out[ok] = mapping[labels[ok]]
    return out


class BodyTracker:
    """
    Give the solver's bodies ids that stay the same from window to window.

    Parameters
    ----------
    omega_weight : float
        Weight of angular-velocity similarity (in [0, 1]) against the shared-track fraction
        (in [0, 1]); shared tracks dominate, angular velocity decides when tracks were lost.

    """

    def __init__(self, omega_weight: float = 0.5) -> None:
        self.omega_weight = float(omega_weight)
        self.reset()

    def reset(self) -> None:
        """Forget everything: the next window is numbered afresh."""
        self.forget_tracks()
        self._omegas: Dict[int, np.ndarray] = {}
        self._seen: Dict[int, float] = {}          # stable id -> last stamp a body held it
        self.n_slots = 0

    def forget_tracks(self) -> None:
        """Forget the track labels (the tracker restarted and may reuse ids); keep the omegas."""
        self._track_ids = np.zeros(0, dtype=np.int64)      # sorted
        self._track_labels = np.zeros(0, dtype=np.int64)
        self._track_ages = np.zeros(0, dtype=np.int64)     # updates since the solver assigned it
        self._track_votes = np.zeros((0, 0), dtype=np.int64)  # (tracks, ids): times given each id

    @property
    def track_labels(self) -> Dict[int, int]:
        """Carried ``{track_id: stable body id}``."""
        return dict(zip(self._track_ids.tolist(), self._track_labels.tolist()))

    def _find(self, track_ids: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Positions of ``track_ids`` in the memory and whether each is there."""
        return find_ids(self._track_ids, np.asarray(track_ids, dtype=np.int64).ravel())

    def previous_labels(self, track_ids: np.ndarray,
                        max_age: Optional[int] = None) -> np.ndarray:
        """
        Stable body id each track had in earlier windows (``-1`` when unknown), (N,) int64.

        With ``max_age``, only labels the solver confirmed at most ``max_age`` updates ago.
        """
        pos, hit = self._find(track_ids)
        if max_age is not None and hit.any():
            hit &= self._track_ages[pos] <= max_age
        out = np.full(hit.shape, -1, dtype=np.int64)
        out[hit] = self._track_labels[pos[hit]]
        return out

    def update(self, track_ids: np.ndarray, labels: np.ndarray,
               angular_velocities: np.ndarray,
               valid: Optional[np.ndarray] = None,
               positions: Optional[np.ndarray] = None,
               new: Sequence[int] = (),
               keeps: Optional[Dict[int, int]] = None,
               stamp: Optional[float] = None) -> np.ndarray:
        """
        Match this window's bodies to the stable ones and remember the result.

        Parameters
        ----------
        track_ids : (N,) int
            Track ids of the window's tracks.
        labels : (N,) int
            Solver body index of every track, ``-1`` unassigned.
        angular_velocities : (n, 3) float
            Angular velocity of every solver body (any consistent unit, e.g. rad/s).
        valid : (n,) bool, optional
            Bodies whose angular velocity is trustworthy (default: finite ones).
        positions : (N, 2) float, optional
            Image position (px) of every track, e.g. its midpoint. When given, the first window
            numbers bodies by decreasing spatial spread of their tracks (the background spans
            the image, objects do not); otherwise by decreasing track count.
        new : sequence of int
            Solver bodies known to be new (the automatic count found one more): each gets an
            id no body held in the last :data:`REUSE_AFTER_S` seconds (with ``stamp``; else
            one never used), whatever its tracks' histories (they were on another body).
        keeps : dict of int to int, optional
            ``{solver body: stable id}`` known to continue that id (two bodies merged, the
            older id kept): the pair's score gains 1, a whole history.
        stamp : float, optional
            Time of the window (s), for the reuse of ids by new bodies.

        Returns
        -------
        (n,) int64
            Stable id of every solver body (a permutation of ``0..n-1`` when the number of bodies
            does not change).

        """
        ids = np.asarray(track_ids, dtype=np.int64).ravel()
        lab = np.asarray(labels, dtype=np.int64).ravel()
        w = np.asarray(angular_velocities, dtype=float).reshape(-1, 3)
        n = w.shape[0]
        if valid is None:
            valid = np.all(np.isfinite(w), axis=1)
        valid = np.asarray(valid, dtype=bool).ravel()
        if ids.shape != lab.shape:
            raise ValueError(f'track_ids {ids.shape} and labels {lab.shape} differ in shape')
        if n == 0:
            return np.zeros(0, dtype=np.int64)
        lab = np.where(lab < n, lab, -1)
        counts = np.bincount(lab[lab >= 0], minlength=n)[:n]
        if self.n_slots == 0:
            order = np.argsort(-self._size(lab, counts, n, positions), kind='stable')
            mapping = np.empty(n, dtype=np.int64)
            mapping[order] = np.arange(n)
        else:
            score = self._score(ids, lab, w, valid, n)
            for body, stable in (keeps or {}).items():
                if 0 <= body < n and 0 <= stable < score.shape[1]:
                    score[body, stable] += 1.0
            fresh = np.zeros(n, dtype=bool)
            fresh[[b for b in new if 0 <= b < n]] = True
            mapping = np.empty(n, dtype=np.int64)
            mapping[~fresh] = assign(score[~fresh])
            mapping[fresh] = self._fresh_ids(int(fresh.sum()), mapping[~fresh], stamp)
        self._remember(ids, lab, w, valid, mapping)
        if stamp is not None:
            self._seen.update(dict.fromkeys(mapping.tolist(), float(stamp)))
        return mapping

    def _fresh_ids(self, k: int, taken: np.ndarray, stamp: Optional[float]) -> np.ndarray:
        """
        ``k`` ids for new bodies: retired ones first (unheld for REUSE_AFTER_S), then new ones.

        A retired id's past (its tracks' votes, its angular velocity) is forgotten.
        """
        busy = set(taken.tolist())
        retired = [] if stamp is None else [
            j for j in range(self.n_slots)
            if j not in busy and stamp - self._seen.get(j, -math.inf) >= REUSE_AFTER_S]
        out = retired[:k]
        for j in out:
            if self._track_votes.shape[1] > j:
                self._track_votes[:, j] = 0
            self._track_labels[self._track_labels == j] = -1
            self._omegas.pop(j, None)
        start = max(self.n_slots, int(taken.max(initial=-1)) + 1)
        return np.asarray(out + list(range(start, start + k - len(out))), dtype=np.int64)

    @staticmethod
    def _size(lab: np.ndarray, counts: np.ndarray, n: int,
              positions: Optional[np.ndarray]) -> np.ndarray:
        """(n,) size of every body: spread of its track positions (px^2), else track count."""
        if positions is None:
            return counts.astype(float)
        pos = np.asarray(positions, dtype=float).reshape(-1, 2)
        ok = (lab >= 0) & np.all(np.isfinite(pos), axis=1)
        size = np.zeros(n)
        for j in range(n):                  # n <= 8 bodies
            p = pos[ok & (lab == j)]
            if len(p) >= 2:
                size[j] = float(np.prod(p.max(axis=0) - p.min(axis=0)))
        return size + 1e-6 * counts         # ties (or no positions): more tracks first

    def _score(self, ids: np.ndarray, lab: np.ndarray, w: np.ndarray, valid: np.ndarray,
               n: int) -> np.ndarray:
        """
        (n, n_slots) score: shared-track fraction + omega_weight * omega similarity.

        The shared-track fraction of body ``i`` and id ``j``: the mean, over the tracks of
        body ``i`` that have a history, of the share of that history spent with id ``j``.
        """
        slots = self.n_slots
        pos, hit = self._find(ids)
        hit &= lab >= 0
        overlap = np.zeros((n, slots))
        if np.any(hit):
            votes = self._track_votes[pos[hit], :slots].astype(float)
            total = votes.sum(axis=1, keepdims=True)
            share = votes / np.maximum(total, 1.0)
            np.add.at(overlap, lab[hit], share)
        overlap /= np.maximum(overlap.sum(axis=1, keepdims=True), 1.0)
        sim = np.zeros((n, slots))
        if self._omegas:
            known = np.fromiter(self._omegas, dtype=np.intp)
            ws = np.stack(list(self._omegas.values()))                   # (slots known, 3)
            d = np.sqrt(np.sum((w[:, None, :] - ws[None]) ** 2, axis=2))
            scale = (np.sqrt(np.sum(w * w, axis=1))[:, None]
                     + np.sqrt(np.sum(ws * ws, axis=1))[None, :] + 1e-9)
            sim[:, known] = np.where(valid[:, None],
                                     np.minimum(np.maximum(1.0 - d / scale, 0.0), 1.0), 0.0)
        return overlap + self.omega_weight * sim

    def _remember(self, ids: np.ndarray, lab: np.ndarray, w: np.ndarray, valid: np.ndarray,
                  mapping: np.ndarray) -> None:
        stable = relabel(lab, mapping)
        self.n_slots = max(self.n_slots, int(mapping.max()) + 1)
        pos, hit = self._find(ids)
        prev = np.where(hit, self._track_labels[pos] if self._track_labels.size else -1, -1)
        age = np.where(hit, self._track_ages[pos] if self._track_ages.size else 0, 0)
        votes = np.zeros((ids.size, self.n_slots), dtype=np.int64)
        old = self._track_votes
        votes[hit, :old.shape[1]] = old[pos[hit]]
        now = stable >= 0
        votes[np.flatnonzero(now), stable[now]] += 1
        carried = np.where(now, stable, prev)           # unassigned now: keep the old label
        ages = np.where(now, 0, age + 1)
        keep = carried >= 0
        order = np.argsort(ids[keep], kind='stable')
        self._track_ids = ids[keep][order]
        self._track_labels = carried[keep][order]
        self._track_ages = ages[keep][order]
        self._track_votes = votes[keep][order]
        for j in np.flatnonzero(valid):
            self._omegas[int(mapping[j])] = w[j].copy()

    def state(self) -> Tuple[int, Dict[int, np.ndarray]]:
        """Return ``(number of stable ids so far, {stable id: last angular velocity})``."""
        return self.n_slots, {k: v.copy() for k, v in self._omegas.items()}
