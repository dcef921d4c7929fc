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
"""The solver's result types: :class:`SegmentationResult` and its :class:`Diagnostics`."""
from dataclasses import dataclass, field
import math
from typing import Any, Dict, Optional, Tuple

import numpy as np


@dataclass
class Diagnostics:
    """
    How a segmentation was found: noise level, starts, scores (for benchmarks and tuning).

    Fields that a method does not produce keep their defaults (``None``, ``False``, empty).

    Attributes
    ----------
    sigma_px : float
        The endpoint noise level (px) the labels and covariances were computed at: a robust
        estimate from the fit (NaN when nothing was estimated).
    principal_point : (cx, cy) or None
        Principal point (px) the tracks were solved with (given, or the image centre when the
        intrinsics were unknown).
    aspect : float
        ``fy / fx`` of the solve (1 when the focal length was estimated).
    image_size : (w, h) or None
        Image size (px) of the solve.
    focal_first_order : float or None
        Unknown focal length: the first-order multibody estimate (px) before its refinement;
        None when it was not determined (or the focal length was given).
    candidate : str or None
        Rotation-only robust solve: the start whose refinement won (``'previous'``: the
        previous window's labels; ``'gpca-weighted'``, ``'gpca'``, ``'msac'``, ``'all'``;
        ``'previous-pass'``: the warm start's final pass competing with the search).
    candidate_costs : dict of str to float
        Truncated total cost of every start the search scored (empty when none was scored).
    potts_coupling : float or None
        Coupling of the spatial smoothing in the final pass.
    early_accept : bool
        The first start was returned alone (clearly right; the other starts skipped).
    warm_rejected : bool
        The previous labels' final pass did not keep enough inliers and a search ran.
    inlier_share : float or None
        Share of the usable tracks the returned labels keep as inliers (robust solves).
    n_bodies_scores : dict of int to float
        ``n_bodies=0``: the score of every number of bodies tried (the smallest won).
    start : str or None
        Method 'general': where the returned segmentation started (``'warm'``: the tracked
        previous motions; ``'rotation-only'``, ``'spatial'``, ``'previous'``: the starts of
        the multi-start search).
    score : float or None
        Method 'general': the segmentation's score (capped marginalised cost plus position
        terms) at its noise level.
    translation_scales : (n,) float or None
        Method 'general': the norm of every body's fitted translation (its unit direction is
        :attr:`SegmentationResult.translation_directions`).
    note : str or None
        Why a method answered in a reduced form (e.g. 'general' on two frames).

    """

    sigma_px: float = math.nan
    principal_point: Optional[Tuple[float, float]] = None
    aspect: float = 1.0
    image_size: Optional[Tuple[float, float]] = None
    focal_first_order: Optional[float] = None
    candidate: Optional[str] = None
    candidate_costs: Dict[str, float] = field(default_factory=dict)
    potts_coupling: Optional[float] = None
    early_accept: bool = False
    warm_rejected: bool = False
    inlier_share: Optional[float] = None
    n_bodies_scores: Dict[int, float] = field(default_factory=dict)
    start: Optional[str] = None
    score: Optional[float] = None
    translation_scales: Optional[np.ndarray] = None
    note: Optional[str] = None


def noted(diagnostics: Diagnostics, **fields: Any) -> Diagnostics:
    """
    Set ``fields`` on ``diagnostics`` and return it.

    For a solve's own, fresh diagnostics on the way out: in place, because
    :func:`dataclasses.replace` copies every field and costs more than the rest of a warm solve's
    bookkeeping.
    """
    for name, value in fields.items():
        setattr(diagnostics, name, value)
    return diagnostics


