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
Synthetic image sequences of rotating striped boxes, with per-frame line ground truth.

Conventions: pixels ``(u, v)`` with pixel centres at integers; camera optical frame x right,
y down, z forward; angular velocities right-handed in the camera frame, rad/s.  A body point
moves as ``X(t + dt) = R (X(t) - P) + P`` with ``R = exp([omega dt]x)`` and pivot ``P``: the
camera centre for ``motion='camera_centre'`` (pure rotation, the model of the solver) or the
box centre for ``motion='own_centre'`` (the lines then also translate).
"""
from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

import cv2
from mlofc_ros.camera import as_camera, CameraLike, CameraModel
from mlofc_tools.render.geometry import distort_pixels
from mlofc_tools.render.raster import offset_polygons, SHIFT, to_fixed
from mlofc_tools.render.scene import Body, make_background, place_boxes
from mlofc_tools.render.truth import visible_segments
import numpy as np

MOTIONS = ('camera_centre', 'own_centre')


@dataclass
class FrameTruth:
    """
    Ground-truth line segments of one frame (``L`` visible 3D edges).

    Attributes
    ----------
    segments
        (L, 4) float64 ``(u1, v1, u2, v2)`` px, the longest visible part of each
        projected straight 3D edge in the undistorted pinhole image.
    segments_distorted
        (L, 4) float64, the same endpoints mapped through the lens
        distortion (equal to ``segments`` without distortion; the segment itself is curved).
    body_ids
        (L,) int64 index into ``RenderedSequence.angular_velocities``.
    edge_ids
        (L,) int64 persistent id of the 3D edge (the same in every frame).
    visible_fraction
        (L,) float64 in (0, 1], visible share of the edge's whole projection.

    """

    segments: np.ndarray
    segments_distorted: np.ndarray
    body_ids: np.ndarray
    edge_ids: np.ndarray
    visible_fraction: np.ndarray


@dataclass
class RenderedSequence:
    """
    A rendered sequence and its ground truth (``F`` frames, ``B`` bodies).

    Attributes
    ----------
    frames
        ``F`` gray images (H, W) uint8 (distorted when the camera has distortion).
    stamps
        (F,) float64 seconds, frame ``i`` at ``i / fps``.
    camera
        the :class:`CameraModel` (K and distortion) of ``frames``.
    angular_velocities
        (B, 3) float64 rad/s, camera optical frame, per body id.
    body_names
        ``B`` names, ``['background', 'box0', ...]`` (no background if disabled).
    truth
        ``F`` :class:`FrameTruth`.
    pivots
        (B, 3) float64 rotation pivot of each body, camera frame (scene units).
    pinhole_frames
        with distortion, the noise-free undistorted pinhole renderings (H, W)
        uint8 that ``frames`` were warped from; None without distortion.

    """

    frames: List[np.ndarray]
    stamps: np.ndarray
    camera: CameraModel
    angular_velocities: np.ndarray
    body_names: List[str]
    truth: List[FrameTruth]
    pivots: np.ndarray
    pinhole_frames: Optional[List[np.ndarray]] = None


def _make_camera(size: Tuple[int, int], camera: CameraLike,
                 distortion: Optional[Sequence[float]]) -> CameraModel:
    width, height = size
    cam = as_camera(camera)
    if cam is None:
        f = 0.9 * width
        cam = CameraModel(f, f, (width - 1) / 2.0, (height - 1) / 2.0)
    if distortion is not None:
        cam = CameraModel(cam.fx, cam.fy, cam.cx, cam.cy, tuple(float(x) for x in distortion),
                          'plumb_bob')
    if cam.has_distortion and cam.distortion_model != 'plumb_bob':
        raise ValueError(
            f'render supports plumb_bob distortion only, got {cam.distortion_model!r}')
    return cam


class _Warp:
    """Pinhole canvas geometry and the remap from it to the distorted image."""

    def __init__(self, cam: CameraModel, size: Tuple[int, int]) -> None:
        width, height = size
        self.size = size
        self.K = cam.K
        self.dist = cam.d if cam.has_distortion else None
        if self.dist is None:
            self.origin = (0, 0)
            self.shape = (height, width)
            self.map_x = self.map_y = None
            return
        d = np.asarray(self.dist, dtype=np.float64)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9)
        uu, vv = np.meshgrid(np.arange(width, dtype=np.float64),
                             np.arange(height, dtype=np.float64))
        grid = np.stack([uu.ravel(), vv.ravel()], axis=1).reshape(-1, 1, 2)
        if hasattr(cv2, 'undistortPointsIter'):     # OpenCV 4
            und = cv2.undistortPointsIter(grid, self.K, d, None, self.K, crit)
        else:                                        # OpenCV 5 takes the criteria directly
            und = cv2.undistortPoints(grid, self.K, d, R=None, P=self.K, criteria=crit)
        und = und.reshape(-1, 2)
        back = distort_pixels(und, self.K, d)
        err = np.abs(back - grid.reshape(-1, 2)).max()
        if not np.all(np.isfinite(und)) or err > 0.05:
            raise ValueError(f'distortion {tuple(d)} cannot be inverted over the '
                             f'{width}x{height} image (round-trip error {err:.3g} px)')
        lo = np.minimum(und.min(axis=0), [0.0, 0.0])
        hi = np.maximum(und.max(axis=0), [width - 1.0, height - 1.0])
        if np.any(hi - lo > 4 * np.array([width, height])):
            raise ValueError(f'distortion {tuple(d)} is too strong for the renderer '
                             f'(undistorted image spans {hi - lo} px)')
        u0, v0 = (int(math.floor(x)) - 3 for x in lo)
        u1, v1 = (int(math.ceil(x)) + 4 for x in hi)
        self.origin = (u0, v0)
        self.shape = (v1 - v0, u1 - u0)
        self.map_x = (und[:, 0] - u0).reshape(height, width).astype(np.float32)
        self.map_y = (und[:, 1] - v0).reshape(height, width).astype(np.float32)

    @property
    def canvas(self) -> Tuple[int, int, int, int]:
        """``(u0, v0, width, height)`` of the rasterised pinhole canvas, image pixels."""
        return self.origin[0], self.origin[1], self.shape[1], self.shape[0]

    def pinhole_crop(self, canvas: np.ndarray) -> np.ndarray:
        """Return the (H, W) part of the canvas under the output image's pinhole pixels."""
        width, height = self.size
        u0, v0 = self.origin
        return canvas[-v0:-v0 + height, -u0:-u0 + width]

    def warp(self, canvas: np.ndarray) -> np.ndarray:
        """Canvas -> output image (distorted with bilinear remap when there is distortion)."""
        if self.map_x is None:
            return canvas
        return cv2.remap(canvas, self.map_x, self.map_y, cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE)


