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
from typing import Any, Dict, Optional, Tuple

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


class WarmStarts:
    """
    What the solves of a stream hand to the next one: the solver's warm start.

    Per stable body id the last motion the labels were made with (methods whose warm start
    is :attr:`WarmStart.MOTIONS`), and the lowered ``warm_inliers`` after a search
    (:data:`WARM_FLOOR_MARGIN`) with the solves it has left. The previous labels themselves
    come from the body tracker.
    """

    def __init__(self) -> None:
        self.motions: Dict[int, Tuple[np.ndarray, np.ndarray]] = {}
        self.floor: Optional[Tuple[float, int]] = None

    def reset(self) -> None:
        """Forget everything (the body ids restart)."""
        self.motions.clear()
        self.floor = None

    def keywords(self, method: Method, labels: Optional[np.ndarray], n: int) -> Dict[str, Any]:
        """
        Return the keywords of :func:`segment_lines` for a solve by ``method`` of n bodies.

        ``labels``: the previous stable body id of every track of the window (``-1`` none),
        None when there is no warm start (``num_bodies`` automatic).
        """
        if labels is None or method.warm_start is WarmStart.NONE:
            return {}
        out: Dict[str, Any] = dict(method.fixed, init_labels=np.where(labels < n, labels, -1))
        if method.warm_start is WarmStart.MOTIONS and self.motions:
            w = np.full((n, 3), np.nan)
            t = np.full((n, 3), np.nan)
            for body, (w_b, t_b) in self.motions.items():
                if body < n:
                    w[body], t[body] = w_b, t_b
            out['init_motions'] = (w, t)
            if method.rescans:
                out['rescan'] = list(range(n))
        if method.accepts('warm_inliers') and self.floor is not None:
            floor, left = self.floor
            out['warm_inliers'] = min(floor, WARM_INLIERS)
            self.floor = (floor, left - 1) if left > 1 else None
        return out

    def solved(self, method: Method, res: SegmentationResult) -> None:
        """Note a solve by ``method``: after a search past the warm start, lower the bar."""
        if method.accepts('warm_inliers') and res.diagnostics.warm_rejected:
            share = res.diagnostics.inlier_share or 0.0
            self.floor = (max(share - WARM_FLOOR_MARGIN, 0.0), WARM_FLOOR_SOLVES)

    def remember(self, res: SegmentationResult, ids: np.ndarray, valid: np.ndarray) -> None:
        """Keep the motions of the valid bodies of ``res`` under their stable ``ids``."""
        if res.translation_directions is None:
            return
        segmented = np.asarray(res.segmentation_angular_velocities, dtype=float).reshape(-1, 3)
        for j in np.flatnonzero(valid):                  # bodies, not lines
            self.motions[int(ids[j])] = (segmented[j],
                                         np.asarray(res.translation_directions[j]))
