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
Bodies that move alike: the rotation model's bodies it cannot tell apart, published as one.

With a count given (``num_bodies``) the solver always returns that many bodies. Where fewer
move, as in a still scene or once a body stops, the extra ones split a rigid body arbitrarily
(visp_cube before its drag: two bodies turning 0.1-1.5 deg/s apart, the split changing from
frame to frame). Two bodies are alike when each one's tracks are explained by the other's
rotation about as well as by their own: the median of their rms residuals under the other
body's rotation within :data:`ALIKE_RATIO` times the tracks' jitter
(:func:`~mlofc_ros.method_choice.track_jitter`, the yardstick of ``method='auto'``), the
median over the last :data:`ALIKE_SOLVES` windows; and when noise decides between them: of
the tracks on either body in two windows running, at least :data:`ALIKE_SWAPS` changed body
(the median over the same windows). The pipeline then publishes their tracks under the older
stable id and no twist for the other; the solver and the body ids keep both (when they move
apart again, the younger id comes back). Measured (the larger of the two ratios, per window,
rotation model, 5 frames): visp_cube before its drag 0.9-2.2 in most windows, 3-6 in two
stretches (frames 12-14 and 23-27, whose groups are spread over the still table: left
split), about 6 in the drag's first window; rendered boxes turning about the camera 100-700.

The ratio alone does not tell two motions apart where the rotation model misfits them both
about alike: Hopkins155's line tracks (the camera and the objects translate, the true count
given, ``method='auto'``) had a pair within 2x the jitter in a tenth of the windows (own
ratios 0.8-1.5), and publishing those as one cost 1.6 / 3.0 points of misclassification
(2 / 3 motions). What sets an arbitrary split apart is that its tracks change body from
window to window: visp_cube before its drag 12-73% a window (the median over five windows
19-57%), two Hopkins155 bodies 0-7% in most sequences.

Only the rotation model's bodies are compared: the general model's differ in translation too,
which its costs do not separate from the rotation (two boxes spinning alike in two places are
two bodies).
"""
from collections import deque
from typing import Deque, Dict, Tuple

import numpy as np

#: Two bodies are alike while each one's tracks fit the other's rotation within this multiple
#: of the tracks' jitter (median over :data:`ALIKE_SOLVES` windows): the ratio of the rotation
#: model to the jitter where it holds, as ``method='auto'`` reads it
#: (:data:`~mlofc_ros.method_choice.MISFIT_RATIO`).
ALIKE_RATIO = 2.0
#: Windows whose median ratio decides (the last ones in which both bodies were solved), and
#: the fewest that decide.
ALIKE_SOLVES = 5
ALIKE_MIN_SOLVES = 3
#: Tracks a body needs for its ratio, and a pair for its share of swaps.
ALIKE_MIN_TRACKS = 4
#: Two bodies are alike only while at least this share of their tracks changes body from
#: one window to the next (median over :data:`ALIKE_SOLVES` windows): noise, not motion,
#: decides between them.
ALIKE_SWAPS = 0.15


def cross_ratios(costs: np.ndarray, labels: np.ndarray, residuals: np.ndarray,
                 jitter: float) -> np.ndarray:
    """
    Return how well each body's tracks fit every other body's motion, in tracks' jitters.

    Parameters
    ----------
    costs : (N, n) float
        Each track's cost under each body (``SegmentationResult.costs``, px^2 summed over its
        rows).
    labels : (N,) int
        Each track's body, ``-1`` none.
    residuals : (N,) float
        Each track's rms residual under its body (px): the cost over its degrees of freedom.
    jitter : float
        The tracks' jitter (px).

    Returns
    -------
    (n, n) float
        ``[a, b]``: the median, over the tracks of body ``b``, of their rms residual under
        body ``a`` over ``jitter``; NaN where ``b`` has fewer than :data:`ALIKE_MIN_TRACKS`
        usable tracks, and on the diagonal.

    """
    costs = np.asarray(costs, dtype=float)
    labels = np.asarray(labels)
    n = costs.shape[1]
    out = np.full((n, n), np.nan)
    if not (np.isfinite(jitter) and jitter > 0):
        return out
    own = costs[np.arange(len(labels)), np.maximum(labels, 0)]
    with np.errstate(invalid='ignore', divide='ignore'):
        dof = own / np.asarray(residuals, dtype=float) ** 2      # the cost's rows
        rms = np.sqrt(costs / dof[:, None]) / jitter             # (N, n)
    usable = (labels >= 0) & np.isfinite(dof) & (dof > 0)
    rms[np.isnan(rms)] = np.inf                  # a track a body cannot explain at all
    for b in range(n):                                           # bodies, not lines
        mine = usable & (labels == b)
        if np.count_nonzero(mine) >= ALIKE_MIN_TRACKS:
            out[:, b] = np.median(rms[mine], axis=0)
    np.fill_diagonal(out, np.nan)
    return out


class AlikeBodies:
    """
    Which stable bodies move alike now, over the last windows (not thread-safe).

    Feed it every rotation-model solve (:meth:`add`): it returns the older stable id that each
    body alike with it is published under.
    """

    def __init__(self) -> None:
        # per pair (older id, younger id): (ratio, share of swaps) of its last windows
        self._seen: Dict[Tuple[int, int], Deque[Tuple[float, float]]] = {}

    def reset(self) -> None:
        """Forget every pair (the body ids restart)."""
        self._seen.clear()

    def add(self, ids: np.ndarray, ratios: np.ndarray, labels: np.ndarray,
            before: np.ndarray) -> Dict[int, int]:
        """
        Take a solve's bodies and :func:`cross_ratios`; return the merges.

        Parameters
        ----------
        ids : (n,) int
            The solve's bodies' stable ids.
        ratios : (n, n) float
            Their :func:`cross_ratios`.
        labels : (N,) int
            Each track of the window's stable body id, ``-1`` none.
        before : (N,) int
            The stable body id each track had at the solve before, ``-1`` none
            (:meth:`~mlofc_ros.bodies.BodyTracker.previous_labels`).

        Returns
        -------
        dict
            ``{stable id: the older stable id it is published under}`` for the bodies alike
            with an older one now (a chain goes to its oldest). A pair of which a body is not
            among ``ids`` is forgotten.

        """
        ids = [int(i) for i in ids]
        now, before = np.asarray(labels), np.asarray(before)
        self._seen = {k: v for k, v in self._seen.items() if k[0] in ids and k[1] in ids}
        for a in range(len(ids)):                                # bodies, not lines
            for b in range(a + 1, len(ids)):
                pair = ratios[[a, b], [b, a]]
                pair = pair[~np.isnan(pair)]       # inf (tracks the other cannot explain) counts
                if pair.size:
                    key = (min(ids[a], ids[b]), max(ids[a], ids[b]))
                    both = np.isin(now, key) & np.isin(before, key)
                    swaps = (float(np.mean(now[both] != before[both]))
                             if np.count_nonzero(both) >= ALIKE_MIN_TRACKS else np.nan)
                    self._seen.setdefault(key, deque(maxlen=ALIKE_SOLVES)).append(
                        (float(pair.max()), swaps))
        into: Dict[int, int] = {}
        for (old, young), seen in sorted(self._seen.items()):
            ratio, swaps = np.array(seen).T
            swaps = swaps[~np.isnan(swaps)]
            if (len(seen) >= ALIKE_MIN_SOLVES and float(np.median(ratio)) <= ALIKE_RATIO
                    and swaps.size and float(np.median(swaps)) >= ALIKE_SWAPS
                    and young not in into):
                into[young] = into.get(old, old)
        return into
