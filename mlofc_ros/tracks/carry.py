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
Carrying tracks into the next frame: prediction, edge refinement, KLT, growth, velocity.

A track with a velocity is predicted by it (the last displacement of both endpoints, turned by
the line's smoothed turn rate) and re-located on the image edges by
:func:`~mlofc_ros.tracks.edges.refine_lines`. New tracks, and tracks whose prediction finds
too little edge support, are carried by pyramidal Lucas-Kanade (``cv2.calcOpticalFlowPyrLK``)
on :data:`N_POINTS` points, a TLS line fit to them (one outlier may be dropped, turns above
:data:`MAX_TURN_DEG` rejected; along the line only points with 2D texture count) and the same
edge refinement; a new track whose KLT fit is rejected is still carried when the refinement of
that fit finds its edge. A carried line then grows along itself while the edge continues
beyond its ends (:func:`grow`), so a track born on a fragment reaches the whole edge before
the next detection.
"""
from typing import Tuple

import cv2
from mlofc_ros.tracks.edges import grow_lines, refine_lines, tls_rows
from mlofc_ros.tracks.frames import Frames, KLT_SCALE
import numpy as np

#: KLT points per track, the LK window (px of the reduced image) and pyramid levels.
N_POINTS = 4
KLT_WIN = 9
KLT_LEVELS = 3
#: Largest distance (px) of a KLT point to the line fitted to the track's points.
RESIDUAL_PX = 0.75
#: Largest turn of a line between two frames (deg).
MAX_TURN_DEG = 12.0
#: LK points whose window's smaller gradient eigenvalue is below this (OpenCV's
#: ``OPTFLOW_LK_GET_MIN_EIGENVALS`` units) do not measure along-line motion.
KLT_MIN_EIG = 1e-2
#: The edge search of :func:`refine_lines`: samples per line, search radius (px), smallest
#: gradient (grey levels per 2 px), inlier distance (px), share of the strongest gradient.
REFINE_SAMPLES = 12
REFINE_RADIUS = 3
REFINE_MIN_GRADIENT = 8.0
REFINE_INLIER_PX = 0.5
REFINE_MIN_RELATIVE = 0.3
#: A peak of the opposite polarity counts as this much further from the prediction (px), so a
#: neighbouring stripe's edge loses a tie. A signed search first (own polarity only, the
#: unsigned one as fallback) measured 0-1.7 points more tracked-5 for ~1.5 ms CPU per frame.
REFINE_PREFER_POLARITY = 1.0
#: Share of the refinement's samples that must agree for the line to count as found.
MIN_SUPPORT = 0.4
#: Weight of the last frame's turn of a line in its smoothed turn rate, in [0, 1].
TURN_SMOOTHING = 0.5
#: Growth: up to GROW_STEPS samples GROW_STEP_PX apart beyond each end of a carried line.
#: There is no shrinking between detections (shrinking to the supported samples cost
#: tracked-5 on every rendered sequence).
GROW_STEPS = 2
GROW_STEP_PX = 2.0

_T = (np.arange(N_POINTS) + 0.5) / N_POINTS     # (P,) KLT points along a segment


def carry(frames: Frames, image: np.ndarray, seg: np.ndarray, vel: np.ndarray,
          has_vel: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Carry the tracks ``seg`` (T, 4) into the current frame: (segments, ok (T,), confirmed (T,)).

    Tracks with a velocity (``has_vel``) are predicted by it (``vel`` (T, 4)) and refined on
    the image edges. Tracks without a velocity, or whose refinement fails, are KLT-carried
    with the full pyramid (tracks without a velocity also pass when the KLT fit fails but its
    edge refinement succeeds). Failed tracks get their constant-velocity prediction and
    ``ok = False``; ``confirmed`` marks the tracks the edge search found. ``image`` is the
    current frame as float32.
    """
    t_n = seg.shape[0]
    new = seg + vel
    ok = np.zeros(t_n, bool)
    confirmed = np.zeros(t_n, bool)
    if t_n == 0 or frames.prev is None:
        return new, ok, confirmed
    sel = np.nonzero(has_vel)[0]
    if sel.size:
        seg1, ok1 = _refine(image, new[sel])
        new[sel[ok1]] = seg1[ok1]
        ok[sel[ok1]] = True
        confirmed[sel[ok1]] = True
    sel = np.nonzero(~ok)[0]
    if sel.size:
        seg2, ok2 = _klt(frames, seg[sel])
        ref2, ok3 = _refine(image, seg2)
        # a good KLT fit stands on its own where the edge search finds too little support
        seg2 = np.where(ok3[:, None], ref2, seg2)
        # a new track whose KLT fit fails (residual, turn) but whose refined line finds
        # its edge is kept: coasting, it would die before the next detection
        ok2 = ok2 | (ok3 & ~has_vel[sel])
        new[sel[ok2]] = seg2[ok2]
        ok[sel[ok2]] = True
        confirmed[sel[ok2 & ok3]] = True
    return new, ok, confirmed


def _refine(image: np.ndarray, seg: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return the segments (n, 4) refined on the image edges and whether each was found."""
    ref, support, _ = refine_lines(image, seg, REFINE_SAMPLES, REFINE_RADIUS,
                                   REFINE_MIN_GRADIENT, REFINE_INLIER_PX, REFINE_MIN_RELATIVE,
                                   None, REFINE_PREFER_POLARITY)
    return ref, support >= MIN_SUPPORT


def _klt(frames: Frames, s: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """KLT-carry segments ``s`` (n, 4) from zero motion: (segments (n, 4), ok (n,))."""
    n = s.shape[0]
    t = _T[None, :, None]
    p0 = (s[:, None, :2] + t * (s[:, None, 2:] - s[:, None, :2])).astype(np.float32)
    q1, st, eig = _lk(frames, p0.reshape(-1, 2))
    # along a line, LK only measures motion where its window has texture across the
    # line's direction too (stripe crossings, corners); elsewhere (parallel stripes) the
    # along-line part is the aperture problem's arbitrary answer
    tex = (eig >= KLT_MIN_EIG).reshape(n, -1).astype(np.float64)
    return _fit(frames.shape, s, p0, q1.reshape(n, -1, 2), st.reshape(n, -1), tex)


def _lk(frames: Frames, p0: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Track points (n, 2) float32 from the previous frame: (new (n, 2), status (n,), eig (n,)).

    ``eig`` is the minimum eigenvalue of each window's gradient matrix (OpenCV's
    normalisation). Runs on the reduced images (pixel centres mapped exactly).
    """
    if p0.shape[0] == 0:
        return p0.copy(), np.zeros(0, bool), np.zeros(0, np.float32)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 10, 0.03)
    f = KLT_SCALE
    q0 = ((p0 + 0.5) * f - 0.5).astype(np.float32)
    p1, st, eig = cv2.calcOpticalFlowPyrLK(frames.small('prev'), frames.small('cur'), q0,
                                           None, winSize=(KLT_WIN, KLT_WIN),
                                           maxLevel=KLT_LEVELS, criteria=crit,
                                           flags=cv2.OPTFLOW_LK_GET_MIN_EIGENVALS)
    p1 = (p1.reshape(-1, 2) + 0.5) / f - 0.5
    return p1, st.reshape(-1).astype(bool), eig.reshape(-1)


def _fit(shape: Tuple[int, int], seg: np.ndarray, p0: np.ndarray, p1: np.ndarray,
         valid: np.ndarray, tex: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Re-fit lines to carried points: (new segments (n, 4), ok (n,)).

    ``seg`` (n, 4) previous segments, ``p0``/``p1`` (n, P, 2) points before/after, ``valid``
    (n, P), ``shape`` the image's (H, W). The new line is the TLS line of the points (at most
    one outlier dropped), spanning the old endpoints projected onto it and slid by the points'
    mean displacement along it (only the points with ``tex`` (n, P) > 0, no slide when none
    has); ``ok`` also requires the line to turn by at most :data:`MAX_TURN_DEG`.
    """
    h, w = shape
    x, y = p1[..., 0].astype(np.float64), p1[..., 1].astype(np.float64)
    inside = (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    wt = (valid & inside).astype(np.float64)
    cx, cy, ux, uy = tls_rows(x, y, wt)
    r = np.abs((x - cx[:, None]) * uy[:, None] - (y - cy[:, None]) * ux[:, None]) * wt
    worst = np.argmax(r, axis=1)
    bad = r[np.arange(r.shape[0]), worst] > RESIDUAL_PX
    wt[bad, worst[bad]] = 0.0
    cx, cy, ux, uy = tls_rows(x, y, wt)
    r = np.abs((x - cx[:, None]) * uy[:, None] - (y - cy[:, None]) * ux[:, None]) * wt
    ok = (wt.sum(1) >= N_POINTS - 1) & (r.max(1) <= RESIDUAL_PX)
    # keep the old orientation; a line turning faster than MAX_TURN_DEG is lost
    d = seg[:, 2:] - seg[:, :2]
    dl = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    cos_turn = (ux * d[:, 0] + uy * d[:, 1]) / dl
    ok &= np.abs(cos_turn) >= np.cos(np.deg2rad(MAX_TURN_DEG))
    flip = cos_turn < 0
    ux, uy = np.where(flip, -ux, ux), np.where(flip, -uy, uy)
    # extent: old endpoints projected on the new line, slid by the mean along-line
    # displacement of the points
    disp = (p1 - p0).astype(np.float64)
    along = disp[..., 0] * ux[:, None] + disp[..., 1] * uy[:, None]
    wa = wt * tex
    slide = (wa * along).sum(1) / np.maximum(wa.sum(1), 1e-9)
    ta = (seg[:, 0] - cx) * ux + (seg[:, 1] - cy) * uy + slide
    tb = (seg[:, 2] - cx) * ux + (seg[:, 3] - cy) * uy + slide
    new = np.stack([cx + ta * ux, cy + ta * uy, cx + tb * ux, cy + tb * uy], axis=1)
    return new, ok


def update_motion(old: np.ndarray, seg: np.ndarray, carried: np.ndarray, vel: np.ndarray,
                  omega: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return the velocities (T, 4) px per frame and turn rates (T,) rad per frame after a carry.

    A carried track's velocity is the displacement of its endpoints from ``old`` to ``seg``
    (T, 4), turned by its smoothed turn rate: with a constant turn rate a line's displacement
    turns with it (a rotating body, or a camera rolling), so the along-line motion stays along
    the line. The other tracks keep ``vel`` and ``omega``.
    """
    vel = np.where(carried[:, None], seg - old, vel)
    d0 = old[:, 2:] - old[:, :2]
    d1 = seg[:, 2:] - seg[:, :2]
    phi = np.arctan2(d0[:, 0] * d1[:, 1] - d0[:, 1] * d1[:, 0],
                     d0[:, 0] * d1[:, 0] + d0[:, 1] * d1[:, 1])
    lim = np.deg2rad(MAX_TURN_DEG)
    b = TURN_SMOOTHING
    omega = np.where(carried, (1 - b) * omega + b * np.clip(phi, -lim, lim), omega)
    return np.where(carried[:, None], _turn(vel, omega), vel), omega


def _turn(vel: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Rotate endpoint displacements (T, 4) by angles ``phi`` (T,) rad."""
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    vx, vy = vel[:, 0::2], vel[:, 1::2]
    out = np.empty_like(vel)
    out[:, 0::2] = c * vx - s * vy
    out[:, 1::2] = s * vx + c * vy
    return out


def grow(image: np.ndarray, seg: np.ndarray, carried: np.ndarray) -> np.ndarray:
    """Return ``seg`` (T, 4) with the carried lines grown along the edges beyond their ends."""
    seg = seg.copy()
    if carried.any():
        idx = np.nonzero(carried)[0]
        seg[idx], _ = grow_lines(image, seg[idx], GROW_STEP_PX, GROW_STEPS,
                                 min(REFINE_RADIUS, 2), REFINE_MIN_GRADIENT,
                                 1.5 * REFINE_INLIER_PX, REFINE_MIN_RELATIVE)
    return seg


def clip_to_image(seg: np.ndarray, shape: Tuple[int, int]) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return segments ``seg`` (T, 4) px clipped to the image and which keep a part in it (T,).

    ``shape``: the image's (H, W); the image is ``[0, W - 1] x [0, H - 1]`` (pixel centres).
    Liang-Barsky clipping: the segments a frame reports lie in the image, and a carried line
    with no part in it is not seen. A segment with no part inside is returned as it was,
    marked outside.
    """
    h, w = shape
    seg = np.asarray(seg, dtype=np.float64)
    xs, ys = seg[:, 0::2], seg[:, 1::2]
    # most lines lie in the image: clip only those that reach past its border
    over = ((xs.min(axis=1) < 0) | (xs.max(axis=1) > w - 1) | (ys.min(axis=1) < 0)
            | (ys.max(axis=1) > h - 1))
    inside = np.ones(seg.shape[0], dtype=bool)
    if not over.any():
        return seg.copy(), inside
    out = seg.copy()
    out[over], inside[over] = _clipped(seg[over], w, h)
    return out, inside


def _clipped(seg: np.ndarray, w: int, h: int) -> Tuple[np.ndarray, np.ndarray]:
    """Return :func:`clip_to_image` of segments ``seg`` (T, 4) that reach past the border."""
    x0, y0 = seg[:, 0], seg[:, 1]
    dx, dy = seg[:, 2] - x0, seg[:, 3] - y0
    # the four half-planes p t <= q of the parametric segment, t in [0, 1]
    p = np.stack([-dx, dx, -dy, dy], axis=1)
    q = np.stack([x0, (w - 1) - x0, y0, (h - 1) - y0], axis=1)
    with np.errstate(divide='ignore', invalid='ignore'):
        r = q / p
    t0 = np.max(np.where(p < 0, r, 0.0), axis=1)
    t1 = np.min(np.where(p > 0, r, 1.0), axis=1)
    inside = (t0 <= t1) & np.all((p != 0) | (q >= 0), axis=1)
    t0, t1 = np.where(inside, t0, 0.0), np.where(inside, t1, 1.0)
    out = np.stack([x0 + t0 * dx, y0 + t0 * dy, x0 + t1 * dx, y0 + t1 * dy], axis=1)
    # rounding can leave a cut end a hair outside
    hi = np.array([w - 1.0, h - 1.0, w - 1.0, h - 1.0])
    out = np.where(inside[:, None], np.minimum(np.maximum(out, 0.0), hi), out)
    return out, inside


def remap_velocity(old: np.ndarray, vel: np.ndarray, new: np.ndarray) -> np.ndarray:
    """
    Move endpoint displacements (T, 4) px of segments ``old`` (T, 4) to the ends of ``new``.

    ``new`` lies on (about) the same lines with the same orientation but another extent; the
    displacement is taken as affine in the position along the line (exact for an affine image
    motion), so the far end of a grown line moves as the line's extrapolated motion says.
    Applied unchanged instead, a turning line whose extent a detection had cut was
    mispredicted in the next frame (measured: tracked-5 +0.9-1.3 points on three of six
    own_centre seeds, -0.4 on one, bench frontend).
    """
    d = old[:, 2:] - old[:, :2]
    l2 = np.maximum(np.einsum('ij,ij->i', d, d), 1e-9)
    s1 = np.einsum('ij,ij->i', new[:, :2] - old[:, :2], d) / l2
    s2 = np.einsum('ij,ij->i', new[:, 2:] - old[:, :2], d) / l2
    va, dv = vel[:, :2], vel[:, 2:] - vel[:, :2]
    return np.concatenate([va + s1[:, None] * dv, va + s2[:, None] * dv], axis=1)