def _project(points: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pinhole projection of camera-frame points (..., 3) to pixels (..., 2)."""
    return points[..., :2] / points[..., 2:] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]


def _render_frame(bodies: List[Body], face_offset: np.ndarray, edge_offset: np.ndarray,
                  t: float, warp: _Warp) -> Tuple[np.ndarray, np.ndarray, np.ndarray,
                                                  np.ndarray, np.ndarray, np.ndarray]:
    """
    Rasterise all bodies at time ``t`` seconds.

    Returns ``(canvas (Hc, Wc) uint8, face ids (Hc, Wc) int32, p1 (N, 2), p2 (N, 2) px,
    faces (N, 2) global face ids, (body id, edge id) (N, 2))`` for the N candidate edges
    (those bounding a front face), in undistorted image pixels.
    """
    K = warp.K
    shift = np.array(warp.origin, dtype=float)
    canvas = np.zeros(warp.shape, dtype=np.uint8)
    ids = np.full(warp.shape, -1, dtype=np.int32)
    poses = [b.pose(t) for b in bodies]
    # painter's order: the background, then boxes far to near (by centre depth)
    order = sorted(range(len(bodies)),
                   key=lambda i: (bodies[i].name != 'background', -poses[i][1][2]))
    verts, nxt, starts, expand, greys, draw = [], [], [], [], [], []
    rects, rect_ids = [], []
    p1s, p2s, faces_all, body_edge = [], [], [], []
    n_verts = 0
    for i in order:
        body = bodies[i]
        rot, cen = poses[i]
        n_cam = body.face_normal @ rot.T
        pt_cam = body.face_point @ rot.T + cen
        front = np.einsum('ij,ij->i', n_cam, pt_cam) < 0
        if not np.any(front):
            continue
        verts.append(body.verts @ rot.T + cen)
        nxt.append(body.vert_next + n_verts)
        starts.append(body.poly_start[:-1] + n_verts)
        other = body.vert_other_face
        vert_face = np.repeat(body.poly_face, np.diff(body.poly_start))
        expand.append((other >= 0) & front[np.maximum(other, 0)] & (vert_face < other))
        greys.append(body.poly_grey)
        draw.append(front[body.poly_face])
        n_verts += len(body.verts)
        rects.append(body.face_rect[front] @ rot.T + cen)
        rect_ids.append(face_offset[i] + np.nonzero(front)[0])
        # edges bounding at least one front face
        ef = body.edge_faces
        cand = np.nonzero(front[ef[:, 0]] | ((ef[:, 1] >= 0) & front[np.maximum(ef[:, 1], 0)]))[0]
        p1s.append(body.edge_a[cand] @ rot.T + cen)
        p2s.append(body.edge_b[cand] @ rot.T + cen)
        faces_all.append(np.where(ef[cand] >= 0, ef[cand] + face_offset[i], -1))
        body_edge.append(np.stack([np.full(len(cand), i), edge_offset[i] + cand], axis=1))
    if not verts:
        empty = np.zeros((0, 2))
        return (canvas, ids, empty, empty, np.zeros((0, 2), dtype=np.int64),
                np.zeros((0, 2), dtype=np.int64))
    uv = _project(np.concatenate(verts), K) - shift
    poly_start = np.concatenate(starts + [[n_verts]])
    fixed = to_fixed(offset_polygons(uv, np.concatenate(nxt), poly_start,
                                     np.concatenate(expand)))
    grey = np.rint(np.concatenate(greys)).astype(int).tolist()
    bounds = poly_start.tolist()
    for p in np.nonzero(np.concatenate(draw))[0].tolist():
        cv2.fillConvexPoly(canvas, fixed[bounds[p]:bounds[p + 1]], grey[p], cv2.LINE_AA, SHIFT)
    rect_fixed = to_fixed(_project(np.concatenate(rects), K) - shift)
    for f, pts in zip(np.concatenate(rect_ids).tolist(), rect_fixed):
        cv2.fillConvexPoly(ids, pts, f, cv2.LINE_8, SHIFT)
    return (canvas, ids, _project(np.concatenate(p1s), K), _project(np.concatenate(p2s), K),
            np.concatenate(faces_all), np.concatenate(body_edge).astype(np.int64))


def render_sequence(n_boxes: int = 2, n_frames: int = 20, size: Tuple[int, int] = (640, 480),
                    motion: str = 'camera_centre', background: bool = True,
                    noise_sigma: float = 2.0, fps: float = 30.0, seed: Optional[int] = 0,
                    camera: CameraLike = None,
                    angular_speed_deg_s: Tuple[float, float] = (60.0, 150.0),
                    distortion: Optional[Sequence[float]] = None,
                    depth_range: Tuple[float, float] = (4.0, 8.0)) -> RenderedSequence:
    """
    Render ``n_frames`` gray frames of ``n_boxes`` rotating striped boxes, with ground truth.

    Parameters
    ----------
    n_boxes
        1..4 cuboids (laid out so they stay apart in the image, at depths in
        ``depth_range``).
    n_frames
        number of frames (>= 1), frame ``i`` at ``i / fps`` seconds.
    size
        ``(width, height)`` px.
    motion
        ``'camera_centre'`` (rotation about the camera centre: pure rotation) or
        ``'own_centre'`` (each box spins about its own centre, no translation of the centre).
    background
        add a static striped wall at depth ~12 (body 0, omega 0).
    noise_sigma
        std of additive Gaussian sensor noise, grey levels.
    fps
        frame rate, Hz.
    seed
        random seed (scene and noise); the same seed renders the same sequence.
    camera
        :class:`CameraModel` or ``(fx, fy, cx, cy)``; default ``fx = fy = 0.9 width``
        with the principal point at the image centre ``((W - 1) / 2, (H - 1) / 2)``.
    angular_speed_deg_s
        ``(min, max)`` of the uniform box rotation speeds, deg/s.
    distortion
        plumb_bob ``(k1, k2, p1, p2, k3)``; frames then show the distortion
        (rendered as pinhole, warped with ``cv2.remap``) and ``camera.d`` carries it.
    depth_range
        ``(min, max)`` of the uniform box centre depths, scene units, at most 9 (the wall is
        at ~12); a box's size follows from its image cell and depth.

    The scene is planned over the whole sequence: for ``'camera_centre'`` the boxes' mid-sequence
    positions are laid out and each rotation axis is drawn in a cone about the box's line of
    sight that is narrow enough to keep the box in view and apart from the others (for long or
    fast sequences the boxes mostly spin about their line of sight), so the same seed with
    another ``n_frames`` gives another scene.  Noise comes from OpenCV's generator, reseeded
    from ``seed`` for every frame (this resets the calling thread's ``cv2.theRNG``).

    Raises ``ValueError`` naming a bad argument.

    """
    if not 1 <= int(n_boxes) <= 4:
        raise ValueError(f'n_boxes must be 1..4, got {n_boxes}')
    if int(n_frames) < 1:
        raise ValueError(f'n_frames must be >= 1, got {n_frames}')
    width, height = (int(x) for x in size)
    if width < 32 or height < 32:
        raise ValueError(f'size must be at least 32x32 px, got {size}')
    if motion not in MOTIONS:
        raise ValueError(f'motion must be one of {MOTIONS}, got {motion!r}')
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f'fps must be > 0, got {fps}')
    if not (math.isfinite(noise_sigma) and noise_sigma >= 0):
        raise ValueError(f'noise_sigma must be >= 0, got {noise_sigma}')
    lo, hi = (float(x) for x in angular_speed_deg_s)
    if not (0 <= lo <= hi and math.isfinite(hi)):
        raise ValueError(f'angular_speed_deg_s must be 0 <= min <= max, got {angular_speed_deg_s}')
    z_lo, z_hi = (float(x) for x in depth_range)
    if not (0 < z_lo <= z_hi <= 9.0):
        raise ValueError(f'depth_range must be 0 < min <= max <= 9 (the wall is at ~12), got '
                         f'{depth_range}')
    cam = _make_camera((width, height), camera, distortion)
    warp = _Warp(cam, (width, height))
    scene_ss, noise_ss = np.random.SeedSequence(seed).spawn(2)
    rng = np.random.default_rng(scene_ss)
    noise_rng = np.random.default_rng(noise_ss)
    stamps = np.arange(int(n_frames), dtype=np.float64) / float(fps)

    bodies: List[Body] = []
    if background:
        bodies.append(make_background(rng, cam.K, warp.canvas))
    bodies.extend(place_boxes(rng, int(n_boxes), (width, height), cam.K, motion, stamps,
                              (lo, hi), (z_lo, z_hi)))
    face_offset = np.concatenate([[0], np.cumsum([len(b.face_normal) for b in bodies])])
    edge_offset = np.concatenate([[0], np.cumsum([len(b.edge_a) for b in bodies])])

    frames: List[np.ndarray] = []
    pinholes: Optional[List[np.ndarray]] = [] if warp.dist is not None else None
    truth: List[FrameTruth] = []
    for t in stamps:
        canvas, ids, p1, p2, faces, be = _render_frame(bodies, face_offset, edge_offset,
                                                       float(t), warp)
        seg, frac, ok = visible_segments(p1, p2, faces, ids, warp.origin, (width, height),
                                         warp.K, warp.dist)
        order = np.argsort(be[ok, 1], kind='stable')
        seg = seg[ok][order]
        if warp.dist is not None:
            seg_d = distort_pixels(seg.reshape(-1, 2), warp.K, warp.dist).reshape(-1, 4)
        else:
            seg_d = seg.copy()
        truth.append(FrameTruth(segments=seg, segments_distorted=seg_d,
                                body_ids=be[ok, 0][order], edge_ids=be[ok, 1][order],
                                visible_fraction=frac[ok][order]))
        img = warp.warp(canvas)
        if pinholes is not None:
            pinholes.append(warp.pinhole_crop(canvas).copy())
        if noise_sigma > 0:
            # OpenCV's (thread-local) generator is several times faster than numpy's here;
            # it is reseeded from the sequence seed for every frame, so output is deterministic
            noise = np.empty(img.shape, dtype=np.float32)
            cv2.setRNGSeed(int(noise_rng.integers(1, 2 ** 31 - 1)))
            cv2.randn(noise, 0.0, float(noise_sigma))
            img = cv2.add(img, noise, dtype=cv2.CV_8U)   # rounds and saturates
        else:
            img = np.ascontiguousarray(img)
        frames.append(img)
    return RenderedSequence(
        frames=frames, stamps=stamps, camera=cam,
        angular_velocities=np.array([b.omega for b in bodies], dtype=np.float64),
        body_names=[b.name for b in bodies], truth=truth,
        pivots=np.array([b.pivot for b in bodies], dtype=np.float64),
        pinhole_frames=pinholes)
