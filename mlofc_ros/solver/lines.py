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
Interpretation-plane normals of line tracks, their noise, and the exact Cayley line flow.

A segment with normalised endpoints ``x_a, x_b`` (``x = K^-1 [u, v, 1]``) spans the plane through
the camera centre with unit normal ``m = x_a x x_b / |x_a x x_b|``. A rotation ``R`` of the body
about the camera centre maps ``m`` to ``m' = R m`` exactly. With the Cayley vector ``c`` of ``R``
(``R = (I - [c]x/2)^-1 (I + [c]x/2)``, ``c = 2 tan(theta/2) k``),
``m' - m = c x m_bar`` with ``m_bar = (m + m')/2``, exactly. Projecting on an orthonormal pair
``e_1, e_2`` orthogonal to ``m_bar`` gives two equations per frame pair, linear in ``c``::

    r_j = e_j . (c x m_bar) - e_j . (m' - m) = (M c - b)_j,  M = -E^T [m_bar]x,  b = E^T (m' - m)

so the row ``y_j = [m_bar x e_j ; -(e_j . g)]`` of R^4 is orthogonal to ``u = [c ; 1]``.
"""
from dataclasses import dataclass, field
from typing import Optional, Tuple

import numpy as np

Intrinsics = Tuple[float, float, float, float]


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``(..., 3, 3)`` of vectors ``(..., 3)``."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def cayley_to_rotvec(c: np.ndarray) -> np.ndarray:
    """Cayley vectors ``(..., 3)`` -> rotation vectors ``theta k`` (rad), theta = 2 atan(|c|/2)."""
    c = np.asarray(c, dtype=float)
    n = np.linalg.norm(c, axis=-1, keepdims=True)
    scale = np.where(n > 1e-12, 2.0 * np.arctan(n / 2.0) / np.maximum(n, 1e-300), 1.0)
    return c * scale


def rotvec_to_cayley(w: np.ndarray) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` (rad, |w| < pi) -> Cayley vectors ``2 tan(theta/2) k``."""
    w = np.asarray(w, dtype=float)
    t = np.linalg.norm(w, axis=-1, keepdims=True)
    scale = np.where(t > 1e-12, 2.0 * np.tan(t / 2.0) / np.maximum(t, 1e-300), 1.0)
    return w * scale


def cayley_jacobian(c: np.ndarray) -> np.ndarray:
    """Jacobian ``(..., 3, 3)`` of :func:`cayley_to_rotvec` (to carry covariances)."""
    c = np.asarray(c, dtype=float)
    n = np.linalg.norm(c, axis=-1)[..., None, None]
    safe = np.maximum(n, 1e-12)
    s = 2.0 * np.arctan(safe / 2.0) / safe
    ds = (1.0 / (1.0 + safe ** 2 / 4.0) - s) / safe          # d s / d |c|
    outer = c[..., :, None] * c[..., None, :] / safe
    return s * np.eye(3) + ds * outer


def rotation_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors ``(..., 3)`` (rad) -> rotation matrices ``(..., 3, 3)``."""
    w = np.asarray(w, dtype=float)
    t = np.linalg.norm(w, axis=-1)[..., None, None]
    k = skew(w) / np.maximum(t, 1e-300)
    small = t < 1e-12
    r = np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * (k @ k)
    return np.where(small, np.eye(3) + skew(w), r)


def normalise_points(uv: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Pixels ``(..., 2)`` -> homogeneous normalised points ``(..., 3)`` ``K^-1 [u, v, 1]``."""
    fx, fy, cx, cy = intrinsics
    out = np.empty(uv.shape[:-1] + (3,))
    out[..., 0] = (uv[..., 0] - cx) / fx
    out[..., 1] = (uv[..., 1] - cy) / fy
    out[..., 2] = 1.0
    return out


