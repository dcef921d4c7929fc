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
The solver's warm start along a stream: what each solve hands to the next one.

The pipeline keeps one :class:`WarmStarts`; it turns the previous labels (from the body
tracker) and the motions of the last solve into the keywords of
:func:`mlofc_ros.solver.segment_lines` for the method in use.
"""
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .methods import Method, WarmStart
from .result import SegmentationResult
from .robust import WARM_INLIERS

#: A method that takes ``warm_inliers`` returns the previous window's labels without a search
#: when they keep 75% of the tracks inliers (:data:`mlofc_ros.solver.robust.WARM_INLIERS`). A
#: real scene that the rotation model explains only in part stays below that: visp_cube's warm
#: starts kept 64-74%, every search then found fewer (40-64%), at 4-5 ms instead of 1.5 ms, in
#: 40% of the frames. After a search, a warm start is accepted when it keeps what the search
#: kept less WARM_FLOOR_MARGIN, for the next WARM_FLOOR_SOLVES solves (then a search looks
#: again).
WARM_FLOOR_MARGIN = 0.05
WARM_FLOOR_SOLVES = 10

#: A method that takes ``step`` (a tracking step from the previous motions, no search) steps
#: on every solve but these: the solves of the FULL_AFTER_SEARCH frames after a search (at
#: most as many solves; one when the solver is slower than the camera, a live node at 30 Hz:
#: bench live, 6 seeds, own2+bg / own3+bg, frames solved 22 / 15% -> 30 / 20%, unlabelled
#: segments 24 / 33% -> 19 / 27%, wrong 5.5 / 7.8% -> 4.3 / 8.3%, worst 16.9 / 15.3% -> 8.8 /
#: 13.7%, side by side) are full solves with
#: every body rescanned from the pivot starts (a search often leaves a body in a wrong basin),
#: and a step whose measured noise is above NOISE_JUMP times the last full solve's is followed
#: by a full solve (the tracked motions no longer explain the window). Every RESCAN_EVERY-th
#: step also rescans one tracked body, in turn. Spinning boxes, 100 frames, window 10, render
#: seeds 0-2, mean wrong % own2+bg / own3+bg / own3 (worst run): a full solve on every frame
#: 1.24 / 1.64 / - (2.68), CPU ~0.9-1.5 s a frame; steps with a full solve every 10 steps
#: 1.57 / 1.48 / 4.77 (11.5: a box 87% off for good); steps with one body rescanned every
#: third step and no periodic full solve 1.38 / 1.37 / 2.28 (4.95), 40-60 ms a step; after a
#: search, steps with every body rescanned instead of full solves: 1.49 / 3.05 / 10.3 (29.0).
FULL_AFTER_SEARCH = 3
RESCAN_EVERY = 3

#: Rescans back off while they find nothing: after every round of ``n`` rescans (one per body)
#: in which no body changed basin, the steps between two rescans double, up to
#: RESCAN_EVERY_MAX; a rescan that moves a body to another basin, and every solve that is not
#: a step, bring them back to RESCAN_EVERY. A rescan costs about three steps and, once the
#: bodies are right, finds only what the steps already hold. bench spinning, window 10, 150
#: frames, render seeds 0-5, own2+bg / own3+bg / own3 / wide2+bg, side by side: mean wrong %
#: 1.15 / 1.60 / 1.12 / 6.14 -> 1.11 / 1.57 / 1.14 / 6.01 (worst 2.48 / 2.97 / 4.28 / 10.2
#: -> 2.39 / 2.97 / 4.52 / 12.9), boxes within 5% of their omega the same, mean frame CPU
#: 5.3 / 5.9 / 5.9 / 6.1 -> 3.8 / 4.9 / 4.3 / 4.8 x LSD. bench live at 30 Hz (the run
#: before / this one, own2+bg / own3+bg): frames solved 21 / 16% -> 57 / 15%, wrong 4.7 /
#: 9.9% -> 3.6 / 11.3% (own3+bg's bad runs keep failing steps, which reset the back-off).
RESCAN_EVERY_MAX = 24

#: A rescanned body changed basin when its rotation moved by more than this share of its
#: rate (or RESCAN_SWITCH_FLOOR rad per frame, for a still body), not by a step's refinement.
RESCAN_SWITCH = 0.25
RESCAN_SWITCH_FLOOR = 2e-3

#: A step whose measured noise (px) is above this multiple of the last full solve's asks for
#: a full solve next: the tracked motions no longer explain the window.
NOISE_JUMP = 2.0


def result_motions(res: SegmentationResult) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the motions ``(W (n, 3), T (n, 3))`` a result's labels were made with.

    ``res``: a result of a method whose warm start is :attr:`WarmStart.MOTIONS`; T with its
    scale (``translation_scales``, 1 when not given), rad per frame.
    """
    W = np.asarray(res.segmentation_angular_velocities, dtype=float).reshape(-1, 3)
    scales = res.diagnostics.translation_scales
    scales = np.ones(len(W)) if scales is None else np.asarray(scales, dtype=float)
    return W, scales[:, None] * np.asarray(res.translation_directions, dtype=float)


