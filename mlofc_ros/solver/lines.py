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
"""Interpretation-plane normals of line tracks, their noise, and the exact Cayley line flow.

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
from typing import Tuple

import numpy as np

Intrinsics = Tuple[float, float, float, float]


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of ``(..., 3)`` arrays: the same products and differences, less overhead."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def _norm3(v: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(v, axis=-1, keepdims=True)`` of ``(..., 3)``: the same sum, in order."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.sqrt(x * x + y * y + z * z)[..., None]


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
    """Compute the unit normals ``m`` and their covariance for every track and frame.

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
    xa = normalise_points(tracks[..., 0:2], intrinsics)
    xb = normalise_points(tracks[..., 2:4], intrinsics)
    n = _cross3(xa, xb)
    norm = _norm3(n)
    with np.errstate(invalid='ignore', divide='ignore'):
        m = n / norm
    # consistent sign along each track: compare with the previous present frame (vectorised
    # over tracks; the loop runs over the few frames of the window)
    last = np.full(m.shape[0:1] + (3,), np.nan)
    for k in range(m.shape[1]):
        flip = np.einsum('ij,ij->i', m[:, k], last) < 0
        m[flip, k] *= -1.0
        ok = np.isfinite(m[:, k, 0])
        last[ok] = m[ok, k]
    # d m = P / |n| d n with P = I - m m^T,  d n = -[x_b]x d x_a + [x_a]x d x_b,
    # d x = K2 d(u, v) (K2: first two columns of K^-1). So cov = s^2 P Q P / |n|^2 with
    # Q = sum over both endpoints of [x]x K2 K2^T [x]x^T, written out (x_2 = 1) and expanded:
    # elementwise products instead of chains of stacked 3x3 matmuls (4x faster at N = 200)
    # numpy scalars: overflow of extreme (fuzzed) focal lengths gives inf, as the matmuls did
    ifx2, ify2 = np.float64(1.0 / intrinsics[0]) ** 2, np.float64(1.0 / intrinsics[1]) ** 2
    q = np.zeros(m.shape + (3,))
    q[..., 0, 0] = 2.0 * ify2
    q[..., 1, 1] = 2.0 * ifx2
    q[..., 0, 2] = q[..., 2, 0] = -(xa[..., 0] + xb[..., 0]) * ify2
    q[..., 1, 2] = q[..., 2, 1] = -(xa[..., 1] + xb[..., 1]) * ifx2
    q[..., 2, 2] = ((xa[..., 1] ** 2 + xb[..., 1] ** 2) * ifx2
                    + (xa[..., 0] ** 2 + xb[..., 0] ** 2) * ify2)
    qm = np.einsum('...ij,...j->...i', q, m)
    mqm = np.einsum('...i,...i->...', m, qm)
    cov = q - m[..., :, None] * qm[..., None, :] - qm[..., :, None] * m[..., None, :]
    cov += mqm[..., None, None] * (m[..., :, None] * m[..., None, :])
    cov *= (endpoint_sigma ** 2 / norm ** 2)[..., None]
    return m, cov


def orthonormal_pair(m: np.ndarray) -> np.ndarray:
    """Orthonormal basis ``E (..., 3, 2)`` of the plane orthogonal to each vector ``m (..., 3)``.

    Built from the axis least aligned with ``m`` so it is well conditioned for every direction
    (vertical image lines included).
    """
    m = m / _norm3(m)
    idx = np.argmin(np.abs(m), axis=-1)
    axis = (idx[..., None] == np.arange(3)).astype(float)     # one-hot: cheaper than a put
    e1 = _cross3(m, axis)
    e1 /= _norm3(e1)
    out = np.empty(m.shape + (2,))
    out[..., 0] = e1
    out[..., 1] = _cross3(m, e1)
    return out


