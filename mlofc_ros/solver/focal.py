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
Unknown focal length: the paper's section 3.3 without the slope singularity, then a refinement.

With the principal point known (image centre) and pixels centred and divided by a fixed scale
``s`` (~ image width, so the columns are comparable), a pixel line ``m_p = (a, b, c)`` is
``m = (a, b, c / f)`` in normalised coordinates (``f`` in units of ``s``) and, for any ``e``
orthogonal to ``m_p``, the row
``[-b e_x + a e_y, -c e_y, c e_x, b e_z, -a e_z, -(e . g_p)]`` is orthogonal to
``u = (w3, w1/f, w2/f, w1 f, w2 f, 1)`` (first order). The multibody coefficients of
``y4 y6^(n-1)`` and ``y2 y6^(n-1)`` are ``sum w1 f`` and ``sum w1 / f`` (likewise y5, y3), which
gives ``f^2`` (the paper's eq. 18, made precise); the two ratios are pooled by least squares.
The first-order estimate is then refined exactly: the profile of the Mahalanobis cost of the
exact known-f model over ``f`` with the labels fixed.

Online (a stream without calibration): every window gives evidence on ``ln f``, the minimum of
its profile and the profile's curvature there (:func:`focal_evidence`; a body that translates,
which biases the rotation model's profile, by the general model's, :func:`general_profiles`),
and
:class:`FocalEstimate` combines the windows' evidence with a broad prior (inverse-variance
weights, inflated when the windows disagree beyond their own spread).
"""
from collections import deque
from dataclasses import dataclass
from functools import lru_cache
import math
from math import comb
from typing import Callable, Deque, Dict, Optional, Sequence, Tuple

import numpy as np

from .general.fit import fit_bodies as fit_general_bodies
from .general.model import LineObservations
from .gpca import balance_scale, multibody_vector
from .lines import line_flows
from .models import fit_bodies, track_costs
from .veronese import embed, exponents, monomial_index


def unknown_f_rows_from_normals(m: np.ndarray, e: np.ndarray, g: np.ndarray) -> np.ndarray:
    """
    Build the f-unknown rows ``(..., 6)`` (see the module docstring).

    From pixel-line normals ``m``, directions ``e`` (orthogonal to ``m``) and flows ``g``.
    """
    a, b, c = m[..., 0], m[..., 1], m[..., 2]
    ex, ey, ez = e[..., 0], e[..., 1], e[..., 2]
    return np.stack([-b * ex + a * ey, -c * ey, c * ex, b * ez, -a * ez,
                     -np.sum(e * g, axis=-1)], axis=-1)


@lru_cache(maxsize=None)
def relation_space(degree: int) -> np.ndarray:
    """
    Orthonormal basis ``(M, q)`` of degree-n polynomials vanishing on every f-unknown row.

    The first five coordinates of the f-unknown row (:func:`unknown_f_rows_from_normals`)
    depend on three parameters up to scale, so they lie on a hypersurface: for n >= 4 a
    polynomial in ``y1..y5`` alone vanishes on all rows whatever the motion (checked: rank 125
    of 126 at n = 4). Found numerically on random rows; ``q = 0`` for n <= 3. Columns index the
    6-variable embedding of :func:`.veronese.exponents`.
    """
    rng = np.random.default_rng(12345)
    n_rows = 4 * comb(degree + 4, 4)
    m = rng.normal(size=(n_rows, 3))
    e = np.cross(m, rng.normal(size=(n_rows, 3)))
    rows = unknown_f_rows_from_normals(m, e, np.zeros((n_rows, 3)))[:, :5]
    v = embed(rows / np.linalg.norm(rows, axis=1, keepdims=True), degree)
    _, s, vt = np.linalg.svd(v)
    null5 = vt[int(np.sum(s > s[0] * 1e-9)):].T                 # (M5, q)
    exps6 = exponents(6, degree)
    out = np.zeros((exps6.shape[0], null5.shape[1]))
    for k, e5 in enumerate(exponents(5, degree)):               # index map, built once per n
        out[monomial_index(exps6, tuple(e5) + (0,)), :] = null5[k]
    return out


def first_order_focal(tracks: np.ndarray, n: int, image_size: Tuple[float, float]
                      ) -> Optional[float]:
    """Focal length (px) from the f-unknown multibody vector, or None if it is not determined."""
    w, h = image_size
    scale = float(max(w, h))
    flows = line_flows(tracks, (scale, scale, w / 2.0, h / 2.0))
    if flows.n_pairs == 0:
        return None
    mbar = 0.5 * (flows.m0 + flows.m1)
    g = flows.m1 - flows.m0
    rows = unknown_f_rows_from_normals(mbar[:, None, :], np.swapaxes(flows.E, 1, 2),
                                       g[:, None, :]).reshape(-1, 6)
    t = balance_scale(rows)
    rows[:, 5] /= t          # the coefficient ratios below do not depend on t
    exps = exponents(6, n)
    relations = relation_space(n) if n >= 4 else None
    coeffs = multibody_vector(rows, n, relations)

    def coef(k: int) -> float:
        e = [0] * 6
        e[k] += 1
        e[5] += n - 1
        return float(coeffs[monomial_index(exps, e)])

    u2, u3, u4, u5 = coef(1), coef(2), coef(3), coef(4)
    den = u2 * u2 + u3 * u3
    f2 = (u4 * u2 + u5 * u3) / den if den > 0 else np.nan
    if not np.isfinite(f2) or f2 <= 0:
        return None
    return float(np.sqrt(f2) * scale)


def profile_cost(tracks: np.ndarray, labels: np.ndarray, n: int, centre: Tuple[float, float]
                 ) -> Callable[[float], float]:
    """
    ``cost(f)``: total Mahalanobis cost of the exact model at focal length ``f``, bodies refit.

    Tracks labelled ``-1`` do not count.
    """
    cx, cy = centre
    lab = np.asarray(labels)

    def cost(f: float) -> float:
        flows = line_flows(tracks, (f, f, cx, cy))
        c, _ = fit_bodies(flows, lab, n)
        costs = track_costs(flows, c, weighted=True)
        ok = (lab >= 0) & np.isfinite(costs).all(axis=1)
        return float(np.sum(costs[np.flatnonzero(ok), lab[ok]]))
    return cost


def refine_focal(cost: Callable[[float], float], f0: float, span: float = 3.0,
                 grid: int = 17, tol: float = 1e-9) -> float:
    """Minimise ``cost(f)`` over ``f0 / span .. f0 * span``: log grid then golden section."""
    logs = np.linspace(np.log(f0 / span), np.log(f0 * span), grid)
    vals = np.array([cost(float(np.exp(x))) for x in logs])
    k = int(np.argmin(vals))
    lo, hi = logs[max(k - 1, 0)], logs[min(k + 1, grid - 1)]
    phi = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - phi * (hi - lo), lo + phi * (hi - lo)
    fa, fb = cost(float(np.exp(a))), cost(float(np.exp(b)))
    while hi - lo > tol:
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - phi * (hi - lo)
            fa = cost(float(np.exp(a)))
        else:
            lo, a, fa = a, b, fb
            b = lo + phi * (hi - lo)
            fb = cost(float(np.exp(b)))
    return float(np.exp(0.5 * (lo + hi)))


#: Standard deviation of ``ln f`` below which the focal length counts as observable (10%).
FOCAL_OBSERVABLE = 0.1
#: Windows with evidence an estimate needs to count as observable (below, its spread is the
#: prior's): their disagreement (the Birge ratio) means little with fewer.
FOCAL_MIN_WINDOWS = 3
#: A window counts towards :data:`FOCAL_MIN_WINDOWS` when its own spread is within this.
FOCAL_WINDOW_INFORMATIVE = 0.3
#: Standard deviation of ``ln f`` of the prior (a factor 2): the start value is one window's
#: estimate, so f stays within a plausible range however little the scene tells.
FOCAL_PRIOR_LOG_SIGMA = math.log(2.0)
#: Windows of evidence an estimate keeps: it follows a change of zoom within this many.
FOCAL_MEMORY = 30
#: A window's profile is searched over ``f0 / span .. f0 * span`` around the running estimate.
FOCAL_EVIDENCE_SPAN = 2.0
#: A body whose rotation-model noise exceeds the solve's model noise by this factor (in
#: variance; 2x in rms) moves in a way the rotation model does not explain (it translates
#: relative to the camera): it would bias the profile's minimum, it gives no evidence.
FOCAL_MISFIT = 4.0
#: Points of the coarse log grid over ``f0 / span .. f0 * span``.
_GRID = 13
#: LM steps of each general-model fit of a focal-length profile (:func:`general_profiles`).
#: Fewer leave the motions near those fitted at the f the window was solved at, so the
#: profile leans towards that f and is too sharp: bench focal's spinning boxes, render seeds
#: 0-5, last f 8 steps +2 / +5 / -26 / -13 / -21 / -12 % (the last four 2.5-7 spreads
#: off), 30 steps with the grid's extension -1 / -2 / -0 / -0 / -9 / -7 %.
GENERAL_PROFILE_ITERATIONS = 30
#: Points of the general model's log grid (each a lockstep LM run per body).
_GENERAL_GRID = 9
#: Usable tracks a body needs to give general-model evidence.
GENERAL_PROFILE_LINES = 8
#: A general-model profile must rise by this many times its noise (px^2) from its minimum to
#: either end of the grid to give evidence.
GENERAL_PROFILE_RISE = 9.0
#: Factor on the variance of a general-model estimate: on bench focal's spinning boxes the
#: windows' estimates scattered 3-5x the spread of their profiles (median |z| 3.0 over 25
#: windows of six render seeds at :data:`GENERAL_PROFILE_ITERATIONS`, 4.1 with 8 steps; the
#: labels and motions the profile starts from are the window's solve at its f).
GENERAL_PROFILE_INFLATION = 25.0
#: Bodies of a window that must give general-model estimates for any to count (pooled, their
#: disagreement widens the spread): one body's profile alone can lean far off (visp_cube's
#: sheet, uncalibrated, its principal point taken at the image centre: 239 px +-20% and
#: 1,518 px +-10% for 548 from two start frames).
GENERAL_PROFILE_BODIES = 2
#: Step in ``ln f`` of the three-point refinement about each body's grid minimum (5%, well
#: within a profile's quadratic range).
_CURVATURE_STEP = 0.05


@dataclass(frozen=True)
class FocalEvidence:
    """
    What one window says about the focal length.

    ``focal`` px: the minimum of its cost profile; ``log_sigma``: the standard deviation of
    ``ln focal`` from the profile's curvature (``inf``: no evidence, a flat profile or a
    minimum at the searched range's edge).
    """

    focal: float
    log_sigma: float


def body_profiles(tracks: np.ndarray, labels: np.ndarray, n: int,
                  centre: Tuple[float, float], focal: np.ndarray
                  ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return every body's cost ``(F, n)`` at each focal length ``focal (F,)`` px, rotation refit.

    And the degrees of freedom ``(n,)`` of each body's cost: its rows less a rotation per
    frame pair. The cost is the Mahalanobis cost (px^2 for 1 px of endpoint noise) of the
    exact rotation model (:func:`.models.track_costs`), summed over the body's tracks;
    tracks labelled ``-1`` do not count.
    """
    lab = np.asarray(labels)
    out = np.zeros((len(focal), n))
    cx, cy = centre
    rows = np.zeros(n)
    labelled = np.flatnonzero(lab >= 0)
    for i, f in enumerate(np.asarray(focal, dtype=float)):
        flows = line_flows(tracks, (f, f, cx, cy))
        c, _ = fit_bodies(flows, lab, n)
        costs = track_costs(flows, c, weighted=True)
        idx = labelled[np.isfinite(costs[labelled, lab[labelled]])]
        out[i] = np.bincount(lab[idx], weights=costs[idx, lab[idx]], minlength=n)
        if i == 0:
            rows = np.bincount(lab[idx], weights=2.0 * flows.pairs_per_track()[idx],
                               minlength=n)
    return out, rows - 3.0 * (tracks.shape[1] - 1)