class WarmStarts:
    """
    What the solves of a stream hand to the next one: the solver's warm start.

    Per stable body id the last motion the labels were made with (methods whose warm start
    is :attr:`WarmStart.MOTIONS`: rotation and translation with its scale), the schedule of
    steps and full solves of a method that takes ``step`` (:data:`FULL_AFTER_SEARCH`) and of
    the rescans in its steps (:data:`RESCAN_EVERY_MAX`), and the lowered ``warm_inliers``
    after a search (:data:`WARM_FLOOR_MARGIN`) with the solves it has left. The previous
    labels themselves come from the body tracker.
    """

    def __init__(self) -> None:
        self.motions: Dict[int, Tuple[np.ndarray, np.ndarray]] = {}
        #: per stable body id, the covariance term of the other minima its last rescan found
        #: ((rad/frame)^2, :attr:`.SegmentationResult.basin_spreads`)
        self.spreads: Dict[int, np.ndarray] = {}
        self.reset()

    def reset(self) -> None:
        """Forget everything (the body ids restart)."""
        self.motions.clear()
        self.spreads.clear()
        self.floor: Optional[Tuple[float, int]] = None
        self.full_due = 0                # full solves still due after a search
        self.noise = math.inf            # the last full solve's noise (px)
        self.full_next = False
        self.search_stamp = math.nan
        self.rescans = 0                 # rescans done (whose turn is next)
        self._rescans_reset()
        self.rescan_out: Optional[Tuple[int, np.ndarray]] = None   # in a lane: (body, its w)

    def _rescans_reset(self) -> None:
        """Rescan at the RESCAN_EVERY-th step from now, no back-off."""
        self.quiet = 0                   # of them, in a row, that changed no basin
        self.until_rescan = RESCAN_EVERY - 1
        self._rescanned: Optional[Tuple[int, np.ndarray]] = None   # (body, its w before)

    def keywords(self, method: Method, labels: Optional[np.ndarray], n: int,
                 ids: Optional[Sequence[int]] = None) -> Dict[str, Any]:
        """
        Return the keywords of :func:`segment_lines` for a solve by ``method`` of n bodies.

        ``labels``: the previous body of every track of the window (``-1`` none), None when
        there is no warm start; stable body ids, or with ``ids`` (the stable id of each of
        the n solver bodies, ``-1`` for a new one: the automatic count) solver bodies.
        """
        if labels is None or method.warm_start is WarmStart.NONE:
            return {}
        out: Dict[str, Any] = dict(method.fixed, init_labels=np.where(labels < n, labels, -1))
        if method.warm_start is WarmStart.MOTIONS and self.motions:
            w = np.full((n, 3), np.nan)
            t = np.full((n, 3), np.nan)
            for body, stable in enumerate(range(n) if ids is None else ids):
                if stable in self.motions:
                    w[body], t[body] = self.motions[stable]
            out['init_motions'] = (w, t)
            if method.accepts('step') and not self.full_solve_due():
                out['step'] = True
                self._rescanned = None
                if self.until_rescan <= 0 and self.rescan_out is None:
                    # one body in turn: its pivot search costs about three steps
                    out['rescan'] = self._next_rescan(w)
            elif method.rescans:
                out['rescan'] = list(range(n))
        if method.accepts('warm_inliers') and self.floor is not None:
            floor, left = self.floor
            out['warm_inliers'] = min(floor, WARM_INLIERS)
            self.floor = (floor, left - 1) if left > 1 else None
        return out

    def rescan_aside(self, handed: bool) -> None:
        """
        Take the rescan out of the step just asked for (:meth:`keywords`).

        ``handed``: it went to a solver lane (:meth:`rescan_returned` takes its answer, and no
        other rescan is asked for until then); else it is asked for again at the next step.
        """
        if handed:
            self.rescan_out = self._rescanned
        self._rescanned = None

    def rescan_meanwhile(self, W: np.ndarray) -> List[int]:
        """
        Return the body ``[b]`` to rescan in a step taken while a full solve is out.

        ``W (n, 3)``: the step's starting rotations. The steps before it did not hold, so the
        running fit stays as it was until the full solve is back; a rescan's new basin
        (:meth:`step_declined`) is the one thing that can change it meanwhile.
        """
        return self._next_rescan(W)

    def _next_rescan(self, W: np.ndarray) -> List[int]:
        """Return the body ``[b]`` whose turn it is to be rescanned; note it with its w."""
        body = self.rescans % W.shape[0]
        self._rescanned = (body, np.array(W[body], dtype=float))
        return [body]

    def rescan_returned(self, motions: Optional[Tuple[np.ndarray, np.ndarray]],
                        spreads: Optional[np.ndarray] = None) -> bool:
        """
        Take a lane's answer to the rescan handed to it; return whether it changed the body.

        ``motions``: the motions ``(W, T) (n, 3)`` of the step that made it, on the window it
        was asked for; None when it failed or was dropped (asked for again at the next step).
        As :meth:`_rescan_noted`. ``spreads``: its :attr:`.SegmentationResult.basin_spreads`,
        if any: the rescanned body's is kept (:meth:`carried_spreads`).
        """
        out, self.rescan_out = self.rescan_out, None
        if out is None:
            return False
        if motions is None:
            self.until_rescan = min(self.until_rescan, 0)
            return False
        if spreads is not None and out[0] < len(spreads) and np.all(np.isfinite(spreads[out[0]])):
            self.spreads[out[0]] = np.array(spreads[out[0]], dtype=float)
        return self._rescan_noted(out, *motions)

    def step_declined(self, motions: Optional[Tuple[np.ndarray, np.ndarray]] = None) -> None:
        """
        Note a step that did not hold (``StepNotTaken``): a full solve next.

        ``motions``: the step's (:attr:`.StepNotTaken.motions`); the rescan it made, if any,
        counts with them (:meth:`_rescan_noted`), else as not made.
        """
        self.full_next = True
        out, self._rescanned = self._rescanned, None
        if out is not None and motions is not None:
            self._rescan_noted(out, *motions)

    def _rescan_noted(self, out: Tuple[int, np.ndarray], W: np.ndarray, T: np.ndarray
                      ) -> bool:
        """
        Note a rescan made outside a step that held; return whether it changed the body.

        ``out``: the body and its rotation before; ``W, T (n, 3)``: the motions after. A body
        the rescan moved to another basin (:data:`RESCAN_SWITCH`) takes the rescan's motion (a
        lane's: the steps since have only refined the old one). Counted for the back-off as a
        rescan in a step.
        """
        switched = self._backed_off(out, W)
        if switched:
            self.motions[out[0]] = (np.array(W[out[0]], dtype=float),
                                    np.array(T[out[0]], dtype=float))
        return switched

    def full_solve_due(self) -> bool:
        """Whether the next solve of a method that steps is a search or a full solve."""
        return not self.motions or self.full_due > 0 or self.full_next

    def solved(self, method: Method, res: SegmentationResult, stamp: float = math.nan,
               interval: float = math.nan) -> None:
        """
        Note a solve by ``method``: the full solves due, the noise, the rescans, the bar.

        ``res``: its result; its ``diagnostics.start`` tells a step (``'step'``), a tracked
        full solve (``'warm'``) and a search apart. ``stamp``: the window's newest frame (s),
        ``interval``: the frame interval (s), to count the frames since a search.
        """
        start, noise = res.diagnostics.start, res.diagnostics.sigma_px
        if start not in ('step', 'warm'):
            self.spreads.clear()        # a search: the bodies' minima are found afresh
        if start == 'step':
            self.full_next = noise > NOISE_JUMP * self.noise
            self._rescan_done(res)
        elif method.accepts('step'):
            self._rescans_reset()
            self.noise, self.full_next = noise, False
            # after a search, full solves (every body rescanned) until FULL_AFTER_SEARCH
            self.full_due = max(self.full_due - 1, 0) if start == 'warm' else FULL_AFTER_SEARCH
            if start != 'warm':
                self.search_stamp = stamp
            elif (self.full_due > 0
                  and stamp - self.search_stamp >= (FULL_AFTER_SEARCH - 0.5) * interval):
                self.full_due = 0       # the window moved FULL_AFTER_SEARCH frames on
        if method.accepts('warm_inliers') and res.diagnostics.warm_rejected:
            share = res.diagnostics.inlier_share or 0.0
            self.floor = (max(share - WARM_FLOOR_MARGIN, 0.0), WARM_FLOOR_SOLVES)

    def _rescan_done(self, res: SegmentationResult) -> None:
        """Count down to the next rescan, or note the one this step made (backing off)."""
        if self._rescanned is None:
            self.until_rescan -= 1
            return
        out, self._rescanned = self._rescanned, None
        self._backed_off(out, np.asarray(res.segmentation_angular_velocities,
                                         dtype=float).reshape(-1, 3))

    def _backed_off(self, out: Tuple[int, np.ndarray], W: np.ndarray) -> bool:
        """
        Note a rescan for the back-off; return whether it moved its body to another basin.

        ``out``: the body and its rotation before; ``W (n, 3)``: the rotations after.
        """
        body, before = out
        n = W.shape[0]
        if body >= n:
            return False
        after = W[body]
        moved = float(np.linalg.norm(after - before))
        rate = max(float(np.linalg.norm(before)), float(np.linalg.norm(after)))
        switched = not moved <= max(RESCAN_SWITCH * rate, RESCAN_SWITCH_FLOOR)
        self.rescans += 1
        self.quiet = 0 if switched else self.quiet + 1
        doublings = min(self.quiet // n, 8)              # beyond RESCAN_EVERY_MAX anyway
        self.until_rescan = min(RESCAN_EVERY << doublings, RESCAN_EVERY_MAX) - 1
        return switched

    def remember(self, res: SegmentationResult, ids: np.ndarray, valid: np.ndarray) -> None:
        """
        Keep the motions of the valid bodies of ``res`` under their stable ``ids``.

        And the basin spreads of those it rescanned (:attr:`.SegmentationResult.basin_spreads`).
        """
        if res.translation_directions is None:
            return
        W, T = result_motions(res)
        spreads = res.basin_spreads
        for j in np.flatnonzero(valid):                  # bodies, not lines
            self.motions[int(ids[j])] = (W[j], T[j])
            if spreads is not None and np.all(np.isfinite(spreads[j])):
                self.spreads[int(ids[j])] = np.array(spreads[j], dtype=float)

    def carried_spreads(self, res: SegmentationResult, ids: np.ndarray) -> np.ndarray:
        """
        Return the basin spreads ``(n, 3, 3)`` ((rad/frame)^2) ``res`` lacks, by stable ``ids``.

        A body that this solve did not rescan (NaN in its
        :attr:`.SegmentationResult.basin_spreads`) takes the one its last rescan found: the
        other minima of a body's cost move little from one frame to the next, and the
        rescans come round only every few steps (:data:`RESCAN_EVERY`). Zero for the bodies
        this solve rescanned, those never rescanned, and every body of a method without them.
        """
        spreads = res.basin_spreads
        out = np.zeros((len(ids), 3, 3))
        if spreads is None:
            return out
        for j, stable in enumerate(ids):                 # bodies, not lines
            if not np.all(np.isfinite(spreads[j])) and int(stable) in self.spreads:
                out[j] = self.spreads[int(stable)]
        return out