def interpretation_normals(tracks: np.ndarray, intrinsics: Intrinsics,
                           endpoint_sigma: float = 1.0) -> Tuple[np.ndarray, np.ndarray]:
    """
    Compute the unit normals ``m`` and their covariance for every track and frame.

    Parameters
    ----------
    tracks : (N, K, 4) float
        Endpoints ``(u1, v1, u2, v2)`` in pixels, NaN where missing.
    intrinsics : (fx, fy, cx, cy)
        Pixels.
    endpoint_sigma : float
        Standard deviation of each endpoint coordinate (px) the covariance is computed for.

    Returns
    -------
    m : (N, K, 3) float64
        Unit normals (NaN where missing), signs made consistent along each track
        (``m_t . m_prev > 0`` against the previous present frame).
    cov : (N, K, 3, 3) float64
        Covariance of ``m`` from isotropic endpoint noise (rank 2: orthogonal to ``m``). Short
        segments and segments far from the principal point are noisier.

    """
    m, cov = _normals(np.asarray(tracks, dtype=float), intrinsics, endpoint_sigma)
    return _per_track(m), _per_track(cov)


def _per_track(a: np.ndarray) -> np.ndarray:
    """Copy a slot-major array ``(..., K, N)`` (see below) to ``(N, K, ...)``."""
    out = np.empty(a.shape[:-3:-1] + a.shape[:-2])
    # copying through a view of the output that matches the input iterates in the input's
    # order: faster than a C-order pass with inner loops of length 2-3
    np.copyto(out.transpose(tuple(range(2, a.ndim)) + (1, 0)), a)
    return out


# The private helpers below work on component-major, slot-major arrays: ``(3, K, N)`` for
# vectors of every frame and track, ``(3, 3, K, N)`` for matrices (``(..., S, N)`` for the
# ``S = K - 1`` frame pairs). Every numpy call then runs over all tracks and frames with a long
# contiguous inner loop, where the per-track layouts ``(..., 3)`` and ``(..., 3, 3)`` (stacked
# 3x3 matmuls, einsum) run inner loops of length 2-3 and are several times slower at N ~ 200;
# and a frame (pair) is a contiguous ``(N,)`` slice for the loops over frames below. At these
# sizes the cost is mostly the number of numpy calls, so components are handled together
# where the arithmetic allows (e.g. :func:`_cross5`).