def focal_evidence(tracks: np.ndarray, labels: np.ndarray, n: int,
                   centre: Tuple[float, float], f0: float,
                   span: float = FOCAL_EVIDENCE_SPAN,
                   noise_var: Optional[float] = None,
                   motions: Optional[Tuple[np.ndarray, np.ndarray]] = None) -> FocalEvidence:
    """
    Return the focal-length evidence of a window, its labels held.

    Parameters
    ----------
    tracks : (N, K, 4) float
        Endpoints px over the window, NaN where unseen.
    labels : (N,) int
        Body of every track in ``0..n-1`` (``-1`` does not count).
    n : int
        Bodies.
    centre : (cx, cy)
        Principal point px.
    f0 : float
        Where to search (px): ``f0 / span .. f0 * span``.
    span : float
        The searched range's factor, > 1.
    noise_var : float, optional
        The endpoint noise variance px^2 of the model that made ``labels`` (the solve's
        ``sigma_px`` squared); None: no body is left out for its misfit.
    motions : (W (n, 3), T (n, 3)), optional
        The bodies' motions under the general model at ``f0`` (rad per frame): a body the
        rotation model misfits then gives the general model's evidence instead
        (:func:`general_profiles`).

    Notes
    -----
    Each body's profile ``C_b(f)`` (:func:`body_profiles`) is scanned on a log grid and
    refined by a parabola through three points 5% apart about its minimum; ``C_b / s_b^2``
    is a chi-square, with the body's noise ``s_b^2`` estimated from ``C_b`` at the minimum,
    so the variance of its ``ln f`` is ``2 s_b^2 / C_b''`` (``C''`` over ``ln f``). A body
    without rotation about the camera (a still background) has a flat profile, a body whose
    minimum is at the grid's edge bounds f on one side only: no evidence from either. A
    body that translates relative to the camera biases its minimum (the rotation model does
    not explain its flow): one whose noise exceeds ``noise_var`` by more than
    :data:`FOCAL_MISFIT` is left out, or with ``motions`` gives the general model's evidence
    instead (:func:`_general_estimates`), counted where at least
    :data:`GENERAL_PROFILE_BODIES` bodies give it. The bodies' estimates are combined with
    inverse-variance weights, the variance multiplied by their Birge ratio when they disagree
    beyond their spread. Bodies that translate alike under a model that cannot tell
    (``robust``: its own noise is the rotation model's) go unseen: a bias left over shows only
    as disagreement between windows, which widens the combined spread (:class:`FocalEstimate`).

    """
    lab = np.asarray(labels)
    grid = math.log(f0) + np.linspace(-math.log(span), math.log(span), _GRID)
    costs, dof = body_profiles(tracks, lab, n, centre, np.exp(grid))
    k = np.argmin(costs, axis=0)
    h = _CURVATURE_STEP
    xs, variances = [], []
    # a body the rotation model misfits (it translates relative to the camera) at its best f,
    # the middle of its three points below
    limit = FOCAL_MISFIT * noise_var if noise_var is not None and noise_var > 0 else np.inf
    misfit = (dof > 0) & (costs[k, np.arange(n)] / np.where(dof > 0, dof, 1.0) > limit)
    near: Dict[int, np.ndarray] = {}      # grid minimum -> every body's costs 5% either side
    for b in np.flatnonzero((k > 0) & (k < _GRID - 1) & (dof > 0) & ~misfit):
        x = grid[k[b]]
        if k[b] not in near:
            near[k[b]] = body_profiles(tracks, lab, n, centre,
                                       np.exp(x + np.array([-h, 0.0, h])))[0]
        c_lo, c_mid, c_hi = near[k[b]][:, b]
        curvature = (c_lo - 2.0 * c_mid + c_hi) / h ** 2
        noise = c_mid / dof[b]
        if not (curvature > 0 and c_mid > 0):
            continue
        xs.append(x + float(np.clip((c_lo - c_hi) / (2.0 * h * curvature), -2 * h, 2 * h)))
        variances.append(2.0 * noise / curvature)
    if motions is not None and np.any(misfit):
        more = _general_estimates(tracks, lab, np.flatnonzero(misfit).tolist(),
                                  (f0, f0) + tuple(centre), motions, span)
        if len(more[0]) >= GENERAL_PROFILE_BODIES:
            xs, variances = xs + more[0], variances + more[1]
    if not xs:
        return FocalEvidence(f0, math.inf)
    mean, var = pooled(np.array(xs), 1.0 / np.array(variances))
    return FocalEvidence(math.exp(mean), math.sqrt(var))


