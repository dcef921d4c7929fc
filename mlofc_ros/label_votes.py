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
The labels ``method='auto'`` publishes: each track's body voted over its recent solves.

A line stays on its rigid body, so a track's label is evidence for the next frames' too.
Every solve votes for the stable body id it gave each track, older votes fading by
:data:`DECAY` per solve (a body that stops or starts moves its tracks over in three or four
solves); the published label is the id with the most votes, for the tracks the latest solve
voted for (the others are ``label_memory``'s). Once ``'auto'`` solves with the general model,
the rotation model's solve of the window's last frames votes too, for the tracks it fits
within :data:`ROTATION_GATE` times their jitter, by :data:`ROTATION_WEIGHT`: it has no
unknowns per line, so where it fits a track its label is the sharper evidence (the general
model gives each line its own depth, with which a line can also fit another body's
translation). The votes restart at the switch: until then they are the rotation model's
labels of a scene it misfits. Measured offline on Hopkins155's line tracks, from the labels
of a ``'robust'`` and a ``'general'`` stream as bench hopkins_stream streams them (every frame
from the first full window, misclassified % of the 2 / 3-motion sequences): each frame's
labels 3.9 / 10.8; voted, the general model's alone after the switch 3.8 / 10.1; with the
rotation model's 3.1 / 7.6. Without the restart (the rotation model labels Hopkins155 fairly:
3.0 / 7.3), other settings: no gate 3.2 / 7.4, gates 4 and 8 3.0 / 7.6 and 3.0 / 7.3; fading
by 0.7 and 0.9 3.2 / 7.6 and 3.0 / 7.4; the rotation model's weight 0.95 and 1.5 3.2 / 8.1
and 3.1 / 7.4. Through the pipeline and on rendered scenes: docs/design/general.md.
"""
from typing import Optional

from mlofc_ros.bodies import assign, find_ids
import numpy as np

#: Each solve keeps this share of the votes before it (a memory of about five solves).
DECAY = 0.8
#: Weight of the rotation model's vote against the solve's own (1): above, so that where the
#: two disagree frame after frame the rotation model's label wins.
ROTATION_WEIGHT = 1.05
#: The rotation model votes for a track whose rms residual under its body is at most this
#: many times the window's track jitter (:func:`.method_choice.track_jitter`): on Hopkins155
#: the tracks' ratios have a median of 1.6 and a 90th percentile of 4.6; the boxes spinning
#: about their own centres that the rotation model misfits have bodies' medians of 4-80.
ROTATION_GATE = 6.0
#: Tiebreak: among equal votes the latest solve's label, the rotation model's first.
_TIE = 1e-6


def match_bodies(labels: np.ndarray, onto: np.ndarray, n: int) -> np.ndarray:
    """
    Return the id in ``onto`` that each of ``n`` bodies in ``labels`` shares most tracks with.

    ``labels (N,)``: bodies ``0..n-1`` (``-1`` none); ``onto (N,)``: ids ``>= 0`` of the same
    tracks (``-1`` none). One body per id, the most shared tracks in all
    (:func:`.bodies.assign`); ``(n,)`` int64, ``-1`` for a body that shares none with its id.
    """
    lab = np.asarray(labels, dtype=np.int64)
    to = np.asarray(onto, dtype=np.int64)
    out = np.full(n, -1, dtype=np.int64)
    both = (lab >= 0) & (lab < n) & (to >= 0)
    if not np.any(both):
        return out
    overlap = np.zeros((n, int(to[both].max()) + 1))
    np.add.at(overlap, (lab[both], to[both]), 1.0)
    cols = assign(overlap)
    shared = cols < overlap.shape[1]
    shared[shared] = overlap[np.flatnonzero(shared), cols[shared]] > 0
    out[shared] = cols[shared]
    return out


class LabelVotes:
    """The fading votes of every track for the stable body ids (see the module)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget every vote (the track or body ids restart)."""
        self._ids = np.zeros(0, dtype=np.int64)                # sorted track ids
        self._votes = np.zeros((0, 0))                         # (tracks, stable ids)
        self._now = np.zeros((0, 0))                           # the latest solve's votes

    def new_solve(self, track_ids: np.ndarray) -> None:
        """
        Start the votes of a solve of the tracks ``track_ids (N,)``: the earlier votes fade.

        Tracks not among them are forgotten (they left the window).
        """
        ids = np.asarray(track_ids, dtype=np.int64).ravel()
        order = np.argsort(ids, kind='stable')
        ids = ids[order]
        votes = np.zeros((ids.size, self._votes.shape[1]))
        pos, hit = find_ids(self._ids, ids)
        votes[hit] = DECAY * self._votes[pos[hit]]
        self._ids, self._votes = ids, votes
        self._now = np.zeros_like(votes)

    def add(self, track_ids: np.ndarray, labels: np.ndarray, weight: float = 1.0,
            where: Optional[np.ndarray] = None) -> None:
        """
        Vote ``weight`` for the stable id ``labels (N,)`` of each track ``track_ids (N,)``.

        ``-1`` labels, tracks outside the solve (:meth:`new_solve`) and tracks where
        ``where (N,)`` is False do not vote.
        """
        ids = np.asarray(track_ids, dtype=np.int64).ravel()
        lab = np.asarray(labels, dtype=np.int64).ravel()
        ok = lab >= 0
        if where is not None:
            ok &= np.asarray(where, dtype=bool).ravel()
        pos, hit = find_ids(self._ids, ids)
        ok &= hit
        if not np.any(ok):
            return
        width = int(lab[ok].max(initial=-1)) + 1
        if width > self._votes.shape[1]:
            grow = ((0, 0), (0, width - self._votes.shape[1]))
            self._votes, self._now = np.pad(self._votes, grow), np.pad(self._now, grow)
        np.add.at(self._votes, (pos[ok], lab[ok]), weight)
        np.add.at(self._now, (pos[ok], lab[ok]), weight)

    def labels(self, track_ids: np.ndarray) -> np.ndarray:
        """
        Return the voted stable id of each track ``track_ids (N,)``, int64.

        ``-1`` for a track the latest solve did not vote for (unassigned by it; the pipeline's
        ``label_memory`` decides what it shows). Equal votes go to the latest solve's label
        (the rotation model's where both voted).
        """
        ids = np.asarray(track_ids, dtype=np.int64).ravel()
        out = np.full(ids.shape, -1, dtype=np.int64)
        if not self._votes.shape[1]:
            return out
        pos, hit = find_ids(self._ids, ids)
        now = self._now[pos[hit]]
        best = np.argmax(self._votes[pos[hit]] + _TIE * now, axis=1)
        out[hit] = np.where(now.max(axis=1) > 0, best, -1)
        return out
