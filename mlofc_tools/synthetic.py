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
Synthetic multi-body line scenes: the paper's section 4.1 protocol, generalised.

Each of ``n`` rigid bodies carries random 3D line segments and moves relative to the camera by
``X' = R X + T`` between consecutive frames, with ``R = expm([w]x)`` a rotation about the CAMERA
CENTRE (the paper's model) and ``T`` a translation the rotation-only model treats as noise. The
motion is constant over the ``K`` frames. Segments are projected with a pinhole camera, their
endpoints slide along the 3D line from frame to frame (line tracks, not point tracks), and
zero-mean Gaussian noise is added to every endpoint coordinate.

Conventions: pixels ``(u, v)`` (column, row); camera optical frame x right, y down, z forward;
angular velocities are rotation vectors in rad per frame interval; translations in scene units
per frame interval (the depth range is in the same units).

Example::

    scene = make_scene(2, 20, noise_px=1.0, seed=0)
    scene.tracks.shape          # (40, 2, 4): (u1, v1, u2, v2) per line and frame
    scene.angular_velocities    # (2, 3) rad/frame
"""
from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

SeedLike = Union[None, int, np.random.SeedSequence, np.random.Generator]

#: How many rejection-sampling rounds :func:`make_scene` tries before giving up on a body.
MAX_ROUNDS = 200
#: Outlier kinds :func:`add_outliers` mixes, and the range of the jitter outliers (px).
MIXES = ('mixed', 'jitter', 'stitched')
JITTER_PX = (10.0, 30.0)


@dataclass(frozen=True)
class SyntheticScene:
    """
    A synthetic multi-body line scene.

    Attributes
    ----------
    tracks : (N, K, 4) float64
        Noisy segment endpoints ``(u1, v1, u2, v2)`` in pixels, per line and frame.
    clean_tracks : (N, K, 4) float64
        The same endpoints without noise: exact projections of the 3D segments.
    labels : (N,) int64
        Body index ``0 .. n-1`` of every line (lines are shuffled, not grouped by body).
    angular_velocities : (n, 3) float64
        Rotation vector ``w`` of each body per frame interval (rad/frame), camera optical frame:
        ``X_{k+1} = expm([w]x) X_k + T``.
    translations : (n, 3) float64
        Translation ``T`` of each body per frame interval (scene units/frame), camera optical
        frame.
    intrinsics : tuple of 4 float
        ``(fx, fy, cx, cy)`` in pixels.
    image_size : tuple of 2 int
        ``(width, height)`` in pixels.
    points : (N, K, 2, 3) float64
        The clean 3D segment endpoints in the camera optical frame at every frame (scene units);
        they project to ``clean_tracks``.
    noise_px : float
        Standard deviation of the Gaussian noise added to each endpoint coordinate (pixels).
    reference_frame : int
        The frame in which the lines were sampled (depth range and image lengths hold there).

    """

    tracks: np.ndarray
    clean_tracks: np.ndarray
    labels: np.ndarray
    angular_velocities: np.ndarray
    translations: np.ndarray
    intrinsics: Tuple[float, float, float, float]
    image_size: Tuple[int, int]
    points: np.ndarray
    noise_px: float
    reference_frame: int

    @property
    def n_bodies(self) -> int:
        """Return the number of bodies ``n``."""
        return int(self.angular_velocities.shape[0])

    @property
    def n_frames(self) -> int:
        """Return the number of frames ``K``."""
        return int(self.tracks.shape[1])

    @property
    def K(self) -> np.ndarray:  # noqa: N802 (the name every vision text uses)
        """Intrinsic matrix (3, 3) in pixels."""
        fx, fy, cx, cy = self.intrinsics
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def rotation_matrices(rotvecs: np.ndarray) -> np.ndarray:
    """
    Rodrigues' formula ``expm([w]x)`` for a stack of rotation vectors.

    Parameters
    ----------
    rotvecs : (..., 3) float
        Rotation vectors (rad), right-handed.

    Returns
    -------
    (..., 3, 3) float64
        Rotation matrices.

    """
    w = np.asarray(rotvecs, dtype=np.float64)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    wx = skew(w)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta ** 2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta ** 2 / 24.0, (1.0 - np.cos(safe)) / safe ** 2)
    return np.eye(3) + a * wx + b * (wx @ wx)


def skew(w: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``[w]x`` (..., 3, 3) of vectors ``w`` (..., 3)."""
    w = np.asarray(w, dtype=np.float64)
    z = np.zeros(w.shape[:-1])
    return np.stack([
        np.stack([z, -w[..., 2], w[..., 1]], axis=-1),
        np.stack([w[..., 2], z, -w[..., 0]], axis=-1),
        np.stack([-w[..., 1], w[..., 0], z], axis=-1),
    ], axis=-2)


def _unit_vectors(rng: np.random.Generator, n: int) -> np.ndarray:
    """Return ``n`` directions uniform on the unit sphere, (n, 3)."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _frame_poses(w: np.ndarray, t: np.ndarray, n_frames: int, ref: int
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Pose of every frame relative to the reference frame, for every body.

    With ``X_{k+1} = R X_k + T`` and ``X_ref`` given, ``X_k = R_k X_ref + t_k``.

    Parameters
    ----------
    w
        (n, 3) rotation vectors (rad/frame).
    t
        (n, 3) translations (units/frame).
    n_frames
        K.
    ref
        Index of the reference frame.

    Returns
    -------
    rots : (n, K, 3, 3), trans : (n, K, 3)

    """
    steps = np.arange(n_frames) - ref
    rots = rotation_matrices(w[:, None, :] * steps[None, :, None])
    r1 = rotation_matrices(w)
    trans = np.zeros((w.shape[0], n_frames, 3))
    for k in range(ref + 1, n_frames):  # forward: t_{k+1} = R t_k + T
        trans[:, k] = np.einsum('nij,nj->ni', r1, trans[:, k - 1]) + t
    for k in range(ref - 1, -1, -1):  # backward: t_{k-1} = R^T (t_k - T)
        trans[:, k] = np.einsum('nji,nj->ni', r1, trans[:, k + 1] - t)
    return rots, trans


def _project(points: np.ndarray, kmat: np.ndarray) -> np.ndarray:
    """Pinhole projection of (..., 3) camera-frame points to (..., 2) pixels."""
    p = points @ kmat.T
    return p[..., :2] / p[..., 2:3]


def _sample_body_lines(rng: np.random.Generator, count: int, rots: np.ndarray,
                       trans: np.ndarray, kmat: np.ndarray, image_size: Tuple[int, int],
                       depth: Tuple[float, float], seg_length_px: Tuple[float, float],
                       slide: float) -> np.ndarray:
    """
    Rejection-sample ``count`` 3D segments of one body visible in every frame.

    Parameters
    ----------
    rng : numpy Generator
        Draws the segments.
    count : int
        Number of segments wanted.
    rots : (K, 3, 3) float
        Rotation of each frame relative to the reference frame (see :func:`_frame_poses`).
    trans : (K, 3) float
        Translation of each frame relative to the reference frame.
    kmat : (3, 3) float
        Intrinsic matrix.
    image_size : (int, int)
        ``(width, height)`` in pixels; every endpoint must project inside in every frame.
    depth : (float, float)
        Range of the segments' depths in the reference frame (scene units).
    seg_length_px : (float, float)
        Range of the segments' projected lengths in the reference frame (pixels).
    slide : float
        Each endpoint moves along the 3D line by up to this share of the segment, independently
        in every frame (line tracks, not point tracks).

    Returns
    -------
    (count, K, 2, 3) float64
        Segment endpoints in the camera frame at every frame (units).

    """
    w_img, h_img = image_size
    kinv = np.linalg.inv(kmat)
    n_frames = rots.shape[0]
    found = []
    have = 0
    for _ in range(MAX_ROUNDS):
        batch = max(4 * (count - have), 16)
        mid = rng.uniform((0.0, 0.0), (w_img, h_img), size=(batch, 2))
        length = rng.uniform(seg_length_px[0], seg_length_px[1], size=batch)
        ang = rng.uniform(0.0, math.pi, size=batch)
        half = 0.5 * length[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        pix = np.stack([mid - half, mid + half], axis=1)  # (B, 2, 2)
        z = rng.uniform(depth[0], depth[1], size=(batch, 2, 1))
        ref_pts = z * (np.concatenate([pix, np.ones((batch, 2, 1))], axis=2) @ kinv.T)
        a, b = ref_pts[:, 0], ref_pts[:, 1]
        # endpoints slide along the 3D line independently in every frame
        s = rng.uniform(-slide, slide, size=(batch, n_frames, 2))
        s[..., 1] += 1.0
        seg = a[:, None, None, :] + s[..., None] * (b - a)[:, None, None, :]  # (B, K, 2, 3)
        pts = np.einsum('kij,bkej->bkei', rots, seg) + trans[None, :, None, :]
        zc = pts[..., 2]
        ok = np.all(zc > 1e-3 * depth[0], axis=(1, 2))
        uv = _project(np.where(zc[..., None] > 0, pts, 1.0), kmat)
        inside = ((uv[..., 0] >= 0.0) & (uv[..., 0] <= w_img - 1.0)
                  & (uv[..., 1] >= 0.0) & (uv[..., 1] <= h_img - 1.0))
        ok &= np.all(inside, axis=(1, 2))
        img_len = np.linalg.norm(uv[:, :, 1] - uv[:, :, 0], axis=-1)
        ok &= np.all(img_len >= 0.5 * seg_length_px[0], axis=1)
        found.append(pts[ok][:count - have])
        have += found[-1].shape[0]
        if have >= count:
            return np.concatenate(found, axis=0)
    raise ValueError(
        f'could not place {count} line segments visible in all {n_frames} frames after '
        f'{MAX_ROUNDS} rounds: the motion is too large for the image (lower rotation_deg, '
        f'translation_ratio or n_frames)')


def _check_scene_args(n_bodies: int, counts: np.ndarray, lines_per_body: object,
                      n_frames: int, noise_px: float, translation_ratio: float,
                      depth: Tuple[float, float], rotation_deg: Tuple[float, float],
                      slide: float) -> None:
    """Raise ``ValueError`` on arguments of :func:`make_scene` that make no scene."""
    if n_bodies < 1:
        raise ValueError(f'n_bodies must be >= 1, got {n_bodies}')
    if np.any(counts < 1):
        raise ValueError(f'lines_per_body must be >= 1, got {lines_per_body}')
    if n_frames < 2:
        raise ValueError(f'n_frames must be >= 2, got {n_frames}')
    if noise_px < 0 or translation_ratio < 0:
        raise ValueError(f'noise_px and translation_ratio must be >= 0, got {noise_px}, '
                         f'{translation_ratio}')
    if not 0 < depth[0] <= depth[1]:
        raise ValueError(f'depth must be 0 < near <= far, got {depth}')
    if not 0 <= rotation_deg[0] <= rotation_deg[1]:
        raise ValueError(f'rotation_deg must be 0 <= low <= high, got {rotation_deg}')
    if not 0 <= slide < 0.5:
        raise ValueError(f'slide must be in [0, 0.5), got {slide}')


def _sample_motions(rng: np.random.Generator, n_bodies: int, rotation_deg: Tuple[float, float],
                    translation_ratio: float, pure_translation_body: bool
                    ) -> Tuple[np.ndarray, np.ndarray]:
    """Draw the bodies' rotation vectors ``w`` (n, 3) and translations ``t`` (n, 3) per frame."""
    angles = np.deg2rad(rng.uniform(rotation_deg[0], rotation_deg[1], size=n_bodies))
    w = _unit_vectors(rng, n_bodies) * angles[:, None]
    t_norm = translation_ratio * angles
    if pure_translation_body:
        w[-1] = 0.0
        t_norm[-1] = translation_ratio * angles[0]
    t = _unit_vectors(rng, n_bodies) * t_norm[:, None]
    return w, t


def make_scene(n_bodies: int, lines_per_body: Union[int, Sequence[int]], n_frames: int = 2,
               noise_px: float = 1.0, image_size: Tuple[int, int] = (1000, 1000),
               focal_length: float = 1000.0, rotation_deg: Tuple[float, float] = (2.0, 6.0),
               depth: Tuple[float, float] = (5.0, 8.0), translation_ratio: float = 0.0,
               pure_translation_body: bool = False, seed: SeedLike = None,
               seg_length_px: Tuple[float, float] = (50.0, 400.0), slide: float = 0.1,
               reference_frame: Optional[int] = None) -> SyntheticScene:
    """
    Generate a random multi-body line scene (the paper's section 4.1 protocol).

    Every body gets a rotation axis uniform on the sphere and an angle uniform in
    ``rotation_deg`` (degrees per frame), constant over the ``n_frames`` frames, about the camera
    centre. Lines are sampled in the reference frame: image midpoint uniform in the image, image
    length uniform in ``seg_length_px``, orientation uniform, each endpoint at a depth uniform in
    ``depth``; a line is kept only if it stays in the image (and in front of the camera, at least
    half the minimum length long) in every frame.

    Translation (the paper's Fig. 3): every body also translates by ``T`` per frame with a random
    direction and ``|T| = translation_ratio * |w|``, i.e. the paper's "linear velocity t times as
    large as the angular velocity" with ``w`` in rad/frame and ``T`` in the scene units of
    ``depth``. Since lines lie 5-8 units away, the translational flow is roughly
    ``translation_ratio / depth`` times the rotational flow.

    Pure translation (the paper's Fig. 4): with ``pure_translation_body`` the LAST body has
    ``w = 0`` and ``|T| = translation_ratio * |w_0|`` (the paper: "the linear velocity of the two
    objects are same, t times as large as the first object's angular velocity"); the other bodies
    keep ``|T_i| = translation_ratio * |w_i|``.

    Parameters
    ----------
    n_bodies : int
        Number of bodies ``n >= 1``.
    lines_per_body : int or sequence of n ints
        Lines on each body.
    n_frames : int
        Frames ``K >= 2``.
    noise_px : float
        Standard deviation of the Gaussian noise on each endpoint coordinate (pixels).
    image_size : (width, height)
        Pixels.
    focal_length : float
        ``fx = fy`` in pixels; the principal point is the image centre.
    rotation_deg : (low, high)
        Range of the rotation angle per frame (degrees).
    depth : (near, far)
        Depth range of the endpoints in the reference frame (scene units).
    translation_ratio : float
        ``t`` above (units per rad); ``0`` gives pure rotation about the camera centre.
    pure_translation_body : bool
        Make the last body translate only (needs ``n_bodies >= 2`` to be meaningful).
    seed : None, int, SeedSequence or Generator
        Randomness; the same seed gives the same scene.
    seg_length_px : (low, high)
        Range of segment lengths in the reference image (pixels).
    slide : float
        Each endpoint slides along its 3D line by up to ``slide`` times the segment length in
        every frame, so endpoints do not correspond between frames.
    reference_frame : int, optional
        Frame in which lines are sampled; default the middle frame ``(K - 1) // 2``.

    Returns
    -------
    SyntheticScene

    Raises
    ------
    ValueError
        On invalid arguments, or when no segment stays visible under the requested motion.

    """
    counts = np.broadcast_to(np.asarray(lines_per_body, dtype=np.int64), (n_bodies,))
    _check_scene_args(n_bodies, counts, lines_per_body, n_frames, noise_px, translation_ratio,
                      depth, rotation_deg, slide)
    ref = (n_frames - 1) // 2 if reference_frame is None else int(reference_frame)
    if not 0 <= ref < n_frames:
        raise ValueError(f'reference_frame must be in [0, {n_frames}), got {ref}')
    rng = np.random.default_rng(seed)
    w_img, h_img = int(image_size[0]), int(image_size[1])
    f = float(focal_length)
    intrinsics = (f, f, w_img / 2.0, h_img / 2.0)
    kmat = np.array([[f, 0.0, intrinsics[2]], [0.0, f, intrinsics[3]], [0.0, 0.0, 1.0]])

    w, t = _sample_motions(rng, n_bodies, rotation_deg, translation_ratio,
                           pure_translation_body)
    rots, trans = _frame_poses(w, t, n_frames, ref)

    pts = np.concatenate([
        _sample_body_lines(rng, int(c), rots[i], trans[i], kmat, (w_img, h_img), depth,
                           seg_length_px, slide)
        for i, c in enumerate(counts)], axis=0)
    labels = np.repeat(np.arange(n_bodies, dtype=np.int64), counts)
    order = rng.permutation(labels.shape[0])
    pts, labels = pts[order], labels[order]
    clean = _project(pts, kmat).reshape(pts.shape[0], n_frames, 4)
    noisy = clean + rng.normal(0.0, float(noise_px), size=clean.shape) if noise_px > 0 \
        else clean.copy()
    return SyntheticScene(tracks=noisy, clean_tracks=clean, labels=labels,
                          angular_velocities=w, translations=t, intrinsics=intrinsics,
                          image_size=(w_img, h_img), points=pts, noise_px=float(noise_px),
                          reference_frame=ref)


def split_lines(total: int, n_bodies: int) -> List[int]:
    """Return ``total`` lines over ``n_bodies`` bodies as evenly as possible (the first more)."""
    return [total // n_bodies + (1 if i < total % n_bodies else 0) for i in range(n_bodies)]


@dataclass
class ScheduledScene:
    """
    A line stream whose bodies start, stop and leave the view (:func:`scheduled_scene`).

    Attributes
    ----------
    tracks : (N, K, 4) float64
        Noisy endpoints px per line and frame, NaN where the line is out of view.
    labels : (N,) int64
        Body of every line (0 = the still background).
    moving : (n, K) bool
        Whether each body turns between frame ``k - 1`` and ``k`` (False at ``k = 0``).
    visible : (n, K) bool
        Whether each body is in view at frame ``k``.
    angular_velocities : (n, 3) float64
        Each body's rotation vector while it moves (rad/frame).
    intrinsics : tuple of 4 float
        ``(fx, fy, cx, cy)`` px.
    image_size : tuple of 2 int
        ``(width, height)`` px.

    """

    tracks: np.ndarray
    labels: np.ndarray
    moving: np.ndarray
    visible: np.ndarray
    angular_velocities: np.ndarray
    intrinsics: Tuple[float, float, float, float]
    image_size: Tuple[int, int]


def scheduled_scene(schedule: Sequence[Tuple[int, int, int]], n_frames: int,
                    lines_per_body: int = 40, background_lines: int = 120,
                    noise_px: float = 0.5,
                    image_size: Tuple[int, int] = (640, 480), focal_length: float = 550.0,
                    rotation_deg: Tuple[float, float] = (0.5, 1.5),
                    depth: Tuple[float, float] = (5.0, 8.0), seed: SeedLike = None
                    ) -> ScheduledScene:
    """
    Generate a line stream of a still background and bodies that start, stop and leave.

    Every body of ``schedule`` ``(start, stop, leave)`` rotates about the camera centre
    (the paper's model) between frames ``start`` and ``stop`` (frame indices; it moves from
    ``start`` to ``start + 1`` first) at a rotation drawn as :func:`make_scene` does, and is in
    view from frame 0 up to ``leave`` (exclusive; ``leave >= n_frames``: always), with
    ``lines_per_body`` lines. Body 0 is a still background of ``background_lines``
    lines. Lines are sampled in frame 0 (visible in every frame the body is in
    view), endpoints slide along their lines by up to 10% per frame, Gaussian noise
    ``noise_px`` on every coordinate.
    """
    rng = np.random.default_rng(seed)
    n = len(schedule) + 1
    w_img, h_img = int(image_size[0]), int(image_size[1])
    f = float(focal_length)
    kmat = np.array([[f, 0.0, w_img / 2.0], [0.0, f, h_img / 2.0], [0.0, 0.0, 1.0]])
    w, _ = _sample_motions(rng, n, rotation_deg, 0.0, False)
    w[0] = 0.0
    moving = np.zeros((n, n_frames), dtype=bool)
    visible = np.ones((n, n_frames), dtype=bool)
    for b, (start, stop, leave) in enumerate(schedule, start=1):
        moving[b, start + 1:stop + 1] = True
        visible[b, leave:] = False
    tracks, labels = [], []
    counts = [background_lines] + [lines_per_body] * (n - 1)
    for b, count in enumerate(counts):
        # rotation of frame k relative to frame 0: the steps while the body moves
        step = rotation_matrices(w[b][None])[0]
        rots = np.empty((n_frames, 3, 3))
        rots[0] = np.eye(3)
        for k in range(1, n_frames):
            rots[k] = step @ rots[k - 1] if moving[b, k] else rots[k - 1]
        seen = int(visible[b].sum())
        pts = _sample_body_lines(rng, count, rots[:seen], np.zeros((seen, 3)), kmat,
                                 (w_img, h_img), depth, (50.0, 300.0), 0.1)
        uv = _project(pts, kmat).reshape(count, seen, 4)
        full = np.full((count, n_frames, 4), np.nan)
        full[:, :seen] = uv + rng.normal(0.0, float(noise_px), size=uv.shape)
        tracks.append(full)
        labels.append(np.full(count, b, dtype=np.int64))
    order = rng.permutation(sum(counts))
    return ScheduledScene(tracks=np.concatenate(tracks)[order],
                          labels=np.concatenate(labels)[order], moving=moving,
                          visible=visible, angular_velocities=w,
                          intrinsics=(f, f, w_img / 2.0, h_img / 2.0), image_size=(w_img, h_img))


def add_outliers(tracks: np.ndarray, fraction: float, rng: np.random.Generator,
                 mix: str = 'mixed') -> Tuple[np.ndarray, np.ndarray]:
    """
    Replace a fraction of the tracks by tracks that follow no rigid motion.

    *Jitter* outliers: every endpoint of every frame of the track moved by a distance uniform
    in :data:`JITTER_PX` in a uniform direction, independently. *Stitched* outliers: frame ``k``
    of the track is frame ``k`` of another line of the scene, a different line for every frame
    (a tracker's association error). ``mix='mixed'`` makes half of the outliers (rounded up)
    jitter and the others stitched; ``'jitter'`` or ``'stitched'`` only one kind.

    Parameters
    ----------
    tracks : (N, K, 4) float
        Line tracks (pixels).
    fraction : float
        Fraction of the tracks to replace (rounded to a whole number of tracks).
    rng : numpy Generator
        Draws the outliers.
    mix : {'mixed', 'jitter', 'stitched'}
        Kinds of outliers (above).

    Returns
    -------
    tracks : (N, K, 4) float64
        A copy with the outliers in place.
    kind : (N,) int64
        0 = inlier (unchanged), 1 = jitter outlier, 2 = stitched outlier.

    """
    src = np.asarray(tracks, dtype=np.float64)
    n_tracks, n_frames = src.shape[:2]
    out = src.copy()
    kind = np.zeros(n_tracks, dtype=np.int64)
    m = int(round(fraction * n_tracks))
    idx = rng.choice(n_tracks, size=m, replace=False)
    if mix not in MIXES:
        raise ValueError(f'mix must be one of {MIXES}, got {mix!r}')
    n_jit = {'mixed': (m + 1) // 2, 'jitter': m, 'stitched': 0}[mix]
    jit, sti = idx[:n_jit], idx[n_jit:]
    mag = rng.uniform(JITTER_PX[0], JITTER_PX[1], size=(jit.size, n_frames, 2))
    ang = rng.uniform(0.0, 2.0 * math.pi, size=mag.shape)
    disp = np.stack([mag * np.cos(ang), mag * np.sin(ang)], axis=-1)  # (J, K, 2 ends, uv)
    out[jit] += disp.reshape(jit.size, n_frames, 4)
    kind[jit] = 1
    for i in sti:  # a few tracks per scene: a loop costs nothing
        others = rng.choice(n_tracks - 1, size=n_frames, replace=n_frames > n_tracks - 1)
        others[others >= i] += 1
        out[i] = src[others, np.arange(n_frames)]
    kind[sti] = 2
    return out, kind