def general_profiles(tracks: np.ndarray, members: Sequence[np.ndarray],
                     intrinsics: Tuple[float, float, float, float], W: np.ndarray,
                     T: np.ndarray, scales: np.ndarray,
                     iterations: int = GENERAL_PROFILE_ITERATIONS) -> np.ndarray:
    """
    Return every body's cost ``(F, B)`` under the general model at focal lengths ``f s``.

    ``tracks (N, K, 4)`` px; ``members``: each body's track indices (at least 3 each);
    ``intrinsics``: ``(fx, fy, cx, cy)`` px, ``f`` their ``fx`` (``fy`` scaled alike);
    ``W, T (B, 3)``: the bodies' motions at ``f`` (rad per frame; T's direction counts);
    ``scales (F,)``: the factors of ``f``. Each cost is the fitted-direction cost
    (:func:`.general.line_residuals`, px^2 for 1 px of endpoint noise, summed over the
    body's tracks) of ``iterations`` LM steps from ``(W, T)``.

    Every focal length and body is one run of one lockstep batch: a line's normals at focal
    length ``f s`` are its normals at ``f`` with the image scaled by ``1 / s`` about the
    principal point, whose endpoint noise is then ``1 / s`` px, so the cost at ``f s`` is
    ``s^2`` times that of the scaled tracks at ``f``.
    """
    fx, fy, cx, cy = intrinsics
    centre = np.array([cx, cy, cx, cy])
    scales = np.asarray(scales, dtype=float)
    stacked = np.concatenate([centre + (tracks - centre) / s for s in scales])
    obs = LineObservations(stacked, (fx, fy, cx, cy))
    n = tracks.shape[0]
    runs = [np.asarray(m) + i * n for i in range(len(scales)) for m in members]
    B = len(members)
    _, _, cost = fit_general_bodies(obs, runs, np.tile(W, (len(scales), 1)),
                                    np.tile(T, (len(scales), 1)), iterations)
    return cost.reshape(len(scales), B) * scales[:, None] ** 2