@dataclass
class SegmentationResult:
    """
    What :func:`mlofc_ros.solver.segment_lines` returns.

    Attributes
    ----------
    labels : (N,) int64
        Body index of every track, ``-1`` = unassigned (unusable track or outlier).
    angular_velocities : (n, 3) float64
        Rotation vector of each body per frame interval (rad per frame), camera optical frame
        (x right, y down, z forward), right-handed: the body moves relative to the camera as
        ``X' = expm([w]x) X`` (+ translation, which the rotation-only model ignores).
    angular_covariances : (n, 3, 3) float64
        Covariance of each row of ``angular_velocities`` ((rad/frame)^2) from the fit; ``inf`` on
        the diagonal when a body has too few lines to be determined.
    focal_length : float
        Focal length in pixels (given, or estimated when the intrinsics were unknown).
    residuals : (N,) float64
        RMS residual of each track under its assigned body (or under the best body for -1
        outliers), in pixels-equivalent (the Mahalanobis distance times the endpoint noise);
        ``nan`` for unusable tracks.
    costs : (N, n) float64
        Normalised cost of every track under every body (sum of squared whitened residuals).
    method : str
        The method that produced the result.
    segmentation_angular_velocities : (n, 3) float64
        The motions the labels were made with, rad per frame. The same as
        ``angular_velocities`` except with method 'general', which publishes a refit of each
        body's rotation; these go (with :attr:`translation_directions`) into the next window's
        ``init_motions``, and are what a tracker of body ids should compare.
    translation_directions : (n, 3) float64 or None
        Unit translation direction of every body (method 'general'; zero rows for bodies
        without a translation); None for the rotation-only methods.
    basin_spreads : (n, 3, 3) float64 or None
        Method 'general': the part of ``angular_covariances`` ((rad/frame)^2) that the other
        minima of a body's cost add, for the bodies rescanned in this solve (zero when the
        rescan found none); NaN for the bodies not rescanned, None for the other methods
        (:func:`.general.basin_spread`). A stream carries a body's last one to the solves
        that do not rescan it.
    noise_covariances : (n, 3, 3) float64 or None
        Method 'general': the covariance of each row of ``angular_velocities`` from the noise
        alone ((rad/frame)^2), without what ``angular_covariances`` adds for a body its motion
        misfits (its reduced chi-square) and for the other minima: the automatic count
        compares two bodies' rotations within it (:func:`mlofc_ros.counting.merge_candidate`).
        None: the same as ``angular_covariances`` (the rotation-only methods).
    diagnostics : Diagnostics
        How the result was found (noise level, starts, scores).

    """

    labels: np.ndarray
    angular_velocities: np.ndarray
    angular_covariances: np.ndarray
    focal_length: float
    residuals: np.ndarray
    costs: np.ndarray
    method: str
    segmentation_angular_velocities: Optional[np.ndarray] = None
    translation_directions: Optional[np.ndarray] = None
    basin_spreads: Optional[np.ndarray] = None
    noise_covariances: Optional[np.ndarray] = None
    diagnostics: Diagnostics = field(default_factory=Diagnostics)

    def __post_init__(self) -> None:
        if self.segmentation_angular_velocities is None:
            self.segmentation_angular_velocities = self.angular_velocities

    @property
    def n_bodies(self) -> int:
        """Return the number of bodies in the model."""
        return int(self.angular_velocities.shape[0])


class StepNotTaken(Exception):
    """
    A tracking step asked for alone (``step_only``) did not hold: no answer for this window.

    The caller runs the full solve elsewhere (the pipeline's solver lane,
    :mod:`mlofc_ros.lane`) and answers the frame from its running fit. ``motions``: the
    step's motions ``(W (n, 3), T (n, 3))`` after its LM steps and rescans (rad per frame, T
    with its scale), None when it fitted none: a rescan's basin holds whatever the labels do.
    """

    def __init__(self, message: str,
                 motions: Optional[Tuple[np.ndarray, np.ndarray]] = None) -> None:
        super().__init__(message)
        self.motions = motions

    def __reduce__(self) -> Tuple[Any, ...]:
        # the motions too across a process boundary (the lane's child)
        return type(self), (str(self), self.motions)