def _normals(tracks: np.ndarray, intrinsics: Intrinsics, endpoint_sigma: float = 1.0
             ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Compute :func:`interpretation_normals` slot-major: ``m (3, K, N)``, ``cov (3, 3, K, N)``.

    The arithmetic is the stacked form's, operation for operation: bit-identical results.
    """
    fx, fy, cx, cy = intrinsics
    x = np.empty((4,) + tracks.shape[1::-1])                    # x_a0, x_a1, x_b0, x_b1
    np.subtract(tracks.transpose(2, 1, 0), np.array([cx, cy, cx, cy])[:, None, None], out=x)
    x /= np.array([fx, fy, fx, fy])[:, None, None]
    # n = x_a x x_b with x_2 = 1 (the factors 1 of the general cross product are exact)
    m = np.empty((3,) + x.shape[1:])
    np.subtract(x[1:3], x[3::-3], out=m[:2])                    # x_a1 - x_b1, x_b0 - x_a0
    np.subtract(x[0] * x[3], x[1] * x[2], out=m[2])
    norm = _norm(m)
    with np.errstate(invalid='ignore', divide='ignore'):
        m /= norm
    _consistent_signs(m, np.isfinite(m[0]))
    # d m = P / |n| d n with P = I - m m^T,  d n = -[x_b]x d x_a + [x_a]x d x_b,
    # d x = K2 d(u, v) (K2: first two columns of K^-1). So cov = s^2 P Q P / |n|^2 with
    # Q = sum over both endpoints of [x]x K2 K2^T [x]x^T, written out (x_2 = 1) and expanded
    # numpy scalars: overflow of extreme (fuzzed) focal lengths gives inf, as the matmuls did
    ifx2, ify2 = np.float64(1.0 / fx) ** 2, np.float64(1.0 / fy) ** 2
    scale = np.array([ify2, ifx2])[:, None, None]               # of Q's rows 0 and 1
    q2 = x[:2] + x[2:]
    q2 *= -scale                                                 # q02, q12
    sq = x * x
    sums = sq[:2] + sq[2:]
    sums *= scale
    q22 = sums[1] + sums[0]
    # qm = Q m and m . qm: 3-term sums in the order einsum adds them on (..., 3) arrays,
    # (t_0 + t_2) + t_1 (q01 = 0 adds exactly nothing)
    qm = np.empty_like(m)
    np.multiply(2.0 * scale, m[:2], out=qm[:2])                  # q00 m0, q11 m1
    qm[:2] += q2 * m[2]
    t = q2 * m[:2]
    np.add(t[0], q22 * m[2], out=qm[2])
    qm[2] += t[1]
    t = m * qm
    mqm = t[0] + t[2]
    mqm += t[1]
    # cov = (Q - m qm^T) - qm m^T + (m . qm) m m^T with whole-array outer products;
    # -a + q is q - a exactly
    mq = m[:, None] * qm[None, :]
    cov = np.negative(mq)
    cov.reshape((9,) + m.shape[1:])[0:5:4] += 2.0 * scale       # q00, q11
    cov[:2, 2] += q2
    cov[2, :2] += q2
    cov[2, 2] += q22
    cov -= mq.transpose(1, 0, 2, 3)
    mm = np.multiply(m[:, None], m[None, :], out=mq)
    mm *= mqm
    cov += mm
    cov *= endpoint_sigma ** 2 / norm ** 2
    return m, cov


def _norm(v: np.ndarray) -> np.ndarray:
    """Norms ``(...)`` of component-major vectors ``(3, ...)``, summed in the order 0, 1, 2."""
    sq = v * v
    out = sq[0] + sq[1]
    out += sq[2]
    return np.sqrt(out, out=out)


def _consistent_signs(m: np.ndarray, ok: np.ndarray) -> None:
    """
    Flip normals ``m (3, K, N)`` in place so that ``m_k . m_prev > 0`` along each track.

    ``m_prev``: the previous present frame (``ok (K, N)``), after its own flip. The sign of
    frame k is the product of the signs of the raw dot products along the track, so one
    cumulative product replaces a loop over frames; an exactly zero dot product (which never
    flips, whatever the earlier flips) falls back to that loop.
    """
    prev = m[:, :-1]
    if not ok.all():
        # the previous present frame's raw normal (NaN before the first): forward fill
        prev = prev.copy()
        gap = ~ok
        for k in range(1, prev.shape[1]):
            np.copyto(prev[:, k], prev[:, k - 1], where=gap[k])
    t = m[:, 1:] * prev
    dot = t[0] + t[2]                                            # einsum's order (above)
    dot += t[1]
    flip = dot < 0.0
    if not flip.any():
        return                                                   # the usual case
    if (dot == 0.0).any():
        _consistent_signs_loop(m, ok)
        return
    sign = np.where(flip, -1.0, 1.0)
    np.multiply.accumulate(sign, axis=0, out=sign)
    m[:, 1:] *= sign


def _consistent_signs_loop(m: np.ndarray, ok: np.ndarray) -> None:
    """Compute :func:`_consistent_signs` frame by frame (vectorised over tracks)."""
    last = np.full((3, m.shape[2]), np.nan)
    for k in range(m.shape[1]):
        mk = m[:, k]
        t = mk * last
        dot = t[0] + t[2]
        dot += t[1]
        np.negative(mk, out=mk, where=dot < 0)
        np.copyto(last, mk, where=ok[k])


def _cross5(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """
    Write ``a x b`` (``(3, ...)``) given rolled vectors ``(5, ...)`` ``(v0, v1, v2, v0, v1)``.

    The three components in three numpy calls (slices of the rolled arrays), with the products
    and differences of ``np.cross``.
    """
    np.multiply(a[1:4], b[2:5], out=out)
    out -= a[2:5] * b[1:4]


def _pair_basis(m: np.ndarray) -> np.ndarray:
    """
    Compute :func:`orthonormal_pair` component-major: ``m (3, ...)`` -> ``E (5, 2, ...)``.

    ``E`` is rolled (rows 3, 4 repeat rows 0, 1) for :func:`_cross5`.
    """
    u = np.empty((5,) + m.shape[1:])
    np.divide(m, _norm(m), out=u[:3])
    u[3:] = u[:2]
    idx = np.argmin(np.abs(u[:3]), axis=0)
    # the one-hot axis (cheaper than a put); the cross product with it is exact
    axis = idx == np.array([0, 1, 2, 0, 1]).reshape((5,) + (1,) * idx.ndim)
    out = np.empty((5, 2) + m.shape[1:])
    e1 = out[:3, 0]
    _cross5(u, axis.astype(float), e1)
    e1 /= _norm(e1)
    out[3:, 0] = out[:2, 0]
    _cross5(u, out[:, 0], out[:3, 1])
    out[3:, 1] = out[:2, 1]
    return out


def pair_components(m: np.ndarray) -> np.ndarray:
    """
    Return :func:`orthonormal_pair` components first: ``m (3, ...)`` -> ``E (3, 2, ...)``.

    ``E[:, c]`` is the basis vector ``c`` of the plane orthogonal to each ``m[:, ...]``.
    """
    return _pair_basis(np.asarray(m, dtype=float))[:3]


def orthonormal_pair(m: np.ndarray) -> np.ndarray:
    """
    Orthonormal basis ``E (..., 3, 2)`` of the plane orthogonal to each vector ``m (..., 3)``.

    Built from the axis least aligned with ``m`` so it is well conditioned for every direction
    (vertical image lines included).
    """
    m = np.asarray(m, dtype=float)
    out = _pair_basis(np.ascontiguousarray(m.reshape(-1, 3).T))[:3]
    return np.ascontiguousarray(out.transpose(2, 0, 1)).reshape(m.shape + (2,))


@dataclass
class LineFlows:
    """
    Line flows of every consecutive frame pair where a track is present in both frames.

    ``P`` pairs; each gives two equations ``r = M c - b`` for its body's Cayley vector ``c``.
    ``cov0``/``cov1`` are the normal covariances for 1 px endpoint noise.

    The per-pair arrays ``m0, m1, cov0, cov1, E, M, b`` are copied out of the slot-major
    arrays :func:`line_flows` computes on first access only: the weighted solvers use
    ``track_rows`` alone (the copies were ~15% of :func:`line_flows`).
    """

    n_tracks: int
    pair_track: np.ndarray   # (P,) int: track index of each pair
    pair_slot: np.ndarray    # (P,) int: frame pair index within the window (k of k -> k+1)
    # (N, 2 (K-1), 4): every track's rows [M, -b] whitened per track (see :func:`whiten_tracks`)
    # by frame-pair slot, zero rows for missing pairs, so that a track's exact cost is
    # |rows @ [c ; 1]|^2 in one product
    track_rows: np.ndarray
    # slot-major sources of the per-pair arrays (see the comment above _normals): normals
    # (3, K, N), their covariances (3, 3, K, N), E (3, 2, S, N), unwhitened [M, -b]
    # (S, 2, 4, N); and the pairs' indices track * S + slot (None: every slot of every track)
    _m: np.ndarray = field(repr=False)
    _cov: np.ndarray = field(repr=False)
    _E: np.ndarray = field(repr=False)
    _rows: np.ndarray = field(repr=False)
    _flat: Optional[np.ndarray] = field(repr=False)
    # derived per-track quantities computed once (the arrays above are never modified):
    # 'pairs' (N,), the TrackStats of :func:`.models.track_stats` by weighting, and the
    # per-pair arrays
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_pairs(self) -> int:
        return int(self.pair_track.shape[0])

    @property
    def m0(self) -> np.ndarray:
        """``(P, 3)`` unit normal in the earlier frame of every pair."""
        return self._frames()[0]

    @property
    def m1(self) -> np.ndarray:
        """``(P, 3)`` unit normal in the later frame of every pair."""
        return self._frames()[1]

    @property
    def cov0(self) -> np.ndarray:
        """``(P, 3, 3)`` covariance of ``m0`` (1 px endpoint noise)."""
        return self._frames()[2]

    @property
    def cov1(self) -> np.ndarray:
        """``(P, 3, 3)`` covariance of ``m1`` (1 px endpoint noise)."""
        return self._frames()[3]

    @property
    def E(self) -> np.ndarray:
        """``(P, 3, 2)`` orthonormal pair orthogonal to ``m_bar``."""
        out = self.cache.get('E')
        if out is None:
            out = self.cache['E'] = _by_pair(self._E, self._flat)
        return out

    @property
    def M(self) -> np.ndarray:
        """``(P, 2, 3)`` line-flow matrix of every pair."""
        return self._pair_rows()[0]

    @property
    def b(self) -> np.ndarray:
        """``(P, 2)`` line flow of every pair."""
        return self._pair_rows()[1]

    def _frames(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        out = self.cache.get('frames')
        if out is None:
            m, cov = _per_track(self._m), _per_track(self._cov)     # (N, K, 3), (N, K, 3, 3)
            if self._flat is None:
                m0, m1 = (np.ascontiguousarray(a).reshape(-1, 3) for a in (m[:, :-1], m[:, 1:]))
                cov0, cov1 = (np.ascontiguousarray(a).reshape(-1, 3, 3)
                              for a in (cov[:, :-1], cov[:, 1:]))
            else:
                frame = self._flat + self.pair_track                 # track * K + slot
                m, cov = m.reshape(-1, 3), cov.reshape(-1, 3, 3)
                m0, m1 = np.take(m, frame, axis=0), np.take(m, frame + 1, axis=0)
                cov0, cov1 = np.take(cov, frame, axis=0), np.take(cov, frame + 1, axis=0)
            out = self.cache['frames'] = (m0, m1, cov0, cov1)
        return out

    def _pair_rows(self) -> Tuple[np.ndarray, np.ndarray]:
        out = self.cache.get('Mb')
        if out is None:
            rows = _by_pair(self._rows.transpose(1, 2, 0, 3), self._flat)
            out = self.cache['Mb'] = (np.ascontiguousarray(rows[..., :3]), -rows[..., 3])
        return out

    @property
    def rows(self) -> np.ndarray:
        """``(P, 2, 4)`` rows ``y = [M_j, -b_j]`` with ``y . [c ; 1] = r_j``."""
        return np.concatenate([self.M, -self.b[..., None]], axis=-1)

    def pairs_per_track(self) -> np.ndarray:
        """``(N,)`` number of frame pairs of every track (read-only, computed once)."""
        out = self.cache.get('pairs')
        if out is None:
            out = np.bincount(self.pair_track, minlength=self.n_tracks)
            out.setflags(write=False)
            self.cache['pairs'] = out
        return out

    @property
    def whitened_rows(self) -> np.ndarray:
        """``(P, 2, 4)`` rows whose residuals are independent with unit variance (1 px)."""
        n, d = self.track_rows.shape[:2]
        return self.track_rows.reshape(n, d // 2, 2, 4)[self.pair_track, self.pair_slot]


def line_flows(tracks: np.ndarray, intrinsics: Intrinsics) -> LineFlows:
    """
    Exact (Cayley midpoint) line flows of a window of tracks; see the module docstring.

    Parameters
    ----------
    tracks : (N, K, 4) float
        Endpoints in pixels, NaN where missing; only consecutive present frames form pairs.
    intrinsics : (fx, fy, cx, cy)
        Pixels.

    """
    m, cov = _normals(np.asarray(tracks, dtype=float), intrinsics)   # (3, K, N), (3, 3, K, N)
    n_slots, n_tracks = m.shape[1] - 1, m.shape[2]
    ok = np.isfinite(m[0])
    pair_ok = ok[:-1] & ok[1:]                                   # (S, N)
    ti, ki = np.nonzero(pair_ok.T)                               # pairs in track, slot order
    flat = None if ti.size == pair_ok.size else ti * n_slots + ki
    # every quantity is computed for every (slot, track), pair or not (NaN), and only the
    # outputs are picked by pair: no gathers or scatters in between
    m0, m1 = m[:, :-1], m[:, 1:]
    cov0, cov1 = cov[:, :, :-1], cov[:, :, 1:]
    mbar = np.empty((5,) + pair_ok.shape)                        # rolled, for _cross5
    np.add(m0, m1, out=mbar[:3])
    mbar[:3] *= 0.5                                              # 0.5 (m0 + m1)
    mbar[3:] = mbar[:2]
    E = _pair_basis(mbar[:3])                                    # (5, 2, S, N)
    # z: per slot and row j, [M_j, -b_j, B_j (2), A_j (2)] (see _whiten); zc: columns first
    z = np.empty((n_slots, 2, 8, n_tracks))
    zc = z.transpose(2, 1, 0, 3)                                 # (8, 2, S, N)
    _cross5(mbar[:, None], E, zc[:3])                           # M = -E^T [m_bar]x: m_bar x e_j
    t = E[:3] * (m1 - m0)[:, None]                               # b = E^T (m1 - m0)
    b = t[0] + t[1]
    b += t[2]
    np.negative(b, out=zc[3])
    _blocks(E[:3], cov0, cov1, zc)
    # the per-pair outputs are copied out on first use (LineFlows); _whiten overwrites z
    rows = z[:, :, :4].copy()                                    # [M, -b] before _whiten
    track_rows = _whiten(z, pair_ok)
    return LineFlows(n_tracks, ti, ki, track_rows, m, cov, E[:3], rows, flat)


def _by_pair(a: np.ndarray, flat: Optional[np.ndarray]) -> np.ndarray:
    """
    Values ``(P, ...)`` of every pair from a slot-major array ``(..., S, N)``.

    ``flat``: the pairs' indices ``track * S + slot``, or None for all (track, slot) in order.
    """
    out = _per_track(a)
    out = out.reshape((-1,) + out.shape[2:])
    return out if flat is None else np.take(out, flat, axis=0)      # take: faster than []


def _blocks(E: np.ndarray, cov0: np.ndarray, cov1: np.ndarray, zc: np.ndarray) -> None:
    """
    Write the residual covariance blocks of every pair into ``zc[4:8] (4, 2, S, N)``.

    ``zc[6:8, j]``: row j of the diagonal block ``A = E^T (S_m0 + S_m1) E`` (2x2) of the pair's
    residual ``r = M c - b``; ``zc[4:6, j]``: of the block ``B = Cov(r_s, r_s+1) =
    -E_s^T S_m(s+1) E_s+1`` with the track's next pair (they share a frame), zero in the last
    slot. ``E (3, 2, S, N)``, ``cov0``/``cov1 (3, 3, S, N)``: the normal covariances of the
    pairs' two frames.
    """
    # two products (C E, then E^T (C E)): fewer multiplications than a three-operand einsum
    ce = np.einsum('ab...,bk...->ak...', cov0 + cov1, E)
    np.einsum('aj...,ak...->kj...', E, ce, out=zc[6:8])
    ce = np.einsum('ab...,bk...->ak...', cov1[:, :, :-1], E[:, :, 1:])
    off = zc[4:6, :, :-1]
    np.einsum('aj...,ak...->kj...', E[:, :, :-1], ce, out=off)
    np.negative(off, out=off)
    zc[4:6, :, -1:] = 0.0


#: ``z`` of a missing pair (see :func:`_whiten`): zero rows, ``A = I``, ``B = 0``
_MISSING = np.array([[0.0] * 6 + [1.0, 0.0], [0.0] * 7 + [1.0]])[:, :, None]


def _whiten(z: np.ndarray, pair_ok: np.ndarray) -> np.ndarray:
    """
    Whitened rows ``(N, 2 S, 4)`` of every track from the pair data ``z (S, 2, 8, N)``.

    ``z[s, j, :, i]`` is ``[M_j, -b_j, B_j0, B_j1, A_j0, A_j1]`` of track i's slot s (see
    :func:`_blocks`); ``pair_ok (S, N)`` says which slots hold a pair (the others may hold
    anything, NaN included). ``z`` is overwritten.

    A track's residual covariance is block-tridiagonal with 2x2 blocks ``A_s`` (diagonal) and
    ``B_s`` (slots s, s+1). Its Cholesky factor follows the block recursion over slots (Schur
    complements ``D``)::

        D_0 = A_0,  L_s = chol(D_s),  V_s = L_s^-1 B_s,  D_s+1 = A_s+1 - V_s^T V_s
        y_s = L_s^-1 (r_s - V_s-1^T y_s-1)

    and ``y = L^-1 r`` are the whitened rows: closed-form 2x2 arithmetic on ``(N,)`` arrays
    for each slot, where the dense ``(N, 2S, 2S)`` matrix and its LAPACK Cholesky and solve
    cost several times more. A missing slot gets ``A = I``, ``B = 0`` and zero rows (as does
    the ``B`` into it): its whitened rows are zero and it breaks the chain.
    """
    n_slots, n_tracks = z.shape[0], z.shape[3]
    if not pair_ok.all():
        miss = ~pair_ok[:, None, None, :]
        np.copyto(z, _MISSING, where=miss)
        np.copyto(z[:-1, :, 4:6], 0.0, where=miss[1:])
    with np.errstate(invalid='ignore', divide='ignore'):
        for s in range(n_slots):
            x0, x1 = z[s]                                        # rows [r, B, D] of the slot
            # L^-1 on all eight columns in place: row 0 / l11 turns D's row 0 into
            # (l11, l21), and row 1 - l21 row 0 turns D's row 1 into (0, l22^2)
            l11 = np.sqrt(x0[6])
            x0 /= l11
            x1 -= x0[7] * x0
            x1 /= np.sqrt(x1[7])
            if s + 1 < n_slots:
                # V^T [y, V] (V = L^-1 B): the next rows' correction and V^T V for the next
                # Schur complement
                corr = x0[4:6, None] * x0[:6] + x1[4:6, None] * x1[:6]   # (2, 6, N)
                nxt = z[s + 1]
                nxt[:, :4] -= corr[:, :4]
                nxt[:, 6:] -= corr[:, 4:]
    out = np.empty((n_tracks, n_slots, 2, 4))
    np.copyto(out.transpose(1, 2, 3, 0), z[:, :, :4])
    return out.reshape(n_tracks, 2 * n_slots, 4)


def whiten_tracks(n_tracks: int, n_slots: int, ti: np.ndarray, ki: np.ndarray, E: np.ndarray,
                  cov0: np.ndarray, cov1: np.ndarray, M: np.ndarray, b: np.ndarray
                  ) -> np.ndarray:
    """
    Whiten every track's stacked residuals ``r = M c - b`` with their full covariance.

    Returns the whitened rows ``[M, -b]`` of every track ``(N, 2 (K-1), 4)`` by frame-pair
    slot, zero where a pair is missing (its slot is uncorrelated with the others, so its
    whitened rows stay zero). The inputs are those of :class:`LineFlows` (``ti``, ``ki``:
    ``pair_track``, ``pair_slot``); :func:`line_flows` does the same on its own arrays.

    Consecutive frame pairs of a track share a frame, so their residuals are correlated
    (``Cov(r_t, r_t+1) = -E_t^T S_m(t+1) E_t+1``): the covariance of a track's ``2 (K-1)``
    residuals is block-tridiagonal. With its Cholesky factor ``L`` the whitened residuals
    ``L^-1 r`` are independent with unit variance for 1 px endpoint noise, so a track's cost is
    chi-square with ``2 (K-1)`` degrees of freedom (checked: tails as chi-square, where the
    block-diagonal approximation put 0.4% of inliers above the 99.9% bound at K = 5). The
    covariance is taken at ``c = 0``: the exact one differs by ``(I +- [c]x/2)``, a few percent.
    """
    def grid(a: np.ndarray) -> np.ndarray:                       # (P, ...) -> (..., S, N)
        out = np.zeros(a.shape[1:] + (n_slots, n_tracks))
        out[..., ki, ti] = np.moveaxis(a, 0, -1)
        return out

    z = np.empty((n_slots, 2, 8, n_tracks))
    zc = z.transpose(2, 1, 0, 3)
    zc[:3] = grid(M).transpose(1, 0, 2, 3)
    zc[3] = -grid(b)
    _blocks(grid(E), grid(cov0), grid(cov1), zc)
    return _whiten(z, grid(np.ones(ti.size)) > 0)


def first_midpoints(tracks: np.ndarray) -> np.ndarray:
    """Midpoint ``(N, 2)`` (px) of every track's first present segment."""
    ok = np.isfinite(tracks[..., 0])
    seg = tracks[np.arange(tracks.shape[0]), np.argmax(ok, axis=1)]
    return 0.5 * (seg[:, :2] + seg[:, 2:])