def _general_estimates(tracks: np.ndarray, labels: np.ndarray, bodies: Sequence[int],
                       intrinsics: Tuple[float, float, float, float],
                       motions: Tuple[np.ndarray, np.ndarray], span: float
                       ) -> Tuple[list, list]:
    """
    Return the estimates of ``ln f`` and their variances from the general model's profiles.

    Of the bodies ``bodies`` (their motions ``motions = (W, T)`` at ``intrinsics``, whose
    ``fx`` is ``f``), each with at least :data:`GENERAL_PROFILE_LINES` usable tracks: its
    profile (:func:`general_profiles`) on the log grid over ``f / span .. f * span``, the grid
    continued once by half its points past an end where a body's minimum lies, a
    parabola through its minimum and the two grid points about it; a body whose profile
    rises less than :data:`GENERAL_PROFILE_RISE` times its noise at either end of the grid
    gives none (a profile that shallow is the LM's noise as much as the data's).
    """
    W, T = motions
    lab = np.asarray(labels)
    ok = np.isfinite(tracks[..., 0])
    dof_track = np.maximum(2.0 * ok.sum(axis=1) - 4.0, 0.0)
    members = {b: np.flatnonzero((lab == b) & (dof_track > 0)) for b in bodies}
    used = [b for b in bodies if members[b].size >= GENERAL_PROFILE_LINES
            and np.all(np.isfinite(W[b])) and np.all(np.isfinite(T[b]))]
    if len(used) < GENERAL_PROFILE_BODIES:          # too few to count: not worth the fits
        return [], []
    grid = np.linspace(-math.log(span), math.log(span), _GENERAL_GRID)
    h = grid[1] - grid[0]
    runs = [members[b] for b in used]
    costs = general_profiles(tracks, runs, intrinsics, W[used], T[used], np.exp(grid))
    # a minimum at the grid's edge: the grid goes on past it once (the windows' profiles
    # lean towards the f they were solved at, so a start far off stayed there)
    edge = np.argmin(costs, axis=0)
    steps = h * np.arange(1, _GENERAL_GRID // 2 + 1)
    past = np.concatenate([grid[-1] + steps if np.any(edge == _GENERAL_GRID - 1) else [],
                           grid[0] - steps if np.any(edge == 0) else []])
    if past.size:                                   # both ends in one lockstep batch
        grid = np.concatenate([grid, past])
        costs = np.concatenate([costs, general_profiles(tracks, runs, intrinsics, W[used],
                                                        T[used], np.exp(past))])
        order = np.argsort(grid)
        grid, costs = grid[order], costs[order]
    xs, variances = [], []
    for i, b in enumerate(used):                                 # bodies, not lines
        c = costs[:, i]
        k = int(np.argmin(c))
        dof = dof_track[members[b]].sum() - 5.0
        if not (0 < k < grid.size - 1 and dof > 0 and c[k] > 0):
            continue
        noise = c[k] / dof
        curvature = (c[k - 1] - 2.0 * c[k] + c[k + 1]) / h ** 2
        if not (curvature > 0 and min(c[0], c[-1]) - c[k] >= GENERAL_PROFILE_RISE * noise):
            continue
        xs.append(math.log(intrinsics[0]) + grid[k]
                  + float(np.clip((c[k - 1] - c[k + 1]) / (2.0 * h * curvature), -h, h)))
        variances.append(GENERAL_PROFILE_INFLATION * 2.0 * noise / curvature)
    return xs, variances


def pooled(x: np.ndarray, w: np.ndarray, prior: Tuple[float, float] = (0.0, 0.0)
           ) -> Tuple[float, float]:
    """
    Return the inverse-variance mean of ``x (k,)`` with weights ``w (k,)``, and its variance.

    ``prior``: ``(mean, weight)`` of a prior taking part in the mean. The variance is
    multiplied by the Birge ratio of ``x`` (its chi-square about the mean over ``k - 1``)
    when it exceeds 1: values that disagree beyond their spread widen it.
    """
    x0, w0 = prior
    weight = w0 + float(w.sum())
    mean = (w0 * x0 + float(w @ x)) / weight
    var = 1.0 / weight
    if len(x) >= 2:
        var *= max(1.0, float(w @ (x - mean) ** 2) / (len(x) - 1))
    return mean, var


class FocalEstimate:
    """
    The focal length of an uncalibrated stream, refined as windows come (not thread-safe).

    A prior ``N(ln f_start, prior_log_sigma^2)`` and the evidence of the last ``memory``
    windows (:func:`focal_evidence`, windows that do not overlap: overlapping ones would
    count the same frames twice), combined in ``ln f`` with inverse-variance weights. When the
    windows disagree beyond their own spread (the Birge ratio ``r^2`` of their chi-square over
    ``k - 1`` degrees of freedom exceeds 1: bodies that translate, wrong labels) the combined
    variance is multiplied by ``r^2``; it never exceeds the prior's, and stays the prior's
    until :data:`FOCAL_MIN_WINDOWS` windows each gave evidence within
    :data:`FOCAL_WINDOW_INFORMATIVE`.
    """

    def __init__(self, f_start: float, prior_log_sigma: float = FOCAL_PRIOR_LOG_SIGMA,
                 memory: int = FOCAL_MEMORY) -> None:
        if not (math.isfinite(f_start) and f_start > 0):
            raise ValueError(f'f_start must be a finite focal length > 0 px, got {f_start}')
        self._prior = (math.log(f_start), prior_log_sigma)
        self._evidence: Deque[FocalEvidence] = deque(maxlen=memory)
        self.focal, self.log_sigma = f_start, prior_log_sigma

    @property
    def observable(self) -> bool:
        """Return whether the focal length is known within :data:`FOCAL_OBSERVABLE`."""
        return self.log_sigma <= FOCAL_OBSERVABLE

    @property
    def n_windows(self) -> int:
        """Windows with evidence (finite spread) among those kept."""
        return sum(math.isfinite(e.log_sigma) for e in self._evidence)

    def add(self, evidence: FocalEvidence) -> None:
        """Take one window's evidence and update :attr:`focal` (px) and :attr:`log_sigma`."""
        self._evidence.append(evidence)
        x0, s0 = self._prior
        ev = [e for e in self._evidence if math.isfinite(e.log_sigma) and e.log_sigma > 0]
        mean, var = pooled(np.array([math.log(e.focal) for e in ev]),
                           np.array([e.log_sigma ** -2 for e in ev]), (x0, s0 ** -2))
        self.focal = math.exp(mean)
        self.log_sigma = min(math.sqrt(var), s0)
        # too few windows that each know f to check each other: the prior's spread (a few
        # sharp windows can lean far off together: visp_cube's sheet alone, uncalibrated,
        # 238 px +-1% for 548; from frame 20 1,476 px with a spread of 20% at a floor of
        # 2 FOCAL_OBSERVABLE)
        if sum(e.log_sigma <= FOCAL_WINDOW_INFORMATIVE for e in ev) < FOCAL_MIN_WINDOWS:
            self.log_sigma = max(self.log_sigma, s0)
