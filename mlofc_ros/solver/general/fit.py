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
Levenberg-Marquardt fit of a body's motion ``(w, T)`` to its line tracks.

Variable projection: each line's own unknowns (its moment, and its direction unless
marginalised) are eliminated for every motion tried (:mod:`.model`), so LM moves only the
body's five or six motion parameters. Several runs advance in lockstep (:func:`_lm_runs`),
on the same tracks (a body's starts) or each on its own (several bodies,
:func:`fit_bodies`); the line cost may be robust (Cauchy, :func:`_robust_costs`).
"""
from dataclasses import dataclass
from typing import NamedTuple, Optional, Sequence, Tuple

import numpy as np

from .jacobian import normal_equations
from .model import _costs2, _grams, _marginal_costs, Grams, LineObservations
from ..lines import orthonormal_pair
from ..models import chi2_quantile


def _tangent(t: np.ndarray) -> np.ndarray:
    """Return two unit vectors ``(2, 3)`` orthogonal to the unit vector ``t``."""
    return np.swapaxes(orthonormal_pair(t[None])[0], 0, 1)


#: Scale of the robust per-line cost (:func:`_robust_costs`), in units of a line's median cost
#: at the noise level: ``sigma2`` times the chi-square median of its ``2 K - 4`` degrees of
#: freedom. Measured on bench spinning: a few of a box's true tracks cost 20-50x the median
#: under the true motion and make a wrong basin cheaper; with each line's cost bounded near 4x
#: the median the true basin is cheaper.
ROBUST_SCALE = 4.0


def robust_scale(frames: np.ndarray, sigma2: float) -> np.ndarray:
    """
    Return the per-line scale ``(L,)`` of the robust cost for tracks seen in ``frames (L,)``.

    :data:`ROBUST_SCALE` times the median cost of a line at the noise variance ``sigma2``
    (px^2): ``sigma2`` times the chi-square median with ``2 K - 4`` degrees of freedom.
    """
    dof = np.maximum(2.0 * np.asarray(frames, dtype=float) - 4.0, 1.0)
    return ROBUST_SCALE * sigma2 * chi2_quantile(0.5, dof)


def _robust_costs(res: np.ndarray, logdet: Optional[np.ndarray], scale: np.ndarray
                  ) -> np.ndarray:
    """
    Return Cauchy line costs ``s log(1 + q / s)`` (plus the log-determinant), shaped as ``res``.

    ``res (..., L)``: line costs; ``logdet``: their log-determinant parts (marginalised
    directions; None for fitted ones), which stay as they are: only the residual part ``q``
    is robust. ``scale (L,)``: :func:`robust_scale`. A line at the median costs about 0.9 of
    its plain cost, one at 50x the median about 10 medians instead of 50.
    """
    q = res if logdet is None else np.maximum(res - logdet, 0.0)
    out = scale * np.log1p(q / scale)
    return out if logdet is None else out + logdet


def _totals(rows: np.ndarray, base: np.ndarray, w: np.ndarray, t: np.ndarray,
            sigma2: Optional[float], scale: Optional[np.ndarray],
            basis: Optional[np.ndarray] = None, products: Optional[np.ndarray] = None
            ) -> Tuple[np.ndarray, np.ndarray]:
    """Return :func:`_costs2` with the line costs made robust when ``scale`` is given."""
    if scale is None:
        return _costs2(rows, base, w, t, sigma2, basis, products=products)
    parts: list = []
    res, n0 = _costs2(rows, base, w, t, sigma2, basis, parts if sigma2 is not None else None,
                      products)
    return _robust_costs(res, parts[0] if parts else None, scale), n0


#: LM step tries per lockstep round of the line search (8 in all, the damping x5 per try;
#: the first success counts, later tries of the round are wasted). The first try succeeds in
#: ~85% of the iterations; after a failure ~3/4 succeed within three more. One batched call
#: for several tries costs little more than one. Measured: (1, 3, 4) ~5% faster than one try
#: per round, (1, 7) no faster, on bench hopkins and bench pipeline.
_TRIES = (1, 3, 4)


#: Largest batch (motions x tracks x frames) of the start scan's cost evaluations: bounds the
#: temporaries (a few tens of floats per unit).
_BATCH = 50000


def _scan_costs(rows: np.ndarray, base: np.ndarray, w: np.ndarray, T: np.ndarray,
                sigma2: Optional[float], scale: Optional[np.ndarray] = None,
                products: Optional[np.ndarray] = None) -> list:
    """
    Return the total two-pass cost of the tracks ``rows`` at each motion ``(w, T)``.

    ``T (C, 3)``; ``w (3,)`` for all of them or ``(C, 3)``, one per candidate. ``scale``: the
    robust per-line cost's (:func:`robust_scale`), None for least squares. ``products``:
    the tracks' :meth:`.LineObservations.row_products` if known.
    """
    size = max(1, _BATCH // max(rows.shape[0] * rows.shape[1], 1))
    w = np.broadcast_to(w, T.shape)
    out: list = []
    for s in range(0, T.shape[0], size):                 # chunks of many candidates
        res, _ = _totals(rows, base, w[s:s + size], T[s:s + size], sigma2, scale,
                         products=products)
        out += [r.sum() for r in res]                    # per candidate: a sum as in a loop
    return out


#: Scales of a translation tried by :func:`rescale_translation`: T = 0 and x 1/16 to x 16 in
#: steps of sqrt(2), searched coarse to fine: T = 0 and the powers of 2 first, then the two
#: half steps beside the cheapest: 12 costs instead of 18, the same scale for 179 of 180
#: bodies (three of 67 lines, 30 scenes, two noise levels), 7.0 -> 5.3 ms (the costs of
#: the larger batches grow with the scales).
RESCALES = np.concatenate([[0.0], 2.0 ** np.arange(-4.0, 4.5, 0.5)])
_COARSE = np.concatenate([[0.0], 2.0 ** np.arange(-4.0, 4.5, 1.0)])


def rescale_translation(obs: LineObservations, idx: np.ndarray, w: np.ndarray, t: np.ndarray,
                        sigma2: float) -> np.ndarray:
    """
    Return ``t (3,)`` at the scale of :data:`RESCALES` that fits the tracks ``idx`` best.

    ``w``: the rotation (rad/frame), held; ``sigma2`` (px^2): the noise variance of the
    marginalised cost, whose translation scale means something only at that level (a fit at
    a small noise leaves it nearly free). One body of :func:`rescale_translations`.
    """
    return rescale_translations(obs, [idx], np.asarray(w, dtype=float)[None],
                                np.asarray(t, dtype=float)[None], sigma2)[0]


def rescale_translations(obs: LineObservations, members: Sequence[np.ndarray], W: np.ndarray,
                         T: np.ndarray, sigma2: float) -> np.ndarray:
    """
    Return each body's ``T (B, 3)`` at the scale of :data:`RESCALES` that fits it best.

    ``members``: each body's track indices (non-empty); ``W, T (B, 3)``: the bodies'
    motions, W held; ``sigma2`` as in :func:`rescale_translation`. Every body in two batched
    cost evaluations, the coarse scales and then the half steps beside each body's cheapest
    (the bodies' tracks padded, :func:`padded_members`), or a few more when a batch would
    exceed 4 :data:`_BATCH`.
    """
    idx, mask = padded_members(members)
    W, T = np.asarray(W, dtype=float), np.asarray(T, dtype=float)
    size = max(1, 4 * _BATCH // (_COARSE.size * idx.shape[1] * obs.rows.shape[1]))
    out = np.empty_like(T)
    for s in range(0, idx.shape[0], size):               # chunks of bodies, not lines
        part = slice(s, s + size)
        # the Gram blocks at T once: at T times a scale they are the same, scaled
        # (:func:`_scale_totals`)
        tracks = (_grams(obs.row_products(idx[part]), W[part], T[part], obs.rows.shape[1]),
                  obs.m_first[idx[part]][:, None], mask[part])
        body = np.arange(T[part].shape[0])
        coarse = _scale_totals(tracks, np.broadcast_to(_COARSE, (body.size, _COARSE.size)),
                               sigma2)
        first = np.argmin(coarse, axis=1)
        best = _COARSE[first]
        # the half steps beside the coarse winner, within the range (T = 0 stays)
        near = np.clip(best[:, None] * np.sqrt(2.0) ** np.array([-1.0, 1.0]),
                       RESCALES[1], RESCALES[-1]) * (best[:, None] > 0)
        fine = _scale_totals(tracks, near, sigma2)
        scales = np.concatenate([best[:, None], near], axis=1)
        pick = np.argmin(np.concatenate([coarse[body, first][:, None], fine], axis=1), axis=1)
        out[part] = T[part] * scales[body, pick][:, None]
    return out


def _scale_totals(tracks: Tuple[Grams, np.ndarray, np.ndarray], scales: np.ndarray,
                  sigma2: float) -> np.ndarray:
    """
    Return the marginalised cost ``(B, R)`` of each body's tracks at ``T`` times each scale.

    ``tracks``: the bodies' padded tracks (:func:`padded_members`) as the :data:`.Grams`
    ``(3, 3, 3, B, L)`` of their constraints at the bodies' motions ``(W, T)``, their first
    normals ``(B, 1, L, 3)`` and mask ``(B, L)``; ``scales (B, R)``; ``sigma2`` (px^2) the
    noise variance. The direction constraints are linear in T: at ``s T`` the Gram blocks
    are ``An^T An``, ``s Av^T An`` and ``s^2 Av^T Av``, no new products.
    """
    grams, base, mask = tracks
    nn, vn, vv = grams
    s = scales[:, :, None]                                                   # (B, R, 1)
    res, _ = _marginal_costs((nn[:, :, :, None], vn[:, :, :, None] * s,
                              vv[:, :, :, None] * (s * s)), base, sigma2, passes=2)  # (B, R, L)
    return np.where(mask[:, None] > 0, res, 0.0).sum(axis=-1)


class _Tracks(NamedTuple):
    """
    The tracks and cost of LM runs, as every run evaluates them.

    Shared by all runs (one body), or each run its own (several bodies in lockstep): then
    every array has a leading run axis, and the runs' tracks are padded to one length by
    repeating a track of their own, with ``mask`` 0 (:func:`fit_bodies`).
    """

    rows: np.ndarray                 # (L, K, 2, 3) observation rows, gathered once
    products: np.ndarray             # (9K, L) their row products
    sigma2: Optional[float]          # None: fitted line directions; else marginalised (px^2)
    scale: Optional[np.ndarray]      # (L,) robust cost's scale; None: least squares
    mask: Optional[np.ndarray] = None    # (S, L) per run: 1 its lines, 0 padding; None: shared

    @property
    def free(self) -> bool:
        """Return whether T has a length of its own (marginalised directions), not unit."""
        return self.sigma2 is not None

    def of(self, runs: Sequence[int]) -> '_Tracks':
        """Return the tracks of the runs ``runs``, one entry per run (shared: as they are)."""
        if self.mask is None:
            return self
        pick = np.asarray(runs, dtype=np.intp)
        return _Tracks(self.rows[pick], self.products[pick],
                       self.sigma2, None if self.scale is None else self.scale[pick],
                       self.mask[pick])

    def totals(self, res: np.ndarray) -> list:
        """Return each run's total cost from its line costs ``res (S, L)`` (:meth:`of`)."""
        if self.mask is None:
            return [float(r.sum()) for r in res]
        return [float(r.sum()) for r in np.where(self.mask > 0, res, 0.0)]


@dataclass
class _Runs:
    """State of lockstep LM runs: motions, moments, costs and dampings per run."""

    W: np.ndarray                    # (S, 3)
    T: np.ndarray                    # (S, 3)
    n0: np.ndarray                   # (S, L, 3)
    cost: list
    lam: list


def _lm_runs(obs: LineObservations, idx: np.ndarray, W0: np.ndarray, T0: np.ndarray,
             iterations: int, sigma2: Optional[float], robust: Optional[float] = None,
             mask: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Run :func:`fit_body` independently from each of ``(W0, T0) (S, 3)`` on the same tracks.

    ``idx (L,)``: the tracks; or ``idx (S, L)`` with ``mask (S, L)``: each run its own tracks,
    padded (:func:`fit_bodies`).

    Returns ``W (S, 3)``, ``T (S, 3)`` and costs ``(S,)``. The runs advance in lockstep so that
    every numpy call serves all of them: each call is dominated by its fixed overhead at these
    sizes (tens of tracks), so one batched call costs little more than a single evaluation.
    Each run takes exactly the steps it takes alone: the batched operations repeat its
    products per motion.

    ``robust`` (px^2, a noise variance): minimise the robust cost of :func:`_robust_costs` at
    :func:`robust_scale` of that variance instead of the sum of squares, by iteratively
    reweighted Gauss-Newton (each line's residuals and Jacobian rows weighted by the Cauchy
    weight ``s / (s + q)`` of its current cost ``q``); steps are accepted on the robust cost,
    which is also the cost returned.
    """
    scale = None if robust is None else robust_scale(obs.frames[idx], robust)
    rows = obs.rows[idx]
    tracks = _Tracks(rows, obs.row_products(idx), sigma2, scale, mask)
    W = np.array(W0, dtype=float)
    T = np.array(T0, dtype=float)
    if not tracks.free:
        for s in range(W.shape[0]):                      # a few runs, not lines
            nt = np.linalg.norm(T[s])
            T[s] = T[s] / nt if nt > 1e-12 else np.array([0.0, 0.0, 1.0])
    res, n0 = _totals(tracks.rows, obs.m_first[idx], W, T, sigma2, scale,
                      products=tracks.products)
    runs = _Runs(W, T, n0, tracks.totals(res), [1e-3] * W.shape[0])
    active = np.arange(W.shape[0])                       # runs still iterating
    for _ in range(iterations):
        if active.size == 0:
            break
        Ta, n0a = T[active], n0[active]
        bases = [np.eye(3) if tracks.free else _tangent(t) for t in Ta]
        basis = orthonormal_pair(n0a)                    # shared by probes and the next pass
        systems = _normal_equations(tracks.of(active), W[active], Ta, n0a, bases, basis)
        accepted = _line_search(tracks, runs, active, systems, Ta, bases, n0a, basis)
        active = active[[a for a in range(active.size)
                         if a in accepted and not np.linalg.norm(accepted[a]) < 1e-12]]
    return W, T, np.array(runs.cost)


def _moved(t: np.ndarray, x: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Return the unit translation ``t`` moved by the parameters ``x[3:]`` along ``basis``."""
    tt = t + x[3:] @ basis
    return tt / np.linalg.norm(tt)


def _normal_equations(tracks: _Tracks, W: np.ndarray, T: np.ndarray, n0: np.ndarray,
                      bases: list, basis: np.ndarray) -> list:
    """
    Return the Gauss-Newton system ``(J^T J, J^T r)`` of each run at ``W, T (A, 3)``.

    ``n0 (A, L, 3)``: the runs' moments, held fixed (variable projection), ``basis`` their
    :func:`.orthonormal_pair`; ``bases``: each run's basis of the T parameters. Analytic
    derivatives, every run in one batch (:func:`.jacobian.normal_equations`).
    """
    H, g = normal_equations(tracks.rows, W, T, n0, basis, tracks.sigma2, tracks.scale,
                            tracks.mask)
    if tracks.free:
        return list(zip(H, g))
    systems = []
    for a in range(W.shape[0]):                          # a few runs, not lines
        # T moves in its tangent plane: x[3:] @ bases[a]
        P = np.zeros((6, 5))
        P[:3, :3] = np.eye(3)
        P[3:, 3:] = bases[a].T
        systems.append((P.T @ H[a] @ P, P.T @ g[a]))
    return systems


def _line_search(tracks: _Tracks, runs: _Runs, active: np.ndarray, systems: list,
                 T: np.ndarray, bases: list, n0: np.ndarray, basis: np.ndarray) -> dict:
    """
    Take one LM step per active run, raising its damping until the cost drops.

    The runs' tries are evaluated together, :data:`_TRIES` at a time; ``runs`` is updated in
    place. ``T (A, 3)``, ``n0 (A, L, 3)``, ``basis``: the active runs' translations, moments
    and their :func:`.orthonormal_pair` at the start of the step. Returns the accepted steps
    by position in ``active``.
    """
    n_par = 6 if tracks.free else 5
    ridge = 1e-12 * np.eye(n_par)
    searching, accepted = list(range(active.size)), {}
    for n_try in _TRIES:
        if not searching:
            break
        # every run's tries, the damping x5 per try; their systems solved in one call
        pos = np.repeat(searching, n_try)
        rep = np.repeat(np.arange(len(searching)), n_try)
        lam = (np.array([runs.lam[active[a]] for a in searching])[rep]
               * np.tile(5.0 ** np.arange(n_try), len(searching)))
        H = np.array([systems[a][0] for a in searching])[rep]
        g = np.array([systems[a][1] for a in searching])[rep]
        damped = H + lam[:, None, None] * (np.einsum('cii->ci', H)[:, :, None] * np.eye(n_par)
                                           + ridge)
        steps = -np.linalg.solve(damped, g[:, :, None])[:, :, 0]
        cand = list(zip(pos.tolist(), steps, lam.tolist()))
        cw = runs.W[active[pos]] + steps[:, :3]
        if tracks.free:
            ct = T[pos] + steps[:, 3:]
        else:
            ct = np.array([_moved(T[a], step, bases[a]) for a, step, _ in cand])
        mine = tracks.of(active[pos])
        rn, n0n = _totals(mine.rows, n0[pos], cw, ct, mine.sigma2, mine.scale, basis[pos],
                          mine.products)
        totals = mine.totals(rn)
        for i, (a, step, lam_a) in enumerate(cand):      # each run's tries in order
            s = active[a]
            if a in accepted:
                continue
            c = totals[i]
            if c < runs.cost[s]:
                runs.W[s], runs.T[s], runs.n0[s], runs.cost[s] = cw[i], ct[i], n0n[i], float(c)
                runs.lam[s] = max(lam_a / 5.0, 1e-12)
                accepted[a] = step
            else:
                runs.lam[s] = lam_a * 5.0
        searching = [a for a in searching if a not in accepted]
    return accepted


def fit_body(obs: LineObservations, idx: np.ndarray, w0: np.ndarray, t0: np.ndarray,
             iterations: int = 15, sigma2: Optional[float] = None,
             robust: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray, float]:
    """
    Fit ``(w, T)`` to the tracks ``idx`` by Levenberg-Marquardt; return w, T, cost.

    Variable projection: the per-line unknowns are eliminated; the Gauss-Newton system is the
    joint one in the motion and the line directions, reduced to the motion, with the moments
    held (analytic derivatives, :mod:`.jacobian`; every run in one batch: :func:`_lm_runs`).
    With ``sigma2`` None (fitted line directions,
    :func:`line_residuals`) T is a unit vector that moves in its tangent plane (five
    parameters, no gauge freedom); with ``sigma2`` (px^2, marginalised directions,
    :func:`marginal_residuals`) T is free (six parameters, its length is the body's
    translation scale). ``robust`` (px^2): the robust cost at that noise level
    (:func:`_lm_runs`).
    """
    W, T, cost = _lm_runs(obs, idx, np.atleast_2d(np.asarray(w0, dtype=float)),
                          np.atleast_2d(np.asarray(t0, dtype=float)), iterations, sigma2,
                          robust)
    return W[0], T[0], float(cost[0])


def fit_bodies(obs: LineObservations, members: Sequence[np.ndarray], W0: np.ndarray,
               T0: np.ndarray, iterations: int, sigma2: Optional[float] = None,
               robust: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Fit several bodies at once: :func:`fit_body` of ``members[b]`` from ``(W0[b], T0[b])``.

    ``members``: each body's track indices (non-empty); ``W0, T0 (B, 3)``. Returns
    ``W, T (B, 3)`` and costs ``(B,)``, each as :func:`fit_body` returns it up to rounding:
    the bodies' LM runs go in lockstep, each on its own tracks padded to the longest by
    repeating its first track at weight 0 (one numpy call per step serves every body: at tens
    of tracks a body each call's fixed overhead dominates).
    """
    idx, mask = padded_members(members)
    W, T, cost = _lm_runs(obs, idx, np.asarray(W0, dtype=float), np.asarray(T0, dtype=float),
                          iterations, sigma2, robust, mask)
    return W, T, cost


def padded_members(members: Sequence[np.ndarray]) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the bodies' track indices padded to one length ``(B, L)`` and their mask ``(B, L)``.

    ``members``: each body's track indices (non-empty). A body's padding repeats its first
    track (a real track: its costs stay finite) at mask 0; mask 1 marks its own tracks.
    """
    longest = max(len(m) for m in members)
    idx = np.empty((len(members), longest), dtype=np.intp)
    mask = np.zeros((len(members), longest))
    for b, m in enumerate(members):                      # bodies, not lines
        idx[b] = m[0]
        idx[b, :len(m)] = m
        mask[b, :len(m)] = 1.0
    return idx, mask


def best_fits(obs: LineObservations, members: Sequence[np.ndarray], W0: np.ndarray,
              T0: np.ndarray, iterations: int, sigma2: Optional[float],
              robust: Optional[float] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Return :func:`_best_fit` of several bodies from ``(W0[b], T0[b])``: ``W, T (B, 3)``, costs.

    ``members``: each body's track indices (non-empty). One batch of
    :func:`best_of_starts`.
    """
    W0, T0 = np.asarray(W0, dtype=float), np.asarray(T0, dtype=float)
    return best_of_starts(obs, members, W0, [(w[None], t[None]) for w, t in zip(W0, T0)],
                          iterations, sigma2, robust)


def best_of_starts(obs: LineObservations, members: Sequence[np.ndarray], W0: np.ndarray,
                   starts: Sequence[Tuple[np.ndarray, np.ndarray]], iterations: int,
                   sigma2: Optional[float], robust: Optional[float] = None,
                   runs: Optional[list] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Run each body's LM from each of its starts; return the cheapest run's ``W, T (B, 3)``, costs.

    ``starts[b]``: body b's starting ``(W (S, 3), T (S, 3))``, to which T = 0 at ``W0[b]`` is
    added (:func:`_with_zero_start`); the first of a body's cheapest runs wins, as in
    :func:`_best_fit`. Every run of every body goes in one lockstep batch (:func:`fit_bodies`).
    ``runs``: a list that receives each body's runs, ``(W (R, 3), costs (R,))``.
    """
    body, w_runs, t_runs = [], [], []
    for b, (ws, ts) in enumerate(starts):                # bodies, not lines
        ws, ts = _with_zero_start(W0[b], ws, ts, sigma2)
        body += [b] * len(ts)
        w_runs.append(ws)
        t_runs.append(ts)
    W, T, cost = fit_bodies(obs, [members[b] for b in body], np.concatenate(w_runs),
                            np.concatenate(t_runs), iterations, sigma2, robust)
    body = np.asarray(body)
    if runs is not None:
        runs += [(W[body == b], cost[body == b]) for b in range(len(members))]
    best = _first_cheapest(body, cost, len(members))
    return W[best], T[best], cost[best]


def _first_cheapest(body: np.ndarray, cost: np.ndarray, n: int) -> np.ndarray:
    """Return, for each of ``n`` bodies, the first of its runs (``body (R,)``) that costs least."""
    best = np.full(n, -1)
    for r in range(body.size):                           # runs, not lines
        b = body[r]
        if best[b] < 0 or cost[r] < cost[best[b]]:
            best[b] = r
    return best


def _with_zero_start(w0: np.ndarray, W0: np.ndarray, starts: np.ndarray,
                     sigma2: Optional[float]) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the starts ``W0, starts (S, 3)`` with T = 0 at ``w0`` added if they lack it.

    Marginalised directions only (``sigma2``): the cost is even in T, so T = 0 is stationary
    and no LM run started at another T returns to it.
    """
    if sigma2 is not None and np.all(np.any(starts != 0.0, axis=1)):
        return (np.concatenate([W0, np.asarray(w0, dtype=float)[None]]),
                np.concatenate([starts, np.zeros((1, 3))]))
    return W0, starts


def _best_fit(obs: LineObservations, idx: np.ndarray, w0: np.ndarray, starts: np.ndarray,
              iterations: int, sigma2: Optional[float], w_starts: Optional[np.ndarray] = None,
              robust: Optional[float] = None, runs: Optional[list] = None
              ) -> Tuple[np.ndarray, np.ndarray, float]:
    """
    Run :func:`fit_body` from ``w0`` and each T of ``starts (S, 3)``; the cheapest wins.

    ``w_starts (S, 3)``: a rotation per start instead of ``w0`` for all. With marginalised
    directions (``sigma2``) T = 0 (at ``w0``) is always one of the starts
    (:func:`_with_zero_start`). ``runs``: a list that receives every run, ``(W (S, 3),
    costs (S,))``.
    """
    w0 = np.asarray(w0, dtype=float)
    W0 = np.broadcast_to(w0, starts.shape) if w_starts is None else w_starts
    W0, starts = _with_zero_start(w0, W0, starts, sigma2)
    W, T, cost = _lm_runs(obs, idx, W0, starts, iterations, sigma2, robust)  # in lockstep
    if runs is not None:
        runs.append((W, cost))
    best = 0
    for s in range(1, cost.size):                        # a few starts, not lines
        if cost[s] < cost[best]:
            best = s
    return W[best], T[best], float(cost[best])
