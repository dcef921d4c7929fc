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
"""Line tracking with persistent ids: KLT prediction + association with fresh detections.

Per frame (everything vectorised over tracks and detections):

1. *Predict*: a few points sampled along every live track are followed from the previous
   frame with pyramidal Lucas-Kanade (``cv2.calcOpticalFlowPyrLK``) and back again; points
   whose forward-backward error *across the line* exceeds ``fb_threshold`` px are dropped (the
   component along an edge is ill-posed and irrelevant to the line). The predicted line is the
   total-least-squares fit to the surviving points.
2. *Detect* (every ``detect_every`` frames): :class:`~mlofc_ros.segments.detect.LineDetector`.
3. *Associate*: a detection joins the predicted track with the lowest normalised cost among
   those passing the gates (oriented angle, perpendicular distance both ways, overlap along the
   line). A track may absorb several collinear fragments; they are fused by a length-weighted
   TLS fit. Unclaimed detections start new tracks (births).
4. Tracks without a detection coast on their KLT prediction (reported while ``report_coasting``)
   and retire after ``max_misses`` consecutive misses or when KLT loses them.

Segments are ``(u1, v1, u2, v2)`` px in the input image, oriented like the detector's (brighter
side on the left). Only the *line* carries over between frames; endpoints need not correspond.
"""
from typing import Optional, Tuple

import cv2
import numpy as np

from mlofc_ros.segments.detect import LineDetector


def _tls_by_group(px: np.ndarray, py: np.ndarray, w: np.ndarray, g: np.ndarray, k: int,
                  sxx0: Optional[np.ndarray] = None, sxy0: Optional[np.ndarray] = None,
                  syy0: Optional[np.ndarray] = None):
    """Weighted TLS line per group: centroid (k, 2), unit direction (k, 2), weight sum (k,).

    Points ``(px, py)`` with weights ``w`` belong to groups ``g`` in ``[0, k)``. Optional
    per-point second moments (``sxx0`` ...) add the spread of a segment around its midpoint.
    """
    W = np.bincount(g, w, k)
    Ws = np.where(W > 0, W, 1.0)
    cx = np.bincount(g, w * px, k) / Ws
    cy = np.bincount(g, w * py, k) / Ws
    dx, dy = px - cx[g], py - cy[g]
    a, b, c = dx * dx, dx * dy, dy * dy
    if sxx0 is not None:
        a, b, c = a + sxx0, b + sxy0, c + syy0
    sxx = np.bincount(g, w * a, k)
    sxy = np.bincount(g, w * b, k)
    syy = np.bincount(g, w * c, k)
    theta = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    return np.stack([cx, cy], 1), np.stack([np.cos(theta), np.sin(theta)], 1), W


