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
Small geometry helpers of the synthetic renderer (rotations, clipping, plumb_bob distortion).

Pixels are ``(u, v)`` (column, row, pixel centres at integers); the camera optical frame is
x right, y down, z forward.
"""
from typing import Sequence, Tuple

import numpy as np


def so3_exp(rotvec: Sequence[float]) -> np.ndarray:
    """Rodrigues: rotation matrix ``exp([w]x)`` (3, 3) of a rotation vector ``w`` (3,) in rad."""
    w = np.asarray(rotvec, dtype=float).reshape(3)
    theta = float(np.linalg.norm(w))
    wx = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if theta < 1e-12:
        return np.eye(3) + wx
    a = np.sin(theta) / theta
    b = (1.0 - np.cos(theta)) / theta ** 2
    return np.eye(3) + a * wx + b * (wx @ wx)


def so3_exp_many(rotvecs: np.ndarray) -> np.ndarray:
    """Vectorised :func:`so3_exp`: rotation vectors (N, 3) rad -> rotation matrices (N, 3, 3)."""
    w = np.asarray(rotvecs, dtype=float).reshape(-1, 3)
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-12
    th = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(th) / th)
    b = np.where(small, 0.5, (1.0 - np.cos(th)) / th ** 2)
    wx = np.zeros((len(w), 3, 3))
    wx[:, 0, 1], wx[:, 0, 2], wx[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    wx[:, 1, 0], wx[:, 2, 0], wx[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return np.eye(3) + a[:, None, None] * wx + b[:, None, None] * (wx @ wx)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Uniformly distributed rotation matrix (3, 3) drawn from ``rng`` (unit quaternion)."""
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def clip_convex_polygon(poly: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """
    Keep the part of a convex 2D polygon ``poly`` (N, 2) where ``normal . x <= offset``.

    Sutherland-Hodgman against one half-plane; returns the clipped polygon (M, 2), M may be 0.
    """
    if len(poly) == 0:
        return poly
    s = poly @ normal - offset
    out = []
    n = len(poly)
    for i in range(n):
        j = (i + 1) % n
        if s[i] <= 0:
            out.append(poly[i])
        if (s[i] < 0 < s[j]) or (s[j] < 0 < s[i]):
            t = s[i] / (s[i] - s[j])
            out.append(poly[i] + t * (poly[j] - poly[i]))
    if not out:
        return np.zeros((0, 2))
    res = np.array(out)
    # drop (near) duplicate consecutive vertices so no polygon edge has zero length
    keep = np.linalg.norm(res - np.roll(res, 1, axis=0), axis=1) > 1e-9
    return res[keep]


def clip_segments_to_rect(p1: np.ndarray, p2: np.ndarray, lo: Tuple[float, float],
                          hi: Tuple[float, float]) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Liang-Barsky clip of segments ``p1 -> p2`` (N, 2) to the box ``lo <= x <= hi``.

    Returns ``(t0, t1, ok)``: parameters (N,) of the clipped part along ``p1 + t (p2 - p1)``
    and a mask (N,) of segments with a non-empty part inside.
    """
    d = p2 - p1
    t0 = np.zeros(len(p1))
    t1 = np.ones(len(p1))
    ok = np.ones(len(p1), dtype=bool)
    for k in range(2):
        for q, bound, sgn in ((p1[:, k], lo[k], -1.0), (p1[:, k], hi[k], 1.0)):
            num = sgn * (bound - q)          # distance inside the boundary (>= 0 is inside)
            den = sgn * d[:, k]
            par = np.abs(den) < 1e-12
            ok &= ~(par & (num < 0))
            with np.errstate(divide='ignore', invalid='ignore'):
                t = np.where(par, 0.0, num / np.where(par, 1.0, den))
            t1 = np.where(~par & (den > 0), np.minimum(t1, t), t1)
            t0 = np.where(~par & (den < 0), np.maximum(t0, t), t0)
    ok &= t0 < t1
    return t0, t1, ok


def distort_pixels(uv: np.ndarray, K: np.ndarray, d: Sequence[float]) -> np.ndarray:
    """
    Map undistorted pinhole pixels ``uv`` (N, 2) through plumb_bob ``d = (k1, k2, p1, p2, k3)``.

    Same model as OpenCV's ``projectPoints``; returns distorted pixels (N, 2).
    """
    k1, k2, p1, p2, k3 = (list(d) + [0.0] * 5)[:5]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x = (uv[:, 0] - cx) / fx
    y = (uv[:, 1] - cy) / fy
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([fx * xd + cx, fy * yd + cy], axis=1)