@dataclass
class LineFlows:
    """Line flows of every consecutive frame pair where a track is present in both frames.

    ``P`` pairs; each gives two equations ``r = M c - b`` for its body's Cayley vector ``c``.
    ``cov0``/``cov1`` are the normal covariances for 1 px endpoint noise.
    """

    n_tracks: int
    pair_track: np.ndarray   # (P,) int: track index of each pair
    m0: np.ndarray           # (P, 3) normal in the earlier frame
    m1: np.ndarray           # (P, 3) normal in the later frame
    cov0: np.ndarray         # (P, 3, 3)
    cov1: np.ndarray         # (P, 3, 3)
    E: np.ndarray            # (P, 3, 2) orthonormal pair orthogonal to m_bar
    M: np.ndarray            # (P, 2, 3)
    b: np.ndarray            # (P, 2)
    pair_slot: np.ndarray    # (P,) int: frame pair index within the window (k of k -> k+1)
    # (N, 2 (K-1), 4): every track's rows [M, -b] whitened per track (see :func:`whiten_tracks`)
    # by frame-pair slot, zero rows for missing pairs, so that a track's exact cost is
    # |rows @ [c ; 1]|^2 in one product
    track_rows: np.ndarray
    # derived per-track quantities computed once (the arrays above are never modified):
    # 'pairs' (N,) and the TrackStats of :func:`.models.track_stats` by weighting
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_pairs(self) -> int:
        return int(self.pair_track.shape[0])

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
    """Exact (Cayley midpoint) line flows of a window of tracks; see the module docstring.

    Parameters
    ----------
    tracks : (N, K, 4) float
        Endpoints in pixels, NaN where missing; only consecutive present frames form pairs.
    intrinsics : (fx, fy, cx, cy)
        Pixels.
    """
    m, cov = interpretation_normals(tracks, intrinsics)
    ok = np.isfinite(m[..., 0])
    pair_ok = ok[:, :-1] & ok[:, 1:]
    ti, ki = np.nonzero(pair_ok)
    m0, m1 = m[ti, ki], m[ti, ki + 1]
    mbar = 0.5 * (m0 + m1)
    E = orthonormal_pair(mbar)
    Et = np.swapaxes(E, -1, -2)
    M = -Et @ skew(mbar)
    b = np.einsum('pjk,pk->pj', Et, m1 - m0)
    cov0, cov1 = cov[ti, ki], cov[ti, ki + 1]
    rows = whiten_tracks(tracks.shape[0], tracks.shape[1] - 1, ti, ki, E, cov0, cov1, M, b)
    return LineFlows(tracks.shape[0], ti, m0, m1, cov0, cov1, E, M, b, ki, rows)


def whiten_tracks(n_tracks: int, n_slots: int, ti: np.ndarray, ki: np.ndarray, E: np.ndarray,
                  cov0: np.ndarray, cov1: np.ndarray, M: np.ndarray, b: np.ndarray
                  ) -> np.ndarray:
    """Whiten every track's stacked residuals ``r = M c - b`` with their full covariance.

    Returns the whitened rows ``[M, -b]`` of every track ``(N, 2 (K-1), 4)`` by frame-pair
    slot, zero where a pair is missing (its slot is uncorrelated with the others, so its
    whitened rows stay zero).

    Consecutive frame pairs of a track share a frame, so their residuals are correlated
    (``Cov(r_t, r_t+1) = -E_t^T S_m(t+1) E_t+1``): the covariance of a track's ``2 (K-1)``
    residuals is block-tridiagonal. With its Cholesky factor ``L`` the whitened residuals
    ``L^-1 r`` are independent with unit variance for 1 px endpoint noise, so a track's cost is
    chi-square with ``2 (K-1)`` degrees of freedom (checked: tails as chi-square, where the
    block-diagonal approximation put 0.4% of inliers above the 99.9% bound at K = 5). The
    covariance is taken at ``c = 0``: the exact one differs by ``(I +- [c]x/2)``, a few percent.
    """
    d = 2 * n_slots
    slot = ki
    full = np.zeros((n_tracks, d, d))
    full[:, np.arange(d), np.arange(d)] = 1.0                         # missing pairs: unit
    cov = full.reshape(n_tracks, n_slots, 2, n_slots, 2)             # a view: 2x2 blocks
    Et = np.swapaxes(E, 1, 2)
    cov[ti, slot, :, slot] = Et @ (cov0 + cov1) @ E
    # pairs (t, t+1) and (t+1, t+2) of the same track share frame t+1
    lookup = np.full((n_tracks, n_slots + 1), -1)
    lookup[ti, slot] = np.arange(ti.size)
    nxt = lookup[ti, slot + 1]
    has = nxt >= 0
    p, q = np.flatnonzero(has), nxt[has]
    off = -(Et[p] @ cov1[p] @ E[q])
    cov[ti[p], slot[p], :, slot[q]] = off
    cov[ti[p], slot[q], :, slot[p]] = np.swapaxes(off, 1, 2)
    stacked = np.zeros((n_tracks, n_slots, 2, 4))
    stacked[ti, slot, :, :3] = M
    stacked[ti, slot, :, 3] = b
    L = np.linalg.cholesky(full)
    rows = np.linalg.solve(L, stacked.reshape(n_tracks, d, 4))
    rows[..., 3] *= -1.0
    return rows


def first_midpoints(tracks: np.ndarray) -> np.ndarray:
    """Midpoint ``(N, 2)`` (px) of every track's first present segment."""
    ok = np.isfinite(tracks[..., 0])
    seg = tracks[np.arange(tracks.shape[0]), np.argmax(ok, axis=1)]
    return 0.5 * (seg[:, :2] + seg[:, 2:])
