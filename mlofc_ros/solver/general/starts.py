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
Starting motions of a body's fit: scans over T, pivot starts and the Necker reversal.

The cost is not convex in the motion: LM from one start often ends in a wrong basin. A body
without a previous fit is therefore scanned over many starts (:func:`fit_body_multistart`),
the best few refined in lockstep (:func:`.fit._best_fit`), and every winner is checked against
its depth-reversed motion (:func:`necker_mirror`).
"""
from typing import Optional, Sequence, Tuple

import numpy as np

from .fit import _best_fit, _scan_costs, best_fits, best_of_starts, fit_bodies, robust_scale
from .model import LineObservations
from ..lines import rotation_matrix


def _hemisphere(n: int = 32, whole: bool = False) -> np.ndarray:
    """
    Return ``(n, 3)`` directions spread over a hemisphere, or the ``whole`` sphere (Fibonacci).

    The cost depends on T only through its span, so T and -T are the same start.
    """
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n if whole else k / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


#: Translation directions scanned for a body without a previous estimate.
T_STARTS = _hemisphere()


#: Translation scales ``|T| / d`` (rad per frame) scanned with the marginalised directions.
T_SCALES = np.geomspace(3e-4, 0.3, 7)


#: Rates (rad per frame) of the pivot starts: six, 0.3 to 9 degrees per frame.
PIVOT_RATES = np.geomspace(0.005, 0.16, 6)


#: Rotation vectors (rad per frame) of the pivot starts (:func:`pivot_starts`): 64 axes over
#: the whole sphere (the sign of W matters there, T follows from it) at each of
#: :data:`PIVOT_RATES` (axis-major: start ``i`` turns at rate ``i % 6``).
PIVOT_W = (_hemisphere(64, whole=True)[:, None, :] * PIVOT_RATES[:, None]).reshape(-1, 3)


#: LM runs started from the best pivot starts of the scan (besides the ``keep`` others).
PIVOT_KEEP = 4


def pivot_picks(scan: np.ndarray, per_rate: bool = False) -> np.ndarray:
    """
    Return the indices of the pivot starts to refine, given their scan costs ``(C,)``.

    The :data:`PIVOT_KEEP` cheapest, or with ``per_rate`` the cheapest of each rate of
    :data:`PIVOT_RATES` (which holds the cheapest of all). Before any LM step a fast start
    costs more than a slow one whose translation explains the flow (the scan's T is only the
    pivot's), so the global ranking favours the slow starts, from which LM slides into a
    nearly static fit. Measured on bench spinning: on a box spinning at 138 deg/s 9 of the
    384 starts reach its motion, the first of them ranked 117th by the scan (41st after 3 LM
    iterations from all), but 1st among the starts at its rate.
    """
    scan = np.asarray(scan, dtype=float)
    if not per_rate:
        return np.argsort(scan)[:PIVOT_KEEP]
    k = PIVOT_RATES.size
    return np.argmin(scan.reshape(-1, k), axis=0) * k + np.arange(k)


def pivot_starts(ray: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return motions ``W, T (C, 3)`` of a body turning about a point on the unit ``ray`` (3,).

    An object that spins about its own centre ``C`` (a box turned on a table, a wheel) moves
    as ``X' = R (X - C) + C``, so ``T = C - R C``: its image barely moves, and the
    rotation-only fit, which sees a camera-centred rotation, is no start for W at all (its
    translation cancels most of the rotation's flow). Here ``C`` is taken on the ray through
    the body's lines at their distance (T in units of it, as the marginalised model's scale),
    for every rotation of :data:`PIVOT_W`.
    """
    return PIVOT_W, _pivot_translation(PIVOT_W, ray)


def _pivot_translation(w: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Return ``c - R c`` ``(..., 3)``: the translation of a turn ``w (..., 3)`` about ``c``."""
    return c - rotation_matrix(w) @ c


def fit_body_multistart(obs: LineObservations, idx: np.ndarray, w0: np.ndarray,
                        t0: Optional[np.ndarray] = None, iterations: int = 15,
                        keep: int = 3, sigma2: Optional[float] = None,
                        ray: Optional[np.ndarray] = None, pivots: bool = True,
                        robust: Optional[float] = None, per_rate: bool = False,
                        runs: Optional[list] = None) -> Tuple[np.ndarray, np.ndarray, float]:
    """
    Run :func:`.fit_body` from the ``keep`` best starts of a scan at ``w0``.

    Fitted directions (``sigma2`` None): from ``t0``, or the best of :data:`T_STARTS` (the cost
    is not convex in the direction of T). Marginalised directions: the direction of ``t0``
    (else :data:`T_STARTS`) at every scale of :data:`T_SCALES`, ``t0`` itself and T = 0.
    With ``ray`` (unit, camera frame: towards the body's lines), also from the
    :data:`PIVOT_KEEP` best of :func:`pivot_starts` (when ``pivots``; with ``per_rate`` the
    best of each rate instead, :func:`pivot_picks`), and the winner's :func:`necker_mirror`
    is tried too. The cheapest run wins. ``robust`` (px^2): scans, fits and comparisons on
    the robust cost at that noise level (:func:`.fit._lm_runs`). ``runs``: a list that
    receives every run's rotation and cost, ``(W (R, 3), costs (R,))``, the mirror's among
    them (the other basins, :func:`.covariance.basin_spread`).
    """
    w_starts, starts = _multistart(obs, idx, w0, t0, keep, sigma2, ray, pivots, robust,
                                   per_rate)
    mine = None if runs is None else []
    fit = _best_fit(obs, idx, w0, starts, iterations, sigma2, w_starts, robust, mine)
    if ray is not None:
        fit = _necker_check(obs, idx, fit, ray, iterations, sigma2, robust, mine)
    if runs is not None:
        runs.append(_joined(mine))
    return fit


def fit_bodies_multistart(obs: LineObservations, members: Sequence[np.ndarray],
                          W0: np.ndarray, T0: Optional[np.ndarray] = None,
                          iterations: int = 15, keep: int = 3,
                          sigma2: Optional[float] = None, pivots: bool = True,
                          robust: Optional[float] = None, per_rate: bool = False,
                          runs: Optional[list] = None
                          ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return :func:`fit_body_multistart` of several bodies: ``W, T (B, 3)`` and costs ``(B,)``.

    ``members``: each body's track indices (at least one); ``W0 (B, 3)``, ``T0 (B, 3)`` (or
    None) their starts; each body's ``ray`` is :meth:`.LineObservations.body_ray`. Every
    run of every body goes in one lockstep batch (:func:`.fit.fit_bodies`), then every
    winner's mirror (:func:`polish_bodies`' check). ``runs``: a list that receives each
    body's runs, as :func:`fit_body_multistart`'s.
    """
    W0 = np.asarray(W0, dtype=float)
    starts = [_multistart(obs, idx, W0[b], None if T0 is None else T0[b], keep, sigma2,
                          obs.body_ray(idx), pivots, robust, per_rate)
              for b, idx in enumerate(members)]                   # bodies, not lines
    parts = None if runs is None else []
    W, T, cost = best_of_starts(obs, members, W0, starts, iterations, sigma2, robust, parts)
    mirrors = None if runs is None else []
    out = _necker_checks(obs, members, W, T, cost, None, iterations, sigma2, robust, mirrors)
    if runs is not None:
        runs += [_joined([a, b]) for a, b in zip(parts, mirrors)]  # bodies, not lines
    return out


def _joined(parts: Sequence[Tuple[np.ndarray, np.ndarray]]) -> Tuple[np.ndarray, np.ndarray]:
    """Return runs ``(W (R, 3), costs (R,))`` given in parts as one."""
    return (np.concatenate([np.reshape(w, (-1, 3)) for w, _ in parts]),
            np.concatenate([np.ravel(c) for _, c in parts]))


def _multistart(obs: LineObservations, idx: np.ndarray, w0: np.ndarray,
                t0: Optional[np.ndarray], keep: int, sigma2: Optional[float],
                ray: Optional[np.ndarray], pivots: bool, robust: Optional[float],
                per_rate: bool) -> Tuple[np.ndarray, np.ndarray]:
    """Return :func:`fit_body_multistart`'s starts ``W, T (S, 3)`` of the tracks ``idx``."""
    rows, base = obs.rows[idx], obs.m_first[idx]
    scale = None if robust is None else robust_scale(obs.frames[idx], robust)
    products = obs.row_products(idx)
    if sigma2 is None and t0 is not None:
        starts = np.atleast_2d(t0)
    else:
        if sigma2 is None:
            cands = T_STARTS
        else:
            dirs = T_STARTS
            extra = [np.zeros((1, 3))]
            if t0 is not None and np.linalg.norm(t0) > 0:
                dirs = np.atleast_2d(t0) / np.linalg.norm(t0)
                extra.append(np.atleast_2d(t0))
            cands = np.concatenate(extra + [(dirs[:, None, :] * T_SCALES[:, None]
                                             ).reshape(-1, 3)])
        # a few hundred starts, vectorised
        scan = _scan_costs(rows, base, np.asarray(w0, dtype=float), cands, sigma2, scale,
                           products)
        starts = cands[np.argsort(scan)[:keep]]
    w_starts = np.broadcast_to(np.asarray(w0, dtype=float), starts.shape)
    if ray is not None and pivots:
        pw, pt = pivot_starts(np.asarray(ray, dtype=float))
        best = pivot_picks(_scan_costs(rows, base, pw, pt, sigma2, scale, products), per_rate)
        w_starts = np.concatenate([w_starts, pw[best]])
        starts = np.concatenate([starts, pt[best]])
    return w_starts, starts


def necker_mirror(w: np.ndarray, ray: np.ndarray) -> np.ndarray:
    """
    Return the rotation vector ``(3,)`` of the depth-reversed motion of ``w`` along ``ray``.

    ``ray``: the unit line of sight.

    Under (weak) perspective, an object turning by ``w`` and its mirror image in the plane
    orthogonal to the line of sight, turning by ``2 (w . r) r - w``, give nearly the same
    images (the Necker reversal); only perspective tells them apart. On small objects the
    LM lands in the wrong one of the two basins as often as not.
    """
    return 2.0 * float(w @ ray) * ray - w


def _necker_check(obs: LineObservations, idx: np.ndarray,
                  fit: Tuple[np.ndarray, np.ndarray, float], ray: np.ndarray, iterations: int,
                  sigma2: Optional[float], robust: Optional[float] = None,
                  runs: Optional[list] = None) -> Tuple[np.ndarray, np.ndarray, float]:
    """
    Return ``fit`` or the LM run from its :func:`necker_mirror`, whichever is cheaper.

    ``runs``: a list that receives the mirror's run, ``(w (1, 3), cost (1,))``.
    """
    W, T, cost = _necker_checks(obs, [idx], fit[0][None], fit[1][None], np.array([fit[2]]),
                                np.asarray(ray, dtype=float)[None], iterations, sigma2, robust,
                                runs)
    return W[0], T[0], float(cost[0])


def polish_body(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                iterations: int, sigma2: float, robust: Optional[float] = None
                ) -> Tuple[np.ndarray, np.ndarray, float]:
    """
    Refit a segmented body at the measured noise ``sigma2``: LM from ``(w, t)`` and its mirror.

    The segmentation's noise level is inflated (:data:`.search.NOISE_FACTOR`), which flattens
    the cost in W; at the measured noise the depth-reversed motion (:func:`necker_mirror`) may
    fit better, so an LM run from it goes beside the one from ``(w, t)`` (and from T = 0, as
    in every :func:`.fit._best_fit`) and the cheapest wins. ``robust``: as in
    :func:`.fit._lm_runs`. One body of :func:`polish_bodies`.
    """
    W, T, cost = polish_bodies(obs, [idx], np.asarray(w, dtype=float)[None],
                               np.asarray(t, dtype=float)[None], iterations, sigma2, robust)
    return W[0], T[0], float(cost[0])


def polish_bodies(obs: LineObservations, members: Sequence[np.ndarray], W: np.ndarray,
                  T: np.ndarray, iterations: int, sigma2: float, robust: Optional[float] = None
                  ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return :func:`polish_body` of several bodies: ``W, T (B, 3)`` and costs ``(B,)``.

    ``members``: each body's track indices (at least one); ``W, T (B, 3)`` their motions.
    Every body's runs go in one lockstep batch (:func:`.fit.best_fits`), then every mirror's.
    """
    W, T, cost = best_fits(obs, members, W, T, iterations, sigma2, robust)
    return _necker_checks(obs, members, W, T, cost, None, iterations, sigma2, robust)


def _necker_checks(obs: LineObservations, members: Sequence[np.ndarray], W: np.ndarray,
                   T: np.ndarray, cost: np.ndarray, rays: Optional[np.ndarray],
                   iterations: int, sigma2: Optional[float], robust: Optional[float] = None,
                   runs: Optional[list] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return :func:`_necker_check` of several bodies' fits ``W, T (B, 3)``, costs ``(B,)``.

    ``rays (B, 3)``: the lines of sight; None: each body's :meth:`.LineObservations.body_ray`.
    The mirrors' LM runs go in one lockstep batch. ``runs``: a list that receives each
    body's mirror run, ``(w (1, 3), cost (1,))``.
    """
    if rays is None:
        rays = np.array([obs.body_ray(idx) for idx in members])     # bodies, not lines
    Wm = 2.0 * np.sum(W * rays, axis=1, keepdims=True) * rays - W     # necker_mirror
    # the mirror turns about the pivot too (:func:`_pivot_translation`, one per body)
    Tm = rays - (rotation_matrix(Wm) @ rays[:, :, None])[:, :, 0]
    if sigma2 is None:
        Tm = Tm * (np.linalg.norm(T, axis=1) / np.maximum(np.linalg.norm(Tm, axis=1),
                                                          1e-300))[:, None]
    Wm, Tm, cost_m = fit_bodies(obs, members, Wm, Tm, iterations, sigma2, robust)
    if runs is not None:
        runs += [(Wm[b][None], cost_m[b:b + 1]) for b in range(len(members))]
    better = cost_m < cost
    return (np.where(better[:, None], Wm, W), np.where(better[:, None], Tm, T),
            np.where(better, cost_m, cost))
