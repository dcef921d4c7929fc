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
The solver's methods as objects: one table of what each needs and what the callers get.

Every method of :func:`.segment_lines` is a :class:`Method`: its solve function and what the
layers above need to know to call it -- whether it is slow (a node solves it off its tracking
thread), how many frames the window must hold before it is used (and which method answers
before that), which warm start it takes from the previous window, whether it rescans its
tracked bodies, and which optional keywords of :func:`.segment_lines` it accepts. Callers pass
the user's method name through :func:`get_method` and read these fields instead of naming
methods.
"""
from dataclasses import dataclass, field, replace
import enum
from functools import partial
from math import comb
from types import MappingProxyType
from typing import Any, Callable, Dict, FrozenSet, Mapping, Optional, Tuple

from .general_method import ROTATION_STEP as _GENERAL_ROTATION_STEP, solve_general
from .problem import Problem
from .result import SegmentationResult
from .rotation import algebraic, algebraic_kmeans, kmeans, solve_robust, solve_rotation


class WarmStart(enum.Enum):
    """What a method takes from the previous window of a stream."""

    #: Nothing: every window is solved cold.
    NONE = 'none'
    #: The previous window's labels (``init_labels``).
    LABELS = 'labels'
    #: The previous labels and every body's motion (``init_labels`` and ``init_motions``:
    #: :attr:`.SegmentationResult.segmentation_angular_velocities` and
    #: :attr:`.SegmentationResult.translation_directions`).
    MOTIONS = 'motions'


#: The optional keywords of :func:`.segment_lines` that only some methods accept.
WARM_KEYWORDS = ('init_labels', 'init_motions', 'rescan', 'step', 'step_only', 'warm_inliers',
                 'warm_competes')


@dataclass(frozen=True, eq=False)
class Method:
    """
    One method of :func:`.segment_lines`.

    Attributes
    ----------
    name : str
        The name callers pass (``segment_lines(method=...)``, the ``method`` parameter).
    solve : callable
        ``solve(problem, **keywords) -> SegmentationResult`` on a checked
        :class:`~.problem.Problem` with the accepted keywords that were given.
    description : str
        One line for documentation.
    slow : bool
        A solve can take seconds (a node runs it off its tracking thread).
    warm_start : WarmStart
        What it takes from the previous window.
    rescans : bool
        It can refit tracked bodies from a full search (``rescan``); a stream asks it for every
        tracked body at every warm solve.
    keywords : frozenset of str
        The optional keywords of :data:`WARM_KEYWORDS` it accepts (the others are refused).
    min_frames : int
        Frames the window must hold (or all of a shorter window) before the method is used;
        :attr:`stand_in` answers before.
    stand_in : Method or None
        What answers a window of fewer than :attr:`min_frames` frames.
    fixed : mapping
        Keywords passed with this entry's warm start (a stand-in's tuning of its method's);
        the caller sets only the :attr:`keywords` that are not fixed.
    algebraic_fit : bool
        It needs the algebraic fit determined (enough tracks for the multibody polynomial)
        even at a known focal length; otherwise two tracks per body do.
    motion_parameters : int
        Parameters of one body's motion (3: a rotation; 6: a rotation and a translation with
        its scale), which the count's score charges per body
        (:func:`.model_selection.bic_score`).
    window : int
        Frames of a stream's sliding window when the caller leaves the length to the method
        (the ``window`` parameter 0).

    """

    name: str
    solve: Callable[..., SegmentationResult] = field(repr=False)
    description: str = ''
    slow: bool = False
    warm_start: WarmStart = WarmStart.NONE
    rescans: bool = False
    keywords: FrozenSet[str] = frozenset()
    min_frames: int = 2
    stand_in: Optional['Method'] = None
    fixed: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    algebraic_fit: bool = True
    motion_parameters: int = 3
    window: int = 5

    def for_window(self, frames: int, window: int) -> 'Method':
        """Return the method that solves a window of ``frames`` frames (of at most ``window``)."""
        if self.stand_in is not None and frames < min(self.min_frames, window):
            return self.stand_in
        return self

    def accepts(self, keyword: str) -> bool:
        """Whether a caller may set ``keyword`` for this entry (accepted and not fixed)."""
        return keyword in self.keywords and keyword not in self.fixed

    def min_tracks(self, n_bodies: int, n_frames: int, focal_known: bool) -> int:
        """
        Fewest usable tracks (present in two consecutive frames) it can solve from.

        Each track gives ``2 (K - 1)`` equations; the algebraic fit needs one fewer than the
        number of monomials (``C(n + 3, 3)`` with known f, ``C(n + 5, 5)`` without); every body
        needs two tracks.
        """
        per_body = 2 * n_bodies
        if focal_known and not self.algebraic_fit:
            return per_body
        dims = 4 if focal_known else 6
        monomials = comb(n_bodies + dims - 1, dims - 1)
        rows_per_track = 2 * max(n_frames - 1, 1)
        return max(per_body, -(-(monomials - 1) // rows_per_track))


def _rotation(name: str, segment) -> Callable[[Problem], SegmentationResult]:
    return partial(solve_rotation, method=name, segment=segment)


ALGEBRAIC = Method('algebraic', _rotation('algebraic', algebraic),
                   "The paper's Algorithm 1 alone (algebraic fit, each track to its best body).")
KMEANS = Method('kmeans', _rotation('kmeans', kmeans),
                "The paper's K-means from a random start (best of 10 restarts).")
ALGEBRAIC_KMEANS = Method('algebraic+kmeans', _rotation('algebraic+kmeans', algebraic_kmeans),
                          "Algorithm 1 then K-means (the paper's best).")
ROBUST = Method('robust', solve_robust,
                'Ours: noise-weighted K-subspaces from several starts, outliers rejected.',
                warm_start=WarmStart.LABELS, algebraic_fit=False,
                keywords=frozenset({'init_labels', 'warm_inliers', 'warm_competes'}))

#: 'robust' as the rotation-only step of 'general' (:data:`.general_method.ROTATION_STEP`):
#: the previous labels only, no lowered bar, the warm start not competing. 'general' answers
#: with it until the window holds :data:`GENERAL_MIN_FRAMES`.
ROTATION_STEP = replace(ROBUST, keywords=frozenset({'init_labels'}),
                        fixed=_GENERAL_ROTATION_STEP)

#: Method 'general' answers with :data:`ROTATION_STEP` until the window holds this many frames
#: (or all of a shorter window). Its first, cold search decides the grouping the warm starts
#: then track; on 3 frames (2 constraints per line) it was often wrong and stayed so. Spinning
#: benchmark, window 10, mean wrong % own2+bg / own3+bg / own2 / own3 over render seeds 0-5
#: (3 -> 5): 2.3 / 10.4 / 0.4 / 3.0 -> 3.8 / 5.5 / 0.4 / 2.6, held-out seeds 6-8 3.4 / 3.8 /
#: 0.0 / 0.5 -> 1.5 / 3.1 / 0.0 / 0.1; 4 frames (3.1 / 10.2 / 0.5 / -) and the whole window
#: (10: 4.3 / 22.6 / 1.1 / 0.4) were worse.
GENERAL_MIN_FRAMES = 5

#: The window of 'general' when the caller leaves it to the method: over 5 frames a body's
#: translation and its rotation about an axis in the image plane hardly differ. Spinning
#: benchmark (30 frames, render seeds 0-2), window 5 -> 10, mean wrong % own2+bg / own3+bg /
#: own2 / own3 12.4 / 4.2 / 0.1 / 14.9 -> 0.4 / 1.2 / 0.0 / 7.7, boxes within 5% of their
#: omega 50 / 56 / 83 / 44 -> 100 / 100 / 100 / 78%, and the mean frame 2-3x cheaper
#: (docs/results/spinning). The other methods keep 5 ('robust' on cam2+bg: 0.13% wrong at 5,
#: 0.26% at 10).
GENERAL_WINDOW = 10

#: A stream rescans every tracked body at every warm solve, not one body per solve in turn: a
#: body tracked in a wrong basin gets its way out at the next solve instead of after up to
#: ``num_bodies`` of them, and the solver's path no longer depends on how the body ids are
#: numbered. Spinning benchmark, window 10, 30 frames, render seeds 0-11, mean wrong % own2+bg
#: / own3+bg / own2 / own3, one in turn -> all: 4.5 / 6.0 / 0.19 / 2.1 -> 3.1 / 4.7 / 0.18 /
#: 1.1; +32% CPU per frame with 4 bodies.
GENERAL = Method('general', solve_general,
                 'Ours with a translation per body too (K >= 3, :mod:`.general`).',
                 slow=True, warm_start=WarmStart.MOTIONS, rescans=True,
                 keywords=frozenset({'init_labels', 'init_motions', 'rescan', 'step',
                                     'step_only'}),
                 min_frames=GENERAL_MIN_FRAMES, stand_in=ROTATION_STEP, motion_parameters=6,
                 window=GENERAL_WINDOW)

#: Every method by name, in the order of :data:`METHODS`.
REGISTRY: Dict[str, Method] = {m.name: m for m in (ALGEBRAIC, KMEANS, ALGEBRAIC_KMEANS, ROBUST,
                                                   GENERAL)}

#: Names of the methods accepted by :func:`.segment_lines`.
METHODS: Tuple[str, ...] = tuple(REGISTRY)


def get_method(name: str) -> Method:
    """Return the method called ``name``; ``ValueError`` for an unknown one."""
    try:
        return REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f'unknown method {name!r}; choose from {METHODS}') from None