class LineTracker:
    """Track line segments over a gray image stream with persistent ``uint32`` ids.

    Parameters (pixels are full-resolution input pixels):

    * ``detector``: a :class:`LineDetector` (default: LSD at scale 0.5, ``min_length``).
    * ``min_length``: shortest segment reported or born, px.
    * ``max_misses``: consecutive frames without a matching detection before a track retires.
    * ``detect_every``: run the detector every n-th frame; KLT alone carries tracks between.
    * ``n_points``: KLT points per track; ``klt_win``/``klt_levels``: LK window and pyramid.
    * ``fb_threshold``: max forward-backward error across the line, px.
    * ``angle_deg``/``distance_px``: association gates (oriented angle, perpendicular offset);
      ``min_overlap``: overlap along the line over the shorter segment's length.
    * ``report_coasting``: also report tracks carried by KLT alone in this frame.
    """

    def __init__(self, detector: Optional[LineDetector] = None, min_length: float = 20.0,
                 max_misses: int = 2, detect_every: int = 1, n_points: int = 5,
                 klt_win: int = 15, klt_levels: int = 3, fb_threshold: float = 1.0,
                 angle_deg: float = 4.0, distance_px: float = 3.0, min_overlap: float = 0.3,
                 report_coasting: bool = True, max_tracks: int = 2000) -> None:
        if int(detect_every) < 1:
            raise ValueError(f'detect_every must be >= 1, got {detect_every}')
        if int(n_points) < 2:
            raise ValueError(f'n_points must be >= 2, got {n_points}')
        self.detector = detector if detector is not None else LineDetector(min_length)
        self.min_length = float(min_length)
        self.max_misses = int(max_misses)
        self.detect_every = int(detect_every)
        self.n_points = int(n_points)
        self.klt_win = (int(klt_win), int(klt_win))
        self.klt_levels = int(klt_levels)
        self.fb_threshold = float(fb_threshold)
        self.angle_deg = float(angle_deg)
        self.distance_px = float(distance_px)
        self.min_overlap = float(min_overlap)
        self.report_coasting = bool(report_coasting)
        self.max_tracks = int(max_tracks)
        self._lk = {'winSize': self.klt_win, 'maxLevel': self.klt_levels,
                    'criteria': (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03),
                    'minEigThreshold': 1e-4}
        self.reset()

    def reset(self) -> None:
        """Drop every track and the previous image; ids restart from 0."""
        self._ids = np.zeros(0, np.uint32)
        self._seg = np.zeros((0, 4), np.float64)
        self._misses = np.zeros(0, np.int32)
        self._age = np.zeros(0, np.int32)
        self._next_id = 0
        self._prev = None
        self._shape = None
        self._frame = 0
        #: per-stage seconds of the last :meth:`update` (``detect``, ``track``)
        self.last_timing = {'detect': 0.0, 'track': 0.0}

    @property
    def n_tracks(self) -> int:
        """Number of live tracks (reported or coasting)."""
        return int(self._ids.size)

    # ------------------------------------------------------------------ prediction
    def _predict(self, pyr) -> Tuple[np.ndarray, np.ndarray]:
        """KLT-predict every live track into the new frame: (segments (T, 4), ok (T,))."""
        t_n = self._seg.shape[0]
        if t_n == 0 or self._prev is None:
            return self._seg.copy(), np.zeros(t_n, bool)
        p = self.n_points
        s = self._seg
        t = np.linspace(0.0, 1.0, p)
        a, b = s[:, None, :2], s[:, None, 2:]
        pts = (a + t[None, :, None] * (b - a)).reshape(-1, 2).astype(np.float32)
        nxt, st1, _ = cv2.calcOpticalFlowPyrLK(self._prev, pyr, pts, None, **self._lk)
        back, st2, _ = cv2.calcOpticalFlowPyrLK(pyr, self._prev, nxt, None, **self._lk)
        d = s[:, 2:] - s[:, :2]
        length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        u = d / length[:, None]
        nrm = np.repeat(np.stack([-u[:, 1], u[:, 0]], 1), p, axis=0)
        fb = np.abs(np.einsum('ij,ij->i', (back - pts).astype(np.float64), nrm))
        ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (fb <= self.fb_threshold)
        h, w = self._shape
        q = nxt.astype(np.float64)
        ok &= (q[:, 0] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] >= 0) & (q[:, 1] <= h - 1)
        g = np.repeat(np.arange(t_n), p)
        gi, qi = g[ok], q[ok]
        cnt = np.bincount(gi, minlength=t_n)
        c, dirn, _ = _tls_by_group(qi[:, 0], qi[:, 1], np.ones(gi.size), gi, t_n)
        # keep the old orientation
        flip = np.einsum('ij,ij->i', dirn, u) < 0
        dirn[flip] *= -1
        # residual check: all surviving points within fb_threshold + 1 px of the fit line
        r = np.abs((qi[:, 0] - c[gi, 0]) * dirn[gi, 1] - (qi[:, 1] - c[gi, 1]) * dirn[gi, 0])
        rmax = np.zeros(t_n)
        np.maximum.at(rmax, gi, r)
        good = (cnt >= max(2, (p + 1) // 2)) & (rmax <= self.fb_threshold + 1.0)
        # extent: old endpoints shifted by the mean displacement, projected on the new line
        disp = np.zeros((t_n, 2))
        np.add.at(disp, gi, qi - pts[ok])
        disp /= np.maximum(cnt, 1)[:, None]
        e1 = s[:, :2] + disp - c
        e2 = s[:, 2:] + disp - c
        t1 = np.einsum('ij,ij->i', e1, dirn)
        t2 = np.einsum('ij,ij->i', e2, dirn)
        pred = np.concatenate([c + t1[:, None] * dirn, c + t2[:, None] * dirn], axis=1)
        pred[~good] = s[~good]
        return pred, good

    # ------------------------------------------------------------------ association
    def _associate(self, pred: np.ndarray, det: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """Best track (index, or -1) for each detection; (D,) intp."""
        t_n, d_n = pred.shape[0], det.shape[0]
        if t_n == 0 or d_n == 0:
            return np.full(d_n, -1, np.intp)
        tp1, tp2 = pred[:, :2], pred[:, 2:]
        td = tp2 - tp1
        tl = np.maximum(np.hypot(td[:, 0], td[:, 1]), 1e-9)
        tu = td / tl[:, None]
        tc = 0.5 * (tp1 + tp2)
        dp1, dp2 = det[:, :2], det[:, 2:]
        dd = dp2 - dp1
        dl = np.maximum(np.hypot(dd[:, 0], dd[:, 1]), 1e-9)
        du = dd / dl[:, None]
        dc = 0.5 * (dp1 + dp2)
        cosang = tu @ du.T                                               # (T, D)
        # gates: wider for tracks without a KLT prediction
        scale = np.where(predicted, 1.0, 3.0)[:, None]
        cos_thr = np.cos(np.deg2rad(np.minimum(self.angle_deg * scale, 45.0)))
        gate = cosang >= cos_thr
        # perpendicular distance of detection endpoints to the track line, and back
        rel = dc[None, :, :] - tc[:, None, :]                            # (T, D, 2)
        tn = np.stack([-tu[:, 1], tu[:, 0]], 1)
        dn = np.stack([-du[:, 1], du[:, 0]], 1)
        dist_td = np.abs(np.einsum('tdk,tk->td', rel, tn))
        dist_dt = np.abs(np.einsum('tdk,dk->td', rel, dn))
        dist = np.maximum(dist_td, dist_dt)
        gate &= dist <= self.distance_px * scale
        # overlap along the track line, relative to the shorter segment
        along = np.einsum('tdk,tk->td', rel, tu)                         # det centre on track
        half_proj = 0.5 * dl[None, :] * np.abs(cosang)
        lo = np.maximum(along - half_proj, -0.5 * tl[:, None])
        hi = np.minimum(along + half_proj, 0.5 * tl[:, None])
        overlap = (hi - lo) / np.minimum(tl[:, None], dl[None, :])
        gate &= overlap >= self.min_overlap
        ang = np.arccos(np.clip(cosang, -1.0, 1.0))
        cost = dist / (self.distance_px * scale) + ang / np.deg2rad(self.angle_deg * scale) \
            - 0.5 * np.minimum(overlap, 1.0)
        cost = np.where(gate, cost, np.inf)
        best = np.argmin(cost, axis=0)
        best = np.where(np.isfinite(cost[best, np.arange(d_n)]), best, -1)
        return best

    @staticmethod
    def _fuse(det: np.ndarray, owner: np.ndarray, t_n: int, ref_dir: np.ndarray) -> np.ndarray:
        """Fuse the detections (D, 4) claimed by each track into one segment per track.

        ``owner`` (D,) holds track indices in ``[0, t_n)``; returns (t_n, 4): the
        length-weighted TLS line spanning the extreme endpoint projections (rows of tracks
        without detections are meaningless).
        """
        p1, p2 = det[:, :2], det[:, 2:]
        d = p2 - p1
        w = np.hypot(d[:, 0], d[:, 1])
        mid = 0.5 * (p1 + p2)
        c, u, _ = _tls_by_group(mid[:, 0], mid[:, 1], w, owner, t_n,
                                d[:, 0] ** 2 / 12.0, d[:, 0] * d[:, 1] / 12.0,
                                d[:, 1] ** 2 / 12.0)
        sd = np.zeros((t_n, 2))
        np.add.at(sd, owner, d)
        flip = np.einsum('ij,ij->i', u, sd) < 0
        u[flip] *= -1
        pts = np.concatenate([p1, p2])
        g = np.concatenate([owner, owner])
        tt = np.einsum('ij,ij->i', pts - c[g], u[g])
        tmin = np.full(t_n, np.inf)
        tmax = np.full(t_n, -np.inf)
        np.minimum.at(tmin, g, tt)
        np.maximum.at(tmax, g, tt)
        return np.concatenate([c + tmin[:, None] * u, c + tmax[:, None] * u], axis=1)

    # ------------------------------------------------------------------ main entry
    def update(self, gray: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Process one frame ``gray`` (H, W) uint8.

        Returns ``(track_ids (M,) uint32, segments (M, 4) float32)`` px of the tracks seen in
        this frame (matched to a detection, or carried by KLT when ``report_coasting``), sorted
        by id. Raises ``ValueError`` on a non-uint8/non-2D image or a change of image size
        (call :meth:`reset` first).
        """
        if gray.ndim != 2 or gray.dtype != np.uint8:
            raise ValueError(f'expected a (H, W) uint8 gray image, got {gray.dtype} '
                             f'{gray.shape}')
        if self._shape is not None and gray.shape != self._shape:
            raise ValueError(f'image size changed from {self._shape} to {gray.shape}; '
                             'reset() the tracker first')
        t0 = cv2.getTickCount()
        self._shape = gray.shape
        # (cv2's Python binding cannot pass prebuilt pyramids to calcOpticalFlowPyrLK)
        pred, predicted = self._predict(gray)
        self._prev = gray
        t_n = pred.shape[0]
        run_detect = (self._frame % self.detect_every == 0) or t_n == 0
        t1 = cv2.getTickCount()
        det = self.detector.detect(gray) if run_detect else np.zeros((0, 4), np.float32)
        t2 = cv2.getTickCount()
        det = det.astype(np.float64)
        owner = self._associate(pred, det, predicted)
        claimed = owner >= 0
        matched = np.zeros(t_n, bool)
        new_seg = pred.copy()
        if claimed.any():
            own = owner[claimed]
            matched[own] = True
            fused = self._fuse(det[claimed], own, t_n, pred[:, 2:] - pred[:, :2])
            new_seg[matched] = fused[matched]
        if run_detect:
            misses = np.where(matched, 0, self._misses + 1)
        else:
            misses = np.where(predicted, self._misses, self._misses + 1)
        alive = (matched | predicted) & (misses <= self.max_misses)
        length = np.hypot(new_seg[:, 2] - new_seg[:, 0], new_seg[:, 3] - new_seg[:, 1])
        alive &= length >= 0.5 * self.min_length
        report = matched | (predicted & self.report_coasting)
        report &= alive & (length >= self.min_length)
        # births
        born = det[~claimed]
        room = max(self.max_tracks - int(alive.sum()), 0)
        born = born[:room]
        nb = born.shape[0]
        new_ids = (self._next_id + np.arange(nb)).astype(np.uint32)
        self._next_id += nb
        self._ids = np.concatenate([self._ids[alive], new_ids])
        self._seg = np.concatenate([new_seg[alive], born])
        self._misses = np.concatenate([misses[alive], np.zeros(nb, np.int32)]).astype(np.int32)
        self._age = np.concatenate([self._age[alive] + 1, np.zeros(nb, np.int32)])
        rep = np.concatenate([report[alive], np.ones(nb, bool)])
        self._frame += 1
        out_ids, out_seg = self._ids[rep], self._seg[rep]
        order = np.argsort(out_ids, kind='stable')
        t3 = cv2.getTickCount()
        f = cv2.getTickFrequency()
        self.last_timing = {'detect': (t2 - t1) / f, 'track': ((t1 - t0) + (t3 - t2)) / f}
        return out_ids[order], out_seg[order].astype(np.float32)
